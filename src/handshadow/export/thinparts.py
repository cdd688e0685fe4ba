"""Thin parts of a print: measure, thicken, or refuse with the height that works.

Parts thinner than the printer's minimum wall get balls of that diameter along their middle
(:func:`handshadow.export.solid.thickening_balls`), as long as the thickened hands' shadow
still matches the fit's by SHADOW_IOU_MIN; otherwise :class:`ThinPartsError` names the fingers
(posed again from pose.json) and the smallest height that works, found by bisection on the
thickness scaled to other heights.
"""

from __future__ import annotations

import dataclasses

import manifold3d as m3
import numpy as np

from handshadow.errors import HandshadowError
from handshadow.export import solid as solids
from handshadow.export.printframe import PrintError, PrintFrame, PrintSettings, ResultMeshes, print_frame, shadow_of
from handshadow.metrics import iou
from handshadow.scene import Scene

SHADOW_IOU_MIN = 0.985  # a thickened print's shadow against the fit's, at the least


class ThinPartsError(PrintError):
    """Parts thinner than the minimum wall whose thickening would change the shadow."""


def printable_hands(
    result: ResultMeshes, frame: PrintFrame, scene: Scene, settings: PrintSettings
) -> tuple[m3.Manifold, float, np.ndarray]:
    """The hands as one clean solid in print millimetres, thickened where thinner than the
    minimum wall; also the thinnest part before thickening (mm) and the thickening balls'
    centres (K, 3). Raises ThinPartsError, naming the parts and the smallest height that
    works, when the thickened hands' shadow would match the fit's by less than
    SHADOW_IOU_MIN (IoU)."""
    reference = shadow_of(result.scene, [(v, f) for _, v, f in result.meshes])
    hands = solids.clean_solid([(frame.apply(v), f) for _, v, f in result.meshes])
    thickness = solids.local_thickness(hands, max_depth=10 * settings.min_wall_mm + 20)
    cast = shadow_of(scene, [solids.to_arrays(hands)])  # in pixels the same at any height
    thick = thickening(thickness, scene, settings.min_wall_mm, cast, reference)
    if len(thick.balls) and thick.shadow_iou < SHADOW_IOU_MIN:
        where = ", ".join(name_places(result, frame, thick.centres)) or f"{len(thick.centres)} spots"
        height = smallest_height(result, frame, thickness, cast, reference, settings)
        raise ThinPartsError(
            f"thinner than {settings.min_wall_mm:g} mm at {settings.height_mm:g} mm tall: {where}"
            f" (thinnest {thick.thinnest:.2f} mm); thickened, its shadow would drift from the fit's"
            f" (IoU {thick.shadow_iou:.3f}); print at --height-mm {height:.0f} or more"
        )
    if len(thick.balls):
        hands = m3.Manifold.batch_boolean([hands, *thick.balls], m3.OpType.Add)
    return hands, thick.thinnest, thick.centres


@dataclasses.dataclass(frozen=True)
class Thickening:
    """What thickening a solid would take. thinnest: its thinnest part (mm); centres: (K, 3)
    ball centres; balls: the balls (diameter: the minimum wall); shadow_iou: the thickened
    solid's shadow against the reference."""

    thinnest: float
    centres: np.ndarray
    balls: list[m3.Manifold]
    shadow_iou: float


def thickening(
    thickness: solids.Thickness, scene: Scene, min_wall: float, cast: np.ndarray, reference: np.ndarray
) -> Thickening:
    """The balls that bring a solid's thin parts to ``min_wall`` (mm), and how well the
    thickened solid's shadow, ``cast`` (H, W) bool (the solid's) with the balls', would match
    ``reference`` (H, W) bool (the shadow of a union is the union of the shadows)."""
    centres = solids.thickening_balls(thickness, min_wall)
    balls = solids.balls(centres, min_wall / 2)
    if balls:
        cast = cast | shadow_of(scene, [solids.to_arrays(b) for b in balls])
    return Thickening(float(thickness.part.min()), centres, balls, iou(cast, reference))


def smallest_height(
    result: ResultMeshes,
    frame: PrintFrame,
    thickness: solids.Thickness,
    cast: np.ndarray,
    reference: np.ndarray,
    settings: PrintSettings,
) -> float:
    """About the smallest height (mm, up to the next 5) at which the thickened hands' shadow
    still matches ``reference`` by SHADOW_IOU_MIN: four bisection steps between this height
    and one at which nothing is thinner than the minimum wall. The hands' thickness (in
    ``frame``'s coordinates) and shadow ``cast`` scale with the print; the stand's
    millimetres do not."""
    vertices = np.concatenate([v for _, v, _ in result.meshes])

    def works(height: float) -> bool:
        other = print_frame(result.scene, vertices, dataclasses.replace(settings, height_mm=height))
        moved = thickness.moved(other.mm_per_m / frame.mm_per_m, frame.translation, other.translation)
        match = thickening(moved, other.scene(result.scene), settings.min_wall_mm, cast, reference).shadow_iou
        return match >= SHADOW_IOU_MIN + 0.002  # a little to spare: the measure is not smooth in the height

    below = settings.stand_size.board + settings.stand_size.margin if settings.stand else 0.0
    low = settings.height_mm
    high = max(low * 1.1, below + (low - below) * settings.min_wall_mm / thickness.part.min() * 1.05)
    for _ in range(5):
        middle = 0.5 * (low + high)
        low, high = (low, middle) if works(middle) else (middle, high)
    return float(5 * np.ceil(high / 5))


def name_places(result: ResultMeshes, frame: PrintFrame, points: np.ndarray) -> list[str]:
    """Names of the hand parts nearest to points (K, 3) in print millimetres ("left index",
    "right palm", "left forearm"), most points first; empty when the result's pose.json
    cannot be posed here (the names are a courtesy, not a requirement)."""
    from handshadow.hands.posed import pose_meshes
    from handshadow.hands.rig import FINGERS
    from handshadow.posefile import load_pose_file

    if len(points) == 0:
        return []
    try:
        keypoints = {m.side: frame.apply(m.keypoints) for m in pose_meshes(load_pose_file(result.folder / "pose.json"))}
    except (HandshadowError, OSError, ValueError):
        return []
    labels = []
    for p in np.asarray(points, float):
        best = (np.inf, "")
        for side, k in keypoints.items():
            for f, finger in enumerate(FINGERS):
                chain = k[[0, *range(1 + 4 * f, 5 + 4 * f)]]  # wrist, the finger's joints, its tip
                d, t = _to_polyline(p, chain)
                name = f"{side} {finger}" if t >= 1 else (f"{side} palm" if t > 0 else f"{side} forearm")
                best = min(best, (d, name))
        labels.append(best[1])
    names, counts = np.unique(labels, return_counts=True)
    return [str(n) for n in names[np.argsort(-counts, kind="stable")]]


def _to_polyline(p: np.ndarray, chain: np.ndarray) -> tuple[float, float]:
    """Distance from p (3,) to the polyline chain (N, 3), and where its nearest point lies as
    segment index plus fraction (below 0: before the first point)."""
    best = (np.inf, 0.0)
    for i, (a, b) in enumerate(zip(chain[:-1], chain[1:])):
        t_raw = float((p - a) @ (b - a) / max((b - a) @ (b - a), 1e-12))
        t = min(max(t_raw, 0.0), 1.0)
        d = float(np.linalg.norm(a + t * (b - a) - p))
        best = min(best, (d, i + t if i or t_raw >= 0 else t_raw))
    return best
