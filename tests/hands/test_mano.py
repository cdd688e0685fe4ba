"""The MANO backend on a synthetic file of the official structure (the real one cannot ship)."""

import io
import os
import pickle

import numpy as np
import pytest
import torch

from handshadow.hands import load_hand, load_rig
from handshadow.hands.mano import (
    MANO_JOINTS,
    ManoFileError,
    SafeManoUnpickler,
    mano_hands_mean,
    mano_pose_rotations,
    read_mano_file,
)
from tests.hands.fake_mano import synthetic_mano_arrays, write_synthetic_mano


@pytest.fixture(scope="module")
def mano_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("mano")
    write_synthetic_mano(d / "MANO_RIGHT.pkl", "right")
    write_synthetic_mano(d / "MANO_LEFT.pkl", "left")
    return d


def numpy_mano(data, betas, pose45, flat_hand_mean=True):
    """MANO forward written out directly in numpy (Romero et al. 2017), native frame."""
    v = data["v_template"] + data["shapedirs"] @ betas
    joints = data["J_regressor"] @ v
    full = pose45.reshape(15, 3) + (0 if flat_hand_mean else data["hands_mean"].reshape(15, 3))
    rots = [np.eye(3)] + [_rodrigues(p) for p in full]
    feature = np.concatenate([(r - np.eye(3)).ravel() for r in rots[1:]])
    v = v + data["posedirs"] @ feature
    parents = data["kintree_table"][0].astype(np.int64)
    world = [None] * 16
    for k in range(16):
        local = np.eye(4)
        local[:3, :3] = rots[k]
        local[:3, 3] = joints[k] - (joints[parents[k]] if k else 0)
        world[k] = local if k == 0 else world[parents[k]] @ local
    skin = []
    for k in range(16):
        a = world[k].copy()
        a[:3, 3] -= a[:3, :3] @ joints[k]
        skin.append(a)
    blended = np.einsum("vk,kij->vij", data["weights"], np.stack(skin))
    return np.einsum("vij,vj->vi", blended[:, :3, :3], v) + blended[:, :3, 3]


def _rodrigues(r):
    angle = np.linalg.norm(r)
    if angle < 1e-12:
        return np.eye(3)
    k = r / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def test_reader_returns_the_arrays(mano_dir):
    data = read_mano_file(mano_dir / "MANO_RIGHT.pkl")
    ref = synthetic_mano_arrays("right")
    assert np.array_equal(data["v_template"], ref["v_template"])  # through chumpy Select
    assert np.array_equal(data["shapedirs"], ref["shapedirs"])  # through chumpy Ch
    assert np.allclose(data["J_regressor"].toarray(), ref["J_regressor"].toarray())  # scipy csc
    assert data["posedirs"].shape == (ref["v_template"].shape[0], 3, 135)


@pytest.mark.parametrize("flat_hand_mean", [True, False])
def test_blend_skinning_equals_direct_numpy(mano_dir, rng, flat_hand_mean):
    side = "right"
    data = read_mano_file(mano_dir / "MANO_RIGHT.pkl")
    betas = rng.normal(scale=0.8, size=10)
    pose45 = rng.normal(scale=0.4, size=45)
    expected = numpy_mano(data, betas, pose45, flat_hand_mean)

    rig = load_rig("mano", side, {"betas": betas.tolist()}, str(mano_dir))
    hand = load_hand("mano", side, {"betas": betas.tolist()}, str(mano_dir), forearm=False, dtype=torch.float64)
    mean = None if flat_hand_mean else mano_hands_mean(mano_dir, side)
    rots = mano_pose_rotations(torch.as_tensor(pose45)[None], rig, mean)
    ours = hand.forward_rotations(rots).vertices[0, : rig.num_vertices].numpy()
    # Back to MANO's native frame: hand frame = C (native - wrist).
    joints = data["J_regressor"] @ (data["v_template"] + data["shapedirs"] @ betas)
    native = ours @ rig.native_rotation + joints[0]
    assert np.abs(native - expected).max() < 1e-9


def test_left_file_gets_the_shapedirs_fix(mano_dir, tmp_path):
    right = load_rig("mano", "right", {"betas": [2.0]}, str(mano_dir)).rest_vertices
    left = load_rig("mano", "left", {"betas": [2.0]}, str(mano_dir)).rest_vertices
    assert np.abs(left * [-1, 1, 1] - right).max() < 1e-9  # mirror images once fixed
    # Without MANO_RIGHT beside it, the fix is still applied (shape-scaling check).
    solo = tmp_path / "solo"
    solo.mkdir()
    write_synthetic_mano(solo / "MANO_LEFT.pkl", "left")
    alone = load_rig("mano", "left", {"betas": [2.0]}, str(solo)).rest_vertices
    assert np.abs(alone - left).max() < 1e-9


def test_positive_bend_flexes_toward_the_palm(mano_dir):
    for side in ("right", "left"):
        hand = load_hand("mano", side, mano_dir=str(mano_dir), dtype=torch.float64)
        rest = hand(hand.rest_pose()).keypoints[0]
        for j, tip in ((3, 8), (6, 12), (9, 16), (12, 20)):  # index..little MCP
            pose = hand.rest_pose()
            pose[0, j, 2] = np.radians(30)
            move = hand(pose).keypoints[0, tip] - rest[tip]
            assert move[2] < -5e-3, (side, j, move)  # toward -z, the palm side


class _Boom:
    def __reduce__(self):
        return (os.system, ("touch /tmp/handshadow-pwned",))


@pytest.mark.parametrize(
    "payload",
    [
        pickle.dumps({"v_template": _Boom()}, protocol=2),
        pickle.dumps({"x": eval}, protocol=2),
        pickle.dumps(np.ma.masked_array([1.0]), protocol=2),  # a numpy class outside the format
    ],
)
def test_any_other_class_is_refused(tmp_path, payload):
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(payload)
    with pytest.raises(ManoFileError, match="refusing to load"):
        read_mano_file(path)
    assert not os.path.exists("/tmp/handshadow-pwned")
    with pytest.raises(pickle.UnpicklingError):
        SafeManoUnpickler(io.BytesIO(payload), encoding="latin1").load()


def test_missing_and_broken_files_give_clear_errors(tmp_path):
    with pytest.raises(ManoFileError, match="MANO_RIGHT.pkl"):
        load_rig("mano", "right", None, str(tmp_path))
    with pytest.raises(ManoFileError, match="--mano-dir"):
        load_rig("mano", "right", None, None)
    (tmp_path / "MANO_RIGHT.pkl").write_bytes(b"not a pickle at all")
    with pytest.raises(ManoFileError, match="not a readable MANO file"):
        load_rig("mano", "right", None, str(tmp_path))


def test_npz_conversion_gives_the_same_hand(mano_dir, tmp_path):
    arrays = synthetic_mano_arrays("right")
    npz = {k: (v.toarray() if hasattr(v, "toarray") else np.asarray(v)) for k, v in arrays.items()}
    np.savez(tmp_path / "MANO_RIGHT.npz", **npz)
    from_npz = load_rig("mano", "right", {"betas": [1.0]}, str(tmp_path))
    from_pkl = load_rig("mano", "right", {"betas": [1.0]}, str(mano_dir))
    assert np.abs(from_npz.rest_vertices - from_pkl.rest_vertices).max() < 1e-12
    assert from_npz.posedirs.shape == (3 * from_npz.num_vertices, 9 * len(MANO_JOINTS))
