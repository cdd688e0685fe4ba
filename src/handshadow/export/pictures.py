"""Pictures for people: the 3D scene (what casts what) and the performer's view of the hands."""

from __future__ import annotations

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
) -> np.ndarray:
    """The lamp, the hands and the wall with the shadow on it, seen from above and beside.

    Args:
        hands: (side, vertices (V, 3), faces (F, 3)) per hand, world frame.
        shadow: (H, W) mask in [0, 1] of the image frame.
        rays_through: optional (N, 3) points; a thin ray is drawn from the lamp through each
            to the wall, to show how the shadow forms.
    Returns (H, W, 3) uint8.
    """
    meshes = [ViewMesh(v, f, color=HAND_COLORS.get(side, SKIN)) for side, v, f in hands]
    meshes.append(_wall(scene, shadow))
    lamp = light_marker_position(scene)
    meshes.append(_sphere(lamp, 0.05, LAMP, emissive=True))
    if rays_through is not None:
        for p in np.asarray(rays_through, float):
            hit = _on_wall(scene, p)
            if hit is not None:
                meshes.append(
                    _rod(
                        lamp if scene.light.type == "point" else p - 0.6 * np.asarray(scene.light.direction),
                        hit,
                        0.0025,
                        RAY,
                    )
                )
    centre = np.asarray(scene.image.origin) + 0.5 * np.asarray(scene.image.u) + 0.5 * np.asarray(scene.image.v)
    normal = np.asarray(scene.wall.normal, float)
    depth = float((lamp - centre) @ normal)
    # Over the performer's right shoulder: lamp in front, hands in the middle, wall behind.
    up = up_dir(scene)
    side_dir = np.asarray(scene.image.u, float) / np.linalg.norm(scene.image.u)
    look_at = centre + normal * depth * 0.3
    eye = centre + normal * (1.45 * depth) + side_dir * (0.55 * depth) + up * (0.35 * depth)
    camera = Camera(tuple(eye), tuple(look_at), tuple(up), fov_deg=42.0, width=size[0], height=size[1])
    return render_view(meshes, camera, background=(0.93, 0.94, 0.96))


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
    normal = np.asarray(scene.wall.normal, float)
    up = up_dir(scene)
    eye = target + normal * distance + up * 0.25 * distance
    camera = Camera(tuple(eye), tuple(target), tuple(up), fov_deg=45.0, width=size[0], height=size[1])
    return render_view(meshes, camera, background=(1.0, 1.0, 1.0), supersample=supersample)


def performer_framing(vertex_sets: list[np.ndarray], scene: Scene) -> tuple[np.ndarray, float]:
    """Where the performer's camera looks and from how far (metres): the median of the
    vertices (V, 3) of all sets, seen from far enough that 90 % of them fit across the view,
    beyond the depth of what reaches toward the lamp (a forearm pointing at it)."""
    pts = np.concatenate([np.asarray(v, float).reshape(-1, 3) for v in vertex_sets])
    centre = np.median(pts, axis=0)
    normal = np.asarray(scene.wall.normal, float)
    d = pts - centre
    depth = d @ normal
    across = np.linalg.norm(d - np.outer(depth, normal), axis=1)
    return centre, max(0.45, 3.2 * float(np.percentile(across, 90)) + max(0.0, float(np.percentile(depth, 90))))


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
