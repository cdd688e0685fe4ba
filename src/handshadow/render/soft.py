"""A soft, wide shadow for coarse optimisation stages: the exact shadow blurred by a Gaussian.

Blurring is linear, so the gradient still comes from the exact outline (edge sampling) and only
spreads its reach: a target several pixels away pulls on the outline. Blur the target the same
way and compare the two; shrink sigma to zero as the fit converges.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F


def gaussian_blur(images: torch.Tensor, sigma_px: float) -> torch.Tensor:
    """Separable Gaussian blur.

    Args:
        images: (B, H, W).
        sigma_px: standard deviation in pixels; <= 0 returns the input unchanged.
    Returns:
        (B, H, W), borders extended by replication (a forearm that leaves the frame stays dark).
    """
    if sigma_px <= 0:
        return images
    radius = max(1, int(math.ceil(3 * sigma_px)))
    x = torch.arange(-radius, radius + 1, dtype=images.dtype, device=images.device)
    kernel = torch.exp(-0.5 * (x / sigma_px) ** 2)
    kernel = kernel / kernel.sum()
    out = images[:, None]
    out = F.conv2d(F.pad(out, (radius, radius, 0, 0), mode="replicate"), kernel.view(1, 1, 1, -1))
    out = F.conv2d(F.pad(out, (0, 0, radius, radius), mode="replicate"), kernel.view(1, 1, -1, 1))
    return out[:, 0]
