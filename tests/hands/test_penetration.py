"""The exact penetration test on meshes: hand-made boxes, a hand pushed into the other at a
known depth, fists, and the finishing step that parts a penetrating result."""

import igl
import numpy as np
import pytest
import torch
import trimesh

from handshadow.hands.penetration import (
    TOLERANCE_MM,
    Hull,
    contact_penalty,
    hand_parts,
    penetration,
    winding_inside,
)


def _box(size, centre):
    m = trimesh.creation.box(extents=size)
    return np.asarray(m.vertices) + centre, np.asarray(m.faces)


@pytest.mark.parametrize("overlap_mm, performable", [(5.0, False), (1.0, True)])
def test_boxes_overlapping_by_5_mm_fail_and_by_1_mm_pass(overlap_mm, performable):
    a = _box([0.1, 0.1, 0.1], [0.0, 0.0, 0.0])
    # A smaller box whose face reaches overlap_mm into the first one: its corners are that deep.
    b = _box([0.06, 0.06, 0.06], [0.05 + 0.03 - overlap_mm / 1000, 0.0, 0.0])
    pen = penetration([a[0], b[0]], [a[1], b[1]])
    assert pen.between_mm == pytest.approx(overlap_mm, abs=1e-6)
    assert pen.performable() is performable
    # Apart, nothing is inside.
    c = _box([0.06, 0.06, 0.06], [0.2, 0.0, 0.0])
    assert penetration([a[0], c[0]], [a[1], c[1]]).between_mm == 0.0


def test_boxes_turned_off_the_axes_overlap_as_deep():
    # The test looks for inside points in a box along the surface's own axes: turned boxes
    # (a rod across the frame's axes) must give the depth they give unturned.
    turn = trimesh.transformations.rotation_matrix(0.7, [1.0, 2.0, 0.5])[:3, :3]
    a = _box([0.2, 0.02, 0.02], [0.0, 0.0, 0.0])
    b = _box([0.06, 0.06, 0.06], [0.1 + 0.03 - 0.004, 0.0, 0.0])
    pen = penetration([a[0] @ turn.T, b[0] @ turn.T], [a[1], b[1]])
    assert pen.between_mm == pytest.approx(4.0, abs=1e-6)


def test_a_hull_holds_its_surface_but_not_the_empty_corners_of_its_axis_aligned_box():
    rod = trimesh.creation.box(extents=[0.2, 0.02, 0.02])
    rod.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 4, [0, 0, 1]))
    hull = Hull.of(np.asarray(rod.vertices))
    assert hull.holds(np.asarray(rod.sample(500, seed=0))).all()
    corner = np.asarray(rod.vertices).max(0)  # a corner of the axis-aligned box, far off the rod
    assert not hull.holds(corner[None])[0]


def test_the_fast_inside_test_answers_as_the_exact_winding_number_near_and_far_from_the_skin(hands64):
    right = hands64["right"]
    out = right(right.rest_pose())
    verts, faces = out.vertices[0].double().numpy(), right.faces.numpy()
    rng = np.random.default_rng(0)
    normals = trimesh.Trimesh(verts, faces, process=False).vertex_normals
    # Points off every vertex along its normal, from 3 mm inside to 3 mm outside (where the
    # approximation is least sure), and points scattered over and around the hand's box.
    offsets = rng.uniform(-0.003, 0.003, len(verts))[:, None]
    near = verts + offsets * normals
    lo, hi = verts.min(0) - 0.02, verts.max(0) + 0.02
    far = rng.uniform(lo, hi, (4000, 3))
    points = np.concatenate([near, far])
    exact = igl.winding_number(verts, faces, points) > 0.5
    assert 0.2 < exact.mean() < 0.8  # both answers are well represented
    assert np.array_equal(winding_inside(verts, faces, points), exact)


@pytest.fixture(scope="module")
def right_and_left(hands64):
    return hands64["right"], hands64["left"]


@pytest.mark.parametrize("depth_mm", [2.0, 6.0, 12.0])
def test_a_finger_pushed_into_the_other_palm_is_found_at_its_depth(right_and_left, depth_mm):
    right, left = right_and_left
    a = right(right.rest_pose()).vertices[0].numpy()
    faces_a = right.faces.numpy()
    # A point on the right palm's skin and its outward normal (the palm side faces -z in the hand frame).
    palm_centre = a[hand_parts(right).palm.vertices].mean(0)
    sq, tri, closest = _nearest(palm_centre + np.array([0.0, 0.0, -0.1]), a, faces_a)
    t = a[faces_a[tri]]
    normal = np.cross(t[1] - t[0], t[2] - t[0])
    normal /= np.linalg.norm(normal)
    # The left hand points its index finger straight at that point, its tip depth_mm inside.
    out = left(left.rest_pose())
    b = out.vertices[0].numpy()
    tip = out.keypoints[0, 8].numpy()  # index fingertip
    along = tip - out.keypoints[0, 5].numpy()
    rot = _rotation_from_to(along / np.linalg.norm(along), -normal)
    b = (b - tip) @ rot.T
    extreme = b[np.argmax(b @ -normal)]  # the vertex that reaches farthest toward the palm
    b = b - extreme + closest - normal * depth_mm / 1000
    pen = penetration([a, b], [faces_a, left.faces.numpy()])
    assert pen.between_mm == pytest.approx(depth_mm, abs=0.5)


def _nearest(point, v, f):
    import igl

    sq, tri, closest = igl.point_mesh_squared_distance(point[None], v, f.astype(np.int64))
    return sq[0], tri[0], closest[0]


def _rotation_from_to(u, v):
    axis = np.cross(u, v)
    s, c = np.linalg.norm(axis), u @ v
    if s < 1e-12:
        return np.eye(3)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]]) / s
    return np.eye(3) + s * k + (1 - c) * k @ k


def test_a_tight_fist_passes_into_its_palm_and_an_open_one_does_not(right_and_left):
    right, _ = right_and_left
    parts = hand_parts(right)
    assert all(len(p.loops) == 1 for p in parts.fingers) and len(parts.palm.loops) == 5

    def fist(scale):
        pose = right.rest_pose()
        for f in range(1, 5):
            pose[0, 3 * f : 3 * f + 3, 2] = torch.tensor(np.radians([80.0, 95.0, 60.0])) * scale
        return right(pose).vertices[0].numpy()

    tight = fist(1.0)
    found = penetration([tight], [right.faces.numpy()], [parts])
    assert found.within_mm[0] > 10
    # Each contact names, in the hand's own vertex indices, a triangle of another part's skin
    # whose nearest point lies at the contact's depth from the vertex.
    c = found.contacts
    nearest = (c.bary[:, :, None] * tight[c.corners]).sum(1)
    assert np.allclose(np.linalg.norm(nearest - tight[c.vertex], axis=1), c.depth_m, atol=1e-9)
    owner = np.full(len(tight), -1)
    for k, part in enumerate((*parts.fingers, parts.palm)):
        owner[part.vertices] = k
    skins = [set(map(tuple, np.sort(p.faces, 1))) for p in (*parts.fingers, parts.palm)]
    for vertex, corners in zip(c.vertex, np.sort(c.corners, 1)):
        holder = [k for k, skin in enumerate(skins) if tuple(corners) in skin]
        assert holder and owner[vertex] not in holder
    assert penetration([fist(0.0)], [right.faces.numpy()], [parts]).within_mm[0] == 0.0
    assert penetration([fist(0.6)], [right.faces.numpy()], [parts]).within_mm[0] <= TOLERANCE_MM


def test_the_contact_penalty_pushes_an_inside_vertex_out():
    a = _box([0.1, 0.1, 0.1], [0.0, 0.0, 0.0])
    b = _box([0.06, 0.06, 0.06], [0.075, 0.0, 0.0])  # 5 mm inside
    pen = penetration([a[0], b[0]], [a[1], b[1]])
    verts = [torch.as_tensor(a[0])[None], torch.as_tensor(b[0])[None].requires_grad_(True)]
    cost = contact_penalty(verts, pen.contacts, margin_m=0.0)
    assert float(cost[0].detach()) > 0
    cost.sum().backward()
    push = -verts[1].grad[0][pen.contacts.vertex[pen.contacts.mesh == 1]]
    assert (push[:, 0] > 0).all()  # out along the first box's +x face
