"""Pictures of the 3D scene for people: a pinhole camera, a depth buffer and simple shading.

Not differentiable and not used for fitting; it reuses the exact span rasteriser to produce
per-pixel fragments, keeps the nearest one per pixel and shades it (Lambert with a key and a
fill light, smooth vertex normals, or a texture looked up by interpolated UVs).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from handshadow.render import merge_faces
from handshadow.render.raster import fragments, rasterize_spans


@dataclasses.dataclass(frozen=True)
class Camera:
    """A pinhole camera looking from ``position`` at ``target``; ``fov_deg`` is vertical."""

    position: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov_deg: float = 40.0
    width: int = 640
    height: int = 480

    def basis(self) -> np.ndarray:
        """(3, 3) rows: right, up, forward (unit), world coordinates."""
        f = np.asarray(self.target, float) - np.asarray(self.position, float)
        f /= np.linalg.norm(f)
        r = np.cross(f, np.asarray(self.up, float))
        r /= np.linalg.norm(r)
        return np.stack([r, np.cross(r, f), f])

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) world points -> (N, 2) continuous pixel coordinates (column, row), (N,) depth."""
        cam = (np.asarray(points, float) - np.asarray(self.position, float)) @ self.basis().T
        depth = cam[:, 2]
        focal = 0.5 * self.height / np.tan(np.radians(self.fov_deg) / 2)
        safe = np.where(depth > 1e-6, depth, 1e-6)
        x = self.width / 2 + focal * cam[:, 0] / safe
        y = self.height / 2 - focal * cam[:, 1] / safe
        return np.stack([x, y], 1), depth


@dataclasses.dataclass
class ViewMesh:
    """A mesh to draw: vertices (V, 3), faces (F, 3); a colour (3,) in [0, 1] or a texture
    (h, w, 3) in [0, 1] with per-vertex ``uv`` (V, 2) (u right, v down, in [0, 1]);
    ``emissive`` meshes ignore lighting."""

    vertices: np.ndarray
    faces: np.ndarray
    color: tuple[float, float, float] = (0.8, 0.8, 0.8)
    texture: np.ndarray | None = None
    uv: np.ndarray | None = None
    emissive: bool = False


def render_view(
    meshes: list[ViewMesh],
    camera: Camera,
    background: tuple[float, float, float] = (1.0, 1.0, 1.0),
    key_light: tuple[float, float, float] = (0.4, 0.8, 0.6),
    supersample: int = 2,
) -> np.ndarray:
    """Draw the meshes; returns (H, W, 3) uint8."""
    s = supersample
    cam = dataclasses.replace(camera, width=camera.width * s, height=camera.height * s)
    h, w = cam.height, cam.width
    verts = np.concatenate([m.vertices for m in meshes])
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    faces = merge_faces([m.faces for m in meshes], [len(m.vertices) for m in meshes])
    mesh_of_face = np.concatenate([np.full(len(m.faces), i) for i, m in enumerate(meshes)])
    xy, depth = cam.project(verts)
    tri_xy = torch.as_tensor(xy[faces], dtype=torch.float64)[None]
    tri_z = depth[faces]
    in_front = torch.as_tensor((tri_z > 1e-3).all(1))[None]
    b, face, row, col = fragments(rasterize_spans(tri_xy, h, w, keep=in_front))
    face_np = face.numpy()
    bary = _barycentric(xy[faces[face_np]], np.stack([col.numpy() + 0.5, row.numpy() + 0.5], 1))
    inv_z = (bary / tri_z[face_np]).sum(1)  # 1/depth is affine in screen space
    pixel = row.numpy() * w + col.numpy()
    order = np.lexsort((-inv_z, pixel))  # per pixel, nearest first
    first = np.ones(len(order), bool)
    first[1:] = pixel[order][1:] != pixel[order][:-1]
    keep = order[first]
    pixel, face_np, bary = pixel[keep], face_np[keep], bary[keep]
    # Perspective-correct barycentrics for attribute interpolation.
    pc = bary / tri_z[face_np]
    pc /= pc.sum(1, keepdims=True)

    image = np.tile(np.asarray(background, float), (h * w, 1))
    normals = _vertex_normals(verts, faces)
    light = np.asarray(key_light, float) / np.linalg.norm(key_light)
    view_dir = -cam.basis()[2]
    for i, m in enumerate(meshes):
        sel = mesh_of_face[face_np] == i
        if not sel.any():
            continue
        fv = faces[face_np[sel]]
        wts = pc[sel][..., None]
        if m.texture is not None:
            uv = (m.uv[fv - offsets[i]] * wts).sum(1)
            th, tw = m.texture.shape[:2]
            color = m.texture[
                np.clip((uv[:, 1] * th).astype(int), 0, th - 1), np.clip((uv[:, 0] * tw).astype(int), 0, tw - 1)
            ]
        else:
            color = np.broadcast_to(np.asarray(m.color, float), (int(sel.sum()), 3))
        if not m.emissive:
            n = (normals[fv] * wts).sum(1)
            n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
            n *= np.where((n @ view_dir) < 0, -1.0, 1.0)[:, None]  # light the side we see
            diffuse = np.clip(n @ light, 0, None)
            fill = np.clip(n @ view_dir, 0, None)
            color = color * (0.35 + 0.5 * diffuse + 0.25 * fill)[:, None]
        image[pixel[sel]] = color
    image = image.reshape(h, w, 3)
    if s > 1:
        image = image.reshape(camera.height, s, camera.width, s, 3).mean((1, 3))
    return (np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)


def _barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (N, 3) of points p (N, 2) in triangles tri (N, 3, 2)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    v0, v1, v2 = b - a, c - a, p - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    den = np.where(np.abs(den) < 1e-12, 1e-12, den)
    l1 = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
    l2 = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    return np.clip(np.stack([1 - l1 - l2, l1, l2], 1), 0, 1)


def _vertex_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    fn = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    n = np.zeros_like(verts)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    return n / (np.linalg.norm(n, axis=1, keepdims=True) + 1e-12)
