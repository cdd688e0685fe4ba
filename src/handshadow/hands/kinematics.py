"""Pure kinematics on batched tensors: joint angles -> rotations -> bone transforms -> skinning.

Conventions: rotations act on column vectors (p' = R p); a rigid transform is a pair
(R (..., 3, 3), t (..., 3)) meaning p' = R p + t. Angles are radians.
"""

from __future__ import annotations

import functools

import torch


def rotvec_to_rotmat(rotvec: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula: rotation vectors (..., 3) (axis times angle, radians) -> (..., 3, 3).

    Same result as ``roma.rotvec_to_rotmat`` (tests check it); written here because importing
    roma pulls in torch._dynamo and adds about 2 s to every command's start.
    Smooth at zero: R = I + A [r]x + B [r]x^2 with A = sin t / t, B = (1 - cos t) / t^2.
    """
    theta2 = (rotvec * rotvec).sum(-1, keepdim=True)[..., None]  # (..., 1, 1)
    small = theta2 < 1e-8
    theta = torch.sqrt(torch.where(small, torch.ones_like(theta2), theta2))
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(
        small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / torch.where(small, torch.ones_like(theta2), theta2)
    )
    x, y, z = rotvec.unbind(-1)
    zero = torch.zeros_like(x)
    k = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(rotvec.shape[:-1] + (3, 3))
    eye = torch.eye(3, dtype=rotvec.dtype, device=rotvec.device)
    return eye + a * k + b * (k @ k)


def axis_angle_rotations(axes: torch.Tensor, angles_rad: torch.Tensor) -> torch.Tensor:
    """Rotations about the given unit axes.

    Args:
        axes: (..., 3) unit axes.
        angles_rad: (...,) angles, radians, right-hand rule about the axis.
    Returns:
        (..., 3, 3) rotation matrices.
    """
    return rotvec_to_rotmat(axes * angles_rad[..., None])


def anatomical_rotations(angles_rad: torch.Tensor, joint_axes: torch.Tensor) -> torch.Tensor:
    """Joint rotations from (twist, spread, bend) angles.

    R = R_bend @ R_spread @ R_twist, each about the joint's rest-frame axis, so that twist is
    applied first (about the bone), then spread, then bend.

    Args:
        angles_rad: (B, 15, 3) twist, spread, bend per joint.
        joint_axes: (15, 3, 3) rows [twist, spread, bend] unit axes.
    Returns:
        (B, 15, 3, 3) rotations in the hand's rest frame, about each joint's centre.
    """
    axes = joint_axes.expand(angles_rad.shape[0], -1, -1, -1)  # (B, 15, 3, 3)
    r = axis_angle_rotations(axes, angles_rad)  # (B, 15, 3, 3, 3): one per axis
    return r[:, :, 2] @ r[:, :, 1] @ r[:, :, 0]


def rotations_to_anatomical(rotations: torch.Tensor, joint_axes: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`anatomical_rotations`: (B, 15, 3, 3) -> (B, 15, 3) radians.

    Expresses each rotation in the joint's (twist, spread, bend) frame and reads the intrinsic
    Euler angles. Exact for spread within (-90, 90) degrees.
    """
    a = joint_axes.transpose(-1, -2)  # columns = axes
    # In axis coordinates R' = A^T R A = Rz(bend) Ry(spread) Rx(twist) when A is right-handed.
    det = torch.linalg.det(joint_axes)[:, None]  # (15, 1): +1 or -1
    local = a.transpose(-1, -2) @ rotations @ a
    twist = torch.atan2(local[..., 2, 1], local[..., 2, 2])
    spread = torch.asin(torch.clamp(-local[..., 2, 0], -1.0, 1.0))
    bend = torch.atan2(local[..., 1, 0], local[..., 0, 0])
    # In a left-handed axis frame every rotation angle reads with the opposite sign.
    return torch.stack([twist, spread, bend], dim=-1) * det[None]


def forward_kinematics(
    joint_rotations: torch.Tensor,
    joint_bones: torch.Tensor,
    bone_heads: torch.Tensor,
    bone_parents: list[int],
) -> tuple[torch.Tensor, torch.Tensor]:
    """Rigid transform of every bone, mapping rest-pose points to posed points.

    Bone k rotates about its rest head h_k by its own rotation R_k (identity for bones that
    are not articulated) after its parent: G_k = G_parent(k) o [x -> R_k (x - h_k) + h_k].
    Bones are composed level by level (all bones of one depth at once).

    Args:
        joint_rotations: (B, 15, 3, 3) rotations of the articulated bones.
        joint_bones: (15,) long, the bone index of each articulated joint.
        bone_heads: (K, 3) rest heads.
        bone_parents: K parent indices, -1 for roots.
    Returns:
        rotations (B, K, 3, 3) and translations (B, K, 3) of the bone transforms.
    """
    batch = joint_rotations.shape[0]
    k_bones = bone_heads.shape[0]
    eye = torch.eye(3, dtype=joint_rotations.dtype, device=joint_rotations.device)
    local = eye.expand(batch, k_bones, 3, 3).clone()
    local[:, joint_bones] = joint_rotations
    # Local transform about the head: x -> R (x - h) + h, i.e. t = h - R h.
    local_t = bone_heads - (local @ bone_heads[..., None])[..., 0]
    rots, trans = local.clone(), local_t.clone()
    for level, parents in _levels(tuple(bone_parents)):
        idx = torch.as_tensor(level, device=local.device)
        par = torch.as_tensor(parents, device=local.device)
        rp, tp = rots[:, par], trans[:, par]
        rots[:, idx] = rp @ local[:, idx]
        trans[:, idx] = (rp @ local_t[:, idx, :, None])[..., 0] + tp
    return rots, trans


@functools.lru_cache(maxsize=8)
def _levels(parents: tuple[int, ...]) -> list[tuple[list[int], list[int]]]:
    """Bones grouped by depth below the roots (roots excluded): [(bones, their parents)]."""
    depth = {}
    for k, p in enumerate(parents):
        depth[k] = 0 if p < 0 else depth[p] + 1  # parents come before children
    levels = []
    for d in range(1, max(depth.values(), default=0) + 1):
        bones = [k for k in range(len(parents)) if depth[k] == d]
        levels.append((bones, [parents[k] for k in bones]))
    return levels


def linear_blend_skinning(
    rest_vertices: torch.Tensor,
    skin_weights: torch.Tensor,
    bone_rotations: torch.Tensor,
    bone_translations: torch.Tensor,
) -> torch.Tensor:
    """Linear blend skinning.

    Args:
        rest_vertices: (V, 3) or (B, V, 3).
        skin_weights: (V, K), rows sum to 1.
        bone_rotations: (B, K, 3, 3); bone_translations: (B, K, 3).
    Returns:
        (B, V, 3) posed vertices.
    """
    batch, k_bones = bone_rotations.shape[:2]
    transforms = torch.cat([bone_rotations, bone_translations[..., None]], dim=-1)  # (B,K,3,4)
    blended = (skin_weights @ transforms.reshape(batch, k_bones, 12)).reshape(batch, -1, 3, 4)
    if rest_vertices.dim() == 2:
        rest_vertices = rest_vertices.expand(batch, -1, -1)
    return (blended[..., :3] @ rest_vertices[..., None])[..., 0] + blended[..., 3]


def apply_rigid(points: torch.Tensor, rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """p' = R p + t for points (B, N, 3), rotation (B, 3, 3), translation (B, 3)."""
    return points @ rotation.transpose(-1, -2) + translation[:, None, :]
