"""A pose file's hands as meshes, and the shadow they cast: the exact geometry of a result.

    meshes, mask = cast_shadow(posed_scene)   # [PosedMesh] float64 metres, (H, W) float mask
    arms = arm_check(posed_scene)             # hands.arms.ArmCheck: can a person hold them?
    pen = pose_penetration(posed_scene, meshes) # hands.penetration.Penetration, between and within
    meshes, masks = cast_shadows(posed_scene) # ... and one (H, W) mask per view

Vertices are rounded as the OBJ files store them, so the written shadow, the meshes and any
independent recomputation from the files agree to the pixel.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from handshadow.errors import HandshadowError
from handshadow.export.meshes import round_vertices
from handshadow.hands import load_hand
from handshadow.hands.arms import ArmCheck, arm_checks
from handshadow.hands.penetration import Penetration, hand_parts, penetration
from handshadow.poses import HandPoseBatch, PosedScene
from handshadow.render import exact_shadow
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


def pose_meshes(posed: PosedScene, mano_dir: str | None = None) -> list[PosedMesh]:
    """Build and pose the hands of a pose file (float64)."""
    out = []
    for h, model in zip(posed.hands, hand_models(posed, mano_dir)):
        with torch.no_grad():
            res = model(*HandPoseBatch.from_hand_poses([h], dtype=torch.float64).args())
        out.append(
            PosedMesh(h.side, round_vertices(res.vertices[0].numpy()), res.faces.numpy(), res.keypoints[0].numpy())
        )
    return out


def hand_models(posed: PosedScene, mano_dir: str | None = None) -> list:
    """The pose file's hands as HandModels (float64), in its order."""
    return [
        load_hand(h.model, h.side, h.shape, mano_dir, forearm=posed.forearm, dtype=torch.float64) for h in posed.hands
    ]


def pose_penetration(
    posed: PosedScene, meshes: list[PosedMesh], mano_dir: str | None = None, models: list | None = None
) -> Penetration:
    """The exact mesh test (hands.penetration) of a pose file's meshes (pose_meshes): how deep
    the hands pass into each other, and a finger into its own hand (a part into another
    part of the same hand). models: the file's hand_models, when already built."""
    parts = [hand_parts(m) for m in models or hand_models(posed, mano_dir)]
    return penetration([m.vertices for m in meshes], [m.faces for m in meshes], parts)


def arm_check(posed: PosedScene, mano_dir: str | None = None, models: list | None = None) -> ArmCheck:
    """The arm rules (hands.arms) for a pose file's hands in every view: whether each
    forearm leads back toward the performer, each elbow's shadow is out of the picture, and
    how many people the elbows' span needs. models: the file's hand_models, when already
    built."""
    models = models or hand_models(posed, mano_dir)
    hands = [HandPoseBatch.from_hand_poses([h], dtype=torch.float64) for h in posed.hands]
    with torch.no_grad():
        return arm_checks(models, hands, posed.views)[0]


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


def mesh_shadow(scene: Scene, meshes: list[PosedMesh]) -> np.ndarray:
    """(H, W) float mask of the exact shadow of posed meshes, after checking their placement."""
    check_placement(scene, meshes)
    return exact_shadow(scene, [m.vertices for m in meshes], [m.faces for m in meshes])


def cast_shadow(posed: PosedScene, mano_dir: str | None = None) -> tuple[list[PosedMesh], np.ndarray]:
    """The meshes of a pose file and their exact shadow (H, W) float in its scene (view 0)."""
    meshes = pose_meshes(posed, mano_dir)
    return meshes, mesh_shadow(posed.scene, meshes)


def cast_shadows(posed: PosedScene, mano_dir: str | None = None) -> tuple[list[PosedMesh], list[np.ndarray]]:
    """The meshes of a pose file and their exact shadow (H, W) float in each of its views."""
    meshes = pose_meshes(posed, mano_dir)
    if len(posed.views) == 1:
        return meshes, [mesh_shadow(posed.scene, meshes)]
    masks = []
    for k, scene in enumerate(posed.views):
        try:
            masks.append(mesh_shadow(scene, meshes))
        except PlacementError as exc:
            raise PlacementError(f"view {k}: {exc}") from None
    return meshes, masks
