"""Pictures for people: the 3D scene (what casts what) and the performer's view of the hands."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh

from handshadow.export.meshes import SKIN, light_marker_position
from handshadow.render.views import Camera, ViewMesh, render_view
from handshadow.scene import Scene

WALL_TINT = np.array([0.96, 0.95, 0.92])
LAMP = (1.0, 0.8, 0.25)
RAY = (1.0, 0.86, 0.45)
HAND_COLORS = {"right": SKIN, "left": (0.80, 0.62, 0.52)}


def scene_picture(
    scene: Scene,
    hands: list[tuple[str, np.ndarray, np.ndarray]],
    shadow: np.ndarray,
    rays_through: np.ndarray | None = None,
    size: tuple[int, int] = (800, 600),
    more_views: Sequence[tuple[Scene, np.ndarray]] = (),
) -> np.ndarray:
    """The lamp, the hands and the wall with the shadow on it, seen from above and beside.

    Args:
        hands: (side, vertices (V, 3), faces (F, 3)) per hand, world frame.
        shadow: (H, W) mask in [0, 1] of the image frame.
        rays_through: optional (N, 3) points; a thin ray is drawn from the lamp through each
            to the wall, to show how the shadow forms.
        more_views: further views (scene, shadow (H, W) in [0, 1]): their lamps, walls with
            shadows and rays too, all seen from beyond the hands, opposite the walls.
    Returns (H, W, 3) uint8.
    """
    meshes = [ViewMesh(v, f, color=HAND_COLORS.get(side, SKIN)) for side, v, f in hands]
    for view, mask in [(scene, shadow), *more_views]:
        meshes += _lit_wall(view, mask, rays_through)
    if not more_views:
        return render_view(meshes, _beside_camera(scene, size), background=(0.93, 0.94, 0.96))
    views = [scene, *(v for v, _ in more_views)]
    camera = _corner_camera(views, size)
    return _label_walls(render_view(meshes, camera, background=(0.93, 0.94, 0.96)), views, camera)


def _label_walls(picture: np.ndarray, views: list[Scene], camera: Camera) -> np.ndarray:
    """'view K' written above each view's picture on its wall."""
    from PIL import Image, ImageDraw, ImageFont

    canvas = Image.fromarray(picture)
    draw = ImageDraw.Draw(canvas)
    font = ImageFont.load_default()
    for k, view in enumerate(views):
        top = frame_centre(view) - 0.5 * np.asarray(view.image.v, float) * (1 + LABEL_ABOVE_SHARE)
        xy, _ = camera.project(top[None])
        draw.text((float(xy[0, 0]), float(xy[0, 1])), f"view {k}", fill=(40, 40, 40), font=font, anchor="mm")
    return np.asarray(canvas)


def _lit_wall(scene: Scene, shadow: np.ndarray, rays_through: np.ndarray | None) -> list[ViewMesh]:
    """A view's wall with its shadow, its lamp, and rays from the lamp through the points."""
    lamp = light_marker_position(scene)
    meshes = [_wall(scene, shadow), _sphere(lamp, 0.05, LAMP, emissive=True)]
    for p in np.asarray(rays_through if rays_through is not None else np.zeros((0, 3)), float):
        hit = _on_wall(scene, p)
        if hit is not None:
            start = lamp if scene.light.type == "point" else p - 0.6 * np.asarray(scene.light.direction)
            meshes.append(_rod(start, hit, 0.0025, RAY))
    return meshes


def _beside_camera(scene: Scene, size: tuple[int, int]) -> Camera:
    """Over the performer's right shoulder: lamp in front, hands in the middle, wall behind."""
    lamp = light_marker_position(scene)
    centre = frame_centre(scene)
    normal = np.asarray(scene.wall.normal, float)
    depth = float((lamp - centre) @ normal)
    up = up_dir(scene)
    side_dir = np.asarray(scene.image.u, float) / np.linalg.norm(scene.image.u)
    look_at = centre + normal * depth * 0.3
    eye = centre + normal * (1.45 * depth) + side_dir * (0.55 * depth) + up * (0.35 * depth)
    return Camera(tuple(eye), tuple(look_at), tuple(up), fov_deg=42.0, width=size[0], height=size[1])


# Seen from beyond the hands, opposite the walls, above: these shares of the mean lamp-to-wall
# distance back and up, looking at the middle of the lamps and frames.
CORNER_BACK = 0.95
CORNER_UP = 0.55
CORNER_FOV_DEG = 48.0
LABEL_ABOVE_SHARE = 0.12  # a wall's label sits this share of its picture's height above it


def _corner_camera(views: list[Scene], size: tuple[int, int]) -> Camera:
    """A camera that sees every view's lamp and wall: from the side of the lamps, opposite
    the walls (along the sum of the walls' normals), above."""
    lamps = np.stack([light_marker_position(v) for v in views])
    centres = np.stack([frame_centre(v) for v in views])
    look_at = np.concatenate([lamps, centres]).mean(0)
    away = np.sum([np.asarray(v.wall.normal, float) for v in views], axis=0)
    away /= np.linalg.norm(away)
    depth = float(np.mean([(lamp - c) @ np.asarray(v.wall.normal) for lamp, c, v in zip(lamps, centres, views)]))
    up = up_dir(views[0])
    eye = look_at + away * CORNER_BACK * depth + up * CORNER_UP * depth
    return Camera(tuple(eye), tuple(look_at), tuple(up), fov_deg=CORNER_FOV_DEG, width=size[0], height=size[1])


def frame_centre(scene: Scene) -> np.ndarray:
    """(3,) the centre of a scene's image frame on its wall, metres."""
    return np.asarray(scene.image.origin) + 0.5 * np.asarray(scene.image.u) + 0.5 * np.asarray(scene.image.v)


def performer_view(
    scene: Scene,
    hands: list[tuple[str, np.ndarray, np.ndarray]],
    size: tuple[int, int] = (640, 640),
    supersample: int = 2,
    framing: tuple[np.ndarray, float] | None = None,
) -> np.ndarray:
    """The hands as the performer sees them: from just behind and above the lamp, looking at
    the wall, so left is left and right is right. framing: (centre (3,), distance metres) to
    share one camera across the frames of a sequence (:func:`performer_framing`); by default
    these hands' own. Returns (H, W, 3) uint8."""
    meshes = [ViewMesh(v, f, color=HAND_COLORS.get(side, SKIN)) for side, v, f in hands]
    target, distance = framing if framing is not None else performer_framing([v for _, v, _ in hands], scene)
    camera = performer_camera(target, distance, scene, size)
    return render_view(meshes, camera, background=(1.0, 1.0, 1.0), supersample=supersample)


PERFORMER_FOV_DEG = 45.0  # the performer view's vertical field of view
PERFORMER_FILL = 0.9  # the share of the half-view that the farthest-out vertex may reach
PERFORMER_DISTANCES_M = np.geomspace(0.45, 12.0, 200)  # the camera distances the framing tries
PERFORMER_RAISE = 0.25  # the camera stands this share of its distance above the hands' centre


def performer_camera(centre: np.ndarray, distance: float, scene: Scene, size: tuple[int, int] = (2, 2)) -> Camera:
    """The performer's camera: ``distance`` metres from ``centre`` toward the lamp along the
    wall's normal, raised by PERFORMER_RAISE of it, looking at ``centre``; size (W, H) pixels."""
    up = up_dir(scene)
    eye = centre + np.asarray(scene.wall.normal, float) * distance + up * PERFORMER_RAISE * distance
    return Camera(tuple(eye), tuple(centre), tuple(up), fov_deg=PERFORMER_FOV_DEG, width=size[0], height=size[1])


def performer_framing(vertex_sets: list[np.ndarray], scene: Scene) -> tuple[np.ndarray, float]:
    """Where the performer's camera looks and from how far (metres): the centre of the box
    around the vertices (V, 3) of all sets, from the nearest of PERFORMER_DISTANCES_M at which
    every vertex lies in front of the camera and within PERFORMER_FILL of the view's
    half-height, as the camera projects it (a forearm reaching toward the lamp is near the
    camera and needs the room; the farthest distance when none fits)."""
    pts = np.concatenate([np.asarray(v, float).reshape(-1, 3) for v in vertex_sets])
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    for distance in PERFORMER_DISTANCES_M:
        # A 2 x 2-pixel view: pixel coordinates 1 +- 1 span its half-height either way.
        xy, depth = performer_camera(centre, float(distance), scene).project(pts)
        if depth.min() > 0 and np.abs(xy - 1.0).max() <= PERFORMER_FILL:
            return centre, float(distance)
    return centre, float(PERFORMER_DISTANCES_M[-1])


def up_dir(scene: Scene) -> np.ndarray:
    """Unit vector pointing up the image frame."""
    return -np.asarray(scene.image.v, float) / np.linalg.norm(scene.image.v)


def _wall(scene: Scene, shadow: np.ndarray) -> ViewMesh:
    im = scene.image
    o, u, v = (np.asarray(a, float) for a in (im.origin, im.u, im.v))
    verts = np.stack([o, o + u, o + u + v, o + v])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    texture = (1.0 - np.clip(shadow, 0, 1) * 0.85)[..., None] * WALL_TINT
    return ViewMesh(verts, np.array([[0, 1, 2], [0, 2, 3]]), texture=texture, uv=uv, emissive=True)


def _sphere(centre: np.ndarray, radius: float, color, emissive: bool = False) -> ViewMesh:
    s = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    return ViewMesh(np.asarray(s.vertices) + centre, np.asarray(s.faces), color=color, emissive=emissive)


def _rod(a: np.ndarray, b: np.ndarray, radius: float, color) -> ViewMesh:
    c = trimesh.creation.cylinder(radius=radius, segment=np.stack([a, b]), sections=6)
    return ViewMesh(np.asarray(c.vertices), np.asarray(c.faces), color=color, emissive=True)


def _on_wall(scene: Scene, p: np.ndarray) -> np.ndarray | None:
    n = np.asarray(scene.wall.normal, float)
    w0 = np.asarray(scene.wall.point, float)
    if scene.light.type == "point":
        lamp = np.asarray(scene.light.position, float)
        d = p - lamp
        origin = lamp
    else:
        d = np.asarray(scene.light.direction, float)
        origin = p
    denom = d @ n
    if abs(denom) < 1e-9:
        return None
    t = ((w0 - origin) @ n) / denom
    return origin + t * d if t > 0 else None


# The plan (a map of the room from above): picture pixels per metre are chosen to fit, with
# this margin around lamps, walls and hands (metres); walls drawn this much past their frames.
PLAN_MARGIN_M = 0.35
PLAN_WALL_EXTRA_M = 0.3
PLAN_PERFORMER_M = 0.55  # the performer stands about this far from the hands, away from the walls
PLAN_BEAM = (255, 236, 170)
PLAN_WALL = (150, 150, 150)
PLAN_FRAME = (40, 40, 40)
PLAN_HANDS = tuple(int(255 * c) for c in SKIN)
PLAN_LABEL_M = 0.12  # a wall's label sits this far behind it
PLAN_LAMP_PX = 9
PLAN_PERSON_PX = 12
PLAN_SCALE_M = 0.5


def plan_picture(views: Sequence[Scene], hand_vertices: np.ndarray, size: int = 560) -> np.ndarray:
    """A map of the set-up from above: each view's wall (its picture's width drawn dark), its
    lamp and the beam from the lamp to the picture, the hands, where the performer stands,
    and a 50 cm scale. Up in the map is toward view 0's wall, right is the performer's right.

    Args:
        views: the scenes, view 0 first (a directional light's lamp is drawn where
            scene_trimesh puts its marker).
        hand_vertices: (V, 3) world points of the hands.
    Returns (size, size, 3) uint8.
    """
    from PIL import Image, ImageDraw

    pts = np.asarray(hand_vertices, float)
    away = np.sum([np.asarray(v.wall.normal, float) for v in views], axis=0)
    performer = pts.mean(0) + PLAN_PERFORMER_M * away / max(float(np.linalg.norm(away)), 1e-9)
    lamps = [light_marker_position(v) for v in views]
    walls = [_frame_ends(v, PLAN_WALL_EXTRA_M) for v in views]
    box = np.concatenate([np.concatenate(walls), np.stack(lamps), pts, performer[None]])[:, [0, 2]]
    lo, hi = box.min(0) - PLAN_MARGIN_M, box.max(0) + PLAN_MARGIN_M
    scale = size / float((hi - lo).max())
    offset = (np.array([size, size]) - (hi - lo) * scale) / 2  # centred

    def at(p) -> tuple[float, float]:  # world (x, y, z) -> map pixel: x to the right, -z up (from above)
        return (float((p[0] - lo[0]) * scale + offset[0]), float((p[2] - lo[1]) * scale + offset[1]))

    canvas = Image.new("RGB", (size, size), "white")
    draw = ImageDraw.Draw(canvas)
    for view, lamp in zip(views, lamps):
        a, b = _frame_ends(view, 0.0)
        draw.polygon([at(lamp), at(a), at(b)], fill=PLAN_BEAM)
    draw.polygon([at(p) for p in _outline_from_above(pts)], fill=PLAN_HANDS, outline=(150, 100, 80))
    _plan_labels(draw, views, lamps, walls, at, at(performer), scale, size)
    return np.asarray(canvas)


def _outline_from_above(points: np.ndarray) -> np.ndarray:
    """(N, 3) the convex outline of points (V, 3) seen from above (their x-z hull, at y 0)."""
    from scipy.spatial import ConvexHull

    xz = points[:, [0, 2]]
    hull = xz[ConvexHull(xz).vertices]
    return np.stack([hull[:, 0], np.zeros(len(hull)), hull[:, 1]], 1)


def _plan_labels(draw, views, lamps, walls, at, performer_px, scale: float, size: int) -> None:
    """The plan's walls, frames, lamps, the performer and the scale, labelled."""
    from PIL import ImageFont

    font = ImageFont.load_default()
    for k, (view, lamp, (wa, wb)) in enumerate(zip(views, lamps, walls)):
        a, b = _frame_ends(view, 0.0)
        draw.line([at(wa), at(wb)], fill=PLAN_WALL, width=3)
        draw.line([at(a), at(b)], fill=PLAN_FRAME, width=5)
        draw.text(
            at(0.5 * (a + b) - PLAN_LABEL_M * np.asarray(view.wall.normal)),
            f"wall {k}",
            fill=PLAN_FRAME,
            font=font,
            anchor="mm",
        )
        x, y = at(lamp)
        r = PLAN_LAMP_PX
        draw.ellipse([x - r, y - r, x + r, y + r], fill=tuple(int(255 * c) for c in LAMP), outline=(0, 0, 0))
        draw.text((x, y + 2 * r), f"lamp {k}", fill=(0, 0, 0), font=font, anchor="mm")
    x, y = performer_px
    r = PLAN_PERSON_PX
    draw.ellipse([x - r, y - r, x + r, y + r], outline=(90, 90, 90), width=2)
    draw.text((x, y + 2 * r), "you", fill=(90, 90, 90), font=font, anchor="mm")
    bar = PLAN_SCALE_M * scale
    draw.line([(12, size - 14), (12 + bar, size - 14)], fill=(0, 0, 0), width=2)
    draw.text((12 + bar / 2, size - 26), f"{PLAN_SCALE_M * 100:.0f} cm", fill=(0, 0, 0), font=font, anchor="mm")
    draw.text((8, 6), "The set-up from above", fill=(40, 40, 40), font=font)


def _frame_ends(scene: Scene, extra_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The two ends (3,) of a view's picture along its width, through its centre, each
    extended by extra_m along the wall."""
    centre = frame_centre(scene)
    u = np.asarray(scene.image.u, float)
    half = 0.5 * u + extra_m * u / np.linalg.norm(u)
    return centre - half, centre + half
