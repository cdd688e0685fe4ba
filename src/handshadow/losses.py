"""Loss terms as pure functions on batched tensors. Each returns (B,) per hypothesis.

Silhouette terms compare a shadow (B, H, W) in [0, 1] with target maps prepared once per
resolution (:class:`TargetMaps`). Penalties keep the hands physical: inside the joint limits
(by construction of the parameters, see search.py), not penetrating, between light and wall.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import torch
from scipy import ndimage
from skimage.morphology import disk

from handshadow.metrics import thin_parts
from handshadow.render.banded import BandedMatrix
from handshadow.render.soft import gaussian_blur


@dataclasses.dataclass(frozen=True)
class TargetMaps:
    """Per-resolution maps of the target, (H, W) tensors unless noted.

    target: binary target; thin: its thin parts (what an opening of radius 4 % of the height
    removes); outside_dist: distance to the target outside it, in frame heights (0 inside);
    inside_depth: distance to the target's outline inside it, in frame heights (0 outside);
    outside_dist_wide: (3H, 3W) the same over a canvas three frames wide, centred on the frame,
    for points whose shadow falls outside the frame; thin_points: (N, 2) pixel coordinates
    (x, y) of up to 256 thin-part pixels (evenly picked); notches: in [0, 1], the target's
    holes and the narrow notches of its outline (see :func:`notches`).
    """

    target: torch.Tensor
    thin: torch.Tensor
    outside_dist: torch.Tensor
    inside_depth: torch.Tensor
    outside_dist_wide: torch.Tensor
    thin_points: torch.Tensor
    notches: torch.Tensor

    @staticmethod
    def build(target: np.ndarray, device="cpu", dtype=torch.float32) -> TargetMaps:
        target = np.asarray(target, bool)
        h, w = target.shape
        t = dict(device=device, dtype=dtype)
        wide = np.zeros((3 * h, 3 * w), bool)
        wide[h : 2 * h, w : 2 * w] = target
        thin = thin_parts(target)
        ys, xs = np.nonzero(thin)
        pick = np.linspace(0, len(xs) - 1, min(256, len(xs))).astype(int) if len(xs) else np.zeros(0, int)
        return TargetMaps(
            target=torch.as_tensor(target, **t),
            thin=torch.as_tensor(thin, **t),
            outside_dist=torch.as_tensor(ndimage.distance_transform_edt(~target) / h, **t),
            inside_depth=torch.as_tensor(ndimage.distance_transform_edt(target) / h, **t),
            outside_dist_wide=torch.as_tensor(ndimage.distance_transform_edt(~wide) / h, **t),
            thin_points=torch.as_tensor(np.stack([xs[pick] + 0.5, ys[pick] + 0.5], 1), **t),
            notches=torch.as_tensor(notches(target), **t),
        )


NOTCH_RADII_SHARE = (0.012, 0.025, 0.04)
# placement() is a mean over every vertex, most of them in range: this gain keeps its unit
# (1 cm out on every vertex costs 10) in the range of the other terms' weights.
PLACEMENT_GAIN = 10.0


def notches(target: np.ndarray) -> np.ndarray:
    """Where the shadow must let light through although the target is close by: the target's
    holes (weight 1) and the narrow notches of its outline, graded by narrowness (the share of
    closings with discs of radius 1.2, 2.5 and 4 % of the frame height that fill the pixel).
    A shadow that fills the gap between two legs or the hole of a letter barely moves the image
    term, yet it puts the gap's whole outline far from the shadow's (HD95), and a viewer sees
    it first.

    target (H, W) bool -> (H, W) float in [0, 1], 0 on the target."""
    target = np.asarray(target, bool)
    h = target.shape[0]
    graded = np.zeros(target.shape)
    for share in NOTCH_RADII_SHARE:
        r = max(1, int(round(share * h)))
        closed = ndimage.binary_closing(np.pad(target, r + 1), disk(r))[r + 1 : -(r + 1), r + 1 : -(r + 1)]
        graded += closed & ~target
    holes = ndimage.binary_fill_holes(target) & ~target
    return np.maximum(graded / len(NOTCH_RADII_SHARE), holes)


def silhouette_l2(shadow: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The paper's image term: mean squared difference per pixel. (B, H, W), (H, W) -> (B,)."""
    return ((shadow - target) ** 2).mean((1, 2))


def weighted_l2(shadow: torch.Tensor, target: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Mean of weight * (shadow - target)^2. weight (H, W) >= 0. -> (B,)."""
    return (weight * (shadow - target) ** 2).mean((1, 2))


def excess(shadow: torch.Tensor, outside_dist: torch.Tensor) -> torch.Tensor:
    """Shadow outside the target, weighted by its distance to the target (frame heights): far
    spills pull back harder. -> (B,)."""
    return (shadow * outside_dist).mean((1, 2))


def attraction(shadow: torch.Tensor, target: torch.Tensor, sigma_px: float) -> torch.Tensor:
    """Minus the overlap of the shadow with the target's still uncovered parts, blurred by
    sigma_px: the outline is drawn toward missing parts (ears, beaks) that may lie several
    pixels away. The uncovered map is a constant of this step. -> (B,)."""
    with torch.no_grad():
        missing = target * (1 - (shadow > 0.5).to(shadow.dtype))
        field = gaussian_blur(missing, sigma_px)
        field = field / field.amax((1, 2), keepdim=True).clamp(min=1e-6)
    return -(shadow * field).mean((1, 2))


def gaps(shadow: torch.Tensor, target: torch.Tensor, radius_px: int) -> torch.Tensor:
    """Light leaking through the shadow where the target is solid: the pinholes, slits and narrow notches
    between fingers that a closing (square, radius_px) of the shadow would fill. Their outlines
    are few pixels for the image term but far from the target's outline (HD95) and plain to
    see. The leak map is a constant of this step. (B, H, W), (H, W) -> (B,)."""
    with torch.no_grad():
        m = (shadow > 0.5).to(shadow.dtype)
        leaks = (square_closing(m, radius_px) - m).clamp(min=0) * target
    return (leaks * (1 - shadow)).mean((1, 2))


def square_closing(masks: torch.Tensor, radius_px: int) -> torch.Tensor:
    """Morphological closing of binary masks (B, H, W) (0 or 1) with a square of side
    2 radius_px + 1, windows cut at the frame's border (a max pool padded with -inf, then a
    min pool likewise). Each pass counts the ones in every window with two products of banded
    0/1 matrices (blockwise on large frames, render.banded): exact (small integers), and on a
    CPU a fraction of a stride-1 max pool's cost. -> (B, H, W) 0 or 1."""
    _, height, width = masks.shape
    rows = _band(height, radius_px, masks.dtype, str(masks.device))
    cols = _band(width, radius_px, masks.dtype, str(masks.device))
    dilated = (cols.cols(rows.rows(masks)) > 0).to(masks.dtype)
    window = rows.dense.sum(1)[:, None] * cols.dense.sum(0)[None]  # pixels each window holds inside the frame
    return (cols.cols(rows.rows(dilated)) == window).to(masks.dtype)


@functools.lru_cache(maxsize=16)
def _band(n: int, radius: int, dtype, device: str) -> BandedMatrix:
    """(n, n) 0/1 matrix, 1 where |i - j| <= radius (symmetric), in banded form."""
    i = torch.arange(n)
    return BandedMatrix.of(((i[:, None] - i[None]).abs() <= radius).to(dtype=dtype, device=device), radius)


def penetration(
    depths_m: torch.Tensor, scale_m: float = 0.01, item: torch.Tensor | None = None, batch: int = 0
) -> torch.Tensor:
    """Sum of squared penetration depths in units of scale_m per hypothesis. depths (B, P)
    metres -> (B,); or, given ``item``, the depths (K,) of K pairs and the hypothesis each
    belongs to (K,), of a batch of ``batch`` -> (batch,) (the pairs left out count 0)."""
    if item is None:
        return ((depths_m / scale_m) ** 2).sum(1)
    return depths_m.new_zeros(batch).index_add(0, item, (depths_m / scale_m) ** 2)


def placement(heights_m: torch.Tensor, lo_m: float, hi_m: float, scale_m: float = 0.01) -> torch.Tensor:
    """Vertices must lie between lo and hi metres in front of the wall (between light and
    wall, off both). heights (B, V) -> (B,) squared overshoot in units of scale_m."""
    below = torch.relu(lo_m - heights_m)
    above = torch.relu(heights_m - hi_m)
    return (((below + above) / scale_m) ** 2).mean(1) * PLACEMENT_GAIN


def inside_frame(points_xy: torch.Tensor, height: int, width: int, margin_px: float = 0.0) -> torch.Tensor:
    """Points that must stay out of the picture (an elbow: the upper arm beyond it would cast
    a shadow we do not model): the squared distance (frame heights) each still has to go to
    leave the frame grown by margin_px, summed over points. points_xy (B, P, 2) pixels -> (B,)."""
    x, y = points_xy[..., 0], points_xy[..., 1]
    to_leave = torch.minimum(torch.minimum(x, width - x), torch.minimum(y, height - y)) + margin_px
    return ((torch.relu(to_leave) / height) ** 2).sum(-1)


def soft_range(value: torch.Tensor, lo: float, hi: float, scale: float) -> torch.Tensor:
    """Squared overshoot of value (B,) outside [lo, hi], in units of scale. -> (B,)."""
    return ((torch.relu(lo - value) + torch.relu(value - hi)) / scale) ** 2


def points_outside(points_xy: torch.Tensor, maps: TargetMaps) -> torch.Tensor:
    """Mean squared distance (frame heights) to the target of projected points, e.g. the hands'
    joints and forearm axes: a long-range pull of whole fingers and forearms into the target,
    which the outline alone cannot give (a forearm leaving the frame has no outline there).

    points_xy (B, P, 2) pixel coordinates -> (B,)."""
    h, w = maps.target.shape
    field = maps.outside_dist_wide[None, None]
    # Canvas coordinates: the frame sits in the middle third; grid_sample wants [-1, 1].
    gx = (points_xy[..., 0] + w) / (3 * w) * 2 - 1
    gy = (points_xy[..., 1] + h) / (3 * h) * 2 - 1
    grid = torch.stack([gx, gy], -1)[:, None]  # (B, 1, P, 2)
    d = torch.nn.functional.grid_sample(
        field.expand(points_xy.shape[0], -1, -1, -1), grid, align_corners=False, padding_mode="border"
    )
    return (d[:, 0, 0] ** 2).mean(1)


def thin_coverage(segments_xy: torch.Tensor, maps: TargetMaps) -> torch.Tensor:
    """Mean squared distance (frame heights) from the target's thin parts to the nearest
    projected finger segment: fingers are drawn to ears, beaks and antlers wherever they are.

    segments_xy (B, S, 2, 2) pixel coordinates of segment ends -> (B,); 0 without thin parts."""
    pts = maps.thin_points
    if pts.shape[0] == 0:
        return segments_xy.new_zeros(segments_xy.shape[0])
    # x and y apart, and squared distances throughout: no (B, N, S, 2) tensors, no root.
    ax, ay = segments_xy[:, None, :, 0, 0], segments_xy[:, None, :, 0, 1]  # (B, 1, S)
    abx, aby = segments_xy[:, None, :, 1, 0] - ax, segments_xy[:, None, :, 1, 1] - ay
    px, py = pts[None, :, 0, None] - ax, pts[None, :, 1, None] - ay  # (B, N, S): from a
    t = ((px * abx + py * aby) / (abx * abx + aby * aby).clamp(min=1e-9)).clamp(0, 1)
    dx, dy = px - t * abx, py - t * aby
    nearest = (dx * dx + dy * dy).amin(2)  # (B, N) squared pixels
    return (nearest / maps.target.shape[0] ** 2).mean(1)
