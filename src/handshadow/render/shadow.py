"""The exact shadow mask and its gradient at the silhouette.

Forward: a pixel is in shadow when its centre is covered by a projected triangle
(:mod:`handshadow.render.raster`); the mask is exactly 0 or 1, never blurred.

Backward (edge sampling): a pixel-sampled mask is piecewise constant, so its gradient comes
from the outline. Moving the outline outward by a small distance turns the strip it sweeps into
shadow, and the loss changes by the loss gradient there times the strip's area. We sample the
contour edges of the projected meshes (edges whose two faces face opposite ways, or open
boundary edges) about once per pixel of length. A sample counts when the pixel just inside the
edge is in shadow and the pixel just outside is lit, i.e. when the edge lies on the outline of
the union of all shadows (interior and hidden edges contribute nothing). Its weight is the mean
of the loss gradient on both sides: for the L2 loss against a binary target this is exactly the
loss change of flipping a pixel, and for losses linear in the mask it is the value at the edge.
The gradient is pushed onto the edge's two vertices with linear weights along the edge.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from handshadow.render.raster import coverage, rasterize_spans


@dataclasses.dataclass(frozen=True)
class MeshTopology:
    """Faces and their edge adjacency, built once per mesh.

    faces: (F, 3) long; edge_faces: (E, 2) long, the two faces of each edge (the second is -1
    on an open boundary; a non-manifold edge keeps two); edge_corners: (E, 3) long, the edge's
    two vertices and the third corner of its first face; closed: no open boundary, so every
    shadow point is covered by a front-facing triangle and back faces can be skipped.
    """

    faces: torch.Tensor
    edge_faces: torch.Tensor
    edge_corners: torch.Tensor
    closed: bool

    @staticmethod
    def from_faces(faces: torch.Tensor) -> MeshTopology:
        f = faces.detach().cpu().numpy().astype(np.int64)
        directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        face_of = np.tile(np.arange(len(f)), 3)
        edges, inverse = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True)
        inverse = inverse.ravel()
        order = np.argsort(inverse, kind="stable")
        sorted_edges = inverse[order]
        starts = np.r_[0, np.flatnonzero(np.diff(sorted_edges)) + 1]
        rank = np.arange(len(order)) - np.repeat(starts, np.diff(np.r_[starts, len(order)]))
        edge_faces = np.full((len(edges), 2), -1, dtype=np.int64)
        keep = rank < 2
        edge_faces[sorted_edges[keep], rank[keep]] = face_of[order[keep]]
        third = f[edge_faces[:, 0]].sum(1) - edges.sum(1)
        corners = np.concatenate([edges, third[:, None]], axis=1)
        as_tensor = lambda a: torch.as_tensor(a, dtype=torch.long, device=faces.device)  # noqa: E731
        return MeshTopology(
            faces=as_tensor(f),
            edge_faces=as_tensor(edge_faces),
            edge_corners=as_tensor(corners),
            closed=bool((edge_faces[:, 1] >= 0).all()),
        )

    def to(self, device: torch.device | str) -> MeshTopology:
        return MeshTopology(
            self.faces.to(device), self.edge_faces.to(device), self.edge_corners.to(device), self.closed
        )


def shadow_mask(points_xy: torch.Tensor, topology: MeshTopology, height: int, width: int) -> torch.Tensor:
    """Exact shadow of a mesh, differentiable with respect to the projected vertices.

    Args:
        points_xy: (B, V, 2) projected vertices in continuous pixel coordinates (column, row).
        topology: faces and edges of the mesh (all hands merged into one mesh).
        height, width: image size in pixels.
    Returns:
        (B, H, W) mask in the dtype of points_xy, 1 in shadow and 0 lit. Gradients reach
        points_xy through the outline only (edge sampling, see module docstring).
    """
    return _ShadowMask.apply(points_xy, topology, height, width)


class _ShadowMask(torch.autograd.Function):
    @staticmethod
    def forward(ctx, points_xy, topology, height, width):
        points = points_xy.detach()
        tri = _gather_triangles(points, topology.faces)  # (B, F, 3, 2)
        facing = front_facing(tri)
        # A closed surface's shadow is the union of its front-facing triangles' shadows.
        spans = rasterize_spans(tri, height, width, keep=facing if topology.closed else None)
        mask = coverage(spans, points.shape[0], height, width)
        ctx.topology = topology
        ctx.save_for_backward(points, mask, facing)
        return mask.to(points_xy.dtype)

    @staticmethod
    def backward(ctx, grad_mask):
        points_xy, mask, facing = ctx.saved_tensors
        grad = outline_gradient(points_xy, ctx.topology, mask, grad_mask, facing)
        return grad, None, None, None


def _gather_triangles(points: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """(B, V, D) points, (F, 3) faces -> (B, F, 3, D) corners."""
    return points.index_select(1, faces.reshape(-1)).view(points.shape[0], faces.shape[0], 3, -1)


def front_facing(tri_xy: torch.Tensor) -> torch.Tensor:
    """(B, F) bool: triangles (B, F, 3, 2) whose projected corners run counter-clockwise in
    pixel coordinates (rows down), i.e. that face the light for outward-oriented meshes."""
    e1 = tri_xy[:, :, 1] - tri_xy[:, :, 0]
    e2 = tri_xy[:, :, 2] - tri_xy[:, :, 0]
    return (e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]) > 0


def contour_edges(facing: torch.Tensor, topology: MeshTopology) -> tuple[torch.Tensor, torch.Tensor]:
    """The edges that can lie on the outline, per batch item.

    An edge of a closed surface can only be on the outline of its projection when its two faces
    face opposite ways as seen from the light (one front-, one back-facing); open boundary edges
    always can. Args: facing (B, F) bool. Returns (batch, edge) index pairs, each (M,) long.
    """
    f0, f1 = topology.edge_faces[:, 0], topology.edge_faces[:, 1]
    candidate = (facing[:, f0] != facing[:, f1.clamp(min=0)]) | (f1 < 0)
    return torch.nonzero(candidate, as_tuple=True)


def outline_gradient(
    points_xy: torch.Tensor,
    topology: MeshTopology,
    mask: torch.Tensor,
    grad_mask: torch.Tensor,
    facing: torch.Tensor,
) -> torch.Tensor:
    """dL/d(points_xy) (B, V, 2) from dL/d(mask) (B, H, W) at the outline.

    The outline passes between two neighbouring pixel centres whose mask values differ. Contour
    edges are cut with the lines through pixel centres (rows y = i + 0.5 and columns
    x = j + 0.5). For each pair of differing neighbours the crossing nearest the lit centre is
    the outline there (hidden contours and folds of the contour lie behind it and lose). A
    winning crossing carries gradient only on its edge's dominant family (steep edges on rows,
    shallow ones on columns), where each crossing stands for one pixel of the edge's extent. Moving that crossing by dx toward the lit centre
    turns an area dx x 1 into shadow; the loss changes by the mean of its gradient at the two
    centres (for L2 against a binary target, exactly the cost of flipping a pixel).

    Args: points_xy (B, V, 2); mask (B, H, W) bool, the forward result; grad_mask (B, H, W);
    facing (B, F) bool from :func:`front_facing`.
    """
    batch, height, width = mask.shape
    n_vertices = points_xy.shape[1]
    dtype = points_xy.dtype
    b, e = contour_edges(facing, topology)
    corners = topology.edge_corners[e]  # (M, 3): a, c, third corner of the first face
    pts = points_xy.reshape(-1, 2).index_select(0, ((b * n_vertices)[:, None] + corners).reshape(-1)).view(-1, 3, 2)
    a, c, o = pts[:, 0], pts[:, 1], pts[:, 2]
    d = c - a
    # Cut every edge with both families of centre lines: rows (v = y, pairs side by side) and
    # columns (v = x, pairs one above the other). All crossings compete for the outline of a
    # pair; only crossings of the edge's dominant family (steep: rows, shallow: columns) carry
    # the gradient, so each stretch of outline counts once.
    n_edges = d.shape[0]
    steep = d[:, 1].abs() >= d[:, 0].abs()
    major = torch.cat(
        [
            torch.ones(n_edges, dtype=torch.long, device=d.device),
            torch.zeros(n_edges, dtype=torch.long, device=d.device),
        ]
    )
    dominant = torch.cat([steep, ~steep])
    a, d, o, b, corners = a.repeat(2, 1), d.repeat(2, 1), o.repeat(2, 1), b.repeat(2), corners.repeat(2, 1)
    minor = 1 - major
    a_u, a_v = a.gather(1, minor[:, None])[:, 0], a.gather(1, major[:, None])[:, 0]
    d_u, d_v = d.gather(1, minor[:, None])[:, 0], d.gather(1, major[:, None])[:, 0]
    rows_family = major == 1
    # Outward normal's sign along u (the pair axis): away from the edge's own face.
    side = d[:, 0] * (o[:, 1] - a[:, 1]) - d[:, 1] * (o[:, 0] - a[:, 0])  # third corner's side
    out_u = torch.where(rows_family, 1.0, -1.0).to(dtype) * torch.sign(side) * torch.sign(d_v)
    # Lines v = k + 0.5 with v in [min, max) of the edge: k = ceil(min - .5) .. ceil(max - .5) - 1.
    v_lo = torch.minimum(a_v, a_v + d_v)
    v_hi = torch.maximum(a_v, a_v + d_v)
    extent = torch.where(rows_family, height, width)
    k_lo = torch.ceil(v_lo - 0.5).clamp(min=0)
    k_hi = torch.minimum(torch.ceil(v_hi - 0.5) - 1, (extent - 1).to(dtype))
    count = (k_hi - k_lo + 1).clamp(min=0).long()
    edge_of = torch.repeat_interleave(torch.arange(len(count), device=count.device), count)
    first = torch.cumsum(count, 0) - count
    k = k_lo.index_select(0, edge_of) + (
        torch.arange(edge_of.shape[0], device=count.device) - first.index_select(0, edge_of)
    ).to(dtype)
    per_edge = torch.stack([a_u, a_v, d_u, d_v, out_u, major.to(dtype), dominant.to(dtype)], 1).index_select(0, edge_of)
    t = (k + 0.5 - per_edge[:, 1]) / per_edge[:, 3]  # position along the edge, in [0, 1)
    cross_u = per_edge[:, 0] + t * per_edge[:, 2]
    lo = torch.floor(cross_u - 0.5)  # the pair of centres lo + .5 <= cross_u < lo + 1.5
    on_rows = per_edge[:, 5] > 0  # crossing a row line: a side-by-side pair
    bs = b.index_select(0, edge_of)
    k_long = k.long()
    lo_long = lo.long()
    row_lo = torch.where(on_rows, k_long, lo_long)
    col_lo = torch.where(on_rows, lo_long, k_long)
    row_hi = torch.where(on_rows, k_long, lo_long + 1)
    col_hi = torch.where(on_rows, lo_long + 1, k_long)
    values = torch.stack([mask.to(dtype), grad_mask], -1).reshape(-1, 2)
    v_lo_px = _pixel_values(values, bs, row_lo, col_lo, height, width)
    v_hi_px = _pixel_values(values, bs, row_hi, col_hi, height, width)
    lit_is_hi = v_hi_px[:, 0] < v_lo_px[:, 0]
    # Both centres inside the image (the shadow beyond the frame is unknown, not lit).
    in_image = (row_lo >= 0) & (col_lo >= 0) & (row_hi < height) & (col_hi < width)
    differ = (v_hi_px[:, 0] != v_lo_px[:, 0]) & in_image
    toward_lit = torch.where(lit_is_hi, 1.0, -1.0).to(dtype)
    valid = differ & (per_edge[:, 4] == toward_lit)
    # Per pixel pair keep the crossing nearest the lit centre.
    dist = torch.where(lit_is_hi, lo + 1.5 - cross_u, cross_u - lo - 0.5)
    key = ((bs * (height + 1) + row_lo + 1) * (width + 1) + col_lo + 1) * 2 + on_rows.long()
    key = torch.where(valid, key, torch.zeros_like(key))
    best = torch.full((batch * (height + 1) * (width + 1) * 2,), float("inf"), dtype=dtype, device=points_xy.device)
    best.scatter_reduce_(0, key, torch.where(valid, dist, torch.full_like(dist, float("inf"))), reduce="amin")
    win = valid & (dist <= best.index_select(0, key))
    weight = (win & (per_edge[:, 6] > 0)).to(dtype) * 0.5 * (v_lo_px[:, 1] + v_hi_px[:, 1]) * toward_lit
    # d(cross_u)/d(a) = (1 - t) (1, -du/dv) and d/d(c) = t (...), in (u, v); back to (x, y).
    slope = per_edge[:, 2] / per_edge[:, 3]
    du_dv = torch.stack([torch.ones_like(slope), -slope], 1)  # (u, v) components
    dxy = torch.where(on_rows[:, None], du_dv, du_dv.flip(1)) * weight[:, None]
    vertex = (bs * n_vertices)[:, None] + corners[:, :2].index_select(0, edge_of)
    grad = torch.zeros_like(points_xy).view(-1, 2)
    grad.index_add_(0, vertex.T.reshape(-1), torch.cat([dxy * (1 - t)[:, None], dxy * t[:, None]]))
    return grad.view_as(points_xy)


def _pixel_values(values: torch.Tensor, b, row, col, height: int, width: int) -> torch.Tensor:
    """Rows of ``values`` ((B*H*W, C)) at pixels (row, col); zero outside the image."""
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    flat = (b * height + row.clamp(0, height - 1)) * width + col.clamp(0, width - 1)
    return values.index_select(0, flat) * inside[:, None].to(values.dtype)
