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

from handshadow.render.raster import coverage, rasterize_spans, winding_coverage


@dataclasses.dataclass(frozen=True)
class MeshTopology:
    """Faces and their edge adjacency, built once per mesh.

    faces: (F, 3) long; edge_faces: (E, 2) long, the two faces of each edge (the second is -1
    on an open boundary; a non-manifold edge keeps two); edge_corners: (E, 3) long, the edge's
    two vertices and the third corner of its first face; closed: no open boundary, so every
    shadow point is covered by a front-facing triangle and back faces can be skipped;
    oriented: closed, and every edge lies between exactly two faces that run it in opposite
    directions, so the front faces' shadow is the winding number of their outline's edges
    (raster.winding_coverage).
    """

    faces: torch.Tensor
    edge_faces: torch.Tensor
    edge_corners: torch.Tensor
    closed: bool
    oriented: bool = False

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
        closed = bool((edge_faces[:, 1] >= 0).all())
        return MeshTopology(
            faces=as_tensor(f),
            edge_faces=as_tensor(edge_faces),
            edge_corners=as_tensor(corners),
            closed=closed,
            oriented=closed and len(directed) == 2 * len(edges) and len(np.unique(directed, axis=0)) == len(directed),
        )

    def to(self, device: torch.device | str) -> MeshTopology:
        return MeshTopology(
            self.faces.to(device),
            self.edge_faces.to(device),
            self.edge_corners.to(device),
            self.closed,
            self.oriented,
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
        # A closed surface's shadow is the union of its front-facing triangles' shadows.
        if topology.oriented:
            facing = facing_of(points, topology.faces)
            mask = _front_outline_coverage(points, topology, facing, height, width)
        else:
            tri = _gather_triangles(points, topology.faces)  # (B, F, 3, 2)
            facing = front_facing(tri)
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


def _front_outline_coverage(
    points: torch.Tensor, topology: MeshTopology, facing: torch.Tensor, height: int, width: int
) -> torch.Tensor:
    """(B, H, W) bool: the union of the front-facing triangles of an oriented closed mesh, from
    the edges between a front and a back face alone (raster.winding_coverage), each directed
    as its front face runs it. points (B, V, 2); facing (B, F) bool."""
    b, e = contour_edges(facing, topology)  # one face front, the other back (no open edges)
    f0, f1 = topology.edge_faces[e, 0], topology.edge_faces[e, 1]
    front = torch.where(facing[b, f0], f0, f1)
    a, c = topology.edge_corners[e, 0], topology.edge_corners[e, 1]
    third = topology.faces.index_select(0, front).sum(1) - a - c
    flat = points.reshape(-1, 2)
    offset = b * points.shape[1]
    pa, pc, po = (flat.index_select(0, offset + i) for i in (a, c, third))
    u, w = pc - pa, po - pa
    forward = (u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]) < 0  # a -> c as the front face runs it
    start = torch.where(forward[:, None], pa, pc)
    end = torch.where(forward[:, None], pc, pa)
    return winding_coverage(start, end, b, points.shape[0], height, width)


def _gather_triangles(points: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """(B, V, D) points, (F, 3) faces -> (B, F, 3, D) corners."""
    return points.index_select(1, faces.reshape(-1)).view(points.shape[0], faces.shape[0], 3, -1)


def front_facing(tri_xy: torch.Tensor) -> torch.Tensor:
    """(B, F) bool: triangles (B, F, 3, 2) that face the light, i.e. whose outward normal
    (corners counter-clockwise about it) points toward the lamp.

    The wall image reads as seen from the lamp's side (columns along u, rows along v, and
    u x v against the wall's normal, as in every scene this project writes), so such a
    triangle's projected corners run counter-clockwise on screen: a negative cross product in
    (column, row) coordinates. In a mirrored frame it picks the back faces instead, which cast
    the same shadow on a closed mesh."""
    return _turn_counter_clockwise(tri_xy[:, :, 0], tri_xy[:, :, 1], tri_xy[:, :, 2])


def facing_of(points_xy: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """(B, F) bool: :func:`front_facing` of the triangles ``faces`` (F, 3) of points (B, V, 2),
    with the same arithmetic (so the same bits). The corners are gathered vertex-major, (V, B, 2)
    rows picked whole: on a CPU that is several times faster than picking along dim 1."""
    by_vertex = points_xy.transpose(0, 1).contiguous()  # (V, B, 2)
    p0, p1, p2 = (by_vertex.index_select(0, faces[:, k]) for k in range(3))  # (F, B, 2) each
    return _turn_counter_clockwise(p0, p1, p2).t()


def _turn_counter_clockwise(p0: torch.Tensor, p1: torch.Tensor, p2: torch.Tensor) -> torch.Tensor:
    """(...) bool: corners (..., 2) each, in (column, row) coordinates, that run counter-clockwise
    on screen (a negative cross product): the front-face rule of :func:`front_facing`."""
    e1, e2 = p1 - p0, p2 - p0
    return (e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]) < 0


def contour_edges(facing: torch.Tensor, topology: MeshTopology) -> tuple[torch.Tensor, torch.Tensor]:
    """The edges that can lie on the outline, per batch item.

    An edge of a closed surface can only be on the outline of its projection when its two faces
    face opposite ways as seen from the light (one front-, one back-facing); open boundary edges
    always can. Args: facing (B, F) bool. Returns (batch, edge) index pairs, each (M,) long.
    """
    f0, f1 = topology.edge_faces[:, 0], topology.edge_faces[:, 1]
    by_face = facing.t().contiguous()  # (F, B): whole rows picked, much faster than along dim 1
    candidate = (by_face.index_select(0, f0) != by_face.index_select(0, f1.clamp(min=0))) | (f1 < 0)[:, None]
    return torch.nonzero(candidate.t().contiguous(), as_tuple=True)


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
    shallow ones on columns), where each crossing stands for one pixel of the edge's extent.
    Moving it by du toward the lit centre turns an area du x 1 into shadow; the loss changes by
    the mean of its gradient at the two centres (for L2 against a binary target, exactly the
    cost of flipping a pixel).

    Args: points_xy (B, V, 2); mask (B, H, W) bool, the forward result; grad_mask (B, H, W);
    facing (B, F) bool from :func:`front_facing`.
    """
    batch, height, width = mask.shape
    n_vertices = points_xy.shape[1]
    dtype, device = points_xy.dtype, points_xy.device
    b, e = contour_edges(facing, topology)
    corners = topology.edge_corners.index_select(0, e)  # (M, 3): a, c, third corner of the first face
    flat_corners = (b * n_vertices)[:, None] + corners
    pts = points_xy.reshape(-1, 2).index_select(0, flat_corners.reshape(-1)).view(-1, 3, 2)
    a, d, o = pts[:, 0], pts[:, 1] - pts[:, 0], pts[:, 2] - pts[:, 0]
    n_edges = d.shape[0]
    # Which side the edge's own face lies on, and whether the edge is steep.
    side = torch.sign(d[:, 0] * o[:, 1] - d[:, 1] * o[:, 0])
    steep = (d[:, 1].abs() >= d[:, 0].abs()).to(dtype)
    # Both families in (u, v) coordinates, v across the lines: rows (u = x, v = y), columns
    # (u = y, v = x). out_u: the outward normal's sign along u, away from the edge's face.
    fam = torch.cat(
        [
            torch.stack([a[:, 0], a[:, 1], d[:, 0], d[:, 1], side * torch.sign(d[:, 1]), steep], 1),
            torch.stack([a[:, 1], a[:, 0], d[:, 1], d[:, 0], -side * torch.sign(d[:, 0]), 1 - steep], 1),
        ]
    )  # (2M, 6): a_u, a_v, d_u, d_v, out_u, carries gradient
    v0 = torch.minimum(fam[:, 1], fam[:, 1] + fam[:, 3])
    v1 = torch.maximum(fam[:, 1], fam[:, 1] + fam[:, 3])
    extent = torch.tensor([height, width], dtype=dtype, device=device).repeat_interleave(n_edges)
    # Lines v = k + 0.5 with v in [v0, v1): k = ceil(v0 - .5) .. ceil(v1 - .5) - 1, in the image.
    k_lo = torch.ceil(v0 - 0.5).clamp_(min=0)
    count = (torch.minimum(torch.ceil(v1 - 0.5), extent) - k_lo).clamp_(min=0).long()
    cut = torch.repeat_interleave(torch.arange(2 * n_edges, device=device), count)  # crossing -> family edge
    first = torch.cumsum(count, 0) - count
    q = fam.index_select(0, cut)
    k = k_lo.index_select(0, cut) + (torch.arange(cut.shape[0], device=device) - first.index_select(0, cut)).to(dtype)
    t = (k + 0.5 - q[:, 1]) / q[:, 3]  # position along the edge, in [0, 1)
    cross_u = q[:, 0] + t * q[:, 2]
    lo = torch.floor(cross_u - 0.5)  # the centres lo + .5 <= cross_u < lo + 1.5 along u
    on_rows = cut < n_edges
    edge = cut - n_edges * (~on_rows).long()
    bs = b.index_select(0, edge)
    k_long, lo_long = k.long(), lo.long()
    # Pixels (row, col) of the pair's two centres: lo and lo + 1 along u, k along v.
    row = torch.where(on_rows, k_long, lo_long)
    col = torch.where(on_rows, lo_long, k_long)
    step_r, step_c = (~on_rows).long(), on_rows.long()
    rows = torch.cat([row, row + step_r])
    cols = torch.cat([col, col + step_c])
    inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    flat = (bs.repeat(2) * height + rows.clamp(0, height - 1)) * width + cols.clamp(0, width - 1)
    values = torch.stack([mask.to(dtype), grad_mask], -1).reshape(-1, 2).index_select(0, flat)
    n_cross = cut.shape[0]
    m_lo, m_hi = values[:n_cross, 0], values[n_cross:, 0]
    both_inside = inside[:n_cross] & inside[n_cross:]  # the shadow beyond the frame is unknown
    lit_is_hi = m_hi < m_lo
    toward_lit = 2 * lit_is_hi.to(dtype) - 1
    valid = (m_hi != m_lo) & both_inside & (q[:, 4] == toward_lit)
    # Per pixel pair keep the crossing nearest the lit centre.
    dist = torch.where(lit_is_hi, lo + 1.5 - cross_u, cross_u - lo - 0.5)
    key = ((bs * (height + 1) + row + 1) * (width + 1) + col + 1) * 2 + on_rows.long()
    key = torch.where(valid, key, torch.zeros_like(key))
    dist = torch.where(valid, dist, torch.full_like(dist, float("inf")))
    best = torch.empty(batch * (height + 1) * (width + 1) * 2, dtype=dtype, device=device)
    best.scatter_reduce_(0, key, dist, reduce="amin", include_self=False)
    win = valid & (dist <= best.index_select(0, key)) & (q[:, 5] > 0)
    weight = win.to(dtype) * 0.5 * (values[:n_cross, 1] + values[n_cross:, 1]) * toward_lit
    # d(cross_u)/d(a) = (1 - t) (1, -du/dv) and d/d(c) = t (1, -du/dv) in (u, v); to (x, y).
    slope = q[:, 2] / q[:, 3]
    du = torch.stack([torch.ones_like(slope), -slope], 1)
    dxy = torch.where(on_rows[:, None], du, du.flip(1)) * weight[:, None]
    vertex = flat_corners[:, :2].index_select(0, edge)
    grad = torch.zeros_like(points_xy).view(-1, 2)
    grad.index_add_(0, vertex.T.reshape(-1), torch.cat([dxy * (1 - t)[:, None], dxy * t[:, None]]))
    return grad.view_as(points_xy)
