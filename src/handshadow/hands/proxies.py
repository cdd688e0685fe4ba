"""Collision proxies: spheres that ride on the bones, for the penetration penalty on the CPU.

Each finger segment carries a few spheres along its axis, the palm a grid of spheres, and the
forearm a row along its axis. Radii come from the mesh (the median distance of the segment's
vertices from its axis), shrunk a little so that touching is not penetrating. Sphere centres
move rigidly with their bone, so posing them costs one small matrix product.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from handshadow.hands.forearm import FOREARM_LENGTH_M, forearm_axis, forearm_scale
from handshadow.hands.rig import N_JOINTS, HandRig

SHRINK = 0.85  # radius factor: contact is allowed, overlap beyond it is penetration
RADIUS_PERCENTILE = 50  # a finger sphere's radius: this percentile of its vertices' distances from the bone
PALM, FOREARM = 5, 6  # part ids after the fingers 0..4 (thumb..little)
# The broad phase passes pairs this much beyond their reach to the exact distance (torch.cdist
# may compute distances through a matrix product, off by far less than this).
BROAD_PHASE_M = 1e-3


@dataclasses.dataclass(frozen=True)
class SphereSet:
    """Spheres of one hand, hand frame: centres (S, 3) m, radii (S,) m, bone (S,) index of the
    bone they ride on, part (S,) finger 0..4 / palm 5 / forearm 6, segment (S,) joint 0..2 for
    fingers (-1 otherwise)."""

    centres: np.ndarray
    radii: np.ndarray
    bone: np.ndarray
    part: np.ndarray
    segment: np.ndarray


SIDEWAYS = 0.25  # share of the sideways gradient kept between the two hands (see depths)


def hand_spheres(rig: HandRig, forearm: bool = True, per_segment: int = 3) -> SphereSet:
    """Build the proxies of a rig (rest pose, hand frame)."""
    verts, weights = rig.rest_vertices, rig.skin_weights
    owner = weights.argmax(1)
    heads = rig.joint_heads
    centres, radii, bones, parts, segments = [], [], [], [], []
    for j in range(N_JOINTS):
        finger, seg = divmod(j, 3)
        start = heads[j]
        end = heads[j + 1] if seg < 2 else verts[rig.tip_vertices[finger]]
        axis = end - start
        length = np.linalg.norm(axis)
        own = verts[owner == rig.joint_bones[j]]
        if len(own) == 0:
            continue
        t = np.clip((own - start) @ axis / length**2, 0, 1)
        radius = np.percentile(np.linalg.norm(own - (start + t[:, None] * axis), axis=1), RADIUS_PERCENTILE) * SHRINK
        for k in range(per_segment):
            s = (k + 0.5) / per_segment
            if seg == 2:
                s = min(s, 1 - radius / length)  # keep the tip sphere inside the fingertip
            centres.append(start + s * axis)
            radii.append(radius)
            bones.append(rig.joint_bones[j])
            parts.append(finger)
            segments.append(seg)
    # Palm: a grid between the wrist and the knuckles, as thick as the palm is.
    wrist = np.zeros(3)
    knuckles = heads[[3, 6, 9, 12]]
    palm_owned = verts[np.isin(owner, _palm_bones(rig))]
    thickness = np.percentile(np.abs(palm_owned[:, 2] - np.median(palm_owned[:, 2])), 75) if len(palm_owned) else 0.012
    for knuckle in knuckles:
        for s in (0.3, 0.6, 0.85):
            centres.append(
                wrist + s * (knuckle - wrist) + np.array([0, 0, np.median(palm_owned[:, 2]) if len(palm_owned) else 0])
            )
            radii.append(max(thickness, 0.008) * SHRINK)
            bones.append(0)
            parts.append(PALM)
            segments.append(-1)
    if forearm and len(rig.wrist_loop):
        centre, axis = forearm_axis(rig)
        ring = verts[rig.wrist_loop]
        radius0 = np.min(np.linalg.norm(np.cross(ring - centre, axis), axis=1))  # the flat side
        for s in np.linspace(0.04, FOREARM_LENGTH_M - 0.02, 8) * rig.size:
            centres.append(centre + s * axis)
            radii.append(radius0 * forearm_scale(s, rig.size) * SHRINK)
            bones.append(len(rig.bone_parents))  # the forearm bone, after the rig's bones
            parts.append(FOREARM)
            segments.append(-1)
    return SphereSet(np.asarray(centres), np.asarray(radii), np.asarray(bones), np.asarray(parts), np.asarray(segments))


def _palm_bones(rig: HandRig) -> np.ndarray:
    """Bones that are neither articulated nor children of articulated bones: wrist, metacarpals."""
    articulated = set(int(b) for b in rig.joint_bones)
    return np.array([k for k in range(len(rig.bone_parents)) if k not in articulated])


def excluded_self_pairs(spheres: SphereSet) -> np.ndarray:
    """(S, S) bool: pairs of one hand never tested (same finger; a finger's base segment
    against the palm; the palm against the forearm; the thumb's base against the palm)."""
    p, s = spheres.part, spheres.segment
    same_finger = (p[:, None] == p[None, :]) & (p[:, None] < PALM)
    base_palm = ((p[:, None] == PALM) & (s[None, :] == 0)) | ((p[None, :] == PALM) & (s[:, None] == 0))
    thumb_palm = ((p[:, None] == PALM) & (p[None, :] == 0) & (s[None, :] <= 1)) | (
        (p[None, :] == PALM) & (p[:, None] == 0) & (s[:, None] <= 1)
    )
    palm_forearm = ((p[:, None] == PALM) & (p[None, :] == FOREARM)) | ((p[None, :] == PALM) & (p[:, None] == FOREARM))
    same_rigid = (p[:, None] == p[None, :]) & (p[:, None] >= PALM)
    return same_finger | base_palm | thumb_palm | palm_forearm | same_rigid | np.eye(len(p), dtype=bool)


class PenetrationModel(torch.nn.Module):
    """Self- and cross-penetration of one or two posed hands, from their sphere proxies.

    Penetration of a pair = max(0, r_i + r_j - |c_i - c_j| - allowance_ij), where the allowance
    is the overlap a pair of one hand already has in the rest pose (neighbouring fingers touch),
    and 0 between the hands.
    """

    def __init__(self, sphere_sets: list[SphereSet], dtype=torch.float32):
        super().__init__()
        self.counts = [len(s.radii) for s in sphere_sets]
        for i, s in enumerate(sphere_sets):
            self.register_buffer(f"centres{i}", torch.as_tensor(s.centres, dtype=dtype))
            self.register_buffer(f"bone{i}", torch.as_tensor(s.bone, dtype=torch.long))
        radii = np.concatenate([s.radii for s in sphere_sets])
        owner = np.concatenate([np.full(len(s.radii), i) for i, s in enumerate(sphere_sets)])
        test = np.zeros((len(radii), len(radii)), bool)
        allowance = np.zeros_like(test, dtype=np.float64)
        start = 0
        for s in sphere_sets:
            n = len(s.radii)
            block = slice(start, start + n)
            test[block, block] = ~excluded_self_pairs(s)
            gap = s.radii[:, None] + s.radii[None, :] - np.linalg.norm(s.centres[:, None] - s.centres[None, :], axis=-1)
            allowance[block, block] = np.maximum(gap, 0.0)
            start += n
        across = owner[:, None] != owner[None, :]
        self.register_buffer("across", torch.as_tensor(across, dtype=torch.bool))
        test |= across  # every pair across the hands
        test &= np.triu(np.ones_like(test), 1).astype(bool)
        # Dense (S, S) form: tested pairs reach r_i + r_j - allowance, the others never touch.
        reach = np.where(test, radii[:, None] + radii[None, :] - allowance, -1.0)
        self.register_buffer("reach", torch.as_tensor(reach, dtype=dtype))
        self.n_pairs = int(test.sum())

    def centres(
        self,
        bone_transforms: list[tuple[torch.Tensor, torch.Tensor]],
        globals_: list[tuple[torch.Tensor, torch.Tensor]],
    ) -> torch.Tensor:
        """(B, S, 3) world sphere centres from each hand's bone transforms (R (B, K, 3, 3),
        t (B, K, 3)) and global transform (rotation (B, 3, 3), translation (B, 3))."""
        out = []
        for i, ((rb, tb), (rg, tg)) in enumerate(zip(bone_transforms, globals_)):
            c, bone = getattr(self, f"centres{i}"), getattr(self, f"bone{i}")
            local = (rb.index_select(1, bone) * c[:, None, :]).sum(-1) + tb.index_select(1, bone)
            out.append(local @ rg.transpose(-1, -2) + tg[:, None])
        return torch.cat(out, 1)

    def depths(self, centres: torch.Tensor, light: torch.Tensor | None = None) -> torch.Tensor:
        """(B, S * S) penetration depth of every pair of spheres, metres (0 when apart or when
        the pair is not tested).

        With ``light`` (a point light's position (3,)), the two hands are pushed apart only
        along the light's rays: moving a hand along a ray leaves its shadow where it is, so
        resolving a crossing of the hands does not shift the shadow (one hand passes in front
        of the other). A quarter of the sideways gradient stays, for parts that lie along a ray
        (a forearm pointing at the wall cannot leave another by sliding along it).
        Self-penetration keeps its full gradient (fingers must bend apart)."""
        if light is None or not bool(self.across.any()):
            d = torch.cdist(centres, centres)
            return torch.relu(self.reach - d).flatten(1)
        b, i, j, depth = self.touching(centres, light)
        n = centres.shape[1]
        out = centres.new_zeros(centres.shape[0], n * n)
        return out.index_put((b, i * n + j), depth)

    def touching(
        self, centres: torch.Tensor, light: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """The tested pairs that touch in some hypothesis, or nearly (the broad phase):
        (hypothesis, sphere, sphere) indices (K,) each and their penetration depths (K,),
        metres, with the gradient (the pairs left out are exactly 0, with none). ``light``:
        as in :meth:`depths`. centres (B, S, 3)."""
        # Only the pairs that touch in some hypothesis are worked out with their gradient (a
        # few hundred of B x S x S).
        b, i, j = self._touching(centres)
        ci, cj = centres[b, i], centres[b, j]  # (K, 3)
        diff = ci - cj
        if light is not None and bool(self.across.any()):
            with torch.no_grad():
                ray = 0.5 * (ci + cj) - light
                ray = ray / ray.norm(dim=-1, keepdim=True).clamp(min=1e-9)
            along = (diff * ray).sum(-1, keepdim=True) * ray
            side = diff - along
            diff = torch.where(
                self.across[i, j][:, None], along + SIDEWAYS * side + (1 - SIDEWAYS) * side.detach(), diff
            )
        d = (diff * diff).sum(-1).clamp(min=1e-18).sqrt()
        return b, i, j, torch.relu(self.reach[i, j] - d)

    @torch.no_grad()
    def _touching(self, centres: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(hypothesis, sphere, sphere) indices (K,) each of the tested pairs within reach, or
        within BROAD_PHASE_M of it (the exact distance then decides). The light's split of a
        difference into along and sideways parts keeps its length, so the plain distance is
        the one to test."""
        near = torch.cdist(centres, centres) < self.reach + BROAD_PHASE_M
        return near.nonzero(as_tuple=True)
