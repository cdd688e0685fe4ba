"""Products of images with banded matrices along one image axis.

A blur of a few pixels or a box count (a morphological window) is an (n, n) matrix that is
zero beyond ``radius`` of its diagonal. At the fine stages' 256 px most of a dense product
multiplies those zeros, so a large frame is cut into blocks. Along the rows the matrix is
block-tridiagonal in blocks of ``BLOCK`` (or ``radius``, if larger) pixels: three batched
products of each block of rows with a block of the matrix, added in place, read the image as
it lies (1.5 to 4 times faster here than the windows below). Along the columns each block of
``BLOCK`` columns is multiplied with the window of 2 radius + BLOCK pixels it reads. Either
way the same sums, about a tenth of the arithmetic of the dense product, forward and backward.
A small frame keeps the dense product, which is faster there.

    band = BandedMatrix.of(matrix, radius)
    band.rows(x)   # (B, n, m): matrix @ x
    band.cols(x)   # (B, m, n): x @ matrix.T
"""

from __future__ import annotations

import dataclasses
import math

import torch
import torch.nn.functional as F

BLOCK = 16  # rows (or columns) per block
# Blockwise from this many pixels along the axis, while the window stays within an eighth of it:
# at 128 px and below the dense product was as fast or faster (this 2-core CPU, one thread).
BLOCKED_FROM_PX = 256


@dataclasses.dataclass(frozen=True)
class BandedMatrix:
    """An (n, n) matrix that is zero beyond ``radius`` of its diagonal.

    dense: (n, n); blocks: (N, BLOCK, BLOCK + 2 radius), block k holding rows k BLOCK onward
    and the columns from k BLOCK - radius on (zero outside the matrix), or None where the
    dense product is used; tridiagonal: (3, N', s, s) with s = max(BLOCK, radius), the blocks
    below, on and above the diagonal of the matrix cut into s x s blocks (zero outside it);
    blocks_t, tridiagonal_t: the same of the transpose (for the gradient)."""

    dense: torch.Tensor
    radius: int
    blocks: torch.Tensor | None
    blocks_t: torch.Tensor | None
    tridiagonal: torch.Tensor | None = None
    tridiagonal_t: torch.Tensor | None = None

    @staticmethod
    def of(dense: torch.Tensor, radius: int) -> BandedMatrix:
        """The banded form of ``dense`` (n, n), whose entries beyond ``radius`` of the diagonal
        must be zero."""
        n = dense.shape[0]
        if n < BLOCKED_FROM_PX or 2 * radius + 1 > n // 8:
            return BandedMatrix(dense, radius, None, None)
        dense_t = dense.T.contiguous()
        size = max(BLOCK, radius)
        return BandedMatrix(
            dense,
            radius,
            _blocks(dense, radius),
            _blocks(dense_t, radius),
            _tridiagonal(dense, size),
            _tridiagonal(dense_t, size),
        )

    def rows(self, x: torch.Tensor) -> torch.Tensor:
        """matrix @ x for x (B, n, m) -> (B, n, m)."""
        if self.blocks is None:
            return self.dense @ x
        return _Banded.apply(x, self.tridiagonal, self.tridiagonal_t, self.radius, rows_product)

    def cols(self, x: torch.Tensor) -> torch.Tensor:
        """x @ matrix.T for x (B, m, n) -> (B, m, n)."""
        if self.blocks is None:
            return x @ self.dense.T
        return _Banded.apply(x, self.blocks, self.blocks_t, self.radius, cols_product)


def _blocks(dense: torch.Tensor, radius: int) -> torch.Tensor:
    n = dense.shape[0]
    count = math.ceil(n / BLOCK)
    padded = dense.new_zeros(count * BLOCK, count * BLOCK + 2 * radius)
    padded[:n, radius : radius + n] = dense
    width = BLOCK + 2 * radius
    return torch.stack([padded[k * BLOCK : (k + 1) * BLOCK, k * BLOCK : k * BLOCK + width] for k in range(count)])


def _tridiagonal(dense: torch.Tensor, size: int) -> torch.Tensor:
    """(3, N, size, size): the blocks of ``dense`` (n, n) below, on and above its diagonal, cut
    into size x size blocks (zero padded to N size), for a band no wider than ``size``."""
    n = dense.shape[0]
    count = math.ceil(n / size)
    padded = dense.new_zeros((count + 2) * size, (count + 2) * size)  # a zero block all round
    padded[size : size + n, size : size + n] = dense
    blocks = [
        [padded[(k + 1) * size : (k + 2) * size, (k + 1 + d) * size : (k + 2 + d) * size] for k in range(count)]
        for d in (-1, 0, 1)
    ]
    return torch.stack([torch.stack(row) for row in blocks])


def rows_product(tridiagonal: torch.Tensor, radius: int, x: torch.Tensor) -> torch.Tensor:
    """Blockwise matrix @ x along dim 1: tridiagonal (3, N, s, s) (BandedMatrix), x (B, n, m)
    -> (B, n, m). The image's rows, cut into N blocks of s, are each multiplied with the three
    blocks of the matrix that read them; the first block's lower and the last one's upper
    block are zero, so the blocks of one image never reach into the next."""
    _, count, size, _ = tridiagonal.shape
    batch, n, m = x.shape
    if n != count * size:
        x = F.pad(x, (0, 0, 0, count * size - n))
    rows = x.reshape(batch * count, size, m)
    lower, diagonal, upper = (t.repeat(batch, 1, 1) for t in tridiagonal)
    out = torch.bmm(diagonal, rows)
    out[1:].baddbmm_(lower[1:], rows[:-1])
    out[:-1].baddbmm_(upper[:-1], rows[1:])
    return out.view(batch, count * size, m)[:, :n]


def cols_product(blocks: torch.Tensor, radius: int, x: torch.Tensor) -> torch.Tensor:
    """Blockwise x @ matrix.T along dim 2: blocks (N, b, b + 2 radius), x (B, m, n) -> (B, m, n)."""
    count, b, width = blocks.shape
    batch, m, n = x.shape
    windows = F.pad(x, (radius, count * b - n + radius)).unfold(2, width, b).transpose(1, 2)  # (B, N, m, width)
    out = windows @ blocks.transpose(-1, -2)  # (B, N, m, b)
    return out.transpose(1, 2).reshape(batch, m, count * b)[:, :, :n]


class _Banded(torch.autograd.Function):
    # y = M x (rows) or x M^T (cols), so dL/dx is the same product with M^T: the transpose's
    # blocks, the same way round.
    @staticmethod
    def forward(ctx, x, blocks, blocks_t, radius, product):
        ctx.save_for_backward(blocks_t)
        ctx.radius, ctx.product = radius, product
        return product(blocks, radius, x.contiguous())

    @staticmethod
    def backward(ctx, grad):
        (blocks_t,) = ctx.saved_tensors
        return ctx.product(blocks_t, ctx.radius, grad.contiguous()), None, None, None, None
