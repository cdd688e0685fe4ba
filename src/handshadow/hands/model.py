"""HandModel: H(shape, pose, rotation, translation) -> vertices, faces, keypoints.

One class poses any :class:`~handshadow.hands.rig.HandRig` (Anny or MANO), with or without its
forearm. The shape is fixed when the rig is built; ``forward`` takes the per-hypothesis pose.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from handshadow.hands import kinematics
from handshadow.hands.forearm import attach_forearm, cap_wrist, forearm_axis, forearm_length_m, wrist_centre
from handshadow.hands.rig import N_JOINTS, HandRig


@dataclasses.dataclass(frozen=True)
class HandOutput:
    """Posed hands, world frame, metres.

    vertices: (B, V, 3); faces: (F, 3) long (shared by the batch);
    keypoints: (B, 21, 3) wrist, then per finger (thumb..little) its 3 joints and its tip
    (KEYPOINT_NAMES order);
    bone_rotations (B, K, 3, 3), bone_translations (B, K, 3): each bone's rigid transform of
    rest points, hand frame (before the global rotation and translation);
    forearm_points: (B, P, 3) points along the forearm's axis from the wrist to the elbow
    (P = 0 without a forearm).
    """

    vertices: torch.Tensor
    faces: torch.Tensor
    keypoints: torch.Tensor
    bone_rotations: torch.Tensor
    bone_translations: torch.Tensor
    forearm_points: torch.Tensor


class HandModel(torch.nn.Module):
    """A posable hand (optionally with its forearm) built from a rig.

    Args:
        rig: the hand rig, hand frame (wrist at the origin, +y distal, +z dorsal).
        forearm: append a forearm, joined to the wrist, that moves with the global transform;
            without it the wrist opening is capped.
        dtype: floating type of the buffers (float32 for speed, float64 for checks).
    """

    def __init__(self, rig: HandRig, forearm: bool = True, dtype: torch.dtype = torch.float32):
        super().__init__()
        self.rig = rig
        self.side = rig.side
        self.model_name = rig.model
        self.num_hand_vertices = rig.num_vertices
        # Either way the mesh is closed: a forearm, or a cap over the wrist opening.
        verts, faces, weights = attach_forearm(rig) if forearm else cap_wrist(rig)
        self.forearm_bone = len(rig.bone_parents) if forearm else None  # an extra bone, last
        self.register_buffer(
            "wrist_centre", torch.as_tensor(wrist_centre(rig) if forearm else np.zeros(3), dtype=dtype)
        )
        if forearm:
            centre, axis = forearm_axis(rig)
            axis_points = centre + np.linspace(0.04 * rig.size, forearm_length_m(rig), 6)[:, None] * axis
        else:
            axis_points = np.zeros((0, 3))
        self.register_buffer("forearm_axis_points", torch.as_tensor(axis_points, dtype=dtype))
        # Deviation toward the thumb turns the forearm toward the little finger: mirrored sides.
        self.radial_sign = 1.0 if rig.side == "right" else -1.0
        self.has_forearm = forearm
        self.register_buffer("rest_vertices", torch.as_tensor(verts, dtype=dtype))
        self.register_buffer("faces", torch.as_tensor(faces, dtype=torch.long))
        self.register_buffer("skin_weights", torch.as_tensor(weights, dtype=dtype))
        # The skinning's constant factor (kinematics.skinning_features), kept once.
        self.register_buffer("skin_features", kinematics.skinning_features(self.rest_vertices, self.skin_weights))
        self.register_buffer("bone_heads", torch.as_tensor(rig.bone_heads, dtype=dtype))
        self.register_buffer("joint_axes", torch.as_tensor(rig.joint_axes, dtype=dtype))
        self.register_buffer("joint_bones", torch.as_tensor(rig.joint_bones, dtype=torch.long))
        self.register_buffer("tip_vertices", torch.as_tensor(rig.tip_vertices, dtype=torch.long))
        self.bone_parents = [int(p) for p in rig.bone_parents]
        if rig.posedirs is not None:
            self.register_buffer("posedirs", torch.as_tensor(rig.posedirs, dtype=dtype))
            self.register_buffer("native_rotation", torch.as_tensor(rig.native_rotation, dtype=dtype))
        else:
            self.posedirs = None

    @property
    def num_vertices(self) -> int:
        return int(self.rest_vertices.shape[0])

    def forward(
        self,
        pose_rad: torch.Tensor,
        rotation: torch.Tensor | None = None,
        translation: torch.Tensor | None = None,
        wrist_rad: torch.Tensor | None = None,
    ) -> HandOutput:
        """Pose the hand.

        Args:
            pose_rad: (B, 15, 3) twist, spread, bend per joint, radians (see rig.py).
            rotation: (B, 3, 3) hand frame -> world rotation; identity if None.
            translation: (B, 3) world position of the wrist, metres; zero if None.
            wrist_rad: (B, 2) wrist flexion (positive: the hand bends toward the palm) and
                deviation (positive: toward the thumb), radians; the forearm turns, the hand
                stays where rotation and translation put it. Zero if None.
        Returns:
            HandOutput with (B, V, 3) vertices (forearm included when enabled).
        """
        if pose_rad.dim() != 3 or pose_rad.shape[1:] != (N_JOINTS, 3):
            raise ValueError(f"pose must have shape (B, 15, 3), got {tuple(pose_rad.shape)}")
        rotations = kinematics.anatomical_rotations(pose_rad, self.joint_axes)
        return self.forward_rotations(rotations, rotation, translation, wrist_rad)

    def forward_rotations(
        self,
        joint_rotations: torch.Tensor,
        rotation: torch.Tensor | None = None,
        translation: torch.Tensor | None = None,
        wrist_rad: torch.Tensor | None = None,
    ) -> HandOutput:
        """Pose the hand from joint rotations (B, 15, 3, 3) in the hand's rest frame."""
        batch = joint_rotations.shape[0]
        rest = self.rest_vertices
        if self.posedirs is not None:
            rest = rest.expand(batch, -1, -1) + self._pose_correctives(joint_rotations)
        bone_r, bone_t = kinematics.forward_kinematics(
            joint_rotations, self.joint_bones, self.bone_heads, self.bone_parents
        )
        forearm_points = self.forearm_axis_points.expand(batch, -1, -1)
        if self.forearm_bone is not None:
            fr, ft = self._forearm_transform(wrist_rad, batch, joint_rotations)
            bone_r = torch.cat([bone_r, fr[:, None]], 1)
            bone_t = torch.cat([bone_t, ft[:, None]], 1)
            forearm_points = forearm_points @ fr.transpose(-1, -2) + ft[:, None]
        # The global rotation and translation go into the bones' transforms (the skin weights
        # sum to 1 per vertex), so the vertices are posed in the world frame in one pass.
        world_r, world_t = bone_r, bone_t
        if rotation is not None or translation is not None:
            eye = torch.eye(3, dtype=bone_t.dtype, device=bone_t.device).expand(batch, 3, 3)
            rotation = eye if rotation is None else rotation
            translation = bone_t.new_zeros(batch, 3) if translation is None else translation
            world_r = rotation[:, None] @ bone_r
            world_t = (bone_t @ rotation.transpose(-1, -2)) + translation[:, None]
            forearm_points = kinematics.apply_rigid(forearm_points, rotation, translation)
        features = self.skin_features if self.posedirs is None else None
        verts = kinematics.linear_blend_skinning(rest, self.skin_weights, world_r, world_t, features)
        # Keypoints: a joint's own transform leaves its centre where its parent put it.
        heads = self.bone_heads[self.joint_bones]
        jb = self.joint_bones
        joints = (world_r[:, jb] @ heads[..., None])[..., 0] + world_t[:, jb]
        tips = verts[:, self.tip_vertices]
        wrist = (
            torch.zeros_like(joints[:, :1]) if translation is None else translation[:, None].expand_as(joints[:, :1])
        )
        keypoints = torch.cat(
            [wrist, torch.cat([joints.reshape(batch, 5, 3, 3), tips[:, :, None]], 2).reshape(batch, 20, 3)],
            dim=1,
        )
        return HandOutput(verts, self.faces, keypoints, bone_r, bone_t, forearm_points)

    def forearm_points(
        self,
        rotation: torch.Tensor | None = None,
        translation: torch.Tensor | None = None,
        wrist_rad: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(B, P, 3) the forearm's axis points, wrist to elbow, as :meth:`forward` places them
        (HandOutput.forearm_points), without posing the hand's vertices: the forearm follows
        the wrist alone. Arguments as forward's; at least one of them gives the batch.
        (B, 0, 3) without a forearm."""
        given = [t for t in (rotation, translation, wrist_rad) if t is not None]
        if not given:
            raise ValueError("forearm_points needs a rotation, translation or wrist angles for its batch")
        batch = given[0].shape[0]
        points = self.forearm_axis_points.expand(batch, -1, -1)
        if self.forearm_bone is not None:
            fr, ft = self._forearm_transform(wrist_rad, batch, points)
            points = points @ fr.transpose(-1, -2) + ft[:, None]
        if rotation is not None or translation is not None:
            eye = torch.eye(3, dtype=points.dtype, device=points.device).expand(batch, 3, 3)
            rotation = eye if rotation is None else rotation
            translation = points.new_zeros(batch, 3) if translation is None else translation
            points = kinematics.apply_rigid(points, rotation, translation)
        return points

    def _forearm_transform(self, wrist_rad, batch, like) -> tuple[torch.Tensor, torch.Tensor]:
        """The forearm bone's rotation (B, 3, 3) and translation (B, 3) in the hand frame: the
        inverse of the wrist's motion, about the wrist centre. Flexion turns about the hand's x
        axis (the forearm swings toward the palm side), deviation about its z axis."""
        eye = torch.eye(3, dtype=like.dtype, device=like.device)
        if wrist_rad is None:
            return eye.expand(batch, 3, 3), like.new_zeros(batch, 3)
        flex, dev = wrist_rad[:, 0], wrist_rad[:, 1] * self.radial_sign
        zeros = torch.zeros_like(flex)
        rx = kinematics.rotvec_to_rotmat(torch.stack([flex, zeros, zeros], -1))
        rz = kinematics.rotvec_to_rotmat(torch.stack([zeros, zeros, dev], -1))
        rot = rz @ rx
        c = self.wrist_centre
        return rot, c - (rot @ c[:, None])[..., 0]

    def _pose_correctives(self, joint_rotations: torch.Tensor) -> torch.Tensor:
        """MANO pose blend shapes: posedirs applied to (R - I) in the native frame. (B, V, 3)."""
        c = self.native_rotation  # rows: hand axes in native coords; native = C^T hand C
        native = c.transpose(0, 1) @ joint_rotations @ c
        eye = torch.eye(3, dtype=native.dtype, device=native.device)
        feat = (native - eye).reshape(native.shape[0], -1)
        offsets_native = (feat @ self.posedirs.transpose(0, 1)).reshape(native.shape[0], -1, 3)
        offsets = offsets_native @ c.transpose(0, 1)
        pad = self.num_vertices - offsets.shape[1]
        if pad:
            offsets = torch.cat([offsets, offsets.new_zeros(offsets.shape[0], pad, 3)], 1)
        return offsets

    def rest_pose(self, batch: int = 1) -> torch.Tensor:
        """(B, 15, 3) zero angles, on this model's device and dtype."""
        return self.rest_vertices.new_zeros(batch, N_JOINTS, 3)
