"""The success test of shared/notes/metrics.md on masks whose answers are known."""

import numpy as np
import pytest

from handshadow.metrics import FitScore, hd95, iou, score, thin_recall


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
