"""Reading and checking pose files (the types are in :mod:`handshadow.poses`).

pose.json holds the hands of a result (per hand its side, model, shape, joint angles, global
rotation and translation) plus the scene, as written by ``fit`` and read by ``render``:

    {"format": "handshadow.pose/1",
     "scene": {...scene.json contract without "meshes"...},  # or a list of views, view 0 first
     "forearm": true,
     "hands": [{"side": "right", "model": "anny", "shape": {...},
                "pose_deg": [[twist, spread, bend] x 15],   # rig.JOINT_NAMES order, degrees
                "wrist_deg": [flexion, deviation],           # optional, degrees
                "rotation": [[...], [...], [...]],           # hand frame -> world, row-major
                "translation": [x, y, z]},                   # wrist position, metres
               ...],
     "fit": {...}}                                           # optional: IoU, iterations, ...

Joint angles follow docs/conventions.md: positive bend flexes toward the palm, positive spread
moves toward the thumb, on either hand.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from handshadow.errors import HandshadowError
from handshadow.hands.limits import wrap_degrees
from handshadow.hands.rig import JOINT_NAMES, check_side
from handshadow.poses import FORMAT, HandPose, PosedScene
from handshadow.scene import Scene, SceneError, views_from_json

PATH_FORMAT = "handshadow.poses/1"  # interpolate's poses.json: a scene and a list of frames


class PoseFileError(HandshadowError):
    """A pose file that cannot be read."""


def load_pose_file(path: str | Path, frame: int = 0) -> PosedScene:
    """Read and check a pose file (pose.json, or one frame of a poses.json path); raises
    PoseFileError with a one-line reason."""
    path = Path(path)
    if not path.is_file():
        raise PoseFileError(f"pose file not found: {path}")
    try:
        data = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PoseFileError(f"{path} is not a JSON pose file ({exc.__class__.__name__}: {exc})") from None
    if isinstance(data, dict) and data.get("format") == PATH_FORMAT:
        frames = data.get("frames")
        if not isinstance(frames, list) or not frames:
            raise PoseFileError(f"{path}: 'frames' must be a non-empty list")
        if not -len(frames) <= frame < len(frames):
            raise PoseFileError(f"{path} has {len(frames)} frames; --frame {frame} is out of range")
        data = {"scene": data.get("scene"), "forearm": data.get("forearm", True), **frames[frame]}
        if data["scene"] is None:
            del data["scene"]
    return parse_pose(data, str(path))


def parse_pose(data, where: str = "pose") -> PosedScene:
    if not isinstance(data, dict):
        raise PoseFileError(f"{where}: expected a JSON object")
    if data.get("format", FORMAT) != FORMAT:
        raise PoseFileError(f"{where}: unsupported format {data.get('format')!r} (expected {FORMAT!r})")
    try:
        views = views_from_json(data["scene"]) if "scene" in data else [Scene.default()]
    except SceneError as exc:
        raise PoseFileError(f"{where}: scene: {exc}") from None
    hands_data = data.get("hands")
    if not isinstance(hands_data, list) or not 1 <= len(hands_data) <= 2:
        raise PoseFileError(f"{where}: 'hands' must be a list of one or two hands")
    hands = tuple(_parse_hand(h, f"{where}: hands[{i}]") for i, h in enumerate(hands_data))
    if len(hands) == 2 and hands[0].side == hands[1].side:
        raise PoseFileError(f"{where}: two hands must be one left and one right")
    forearm = data.get("forearm", True)
    if not isinstance(forearm, bool):
        raise PoseFileError(f"{where}: 'forearm' must be true or false")
    fit = data.get("fit")
    unknown = set(data) - {"format", "about", "scene", "forearm", "hands", "fit", "iou_a", "iou_b"}
    if unknown:
        raise PoseFileError(f"{where}: unknown field(s) {', '.join(sorted(unknown))}")
    fit = fit if isinstance(fit, dict) else None
    return PosedScene(hands=hands, scene=views[0], forearm=forearm, fit=fit, more_views=tuple(views[1:]))


def _parse_hand(h, where: str) -> HandPose:
    if not isinstance(h, dict):
        raise PoseFileError(f"{where}: expected an object")
    try:
        side = check_side(h.get("side"))
    except ValueError as exc:
        raise PoseFileError(f"{where}: {exc}") from None
    model = h.get("model", "anny")
    if model not in ("anny", "mano"):
        raise PoseFileError(f"{where}: model must be 'anny' or 'mano', got {model!r}")
    shape = h.get("shape") or {}
    if not isinstance(shape, dict):
        raise PoseFileError(f"{where}: shape must be an object")
    # A joint turns alike every 360 degrees: 370 is read as 10, as the guide and the limits see it.
    pose = wrap_degrees(_array(h.get("pose_deg", np.zeros((15, 3))), (len(JOINT_NAMES), 3), f"{where}.pose_deg"))
    rotation = _array(h.get("rotation", np.eye(3)), (3, 3), f"{where}.rotation")
    u, sv, vt = np.linalg.svd(rotation)
    if np.abs(sv - 1).max() > 1e-3 or np.linalg.det(rotation) < 0:
        raise PoseFileError(f"{where}.rotation must be a rotation matrix (orthonormal, det +1)")
    rotation = u @ vt
    translation = _array(h.get("translation"), (3,), f"{where}.translation")
    wrist = wrap_degrees(_array(h.get("wrist_deg", np.zeros(2)), (2,), f"{where}.wrist_deg"))
    return HandPose(side, model, shape, pose, rotation, translation, wrist)


def _array(value, shape, where: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise PoseFileError(f"{where} must be numbers of shape {shape}") from None
    if arr.shape != shape:
        raise PoseFileError(f"{where} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise PoseFileError(f"{where} must be finite")
    if np.abs(arr).max(initial=0.0) > 1e4:
        raise PoseFileError(f"{where} has implausibly large values")
    return arr
