"""A soft, wide shadow for coarse optimisation stages: the exact shadow blurred by a Gaussian.

Blurring is linear, so the gradient still comes from the exact outline (edge sampling) and only
spreads its reach: a target several pixels away pulls on the outline. Blur the target the same
way and compare the two; shrink sigma to zero as the fit converges.
"""

from __future__ import annotations

import functools
import math

import torch

from handshadow.render.banded import BandedMatrix


def gaussian_blur(images: torch.Tensor, sigma_px: float) -> torch.Tensor:
    """Separable Gaussian blur.

    Args:
        images: (B, H, W).
        sigma_px: standard deviation in pixels; <= 0 returns the input unchanged.
    Returns:
        (B, H, W), borders extended by replication (a forearm that leaves the frame stays dark).

    Each pass is a product with a banded (N, N) blur matrix (blur_matrix), blockwise on large
    frames (render.banded): on a CPU a matrix product and its gradient cost a fraction of a
    one-channel convolution's.
    """
    if sigma_px <= 0:
        return images
    _, height, width = images.shape
    rows = _banded_blur(height, float(sigma_px), images.dtype, str(images.device))
    cols = _banded_blur(width, float(sigma_px), images.dtype, str(images.device))
    return cols.cols(rows.rows(images))


def blur_radius(sigma_px: float) -> int:
    """Taps of a blur on each side of its centre: within 3 sigma, at least one."""
    return max(1, int(math.ceil(3 * sigma_px)))


@functools.lru_cache(maxsize=64)
def _banded_blur(n: int, sigma_px: float, dtype, device: str) -> BandedMatrix:
    return BandedMatrix.of(blur_matrix(n, sigma_px, dtype, device), blur_radius(sigma_px))


def blur_matrix(n: int, sigma_px: float, dtype=torch.float32, device="cpu") -> torch.Tensor:
    """(n, n) matrix of a 1D Gaussian blur over n pixels, borders extended by replication:
    row i holds the weights of the pixels that blur into pixel i (taps within 3 sigma)."""
    return _blur_matrix(n, float(sigma_px), dtype, str(device))


@functools.lru_cache(maxsize=64)
def _blur_matrix(n: int, sigma_px: float, dtype, device: str) -> torch.Tensor:
    radius = blur_radius(sigma_px)
    taps = torch.arange(-radius, radius + 1, dtype=torch.float64)
    kernel = torch.exp(-0.5 * (taps / sigma_px) ** 2)
    kernel = kernel / kernel.sum()
    rows = torch.arange(n)[:, None].expand(n, len(taps))
    source = (rows + taps.long()[None]).clamp(0, n - 1)  # replicated borders
    matrix = torch.zeros(n, n, dtype=torch.float64).index_put_((rows, source), kernel.expand(n, -1), accumulate=True)
    return matrix.to(dtype=dtype, device=device)
