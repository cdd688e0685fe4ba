"""The whole path in a page: target -> scene -> hands -> render -> loss -> search -> export.

``render_pose_set`` turns a pose file into its shadow and pictures; the fit and the morph build
on the same pieces.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch

from handshadow.errors import HandshadowError
from handshadow.export.files import ResultFolder, shadow_image, write_json, write_png
from handshadow.export.meshes import round_vertices, write_glb, write_obj
from handshadow.export.pictures import scene_picture
from handshadow.hands import load_hand
from handshadow.posefile import PoseSet
from handshadow.render import MeshTopology, shadow_mask
from handshadow.scene import Scene


class PlacementError(HandshadowError):
    """Geometry that does not lie between the light and the wall."""


@dataclasses.dataclass(frozen=True)
class PosedMesh:
    """One posed hand, world frame: vertices (V, 3) float64 metres (rounded as in the OBJ),
    faces (F, 3), keypoints (21, 3)."""

    side: str
    vertices: np.ndarray
    faces: np.ndarray
    keypoints: np.ndarray


def pose_hands(pose_set: PoseSet, mano_dir: str | None = None) -> list[PosedMesh]:
    """Build and pose the hands of a pose file (float64)."""
    out = []
    for h in pose_set.hands:
        model = load_hand(h.model, h.side, h.shape, mano_dir, forearm=pose_set.forearm, dtype=torch.float64)
        with torch.no_grad():
            res = model(*h.tensors(dtype=torch.float64))
        out.append(
            PosedMesh(h.side, round_vertices(res.vertices[0].numpy()), res.faces.numpy(), res.keypoints[0].numpy())
        )
    return out


def check_placement(scene: Scene, meshes: list[PosedMesh]) -> None:
    """Raise PlacementError unless every vertex lies strictly between the light and the wall."""
    lo, hi = scene.light_depth_range()
    n = np.asarray(scene.wall.normal)
    for m in meshes:
        h = (m.vertices - np.asarray(scene.wall.point)) @ n
        if h.min() <= lo:
            raise PlacementError(
                f"the {m.side} hand reaches through the wall ({h.min():.3f} m); move it toward the light"
            )
        if h.max() >= hi:
            raise PlacementError(
                f"the {m.side} hand reaches the light's plane ({h.max():.3f} m from the wall); move it toward the wall"
            )


def exact_shadow(scene: Scene, meshes: list[PosedMesh]) -> np.ndarray:
    """(H, W) float mask of the exact shadow of the meshes (float64 projection)."""
    check_placement(scene, meshes)
    verts = torch.as_tensor(np.concatenate([m.vertices for m in meshes]))[None]
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    faces = torch.as_tensor(np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]))
    xy, _ = scene.project(verts)
    return shadow_mask(xy, MeshTopology.from_faces(faces), scene.image.height, scene.image.width)[0].numpy()


def mesh_names(meshes: list[PosedMesh]) -> list[str]:
    return [f"{m.side}.obj" for m in meshes]


def write_scene_files(folder: ResultFolder, scene: Scene, meshes: list[PosedMesh], mask: np.ndarray) -> None:
    """shadow.png, scene.json, <side>.obj, hands.glb and scene.png into the folder."""
    shadow = shadow_image(mask)
    write_png(folder / "shadow.png", shadow)
    write_json(folder / "scene.json", scene.to_json(meshes=mesh_names(meshes)))
    for m in meshes:
        write_obj(folder / f"{m.side}.obj", m.vertices, m.faces, f"{m.side}_hand")
    hands = [(m.side, m.vertices, m.faces) for m in meshes]
    write_glb(folder / "hands.glb", scene, hands, shadow)
    tips = np.concatenate([m.keypoints[[4, 12]] for m in meshes])  # thumb and middle tips
    write_png(folder / "scene.png", scene_picture(scene, hands, mask, rays_through=tips))


def render_pose_set(pose_set: PoseSet, out: str | Path, force: bool = False, mano_dir: str | None = None) -> Path:
    """Render a pose file into ``out``: shadow.png, scene.json, <side>.obj, hands.glb, scene.png."""
    meshes = pose_hands(pose_set, mano_dir)
    mask = exact_shadow(pose_set.scene, meshes)
    with ResultFolder(out, force) as folder:
        write_scene_files(folder, pose_set.scene, meshes, mask)
        write_json(folder / "pose.json", pose_set.to_json())
        return folder.commit()
