"""Hops: a close result's way out of its basin, after the finishing steps.

A result within reach of the success test (metrics.FitScore.within: IoU met, thin parts at
most config.Hops.reach_thin short and HD95 at most config.Hops.reach_hd95 past their bars)
has the shape but not the outline, and the polish's small steps stay in its basin. A hop
jitters copies of it harder than the polish does (config.Hops), sends them through the
search's last stages again (stages.run_stages, config.Hops.stages of them: with the default
quality the two at full resolution) and finishes the best as the fit does (``finish``:
separation, polish). A few of the copies
jitter only the fingers whose shadow lies where the outline fails the HD95 bar
(metrics.far_outline: a part missing or added, a hole filled, light leaking through),
harder, and leave the rest of the pose as it is (``focused_joints``). The last hop
(config.Hops.far_hops) weighs the wrong regions past the HD95 bar more in its stages
(objective.FarOutline, as the polish does): when the plain hops could not leave the basin, it
aims at what fails the bar. The result is kept only when it ranks better and is no less
performable; hops end at the first success.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
from collections.abc import Callable

import numpy as np
import torch
from scipy import ndimage

from handshadow.hands.penetration import TOLERANCE_MM
from handshadow.metrics import far_outline
from handshadow.poses import PoseBatch, PoseParameters
from handshadow.search.config import Hops, Stage
from handshadow.search.finishing import Interrupted, jitter
from handshadow.search.objective import SEGMENT_ENDS, SEGMENT_STARTS
from handshadow.search.problem import Problem
from handshadow.search.stages import Progress, run_stages

log = logging.getLogger(__name__)


def hop(
    problem: Problem,
    poses: PoseBatch,
    stages: list[Stage],
    finish: Callable[[PoseBatch], PoseBatch],
    rounds: int,
    settings: Hops = Hops(),
    generator: torch.Generator | None = None,
    stop: Callable[[], bool] | None = None,
    progress: Callable[[Progress], None] | None = None,
) -> PoseBatch:
    """Up to ``rounds`` hops from a finished batch-1 pose while it is within
    ``settings.reach_hd95`` and ``settings.reach_thin`` of the success test: each hop runs
    ``settings.copies`` copies of the best so far (all but the first jittered by ``settings.jitter``: joint logits, rotation
    vector in radians, translation in metres; the last ``settings.focused`` of them only in
    the fingers near the failing outline, by ``settings.focus_jitter``) through ``stages``,
    then ``finish`` on the stages' best. A hop's result replaces the best only when its score
    ranks better (metrics.ViewScores.key), it goes no deeper into other flesh than the best
    (or the exact test's tolerance) and its arms can be held when the best's could. A pose out
    of reach (or a success) comes back as it is. ``progress`` sees the hops' stages
    (search.Progress with hop and hops set). Ctrl-C or ``stop`` raises finishing.Interrupted
    with the best so far."""
    best = poses
    if rounds < 1 or not stages:
        return poses
    generator = generator or torch.Generator(device="cpu").manual_seed(0)
    try:
        score = problem.scores(poses)[0]
        if not score.within(settings.reach_hd95, settings.reach_thin):
            return poses
        depth = problem.mesh_penetration(poses)[0].deepest_mm
        holdable = problem.holdable(poses)[0]
        for i in range(rounds):
            if not score.within(settings.reach_hd95, settings.reach_thin):
                break
            log.info("within reach (%s): hop %d of %d", score, i + 1, rounds)
            tell = None if progress is None else functools.partial(_told, progress, i + 1, rounds)
            found = run_stages(
                problem,
                _copies(problem, best, settings, generator),
                hop_stages(stages, settings, i, rounds),
                tell,
                stop=stop,
            )
            if found.interrupted:
                raise Interrupted(best)
            out = finish(found.poses)
            out_score = problem.scores(out)[0]
            out_depth = problem.mesh_penetration(out)[0].deepest_mm
            out_holdable = problem.holdable(out)[0]
            if (
                out_score.key() < score.key()
                and out_depth <= max(depth, TOLERANCE_MM)
                and (out_holdable or not holdable)
            ):
                best, score, depth, holdable = out, out_score, out_depth, out_holdable
    except (KeyboardInterrupt, Interrupted):  # a half-finished hop may still overlap: the best so far is kept
        raise Interrupted(best) from None
    return best


def hop_stages(stages: list[Stage], settings: Hops, i: int, rounds: int) -> list[Stage]:
    """The stages of hop i (0 first) of ``rounds``: for the last ``settings.far_hops`` hops they
    weigh the wrong regions past the HD95 bar by ``settings.far`` (Stage.far); the other hops
    run them as they are."""
    if i < rounds - settings.far_hops:
        return stages
    return [dataclasses.replace(st, far=settings.far) for st in stages]


def _told(progress: Callable[[Progress], None], hop: int, hops: int, p: Progress) -> None:
    progress(dataclasses.replace(p, hop=hop, hops=hops))


def _copies(problem: Problem, best: PoseBatch, settings: Hops, generator: torch.Generator) -> PoseBatch:
    """A hop's ``settings.copies`` copies of the batch-1 pose: the pose itself, copies
    jittered all over by settings.jitter, and the last ``settings.focused`` (at most half of
    the jittered ones) with only the joints of ``focused_joints`` jittered, by
    ``settings.focus_jitter`` logits (when no finger is near the failing outline, all over as
    the others)."""
    params = PoseParameters(best.repeat(settings.copies), problem.limits)
    focused = min(settings.focused, (settings.copies - 1) // 2)
    near = focused_joints(problem, best, settings.focus_share) if focused else []
    if not any(bool(n.any()) for n in near):
        focused = 0
    plain = settings.copies - focused
    jitter(params, settings.jitter, generator, rows=slice(1, plain))
    if focused:
        jitter(params, (settings.focus_jitter, 0.0, 0.0), generator, rows=slice(plain, None), joints_only=near)
    return params.poses()


@torch.no_grad()
def focused_joints(problem: Problem, poses: PoseBatch, share: float) -> list[torch.Tensor]:
    """Per hand slot, (15,) bool in JOINT_NAMES order: the joints whose finger, from that
    joint to its tip, passes within ``share`` of the frame height of an outline pixel beyond
    the HD95 bar (metrics.far_outline) in some view: the joints that move the shadow where it
    fails. poses: batch 1."""
    masks = problem.view_masks(poses)
    outs = problem.pose(poses.hands)
    near = [torch.zeros(15, dtype=torch.bool) for _ in outs]
    t = np.linspace(0.0, 1.0, 6)
    for k, view in enumerate(problem.views):
        far = far_outline(masks[k][0], view.target)
        if not far.any():
            continue
        dist = ndimage.distance_transform_edt(~far)
        height, width = far.shape
        scene = problem.level(problem.height, k).scene
        for i, out in enumerate(outs):
            xy = scene.project(out.keypoints[:1])[0][0].cpu().double().numpy()  # (21, 2) pixels (x, y)
            a, b = xy[SEGMENT_STARTS], xy[SEGMENT_ENDS]  # (15, 2): each finger segment
            points = a[:, None] + (b - a)[:, None] * t[None, :, None]  # (15, 6, 2)
            col, row = np.floor(points[..., 0]).astype(int), np.floor(points[..., 1]).astype(int)
            inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
            d = np.where(inside, dist[row.clip(0, height - 1), col.clip(0, width - 1)], np.inf)
            segment = (d.min(1) <= share * height).reshape(5, 3)
            # A joint moves every segment from it to the tip.
            joint = np.flip(np.logical_or.accumulate(np.flip(segment, 1), 1), 1).reshape(15)
            near[i] |= torch.from_numpy(joint.copy())
    return near
