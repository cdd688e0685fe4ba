"""Telling a person how to hold their hands: a few plain sentences per hand, and the guide
picture (the hands seen from the performer's side, with those sentences beside them)."""

from __future__ import annotations

import numpy as np

from handshadow.hands.rig import FINGERS
from handshadow.poses import HandPose
from handshadow.scene import Scene

_DIRS = {
    "up": (0, 1, 0),
    "down": (0, -1, 0),
    "left": (-1, 0, 0),
    "right": (1, 0, 0),
    "the lamp": (0, 0, 1),
    "the wall": (0, 0, -1),
}


def _word(vec: np.ndarray, scene: Scene) -> str:
    """The closest plain direction of a world vector, as the performer sees it."""
    up = -np.asarray(scene.image.v, float) / np.linalg.norm(scene.image.v)
    right = np.asarray(scene.image.u, float) / np.linalg.norm(scene.image.u)
    toward_lamp = np.asarray(scene.wall.normal, float)
    local = np.array([vec @ right, vec @ up, vec @ toward_lamp])
    names = list(_DIRS)
    scores = [local @ np.asarray(_DIRS[n]) for n in names]
    best = names[int(np.argmax(scores))]
    second = names[int(np.argsort(scores)[-2])]
    if sorted(scores)[-2] > 0.45 and {best, second} not in (
        {"up", "down"},
        {"left", "right"},
        {"the lamp", "the wall"},
    ):
        if best in ("up", "down") and second in ("left", "right"):
            return f"{best} and to the {second}"
        if best in ("left", "right") and second in ("up", "down"):
            return f"to the {best} and {second}"
    return best if best in ("up", "down") else (f"to the {best}" if best in ("left", "right") else f"toward {best}")


def _finger_state(angles_deg: np.ndarray) -> str:
    bend = float(np.sum(angles_deg[:, 2]))
    if bend < 35:
        return "straight"
    if bend < 120:
        return "half bent"
    return "curled in"


def describe_hand(hand: HandPose, scene: Scene) -> list[str]:
    """Sentences telling a person how to hold this hand."""
    rot = np.asarray(hand.rotation, float)
    fingers, back = rot[:, 1], rot[:, 2]
    name = "Right hand" if hand.side == "right" else "Left hand"
    n = np.asarray(scene.wall.normal, float)
    height = float((np.asarray(hand.translation) - np.asarray(scene.wall.point)) @ n)
    lines = [
        f"{name}: fingers point {_word(fingers, scene)}, palm faces {_word(-back, scene).replace('to the ', '').replace('toward ', '')}.",
        f"  Wrist about {height * 100:.0f} cm from the wall."
        + (
            f" Bend the wrist {abs(hand.wrist_deg[0]):.0f} degrees {'toward the palm' if hand.wrist_deg[0] > 0 else 'back'}."
            if abs(hand.wrist_deg[0]) >= 15
            else ""
        ),
    ]
    states = {}
    for f, finger in enumerate(FINGERS):
        states.setdefault(_finger_state(hand.pose_deg[3 * f : 3 * f + 3]), []).append(finger)
    parts = [
        f"{' and '.join(names) if len(names) < 3 else ', '.join(names)} {state}" for state, names in states.items()
    ]
    lines.append("  " + "; ".join(parts) + ".")
    spread = hand.pose_deg[[3, 6, 9, 12], 1]
    if np.ptp(spread) > 25:
        lines.append("  Spread the fingers wide.")
    return lines


def describe(hands: list[HandPose], scene: Scene) -> list[str]:
    out = []
    for h in sorted(hands, key=lambda h: h.side != "left"):
        out += describe_hand(h, scene)
    return out


def guide_image(view: np.ndarray, shadow_overlay: np.ndarray, lines: list[str]) -> np.ndarray:
    """The performer's view on the left, the shadow over the target as an inset, and the
    instructions below. All uint8 RGB."""
    from PIL import Image, ImageDraw, ImageFont

    h, w = view.shape[:2]
    inset = Image.fromarray(shadow_overlay).resize(
        (w // 3, w // 3 * shadow_overlay.shape[0] // shadow_overlay.shape[1])
    )
    text_h = 18 * (len(lines) + 2)
    canvas = Image.new("RGB", (w, h + text_h), "white")
    canvas.paste(Image.fromarray(view), (0, 0))
    canvas.paste(inset, (w - inset.width - 6, 6))
    draw = ImageDraw.Draw(canvas)
    draw.rectangle([w - inset.width - 7, 5, w - 6, 6 + inset.height], outline=(120, 120, 120))
    font = ImageFont.load_default()
    draw.text((8, 6), "What you see from behind the lamp", fill=(40, 40, 40), font=font)
    draw.text((w - inset.width - 6, inset.height + 10), "shadow vs target", fill=(90, 90, 90), font=font)
    y = h + 8
    for line in lines:
        draw.text((10, y), line, fill=(20, 20, 20), font=font)
        y += 18
    return np.asarray(canvas)
