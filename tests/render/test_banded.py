"""Blockwise products with banded matrices (render.banded) equal the dense products, forward
and backward, on frames large enough to take the blocks."""

import torch

from handshadow.render.banded import BLOCK, BandedMatrix
from handshadow.render.soft import blur_matrix, blur_radius, gaussian_blur


def _box(n: int, radius: int) -> torch.Tensor:
    i = torch.arange(n)
    return ((i[:, None] - i[None]).abs() <= radius).double()


def test_blockwise_products_equal_the_dense_ones_and_their_gradients():
    gen = torch.Generator().manual_seed(5)
    # Sizes a multiple of the block and not; a replicated-border blur (not symmetric at the
    # ends) and a box count; radii from 1 to 12 pixels, and one wider than a block (the rows'
    # blocks then as wide as the band).
    for n, matrix, radius in (
        (256, blur_matrix(256, 1.0, torch.float64), blur_radius(1.0)),
        (300, blur_matrix(300, 4.0, torch.float64), blur_radius(4.0)),
        (257, _box(257, 2), 2),
        (410, _box(410, 21), 21),
    ):
        band = BandedMatrix.of(matrix, radius)
        assert band.blocks is not None and band.blocks.shape[1] == BLOCK
        assert band.tridiagonal.shape[2] == max(BLOCK, radius)
        x = torch.rand(3, n, 70, dtype=torch.float64, generator=gen, requires_grad=True)
        g = torch.rand(3, n, 70, dtype=torch.float64, generator=gen)
        for product, dense in (
            (band.rows(x), matrix @ x),
            (band.cols(x.transpose(1, 2)), x.transpose(1, 2) @ matrix.T),
        ):
            g_here = g if product.shape == g.shape else g.transpose(1, 2)
            assert torch.allclose(product, dense, rtol=0, atol=1e-12)
            (grad,) = torch.autograd.grad((product * g_here).sum(), x)
            (expected,) = torch.autograd.grad((dense * g_here).sum(), x)
            assert torch.allclose(grad, expected, rtol=0, atol=1e-12)


def test_small_frames_and_wide_bands_keep_the_dense_product():
    assert BandedMatrix.of(blur_matrix(128, 1.0), blur_radius(1.0)).blocks is None
    assert BandedMatrix.of(blur_matrix(256, 8.0), blur_radius(8.0)).blocks is None  # 49 taps > 256 / 8


def test_blur_of_a_large_frame_is_the_dense_blur():
    x = torch.rand(2, 256, 320, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    for sigma in (1.0, 2.5):
        dense = blur_matrix(256, sigma, torch.float64) @ x @ blur_matrix(320, sigma, torch.float64).T
        assert torch.allclose(gaussian_blur(x, sigma), dense, rtol=0, atol=1e-12)
