"""Meshes out: OBJ per hand (the exact shadow-casting geometry) and a GLB of the whole scene."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import trimesh

from handshadow.scene import Scene

SKIN = (0.87, 0.68, 0.56)
OBJ_DIGITS = 9  # 1 nm: vertices are rounded to this before rendering, so OBJ and PNG agree


def round_vertices(vertices: np.ndarray) -> np.ndarray:
    """The vertex values an OBJ file stores; render the shadow from these."""
    return np.round(np.asarray(vertices, dtype=np.float64), OBJ_DIGITS)


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, name: str) -> None:
    """Plain OBJ (v / f lines), world frame, metres."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    text = trimesh.exchange.obj.export_obj(
        mesh, include_normals=False, include_texture=False, digits=OBJ_DIGITS, header=None
    )
    Path(path).write_text(f"# handshadow: {name}, world frame, metres\no {name}\n" + text)


def scene_trimesh(
    scene: Scene,
    hands: list[tuple[str, np.ndarray, np.ndarray]],
    shadow: np.ndarray | None,
    more_views: Sequence[tuple[Scene, np.ndarray | None]] = (),
) -> trimesh.Scene:
    """A trimesh scene: the hands (named by side), the wall frame textured with the shadow,
    and a small sphere at the lamp (or toward the sun for a directional light); further views
    (scene, shadow image) add their walls and lamps as wall_K and light_K, K = 1, 2, ..."""
    out = trimesh.Scene()
    for name, verts, faces in hands:
        mesh = trimesh.Trimesh(verts, faces, process=False)
        mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=np.r_[np.asarray(SKIN) * 255, 255].astype(np.uint8))
        out.add_geometry(mesh, node_name=f"{name}_hand", geom_name=f"{name}_hand")
    for k, (view, image) in enumerate([(scene, shadow), *more_views]):
        suffix = f"_{k}" if k else ""
        out.add_geometry(wall_mesh(view, image), node_name=f"wall{suffix}", geom_name=f"wall{suffix}")
        marker = trimesh.creation.icosphere(subdivisions=2, radius=0.04)
        marker.apply_translation(light_marker_position(view))
        marker.visual = trimesh.visual.ColorVisuals(marker, face_colors=[255, 214, 80, 255])
        out.add_geometry(marker, node_name=f"light{suffix}", geom_name=f"light{suffix}")
    return out


def wall_mesh(scene: Scene, shadow: np.ndarray | None) -> trimesh.Trimesh:
    """The image frame on the wall as two triangles, textured with the shadow image."""
    im = scene.image
    o, u, v = (np.asarray(a, float) for a in (im.origin, im.u, im.v))
    verts = np.stack([o, o + u, o + u + v, o + v])
    faces = np.array([[0, 2, 1], [0, 3, 2]])  # facing the light (+normal)
    if np.cross(u, v) @ np.asarray(scene.wall.normal) > 0:
        faces = faces[:, ::-1]
    mesh = trimesh.Trimesh(verts, faces, process=False)
    if shadow is not None:
        from PIL import Image

        texture = np.repeat(np.asarray(shadow, np.uint8)[..., None], 3, axis=2)
        uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float)  # glTF-style uv, v up in trimesh
        mesh.visual = trimesh.visual.TextureVisuals(
            uv=uv,
            material=trimesh.visual.material.PBRMaterial(
                baseColorTexture=Image.fromarray(texture), metallicFactor=0.0, roughnessFactor=1.0
            ),
        )
    return mesh


def light_marker_position(scene: Scene) -> np.ndarray:
    if scene.light.type == "point":
        return np.asarray(scene.light.position, float)
    d = np.asarray(scene.light.direction, float)
    centre = np.asarray(scene.image.origin) + 0.5 * np.asarray(scene.image.u) + 0.5 * np.asarray(scene.image.v)
    return centre - 2.0 * d / np.linalg.norm(d)


def write_glb(
    path: Path,
    scene: Scene,
    hands: list[tuple[str, np.ndarray, np.ndarray]],
    shadow: np.ndarray | None,
    more_views: Sequence[tuple[Scene, np.ndarray | None]] = (),
) -> None:
    Path(path).write_bytes(scene_trimesh(scene, hands, shadow, more_views).export(file_type="glb"))
