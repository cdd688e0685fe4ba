"""Casting the shadow: project from the light, rasterise exactly, differentiate at the outline.

    xy, height = scene.project(vertices)             # (B, V, 2) pixels, (B, V) metres
    mask = shadow_mask(xy, topology, H, W)          # (B, H, W) exact 0/1, edge-sampled gradient
    soft = gaussian_blur(mask, sigma_px)            # optional wide mode for coarse stages

:class:`ShadowRenderer` composes the three for a fixed set of meshes (the hands of a fit).
"""

from __future__ import annotations

import numpy as np
import torch

from handshadow.render.shadow import MeshTopology, shadow_mask
from handshadow.render.soft import gaussian_blur
from handshadow.scene import Scene

__all__ = ["MeshTopology", "ShadowRenderer", "gaussian_blur", "merge_meshes", "mesh_shadow", "shadow_mask"]


def merge_meshes(vertices: list[torch.Tensor], faces: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """Concatenate meshes: vertices [(B, V_i, 3)] -> (B, sum V_i, 3); faces [(F_i, 3)] -> (sum F_i, 3)."""
    offsets = [0]
    for v in vertices[:-1]:
        offsets.append(offsets[-1] + v.shape[1])
    return torch.cat(vertices, 1), torch.cat([f + o for f, o in zip(faces, offsets)])


def mesh_shadow(scene: Scene, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(H, W) bool exact shadow of one closed mesh: vertices (V, 3) and faces (F, 3) as numpy
    arrays in the scene's units, projected in float64. No gradient."""
    points = torch.as_tensor(np.asarray(vertices, dtype=np.float64))[None]
    topology = MeshTopology.from_faces(torch.as_tensor(np.asarray(faces, dtype=np.int64)))
    with torch.no_grad():
        xy, _ = scene.project(points)
        mask = shadow_mask(xy, topology, scene.image.height, scene.image.width)
    return mask[0].numpy() > 0.5


class ShadowRenderer:
    """The shadow of a fixed set of meshes in a scene.

    Args:
        scene: light, wall and image frame (its width and height set the resolution).
        faces: one (F_i, 3) face tensor per mesh, in the order their vertices will be passed.
        num_vertices: V_i of each mesh.
    """

    def __init__(self, scene: Scene, faces: list[torch.Tensor], num_vertices: list[int]):
        self.scene = scene
        offsets = [sum(num_vertices[:i]) for i in range(len(faces))]
        self.topology = MeshTopology.from_faces(torch.cat([f + o for f, o in zip(faces, offsets)]))

    def to(self, device: torch.device | str) -> ShadowRenderer:
        self.topology = self.topology.to(device)
        return self

    def project(self, vertices: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """[(B, V_i, 3)] world vertices -> (B, V, 2) pixel coordinates and (B, V) heights above the wall."""
        return self.scene.project(torch.cat(vertices, 1))

    def __call__(self, vertices: list[torch.Tensor], sigma_px: float = 0.0) -> torch.Tensor:
        """(B, H, W) shadow of the meshes; exact when sigma_px is 0, else blurred by it."""
        xy, _ = self.project(vertices)
        mask = shadow_mask(xy, self.topology, self.scene.image.height, self.scene.image.width)
        return gaussian_blur(mask, sigma_px)
