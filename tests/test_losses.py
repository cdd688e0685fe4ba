"""Loss terms on small hand-made masks: what they count and where their gradient points."""

import torch

from handshadow import losses


def _solid_target(h=32, w=32):
    t = torch.zeros(h, w)
    t[4:28, 4:28] = 1
    return t


def test_gaps_counts_light_leaking_through_a_solid_target_only():
    target = _solid_target()
    solid = target.clone()[None]
    slit = solid.clone()
    slit[0, 10:20, 15:17] = 0  # a 2-pixel slit between two "fingers", inside the target
    dent = solid.clone()
    dent[0, 4:8, 10:20] = 0  # a wide dent in the outline: the image term's business, not a leak
    assert float(losses.gaps(solid, target, 2)[0]) == 0.0
    assert float(losses.gaps(dent, target, 2)[0]) == 0.0
    assert float(losses.gaps(slit, target, 2)[0]) * 32 * 32 == 20.0  # every slit pixel counts once
    # Where the target itself has a hole, a hole in the shadow is right, not a leak.
    holed = target.clone()
    holed[10:20, 15:17] = 0
    assert float(losses.gaps(slit, holed, 2)[0]) == 0.0


def test_gaps_gradient_closes_the_leak():
    target = _solid_target()
    shadow = target.clone()[None]
    shadow[0, 10:20, 15:17] = 0
    shadow.requires_grad_(True)
    losses.gaps(shadow, target, 2).sum().backward()
    g = shadow.grad[0]
    assert (g[10:20, 15:17] < 0).all()  # raising coverage there lowers the loss
    assert float(g[target == 0].abs().sum()) == 0.0


def test_notches_mark_holes_and_narrow_gaps_not_open_ground():
    import numpy as np

    t = np.zeros((100, 100), bool)
    t[20:80, 10:30] = True  # two legs 6 px apart (a narrow notch from below) ...
    t[20:80, 36:56] = True
    t[20:40, 10:56] = True  # ... joined by a body
    t[20:80, 70:95] = True
    t[45:55, 78:87] = False  # a hole in the second shape
    n = losses.notches(t)
    assert n.shape == t.shape and float(n[t].max()) == 0.0
    assert (n[45:55, 78:87] == 1).all()  # the hole
    assert n[60, 32] > 0  # deep in the narrow gap between the legs
    t[20:80, 30:33] = True  # narrow the gap to 3 px: it scores higher
    assert losses.notches(t)[60, 34] > n[60, 34]
    assert n[60, 62] == 0  # the wide gap between the two shapes
    assert n[5, 5] == 0 and n[90, 50] == 0  # open ground


def _maps(target):
    import numpy as np

    from handshadow.losses import TargetMaps

    return TargetMaps.build(np.asarray(target, bool))


def test_attraction_pulls_toward_missing_parts_only():
    target = _solid_target()
    shadow = target.clone()[None]
    shadow[0, 4:28, 20:28] = 0  # the right third of the target is missing
    shadow.requires_grad_(True)
    losses.attraction(shadow, target, 3.0).sum().backward()
    g = shadow.grad[0]
    # More coverage next to the missing part lowers the loss; far from it, nothing changes.
    assert float(g[16, 20]) < 0 and float(g[16, 20]) < float(g[16, 8])
    assert float(g[16, 5]) == 0.0 or abs(float(g[16, 5])) < 1e-4 * abs(float(g[16, 20]))


def test_placement_counts_only_vertices_outside_the_range():
    heights = torch.tensor([[0.5, 1.0, 1.5], [0.5, -0.01, 2.01]])
    out = losses.placement(heights, 0.0, 2.0)
    assert float(out[0]) == 0.0
    # 1 cm below and 1 cm beyond: each one unit squared, averaged over 3 vertices, times 10.
    assert float(out[1]) == pytest_approx(2 / 3 * 10)


def pytest_approx(x):
    import pytest

    return pytest.approx(x, rel=1e-5)


def test_thin_coverage_is_zero_when_a_finger_lies_on_the_thin_part():
    import numpy as np

    yy, xx = np.mgrid[:64, :64]
    t = (yy - 42) ** 2 + (xx - 31) ** 2 <= 15**2  # a round body (an opening keeps it whole)
    t[5:30, 30:32] = True  # a thin ear, 2 px wide, x 30..31, y 5..29
    maps = _maps(t)
    assert maps.thin_points.shape[0] > 0
    on = torch.tensor([[[[31.0, 4.0], [31.0, 29.0]]]])  # a finger segment along the ear
    off = torch.tensor([[[[5.0, 60.0], [20.0, 60.0]]]])  # one far below
    near = float(losses.thin_coverage(on, maps)[0])
    far = float(losses.thin_coverage(off, maps)[0])
    assert near < 1e-3 * far and near < 1e-4
    # With no thin parts there is nothing to reach.
    blob = _maps((yy - 32) ** 2 + (xx - 32) ** 2 <= 20**2)  # a disc has no thin parts
    assert float(losses.thin_coverage(off, blob)[0]) == 0.0


def test_square_closing_equals_the_max_pool_closing_to_the_bit():
    gen = torch.Generator().manual_seed(3)
    pool = torch.nn.functional.max_pool2d
    for radius in (1, 2, 3):
        k = 2 * radius + 1
        noise = (torch.rand(3, 40, 56, generator=gen) > 0.6).float()
        shapes = torch.zeros(2, 40, 56)
        shapes[:, 5:30, 0:20] = 1  # touches the border
        shapes[:, 12:14, 2:18] = 0  # a slit the closing fills
        shapes[1, 20:22, 30:56] = 1
        for masks in (noise, shapes):
            expected = -pool(-pool(masks[:, None], k, 1, radius), k, 1, radius)[:, 0]
            assert torch.equal(losses.square_closing(masks, radius), expected)
    # A frame large enough for the blockwise products (render.banded), not a multiple of a block.
    masks = (torch.rand(2, 264, 300, generator=gen) > 0.6).float()
    masks[0, 100:180, 0:120] = 1
    masks[0, 140:142, 4:110] = 0
    for radius in (1, 2, 5):
        k = 2 * radius + 1
        expected = -pool(-pool(masks[:, None], k, 1, radius), k, 1, radius)[:, 0]
        assert torch.equal(losses.square_closing(masks, radius), expected)
