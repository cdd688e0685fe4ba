"""The coarse-to-fine stages: many hypotheses optimised together, ranked by the fit measures
after each stage, the best kept."""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable

import numpy as np
import torch

from handshadow.metrics import SUCCESS_HD95, SUCCESS_IOU, iou
from handshadow.poses import HandPoseBatch, PoseBatch, PoseParameters
from handshadow.search.config import FAR_EVERY, GiveUp, Stage
from handshadow.search.crossover import crossed
from handshadow.search.finishing import pass_in_front
from handshadow.search.loop import optimise
from handshadow.search.objective import ExactContacts, FarOutline, view_objective
from handshadow.search.problem import Problem

log = logging.getLogger(__name__)

# After every stage but the last, two-hand hypotheses are also recombined (search.crossover):
# up to the stage's keep of pairings, one hypothesis's right hand with another's left, join
# the ranking when they cover the target better than every hypothesis as it stands.
CROSS = True


@dataclasses.dataclass
class Progress:
    """What a progress callback sees: stage index, step within it, steps done over all stages,
    their total, the best hypothesis's current shadow (H, W) numpy at the stage resolution
    (view 0's), its IoU, its poses (PoseBatch of batch 1), its loss terms by name, and with
    several views the other views' shadows (H, W) at the stage resolution; the fit's attempt
    (0 first, fit.fit_frame) it belongs to; from a hop's stages (search.hops) the hop (1 first)
    and the hops it may make, its steps counted from 0 again (0 and 0 from the search)."""

    stage: int
    step: int
    done: int
    total: int
    shadow: np.ndarray
    iou: float
    poses: PoseBatch
    terms: dict[str, float] = dataclasses.field(default_factory=dict)
    more_shadows: tuple[np.ndarray, ...] = ()
    attempt: int = 0
    hop: int = 0
    hops: int = 0


@dataclasses.dataclass
class SearchResult:
    """poses: the best hypothesis (batch 1); steps taken; seconds; whether Ctrl-C or ``stop``
    ended it; ranking: per surviving hypothesis its index, measures and rank key, best first;
    gave_up: the stages stopped early with every survivor out of reach (:func:`out_of_reach`);
    timed_out: the deadline ended them."""

    poses: PoseBatch
    steps: int
    seconds: float
    interrupted: bool
    ranking: list[dict]
    gave_up: bool = False
    timed_out: bool = False

    @property
    def key(self) -> tuple:
        return self.ranking[0]["key"]


def run_stages(
    problem: Problem,
    starts: PoseBatch,
    stages: list[Stage],
    progress: Callable[[Progress], None] | None = None,
    every: int = 10,
    deadline_s: float | None = None,
    stop: Callable[[], bool] | None = None,
    give_up: GiveUp | None = None,
) -> SearchResult:
    """Optimise the starting hypotheses through the stages, keeping each stage's best.
    Ctrl-C (KeyboardInterrupt), ``stop`` returning True (checked every step) or the deadline
    ends it early with the best so far. With ``give_up``, the stages end after its stage when
    every survivor is out of reach there (:func:`out_of_reach`; SearchResult.gave_up)."""
    t0 = time.perf_counter()
    total = sum(s.steps for s in stages)
    done, interrupted, gave_up, timed_out = 0, False, False, False
    poses = starts
    try:
        for si, stage in enumerate(stages):
            log.info("stage %d of %d: %d hypotheses at %d px", si + 1, len(stages), poses.batch, stage.height)
            params = PoseParameters(poses, problem.limits)

            contacts = ExactContacts(problem, stage.contacts_every)
            far = FarOutline(FAR_EVERY)

            def evaluate(stage=stage, params=params, contacts=contacts, far=far):
                terms, shadows = view_objective(problem, params.hands(), stage, contacts=contacts, far=far)
                return terms.total, (terms, shadows)

            def after(step, seen, si=si, stage=stage, params=params):
                nonlocal done
                done += 1
                if progress and (step % every == 0 or step == stage.steps - 1):
                    progress(_progress(problem, params, stage, si, step, done, total, *seen))
                if deadline_s is not None and time.perf_counter() - t0 > deadline_s:
                    raise TimeoutError
                return False

            try:
                optimise(
                    params,
                    evaluate,
                    stage.steps,
                    problem.rates.scaled(stage.lr_scale),
                    cosine=True,
                    after=after,
                    stop=stop,
                )
            finally:
                poses = params.poses()
            if CROSS and si < len(stages) - 1:
                pairs = crossed(problem, poses, stage.height, stage.keep)
                if pairs is not None:
                    log.info("stage %d: %d pairings of one's right hand with another's left", si + 1, pairs.batch)
                    poses = PoseBatch.cat([poses, pairs])
            keep = min(stage.keep, poses.batch)
            poses = poses.select(rank_at(problem, poses, stage.height)[:keep])
            if give_up is not None and si == give_up.after_stage and si < len(stages) - 1:
                if out_of_reach(problem, poses, give_up):
                    log.info("stage %d of %d: every hypothesis out of reach, the stages end here", si + 1, len(stages))
                    gave_up = True
                    break
            if stage.layer:
                poses = layered(problem, poses)
    except KeyboardInterrupt:
        interrupted = True
    except TimeoutError:
        log.info("search stopped at its time limit")
        timed_out = True
    ranking = rank_details(problem, poses)
    seconds = time.perf_counter() - t0
    return SearchResult(poses.item(ranking[0]["index"]), done, seconds, interrupted, ranking, gave_up, timed_out)


def out_of_reach(problem: Problem, poses: PoseBatch, give_up: GiveUp) -> bool:
    """Whether no hypothesis, measured at full resolution in every view, is within
    ``give_up``'s reach: an IoU at most ``iou_margin`` short of the success test's bar and an
    HD95 at most ``hd95_margin`` (a share of the frame height) past its bar, and with an IoU
    under the bar an HD95 at most ``hd95_margin_short`` past it."""

    def within(v) -> bool:
        hd95_margin = give_up.hd95_margin if v.iou >= SUCCESS_IOU else give_up.hd95_margin_short
        return v.iou >= SUCCESS_IOU - give_up.iou_margin and v.hd95 <= SUCCESS_HD95 + hd95_margin

    return not any(all(within(v) for v in s.scores) for s in problem.scores(poses))


def layered(problem: Problem, poses: PoseBatch) -> PoseBatch:
    """Each hypothesis whose two hands pass through each other (the exact test between them)
    with one hand put in front of the other along the light's rays (finishing.pass_in_front;
    the shadow changes by a few per cent of scale). One hand, or several views (no ray keeps
    every shadow), come back as they are."""
    if poses.n_hands < 2 or len(problem.views) > 1:
        return poses
    items = [pass_in_front(problem, poses.item(i)) for i in range(poses.batch)]
    hands = [HandPoseBatch(*(torch.cat(t) for t in zip(*(p.hands[h].args() for p in items)))) for h in range(2)]
    return PoseBatch(hands, poses.origins)


def _progress(problem, params, stage, si, step, done, total, terms, shadows) -> Progress:
    loss = terms.total.detach()
    best = int(torch.argmin(loss))
    m = shadows[0].mask[best].detach().cpu().numpy()
    target = problem.level(stage.height).maps.target.cpu().numpy() > 0.5
    more = tuple(s.mask[best].detach().cpu().numpy() for s in shadows[1:])
    poses = params.poses().item(best)
    return Progress(si, step, done, total, m, iou(m > 0.5, target), poses, terms.values(best), more)


def rank_at(problem: Problem, poses: PoseBatch, height: int) -> list[int]:
    """Hypotheses' indices, best first, by the fit measures at a frame height (every view's,
    metrics.ViewScores); at full resolution those whose arms the performers can hold first
    (the search's arms term is soft, and a pose nobody can hold is no result)."""
    keys = [s.key() for s in problem.scores(poses, height)]
    if height == problem.height:
        keys = [(not held, *k) for held, k in zip(problem.holdable(poses), keys)]
    return sorted(range(poses.batch), key=keys.__getitem__)


def rank_details(problem: Problem, poses: PoseBatch) -> list[dict]:
    """Per hypothesis at full resolution: index, view 0's measures, whether its arms can be
    held, rank key (holdable first, then every view's measures) and, with several views,
    each view's measures under "views"; best first."""
    rows = []
    for i, (s, held) in enumerate(zip(problem.scores(poses), problem.holdable(poses))):
        row = {"index": i, **s.scores[0].as_dict(), "holdable": held, "key": (not held, *s.key())}
        if len(s.scores) > 1:
            row["views"] = [v.as_dict() for v in s.scores]
        rows.append(row)
    return sorted(rows, key=lambda r: r["key"])
