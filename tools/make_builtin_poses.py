"""Regenerate the built-in poses (src/handshadow/data/poses/*.json) from readable definitions.

Angles: per finger (J1, J2, J3) x (twist, spread, bend) degrees; global rotation as XYZ Euler
degrees applied to the hand frame (y distal, z dorsal); translation = wrist position, metres.
Run:  .venv/bin/python tools/make_builtin_poses.py
"""

import json

import numpy as np
from scipy.spatial.transform import Rotation

from handshadow.examples import POSES
from handshadow.scene import Scene

FINGERS = ("thumb", "index", "middle", "ring", "little")


def hand(side, euler_deg, translation, fingers=None):
    pose = np.zeros((15, 3))
    for name, joints in (fingers or {}).items():
        f = FINGERS.index(name)
        pose[3 * f : 3 * f + 3] = np.asarray(joints, float)
    return {
        "side": side,
        "model": "anny",
        "shape": {},
        "pose_deg": pose.round(3).tolist(),
        "rotation": Rotation.from_euler("xyz", euler_deg, degrees=True).as_matrix().round(9).tolist(),
        "translation": list(translation),
    }


SPREAD = {
    "index": [[0, 8, 0], [0, 0, 0], [0, 0, 0]],
    "ring": [[0, -6, 0], [0, 0, 0], [0, 0, 0]],
    "little": [[0, -14, 0], [0, 0, 0], [0, 0, 0]],
    "thumb": [[0, 10, 0], [0, 0, 0], [0, 0, 0]],
}

POSE_SETS = {
    "open-hand": (
        "One right hand, fingers up and slightly spread.",
        [hand("right", (0, 0, 0), (0.0, -0.12, 1.0), SPREAD)],
    ),
    "two-hands": (
        "Both hands raised, fingers spread, thumbs almost touching.",
        [
            hand("left", (0, 0, -18), (-0.085, -0.12, 1.0), SPREAD),
            hand("right", (0, 0, 18), (0.085, -0.12, 1.0), SPREAD),
        ],
    ),
}

if __name__ == "__main__":
    POSES.mkdir(parents=True, exist_ok=True)
    scene = Scene.default(256, 256).to_json()
    for name, (about, hands) in POSE_SETS.items():
        data = {"format": "handshadow.pose/1", "about": about, "scene": scene, "forearm": True, "hands": hands}
        (POSES / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")
        print("wrote", POSES / f"{name}.json")
