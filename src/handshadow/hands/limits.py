"""Joint-angle limits: (15, 3, 2) [low, high] degrees per joint and axis (twist, spread, bend),
and (2, 2) for the wrist (flexion, deviation).

Two presets:

``anatomical`` (default): active ranges of motion of the finger joints of adult hands, from
    Hume, Gellman, McKellop & Brumfield, "Functional range of motion of the joints of the hand",
    J. Hand Surg. 15A:240-243 (1990), and the AAOS handbook "Joint Motion: Method of Measuring
    and Recording" (1965): MCP flexion to 90 with some hyperextension, PIP to 100-110, DIP to
    80-90 with slight hyperextension, MCP abduction about 20 either way, thumb MCP to 55-60 and
    IP from -15 to 80. Twist and the spread of the PIP/DIP hinges are small passive play.

``paper``: Table 1 of Gangopadhyay et al. 2023 (shared/paper, transcribed in
    data/table1_joint_limits.json), as printed. The paper does not say whether a triple is a
    bound or a range; we read each printed value v as the one-sided range from 0 to v about that
    axis of MANO's joint frame (theta, phi, psi about x, y, z ~ our twist, spread, bend). MANO's
    left hand mirrors its right, so positive angles mean the same motion on both sides after a
    sign change on the right hand: our angle = -value (right), +value (left). A printed 0 locks
    the axis. The table is asymmetric between the hands (e.g. index MCP flexion 35 on the right,
    75 on the left); we keep it as printed.
"""

from __future__ import annotations

import dataclasses
import json
from typing import TYPE_CHECKING

import numpy as np

from handshadow.hands.rig import FINGERS, Side, check_side
from handshadow.paths import PACKAGE_DATA

if TYPE_CHECKING:
    import torch

PRESETS = ("anatomical", "paper")
# Wrist (flexion, deviation) [low, high] degrees: extension 70 / flexion 80, ulnar deviation 30
# / radial 20 (AAOS 1965). The paper has no wrist (its hands have no forearm): both presets use
# these.
WRIST_DEG = np.array([[-70.0, 80.0], [-30.0, 20.0]])

# Per finger, per joint (J1, J2, J3): ((twist lo, hi), (spread lo, hi), (bend lo, hi)) degrees.
_FINGER = (
    ((-10, 10), (-20, 20), (-20, 90)),  # MCP
    ((-5, 5), (-5, 5), (0, 105)),  # PIP
    ((-5, 5), (-5, 5), (-5, 80)),  # DIP
)
_ANATOMICAL = {
    "thumb": (
        ((-20, 30), (-20, 50), (-20, 45)),  # CMC: opposition twist, abduction, flexion
        ((-10, 10), (-10, 10), (-5, 60)),  # MCP
        ((-5, 5), (-5, 5), (-15, 80)),  # IP
    ),
    "index": _FINGER,
    "middle": _FINGER,
    "ring": _FINGER,
    "little": (
        ((-10, 10), (-30, 20), (-20, 90)),  # the little finger abducts further (negative spread: ulnar)
        _FINGER[1],
        _FINGER[2],
    ),
}


def joint_limits_deg(preset: str = "anatomical", side: str = "right") -> np.ndarray:
    """(15, 3, 2) [low, high] degrees, rig.JOINT_NAMES order, axes (twist, spread, bend)."""
    side = check_side(side)
    if preset == "anatomical":
        return np.array([_ANATOMICAL[f] for f in FINGERS], dtype=np.float64).reshape(15, 3, 2)
    if preset == "paper":
        return _paper_limits(side)
    raise ValueError(f"unknown joint-limit preset {preset!r}; choose {' or '.join(PRESETS)}")


def wrist_limits_deg(preset: str = "anatomical") -> np.ndarray:
    """(2, 2) [low, high] degrees of wrist flexion and deviation (toward the thumb positive)."""
    if preset not in PRESETS:
        raise ValueError(f"unknown joint-limit preset {preset!r}; choose {' or '.join(PRESETS)}")
    return WRIST_DEG.copy()


def _paper_limits(side: Side) -> np.ndarray:
    table = json.loads((PACKAGE_DATA / "table1_joint_limits.json").read_text())[side]
    sign = -1.0 if side == "right" else 1.0
    out = np.zeros((15, 3, 2))
    for f, finger in enumerate(FINGERS):
        for j in range(3):
            values = sign * np.asarray(table[finger][f"J{j + 1}"], dtype=np.float64)
            out[3 * f + j, :, 0] = np.minimum(0.0, values)
            out[3 * f + j, :, 1] = np.maximum(0.0, values)
    return out


@dataclasses.dataclass(frozen=True)
class JointLimits:
    """Joint limits of one hand as tensors, radians: joints (15, 3, 2) and wrist (2, 2), each
    [low, high]."""

    joints: torch.Tensor
    wrist: torch.Tensor

    @staticmethod
    def preset(preset: str = "anatomical", side: str = "right", dtype=None, device="cpu") -> JointLimits:
        """A preset's limits for one side (float32 unless dtype)."""
        import torch

        t = dict(dtype=dtype or torch.float32, device=device)
        return JointLimits(
            torch.as_tensor(np.radians(joint_limits_deg(preset, side)), **t),
            torch.as_tensor(np.radians(wrist_limits_deg(preset)), **t),
        )

    def to(self, device) -> JointLimits:
        return JointLimits(self.joints.to(device), self.wrist.to(device))


AXES = ("twist", "spread", "bend")
# rig.JOINT_NAMES as a person names them: per finger from the palm outward (the thumb's base in
# the wrist, then its knuckle and end joint; a finger's knuckle, middle and end joint).
JOINT_WORDS = ("thumb base", "thumb knuckle", "thumb end joint") + tuple(
    f"{finger} {joint}"
    for finger in ("index", "middle", "ring", "little")
    for joint in ("knuckle", "middle joint", "end joint")
)
WRIST_AXES = ("flexion", "deviation")


def beyond_limits(pose_deg: np.ndarray, wrist_deg: np.ndarray | None, side: str, tol_deg: float = 0.5) -> list[str]:
    """The angles of one hand past what every preset allows, by more than ``tol_deg``, each as
    a person reads it, "<joint> <axis> <angle> (<low> to <high>)", e.g. "index knuckle spread
    40 deg (-20 to 20)" (rig.JOINT_NAMES order, then the wrist's; :data:`JOINT_WORDS`; positive
    spreads and twists toward the thumb, positive bends toward the palm).

    Args:
        pose_deg: (15, 3) twist, spread, bend degrees.
        wrist_deg: (2,) flexion, deviation degrees; None for a hand without a forearm, whose
            wrist angles move nothing.
        side: "right" or "left" (the paper's table differs per side).
    """
    presets = np.stack([joint_limits_deg(p, side) for p in PRESETS])  # (P, 15, 3, 2)
    lo, hi = presets[..., 0].min(0), presets[..., 1].max(0)
    out = []
    for (j, a), v in np.ndenumerate(wrap_degrees(pose_deg)):
        if v < lo[j, a] - tol_deg or v > hi[j, a] + tol_deg:
            out.append(f"{JOINT_WORDS[j]} {AXES[a]} {v:.0f} deg ({lo[j, a]:.0f} to {hi[j, a]:.0f})")
    for a, v in enumerate(wrap_degrees(() if wrist_deg is None else wrist_deg)):
        if v < WRIST_DEG[a, 0] - tol_deg or v > WRIST_DEG[a, 1] + tol_deg:
            out.append(f"wrist {WRIST_AXES[a]} {v:.0f} deg ({WRIST_DEG[a, 0]:.0f} to {WRIST_DEG[a, 1]:.0f})")
    return out


def wrap_degrees(degrees) -> np.ndarray:
    """Joint angles in [-180, 180), same shape, float64: each elementary rotation (twist,
    spread, bend, the wrist's) turns alike every 360 degrees, so 370 in a pose file is the
    joint at 10."""
    return (np.asarray(degrees, float) + 180.0) % 360.0 - 180.0
