"""The success test of shared/notes/metrics.md on masks whose answers are known."""

import numpy as np
import pytest

from handshadow.metrics import FitScore, far_outline, far_regions, hd95, iou, score, thin_recall


def head_with_ears(size: int = 200, ears: bool = True) -> np.ndarray:
    """A disc (the head) with two thin ears above it, like the rabbit puppet."""
    yy, xx = np.mgrid[:size, :size]
    mask = (yy - 130) ** 2 + (xx - 100) ** 2 <= 45**2
    if ears:
        mask |= (yy >= 30) & (yy < 95) & (((xx >= 78) & (xx < 86)) | ((xx >= 114) & (xx < 122)))
    return mask


def test_a_perfect_shadow_succeeds():
    t = head_with_ears()
    s = score(t, t)
    assert s.iou == 1.0 and s.hd95 == 0.0 and s.thin_recall == 1.0 and s.boundary_f1 == 1.0
    assert s.success and not s.near_miss


def test_cut_off_ears_fail_though_iou_is_high():
    t = head_with_ears()
    s = score(head_with_ears(ears=False), t)
    assert s.iou > 0.8  # IoU alone would call this a fit
    assert thin_recall(head_with_ears(ears=False), t) < 0.1
    assert s.hd95 > 0.03 and not s.success


@pytest.mark.parametrize("shift", [2, 5])
def test_hd95_of_a_shifted_shadow_is_the_shift(shift):
    t = head_with_ears(ears=False)
    s = np.roll(t, shift, axis=1)
    assert hd95(s, t) == pytest.approx(shift / t.shape[0], abs=1.0 / t.shape[0])
    assert iou(s, t) < 1.0


def test_near_miss_is_a_failure_within_reach():
    def near(iou, hd95, thin):
        return FitScore(iou=iou, boundary_f1=0.5, hd95=hd95, thin_recall=thin).near_miss

    assert near(0.9, 0.035, 0.9)
    assert not near(0.9, 0.045, 0.9)  # too far from the HD95 bar
    assert not near(0.9, 0.035, 0.4)  # thin parts missed
    assert not near(0.75, 0.035, 0.9)  # IoU missed
    assert not near(0.9, 0.025, 0.9)  # a success
    wider = FitScore(iou=0.9, boundary_f1=0.5, hd95=0.045, thin_recall=0.9)
    assert wider.within(0.02) and not wider.within(0.01)  # a wider reach (the hops')
    assert not FitScore(iou=0.9, boundary_f1=0.5, hd95=0.045, thin_recall=0.4).within(0.02)
    short = FitScore(iou=0.9, boundary_f1=0.5, hd95=0.025, thin_recall=0.57)  # thin parts a little short
    assert short.within(0.0, thin_margin=0.05) and not short.within(0.02) and not short.within(0.02, 0.02)


def test_one_iou_for_masks_batches_and_tensors():
    import torch

    from handshadow.metrics import iou

    a = np.zeros((8, 8), bool)
    a[2:6, 2:6] = True
    b = np.zeros((8, 8), bool)
    b[4:8, 4:8] = True
    assert iou(a, b) == 4 / 28
    empty = np.zeros((8, 8), bool)
    assert iou(empty, empty) == 1.0  # two empty masks agree
    batch = np.stack([a, b, empty])
    assert np.allclose(iou(batch, a), [1.0, 4 / 28, 0.0])
    t = iou(torch.as_tensor(np.stack([a, empty])), torch.as_tensor(empty))
    assert torch.equal(t, torch.tensor([0.0, 1.0]))
    soft = torch.as_tensor(a, dtype=torch.float32) * 0.5  # coverage: the soft IoU
    assert float(iou(soft, torch.as_tensor(a))) == 0.5


def test_several_views_are_judged_together():
    from handshadow.metrics import ViewScores, rank_key

    good = FitScore(iou=0.9, boundary_f1=0.9, hd95=0.01, thin_recall=0.9)
    near = FitScore(iou=0.9, boundary_f1=0.9, hd95=0.035, thin_recall=0.9)
    bad = FitScore(iou=0.5, boundary_f1=0.5, hd95=0.2, thin_recall=0.2)
    assert ViewScores((good,), (1.0,)).key() == rank_key(good)  # one view: the single-view key
    both, one, none = (ViewScores(s, (0.5, 0.5)) for s in ((good, good), (good, bad), (bad, bad)))
    assert both.success and not one.success and not one.near_miss
    assert ViewScores((good, near), (0.5, 0.5)).near_miss
    farther = FitScore(iou=0.9, boundary_f1=0.9, hd95=0.045, thin_recall=0.9)
    assert ViewScores((good, farther), (0.5, 0.5)).within(0.02)
    assert not ViewScores((good, farther), (0.5, 0.5)).near_miss
    assert sorted([none, one, both], key=ViewScores.key) == [both, one, none]
    # A view's weight decides which single success ranks first.
    front_first = ViewScores((good, bad), (0.8, 0.2))
    side_first = ViewScores((bad, good), (0.8, 0.2))
    assert front_first.key() < side_first.key()


def test_missing_parts_are_found_where_they_are_and_named_thin():
    from handshadow.guide import parts_text
    from handshadow.metrics import thin_parts, uncovered_parts

    target = np.zeros((100, 100), bool)
    target[40:90, 30:70] = True  # a body
    target[10:40, 66:70] = True  # an ear, 4 px wide: a thin part, top right
    shadow = target.copy()
    shadow[10:40, 66:70] = False  # the ear missed
    shadow[85:98, 10:30] = True  # a spill at the bottom left
    shadow[40:90, 30] = False  # a one-pixel sliver along the outline: no part
    missing = uncovered_parts(target, shadow, target)
    assert len(missing) == 1 and missing[0].thin
    assert missing[0].centre[0] > 2 / 3 and missing[0].centre[1] < 1 / 3
    assert missing[0].share == pytest.approx(120 / target.sum(), rel=0.05)
    extra = uncovered_parts(shadow, target, target)
    assert len(extra) == 1 and not extra[0].thin and extra[0].centre[1] > 2 / 3
    assert thin_parts(target)[20, 68]
    text = parts_text(missing, extra)
    assert text.startswith("missing a thin part at the top right") and "extra shadow at the bottom left" in text
    assert parts_text([], []) == "nothing missing"


def test_a_shadow_short_of_the_success_test_says_which_bars_it_misses_and_where():
    from handshadow.guide import shortfall_line
    from handshadow.metrics import score, thin_parts, uncovered_parts

    target = np.zeros((100, 100), bool)
    target[40:90, 30:70] = True  # a body
    target[10:40, 68:78] = True  # an ear, top right
    shadow = target.copy()
    shadow[10:40, 68:78] = False  # the ear missed: its outline is 30 px off, far past the HD95 bar
    thin = thin_parts(target)
    parts = uncovered_parts(target, shadow, target, thin), uncovered_parts(shadow, target, target, thin)
    s = score(shadow, target, thin)
    assert s.iou >= 0.8 and s.thin_recall < 0.6 and s.hd95 > 0.03
    line = shortfall_line(s, *parts)
    assert line.startswith(
        f"Short of the success test (thin parts {s.thin_recall:.2f} under 0.6; HD95 {s.hd95:.3f} over 0.03"
    )
    assert "IoU" not in line and "missing a part at the top right" in line and "extra shadow" not in line
    assert shortfall_line(score(target, target, thin), [], []) is None  # a success says nothing more


def test_guide_lines_are_wrapped_to_the_picture_and_keep_every_word():
    from PIL import ImageFont

    from handshadow.guide import wrapped

    font = ImageFont.load_default()
    long = "Short of the success test " + " ".join(f"word{k}" for k in range(60))
    lines = wrapped([long, "  Spread the fingers wide."], 300, font)
    assert len(lines) > 3 and lines[-1] == "  Spread the fingers wide."
    assert all(font.getlength(line) <= 300 for line in lines)
    assert " ".join(line.strip() for line in lines[:-1]).split() == long.split()
    assert all(line.startswith("  ") for line in lines[1:-1])  # a continuation is indented


def test_far_outline_marks_where_the_outline_fails_the_hd95_bar():
    # The bar is 0.03 of the frame height: 3 px here.
    target = np.zeros((100, 100), bool)
    target[20:80, 20:80] = True
    assert not far_outline(target, target).any()
    # A hole of the target that the shadow fills: its outline is far from every shadow outline.
    holed = target.copy()
    holed[45:55, 45:55] = False
    far = far_outline(target, holed)
    assert far[44:56, 44:56].sum() == far.sum() == 40  # the ring of target pixels around the hole
    # A bump of shadow 10 px out: its far end is past the bar, and so is the middle of the
    # target's edge that it hides; its root and the rest of the square are not.
    bumped = target.copy()
    bumped[80:90, 45:55] = True
    far = far_outline(bumped, target)
    assert far[89, 45:55].all() and far[83:89, 45].all() and far[79, 48:52].all()
    assert far.sum() == 10 + 2 * 6 + 4 and not far[80:83].any()


def test_far_regions_are_the_wrong_regions_that_fail_the_hd95_bar():
    # The bar is 0.03 of the frame height: 3 px here.
    target = np.zeros((100, 100), bool)
    target[20:80, 20:80] = True
    target[20:50, 45:51] = False  # a notch 6 px wide, 30 px deep, from the top edge
    target[5:20, 30:34] = True  # an ear 4 px wide, 15 px long
    assert not far_regions(target, target).any()
    shadow = np.zeros_like(target)
    shadow[20:80, 20:80] = True  # fills the notch, misses the ear
    shadow[20:80, 80:82] = True  # and a sliver 2 px wide along the right edge: within the bar
    regions = far_regions(shadow, target)
    notch, ear = np.zeros_like(target), np.zeros_like(target)
    notch[20:50, 45:51] = True
    ear[5:20, 30:34] = True
    assert np.array_equal(regions, notch | ear)
    assert hd95(shadow, target) > 0.03
    # Without the notch and the ear only the sliver is wrong, and nothing fails the bar.
    shadow[20:50, 45:51] = False
    shadow[5:20, 30:34] = True
    assert hd95(shadow, target) <= 0.03 and not far_regions(shadow, target).any()
