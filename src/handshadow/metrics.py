"""Judging a fit (docs/metrics.md): IoU alone rewards blobs.

All functions take binary (H, W) numpy masks (shadow, target) and work in pixels of that frame
(``iou`` also takes batches and tensors).
    iou              intersection over union
    boundary_f1      outlines within 2 px of each other, precision and recall combined
    hd95             95th percentile of outline-to-outline distances, both ways, / frame height
    far_outline      the outline pixels beyond the HD95 bar (where a shadow fails it)
    far_regions      the wrong pixels (shadow XOR target) in regions that reach such a pixel
    thin_recall      share of the target's thin parts covered by the shadow; thin parts are
                     what an opening with a disc of radius 4 % of the frame height removes
A fit is a success when IoU >= 0.8, thin-part recall >= 0.6 and HD95 <= 0.03.
:func:`rank_key` orders results by these measures (the search's ranking); :class:`ViewScores`
judges one pose in several views (one per lamp and wall) together.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage
from skimage.morphology import disk, opening

SUCCESS_IOU = 0.8
SUCCESS_THIN = 0.6
SUCCESS_HD95 = 0.03
THIN_RADIUS_SHARE = 0.04
NEAR_MISS_HD95 = 0.01  # how far past the HD95 bar a result still counts as a near miss
# The ranking's blend among results on the same side of the success test: IoU, plus this
# much thin-part recall, minus this much HD95 (a share of the frame, so 0.01 weighs 0.04).
RANK_THIN = 0.5
RANK_HD95 = 4.0
BOUNDARY_TOL_PX = 2.0  # the boundary F1 counts outline pixels within this distance of the other outline
# Parts of a target a shadow misses (or shadow it adds), as a person would name them: slivers
# along the outline are not parts (a part reaches PART_MIN_DEPTH_PX, or PART_DEPTH_SHARE of the
# frame height when that is more, from its edge: at least 3 px across), nor are pieces smaller
# than PART_MIN_SHARE of the target's area.
PART_MIN_DEPTH_PX = 2.0
PART_DEPTH_SHARE = 0.008
PART_MIN_SHARE = 0.01


@dataclasses.dataclass(frozen=True)
class FitScore:
    iou: float
    boundary_f1: float
    hd95: float
    thin_recall: float

    @property
    def success(self) -> bool:
        return self.iou >= SUCCESS_IOU and self.thin_recall >= SUCCESS_THIN and self.hd95 <= SUCCESS_HD95

    @property
    def near_miss(self) -> bool:
        """Fails the success test, but within reach of it: IoU and thin-part recall met and
        HD95 within 0.01 of its bar (a few fingertips or a notch away)."""
        return self.within(NEAR_MISS_HD95)

    def within(self, hd95_margin: float, thin_margin: float = 0.0) -> bool:
        """Fails the success test with IoU met, HD95 at most ``hd95_margin`` (a share of the
        frame height) past its bar and thin-part recall at most ``thin_margin`` short of
        its bar."""
        return (
            not self.success
            and self.iou >= SUCCESS_IOU
            and self.thin_recall >= SUCCESS_THIN - thin_margin
            and self.hd95 <= SUCCESS_HD95 + hd95_margin
        )

    def as_dict(self) -> dict:
        return {**dataclasses.asdict(self), "success": self.success}

    def __str__(self) -> str:
        """The measures a person reads: 'IoU 0.871, thin parts 0.94, HD95 0.033'."""
        return f"IoU {self.iou:.3f}, thin parts {self.thin_recall:.2f}, HD95 {self.hd95:.3f}"


def iou(shadow, target):
    """Intersection over union over the last two axes (H, W); leading batch axes broadcast.

    numpy arrays or torch tensors, binary masks or coverages in [0, 1] (for those the soft
    IoU sum(a b) / (sum a + sum b - sum(a b)), which is the IoU on binary masks). Two empty
    masks agree perfectly: 1. Returns a float for single masks, else an array or tensor of
    the batch shape."""
    if hasattr(shadow, "detach"):  # torch
        a = shadow.float() if not shadow.is_floating_point() else shadow
        b = target.to(a.dtype)
        inter = (a * b).sum((-2, -1))
        union = a.sum((-2, -1)) + b.sum((-2, -1)) - inter
        return _ratio_or_one(inter, union)
    a = np.asarray(shadow, np.float64)
    b = np.asarray(target, np.float64)
    inter = (a * b).sum((-2, -1))
    union = a.sum((-2, -1)) + b.sum((-2, -1)) - inter
    out = np.where(union > 0, inter / np.maximum(union, 1e-12), 1.0)
    return float(out) if out.ndim == 0 else out


def _ratio_or_one(inter, union):
    """inter / union for tensors, 1 where the union is empty."""
    return (inter / union.clamp(min=1e-12)).where(union > 0, union.new_ones(()))


def outline(mask: np.ndarray) -> np.ndarray:
    """Pixels of the mask with a 4-neighbour outside it (the frame border counts as outside)."""
    mask = np.asarray(mask, bool)
    return mask & ~ndimage.binary_erosion(mask, border_value=0)


def _distance_to(mask_outline: np.ndarray) -> np.ndarray:
    if not mask_outline.any():
        return np.full(mask_outline.shape, np.inf)
    return ndimage.distance_transform_edt(~mask_outline)


def boundary_f1(shadow: np.ndarray, target: np.ndarray, tol_px: float = BOUNDARY_TOL_PX) -> float:
    return _boundary_f1(_Outlines.of(shadow, target), tol_px)


def hd95(shadow: np.ndarray, target: np.ndarray) -> float:
    return _hd95(_Outlines.of(shadow, target), shadow.shape[0])


@dataclasses.dataclass(frozen=True)
class _Outlines:
    """Both outlines and, when both exist, each outline pixel's distance to the other outline
    (shadow_to_target over the shadow's outline pixels, target_to_shadow likewise): what the
    boundary F1 and the HD95 share, worked out once."""

    shadow: np.ndarray
    target: np.ndarray
    shadow_to_target: np.ndarray | None = None
    target_to_shadow: np.ndarray | None = None

    @staticmethod
    def of(shadow: np.ndarray, target: np.ndarray) -> _Outlines:
        a, b = outline(shadow), outline(target)
        if not a.any() or not b.any():
            return _Outlines(a, b)
        return _Outlines(a, b, _distance_to(b)[a], _distance_to(a)[b])


def _boundary_f1(o: _Outlines, tol_px: float) -> float:
    if o.shadow_to_target is None:
        return float(o.shadow.any() == o.target.any())
    precision = (o.shadow_to_target <= tol_px).mean()
    recall = (o.target_to_shadow <= tol_px).mean()
    return float(2 * precision * recall / (precision + recall)) if precision + recall else 0.0


def _hd95(o: _Outlines, height: int) -> float:
    if o.shadow_to_target is None:
        return 1.0 if o.shadow.any() != o.target.any() else 0.0
    d = np.concatenate([o.shadow_to_target, o.target_to_shadow])
    return float(np.percentile(d, 95) / height)


def far_outline(shadow: np.ndarray, target: np.ndarray, bar: float = SUCCESS_HD95) -> np.ndarray:
    """(H, W) bool: the outline pixels, the shadow's and the target's, farther than ``bar`` (a
    share of the frame height) from the other outline: the pixels above the HD95 bar, where
    a shadow fails it (a part missing or added, a hole filled, light leaking through). Empty
    when either outline is."""
    o = _Outlines.of(np.asarray(shadow, bool), np.asarray(target, bool))
    far = np.zeros(o.shadow.shape, bool)
    if o.shadow_to_target is None:
        return far
    limit = bar * shadow.shape[0]
    far[o.shadow] = o.shadow_to_target > limit
    far[o.target] |= o.target_to_shadow > limit
    return far


def far_regions(shadow: np.ndarray, target: np.ndarray, bar: float = SUCCESS_HD95) -> np.ndarray:
    """(H, W) bool: the connected regions of wrong pixels (shadow XOR target, 4-connected)
    that touch an outline pixel beyond ``bar`` (:func:`far_outline`; 4-neighbours):
    the whole filled notch or hole, missing part or spill that fails the HD95 bar, and none
    of the slivers along the outline that pass it."""
    shadow, target = np.asarray(shadow, bool), np.asarray(target, bool)
    far = far_outline(shadow, target, bar)
    if not far.any():
        return np.zeros(shadow.shape, bool)
    wrong = shadow ^ target
    labels, _ = ndimage.label(wrong)
    hit = np.unique(labels[ndimage.binary_dilation(far) & wrong])
    return np.isin(labels, hit[hit > 0])


def thin_parts(target: np.ndarray) -> np.ndarray:
    """What an opening with a disc of radius 4 % of the frame height removes from the target."""
    radius = max(1, int(round(THIN_RADIUS_SHARE * target.shape[0])))
    target = np.asarray(target, bool)
    return target & ~opening(target, disk(radius)).astype(bool)


def thin_recall(shadow: np.ndarray, target: np.ndarray, thin: np.ndarray | None = None) -> float:
    thin = thin_parts(target) if thin is None else thin
    return float((np.asarray(shadow, bool) & thin).sum() / thin.sum()) if thin.any() else 1.0


def score(shadow: np.ndarray, target: np.ndarray, thin: np.ndarray | None = None) -> FitScore:
    """All four measures; thin: the target's thin parts when already known (thin_parts)."""
    shadow, target = np.asarray(shadow, bool), np.asarray(target, bool)
    outlines = _Outlines.of(shadow, target)  # the boundary F1 and the HD95 share the distances
    return FitScore(
        iou(shadow, target),
        _boundary_f1(outlines, BOUNDARY_TOL_PX),
        _hd95(outlines, shadow.shape[0]),
        thin_recall(shadow, target, thin),
    )


def rank_key(s: FitScore) -> tuple:
    """Sort key, smaller is better: successes first, then a blend of the measures
    (RANK_THIN, RANK_HD95)."""
    return (not s.success, -(s.iou + RANK_THIN * s.thin_recall - RANK_HD95 * s.hd95))


@dataclasses.dataclass(frozen=True)
class ViewScores:
    """One pose's measures in every view (view 0 first) and the views' weights (summing to 1).

    A success when every view is one; a near miss when it is not but every view is a success
    or a near miss. :meth:`key` ranks: the weighted share of failed views first, then the
    weighted sum of the views' blends (with one view exactly :func:`rank_key`)."""

    scores: tuple[FitScore, ...]
    weights: tuple[float, ...]

    @property
    def success(self) -> bool:
        return all(s.success for s in self.scores)

    @property
    def near_miss(self) -> bool:
        return self.within(NEAR_MISS_HD95)

    def within(self, hd95_margin: float, thin_margin: float = 0.0) -> bool:
        """Fails, and every view is a success or within the margins of it (FitScore.within)."""
        return not self.success and all(s.success or s.within(hd95_margin, thin_margin) for s in self.scores)

    def key(self) -> tuple:
        if len(self.scores) == 1:
            return rank_key(self.scores[0])
        keys = [rank_key(s) for s in self.scores]
        failed = sum(w * k[0] for w, k in zip(self.weights, keys))
        return (failed, sum(w * k[1] for w, k in zip(self.weights, keys)))

    def __str__(self) -> str:
        if len(self.scores) == 1:
            return str(self.scores[0])
        return "; ".join(f"view {k}: {s}" for k, s in enumerate(self.scores))


@dataclasses.dataclass(frozen=True)
class Part:
    """A piece of the target the shadow misses (or of shadow outside the target): its area
    as a share of the target's, its centre (x, y) as shares of the frame's width and height
    from the top-left corner, and whether it is mostly the target's thin parts (an ear, a
    beak, a finger)."""

    share: float
    centre: tuple[float, float]
    thin: bool


def uncovered_parts(
    shape: np.ndarray, cover: np.ndarray, target: np.ndarray, thin: np.ndarray | None = None
) -> list[Part]:
    """The pieces of ``shape`` (H, W) bool that ``cover`` (H, W) bool leaves bare, largest
    first: target parts a shadow misses (shape = target, cover = shadow) or extra shadow
    (shape = shadow, cover = target). Slivers and crumbs are left out (PART_MIN_DEPTH_PX,
    PART_DEPTH_SHARE, PART_MIN_SHARE); shares are of the target's area; thin: the target's
    thin parts."""
    shape, cover, target = (np.asarray(a, bool) for a in (shape, cover, target))
    h, w = shape.shape
    thin = thin_parts(target) if thin is None else thin
    bare = shape & ~cover
    depth = ndimage.distance_transform_edt(bare)
    labels, n = ndimage.label(bare)
    area = max(int(target.sum()), 1)
    min_depth = max(PART_MIN_DEPTH_PX, PART_DEPTH_SHARE * h)
    parts = []
    for k in range(1, n + 1):
        piece = labels == k
        size = int(piece.sum())
        if size < PART_MIN_SHARE * area or depth[piece].max() < min_depth:
            continue

        ys, xs = np.nonzero(piece)
        on_thin = int((piece & thin).sum())
        parts.append(Part(size / area, ((xs.mean() + 0.5) / w, (ys.mean() + 0.5) / h), on_thin >= 0.5 * size))
    return sorted(parts, key=lambda p: -p.share)


def rank(shadows: np.ndarray, target: np.ndarray, thin: np.ndarray | None = None) -> list[int]:
    """Indices of shadows (B, H, W) bool, best first by :func:`rank_key` against the target."""
    thin = thin_parts(target) if thin is None else thin
    keys = [rank_key(score(m, target, thin)) for m in shadows]
    return sorted(range(len(keys)), key=keys.__getitem__)
