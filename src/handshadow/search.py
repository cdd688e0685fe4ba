"""The search: many hand hypotheses optimised together, pruned as they go, the best refined.

No I/O here. A hypothesis is one or two hands (pose angles, global rotation, translation).
Joint angles are parameterised inside their limits (angle = lo + (hi - lo) sigmoid(z)), so every
hypothesis respects the limits by construction; rotations are a rotation vector applied in world
axes on top of a starting rotation; translations are metres.

Stages run coarse to fine: low resolution with a wide blur and a strong pull toward missing
target parts first, the exact shadow at full resolution last. After each stage the hypotheses
are ranked by the fit measures (IoU, thin-part recall, HD95) and only the best continue.
After the stages, :meth:`Searcher.separate` resolves what penetration is left and
:meth:`Searcher.polish` aims a few more steps at the success test.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
from collections.abc import Callable

import numpy as np
import torch

from handshadow import losses
from handshadow.hands.kinematics import rotvec_to_rotmat
from handshadow.hands.model import HandModel
from handshadow.hands.proxies import PenetrationModel, hand_spheres
from handshadow.metrics import score, thin_parts
from handshadow.render import ShadowRenderer, gaussian_blur
from handshadow.scene import Scene

log = logging.getLogger(__name__)
# Finger segments between keypoints (rig.KEYPOINT_NAMES: wrist, then per finger 3 joints + tip).
_SEG_A = [1 + 4 * f + k for f in range(5) for k in range(3)]
_SEG_B = [2 + 4 * f + k for f in range(5) for k in range(3)]


@dataclasses.dataclass(frozen=True)
class Stage:
    """One coarse-to-fine stage: resolution (pixels of the frame height), blur and attraction
    radius in full-resolution pixels, Adam steps, and how many hypotheses survive it."""

    height: int
    blur_px: float
    attract_px: float
    steps: int
    keep: int
    lr_scale: float = 1.0
    skeleton: float = 1.0  # weight factor of the skeleton terms (long-range guides)


@dataclasses.dataclass(frozen=True)
class Weights:
    l2: float = 1.0
    thin: float = 4.0  # extra weight of the target's thin parts in the image term
    depth: float = 20.0  # extra weight per frame height of depth inside the target (holes cost more)
    depth_cap: float = 0.05
    spill: float = 0.0  # the same outside the target, per frame height of distance (the polish uses it)
    notches: float = 0.0  # extra weight of the target's holes and narrow notches (the polish uses it)
    excess: float = 2.0
    attraction: float = 0.3
    penetration: float = 0.02
    placement: float = 0.05
    forearm: float = 0.05
    inside: float = 3.0  # joints and forearm axes project into the target
    thin_pull: float = 3.0  # fingers reach the target's thin parts
    anchor: float = 0.002  # closeness to anchor poses, when the search has some
    gaps: float = 4.0  # light leaking between fingers where the target is solid (fine stages)


@dataclasses.dataclass
class HandPoses:
    """Poses of one hand for B hypotheses: pose_rad (B, 15, 3), rotation (B, 3, 3),
    translation (B, 3) metres, wrist_rad (B, 2) flexion and deviation."""

    pose_rad: torch.Tensor
    rotation: torch.Tensor
    translation: torch.Tensor
    wrist_rad: torch.Tensor

    def select(self, idx) -> HandPoses:
        return HandPoses(self.pose_rad[idx], self.rotation[idx], self.translation[idx], self.wrist_rad[idx])

    def to(self, device) -> HandPoses:
        return HandPoses(*(t.to(device) for t in self.args()))

    def args(self) -> tuple[torch.Tensor, ...]:
        """HandModel.forward's arguments."""
        return self.pose_rad, self.rotation, self.translation, self.wrist_rad

    @staticmethod
    def cat(items: list[HandPoses]) -> HandPoses:
        return HandPoses(*(torch.cat(ts) for ts in zip(*(i.args() for i in items))))


@dataclasses.dataclass(frozen=True)
class Limits:
    """Joint limits of one hand, radians: joints (15, 3, 2) and wrist (2, 2) [low, high]."""

    joints: torch.Tensor
    wrist: torch.Tensor


class Hypotheses(torch.nn.Module):
    """Optimisable parameters of B hypotheses of one or two hands."""

    def __init__(self, starts: list[HandPoses], limits: list[Limits]):
        super().__init__()
        self.n_hands = len(starts)
        for i, (s, lim) in enumerate(zip(starts, limits)):
            for name, value, bounds in (("", s.pose_rad, lim.joints), ("wrist_", s.wrist_rad, lim.wrist)):
                lo, hi = bounds[..., 0], bounds[..., 1]
                self.register_buffer(f"{name}lo{i}", lo)
                self.register_buffer(f"{name}span{i}", hi - lo)
                frac = ((value - lo) / (hi - lo).clamp(min=1e-9)).clamp(0.02, 0.98)
                self.register_parameter(f"{name}logits{i}", torch.nn.Parameter(torch.log(frac / (1 - frac))))
            self.register_buffer(f"rot0_{i}", s.rotation.clone())
            self.register_parameter(f"rotvec{i}", torch.nn.Parameter(torch.zeros_like(s.translation)))
            self.register_parameter(f"trans{i}", torch.nn.Parameter(s.translation.clone()))

    @property
    def batch(self) -> int:
        return self.trans0.shape[0]

    def hand(self, i: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(pose_rad (B, 15, 3), rotation (B, 3, 3), translation (B, 3), wrist_rad (B, 2)) of hand i."""
        pose = getattr(self, f"lo{i}") + getattr(self, f"span{i}") * torch.sigmoid(getattr(self, f"logits{i}"))
        wrist = getattr(self, f"wrist_lo{i}") + getattr(self, f"wrist_span{i}") * torch.sigmoid(
            getattr(self, f"wrist_logits{i}")
        )
        rot = rotvec_to_rotmat(getattr(self, f"rotvec{i}")) @ getattr(self, f"rot0_{i}")
        return pose, rot, getattr(self, f"trans{i}"), wrist

    def poses(self) -> list[HandPoses]:
        """Current values, detached."""
        with torch.no_grad():
            return [HandPoses(*(t.detach().clone() for t in self.hand(i))) for i in range(self.n_hands)]

    def param_groups(self, lr_scale: float) -> list[dict]:
        groups = []
        for i in range(self.n_hands):
            groups += [
                {"params": [getattr(self, f"logits{i}"), getattr(self, f"wrist_logits{i}")], "lr": 0.08 * lr_scale},
                {"params": [getattr(self, f"rotvec{i}")], "lr": 0.02 * lr_scale},
                {"params": [getattr(self, f"trans{i}")], "lr": 0.003 * lr_scale},
            ]
        return groups


@dataclasses.dataclass
class Progress:
    """What a progress callback sees: stage index, step, total steps so far, the best
    hypothesis's current shadow (H, W) numpy at the stage resolution, its IoU, and its poses."""

    stage: int
    step: int
    done: int
    total: int
    shadow: np.ndarray
    iou: float
    poses: list[HandPoses]


@dataclasses.dataclass
class SearchResult:
    poses: list[HandPoses]  # each with batch 1: the best hypothesis
    steps: int
    seconds: float
    interrupted: bool
    ranking: list[dict]  # final scores of the surviving hypotheses


class Searcher:
    """Runs the stages for a target.

    Args:
        scene: the full-resolution scene (its image size is the output size).
        target: (H, W) bool target frame at the scene's resolution.
        hands: one or two HandModels (same device).
        limits: per hand its joint limits.
    """

    def __init__(
        self,
        scene: Scene,
        target: np.ndarray,
        hands: list[HandModel],
        limits: list[Limits],
        weights: Weights | None = None,
        anchor: list[HandPoses] | None = None,
    ):
        self.anchor = anchor  # optional batch-1 poses the solution should stay near
        self.scene = scene
        self.target = np.asarray(target, bool)
        self.hands = hands
        self.limits = limits
        self.weights = weights or Weights()
        self.device = hands[0].rest_vertices.device
        self.dtype = hands[0].rest_vertices.dtype
        self.penetration = PenetrationModel([hand_spheres(h.rig, h.has_forearm) for h in hands], dtype=self.dtype).to(
            self.device
        )
        self._renderers: dict[int, tuple[Scene, ShadowRenderer, losses.TargetMaps]] = {}
        self.light_position = (
            torch.as_tensor(scene.light.position, dtype=self.dtype, device=self.device)
            if scene.light.type == "point"
            else None
        )
        lo, hi = scene.light_depth_range()
        self.height_range = (0.03, min(hi - 0.25, 3.0) if math.isfinite(hi) else 3.0)

    def level(self, height: int) -> tuple[Scene, ShadowRenderer, losses.TargetMaps]:
        """Scene, renderer and target maps at a frame height (cached)."""
        if height not in self._renderers:
            full_h, full_w = self.target.shape
            width = max(1, round(full_w * height / full_h))
            scene = self.scene.with_size(width, height)
            renderer = ShadowRenderer(scene, [h.faces for h in self.hands], [h.num_vertices for h in self.hands]).to(
                self.device
            )
            small = self.target if height == full_h else _resize_mask(self.target, height, width)
            self._renderers[height] = (scene, renderer, losses.TargetMaps.build(small, self.device, self.dtype))
        return self._renderers[height]

    def objective(
        self, hyp: Hypotheses, stage: Stage, weights: Weights | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-hypothesis loss (B,) and the exact shadow (B, H, W) at the stage resolution."""
        w = weights or self.weights
        scene, renderer, maps = self.level(stage.height)
        scale = stage.height / self.target.shape[0]
        outs, globals_ = [], []
        for i, hand in enumerate(self.hands):
            pose, rot, trans, wrist = hyp.hand(i)
            outs.append(hand(pose, rot, trans, wrist))
            globals_.append((rot, trans))
        xy, height = renderer.project([o.vertices for o in outs])
        from handshadow.render.shadow import shadow_mask

        mask = shadow_mask(xy, renderer.topology, scene.image.height, scene.image.width)
        blur = stage.blur_px * scale
        soft = gaussian_blur(mask, blur)
        target_soft = gaussian_blur(maps.target[None], blur)[0]
        weight = (
            1.0
            + w.thin * gaussian_blur(maps.thin[None], max(blur, 1.0))[0]
            + w.depth * maps.inside_depth.clamp(max=w.depth_cap)
        )
        if w.spill:
            weight = weight + w.spill * maps.outside_dist.clamp(max=w.depth_cap)
        if w.notches:
            weight = weight + w.notches * gaussian_blur(maps.notches[None], blur)[0]
        total = w.l2 * losses.weighted_l2(soft, target_soft, weight)
        total = total + w.excess * losses.excess(mask, maps.outside_dist)
        if w.gaps and stage.blur_px <= 1:
            total = total + w.gaps * losses.gaps(mask, maps.target, max(1, round(2 * scale)))
        if w.attraction and stage.attract_px > 0:
            total = total + w.attraction * losses.attraction(mask, maps.target, stage.attract_px * scale)
        if stage.skeleton > 0:
            kp = torch.cat([torch.cat([o.keypoints, o.forearm_points], 1) for o in outs], 1)
            kp_xy, _ = scene.project(kp)
            total = total + stage.skeleton * w.inside * losses.points_outside(kp_xy, maps)
            segs = kp_xy.new_zeros(kp_xy.shape[0], 0, 2, 2)
            offset = 0
            for o in outs:
                k = kp_xy[:, offset : offset + 21]
                ends = torch.stack([k[:, _SEG_A], k[:, _SEG_B]], 2)
                segs = torch.cat([segs, ends], 1)
                offset += o.keypoints.shape[1] + o.forearm_points.shape[1]
            total = total + stage.skeleton * w.thin_pull * losses.thin_coverage(segs, maps)
        if self.anchor is not None:
            total = total + w.anchor * self._anchor_distance(globals_)
        centres = self.penetration.centres([(o.bone_rotations, o.bone_translations) for o in outs], globals_)
        total = total + w.penetration * losses.penetration(self.penetration.depths(centres, self.light_position))
        total = total + w.placement * losses.placement(height, *self.height_range)
        total = total + w.forearm * self._forearm_terms(outs, globals_)
        return total, mask

    def _anchor_distance(self, globals_) -> torch.Tensor:
        """Squared distance of each hand's placement from the anchor's: 5 cm of wrist travel or
        0.5 rad of turn count one."""
        from handshadow.hands.kinematics import rotmat_to_rotvec

        out = 0
        for (rot, trans), a in zip(globals_, self.anchor):
            out = out + (((trans - a.translation) / 0.05) ** 2).sum(1)
            out = out + (rotmat_to_rotvec(a.rotation.transpose(-1, -2) @ rot).norm(dim=1) / 0.5) ** 2
        return out

    def _forearm_terms(self, outs, globals_) -> torch.Tensor:
        """Two wrists stay within reach of each other (at most 45 cm apart). Forearms may point
        any way, into the wall included (a forearm along the light's ray hides behind its hand;
        the performer then stands beside the beam)."""
        if len(globals_) < 2:
            return torch.zeros((), dtype=self.dtype, device=self.device)
        gap = (globals_[0][1] - globals_[1][1]).norm(dim=1)
        return losses.soft_range(gap, 0.0, 0.45, 0.05)

    def run(
        self,
        starts: list[HandPoses],
        stages: list[Stage],
        progress: Callable[[Progress], None] | None = None,
        every: int = 10,
        deadline_s: float | None = None,
        stop: Callable[[], bool] | None = None,
    ) -> SearchResult:
        """Optimise the starting hypotheses through the stages; Ctrl-C (KeyboardInterrupt),
        ``stop`` returning True (checked every step) or the deadline stops early and keeps the
        best so far."""
        t0 = time.perf_counter()
        total_steps = sum(s.steps for s in stages)
        done, interrupted = 0, False
        hyp = Hypotheses(starts, self.limits).to(self.device)
        best_idx = torch.zeros(1, dtype=torch.long)
        try:
            for si, stage in enumerate(stages):
                opt = torch.optim.Adam(hyp.param_groups(stage.lr_scale))
                sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(1, stage.steps), eta_min=0.0)
                for step in range(stage.steps):
                    opt.zero_grad(set_to_none=True)
                    loss, mask = self.objective(hyp, stage)
                    loss.sum().backward()
                    opt.step()
                    sched.step()
                    done += 1
                    if progress and (step % every == 0 or step == stage.steps - 1):
                        best = int(torch.argmin(loss.detach()))
                        m = mask[best].detach().cpu().numpy()
                        progress(
                            Progress(
                                si,
                                step,
                                done,
                                total_steps,
                                m,
                                _iou_small(m, self.level(stage.height)[2]),
                                [p.select(slice(best, best + 1)) for p in hyp.poses()],
                            )
                        )
                    if deadline_s is not None and time.perf_counter() - t0 > deadline_s:
                        raise TimeoutError
                    if stop is not None and stop():
                        raise KeyboardInterrupt
                keep = min(stage.keep, hyp.batch)
                best_idx = self.rank(hyp, stage)[:keep]
                hyp = Hypotheses([p.select(best_idx) for p in hyp.poses()], self.limits).to(self.device)
        except KeyboardInterrupt:
            interrupted = True
        except TimeoutError:
            log.info("search stopped at its time limit")
        final = self.rank_details(hyp)
        best = final[0]["index"]
        poses = [p.select(slice(best, best + 1)) for p in hyp.poses()]
        return SearchResult(poses, done, time.perf_counter() - t0, interrupted, final)

    @torch.no_grad()
    def penetration_mm(self, poses: list[HandPoses]) -> torch.Tensor:
        """(B,) deepest overlap of any two collision proxies (within or across hands), mm."""
        outs = [hand(*p.args()) for hand, p in zip(self.hands, poses)]
        globals_ = [(p.rotation, p.translation) for p in poses]
        centres = self.penetration.centres([(o.bone_rotations, o.bone_translations) for o in outs], globals_)
        return self.penetration.depths(centres).amax(1) * 1000

    def separate(
        self,
        poses: list[HandPoses],
        tol_mm: float = 1.0,
        max_steps: int = 150,
        stop: Callable[[], bool] | None = None,
    ) -> list[HandPoses]:
        """Resolve what penetration the search left (its penalty is soft so that hands may pass
        through each other on the way): a few small steps of the full-resolution objective
        with a penetration weight 100 times higher, until no proxies overlap by more than tol_mm.
        Batch-1 poses in and out; Ctrl-C, or ``stop`` returning True, raises
        :class:`Interrupted` with the poses reached."""
        hyp = None
        try:
            if float(self.penetration_mm(poses).max()) <= tol_mm:
                return poses
            stage = self._finishing_stage(max_steps)
            weights = dataclasses.replace(self.weights, penetration=self.weights.penetration * 100)
            hyp = Hypotheses(poses, self.limits).to(self.device)
            opt = torch.optim.Adam(hyp.param_groups(stage.lr_scale))
            for _ in range(max_steps):
                if stop is not None and stop():
                    raise KeyboardInterrupt
                opt.zero_grad(set_to_none=True)
                loss, _ = self.objective(hyp, stage, weights)
                loss.sum().backward()
                opt.step()
                if float(self.penetration_mm(hyp.poses()).max()) <= tol_mm:
                    break
        except KeyboardInterrupt:  # Ctrl-C keeps the result as it stands
            raise Interrupted(hyp.poses() if hyp is not None else poses) from None
        log.info("separated the hands: deepest overlap %.1f mm", float(self.penetration_mm(hyp.poses()).max()))
        return hyp.poses()

    def polish(
        self,
        poses: list[HandPoses],
        rounds: int = 2,
        near_rounds: int = 0,
        steps: int = 60,
        copies: int = 4,
        check_every: int = 4,
        tol_mm: float = 1.0,
        always: bool = False,
        stop: Callable[[], bool] | None = None,
    ) -> list[HandPoses]:
        """Aim the last steps at what the success test sees: a few copies of the result (the
        first as it is, the others slightly jittered) take small steps of an objective that
        stresses light leaking between fingers, shadow filling the target's holes and notches,
        and far spills; the best-scoring pose met on the way wins, and only if it scores better
        than the start and overlaps no more. Rounds repeat from the best while the success test
        is not passed: ``rounds`` of them, then up to ``near_rounds`` more while the result is a
        near miss (:attr:`FitScore.near_miss`) and the last round improved it. A start that
        already passes is returned as it is unless ``always``. Batch-1 poses in and out; Ctrl-C,
        or ``stop`` returning True (checked every step), raises :class:`Interrupted` with the
        best met so far."""
        w = self.weights
        weights = dataclasses.replace(w, gaps=w.gaps * 10, notches=4.0, spill=20.0, penetration=w.penetration * 100)
        best = poses
        try:
            best_score = score(self.shadows(poses)[0].cpu().numpy() > 0.5, self.target, self._target_thin)
            allowed = max(tol_mm, float(self.penetration_mm(poses).max()))
            improved = False
            gen = torch.Generator(device="cpu").manual_seed(0)
            for i in range(rounds + near_rounds):
                if best_score.success and not always:
                    break
                if i >= rounds and not (best_score.near_miss and improved):
                    break
                previous = best_score
                best_score, best = self._polish_round(
                    best, best_score, weights, steps, copies, check_every, allowed, gen, stop
                )
                improved = rank_key(best_score) < rank_key(previous)
        except KeyboardInterrupt:  # between steps, or while scoring the start
            raise Interrupted(best) from None
        return best

    def _polish_round(self, poses, best_score, weights, steps, copies, check_every, allowed_mm, gen, stop=None):
        stage = self._finishing_stage(steps)
        hyp = Hypotheses([p.select([0] * copies) for p in poses], self.limits).to(self.device)
        groups = hyp.param_groups(stage.lr_scale)
        with torch.no_grad():  # jitter every copy but the first: joint logits, rotation, translation (m)
            for group, sigma in zip(groups, [0.15, 0.01, 0.002] * hyp.n_hands):
                for p in group["params"]:
                    noise = torch.randn(p.shape, generator=gen).to(p) * sigma
                    noise[0] = 0
                    p.add_(noise)
        opt = torch.optim.Adam(groups)
        best, best_key = poses, rank_key(best_score)
        try:
            for step in range(steps + 1):
                opt.zero_grad(set_to_none=True)
                loss, mask = self.objective(hyp, stage, weights)
                if step % check_every == 0 or step == steps:
                    current = hyp.poses()
                    depth = self.penetration_mm(current)
                    for i, m in enumerate(mask.detach().cpu().numpy() > 0.5):
                        s = score(m, self.target, self._target_thin)
                        key = rank_key(s)
                        if key < best_key and float(depth[i]) <= allowed_mm:
                            best_score, best_key, best = s, key, [p.select(slice(i, i + 1)) for p in current]
                if step == steps:
                    break
                if stop is not None and stop():
                    raise KeyboardInterrupt
                loss.sum().backward()
                opt.step()
        except KeyboardInterrupt:
            raise Interrupted(best) from None
        return best_score, best

    def _finishing_stage(self, steps: int) -> Stage:
        """Small exact-shadow steps at full resolution, without the skeleton guides."""
        return Stage(self.target.shape[0], 0, 0, steps, 1, 0.15, 0.0)

    @functools.cached_property
    def _target_thin(self) -> np.ndarray:
        return thin_parts(self.target)

    @torch.no_grad()
    def shadows(self, poses: list[HandPoses], height: int | None = None) -> torch.Tensor:
        """(B, H, W) exact shadows of hypotheses at a resolution (full by default)."""
        scene, renderer, _ = self.level(height or self.target.shape[0])
        verts = [hand(*p.args()).vertices for hand, p in zip(self.hands, poses)]
        from handshadow.render.shadow import shadow_mask

        xy, _ = renderer.project(verts)
        return shadow_mask(xy, renderer.topology, scene.image.height, scene.image.width)

    def rank(self, hyp: Hypotheses, stage: Stage) -> torch.Tensor:
        """Indices of hypotheses, best first, by the fit measures at the stage resolution."""
        _, _, maps = self.level(stage.height)
        masks = self.shadows(hyp.poses(), stage.height).cpu().numpy() > 0.5
        target = maps.target.cpu().numpy() > 0.5
        keys = [rank_key(score(m, target)) for m in masks]
        order = sorted(range(len(keys)), key=keys.__getitem__)
        return torch.as_tensor(order, dtype=torch.long, device=self.device)

    def rank_details(self, hyp: Hypotheses) -> list[dict]:
        masks = self.shadows(hyp.poses()).cpu().numpy() > 0.5
        rows = []
        for i, m in enumerate(masks):
            s = score(m, self.target)
            rows.append({"index": i, **s.as_dict(), "key": rank_key(s)})
        return sorted(rows, key=lambda r: r["key"])


class Interrupted(Exception):
    """Ctrl-C during a finishing step (separation, polish), carrying the batch-1 poses to keep."""

    def __init__(self, poses: list[HandPoses]):
        super().__init__("interrupted")
        self.poses = poses


def rank_key(s) -> tuple:
    """Sort key, smaller is better: successes first, then a blend of the measures."""
    return (not s.success, -(s.iou + 0.5 * s.thin_recall - 4.0 * s.hd95))


def _iou_small(mask: np.ndarray, maps: losses.TargetMaps) -> float:
    t = maps.target.cpu().numpy() > 0.5
    m = mask > 0.5
    union = (m | t).sum()
    return float((m & t).sum() / union) if union else 1.0


def _resize_mask(mask: np.ndarray, height: int, width: int) -> np.ndarray:
    from skimage.transform import resize

    return resize(mask.astype(float), (height, width), order=1, anti_aliasing=True) >= 0.5
