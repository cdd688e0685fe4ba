"""Pose paths between two fitted solutions: a performance that morphs shadow A into shadow B.

The straight path blends joint and wrist angles linearly, turns each hand's global rotation
along the geodesic on SO(3) and moves the wrists in straight lines. It is then refined as a
whole: every in-between frame keeps its joints within limits (by construction, as in the fit),
avoids penetration, stays between light and wall, follows a signed-distance morph of A into B
as a soft target, and changes as evenly as possible from frame to frame (first and second
differences); a hinge keeps every step under the step limit. The end frames stay the fits.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import torch
from scipy import ndimage

from handshadow import losses
from handshadow.hands.kinematics import rotation_angle_deg, rotmat_to_rotvec, slerp_rotations
from handshadow.hands.penetration import TOLERANCE_MM, Contacts, contact_penalty
from handshadow.metrics import iou, score
from handshadow.poses import HandPoseBatch, PoseBatch, PoseParameters
from handshadow.render import gaussian_blur
from handshadow.search import Interrupted, Problem
from handshadow.search.loop import optimise
from handshadow.search.problem import resize_coverage

STEP_LIMIT_DEG = 8.0  # the hinge starts here, under the 10-degree bar
CONTACT_ROUNDS = 6  # at most this many rounds of pushing the exact test's contacts out
CONTACT_STEPS = 25
TRAVEL_PER_RADIAN_M = 0.02  # in the smoothness terms, this much wrist travel weighs like a radian
PATH_LR_SCALE = 0.3  # the refinement's learning rates, as a share of the search's
MORPH_BLUR_PX = 2.0  # full-resolution pixels of blur on the morph's shadows and targets


def straight_path(a: PoseBatch, b: PoseBatch, frames: int) -> PoseBatch:
    """Blend per hand from a (batch 1) to b (batch 1) over ``frames`` frames (batch = frames)."""
    t = torch.linspace(0, 1, frames, dtype=a.hands[0].pose_rad.dtype, device=a.hands[0].pose_rad.device)
    out = []
    for ha, hb in zip(a.hands, b.hands):
        lerp = lambda x, y: x + (y - x) * t.view(-1, *([1] * (x.dim() - 1)))  # noqa: E731
        out.append(
            HandPoseBatch(
                lerp(ha.pose_rad, hb.pose_rad),
                slerp_rotations(ha.rotation[0], hb.rotation[0], t),
                lerp(ha.translation, hb.translation),
                lerp(ha.wrist_rad, hb.wrist_rad),
            )
        )
    return PoseBatch(out)


def morph_targets(a: np.ndarray, b: np.ndarray, frames: int) -> np.ndarray:
    """(frames, H, W) bool: a signed-distance blend of the two targets."""

    def sdf(m):
        return ndimage.distance_transform_edt(~m) - ndimage.distance_transform_edt(m)

    da, db = sdf(np.asarray(a, bool)), sdf(np.asarray(b, bool))
    t = np.linspace(0, 1, frames)[:, None, None]
    return (1 - t) * da + t * db < 0


@dataclasses.dataclass(frozen=True)
class PathWeights:
    smooth: float = 30.0
    accel: float = 60.0
    step_hinge: float = 200.0
    penetration: float = 2.0
    placement: float = 0.05
    morph: float = 0.3
    contact: float = 0.5  # mesh vertices inside other flesh (the exact test's contacts), per cm^2


def step_sizes_deg(path: PoseBatch) -> torch.Tensor:
    """(frames - 1,) the largest change between consecutive frames of any joint angle, wrist
    angle or global rotation (geodesic), degrees."""
    steps = []
    for h in path.hands:
        steps.append(torch.rad2deg((h.pose_rad[1:] - h.pose_rad[:-1]).abs().flatten(1).amax(1)))
        steps.append(torch.rad2deg((h.wrist_rad[1:] - h.wrist_rad[:-1]).abs().amax(1)))
        steps.append(rotation_angle_deg(h.rotation[:-1], h.rotation[1:]))
    return torch.stack(steps, 1).amax(1)


def path_smoothness(hands: list[HandPoseBatch]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Smoothness terms of a path, each a scalar: the sum of squared first differences (joint,
    wrist and rotation-vector steps in radians, wrist travel in units of TRAVEL_PER_RADIAN_M),
    of squared second differences (the same but rotations), and the squared overshoot of every
    step beyond STEP_LIMIT_DEG. hands: per hand slot its poses along the F frames."""
    smooth = accel = hinge = 0
    for pose, rot, trans, wrist in (h.args() for h in hands):
        d_pose = pose[1:] - pose[:-1]
        d_wrist = wrist[1:] - wrist[:-1]
        d_rot = rotmat_to_rotvec(rot[:-1].transpose(-1, -2) @ rot[1:])
        d_trans = (trans[1:] - trans[:-1]) / TRAVEL_PER_RADIAN_M
        smooth = smooth + sum((d**2).flatten(1).sum(1).sum() for d in (d_pose, d_wrist, d_rot, d_trans))
        accel = accel + sum(((d[1:] - d[:-1]) ** 2).flatten(1).sum(1).sum() for d in (d_pose, d_wrist, d_trans))
        biggest = torch.cat([d_pose.abs().flatten(1), d_wrist.abs(), d_rot.norm(dim=1, keepdim=True)], 1)
        hinge = hinge + (torch.relu(biggest - np.radians(STEP_LIMIT_DEG)) ** 2).sum()
    return smooth, accel, hinge


def refine_path(
    problem: Problem,
    path: PoseBatch,
    morph: np.ndarray,
    steps: int = 200,
    weights: PathWeights = PathWeights(),
    height: int = 96,
    time_limit_s: float | None = None,
) -> tuple[PoseBatch, bool]:
    """Optimise the in-between frames of a path (the first and last stay fixed): smoothness
    over the whole path, and per frame penetration, placement and the morph target
    ``morph`` (F, H, W) bool as a soft silhouette target. Then, while the exact mesh test
    finds frames whose hands pass through each other (hands.penetration), rounds of
    CONTACT_STEPS more steps push those contacts out too. ``time_limit_s`` (None or 0: no
    limit) ends the first part after about that many seconds; the contacts' rounds still
    follow, as a fit's separation follows its time limit. Returns the path and whether the
    limit ended its refinement. Ctrl-C raises :class:`Interrupted` with the path as refined
    so far."""
    if path.batch <= 2:
        return path, False
    current = path
    deadline = time.perf_counter() + time_limit_s if time_limit_s else None
    try:
        level = problem.level(height)
        targets = torch.as_tensor(
            np.stack([resize_coverage(m, *level.maps.target.shape) for m in morph]),
            dtype=problem.dtype,
            device=problem.device,
        )
        current, taken = _refine(problem, current, level, targets, steps, weights, deadline=deadline)
        for _ in range(CONTACT_ROUNDS):
            found = problem.mesh_penetration(current)[1:-1]  # the end frames are the fits, apart
            deep = [f.contacts for f in found if f.deepest_mm > TOLERANCE_MM]
            if not deep:
                break
            current, _ = _refine(problem, current, level, targets, CONTACT_STEPS, weights, Contacts.cat(deep))
    except KeyboardInterrupt:  # between the rounds: the path as refined so far
        raise Interrupted(current) from None
    return current, taken < steps


def _refine(
    problem, path, level, targets, steps, weights, contacts: Contacts | None = None, deadline: float | None = None
) -> tuple[PoseBatch, int]:
    """Steps of the path objective (plus the contacts' push, when given), ending early once
    time.perf_counter() passes ``deadline``; returns the path and the steps taken. Ctrl-C
    raises Interrupted with the path reached."""
    params = PoseParameters(path, problem.limits)
    free = torch.ones(path.batch, dtype=problem.dtype, device=problem.device)  # the end frames stay the fits
    free[0] = free[-1] = 0
    blur = MORPH_BLUR_PX * level.scale

    def evaluate():
        hands = params.hands()
        outs = problem.pose(hands)
        shadow = level.renderer.render([o.vertices for o in outs])
        sil = ((gaussian_blur(shadow.mask, blur) - gaussian_blur(targets, blur)) ** 2).mean((1, 2))
        pen = problem.proxy_penetration(hands, outs)
        place = losses.placement(shadow.heights, *problem.placement_range)
        smooth, accel, hinge = path_smoothness(hands)
        per_frame = weights.penetration * pen + weights.placement * place + weights.morph * sil
        if contacts is not None:
            per_frame = per_frame + weights.contact * contact_penalty([o.vertices for o in outs], contacts)
        loss = weights.smooth * smooth + weights.accel * accel + weights.step_hinge * hinge + (per_frame * free).sum()
        return loss, None

    past = None if deadline is None else (lambda step, seen: time.perf_counter() > deadline)
    try:
        taken = optimise(params, evaluate, steps, problem.rates.scaled(PATH_LR_SCALE), after=past, grad_mask=free)
    except KeyboardInterrupt:
        raise Interrupted(params.poses()) from None
    return params.poses(), taken


@dataclasses.dataclass
class PathReport:
    iou_start: float
    iou_end: float
    thin_start: float
    thin_end: float
    hd95_start: float
    hd95_end: float
    max_step_deg: float
    penetrating_frames: int
    iou_a: list[float]
    iou_b: list[float]
    steps_deg: list[float]
    penetration_mm: list[float]
    interrupted: bool = False  # Ctrl-C during the path refinement: the path as refined so far
    # the time limit ended the fit of the start, of the end, the path's refinement
    time_limited: tuple[bool, bool, bool] = (False, False, False)

    def summary(self) -> str:
        ended = ",".join(end for end, t in zip(("start", "end", "path"), self.time_limited) if t)
        return (
            f"SUMMARY iou_start={self.iou_start:.3f} iou_end={self.iou_end:.3f} thin_start={self.thin_start:.3f} "
            f"thin_end={self.thin_end:.3f} hd95_start={self.hd95_start:.4f} hd95_end={self.hd95_end:.4f} "
            f"max_step_deg={self.max_step_deg:.2f} penetrating_frames={self.penetrating_frames}"
            + (f" time_limited={ended}" if ended else "")
        )


@torch.no_grad()
def report(
    problem: Problem, path: PoseBatch, target_a: np.ndarray, target_b: np.ndarray, interrupted: bool = False
) -> tuple[PathReport, np.ndarray]:
    """Measures of a path, and its exact shadows (frames, H, W) bool at full resolution;
    interrupted: the path is as refined so far (Ctrl-C)."""
    shadows = problem.shadows(path).cpu().numpy() > 0.5
    a, b = np.asarray(target_a, bool), np.asarray(target_b, bool)
    start, end = score(shadows[0], a), score(shadows[-1], b)
    depth = np.array([p.deepest_mm for p in problem.mesh_penetration(path)])
    steps = step_sizes_deg(path).cpu().numpy()
    rep = PathReport(
        start.iou,
        end.iou,
        start.thin_recall,
        end.thin_recall,
        start.hd95,
        end.hd95,
        float(steps.max()) if len(steps) else 0.0,
        int((depth > TOLERANCE_MM).sum()),
        iou(shadows, a).tolist(),
        iou(shadows, b).tolist(),
        steps.tolist(),
        depth.tolist(),
        interrupted,
    )
    return rep, shadows
