"""Casting the shadow: project from the light, rasterise exactly, differentiate at the outline.

    xy, height = scene.project(vertices)             # (B, V, 2) pixels, (B, V) metres
    mask = shadow_mask(xy, topology, H, W)          # (B, H, W) exact 0/1, edge-sampled gradient
    soft = gaussian_blur(mask, sigma_px)            # optional wide mode for coarse stages

:class:`ShadowRenderer` composes the two steps for a fixed set of meshes (the hands of a fit);
:func:`exact_shadow` casts the shadow of posed meshes (numpy, float64), as the files show it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import torch

from handshadow.render.shadow import MeshTopology, shadow_mask
from handshadow.render.soft import gaussian_blur
from handshadow.scene import Scene

__all__ = [
    "MeshTopology",
    "Shadow",
    "ShadowRenderer",
    "exact_shadow",
    "gaussian_blur",
    "merge_faces",
    "shadow_mask",
]


def merge_faces(faces: Sequence, num_vertices: Sequence[int]):
    """Faces of meshes whose vertices are concatenated in this order: [(F_i, 3)] and their
    vertex counts V_i -> (sum F_i, 3), each mesh's indices offset by the vertices before it.
    numpy arrays in, numpy out; tensors in, a tensor out."""
    offsets = np.cumsum([0, *num_vertices[:-1]])
    shifted = [f + int(o) for f, o in zip(faces, offsets)]
    return torch.cat(shifted) if isinstance(faces[0], torch.Tensor) else np.concatenate(shifted)


@dataclasses.dataclass(frozen=True)
class Shadow:
    """What the renderer gives: mask (B, H, W) exact 0/1 in the vertices' dtype (gradients at
    the outline), points_xy (B, V, 2) projected vertices in pixels, heights (B, V) distances
    of the vertices in front of the wall, metres."""

    mask: torch.Tensor
    points_xy: torch.Tensor
    heights: torch.Tensor


class ShadowRenderer:
    """The shadow of a fixed set of meshes in a scene: a projection from the light composed
    with the exact rasteriser.

    Args:
        scene: light, wall and image frame (its width and height set the resolution).
        faces: one (F_i, 3) face tensor per mesh, in the order their vertices will be passed.
        num_vertices: V_i of each mesh.
    """

    def __init__(self, scene: Scene, faces: list[torch.Tensor], num_vertices: list[int]):
        self.scene = scene
        self.topology = MeshTopology.from_faces(merge_faces(faces, num_vertices))

    def to(self, device: torch.device | str) -> ShadowRenderer:
        self.topology = self.topology.to(device)
        return self

    def render(self, vertices: list[torch.Tensor]) -> Shadow:
        """[(B, V_i, 3)] world vertices -> :class:`Shadow`."""
        xy, heights = self.scene.project(torch.cat(vertices, 1))
        mask = shadow_mask(xy, self.topology, self.scene.image.height, self.scene.image.width)
        return Shadow(mask, xy, heights)

    def __call__(self, vertices: list[torch.Tensor], sigma_px: float = 0.0) -> torch.Tensor:
        """(B, H, W) shadow of the meshes; exact when sigma_px is 0, else blurred by it."""
        return gaussian_blur(self.render(vertices).mask, sigma_px)


def exact_shadow(scene: Scene, vertices: Sequence[np.ndarray], faces: Sequence[np.ndarray]) -> np.ndarray:
    """(H, W) float mask of the exact shadow of meshes given as numpy vertices (V_i, 3) and
    faces (F_i, 3), projected in float64. The caller checks that they lie between the light
    and the wall."""
    verts = torch.as_tensor(np.concatenate(vertices), dtype=torch.float64)[None]
    topology = MeshTopology.from_faces(torch.as_tensor(merge_faces(list(faces), [len(v) for v in vertices])))
    xy, _ = scene.project(verts)
    return shadow_mask(xy, topology, scene.image.height, scene.image.width)[0].numpy()
