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


def rotmat_to_rotvec(rotation: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`rotvec_to_rotmat`: (..., 3, 3) -> (..., 3), angles in [0, pi].

    Through the unit quaternion (Shepperd's method picks the numerically safest branch).
    """
    m = rotation
    tr = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = torch.stack(
        [
            torch.stack(
                [1 + tr, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1
            ),
            torch.stack(
                [
                    m[..., 2, 1] - m[..., 1, 2],
                    1 + 2 * m[..., 0, 0] - tr,
                    m[..., 0, 1] + m[..., 1, 0],
                    m[..., 0, 2] + m[..., 2, 0],
                ],
                -1,
            ),
            torch.stack(
                [
                    m[..., 0, 2] - m[..., 2, 0],
                    m[..., 0, 1] + m[..., 1, 0],
                    1 + 2 * m[..., 1, 1] - tr,
                    m[..., 1, 2] + m[..., 2, 1],
                ],
                -1,
            ),
            torch.stack(
                [
                    m[..., 1, 0] - m[..., 0, 1],
                    m[..., 0, 2] + m[..., 2, 0],
                    m[..., 1, 2] + m[..., 2, 1],
                    1 + 2 * m[..., 2, 2] - tr,
                ],
                -1,
            ),
        ],
        -2,
    )  # (..., 4, 4): each row a quaternion (w, x, y, z) up to scale
    diag = torch.stack([tr, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], -1)
    best = diag.argmax(-1)
    q = torch.gather(cands, -2, best[..., None, None].expand(*best.shape, 1, 4))[..., 0, :]
    q = q / q.norm(dim=-1, keepdim=True)
    q = q * torch.where(q[..., :1] < 0, -1.0, 1.0).to(q.dtype)  # w >= 0: the short way round
    sin_half = q[..., 1:].norm(dim=-1, keepdim=True)
    angle = 2 * torch.atan2(sin_half, q[..., :1])
    scale = torch.where(sin_half > 1e-8, angle / sin_half.clamp(min=1e-12), torch.full_like(angle, 2.0))
    return q[..., 1:] * scale


def slerp_rotations(r0: torch.Tensor, r1: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Geodesic interpolation on SO(3): r0 (3, 3), r1 (3, 3), t (N,) in [0, 1] -> (N, 3, 3)."""
    delta = rotmat_to_rotvec(r0.transpose(-1, -2) @ r1)
    return r0 @ rotvec_to_rotmat(t[:, None] * delta)


def rotation_angle_deg(r0: torch.Tensor, r1: torch.Tensor) -> torch.Tensor:
    """Geodesic angle between rotations (..., 3, 3), degrees."""
    return torch.rad2deg(rotmat_to_rotvec(r0.transpose(-1, -2) @ r1).norm(dim=-1))


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

    Bone k rotates about its rest head h_k by its own rotation R_k after its parent:
    G_k = G_parent(k) o [x -> R_k (x - h_k) + h_k]. Only the 15 finger joints rotate (the
    wrist, palm and metacarpal bones are fixed; the global transform is applied afterwards),
    so each finger is a chain J1 -> J2 -> J3 hanging from fixed bones, composed for all five
    fingers at once.

    Args:
        joint_rotations: (B, 15, 3, 3) rotations of the articulated bones (JOINT_NAMES order).
        joint_bones: (15,) long, the bone index of each articulated joint.
        bone_heads: (K, 3) rest heads.
        bone_parents: K parent indices, -1 for roots.
    Returns:
        rotations (B, K, 3, 3) and translations (B, K, 3) of the bone transforms.
    """
    batch = joint_rotations.shape[0]
    k_bones = bone_heads.shape[0]
    heads = bone_heads.index_select(0, joint_bones)  # (15, 3)
    # Local transform about the head: x -> R (x - h) + h, i.e. t = h - R h.
    t_local = heads - (joint_rotations @ heads[..., None])[..., 0]  # (B, 15, 3)
    r = joint_rotations.view(batch, 5, 3, 3, 3)
    t = t_local.view(batch, 5, 3, 3)
    r2 = r[:, :, 0] @ r[:, :, 1]
    t2 = (r[:, :, 0] @ t[:, :, 1, :, None])[..., 0] + t[:, :, 0]
    r3 = r2 @ r[:, :, 2]
    t3 = (r2 @ t[:, :, 2, :, None])[..., 0] + t2
    rots = torch.stack([r[:, :, 0], r2, r3], 2).reshape(batch, 15, 3, 3)
    trans = torch.stack([t[:, :, 0], t2, t3], 2).reshape(batch, 15, 3)
    # Every other bone keeps the identity: gather from [identity, joints...] by bone.
    source = _bone_sources(tuple(int(b) for b in joint_bones), tuple(bone_parents), k_bones)
    source = torch.as_tensor(source, device=joint_rotations.device)
    eye = torch.eye(3, dtype=rots.dtype, device=rots.device).expand(batch, 1, 3, 3)
    all_r = torch.cat([eye, rots], 1).index_select(1, source)
    all_t = torch.cat([torch.zeros_like(trans[:, :1]), trans], 1).index_select(1, source)
    return all_r, all_t


@functools.lru_cache(maxsize=8)
def _bone_sources(joint_bones: tuple[int, ...], parents: tuple[int, ...], k_bones: int) -> list[int]:
    """Per bone, 0 (fixed) or 1 + its joint index; checks the finger-chain structure."""
    joint_of = {b: j for j, b in enumerate(joint_bones)}
    for j, b in enumerate(joint_bones):
        parent = parents[b]
        if j % 3:
            ok = parent == joint_bones[j - 1]
        else:  # J1 hangs from fixed bones only
            ok = True
            while parent >= 0:
                ok &= parent not in joint_of
                parent = parents[parent]
        if not ok:
            raise ValueError("the rig's finger joints do not form J1 -> J2 -> J3 chains under fixed bones")
    for k in range(k_bones):
        if k not in joint_of and any(p in joint_of for p in _ancestors(k, parents)):
            raise ValueError(f"bone {k} hangs from a finger joint but is not one of the 15 joints")
    return [0 if k not in joint_of else 1 + joint_of[k] for k in range(k_bones)]


def _ancestors(k: int, parents: tuple[int, ...]) -> list[int]:
    out = []
    while parents[k] >= 0:
        k = parents[k]
        out.append(k)
    return out


def linear_blend_skinning(
    rest_vertices: torch.Tensor,
    skin_weights: torch.Tensor,
    bone_rotations: torch.Tensor,
    bone_translations: torch.Tensor,
    features: torch.Tensor | None = None,
) -> torch.Tensor:
    """Linear blend skinning.

    Args:
        rest_vertices: (V, 3) or (B, V, 3).
        skin_weights: (V, K), rows sum to 1.
        bone_rotations: (B, K, 3, 3); bone_translations: (B, K, 3).
        features: skinning_features(rest_vertices, skin_weights) when the caller keeps them
            (rest vertices (V, 3) only); None computes them.
    Returns:
        (B, V, 3) posed vertices.
    """
    batch, k_bones = bone_rotations.shape[:2]
    transforms = torch.cat([bone_rotations, bone_translations[..., None]], dim=-1)  # (B,K,3,4)
    if rest_vertices.dim() == 2:
        # One matrix product for the whole batch: posed[b, v, i] = sum over bones k and
        # homogeneous coordinates j of (w[v, k] * rest[v, j]) * T[b, k, i, j]. On this CPU a
        # batch of 32 hands (1,950 vertices, 22 bones) takes a sixth of the blend-then-apply
        # form's time, forward and backward.
        features = skinning_features(rest_vertices, skin_weights) if features is None else features  # (V, 4K)
        flat = transforms.permute(1, 3, 0, 2).reshape(k_bones * 4, batch * 3)  # (4K, B*3)
        return (features @ flat).reshape(-1, batch, 3).transpose(0, 1)
    blended = (skin_weights @ transforms.reshape(batch, k_bones, 12)).reshape(batch, -1, 3, 4)
    # Many tiny 3x3 products: an elementwise product and a sum beats a batched matmul here.
    return (blended[..., :3] * rest_vertices[..., None, :]).sum(-1) + blended[..., 3]


def skinning_features(rest_vertices: torch.Tensor, skin_weights: torch.Tensor) -> torch.Tensor:
    """(V, 4K): each vertex's skin weights times its homogeneous rest position, for rest
    vertices (V, 3) and skin weights (V, K); column 4k + j is w[v, k] * [x, y, z, 1][j]."""
    homogeneous = torch.cat([rest_vertices, rest_vertices.new_ones(rest_vertices.shape[0], 1)], 1)
    return (skin_weights[:, :, None] * homogeneous[:, None, :]).reshape(rest_vertices.shape[0], -1)


def apply_rigid(points: torch.Tensor, rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """p' = R p + t for points (B, N, 3), rotation (B, 3, 3), translation (B, 3)."""
    return points @ rotation.transpose(-1, -2) + translation[:, None, :]
