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
    """Row spans of triangles; N spans, each a run of covered pixels in one row (possibly
    empty: col_end == col_start).

    triangle: (N,) long, index into the flattened (B * F) triangles; row: (N,) long;
    col_start, col_end: (N,) long, columns [start, end) covered; faces_per_batch: F.
    """

    triangle: torch.Tensor
    row: torch.Tensor
    col_start: torch.Tensor
    col_end: torch.Tensor
    faces_per_batch: int

    @property
    def batch(self) -> torch.Tensor:
        return torch.div(self.triangle, self.faces_per_batch, rounding_mode="floor")

    @property
    def face(self) -> torch.Tensor:
        return self.triangle % self.faces_per_batch


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
    # Corners sorted by row: y0 <= y1 <= y2. A row's span runs between the long edge (0-2) and
    # the short edge beside it (0-1 above y1, 1-2 below).
    y, order = tri[:, 1::2].sort(dim=1)
    x = tri[:, 0::2].gather(1, order)
    dy = y[:, [2, 1, 2]] - y[:, [0, 0, 1]]
    dx = x[:, [2, 1, 2]] - x[:, [0, 0, 1]]
    slope = dx / torch.where(dy > 0, dy, torch.ones_like(dy))  # 0-2, 0-1, 1-2; flat edges unused
    # Rows whose centre line y = i + 0.5 meets the triangle: ceil(y0 - .5) .. floor(y2 - .5).
    row_lo = torch.ceil(y[:, 0] - 0.5).clamp_(min=0)
    row_hi = torch.floor(y[:, 2] - 0.5).clamp_(max=height - 1)
    count = (row_hi - row_lo + 1).clamp_(min=0).long()
    table = torch.cat([x[:, :2], y[:, :2], slope, row_lo[:, None]], dim=1)  # (T, 8)

    tri_index = torch.repeat_interleave(torch.arange(tri.shape[0], device=tri.device), count)
    first = torch.cumsum(count, 0) - count
    step = torch.arange(tri_index.shape[0], device=tri.device) - first.index_select(0, tri_index)
    t = table.index_select(0, tri_index)  # (N, 8): x0 x1 y0 y1 s02 s01 s12 row_lo
    row = t[:, 7] + step.to(t.dtype)
    yc = row + 0.5
    x_long = t[:, 0] + (yc - t[:, 2]) * t[:, 4]
    x_short = torch.where(yc < t[:, 3], t[:, 0] + (yc - t[:, 2]) * t[:, 5], t[:, 1] + (yc - t[:, 3]) * t[:, 6])
    x_left = torch.minimum(x_long, x_short)
    x_right = torch.maximum(x_long, x_short)
    col_start = torch.ceil(x_left - 0.5).clamp_(min=0, max=width)
    col_end = torch.maximum(torch.floor(x_right - 0.5) + 1, col_start).clamp_(max=width)
    if index is not None:
        tri_index = index.index_select(0, tri_index)
    return Spans(tri_index, row.long(), col_start.long(), col_end.long(), n_faces)


def coverage(spans: Spans, batch: int, height: int, width: int) -> torch.Tensor:
    """(B, H, W) bool: pixels covered by at least one span."""
    device = spans.row.device
    diff = torch.zeros(batch * height * (width + 1), dtype=torch.int32, device=device)
    base = (spans.batch * height + spans.row) * (width + 1)  # empty spans add +1 and -1 at one place
    ones = torch.ones_like(base, dtype=torch.int32)
    diff.index_add_(0, torch.cat([base + spans.col_start, base + spans.col_end]), torch.cat([ones, -ones]))
    counts = torch.cumsum(diff.view(batch, height, width + 1), dim=2)[..., :width]
    return counts > 0


def winding_coverage(
    start: torch.Tensor, end: torch.Tensor, batch_index: torch.Tensor, batch: int, height: int, width: int
) -> torch.Tensor:
    """(B, H, W) bool: pixel centres with a non-zero winding number about closed chains of
    directed edges, e.g. the outline edges of a mesh's front faces (render.shadow).

    The union of triangles that all run one way round is the set of points about which the
    sum of their boundaries winds; edges two of them share in opposite directions cancel, so
    only the outline's edges need crossing with the rows, and the cost grows with the outline,
    not with the triangles. Each edge crosses the centre lines y = i + 0.5 in [min y, max y)
    and adds its direction (+1 downward) at the first centre right of the crossing, and a
    cumulative sum along the row counts. The crossings are computed as :func:`rasterize_spans`
    computes a triangle's (from the edge's upper end, with its slope), and a crossing where the
    count rises takes a centre on it as the triangle rasteriser does (inside), so the two agree
    but at centres exactly on a horizontal edge or a lowest corner.

    Args:
        start, end: (M, 2) edge ends in continuous pixel coordinates (column, row), finite;
            edges of counter-clockwise chains (negative cross product in these coordinates:
            render.shadow.front_facing) give positive counts.
        batch_index: (M,) long, each edge's batch item; batch, height, width: the image size.
    """
    device = start.device
    down = end[:, 1] > start[:, 1]
    top = torch.where(down[:, None], start, end)  # the upper end (smaller row)
    bottom = torch.where(down[:, None], end, start)
    dy = bottom[:, 1] - top[:, 1]
    slope = (bottom[:, 0] - top[:, 0]) / torch.where(dy > 0, dy, torch.ones_like(dy))
    row_lo = torch.ceil(top[:, 1] - 0.5).clamp_(min=0)
    count = (torch.ceil(bottom[:, 1] - 0.5).clamp_(max=height) - row_lo).clamp_(min=0).long()
    edge = torch.repeat_interleave(torch.arange(start.shape[0], device=device), count)
    first = torch.cumsum(count, 0) - count
    row = row_lo.index_select(0, edge) + (torch.arange(edge.shape[0], device=device) - first.index_select(0, edge))
    x = top.index_select(0, edge)[:, 0] + (row + 0.5 - top.index_select(0, edge)[:, 1]) * slope.index_select(0, edge)
    rising = down.index_select(0, edge)  # downward edges raise the count (the chains' left sides)
    col = torch.where(rising, torch.ceil(x - 0.5), torch.floor(x - 0.5) + 1).clamp_(min=0, max=width).long()
    base = (batch_index.index_select(0, edge) * height + row.long()) * (width + 1)
    step = torch.where(rising, 1, -1).to(torch.int32)
    diff = torch.zeros(batch * height * (width + 1), dtype=torch.int32, device=device)
    diff.index_add_(0, base + col, step)
    return torch.cumsum(diff.view(batch, height, width + 1), dim=2)[..., :width] != 0


def fragments(spans: Spans) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Expand spans into per-pixel fragments: (batch, face, row, col), each (M,) long."""
    length = spans.col_end - spans.col_start  # empty spans expand to nothing
    index = torch.repeat_interleave(torch.arange(length.shape[0], device=length.device), length)
    first = torch.cumsum(length, 0) - length
    col = spans.col_start[index] + torch.arange(index.shape[0], device=length.device) - first[index]
    return spans.batch[index], spans.face[index], spans.row[index], col


def points_covered(
    tri_xy: torch.Tensor, keep: torch.Tensor | None, batch: torch.Tensor, points: torch.Tensor, cell_px: float = 2.0
) -> torch.Tensor:
    """Whether each point lies in (or on) any triangle of its batch item.

    Exact point-in-triangle tests against the triangles whose bounding boxes share the point's
    cell of a uniform grid (``cell_px`` pixels), so the cost grows with the triangles near the
    points, not with the image.

    Args:
        tri_xy: (B, F, 3, 2) triangles in pixel coordinates.
        keep: optional (B, F) bool, the triangles to test against.
        batch: (S,) long, the batch item of each point.
        points: (S, 2) pixel coordinates.
    Returns:
        (S,) bool.
    """
    n_batch, n_faces = tri_xy.shape[:2]
    tri = tri_xy.detach().reshape(-1, 3, 2)
    index = (
        torch.arange(tri.shape[0], device=tri.device)
        if keep is None
        else torch.nonzero(keep.reshape(-1), as_tuple=True)[0]
    )
    tri = tri.index_select(0, index)
    tri_batch = torch.div(index, n_faces, rounding_mode="floor")
    # Grid over the points' extent (plus one cell), triangles clamped into it.
    lo_pt = torch.floor(points.amin(0) / cell_px) - 1 if len(points) else points.new_zeros(2)
    hi_pt = torch.floor(points.amax(0) / cell_px) + 1 if len(points) else points.new_zeros(2)
    size = (hi_pt - lo_pt + 1).long()
    t_lo = (torch.floor(tri.amin(1) / cell_px) - lo_pt).clamp(min=0)
    t_hi = (torch.floor(tri.amax(1) / cell_px) - lo_pt).minimum(size - 1)
    extent = (t_hi - t_lo + 1).clamp(min=0).long()  # (N, 2): cells in x and y
    n_cells = extent[:, 0] * extent[:, 1]
    tri_rep = torch.repeat_interleave(torch.arange(tri.shape[0], device=tri.device), n_cells)
    k = torch.arange(tri_rep.shape[0], device=tri.device) - (torch.cumsum(n_cells, 0) - n_cells).index_select(
        0, tri_rep
    )
    ex = extent[:, 0].index_select(0, tri_rep)
    cx = t_lo[:, 0].long().index_select(0, tri_rep) + k % ex
    cy = t_lo[:, 1].long().index_select(0, tri_rep) + torch.div(k, ex, rounding_mode="floor")
    key = (tri_batch.index_select(0, tri_rep) * size[1] + cy) * size[0] + cx
    key, order = torch.sort(key)
    tri_sorted = tri_rep.index_select(0, order)

    q = (torch.floor(points / cell_px) - lo_pt).long()
    q_key = (batch * size[1] + q[:, 1]) * size[0] + q[:, 0]
    start = torch.searchsorted(key, q_key)
    count = torch.searchsorted(key, q_key, right=True) - start
    pt_rep = torch.repeat_interleave(torch.arange(points.shape[0], device=points.device), count)
    j = (
        start.index_select(0, pt_rep)
        + torch.arange(pt_rep.shape[0], device=points.device)
        - (torch.cumsum(count, 0) - count).index_select(0, pt_rep)
    )
    t = tri.index_select(0, tri_sorted.index_select(0, j))  # (P, 3, 2)
    p = points.index_select(0, pt_rep)[:, None, :]
    a, b = t, t.roll(-1, 1)
    side = (b[..., 0] - a[..., 0]) * (p[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (p[..., 0] - a[..., 0])
    inside = ((side >= 0).all(1) | (side <= 0).all(1)).to(torch.int32)
    hits = torch.zeros(points.shape[0], dtype=torch.int32, device=points.device).index_add_(0, pt_rep, inside)
    return hits > 0
