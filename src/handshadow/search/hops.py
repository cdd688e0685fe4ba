"""Hops: a close result's way out of its basin, after the finishing steps.

A result within reach of the success test (metrics.FitScore.within: IoU and thin parts met,
HD95 at most config.Hops.reach_hd95 past its bar) has the shape but not the outline, and the
polish's small steps stay in its basin. A hop jitters copies of it harder than the polish
does (config.Hops), sends them through the search's last stages again (stages.run_stages,
the fine stages at full resolution) and finishes the best as the fit does (``finish``:
separation, polish). The result is kept only when it ranks better and is no less
performable; hops end at the first success.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import torch

from handshadow.hands.penetration import TOLERANCE_MM
from handshadow.poses import PoseBatch, PoseParameters
from handshadow.search.config import Hops, Stage
from handshadow.search.finishing import Interrupted, jitter
from handshadow.search.problem import Problem
from handshadow.search.stages import run_stages

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
) -> PoseBatch:
    """Up to ``rounds`` hops from a finished batch-1 pose while it is within
    ``settings.reach_hd95`` of the success test: each hop
    runs ``settings.copies`` copies of the best so far (all but the first jittered by
    ``settings.jitter``: joint logits, rotation vector in radians, translation in metres)
    through ``stages``, then ``finish`` on the stages' best. A hop's result replaces the best
    only when its score ranks better (metrics.ViewScores.key), it goes no deeper into other
    flesh than the best (or the exact test's tolerance) and its arms can be held when the
    best's could. A pose out of reach (or a success) comes back as it is. Ctrl-C or ``stop``
    raises finishing.Interrupted with the best so far."""
    best, score = poses, problem.scores(poses)[0]
    if rounds < 1 or not score.within(settings.reach_hd95):
        return poses
    generator = generator or torch.Generator(device="cpu").manual_seed(0)
    try:
        depth = problem.mesh_penetration(poses)[0].deepest_mm
        holdable = problem.holdable(poses)[0]
        for i in range(rounds):
            if not score.within(settings.reach_hd95):
                break
            log.info("within reach (%s): hop %d of %d", score, i + 1, rounds)
            params = PoseParameters(best.repeat(settings.copies), problem.limits)
            jitter(params, settings.jitter, generator)
            found = run_stages(problem, params.poses(), stages, stop=stop)
            if found.interrupted:
                raise Interrupted(best)
            out = finish(found.poses)
            out_score = problem.scores(out)[0]
            out_depth = problem.mesh_penetration(out)[0].deepest_mm
            if (
                out_score.key() < score.key()
                and out_depth <= max(depth, TOLERANCE_MM)
                and (problem.holdable(out)[0] or not holdable)
            ):
                best, score, depth = out, out_score, out_depth
    except (KeyboardInterrupt, Interrupted):  # a half-finished hop may still overlap: the best so far is kept
        raise Interrupted(best) from None
    return best
