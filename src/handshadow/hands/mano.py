"""MANO hands for users who hold the official files (MANO_RIGHT.pkl / MANO_LEFT.pkl, or the
same data converted to .npz). The MANO licence forbids redistribution: nothing of MANO ships here.

The .pkl files are Python-2 pickles holding chumpy objects and a scipy sparse matrix. They are
read without chumpy and without running pickled code: :class:`SafeManoUnpickler` resolves only
the handful of globals the format uses (chumpy ``Ch`` and ``Select`` and scipy's ``csc_matrix``,
all three replaced by inert stand-ins; numpy's array reconstruction; ``set``; the generic
``copyreg._reconstructor`` restricted to the stand-ins) and refuses anything else.

Model (Romero et al. 2017): v = LBS(v_template + shapedirs beta + posedirs (R - I), J(beta), W).
Joint order in the files: 0 wrist, 1-3 index, 4-6 middle, 7-9 little, 10-12 ring, 13-15 thumb.
"""

from __future__ import annotations

import importlib
import pickle
from pathlib import Path

import numpy as np
import scipy.sparse

from handshadow.errors import HandshadowError
from handshadow.hands.forearm import sized_like
from handshadow.hands.rig import HandRig, Side, canonicalise, check_side, fingertip_vertices

# Our joint order (thumb, index, middle, ring, little) -> MANO joint index.
MANO_JOINTS = np.array([13, 14, 15, 1, 2, 3, 4, 5, 6, 10, 11, 12, 7, 8, 9])
N_BETAS = 10


class ManoFileError(HandshadowError):
    """A MANO file that is missing, unreadable or not allowed."""


class RefusedObject(pickle.UnpicklingError):
    """The pickle asked for a global that is not part of the MANO format."""


class _ChStandIn:
    """Inert replacement for chumpy.ch.Ch: keeps the pickled attributes; ``value`` is ``x``."""

    def __setstate__(self, state):
        self.__dict__.update(state if isinstance(state, dict) else {})

    def value(self) -> np.ndarray:
        return np.asarray(self.__dict__.get("x"), dtype=np.float64)


class _SelectStandIn(_ChStandIn):
    """Inert replacement for chumpy.reordering.Select: a.ravel()[idxs], reshaped."""

    def value(self) -> np.ndarray:
        a = _to_array(self.__dict__["a"]).ravel()
        out = a[np.asarray(self.__dict__["idxs"]).ravel()]
        shape = self.__dict__.get("preferred_shape")
        return out.reshape(shape) if shape is not None else out


class _CscStandIn:
    """Inert replacement for scipy.sparse csc_matrix: keeps data/indices/indptr/shape."""

    def __setstate__(self, state):
        self.__dict__.update(state if isinstance(state, dict) else {})

    def value(self) -> scipy.sparse.csc_matrix:
        d = self.__dict__
        shape = d.get("_shape", d.get("shape"))
        return scipy.sparse.csc_matrix(
            (np.asarray(d["data"]), np.asarray(d["indices"]), np.asarray(d["indptr"])), shape=tuple(shape)
        )


_STAND_INS = (_ChStandIn, _SelectStandIn, _CscStandIn)


def _safe_reconstructor(cls, base, state):
    """copyreg._reconstructor limited to our stand-ins on ``object``."""
    if cls not in _STAND_INS or base is not object or state is not None:
        raise RefusedObject("refusing to load: object reconstruction outside the MANO format")
    return cls.__new__(cls)


def _numpy_global(name: str):
    """numpy's array/scalar reconstruction functions (numpy 2 moved them to numpy._core)."""
    try:
        multiarray = importlib.import_module("numpy._core.multiarray")
    except ImportError:  # numpy < 2
        multiarray = importlib.import_module("numpy.core.multiarray")
    return getattr(multiarray, name)


class SafeManoUnpickler(pickle.Unpickler):
    """Unpickler for MANO .pkl files that knows only the classes the format uses."""

    _ALLOWED = {
        ("chumpy.ch", "Ch"): lambda: _ChStandIn,
        ("chumpy.reordering", "Select"): lambda: _SelectStandIn,
        ("scipy.sparse.csc", "csc_matrix"): lambda: _CscStandIn,
        ("scipy.sparse._csc", "csc_matrix"): lambda: _CscStandIn,
        ("copy_reg", "_reconstructor"): lambda: _safe_reconstructor,
        ("copyreg", "_reconstructor"): lambda: _safe_reconstructor,
        ("__builtin__", "object"): lambda: object,
        ("builtins", "object"): lambda: object,
        ("__builtin__", "set"): lambda: set,
        ("builtins", "set"): lambda: set,
        ("numpy", "ndarray"): lambda: np.ndarray,
        ("numpy", "dtype"): lambda: np.dtype,
        ("numpy.core.multiarray", "_reconstruct"): lambda: _numpy_global("_reconstruct"),
        ("numpy._core.multiarray", "_reconstruct"): lambda: _numpy_global("_reconstruct"),
        ("numpy.core.multiarray", "scalar"): lambda: _numpy_global("scalar"),
        ("numpy._core.multiarray", "scalar"): lambda: _numpy_global("scalar"),
    }

    def find_class(self, module, name):
        factory = self._ALLOWED.get((module, name))
        if factory is None:
            raise RefusedObject(f"refusing to load {module}.{name}: not part of the MANO file format")
        return factory()


def _to_array(value) -> np.ndarray:
    if isinstance(value, (_ChStandIn, _CscStandIn)):
        value = value.value()
    if scipy.sparse.issparse(value):
        return value
    return np.asarray(value)


def read_mano_file(path: str | Path) -> dict:
    """The MANO data as plain numpy arrays (J_regressor as a scipy sparse matrix).

    Reads the official .pkl safely or a .npz with the same keys (loaded with allow_pickle=False).
    Raises ManoFileError with a one-line reason.
    """
    path = Path(path)
    if not path.is_file():
        raise ManoFileError(f"MANO file not found: {path}")
    try:
        if path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as npz:
                raw = {k: npz[k] for k in npz.files}
        else:
            with open(path, "rb") as fh:
                raw = SafeManoUnpickler(fh, encoding="latin1").load()
    except RefusedObject as exc:
        raise ManoFileError(f"{path}: {exc}") from None
    except (
        pickle.UnpicklingError,
        EOFError,
        ValueError,
        OSError,
        KeyError,
        TypeError,
        AttributeError,
        IndexError,
    ) as exc:
        raise ManoFileError(f"{path} is not a readable MANO file ({exc.__class__.__name__}: {exc})") from None
    if not isinstance(raw, dict):
        raise ManoFileError(f"{path} is not a MANO model (expected a dict of arrays)")
    data = {k: _to_array(v) for k, v in raw.items()}
    for key in ("v_template", "f", "weights", "posedirs", "shapedirs", "J_regressor", "kintree_table"):
        if key not in data:
            raise ManoFileError(f"{path} is not a MANO model (missing {key!r})")
    return data


def mano_path(mano_dir: str | Path, side: Side) -> Path:
    """MANO_RIGHT/LEFT .pkl (or .npz) in mano_dir; raises ManoFileError if absent."""
    mano_dir = Path(mano_dir)
    stem = "MANO_RIGHT" if side == "right" else "MANO_LEFT"
    for suffix in (".pkl", ".npz"):
        if (mano_dir / (stem + suffix)).is_file():
            return mano_dir / (stem + suffix)
    raise ManoFileError(
        f"no {stem}.pkl or {stem}.npz in {mano_dir} (MANO files must be downloaded from mano.is.tue.mpg.de)"
    )


def fix_left_shapedirs(left: dict, right: dict | None) -> dict:
    """The known MANO_LEFT fix: its shape blend shapes' x component is not mirrored.

    With the right model at hand, flip when the left x component equals the right one (the
    widespread check). Without it, flip when the x displacements of the first shape component
    point the opposite way to the vertices' x positions while y and z agree (a mirrored model
    scales outward on all three axes).
    """
    sd = np.array(left["shapedirs"], dtype=np.float64)
    if right is not None and np.asarray(right["shapedirs"]).shape == sd.shape:
        buggy = np.abs(sd[:, 0, :] - np.asarray(right["shapedirs"])[:, 0, :]).sum() < 1.0
    else:
        centred = left["v_template"] - left["v_template"].mean(0)
        corr = [np.corrcoef(sd[:, k, 0], centred[:, k])[0, 1] for k in range(3)]
        buggy = corr[0] * np.sign(corr[1] + corr[2]) < 0
    if buggy:
        sd[:, 0, :] *= -1
    return {**left, "shapedirs": sd}


def mano_arrays(data: dict, betas: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Rest mesh and skeleton of a MANO model for the given betas, native frame."""
    v_template = np.asarray(data["v_template"], dtype=np.float64)
    shapedirs = np.asarray(data["shapedirs"], dtype=np.float64)
    betas = np.zeros(shapedirs.shape[-1]) if betas is None else np.asarray(betas, dtype=np.float64)
    if betas.shape != (shapedirs.shape[-1],):
        raise ValueError(f"MANO shape must have {shapedirs.shape[-1]} betas, got {betas.shape}")
    v_shaped = v_template + shapedirs @ betas
    joints = np.asarray(data["J_regressor"] @ v_shaped)
    parents = np.asarray(data["kintree_table"], dtype=np.int64)[0].copy()
    parents[0] = -1
    return dict(vertices=v_shaped, joints=joints, parents=parents)


def load_mano_rig(mano_dir: str | Path, side: str = "right", shape=None) -> HandRig:
    """The MANO hand of the given side and betas (``shape``: up to 10 numbers or {"betas": [...]})."""
    side = check_side(side)
    data = read_mano_file(mano_path(mano_dir, side))
    if side == "left":
        try:
            right = read_mano_file(mano_path(mano_dir, "right"))
        except ManoFileError:
            right = None
        data = fix_left_shapedirs(data, right)
    betas = _betas(shape, np.asarray(data["shapedirs"]).shape[-1])
    rig = _rig(data, side, betas)
    # Another shape is sized against the mean hand of the same file (its forearm grows with it).
    return sized_like(rig, _rig(data, side, np.zeros_like(betas))) if betas.any() else rig


def _rig(data: dict, side: Side, betas: np.ndarray) -> HandRig:
    """The HandRig of a read (and, for the left hand, fixed) MANO file for the given betas."""
    arrays = mano_arrays(data, betas)
    weights = np.asarray(data["weights"], dtype=np.float64)
    n_vertices = arrays["vertices"].shape[0]
    posedirs = np.asarray(data["posedirs"], dtype=np.float64).reshape(n_vertices * 3, -1)
    # Reorder the 15 joints' 9 columns each into our joint order.
    cols = (MANO_JOINTS[:, None] - 1) * 9 + np.arange(9)[None]
    posedirs = posedirs[:, cols.ravel()]
    tips = fingertip_vertices(arrays["vertices"], weights, arrays["joints"], MANO_JOINTS)
    return canonicalise(
        side,
        "mano",
        vertices=arrays["vertices"],
        faces=np.asarray(data["f"], dtype=np.int64),
        skin_weights=weights,
        bone_heads=arrays["joints"],
        bone_parents=arrays["parents"],
        joint_bones=MANO_JOINTS,
        wrist_bone=0,
        tip_vertices=tips,
        posedirs=posedirs,
    )


def mano_hands_mean(mano_dir: str | Path, side: str) -> np.ndarray:
    """(15, 3) MANO mean pose (axis-angle, native frame) in our joint order."""
    side = check_side(side)
    data = read_mano_file(mano_path(mano_dir, side))
    mean = np.asarray(data.get("hands_mean", np.zeros(45)), dtype=np.float64).reshape(15, 3)
    return mean[MANO_JOINTS - 1]


def mano_pose_rotations(pose45, rig: HandRig, hands_mean: np.ndarray | None = None):
    """Joint rotations (B, 15, 3, 3) in the hand frame, our joint order, from a native MANO
    pose (B, 45): axis-angle per joint in the file's joint order (index, middle, little, ring,
    thumb), as smplx/manopth take it. ``hands_mean`` (15, 3, our order) is added first, as with
    ``flat_hand_mean=False``; leave it None for ``flat_hand_mean=True``.
    """
    import torch

    from handshadow.hands.kinematics import rotvec_to_rotmat

    pose = pose45.reshape(-1, 15, 3)[:, torch.as_tensor(MANO_JOINTS - 1, device=pose45.device)]
    if hands_mean is not None:
        pose = pose + torch.as_tensor(hands_mean, dtype=pose.dtype, device=pose.device)
    c = torch.as_tensor(rig.native_rotation, dtype=pose.dtype, device=pose.device)
    return c @ rotvec_to_rotmat(pose) @ c.T


def _betas(shape, n: int) -> np.ndarray:
    if shape is None or shape == {}:
        return np.zeros(n)
    if isinstance(shape, dict):
        shape = shape.get("betas", [])
    betas = np.zeros(n)
    values = np.asarray(shape, dtype=np.float64).ravel()
    if len(values) > n:
        raise ValueError(f"MANO shape takes at most {n} betas, got {len(values)}")
    betas[: len(values)] = values
    return betas
