"""HandModel on the Anny backend: conventions, forearm, batching, gradients."""

import numpy as np
import pytest
import torch
import trimesh

from handshadow.hands import JOINT_NAMES, load_hand
from handshadow.hands.kinematics import (
    anatomical_rotations,
    apply_rigid,
    linear_blend_skinning,
    rotations_to_anatomical,
)
from tests.conftest import random_pose, random_rotation

FINGER_JOINTS = {
    f: [JOINT_NAMES.index(f"{f}{k}") for k in (1, 2, 3)] for f in ("thumb", "index", "middle", "ring", "little")
}
TIP = {"thumb": 4, "index": 8, "middle": 12, "ring": 16, "little": 20}


@pytest.mark.parametrize("side", ["right", "left"])
def test_positive_bend_moves_each_finger_toward_the_palm(hands64, side):
    hand = hands64[side]
    rest = hand(hand.rest_pose())
    palm_centre = rest.keypoints[0, [0, 5, 9, 13, 17]].mean(0) + torch.tensor([0, 0, -0.03], dtype=torch.float64)
    for finger, joints in FINGER_JOINTS.items():
        for j in joints:
            pose = hand.rest_pose()
            pose[0, j, 2] = np.radians(30)
            bent = hand(pose)
            move = bent.keypoints[0, TIP[finger]] - rest.keypoints[0, TIP[finger]]
            # The tip moves toward the palm side (-z, volar) and closer to the palm's centre.
            if finger != "thumb":
                assert move[2] < -1e-3, (side, JOINT_NAMES[j], move)
            before = (rest.keypoints[0, TIP[finger]] - palm_centre).norm()
            after = (bent.keypoints[0, TIP[finger]] - palm_centre).norm()
            assert after < before - 1e-3, (side, JOINT_NAMES[j])


def test_same_angles_give_mirror_image_hands(hands64, rng):
    from scipy.spatial import cKDTree

    pose = random_pose(rng)
    n = hands64["right"].num_hand_vertices
    right = hands64["right"](pose).vertices[0].numpy() * np.array([-1.0, 1.0, 1.0])
    left = hands64["left"](pose).vertices[0].numpy()
    assert np.abs(right[:n] - left[:n]).max() < 1e-9  # Anny's hands share their vertex order
    assert cKDTree(left[n:]).query(right[n:])[0].max() < 1e-9  # forearm rings run either way


def test_hand_frame_conventions(hands64):
    right = hands64["right"](hands64["right"].rest_pose())
    kp = right.keypoints[0]
    assert torch.allclose(kp[0], torch.zeros(3, dtype=torch.float64))  # wrist at the origin
    assert kp[12, 1] > 0.15  # middle tip along +y, about 18 cm
    assert kp[4, 0] < -0.03 and kp[20, 0] > 0.03  # right thumb on -x, little finger on +x


@pytest.mark.parametrize("forearm", [True, False])
def test_meshes_are_closed_and_outward(forearm):
    hand = load_hand("anny", "right", forearm=forearm, dtype=torch.float64)
    mesh = trimesh.Trimesh(hand.rest_vertices.numpy(), hand.faces.numpy(), process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0


def test_forearm_is_long_rigid_and_joined_smoothly(hands64, rng):
    hand = hands64["right"]
    n = hand.num_hand_vertices
    rot = random_rotation(rng, 90)
    trans = torch.tensor([[0.1, -0.2, 0.9]], dtype=torch.float64)
    posed = hand(random_pose(rng), rot, trans).vertices[0]
    forearm = posed[n:]
    rest_forearm = hand.rest_vertices[n:]
    # The forearm follows the global transform only, whatever the finger pose.
    assert torch.allclose(forearm, rest_forearm @ rot[0].T + trans[0], atol=1e-12)
    # It reaches 25-35 cm from the wrist, back along -y of the hand frame.
    assert 0.25 < -rest_forearm[:, 1].min() < 0.35
    # Joined smoothly: no edge of the first forearm ring is much longer than the wrist loop's.
    loop = hand.rig.wrist_loop
    loop_pts = hand.rest_vertices[loop]
    ring = hand.rest_vertices[n : n + len(loop)]
    assert (ring - loop_pts).norm(dim=1).max() < 0.01


def test_batch_matches_single_and_gradients_flow(hands64, rng):
    hand = hands64["left"]
    pose = random_pose(rng, batch=3).requires_grad_(True)
    rot = torch.cat([random_rotation(rng) for _ in range(3)])
    trans = torch.randn(3, 3, dtype=torch.float64) * 0.1
    out = hand(pose, rot, trans)
    for b in range(3):
        single = hand(pose[b : b + 1], rot[b : b + 1], trans[b : b + 1])
        assert torch.allclose(single.vertices[0], out.vertices[b], atol=1e-12)
    out.vertices.sum().backward()
    assert torch.isfinite(pose.grad).all() and pose.grad.abs().sum() > 0


def test_posing_in_one_matrix_product_equals_blending_then_moving(hands64, rng):
    """The world-frame vertices come from one skinning pass with the global rotation and
    translation folded into the bones; they equal skinning in the hand frame (the per-vertex
    blend form, taken for a batch of rest shapes) and then moving the hand rigidly."""
    hand = hands64["right"]
    pose = random_pose(rng, batch=4)
    rot = torch.cat([random_rotation(rng, 150.0) for _ in range(4)])
    trans = torch.randn(4, 3, dtype=torch.float64)
    wrist = torch.as_tensor(rng.uniform(-0.6, 0.6, (4, 2)))
    out = hand(pose, rot, trans, wrist)
    local = hand(pose, wrist_rad=wrist)
    rest = hand.rest_vertices.expand(4, -1, -1)  # a batch of rest shapes takes the blend form
    blended = linear_blend_skinning(rest, hand.skin_weights, local.bone_rotations, local.bone_translations)
    assert torch.allclose(blended, local.vertices, atol=1e-12)
    assert torch.allclose(apply_rigid(blended, rot, trans), out.vertices, atol=1e-12)
    assert torch.allclose(apply_rigid(local.keypoints, rot, trans), out.keypoints, atol=1e-12)
    assert torch.equal(out.bone_rotations, local.bone_rotations)  # bones stay in the hand frame


def test_anatomical_angles_round_trip(hands64, rng):
    axes = hands64["right"].joint_axes
    pose = random_pose(rng, batch=4)
    back = rotations_to_anatomical(anatomical_rotations(pose, axes), axes)
    assert torch.allclose(back, pose, atol=1e-9)


def test_bad_pose_shape_is_refused(hands64):
    with pytest.raises(ValueError, match="shape"):
        hands64["right"](torch.zeros(1, 16, 3, dtype=torch.float64))


def test_rodrigues_matches_roma_and_is_smooth_at_zero():
    roma = pytest.importorskip("roma")
    from handshadow.hands.kinematics import rotvec_to_rotmat

    r = torch.randn(64, 3, dtype=torch.float64) * 2
    r[:4] *= 1e-7  # tiny angles take the series branch
    assert torch.allclose(rotvec_to_rotmat(r), roma.rotvec_to_rotmat(r), atol=1e-12)
    zero = torch.zeros(1, 3, dtype=torch.float64, requires_grad=True)
    rotvec_to_rotmat(zero).sum().backward()
    assert torch.isfinite(zero.grad).all()
    assert torch.autograd.gradcheck(rotvec_to_rotmat, (torch.randn(3, 3, dtype=torch.float64, requires_grad=True),))
