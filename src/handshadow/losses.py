"""Loss terms as pure functions on batched tensors. Each returns (B,) per hypothesis.

Silhouette terms compare a shadow (B, H, W) in [0, 1] with target maps prepared once per
resolution (:class:`TargetMaps`). Penalties keep the hands physical: inside the joint limits
(by construction of the parameters, see search.py), not penetrating, between light and wall.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from scipy import ndimage

from handshadow.metrics import thin_parts
from handshadow.render.soft import gaussian_blur


@dataclasses.dataclass(frozen=True)
class TargetMaps:
    """Per-resolution maps of the target, (H, W) tensors.

    target: binary target; thin: its thin parts (what an opening of radius 4 % of the height
    removes); outside_dist: distance to the target outside it, in frame heights (0 inside).
    """

    target: torch.Tensor
    thin: torch.Tensor
    outside_dist: torch.Tensor

    @staticmethod
    def build(target: np.ndarray, device="cpu", dtype=torch.float32) -> TargetMaps:
        target = np.asarray(target, bool)
        h = target.shape[0]
        t = dict(device=device, dtype=dtype)
        return TargetMaps(
            target=torch.as_tensor(target, **t),
            thin=torch.as_tensor(thin_parts(target), **t),
            outside_dist=torch.as_tensor(ndimage.distance_transform_edt(~target) / h, **t),
        )


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


def penetration(depths_m: torch.Tensor, scale_m: float = 0.01) -> torch.Tensor:
    """Sum of squared penetration depths in units of scale_m. depths (B, P) metres -> (B,)."""
    return ((depths_m / scale_m) ** 2).sum(1)


def placement(heights_m: torch.Tensor, lo_m: float, hi_m: float, scale_m: float = 0.01) -> torch.Tensor:
    """Vertices must lie between lo and hi metres in front of the wall (between light and
    wall, off both). heights (B, V) -> (B,) squared overshoot in units of scale_m."""
    below = torch.relu(lo_m - heights_m)
    above = torch.relu(heights_m - hi_m)
    return (((below + above) / scale_m) ** 2).mean(1) * 10


def soft_range(value: torch.Tensor, lo: float, hi: float, scale: float) -> torch.Tensor:
    """Squared overshoot of value (B,) outside [lo, hi], in units of scale. -> (B,)."""
    return ((torch.relu(lo - value) + torch.relu(value - hi)) / scale) ** 2
