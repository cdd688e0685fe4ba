"""Check a print from its files alone: cast the STL's shadow from the lamp in print.json onto
its wall, with plain numpy.

Deliberately independent of the rest of handshadow (no Scene, no projective matrix, no torch
rasteriser): it reads only the mesh file and print.json, so tests and the bench measure what a
person with the two files would see. A pixel is in shadow when its centre on the wall, seen
from the lamp, is covered by a triangle of the part of the mesh in front of the wall (the
board behind the wall casts nothing; the picture falls on its front face).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def load_print(mesh_path: str | Path, json_path: str | Path) -> tuple[np.ndarray, np.ndarray, dict]:
    """Vertices (V, 3) mm, faces (F, 3) of the printed mesh, and print.json as a dict."""
    import trimesh

    mesh = trimesh.load(mesh_path, process=True, force="mesh")
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), json.loads(Path(json_path).read_text())


def cast_shadow(vertices: np.ndarray, faces: np.ndarray, info: dict) -> np.ndarray:
    """(H, W) bool shadow of a mesh (vertices (V, 3), faces (F, 3), print millimetres) under
    print.json's point light ``info["light"]`` on its ``info["wall"]``, sampled at the pixel
    centres of its ``info["image"]``."""
    lamp = np.asarray(info["light"]["position"], float)
    wall = np.asarray(info["wall"]["point"], float)
    normal = np.asarray(info["wall"]["normal"], float)
    normal = normal / np.linalg.norm(normal)
    im = info["image"]
    width, height = int(im["width"]), int(im["height"])
    origin, u, v = (np.asarray(im[k], float) for k in ("origin", "u", "v"))
    lamp_height = (lamp - wall) @ normal
    triangles = _clip_in_front(np.asarray(vertices, float)[faces], wall, normal, lamp_height)
    flat = triangles.reshape(-1, 3)
    scale = lamp_height / (lamp_height - (flat - wall) @ normal)  # lamp -> point, extended to the wall
    on_wall = lamp + (flat - lamp) * scale[:, None]
    x = (on_wall - origin) @ u / (u @ u) * width
    y = (on_wall - origin) @ v / (v @ v) * height
    return _cover(np.stack([x, y], 1).reshape(-1, 3, 2), height, width)


def _clip_in_front(tri: np.ndarray, wall: np.ndarray, normal: np.ndarray, lamp_height: float) -> np.ndarray:
    """Triangles (T, 3, 3) cut to the slab between the wall (exclusive: faces lying on it cast
    nothing) and just short of the lamp's plane; returns (T', 3, 3)."""
    eps = 1e-9 * lamp_height
    for offset, sign in ((eps, 1.0), (lamp_height * (1 - 1e-9), -1.0)):
        tri = _clip_halfspace(tri, lambda p, o=offset, s=sign: s * ((p - wall) @ normal - o))
    return tri


def _clip_halfspace(tri: np.ndarray, side) -> np.ndarray:
    """Keep the part of each triangle where side(p) >= 0 (a triangle with one corner out
    becomes two, with two out becomes one)."""
    d = side(tri.reshape(-1, 3)).reshape(-1, 3)
    inside = d >= 0
    count = inside.sum(1)
    keep = [tri[count == 3]]
    for n_in in (1, 2):
        sel = count == n_in
        if not sel.any():
            continue
        t, dd, ins = tri[sel], d[sel], inside[sel]
        # rotate corners so the odd one (the lone inside or the lone outside corner) comes first
        odd = np.argmax(ins if n_in == 1 else ~ins, axis=1)
        idx = (odd[:, None] + np.arange(3)) % 3
        t = np.take_along_axis(t, idx[:, :, None], 1)
        dd = np.take_along_axis(dd, idx, 1)
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        ab = a + (b - a) * (dd[:, 0] / (dd[:, 0] - dd[:, 1]))[:, None]
        ac = a + (c - a) * (dd[:, 0] / (dd[:, 0] - dd[:, 2]))[:, None]
        if n_in == 1:
            keep.append(np.stack([a, ab, ac], 1))
        else:
            keep.append(np.stack([ab, b, c], 1))
            keep.append(np.stack([ab, c, ac], 1))
    return np.concatenate(keep)


def _cover(tri: np.ndarray, height: int, width: int, chunk: int = 20000) -> np.ndarray:
    """(H, W) bool: pixel centres (j + 0.5, i + 0.5) inside or on any triangle (T, 3, 2)."""
    mask = np.zeros((height, width), bool)
    lo = np.clip(np.ceil(tri.min(1) - 0.5), 0, [width, height]).astype(np.int64)
    hi = np.clip(np.floor(tri.max(1) - 0.5) + 1, 0, [width, height]).astype(np.int64)
    size = np.maximum(hi - lo, 0)
    count = size[:, 0] * size[:, 1]
    for start in range(0, len(tri), chunk):
        sl = slice(start, start + chunk)
        which = np.repeat(np.arange(start, min(start + chunk, len(tri))), count[sl])
        if len(which) == 0:
            continue
        k = np.arange(len(which)) - np.repeat(np.cumsum(count[sl]) - count[sl], count[sl])
        col = lo[which, 0] + k % np.maximum(size[which, 0], 1)
        row = lo[which, 1] + k // np.maximum(size[which, 0], 1)
        p = np.stack([col + 0.5, row + 0.5], 1)
        a, b, c = tri[which, 0], tri[which, 1], tri[which, 2]
        e = [_cross(b - a, p - a), _cross(c - b, p - b), _cross(a - c, p - c)]
        inside = ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))
        inside &= _cross(b - a, c - a) != 0
        mask[row[inside], col[inside]] = True
    return mask


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def crossing_edges(vertices: np.ndarray, faces: np.ndarray, tolerance: float = 1e-3) -> int:
    """How many edges of a triangle mesh pass through a triangle they do not belong to, by
    more than ``tolerance`` (mesh units) on both sides and inside it: 0 for a surface that
    does not cross itself (what a slicer needs), hundreds for a posed hand's raw skin. The
    tolerance ignores the rounding of an STL's 32-bit coordinates."""
    from scipy.spatial import cKDTree

    v, f = np.asarray(vertices, float), np.asarray(faces, np.int64)
    edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1), axis=0)
    tri = v[f]
    centre = tri.mean(1)
    reach = np.linalg.norm(tri - centre[:, None], axis=2).max(1)
    mid = v[edges].mean(1)
    half = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1) / 2
    # Candidate (edge, triangle) pairs by bounding spheres; edges and triangles bucketed by
    # size so a few large ones (a print's board) do not widen every search.
    edge_bucket = np.floor(np.log2(np.maximum(half, 1e-12))).astype(int)
    tri_bucket = np.floor(np.log2(np.maximum(reach, 1e-12))).astype(int)
    pairs_e, pairs_t = [], []
    for ke in np.unique(edge_bucket):
        e_members = np.flatnonzero(edge_bucket == ke)
        e_tree = cKDTree(mid[e_members])
        for kt in np.unique(tri_bucket):
            t_members = np.flatnonzero(tri_bucket == kt)
            near = e_tree.sparse_distance_matrix(
                cKDTree(centre[t_members]), half[e_members].max() + reach[t_members].max(), output_type="ndarray"
            )
            e, t = e_members[near["i"]], t_members[near["j"]]
            close = near["v"] <= half[e] + reach[t]
            pairs_e.append(e[close])
            pairs_t.append(t[close])
    e, t = np.concatenate(pairs_e), np.concatenate(pairs_t)
    lo, hi = tri.min(1), tri.max(1)
    e_lo, e_hi = np.minimum(v[edges[:, 0]], v[edges[:, 1]]), np.maximum(v[edges[:, 0]], v[edges[:, 1]])
    keep = (e_lo[e] <= hi[t]).all(1) & (e_hi[e] >= lo[t]).all(1)
    keep &= (f[t] != edges[e, 0:1]).all(1) & (f[t] != edges[e, 1:2]).all(1)
    e, t = e[keep], t[keep]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(normal, axis=1)
    unit = normal / np.maximum(area2, 1e-300)[:, None]
    d0 = ((v[edges[e, 0]] - tri[t, 0]) * unit[t]).sum(1)
    d1 = ((v[edges[e, 1]] - tri[t, 0]) * unit[t]).sum(1)
    crosses = (d0 * d1 < 0) & (np.minimum(abs(d0), abs(d1)) > tolerance) & (area2[t] > 0)
    e, t, d0, d1 = e[crosses], t[crosses], d0[crosses], d1[crosses]
    p0, p1 = v[edges[e, 0]], v[edges[e, 1]]
    x = p0 + (d0 / (d0 - d1))[:, None] * (p1 - p0)
    inside = np.ones(len(e), bool)
    for i, j in ((0, 1), (1, 2), (2, 0)):  # distance inside each edge line, within the plane
        side = np.cross(unit[t], tri[t, j] - tri[t, i])
        inside &= ((x - tri[t, i]) * side).sum(1) / np.maximum(np.linalg.norm(side, axis=1), 1e-300) > tolerance
    return len(np.unique(e[inside]))
