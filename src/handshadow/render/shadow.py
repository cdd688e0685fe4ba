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

SAMPLE_SPACING_PX = 1.0  # distance between gradient samples along an edge


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
    def from_faces(faces: torch.Tensor) -> "MeshTopology":
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

    def to(self, device: torch.device | str) -> "MeshTopology":
        return MeshTopology(self.faces.to(device), self.edge_faces.to(device), self.edge_corners.to(device), self.closed)


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
    """dL/d(points_xy) (B, V, 2) from dL/d(mask) (B, H, W) by edge sampling at the outline.

    Args: points_xy (B, V, 2); mask (B, H, W) bool, the forward result; grad_mask (B, H, W);
    facing (B, F) bool from :func:`front_facing`.
    """
    batch, height, width = mask.shape
    n_vertices = points_xy.shape[1]
    dtype = points_xy.dtype
    b, e = contour_edges(facing, topology)
    corners = topology.edge_corners[e]  # (M, 3): a, c, third
    pts = points_xy.reshape(-1, 2).index_select(0, ((b * n_vertices)[:, None] + corners).reshape(-1)).view(-1, 3, 2)
    a, c, o = pts[:, 0], pts[:, 1], pts[:, 2]
    along = c - a
    length = along.norm(dim=1)
    normal = torch.stack([along[:, 1], -along[:, 0]], 1) / length.clamp(min=1e-12)[:, None]
    # Outward: away from the third corner of the edge's first face.
    normal = normal * torch.where(((o - a) * normal).sum(1) > 0, -1.0, 1.0).to(dtype)[:, None]

    n_samples = torch.ceil(length / SAMPLE_SPACING_PX).clamp_(max=4 * max(height, width)).long()
    edge_of = torch.repeat_interleave(torch.arange(len(length), device=length.device), n_samples)
    first = torch.cumsum(n_samples, 0) - n_samples
    k = torch.arange(edge_of.shape[0], device=length.device) - first.index_select(0, edge_of)
    per_edge = torch.cat([a, along, normal, (length / n_samples.clamp(min=1))[:, None], n_samples[:, None].to(dtype)], 1)
    q = per_edge.index_select(0, edge_of)  # (S, 8)
    t = (k.to(dtype) + 0.5) / q[:, 7]
    nrm = q[:, 4:6]
    pos = q[:, 0:2] + t[:, None] * q[:, 2:4]
    # Step far enough (in the max-norm) that the pixel centres probed lie on either side.
    offset = (0.5 * (nrm.abs().sum(1) + 1e-3))[:, None] * nrm
    bs = b.index_select(0, edge_of)
    values = torch.stack([mask.to(dtype), grad_mask], -1).reshape(-1, 2)
    out_v = _lookup(values, bs, pos + offset, height, width)
    in_v = _lookup(values, bs, pos - offset, height, width)
    # Near the outline when one probe is lit and the other in shadow. The normal is the edge's
    # own (away from its faces), so where the contour folds back within a pixel of the outline
    # (three contour edges side by side) the middle one pushes inward and the fold counts once.
    near_outline = (in_v[:, 0] - out_v[:, 0]).abs()
    weight = near_outline * 0.5 * (in_v[:, 1] + out_v[:, 1]) * q[:, 6]
    push = weight[:, None] * nrm  # (S, 2): dL per unit outward motion of the edge there
    vertex = (bs * n_vertices)[:, None] + corners[:, :2].index_select(0, edge_of)  # (S, 2)
    grad = torch.zeros_like(points_xy).view(-1, 2)
    grad.index_add_(0, vertex.T.reshape(-1), torch.cat([push * (1 - t)[:, None], push * t[:, None]]))
    return grad.view_as(points_xy)


def _lookup(values: torch.Tensor, b: torch.Tensor, pos: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Rows of ``values`` ((B*H*W, C)) at the pixels containing pos (S, 2); zero outside."""
    col = torch.floor(pos[:, 0]).long()
    row = torch.floor(pos[:, 1]).long()
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    flat = (b * height + row.clamp(0, height - 1)) * width + col.clamp(0, width - 1)
    return values.index_select(0, flat) * inside[:, None].to(values.dtype)
