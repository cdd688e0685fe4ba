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
