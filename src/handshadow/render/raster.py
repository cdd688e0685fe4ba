"""Exact scanline rasterisation of 2D triangles at pixel centres, in pure PyTorch.

A pixel (row i, column j) is covered by a triangle when its centre (j + 0.5, i + 0.5) lies in
the closed triangle. Each triangle is cut into row spans: for every pixel row whose centre line
crosses it, the run of columns whose centres fall inside. Spans turn into a coverage mask with a
difference buffer and a cumulative sum (no per-pixel loop), or into per-pixel fragments for a
depth buffer. All of it is batched and runs unchanged on CUDA.
"""

from __future__ import annotations

import dataclasses

import torch


@dataclasses.dataclass(frozen=True)
class Spans:
    """Row spans of triangles; N spans, each a run of covered pixels in one row.

    batch, face, row: (N,) long; col_start, col_end: (N,) long, columns [start, end) covered.
    """

    batch: torch.Tensor
    face: torch.Tensor
    row: torch.Tensor
    col_start: torch.Tensor
    col_end: torch.Tensor


def rasterize_spans(tri_xy: torch.Tensor, height: int, width: int, keep: torch.Tensor | None = None) -> Spans:
    """Spans of every triangle within an H x W image.

    Args:
        tri_xy: (B, F, 3, 2) triangle corners in continuous pixel coordinates (column, row);
            must be finite. Degenerate and off-image triangles simply produce no spans.
        height, width: image size in pixels.
        keep: optional (B, F) bool, the triangles to rasterise (others are skipped).
    Returns:
        Spans, clipped to the image.
    """
    n_faces = tri_xy.shape[1]
    tri = tri_xy.detach().reshape(-1, 6)  # x0 y0 x1 y1 x2 y2
    index = None
    if keep is not None:
        index = torch.nonzero(keep.reshape(-1), as_tuple=True)[0]
        tri = tri.index_select(0, index)
    x, y = tri[:, 0::2], tri[:, 1::2]
    # Rows whose centre line y = i + 0.5 meets the triangle: ceil(ymin - .5) .. floor(ymax - .5).
    ymin, ymax = torch.aminmax(y, dim=1)
    row_lo = torch.ceil(ymin - 0.5).clamp_(min=0)
    row_hi = torch.floor(ymax - 0.5).clamp_(max=height - 1)
    count = (row_hi - row_lo + 1).clamp_(min=0).long()
    # Per edge (0-1, 1-2, 2-0): start x, start y, slope dx/dy, and its y extent; horizontal
    # edges get an empty extent (the two other edges give the span's ends).
    xb, yb = x.roll(-1, 1), y.roll(-1, 1)
    flat = y == yb
    slope = (xb - x) / torch.where(flat, torch.ones_like(y), yb - y)
    lo = torch.where(flat, torch.full_like(y, float("inf")), torch.minimum(y, yb))
    table = torch.cat([x, y, slope, lo, torch.maximum(y, yb), row_lo[:, None]], dim=1)  # (T, 16)

    tri_index = torch.repeat_interleave(torch.arange(tri.shape[0], device=tri.device), count)
    first = torch.cumsum(count, 0) - count
    step = torch.arange(tri_index.shape[0], device=tri.device) - first.index_select(0, tri_index)
    t = table.index_select(0, tri_index)  # (N, 16)
    row = t[:, 15] + step.to(t.dtype)
    yc = (row + 0.5)[:, None]
    crosses = (t[:, 9:12] <= yc) & (yc <= t[:, 12:15])
    xc = t[:, 0:3] + (yc - t[:, 3:6]) * t[:, 6:9]
    x_left = torch.where(crosses, xc, float("inf")).amin(1)
    x_right = torch.where(crosses, xc, float("-inf")).amax(1)
    col_start = torch.ceil(x_left - 0.5).clamp_(min=0)
    col_end = (torch.floor(x_right - 0.5) + 1).clamp_(max=width)
    nonempty = col_start < col_end
    tri_index = tri_index[nonempty]
    if index is not None:
        tri_index = index.index_select(0, tri_index)
    return Spans(
        batch=torch.div(tri_index, n_faces, rounding_mode="floor"),
        face=tri_index % n_faces,
        row=row[nonempty].long(),
        col_start=col_start[nonempty].long(),
        col_end=col_end[nonempty].long(),
    )


def coverage(spans: Spans, batch: int, height: int, width: int) -> torch.Tensor:
    """(B, H, W) bool: pixels covered by at least one span."""
    device = spans.row.device
    diff = torch.zeros(batch * height * (width + 1), dtype=torch.int32, device=device)
    base = (spans.batch * height + spans.row) * (width + 1)
    ones = torch.ones_like(base, dtype=torch.int32)
    diff.index_add_(0, torch.cat([base + spans.col_start, base + spans.col_end]), torch.cat([ones, -ones]))
    counts = torch.cumsum(diff.view(batch, height, width + 1), dim=2)[..., :width]
    return counts > 0


def fragments(spans: Spans) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Expand spans into per-pixel fragments: (batch, face, row, col), each (M,) long."""
    length = spans.col_end - spans.col_start
    index = torch.repeat_interleave(torch.arange(length.shape[0], device=length.device), length)
    first = torch.cumsum(length, 0) - length
    col = spans.col_start[index] + torch.arange(index.shape[0], device=length.device) - first[index]
    return spans.batch[index], spans.face[index], spans.row[index], col
