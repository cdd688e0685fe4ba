"""Telling a person how to hold their hands: a few plain sentences per hand, and the guide
picture (the hands seen from the performer's side, with those sentences beside them). With
several views (one pose, a lamp and a wall per shadow): where to put each lamp and wall, and
per view how well its shadow came out and which parts of its target are missing."""

from __future__ import annotations

import dataclasses
import math
import textwrap
from collections.abc import Sequence

import numpy as np

from handshadow.hands.arms import ArmCheck
from handshadow.hands.penetration import TOLERANCE_MM
from handshadow.hands.rig import FINGERS
from handshadow.metrics import SUCCESS_HD95, SUCCESS_IOU, SUCCESS_THIN, FitScore, Part
from handshadow.poses import HandPose, PosedScene
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


def describe(hands: list[HandPose], scene: Scene, hand_length_m: float | None = None, views: int = 1) -> list[str]:
    """How to hold the hands, hand by hand (left first), then, given the hands' length
    (hands.rig.hand_length_m), the line on other hands (:func:`size_line`)."""
    out = []
    for h in sorted(hands, key=lambda h: h.side != "left"):
        out += describe_hand(h, scene)
    if hand_length_m is not None:
        out.append(size_line(hands, scene, hand_length_m, views))
    return out


def size_line(hands: Sequence[HandPose], scene: Scene, hand_length_m: float, views: int = 1) -> str:
    """The hands' length and, under one point lamp, how a person with longer or shorter hands
    (and forearms in proportion) casts the same shadow: every point of the hands k times as far
    from the lamp casts the same shadow, so a hand k times as long holds its wrist k times as
    far from the lamp, straight away from it along the light (the gap between the wrists grows
    with it). Under a distant light, or with several lamps, no such move exists."""
    said = f"Sized for hands {hand_length_m * 100:.1f} cm long (wrist crease to the tip of the middle finger)."
    if scene.light.type != "point" or views > 1:
        return said + " Longer or shorter hands cast a larger or smaller shadow of the same pose."
    lamp = np.asarray(scene.light.position, float)
    reach = float(np.mean([np.linalg.norm(np.asarray(h.translation, float) - lamp) for h in hands]))
    return (
        f"{said} With longer or shorter hands keep the pose and move each wrist straight away from"
        f" the lamp or toward it by the same share: a hand 10 % longer, its wrist 10 % farther from"
        f" the lamp (here about {0.1 * reach * 100:.0f} cm)."
    )


def held_by(posed: PosedScene, shape: dict, mano_dir: str | None = None) -> PosedScene:
    """The pose held as :func:`size_line` says by hands of another build ``shape`` (as
    HandPose.shape): each hand of that build, k times the length of the hand it replaces
    (HandRig.size), its wrist k times as far from view 0's point lamp along the light."""
    from handshadow.hands import load_rig

    lamp = np.asarray(posed.scene.light.position, float)
    hands = []
    for h in posed.hands:
        k = load_rig(h.model, h.side, shape, mano_dir).size / load_rig(h.model, h.side, h.shape, mano_dir).size
        t = lamp + k * (np.asarray(h.translation, float) - lamp)
        hands.append(dataclasses.replace(h, shape=dict(shape), translation=t))
    return dataclasses.replace(posed, hands=tuple(hands))


def holding_line(
    sides: Sequence[str],
    between_mm: float,
    arms: ArmCheck,
    within_mm: Sequence[float] = (),
    beyond: Sequence[Sequence[str]] = (),
) -> str:
    """Whether a person can hold a pose, in a line (handshadow render says it of a pose file):
    the hands no more than TOLERANCE_MM inside each other by the exact mesh test
    (between_mm, the deepest), no hand more than that inside itself, a finger in its palm or
    another finger (within_mm, per hand; hands.penetration), every angle within the joint
    limits (beyond, per hand the angles past them; hands.limits.beyond_limits), each forearm
    leading back toward the performer, and the elbows within one person's span (arms,
    hands.arms.ArmCheck). Per-hand values are in sides' order. A pose that only needs two
    people's arms says so."""
    said = []
    if between_mm > TOLERANCE_MM:
        said.append(f"the hands pass {between_mm:.1f} mm into each other")
    for side, mm in zip(sides, within_mm):
        if mm > TOLERANCE_MM:
            said.append(f"the {side} hand's fingers pass {mm:.1f} mm into its palm or each other")
    if said:  # once, after the last depth
        said[-1] += f" (skin gives about {TOLERANCE_MM:.0f} mm)"
    for side, angles in zip(sides, beyond):
        if angles:
            more = f" and {len(angles) - 3} more" if len(angles) > 3 else ""
            said.append(f"the {side} hand goes past its joints' limits: " + ", ".join(angles[:3]) + more)
    for side, back in zip(sides, arms.leads_back):
        if not back:
            said.append(f"the {side} forearm leads toward the wall (its elbow is nearer the wall than its wrist)")
    span = f"the elbows are {arms.span_m:.2f} m apart, more than one person's arms span"
    if said:
        return "Can be held: no, " + "; ".join(said + [span] * (arms.performers > 1)) + "."
    return f"Can be held: by two people ({span})." if arms.performers > 1 else "Can be held: yes."


def wrapped(lines: Sequence[str], width_px: int, font) -> list[str]:
    """Lines broken at spaces to fit ``width_px`` pixels in ``font`` (a PIL font); a line's
    continuation is indented as far as the line is, and by two spaces more."""
    per_char = max(font.getlength("abcdefghijklmnopqrstuvwxyz ") / 27, 1.0)
    out = []
    for line in lines:
        indent = " " * (len(line) - len(line.lstrip(" ")))
        out += textwrap.wrap(line, max(int(width_px / per_char), 20), subsequent_indent=indent + "  ") or [line]
    return out


def guide_image(
    view: np.ndarray, shadow_overlay: np.ndarray, lines: list[str], label: str = "shadow vs target"
) -> np.ndarray:
    """The performer's view on the left, the shadow over the target as an inset (``label``
    under it; a rendered pose's guide shows its shadow alone), and the instructions below.
    All uint8 RGB. The inset sits in the view's top right corner where
    that corner is empty (the view's white), else beside the view, so it never hides a hand
    or a forearm."""
    from PIL import Image, ImageDraw, ImageFont

    h, w = view.shape[:2]
    inset = Image.fromarray(shadow_overlay).resize(
        (w // 3, w // 3 * shadow_overlay.shape[0] // shadow_overlay.shape[1])
    )
    font = ImageFont.load_default()
    label_w = int(np.ceil(font.getlength(label)))
    # The corner the inset and its label would cover, with the gap around them.
    corner = view[: inset.height + 26, max(0, w - max(inset.width, label_w) - 14) :]
    beside = bool((corner < 250).any(axis=-1).any())
    width = w + inset.width + 12 if beside else w
    lines = wrapped(lines, width - 20, font)
    text_h = 18 * (len(lines) + 2)
    canvas = Image.new("RGB", (width, h + text_h), "white")
    canvas.paste(Image.fromarray(view), (0, 0))
    x = width - inset.width - 6
    canvas.paste(inset, (x, 6))
    draw = ImageDraw.Draw(canvas)
    draw.rectangle([x - 1, 5, width - 6, 6 + inset.height], outline=(120, 120, 120))
    draw.text((8, 6), "What you see from behind the lamp", fill=(40, 40, 40), font=font)
    at = (max(8, min(x, width - 8 - label_w)), inset.height + 10)  # small views too
    draw.text(at, label, fill=(90, 90, 90), font=font)
    y = h + 8
    for line in lines:
        draw.text((10, y), line, fill=(20, 20, 20), font=font)
        y += 18
    return np.asarray(canvas)


# Directions in the room from the hands, as the performer (by view 0's lamp, facing its wall)
# names them, by the angle about the vertical from "toward you" (positive: to the right).
_TURN_WORDS = [
    (22.5, "toward you"),
    (67.5, "toward you and to the {side}"),
    (112.5, "to the {side}"),
    (157.5, "to the {side}, toward wall 0"),
    (180.0, "toward wall 0"),
]


def _heading_deg(vec: np.ndarray, first: Scene) -> float:
    """The angle about the vertical from "toward you" (view 0's wall normal) to a vector,
    degrees, positive to the performer's right."""
    toward_you = np.asarray(first.wall.normal, float)
    right = np.asarray(first.image.u, float) / np.linalg.norm(first.image.u)
    return math.degrees(math.atan2(float(vec @ right), float(vec @ toward_you)))


def _direction(angle_deg: float) -> str:
    side = "right" if angle_deg > 0 else "left"
    return next(words for limit, words in _TURN_WORDS if abs(angle_deg) <= limit).format(side=side)


def lamp_lines(views: Sequence[Scene], hands_centre: np.ndarray) -> list[str]:
    """Where each view's lamp and wall go, from the hands' centre (3,) metres, in the
    performer's words (view 0's frame: right, toward you)."""
    lines = []
    c = np.asarray(hands_centre, float)
    for k, view in enumerate(views):
        normal = np.asarray(view.wall.normal, float)
        wall_m = float((c - np.asarray(view.wall.point)) @ normal)
        picture = f"its picture {np.linalg.norm(view.image.v):.2f} m high"
        if view.light.type == "point":
            lamp = np.asarray(view.light.position, float)
            where = _direction(_heading_deg(lamp - c, views[0]))
            lamp_text = f"the lamp {np.linalg.norm(lamp - c):.2f} m from the hands, {where}"
        else:
            lamp_text = "a distant light shining square onto its wall"
        turn = _heading_deg(normal, views[0])
        turned = f", turned {abs(turn):.0f} degrees to your {'right' if turn > 0 else 'left'}" if k else ""
        lines.append(f"View {k}: {lamp_text}; its wall {wall_m:.2f} m beyond the hands{turned}, {picture}.")
    if len(views) > 1:
        lines.append("  Keep every lamp level with the middle of its picture; light one lamp at a time to check.")
    return lines


def _place(centre: tuple[float, float]) -> str:
    """'the top left', 'the middle', ... of a frame, for a centre (x, y) in shares of it."""
    row = ("top", "", "bottom")[min(2, int(centre[1] * 3))]
    col = ("left", "", "right")[min(2, int(centre[0] * 3))]
    return "the " + (f"{row} {col}".strip() or "middle")


PARTS_NAMED = 3  # the largest this many places of missing parts (and of extra shadow) are named


def _by_place(parts: Sequence[Part], thin_words: bool) -> list[str]:
    """Parts grouped by where they are (shares summed, largest first), as words."""
    places: dict[str, list[Part]] = {}
    for p in parts:
        places.setdefault(_place(p.centre), []).append(p)
    ranked = sorted(places.items(), key=lambda item: -sum(p.share for p in item[1]))
    out = []
    for place, found in ranked[:PARTS_NAMED]:
        kind = ("thin parts" if len(found) > 1 else "a thin part") if all(p.thin for p in found) else "a part"
        out.append(f"{kind + ' at ' if thin_words else ''}{place} ({sum(p.share for p in found):.0%})")
    return out


def parts_text(missing: Sequence[Part], extra: Sequence[Part]) -> str:
    """Which target parts a shadow misses and where it spills (shares of the target's area),
    in words."""
    said = []
    if missing:
        said.append("missing " + ", ".join(_by_place(missing, True)))
    if extra:
        said.append("extra shadow at " + ", ".join(_by_place(extra, False)))
    return "; ".join(said) if said else "nothing missing"


def shortfall_line(s: FitScore, missing: Sequence[Part], extra: Sequence[Part]) -> str | None:
    """For a shadow short of the success test: which of its bars it misses and which target
    parts the hands did not make (and where they cast shadow beyond the target), in words;
    None for a shadow that passes."""
    if s.success:
        return None
    missed = []
    if s.iou < SUCCESS_IOU:
        missed.append(f"IoU {s.iou:.3f} under {SUCCESS_IOU:g}")
    if s.thin_recall < SUCCESS_THIN:
        missed.append(f"thin parts {s.thin_recall:.2f} under {SUCCESS_THIN:g}")
    if s.hd95 > SUCCESS_HD95:
        missed.append(f"HD95 {s.hd95:.3f} over {SUCCESS_HD95:g}: the outline strays")
    found = parts_text(missing, extra) if missing or extra else "no part beyond slivers along the outline"
    where = "Where the shadow differs (share of the target's area)"
    return f"Short of the success test ({'; '.join(missed)}). {where}: {found}."


def view_lines(scores: Sequence[FitScore], parts: Sequence[tuple[list[Part], list[Part]]], weights) -> list[str]:
    """Per view how well its shadow came out and which target parts it misses (shares of the
    target's area), then the trade-off when the views could not all be met."""
    lines = []
    for k, (s, (missing, extra)) in enumerate(zip(scores, parts)):
        verdict = "a success" if s.success else "short of the success test"
        lines.append(f"View {k}: {s} ({verdict}); {parts_text(missing, extra)}.")
    met = [k for k, s in enumerate(scores) if s.success]
    ratio = " : ".join(f"{w / weights[0]:g}" for w in weights)
    if met and len(met) < len(scores):
        gave = ", ".join(str(k) for k in range(len(scores)) if k not in met)
        lines.append(
            f"  One pose could not cast every shadow: view {gave} gave way (view weights {ratio};"
            " --view-weights favours a view)."
        )
    elif not met:
        lines.append(
            f"  No view passes the success test: the pose is the best compromise found (view weights {ratio})."
        )
    return lines


GUIDE_TILE_PX = 360  # each view's shadow over its target, this many pixels wide


def guide_views_image(
    view: np.ndarray, plan: np.ndarray, overlays: Sequence[np.ndarray], lines: list[str]
) -> np.ndarray:
    """The guide for several views: the performer's view and the plan of the room side by
    side, each view's shadow over its target below them, then the instructions. uint8 RGB."""
    from PIL import Image, ImageDraw, ImageFont

    h, w = view.shape[:2]
    width = w + plan.shape[1]
    tile = min(GUIDE_TILE_PX, width // len(overlays) - 12)
    lines = wrapped(lines, width - 20, ImageFont.load_default())
    canvas = Image.new("RGB", (width, h + tile + 30 + 18 * (len(lines) + 2)), "white")
    canvas.paste(Image.fromarray(view), (0, 0))
    canvas.paste(Image.fromarray(plan), (w, 0))
    draw = ImageDraw.Draw(canvas)
    font = ImageFont.load_default()
    draw.text((8, 6), "What you see from behind lamp 0", fill=(40, 40, 40), font=font)
    for k, overlay in enumerate(overlays):
        x = 6 + k * (tile + 12)
        canvas.paste(Image.fromarray(overlay).resize((tile, tile * overlay.shape[0] // overlay.shape[1])), (x, h + 22))
        draw.text((x, h + 6), f"view {k}: shadow vs target", fill=(90, 90, 90), font=font)
    y = h + tile + 34
    for line in lines:
        draw.text((10, y), line, fill=(20, 20, 20), font=font)
        y += 18
    return np.asarray(canvas)
