"""Finishing steps after the search, on its best hypothesis (a PoseBatch of batch 1):

    separate   resolve the penetration the search's soft penalty left
    polish     aim a few more steps at the success test
    keep_between_light_and_wall   a rigid shift so that nothing touches the wall or the lamp

Ctrl-C, or a ``stop`` callable returning True, raises :class:`Interrupted` carrying the poses
reached, so the caller can still write the best result.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import torch

from handshadow.metrics import FitScore, rank_key, score
from handshadow.poses import PoseBatch, PoseParameters
from handshadow.scene import RESULT_MARGIN_M
from handshadow.search.config import Finishing
from handshadow.search.loop import optimise
from handshadow.search.objective import objective
from handshadow.search.problem import Problem

log = logging.getLogger(__name__)


class Interrupted(Exception):
    """Ctrl-C (or a stop request) during a finishing step, carrying the batch-1 poses to keep."""

    def __init__(self, poses: PoseBatch):
        super().__init__("interrupted")
        self.poses = poses


def separate(
    problem: Problem,
    poses: PoseBatch,
    settings: Finishing = Finishing(),
    stop: Callable[[], bool] | None = None,
) -> PoseBatch:
    """Resolve what penetration the search left (its penalty is soft so that hands may pass
    through each other on the way): small steps of the full-resolution objective with a much
    higher penetration weight, until no proxies overlap by more than the tolerance."""
    params = None
    try:
        if float(problem.penetration_mm(poses).max()) <= settings.tolerance_mm:
            return poses
        stage = settings.stage(problem.height, settings.separation_steps)
        weights = settings.separation_weights(problem.weights)
        params = PoseParameters(poses, problem.limits)

        def evaluate():
            terms, _ = objective(problem, [params.hand(i) for i in range(params.n_hands)], stage, weights)
            return terms.total, None

        def apart(step, _):
            return step > 0 and float(problem.penetration_mm(params.poses()).max()) <= settings.tolerance_mm

        rates = problem.rates.scaled(stage.lr_scale)
        optimise(params, evaluate, stage.steps, rates, observe=apart, stop=stop)
    except KeyboardInterrupt:  # Ctrl-C keeps the result as it stands
        raise Interrupted(params.poses() if params is not None else poses) from None
    result = params.poses()
    log.info("separated the hands: deepest overlap %.1f mm", float(problem.penetration_mm(result).max()))
    return result


def polish(
    problem: Problem,
    poses: PoseBatch,
    rounds: int = 2,
    near_rounds: int = 0,
    settings: Finishing = Finishing(),
    always: bool = False,
    stop: Callable[[], bool] | None = None,
    generator: torch.Generator | None = None,
) -> PoseBatch:
    """Aim the last steps at what the success test sees: a few copies of the result (the
    first as it is, the others slightly jittered) take small steps of an objective that
    stresses light leaking between fingers, shadow filling the target's holes and notches,
    and far spills; the best-scoring pose met on the way wins, and only if it scores better
    than the start and overlaps no more. Rounds repeat from the best while the success test
    is not passed: ``rounds`` of them, then up to ``near_rounds`` more while the result is a
    near miss (:attr:`FitScore.near_miss`) and the last round improved it. A start that
    already passes is returned as it is unless ``always``."""
    best = poses
    try:
        best_score = score(problem.shadows(poses)[0].cpu().numpy() > 0.5, problem.target, problem.thin)
        allowed = max(settings.tolerance_mm, float(problem.penetration_mm(poses).max()))
        generator = generator or torch.Generator(device="cpu").manual_seed(0)
        improved = False
        for i in range(rounds + near_rounds):
            if best_score.success and not always:
                break
            if i >= rounds and not (best_score.near_miss and improved):
                break
            previous = best_score
            best_score, best = polish_round(problem, best, best_score, settings, allowed, generator, stop)
            improved = rank_key(best_score) < rank_key(previous)
    except KeyboardInterrupt:  # between steps, or while scoring the start
        raise Interrupted(best) from None
    return best


def polish_round(
    problem: Problem,
    poses: PoseBatch,
    best_score: FitScore,
    settings: Finishing,
    allowed_mm: float,
    generator: torch.Generator,
    stop: Callable[[], bool] | None = None,
) -> tuple[FitScore, PoseBatch]:
    """One round of the polish: (the best score met, its poses), the start's if none beat it."""
    stage = settings.stage(problem.height, settings.steps)
    weights = settings.polish_weights(problem.weights)
    params = PoseParameters(poses.repeat(settings.copies), problem.limits)
    jitter(params, settings.jitter, generator)
    best = {"score": best_score, "key": rank_key(best_score), "poses": poses}

    def evaluate():
        terms, shadow = objective(problem, [params.hand(i) for i in range(params.n_hands)], stage, weights)
        return terms.total, shadow.mask

    def look(step, mask):
        if step % settings.check_every and step != settings.steps:
            return False
        current = params.poses()
        depth = problem.penetration_mm(current)
        for i, m in enumerate(mask.detach().cpu().numpy() > 0.5):
            s = score(m, problem.target, problem.thin)
            key = rank_key(s)
            if key < best["key"] and float(depth[i]) <= allowed_mm:
                best.update(score=s, key=key, poses=current.item(i))
        return False

    try:
        optimise(
            params, evaluate, stage.steps, problem.rates.scaled(stage.lr_scale), observe=look, look_last=True, stop=stop
        )
    except KeyboardInterrupt:
        raise Interrupted(best["poses"]) from None
    return best["score"], best["poses"]


def jitter(params: PoseParameters, sigmas: tuple[float, float, float], generator: torch.Generator) -> None:
    """Add Gaussian noise to every copy but the first: sigmas for the angle logits, the
    rotation vector (radians) and the translation (metres)."""
    with torch.no_grad():
        for i in range(params.n_hands):
            joints, wrist, rotvec, trans = params.hand_parameters(i)
            for group, sigma in zip(((joints, wrist), (rotvec,), (trans,)), sigmas):
                for p in group:
                    noise = torch.randn(p.shape, generator=generator).to(p) * sigma
                    noise[0] = 0
                    p.add_(noise)


@torch.no_grad()
def keep_between_light_and_wall(problem: Problem, poses: PoseBatch, margin_m: float = RESULT_MARGIN_M) -> PoseBatch:
    """The placement penalty is soft; if any vertex still comes within margin_m of the wall
    (or of the light's plane), move both hands along the wall normal just enough, so the
    result is physical."""
    n = torch.as_tensor(problem.scene.wall.normal, dtype=problem.dtype, device=problem.device)
    w0 = torch.as_tensor(problem.scene.wall.point, dtype=problem.dtype, device=problem.device)
    heights = torch.cat([((o.vertices - w0) @ n).flatten() for o in problem.pose(poses.hands)])
    lo, hi = problem.scene.light_depth_range()
    shift = 0.0
    if float(heights.min()) < lo + margin_m:
        shift = lo + margin_m - float(heights.min())
    elif float(heights.max()) > hi - margin_m:
        shift = hi - margin_m - float(heights.max())
    if shift == 0.0:
        return poses
    log.info("moved the hands %.1f mm along the wall normal to keep them off the wall and the light", shift * 1000)
    return PoseBatch([h.moved(shift * n) for h in poses.hands], poses.origins)


def shadow_score(problem: Problem, poses: PoseBatch) -> tuple[np.ndarray, FitScore]:
    """The full-resolution shadow (H, W) bool of a batch-1 pose and its measures."""
    shadow = problem.shadows(poses)[0].cpu().numpy() > 0.5
    return shadow, score(shadow, problem.target, problem.thin)
