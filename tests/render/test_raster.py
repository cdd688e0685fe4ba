"""The span rasteriser against a brute-force point-in-triangle test at every pixel centre."""

import numpy as np
import pytest
import torch

from handshadow.render.raster import coverage, fragments, rasterize_spans, winding_coverage
from handshadow.render.shadow import MeshTopology, shadow_mask


def brute_force(tri: np.ndarray, height: int, width: int) -> np.ndarray:
    """(F, 3, 2) triangles -> (H, W) bool: pixel centre inside (or on) any triangle."""
    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    p = np.stack([jj, ii], -1)[..., None, :]  # (H, W, 1, 2)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]

    def side(u, v):
        return (v[..., 0] - u[..., 0]) * (p[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (p[..., 0] - u[..., 0])

    s1, s2, s3 = side(a, b), side(b, c), side(c, a)
    inside = ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
    area = np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    return (inside & (area > 0)).any(-1)


@pytest.mark.parametrize("seed", range(4))
def test_coverage_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    h, w = 37, 53
    # Random triangles, some off-image, some tiny, some degenerate, corners on pixel centres.
    tri = rng.uniform(-10, 60, size=(40, 3, 2))
    tri[:5] = np.round(tri[:5]) + 0.5
    tri[5:10] = tri[5:10, :1] + rng.uniform(-1, 1, (5, 3, 2))
    tri[10, 2] = tri[10, 0]
    mask = coverage(rasterize_spans(torch.as_tensor(tri)[None], h, w), 1, h, w)[0].numpy()
    assert np.array_equal(mask, brute_force(tri, h, w))


@pytest.mark.parametrize("seed", range(3))
def test_winding_of_triangle_boundaries_covers_their_union(seed):
    """Triangles all run one way (negative cross product, as front faces do), their edges
    given as directed chains: the winding coverage is their union, per batch item."""
    rng = np.random.default_rng(seed)
    h, w = 41, 37
    tri = rng.uniform(-8, 48, size=(2, 25, 3, 2))
    e1, e2 = tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :]
    flip = (e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]) > 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    start = torch.as_tensor(tri.reshape(-1, 3, 2))
    end = start[:, [1, 2, 0]]
    batch = torch.arange(2).repeat_interleave(25 * 3)
    got = winding_coverage(start.reshape(-1, 2), end.reshape(-1, 2), batch, 2, h, w).numpy()
    for b in range(2):
        assert np.array_equal(got[b], brute_force(tri[b], h, w))


def test_fragments_list_each_covered_pixel_of_each_triangle():
    tri = torch.tensor(
        [[[[1.0, 1.0], [9.0, 2.0], [3.0, 8.0]], [[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]]]], dtype=torch.float64
    )
    b, face, row, col = fragments(rasterize_spans(tri, 10, 10))
    for f in range(2):
        got = np.zeros((10, 10), bool)
        got[row[face == f].numpy(), col[face == f].numpy()] = True
        assert np.array_equal(got, brute_force(tri[0, f : f + 1].numpy(), 10, 10))


def test_closed_mesh_culling_keeps_the_exact_shadow(hands64):
    """Front faces alone give the same shadow as all faces (closed meshes)."""
    hand = hands64["right"]
    verts = hand(hand.rest_pose()).vertices[:, :, :2] * 300 + 64
    topo = MeshTopology.from_faces(hand.faces)
    culled = shadow_mask(verts, topo, 128, 128)
    everything = coverage(rasterize_spans(verts[:, hand.faces], 128, 128), 1, 128, 128)
    assert topo.closed and torch.equal(culled.bool(), everything)


def test_posed_hands_shadow_from_their_outline_equals_every_triangle(hands64, rng):
    """The shadow of oriented closed meshes comes from their outline edges alone
    (raster.winding_coverage); it equals rasterising every triangle, pixel for pixel, for two
    posed hands in a batch, partly out of the frame; a mesh with a face turned round is not
    oriented and is rasterised triangle by triangle."""
    from tests.conftest import random_pose, random_rotation

    right, left = hands64["right"], hands64["left"]
    rot = torch.cat([random_rotation(rng, 180.0) for _ in range(6)])
    verts = [
        hand(random_pose(rng, batch=6), rot, torch.as_tensor(rng.normal(0, 0.05, (6, 3)))).vertices
        for hand in (right, left)
    ]
    faces = torch.cat([right.faces, left.faces + verts[0].shape[1]])
    xy = torch.cat(verts, 1)[..., :2] * torch.as_tensor(rng.uniform(150, 400, (6, 1, 1))) + 48
    topo = MeshTopology.from_faces(faces)
    assert topo.oriented
    fast = shadow_mask(xy, topo, 96, 112)
    everything = coverage(rasterize_spans(xy[:, faces], 96, 112), 6, 96, 112)
    assert torch.equal(fast.bool(), everything)
    assert 0 < int(everything.sum()) < everything.numel() and not bool(everything[:, 0].all())
    turned = faces.clone()
    turned[0] = turned[0, [0, 2, 1]]
    assert not MeshTopology.from_faces(turned).oriented


def test_a_triangle_whose_normal_points_at_the_lamp_faces_the_light():
    from handshadow.render.shadow import front_facing
    from handshadow.scene import Scene

    scene = Scene.default(64, 64)  # lamp at z = 2, wall at z = 0
    tri = torch.tensor([[[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 1.0]]], dtype=torch.float64)
    normal = torch.linalg.cross(tri[0, 1] - tri[0, 0], tri[0, 2] - tri[0, 0])
    assert float(normal[2]) > 0  # counter-clockwise about +z: it faces the lamp
    xy, _ = scene.project(tri)
    assert bool(front_facing(xy[:, None])[0, 0])
    assert not bool(front_facing(xy[:, None, [0, 2, 1]])[0, 0])  # the same triangle turned away


def test_facing_gathered_by_vertex_is_front_facing_to_the_bit():
    """shadow.facing_of (corners picked vertex-major, the renderer's fast path) gives exactly
    front_facing of the gathered triangles, and contour_edges the pairs a direct test lists."""
    from handshadow.render.shadow import contour_edges, facing_of, front_facing

    rng = np.random.default_rng(3)
    points = torch.as_tensor(rng.uniform(0, 64, (5, 40, 2)))
    faces = torch.as_tensor(rng.integers(0, 40, (90, 3)))
    faces[:4] = torch.tensor([[0, 1, 1], [2, 2, 2], [3, 4, 5], [5, 4, 3]])  # degenerate, reversed
    facing = facing_of(points, faces)
    assert torch.equal(facing, front_facing(points[:, faces]))
    assert 0 < int(facing.sum()) < facing.numel()
    topology = MeshTopology.from_faces(faces)
    b, e = contour_edges(facing, topology)
    f0, f1 = topology.edge_faces[:, 0], topology.edge_faces[:, 1]
    direct = (facing[:, f0] != facing[:, f1.clamp(min=0)]) | (f1 < 0)
    assert torch.equal(torch.stack([b, e]), torch.stack(torch.nonzero(direct, as_tuple=True)))
    assert 0 < b.numel() < direct.numel()
