"""Products of images with banded matrices along one image axis.

A blur of a few pixels or a box count (a morphological window) is an (n, n) matrix that is
zero beyond ``radius`` of its diagonal. At the fine stages' 256 px most of a dense product
multiplies those zeros, so a large frame is cut into blocks of ``BLOCK`` rows (or columns),
each multiplied with the window of 2 radius + BLOCK pixels it reads: the same sums, about a
tenth of the arithmetic (2 to 2.5 times faster here, forward and backward). A small frame
keeps the dense product, which is faster there.

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
    dense product is used; blocks_t: the same of the transpose (for the gradient)."""

    dense: torch.Tensor
    radius: int
    blocks: torch.Tensor | None
    blocks_t: torch.Tensor | None

    @staticmethod
    def of(dense: torch.Tensor, radius: int) -> BandedMatrix:
        """The banded form of ``dense`` (n, n), whose entries beyond ``radius`` of the diagonal
        must be zero."""
        n = dense.shape[0]
        if n < BLOCKED_FROM_PX or 2 * radius + 1 > n // 8:
            return BandedMatrix(dense, radius, None, None)
        return BandedMatrix(dense, radius, _blocks(dense, radius), _blocks(dense.T.contiguous(), radius))

    def rows(self, x: torch.Tensor) -> torch.Tensor:
        """matrix @ x for x (B, n, m) -> (B, n, m)."""
        if self.blocks is None:
            return self.dense @ x
        return _Banded.apply(x, self.blocks, self.blocks_t, self.radius, rows_product)

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


def rows_product(blocks: torch.Tensor, radius: int, x: torch.Tensor) -> torch.Tensor:
    """Blockwise matrix @ x along dim 1: blocks (N, b, b + 2 radius), x (B, n, m) -> (B, n, m)."""
    count, b, width = blocks.shape
    batch, n, m = x.shape
    windows = F.pad(x, (0, 0, radius, count * b - n + radius)).unfold(1, width, b)  # (B, N, m, width)
    out = windows @ blocks.transpose(-1, -2)  # (B, N, m, b)
    return out.transpose(-1, -2).reshape(batch, count * b, m)[:, :n]


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
        return product(blocks, radius, x)

    @staticmethod
    def backward(ctx, grad):
        (blocks_t,) = ctx.saved_tensors
        return ctx.product(blocks_t, ctx.radius, grad.contiguous()), None, None, None, None
