"""Solids for printing: closed triangle meshes -> one clean manifold3d solid, its local
thickness, and thickening of the parts that are too thin.

Posed hands are closed surfaces but not clean solids: skinning folds the skin at bent joints
and fingers that press together pass through each other, so a hand's own triangles cross
(a fitted hand has a few hundred crossing edges). Boolean operations assume operands that do
not cross themselves, so a hand is not handed to manifold3d as it is. Instead each vertex's
fan of triangles is wrapped in its convex hull, grown by ``shell`` (a small octahedron
at each corner, so every edge lies strictly inside the hulls of both its fans); manifold3d
unites these small convex pieces into a thin shell, and the shell's inner surfaces (the
hollow inside the hand and any pockets of the folds) are dropped. What is left is the region
enclosed by the skin, grown by at most ``shell``, as one manifold without crossings. The
growth and the hulls' chords over concave places scale with the solid, so the result of
scaled meshes is the scaled result when ``shell`` scales too.

Units are whatever the vertices are in; the printing stage works in millimetres.
"""

from __future__ import annotations

import dataclasses

import manifold3d as m3
import numpy as np
from scipy.spatial import cKDTree

SHELL = 1e-4  # growth of the skin while uniting its fans, as a share of the solid's size
STL_TOLERANCE = 1e-4  # edges shorter than this are collapsed before writing (units of the solid)
PART_NEIGHBOURS = 16  # a part is thin when so many vertices around are thin too
_OCTAHEDRON = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)


def to_manifold(vertices: np.ndarray, faces: np.ndarray) -> m3.Manifold:
    """A manifold3d solid from vertices (V, 3) and outward-wound faces (F, 3); raises
    ValueError when the surface is not closed and oriented."""
    mesh = m3.Mesh64(
        vert_properties=np.ascontiguousarray(vertices, dtype=np.float64),
        tri_verts=np.ascontiguousarray(faces, dtype=np.uint64),
    )
    solid = m3.Manifold(mesh)
    if solid.status() != m3.Error.NoError:
        raise ValueError(f"not a closed, oriented surface ({solid.status().name})")
    return solid


def to_arrays(solid: m3.Manifold) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 and faces (F, 3) int64 of a manifold3d solid."""
    mesh = solid.to_mesh64()
    return np.asarray(mesh.vert_properties)[:, :3].astype(np.float64), np.asarray(mesh.tri_verts).astype(np.int64)


def vertex_fans(faces: np.ndarray, num_vertices: int) -> list[np.ndarray]:
    """Vertex sets of fans (a vertex and its ring) that together hold every face: greedily the
    vertex whose fan holds the most faces not yet held. Returns arrays of vertex indices."""
    faces = np.asarray(faces)
    incident = [[] for _ in range(num_vertices)]
    for i, tri in enumerate(faces):
        for k in tri:
            incident[k].append(i)
    open_count = np.array([len(f) for f in incident])
    held = np.zeros(len(faces), bool)
    fans = []
    while True:
        k = int(np.argmax(open_count))
        if open_count[k] == 0:
            return fans
        new = [i for i in incident[k] if not held[i]]
        held[new] = True
        for i in new:
            np.subtract.at(open_count, faces[i], 1)
        fans.append(np.unique(faces[incident[k]]))


def clean_solid(meshes: list[tuple[np.ndarray, np.ndarray]], shell: float | None = None) -> m3.Manifold:
    """The region enclosed by closed surfaces (each vertices (V, 3), faces (F, 3)), as one
    manifold3d solid without self-crossings, grown by at most ``shell`` (default: SHELL of
    the diagonal of all vertices' bounding box; 0.02 mm on a 150 mm print).

    Surfaces may cross themselves and each other. Pieces that end up apart stay apart (the
    result may hold several disjoint solids; see :func:`parts`).
    """
    if shell is None:
        every = np.concatenate([np.asarray(v, np.float64) for v, _ in meshes])
        shell = SHELL * float(np.linalg.norm(every.max(0) - every.min(0)))
    pieces = []
    for vertices, faces in meshes:
        v = np.asarray(vertices, np.float64)
        for fan in vertex_fans(faces, len(v)):
            pieces.append(m3.Manifold.hull_points((v[fan][:, None, :] + shell * _OCTAHEDRON).reshape(-1, 3)))
    return fill(m3.Manifold.batch_boolean(pieces, m3.OpType.Add))


def fill(solid: m3.Manifold) -> m3.Manifold:
    """Drop inner surfaces: the shells that bound hollows (negative volume on their own) and
    any solid that floats inside another."""
    shells = sorted(solid.decompose(), key=lambda s: -s.volume())
    kept: list[m3.Manifold] = []
    for s in shells:
        if s.volume() <= 0:
            continue
        if any((s ^ k).volume() > 0.5 * s.volume() for k in kept):  # ^ is intersection
            continue
        kept.append(s)
    return m3.Manifold.batch_boolean(kept, m3.OpType.Add) if len(kept) != 1 else kept[0]


def for_stl(solid: m3.Manifold, tolerance: float = STL_TOLERANCE) -> m3.Manifold:
    """The solid as an STL can hold it: edges shorter than ``tolerance`` collapsed (a union
    of many small pieces leaves slivers, and corners that touch without being joined, which
    a file of bare positions would fuse), then the vertices rounded to 32-bit floats, with
    manifold3d collapsing any triangle the rounding flattens. The surface moves by about the
    tolerance. (A coarser simplification, 0.01 mm, let a few edges pass through faces.)"""
    simple = solid.as_original().simplify(tolerance)
    vertices, faces = to_arrays(simple)
    rounded = m3.Manifold(m3.Mesh(vert_properties=vertices.astype(np.float32), tri_verts=faces.astype(np.uint32)))
    if rounded.status() != m3.Error.NoError:
        raise ValueError(f"rounding to 32-bit floats broke the solid ({rounded.status().name})")
    return rounded


def parts(solid: m3.Manifold) -> list[m3.Manifold]:
    """The disjoint solids of a filled solid, largest first."""
    return sorted(solid.decompose(), key=lambda s: -s.volume())


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals, outward for outward-wound faces."""
    fn = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    n = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


@dataclasses.dataclass(frozen=True)
class Thickness:
    """Thickness of a solid at its surface vertices.

    points: (V, 3) the vertices; faces: (F, 3) the surface's triangles; normals: (V, 3)
    outward unit normals; depth: (V,) distance
    from each vertex straight inward (along -normal) to where the ray leaves the solid again,
    capped at the search depth; part: (V,) the thickness of the part a vertex belongs to,
    the median depth over its PART_NEIGHBOURS nearest vertices (a sharp edge or a lone spike
    on a thick part is not a thin part; a thin finger is thin all around).
    """

    points: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    depth: np.ndarray
    part: np.ndarray

    @property
    def centres(self) -> np.ndarray:
        """(V, 3) points half-way through the solid under each vertex."""
        return self.points - 0.5 * self.depth[:, None] * self.normals

    def moved(self, ratio: float, before: np.ndarray, after: np.ndarray) -> Thickness:
        """The thickness of the same solid scaled by ``ratio`` about the point ``before``
        (3,), which goes to ``after`` (3,)."""
        return dataclasses.replace(
            self,
            points=ratio * (self.points - before) + after,
            depth=ratio * self.depth,
            part=ratio * self.part,
        )


def local_thickness(solid: m3.Manifold, max_depth: float) -> Thickness:
    """Thickness at each vertex of a clean solid (no self-crossings): the inward ray's length
    through it (a finger of diameter d: d across it), then the part thickness (see
    :class:`Thickness`). Units of the solid; max_depth caps the rays."""
    points, faces = to_arrays(solid)
    normals = vertex_normals(points, faces)
    depth = np.full(len(points), float(max_depth))
    lead = 1e-6 * max_depth  # start just inside, past the vertex's own faces
    for i, (p, n) in enumerate(zip(points, normals)):
        hits = solid.ray_cast(p - lead * n, p - max_depth * n)
        if hits:
            depth[i] = lead + hits[0].distance * (max_depth - lead)
    _, nearest = cKDTree(points).query(points, k=min(PART_NEIGHBOURS, len(points)))
    part = np.median(depth[nearest], axis=1)
    return Thickness(points=points, faces=faces, normals=normals, depth=depth, part=part)


def thickening_balls(thickness: Thickness, min_wall: float) -> np.ndarray:
    """Centres (K, 3) of the balls of diameter ``min_wall`` that bring every part thinner
    than it to that thickness: half-way through the solid under each thin vertex and along
    the edges between thin vertices (so the balls overlap into a tube along a thin finger,
    however sparse its vertices), thinned to one per cell of min_wall / 4.

    Thin vertices: those of thin parts, and those within min_wall of them whose own depth
    is below it (the last millimetre of a thin fingertip, whose part thickness the tip's long
    rays lift)."""
    core = thickness.part < min_wall
    if not core.any():
        return np.zeros((0, 3))
    distance, _ = cKDTree(thickness.points[core]).query(thickness.points, distance_upper_bound=min_wall)
    thin = core | (np.isfinite(distance) & (thickness.depth < min_wall))
    centres = thickness.centres
    f = thickness.faces
    edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1), axis=0)
    edges = edges[thin[edges].all(1)]
    a, b = centres[edges[:, 0]], centres[edges[:, 1]]
    steps = np.ceil(np.linalg.norm(b - a, axis=1) / (min_wall / 4)).astype(np.int64)
    which = np.repeat(np.arange(len(edges)), steps)
    t = (np.arange(len(which)) - np.repeat(np.cumsum(steps) - steps, steps) + 0.5) / steps[which]
    points = np.concatenate([centres[thin], a[which] + t[:, None] * (b[which] - a[which])])
    cells = np.floor(points / (min_wall / 4)).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    return points[np.sort(first)]


def balls(centres: np.ndarray, radius: float) -> list[m3.Manifold]:
    """Convex balls around centres (K, 3): hulls of 42 points on a sphere, just large enough
    that the ball of ``radius`` fits inside each."""
    import trimesh

    unit = trimesh.creation.icosphere(subdivisions=1)
    inradius = float(np.min(np.abs((unit.face_normals * unit.triangles[:, 0]).sum(1))))
    return [m3.Manifold.hull_points(c + radius / inradius * unit.vertices) for c in np.asarray(centres, float)]
