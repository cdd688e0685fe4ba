"""Fitting hands to a target shadow: configuration, starts, search, finishing, result. No file
output.

result = fit_frame(target_frame, FitConfig(hands="2"))
result.posed     # PosedScene (hands + scene + fit info), ready to save or render
result.shadow    # the exact shadow of exactly what pose.json holds, and result.score its measures

result = fit_frame([front, side], FitConfig(view_angle_deg=90))   # one pose, two shadows
result.views     # per view (ViewFit): its scene, target, shadow, measures, missing parts
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Sequence

import numpy as np
import torch

from handshadow.errors import HandshadowError
from handshadow.hands import load_hand
from handshadow.hands.arms import ArmCheck
from handshadow.hands.limits import JointLimits
from handshadow.hands.penetration import Penetration, hand_parts, penetration
from handshadow.hands.posed import PosedMesh, cast_shadows
from handshadow.metrics import FitScore, Part, ViewScores, iou, score, thin_parts, uncovered_parts
from handshadow.posefile import parse_pose
from handshadow.poses import PoseBatch, PosedScene
from handshadow.scene import (
    FIT_LAMP_TO_WALL_M,
    LAMP_TO_WALL_M,
    Scene,
    check_view_angle,
    default_views,
    frame_height_for,
)
from handshadow.search import (
    Finishing,
    GiveUp,
    Hops,
    Interrupted,
    Problem,
    Progress,
    Reach,
    SearchResult,
    Settle,
    Stage,
    ViewTarget,
    hop,
    keep_between_light_and_wall,
    polish,
    run_stages,
    separate,
    settle,
)
from handshadow.search.atlas import load_atlas
from handshadow.search.config import OUTLINE_THIN
from handshadow.search.pieces import Partner, two_pieces
from handshadow.search.stages import rank_details
from handshadow.search.starts import choose_starts, start_key

log = logging.getLogger(__name__)
QUALITY = ("fast", "default", "best")
# Polish rounds, at most and only while the result fails the success test: (rounds, further
# rounds while it is a near miss, patience: the near miss's rounds end after this many in a
# row that bring nothing). Each round's jitter differs; a near miss often passes a few rounds
# after one that brought nothing (search.finishing.polish). Fast hunts a near miss's last
# pixels as the default does (with its hops below).
POLISH_ROUNDS = {"fast": (1, 8, 3), "default": (2, 8, 3), "best": (3, 12, 4)}
# --hands auto takes one hand when its search passes the success test (a person makes the shape
# with one hand and keeps the other free); when neither passes, one hand unless two score better
# by more than this (rank-key blend).
ONE_HAND_PREFERENCE = 0.02
# The stages at full resolution push out what the exact mesh test finds inside other flesh,
# found afresh every this many steps (search.objective.ExactContacts; 0 turns it off).
CONTACTS_EVERY = 10
# The exact-outline stages (blur at most this many pixels, skeleton guides at most this factor)
# weigh spills and the target's holes and notches as the polish does (Finishing's
# polish_spill and polish_notches), and thin parts at OUTLINE_THIN (twice Weights.thin): the
# spill weight alone pulled thin parts in as it pulled spills back (docs/measured.md, **Outline stages**).
OUTLINE_STAGE_BLUR_PX = 1.0
OUTLINE_STAGE_SKELETON = 0.05
CUDA_WIDER = 16  # on a GPU the search keeps this many times the hypotheses (see schedule)
MAX_VIEWS = 2  # targets one pose may answer: today's lamp and wall, and one turned about the hands
# With several views each shadow's outline is pulled by the other views too and settles more
# slowly: a last exact stage at a small rate, at full resolution (schedule sets height and steps).
VIEWS_SETTLE = Stage(height=0, blur_px=0, attract_px=2, steps=0, keep=1, lr_scale=0.1, skeleton=0.0)
VIEWS_SETTLE_STEPS = {"fast": 60, "default": 80, "best": 100}
# Several shadows are seldom all met by the search alone: twice the polish's base rounds (a
# round never hands back worse, and costs a few seconds).
VIEWS_POLISH_ROUNDS = {"fast": (2, 0, 1), "default": (4, 8, 3), "best": (6, 12, 4)}
# Attempts a fit may make: one that fails the success test starts afresh with the next seed
# (other random starts, other jitter) and from library and atlas starts not searched yet, and
# the best result is kept. On the 64 of 95 HSP targets that the first attempt failed, a second
# turned 10 into successes (9 with the next seed alone); on the 35 that two attempts failed
# (2026-12-03), a third turned 5 into successes; on the 30 that three failed, a fourth 3 and a
# fifth 3 of the 27 left, a sixth 1 of 24 (2026-12-04, docs/measured.md, **Fitting**). A pass costs no more;
# a failure costs every attempt. Fast's further attempts start only from a near result (below).
ATTEMPTS = {"fast": 4, "default": 5, "best": 6}
# With these qualities' own attempts (FitConfig.attempts None; an explicit count runs in full),
# a failed attempt starts afresh only when its result is within reach of the success test (the
# hops' reach, config.Hops): fast answers a far miss at once and spends its further attempts
# where a pass is near. On the 22 of 95 HSP targets whose first fast attempt failed within
# reach, attempts 2 to 4 passed 10 (5 second, 3 third, 2 fourth), so fast passes 58 rather than
# 48 (issue 14's command, one fit at a time); a far miss still ends after one attempt, so the
# median time stays 13.6 s, and a near miss takes up to about 3 min (docs/measured.md, **Fast's
# attempts from a near miss**).
AFRESH_ONLY_WITHIN_REACH = {"fast": True, "default": False, "best": False}
SKIP_TRIED = True  # a later attempt leaves out the library and atlas starts an earlier one searched
# Hops an attempt may make from a result within reach after its finishing steps (search.hops,
# config.Hops.reach_hd95): its fine stages again from harder-jittered copies, separated and
# polished, the better kept. On the 20 near misses of the default's run on the 95 HSP targets,
# 2 hops turned 5 into successes, each in its first attempt; reaching HD95 0.06 rather than
# 0.04 passed 3 of 31 farther failures (docs/measured.md, Hops). A third hop, weighing the wrong regions
# past the HD95 bar (config.Hops.far_hops), passed 4 of 18 first attempts that two hops left
# within reach; three plain hops passed 3 (docs/measured.md, **A far hop**). Fast hops as the default
# does: on the 95 HSP targets it then passed 44 rather than 31 and lost none, a median 13.4 s
# against 12.1 s; a result within reach takes 20 to 80 s (docs/measured.md, **Fast hops**). Near-miss
# polish rounds alone passed 1 of the first 43 it failed. With the wider fast schedule
# (schedule) 48 pass in a median 14.1 s, one fit at a time.
HOPS = {"fast": 3, "default": 3, "best": 4}
# An attempt that is not the last stops after the 128 px stage when every hypothesis there is
# out of reach (search.config.GiveUp), and the next starts afresh: the stages, finishing steps
# and hops after it cost 15 s or more and would not pass. Fast's attempts run to their end
# (AFRESH_ONLY_WITHIN_REACH: a further one follows only a near result).
GIVE_UP = {"fast": None, "default": GiveUp(), "best": GiveUp()}
# Last of an attempt's finishing steps, after the hops: a result that passes settles into its
# shadow at a steady rate, the outline's weights and then the area's (search.finishing.settle;
# None: off). The search's last stage anneals to zero within 100 steps and leaves shadows a few
# pixels off all along their outline. On 48 HSP first attempts it raised the median IoU from
# 0.893 to 0.900 in a median 9 s and turned no failure into a pass (docs/measured.md, **Settling**).
SETTLE = {"fast": None, "default": Settle(), "best": Settle()}


@dataclasses.dataclass(frozen=True)
class FitConfig:
    """Everything a fit needs besides the target.

    hands: '1', '2' or 'auto' (tries both; one hand when it passes, or does nearly as well);
    size: frame height in pixels that pipeline and the CLI resize the target to (width follows
    the target frame; fit_frame itself fits at the target's own size); iters: total optimisation
    steps (None: the quality's default); quality: 'fast', 'default' or 'best';
    time_limit_s: bounds the search and the polish (None or 0: no limit);
    exclude_library: library poses the search must not start from (tests and benchmarks
    whose targets are shadows of library poses); performers: 1, or 2 to let two people hold
    the two hands (no limit on how far apart the arms are). With two targets (two views):
    view_angle_deg turns view 1's lamp, wall and frame about the vertical axis through the
    hands' working volume (scene.Scene.turned); view_weights weighs the views (None: equally).
    attempts: fresh starts (seed, seed + 1, ...) while the result fails the success test, the
    best kept (None: ATTEMPTS of the quality). lamp_to_wall_m: the point lamp's distance from
    the wall (scene.LAMP_TO_WALL_RANGE_M; one view only; None: scene.FIT_LAMP_TO_WALL_M for one
    view, scene.LAMP_TO_WALL_M for two); the frame on the wall keeps its size. hops: from a
    result within reach of the success test (search.config.Hops.reach_hd95), the attempt's
    fine stages again from jittered copies (search.hops; None: HOPS of the quality, 0: none).
    skip_attempts: the first attempts not run, their library and atlas starts left out as if
    they had been searched (a benchmark measures a further attempt on an earlier run's
    failures alone: attempts are deterministic, and a later one only adds to the earlier).
    hand_shape: the hands' shape, the person's own (Anny: phenotype values in [0, 1] by name,
    hands.anny.PHENOTYPES; MANO: {"betas": [...]}; empty: the model's default hand); pose.json
    records it with each hand. The search's starts are the default hand's poses.
    frame_height_m: the image frame's height on the wall, metres (None: with one view, sized to
    the target so that its shape has the size the search works at, scene.frame_height_for;
    with two, scene.FRAME_HEIGHT_M). Only scene.json's metres follow it: the pixels do not."""

    hands: str = "auto"
    size: int = 256
    iters: int | None = None
    device: str = "auto"
    seed: int = 0
    hand_model: str = "anny"
    mano_dir: str | None = None
    limits: str = "anatomical"
    light: str = "point"
    forearm: bool = True
    quality: str = "default"
    time_limit_s: float | None = None
    exclude_library: tuple[str, ...] = ()
    performers: int = 1
    atlas: bool = True
    view_angle_deg: float = 90.0
    view_weights: tuple[float, ...] | None = None
    attempts: int | None = None
    lamp_to_wall_m: float | None = None
    hops: int | None = None
    skip_attempts: int = 0
    hand_shape: dict = dataclasses.field(default_factory=dict)
    frame_height_m: float | None = None


@dataclasses.dataclass
class ViewFit:
    """One view of a fit: its full-resolution scene, target (H, W) bool, the exact shadow
    (H, W) bool of exactly what pose.json holds, its measures, its weight (the views' sum to
    1), the target's parts the shadow misses and the shadow's extra parts (metrics.Part)."""

    scene: Scene
    target: np.ndarray
    shadow: np.ndarray
    score: FitScore
    weight: float
    missing: list[Part]
    extra: list[Part]

    def to_json(self) -> dict:
        """pose.json's per-view measures: the shadow's, its weight, missing and extra parts."""
        out = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.score.as_dict().items()}
        out["shadow_success"] = out.pop("success")
        parts = {"missing": self.missing, "extra": self.extra}
        out["weight"] = round(self.weight, 4)
        for name, found in parts.items():
            out[name] = [
                {"share": round(p.share, 4), "centre": [round(c, 3) for c in p.centre], "thin": p.thin} for p in found
            ]
        return out


@dataclasses.dataclass
class FitResult:
    """A fit. ``shadow``, ``score`` and ``penetration`` are those of exactly what ``posed``
    holds as a file (float64, rounded as pose.json and the OBJ files store it); ``meshes`` are
    those hands. ``success``: the shadow passes the success test and the pose is performable
    (no vertex more than 3 mm inside other flesh, docs/metrics.md)."""

    posed: PosedScene
    score: FitScore
    penetration: Penetration
    arms: ArmCheck
    shadow: np.ndarray  # (H, W) bool at full resolution
    target: np.ndarray  # (H, W) bool
    meshes: list[PosedMesh]
    steps: int  # the search's optimisation steps, every attempt run (pose.json: iterations)
    seconds: float
    interrupted: bool
    poses: PoseBatch  # the result as tensors (batch 1, hand-slot order as posed.hands)
    problem: Problem  # the search's context (hands, limits, renderers) for follow-up work
    views: list[ViewFit]  # every view, view 0 first (score, shadow and target above are view 0's)

    @property
    def performable(self) -> bool:
        """No vertex more than 3 mm inside other flesh, and arms the performers can hold."""
        return self.penetration.performable() and self.arms.holdable(self.problem.reach.performers)

    @property
    def success(self) -> bool:
        """Every view's shadow passes the success test and the pose is performable."""
        return self.view_scores.success and self.performable

    @property
    def view_scores(self) -> ViewScores:
        """Every view's measures and weight, view 0 first (metrics.ViewScores)."""
        return ViewScores(tuple(v.score for v in self.views), tuple(v.weight for v in self.views))


@dataclasses.dataclass
class HandCountFit:
    """The search with one hand count: its sides, problem and result."""

    n_hands: int
    sides: list[str]
    problem: Problem
    search: SearchResult
    left_mm: float | None = None  # how deep the search's result went into other flesh (exact test)
    separation_iou: float | None = None  # the shadow after the separation against before it

    def preference_key(self) -> tuple:
        """Rank key with the one-hand preference, smaller is better: arms that can be held
        first, then the views' failed share; among passes one hand before two; then the blend,
        one hand ahead by ONE_HAND_PREFERENCE."""
        unholdable, failed, blend = self.search.key
        one = self.n_hands == 1
        return unholdable, failed, not (one and not failed), blend - (ONE_HAND_PREFERENCE if one else 0.0)


def resolve_device(name: str) -> str:
    """'cpu', 'cuda' / 'cuda:N' (checked) or 'auto' (CUDA when present, else the CPU)."""
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" or name.startswith("cuda:"):
        if not torch.cuda.is_available():
            raise HandshadowError("CUDA was asked for but no CUDA device is available here (use --device cpu)")
        return name
    if name == "cpu":
        return name
    raise HandshadowError(f"unknown device {name!r} (use cpu, cuda or auto)")


def schedule(
    quality: str, iters: int | None, size: int, device: str = "cpu", views: int = 1
) -> tuple[int, int, list[Stage]]:
    """(random starts, kept starts, stages) for a quality, scaled to a total step budget. On a
    GPU a batch of a thousand hypotheses costs about what one does, so it keeps CUDA_WIDER
    times the starts and CUDA_WIDER / 4 times the survivors of every stage but the last. With
    several views a last exact stage (VIEWS_SETTLE) settles the pose in all of them. The stages
    at full resolution push out the exact mesh contacts (CONTACTS_EVERY), all but the first: a
    small frame (64 px) brings the first stage to full resolution too, and its many
    hypotheses, a broad search, go without the slow exact test. After every stage but
    the last, hands inside each other pass one in front of the other (Stage.layer). The
    exact-outline stages weigh spills, notches and thin parts more (OUTLINE_THIN and the
    polish's weights). Fast is the default's shape at about two-thirds of its starts and
    steps, and keeps fewer hypotheses (docs/measured.md, **Atlas pairs one person can hold**, **Fast
    hops**)."""
    if quality not in QUALITY:
        raise ValueError(f"quality must be one of {', '.join(QUALITY)}")
    s = Stage
    n_random, n_keep, stages = {
        "fast": (
            80,
            20,
            [
                s(height=64, blur_px=8, attract_px=16, steps=125, keep=6, lr_scale=1.0, skeleton=1.0),
                s(height=128, blur_px=3, attract_px=8, steps=88, keep=3, lr_scale=0.7, skeleton=0.3),
                s(height=size, blur_px=1, attract_px=4, steps=100, keep=2, lr_scale=0.4, skeleton=0.05),
                s(height=size, blur_px=0, attract_px=2, steps=62, keep=1, lr_scale=0.15, skeleton=0.0),
            ],
        ),
        "default": (
            128,
            32,
            [
                s(height=64, blur_px=8, attract_px=16, steps=160, keep=8, lr_scale=1.0, skeleton=1.0),
                s(height=128, blur_px=3, attract_px=8, steps=120, keep=4, lr_scale=0.7, skeleton=0.3),
                s(height=size, blur_px=1, attract_px=4, steps=160, keep=3, lr_scale=0.4, skeleton=0.05),
                s(height=size, blur_px=0, attract_px=2, steps=100, keep=1, lr_scale=0.15, skeleton=0.0),
            ],
        ),
        "best": (
            192,
            48,
            [
                s(height=64, blur_px=8, attract_px=16, steps=240, keep=12, lr_scale=1.0, skeleton=1.0),
                s(height=128, blur_px=3, attract_px=8, steps=160, keep=4, lr_scale=0.7, skeleton=0.3),
                s(height=size, blur_px=1, attract_px=4, steps=220, keep=3, lr_scale=0.4, skeleton=0.05),
                s(height=size, blur_px=0, attract_px=2, steps=140, keep=1, lr_scale=0.15, skeleton=0.0),
            ],
        ),
    }[quality]
    stages = [dataclasses.replace(st, height=min(st.height, size)) for st in stages]
    if device.startswith("cuda"):
        n_random, n_keep = n_random * CUDA_WIDER, n_keep * CUDA_WIDER
        stages = [dataclasses.replace(st, keep=st.keep * CUDA_WIDER // 4) for st in stages[:-1]] + stages[-1:]
    if views > 1:
        stages = [*stages, dataclasses.replace(VIEWS_SETTLE, height=size, steps=VIEWS_SETTLE_STEPS[quality])]
    stages = [
        dataclasses.replace(st, contacts_every=CONTACTS_EVERY) if st.height == size and i > 0 else st
        for i, st in enumerate(stages)
    ]
    finishing = Finishing()
    stages = [
        dataclasses.replace(st, thin=OUTLINE_THIN, spill=finishing.polish_spill, notches=finishing.polish_notches)
        if st.blur_px <= OUTLINE_STAGE_BLUR_PX and st.skeleton <= OUTLINE_STAGE_SKELETON
        else st
        for st in stages
    ]
    stages = [dataclasses.replace(st, layer=True) for st in stages[:-1]] + stages[-1:]
    if iters is not None:
        total = sum(st.steps for st in stages)
        stages = [dataclasses.replace(st, steps=max(1, round(st.steps * iters / total))) for st in stages]
    return n_random, n_keep, stages


def hand_counts(config: FitConfig, given: PoseBatch | None = None) -> list[int]:
    """The hand counts a fit tries: the config's, or the given poses' count."""
    if given is not None:
        return [given.n_hands]
    options = ["1", "2"] if config.hands == "auto" else [config.hands]
    if any(o not in ("1", "2") for o in options):
        raise ValueError(f"--hands must be 1, 2 or auto, got {config.hands!r}")
    return [int(o) for o in options]


def fit_frame(
    target: np.ndarray | Sequence[np.ndarray],
    config: FitConfig = FitConfig(),
    progress: Callable[[Progress], None] | None = None,
    extra_starts: PoseBatch | None = None,
    anchor: PoseBatch | None = None,
    stop: Callable[[], bool] | None = None,
) -> FitResult:
    """Fit one or two hands to a binary target frame (H, W), or one pose to one target per
    view (a list of frames of one size: view 0 lit as today, view 1 turned by
    config.view_angle_deg, see :func:`view_scenes`).

    A fit whose result fails the success test starts afresh with the next seed and from
    library and atlas starts not searched yet, up to config.attempts times in all (None:
    ATTEMPTS of the quality); the best result is kept (:func:`result_key`) and the attempts
    end at the first success. Progress reports carry their attempt (0 first).

    extra_starts: hypotheses (hand slots right first) always tried, as given and aligned to
    the target; anchor: batch-1 poses the solution should stay close to (a morph's other
    end). Either fixes the number of hands to theirs. stop: checked at every step of the
    search and of the finishing steps but the separation; True stops the fit as Ctrl-C does
    (the best result so far, marked interrupted). The separation of overlapping hands always
    runs to its end, after a stop or a Ctrl-C too: a result must not penetrate.
    config.time_limit_s bounds the search (set-up included) and the polish of all attempts
    (not marked interrupted; posed.fit["time_limited"] says whether it ended the fit)."""
    t0 = time.perf_counter()
    config = dataclasses.replace(config, device=resolve_device(config.device))
    attempts = attempts_of(config)
    reach_only = config.attempts is None and AFRESH_ONLY_WITHIN_REACH[config.quality]
    hops_of(config)  # a bad count fails before the search, not after it
    check_seed(config.seed)
    # torch.optim imports torch._dynamo on first use, for seconds; a Ctrl-C inside that import
    # would leave it half-done and break every optimiser after it. Import it before the search,
    # where an interrupt has nothing to lose.
    import torch._dynamo  # noqa: F401

    targets = [np.asarray(target, bool)] if isinstance(target, np.ndarray) else [np.asarray(t, bool) for t in target]
    scenes = view_scenes(targets, config)
    limit = config.time_limit_s or None  # seconds; None or 0: no limit
    best, interrupted, runs, steps = None, False, 0, 0
    time_limited = False  # the limit, not the search, ended a search, a polish or the attempts
    gave_up: tuple | None = None  # the best attempt that gave up so far: (index, GaveUp, its config)
    tried: dict[int, set] = {}  # per hand count, the library and atlas starts searched so far
    for k in range(skipped_attempts(config)):
        _skip_attempt(targets, scenes, dataclasses.replace(config, seed=config.seed + k), extra_starts, anchor, tried)
    for k in range(config.skip_attempts, attempts):
        left = None if limit is None else limit - (time.perf_counter() - t0)
        if (best is not None or gave_up is not None) and left is not None and left <= 0:
            time_limited = True
            break
        tell = None if progress is None else (lambda p, k=k: progress(dataclasses.replace(p, attempt=k)))
        attempt = dataclasses.replace(config, seed=config.seed + k)
        give_up = GIVE_UP[config.quality] if k + 1 < attempts else None  # the last attempt always finishes
        try:
            result = _attempt(targets, scenes, attempt, tell, extra_starts, anchor, stop, left, tried, give_up)
        except KeyboardInterrupt:  # Ctrl-C while a later attempt sets up: the best so far stands
            if best is None and gave_up is None:
                raise
            interrupted = True
            break
        except GaveUp as early:
            runs += 1
            steps += early.steps
            if gave_up is None or early.chosen.preference_key() < gave_up[1].chosen.preference_key():
                gave_up = (k, early, attempt)
            log.info(
                "attempt %d of %d out of reach after stage %d: a fresh start", k + 1, attempts, give_up.after_stage + 1
            )
            if stop is not None and stop():
                interrupted = True
                break
            continue
        runs += 1
        steps += result.steps
        interrupted = interrupted or result.interrupted
        time_limited = time_limited or result.posed.fit["time_limited"]
        if best is None or result_key(result) < result_key(best):
            best, chosen = result, k
        if best.success or interrupted or (stop is not None and stop()):
            break
        if k + 1 < attempts and reach_only and not within_reach(result):
            log.info("attempt %d of %d failed out of reach (%s): no fresh start", k + 1, attempts, result.score)
            break
        if k + 1 < attempts:
            log.info("attempt %d of %d failed the success test (%s): a fresh start", k + 1, attempts, result.score)
    if gave_up is not None and (best is None or best.interrupted):
        # A Ctrl-C, stop or the time limit came before a later attempt finished: the attempt that
        # gave up is finished too (separated; not polished after a Ctrl-C or stop), the better kept.
        k, early, attempt = gave_up
        halt = (lambda: True) if interrupted else stop
        left = None if limit is None else limit - (time.perf_counter() - t0)
        result = _complete(
            targets, scenes, early.chosen, attempt, halt, time.perf_counter(), left, None, early.steps, interrupted
        )
        time_limited = time_limited or result.posed.fit["time_limited"]
        if best is None or result_key(result) < result_key(best):
            best, chosen = result, k
    seconds = time.perf_counter() - t0
    fit = dict(
        best.posed.fit,
        iterations=steps,
        seconds=round(seconds, 2),
        interrupted=interrupted,
        time_limited=time_limited and not interrupted,
        attempt=chosen + 1,
        attempts_run=runs,
    )
    return dataclasses.replace(
        best, posed=dataclasses.replace(best.posed, fit=fit), steps=steps, seconds=seconds, interrupted=interrupted
    )


def attempts_of(config: FitConfig) -> int:
    """How many attempts a fit may make: config.attempts, or the quality's (ATTEMPTS)."""
    attempts = ATTEMPTS[config.quality] if config.attempts is None else config.attempts
    if attempts < 1:
        raise HandshadowError(f"a fit needs at least one attempt, got {attempts}")
    return attempts


def skipped_attempts(config: FitConfig) -> int:
    """config.skip_attempts, if it leaves an attempt to run (0 to attempts_of(config) - 1)."""
    skip, attempts = config.skip_attempts, attempts_of(config)
    if isinstance(skip, bool) or not isinstance(skip, int) or not 0 <= skip < attempts:
        raise HandshadowError(f"skip_attempts must be a whole number from 0 to {attempts - 1}, got {skip!r}")
    return skip


MAX_SEED = 2**32 - 1


def check_seed(seed: int, name: str = "the seed") -> int:
    """The seed if it is a whole number from 0 to MAX_SEED; else HandshadowError (naming it ``name``)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed <= MAX_SEED:
        raise HandshadowError(f"{name} must be a whole number from 0 to {MAX_SEED}, got {seed!r}")
    return int(seed)


def hops_of(config: FitConfig) -> int:
    """How many hops an attempt may make from a result within reach: config.hops, or the quality's (HOPS)."""
    hops = HOPS[config.quality] if config.hops is None else config.hops
    if hops < 0:
        raise HandshadowError(f"hops cannot be negative, got {hops}")
    return hops


def within_reach(result: FitResult) -> bool:
    """Whether a failed result is within the hops' reach of the success test in every view
    (config.Hops, metrics.ViewScores.within)."""
    settings = Hops()
    return result.view_scores.within(settings.reach_hd95, settings.reach_thin)


def result_key(result: FitResult) -> tuple:
    """Sort key of finished fits, smaller is better: performable first, then the views'
    success and blend (metrics.ViewScores.key; with one view metrics.rank_key)."""
    return (not result.performable, *result.view_scores.key())


def _skip_attempt(targets, scenes, config, extra_starts, anchor, tried: dict) -> None:
    """An attempt not run (FitConfig.skip_attempts): only its starts are chosen, and its library
    and atlas starts added to ``tried`` as the attempt would have added them."""
    counts, pieces = search_plan(targets, scenes, config, extra_starts, anchor)
    for n in counts:
        if n == 2 and pieces is not None:
            for side, piece in zip(PIECE_SIDES, pieces):
                _prepare([piece], scenes, 1, config, None, None, tried.setdefault(("piece", side), set()), [side])
        else:
            _prepare(targets, scenes, n, config, extra_starts, anchor, tried.setdefault(n, set()))


class GaveUp(Exception):
    """An attempt's searches all stopped out of reach (search.config.GiveUp), after ``steps``
    steps in all. ``chosen`` is the best of them, unfinished: the fit finishes it only when no
    later attempt gives a result (a Ctrl-C, ``stop`` or the time limit comes first)."""

    def __init__(self, chosen: HandCountFit, steps: int):
        super().__init__(f"out of reach after {steps} steps")
        self.chosen, self.steps = chosen, steps


def _attempt(
    targets, scenes, config, progress, extra_starts, anchor, stop, limit, tried=None, give_up: GiveUp | None = None
) -> FitResult:
    """One attempt: a search per hand count (search_plan; a target in two pieces: the pieces'
    search, _piece_search, and the whole target's two-hand search too when the pieces end
    under PIECES_ALONE_IOU), the chosen one finished and measured. ``limit``
    bounds its search and polish in seconds (None: no limit). ``tried``: per hand count (per
    piece: ("piece", side)), the library and atlas starts earlier attempts searched
    (search.starts.start_key); they are left out, and this attempt's are added. ``give_up``:
    a search may stop out of reach (search.stages.run_stages; not the pieces' search); when
    every one does, raises GaveUp."""
    t0 = time.perf_counter()
    counts, pieces = search_plan(targets, scenes, config, extra_starts, anchor)
    tried = {} if tried is None else tried
    searches = []
    for i, n in enumerate(counts):
        # Each hand count gets an equal share of what is left of the limit, from its own set-up on.
        deadline = (limit - (time.perf_counter() - t0)) / (len(counts) - i) if limit else None
        if n == 2 and pieces is not None:
            searches.append(_piece_search(targets, scenes, pieces, config, progress, deadline, stop, tried))
            if searches[-1].search.interrupted or searches[-1].search.ranking[0]["iou"] >= PIECES_ALONE_IOU:
                continue
            # The pieces' hands fit loosely: the two-hand search from the whole target too, the better kept.
            deadline = (limit - (time.perf_counter() - t0)) if limit else None
        seen = tried.setdefault(n, set())
        searches.append(
            _search(targets, scenes, n, config, progress, deadline, extra_starts, anchor, stop, seen, give_up)
        )
        if searches[-1].search.interrupted:
            break
    steps = sum(s.search.steps for s in searches)
    interrupted = any(s.search.interrupted for s in searches)
    # A search that gave up is still a candidate when another was interrupted: the fit ends here.
    reached = searches if interrupted else [s for s in searches if not s.search.gave_up]
    if not reached:
        raise GaveUp(min(searches, key=HandCountFit.preference_key), steps)
    chosen = min(reached, key=HandCountFit.preference_key)
    timed_out = any(s.search.timed_out for s in searches)
    return _complete(targets, scenes, chosen, config, stop, t0, limit, progress, steps, interrupted, timed_out)


def _complete(
    targets, scenes, chosen, config, stop, t0, limit, progress, steps, interrupted, timed_out=False
) -> FitResult:
    """A search's best finished (separation, polish, hops, placement) and measured: the
    attempt's FitResult. ``t0`` and ``limit`` as the attempt's; ``steps`` its search steps;
    ``timed_out``: the limit ended one of its searches (posed.fit["time_limited"] also counts
    the finishing steps')."""
    poses, finish_interrupted, finish_timed_out = _finish(chosen, config, stop, t0, limit, progress)
    interrupted = interrupted or finish_interrupted
    timed_out = timed_out or finish_timed_out
    try:
        return _result(targets, scenes, chosen, poses, config, steps, time.perf_counter() - t0, interrupted, timed_out)
    except KeyboardInterrupt:  # Ctrl-C while the finished pose is measured: measure it, then stop
        return _result(targets, scenes, chosen, poses, config, steps, time.perf_counter() - t0, True, timed_out)


def view_scenes(targets: list[np.ndarray], config: FitConfig) -> list[Scene]:
    """The scene of each target (H, W): view 0 is Scene.default (one view: its frame sized to the
    target, config.frame_height_m); view 1 the same turned by
    config.view_angle_deg about the vertical axis through the hands' working volume. Raises
    HandshadowError for more than MAX_VIEWS targets, targets of different sizes, an angle out
    of range (scene.check_view_angle), view weights that do not fit, or a lamp distance out of
    range or with two views."""
    if not 1 <= len(targets) <= MAX_VIEWS:
        raise HandshadowError(f"one pose can answer 1 to {MAX_VIEWS} targets, got {len(targets)}")
    if len({t.shape for t in targets}) > 1:
        raise HandshadowError(f"the targets must have one size, got {', '.join(str(t.shape) for t in targets)}")
    weights = config.view_weights
    if weights is not None and (len(weights) != len(targets) or not all(w > 0 for w in weights)):
        raise HandshadowError(f"give one positive weight per target ({len(targets)}), got {list(weights)}")
    height, width = targets[0].shape
    if len(targets) > 1:
        check_view_angle(config.view_angle_deg)
    angles = (0.0, config.view_angle_deg)[: len(targets)]
    lamp = config.lamp_to_wall_m
    if lamp is None:
        lamp = FIT_LAMP_TO_WALL_M if len(targets) == 1 else LAMP_TO_WALL_M
    frame = config.frame_height_m
    if frame is None and len(targets) == 1:
        frame = frame_height_for(targets, config.light)
    return default_views(width, height, config.light, angles, lamp, frame)


def _finish(
    chosen: HandCountFit, config: FitConfig, stop, t0: float, limit: float | None, progress=None
) -> tuple[PoseBatch, bool, bool]:
    """Separation, polish, hops, settling and placement of the chosen search's best: (poses,
    interrupted, whether the time limit ended a finishing step). ``progress`` sees the hops'
    stages."""
    problem, res = chosen.problem, chosen.search
    timed_out = False

    def polish_stop() -> bool:
        nonlocal timed_out
        if stop is not None and stop():
            return True
        timed_out = limit is not None and time.perf_counter() - t0 > limit
        return timed_out

    poses, interrupted = _separated(chosen)
    try:
        if not (res.interrupted or interrupted):
            views = len(problem.views)
            rounds, near_rounds, patience = (POLISH_ROUNDS if views == 1 else VIEWS_POLISH_ROUNDS)[config.quality]
            generator = torch.Generator(device="cpu").manual_seed(config.seed)
            poses = polish(
                problem, poses, rounds, near_rounds, patience=patience, stop=polish_stop, generator=generator
            )
            hops = hops_of(config)
            if hops > 0:
                _, _, stages = schedule(config.quality, config.iters, problem.height, config.device, views)

                def finish(found: PoseBatch) -> PoseBatch:
                    found = separate(problem, found, stop=polish_stop)
                    return polish(
                        problem, found, rounds, near_rounds, patience=patience, stop=polish_stop, generator=generator
                    )

                settings = Hops()
                poses = hop(
                    problem,
                    poses,
                    stages[max(0, len(stages) - settings.stages) :],
                    finish,
                    hops,
                    settings,
                    generator,
                    stop=polish_stop,
                    progress=progress,
                )
            settling = SETTLE[config.quality]
            if settling is not None and problem.scores(poses)[0].success:
                poses = settle(problem, poses, settling, stop=polish_stop)
    except Interrupted as halt:  # Ctrl-C, stop or the time limit in the finishing steps: keep what they reached
        poses, interrupted = halt.poses, not timed_out
        if timed_out:
            log.info("the polish stopped at the time limit")
    return keep_between_light_and_wall(problem, poses), interrupted, timed_out and not interrupted


def _separated(chosen: HandCountFit) -> tuple[PoseBatch, bool]:
    """The search's best separated until the exact mesh test passes (finishing.separate), run
    to its end even after a stopped search or a Ctrl-C during it, since a result must not
    penetrate: (poses, whether Ctrl-C came meanwhile). Sets chosen.left_mm (how deep the
    search's result went) and chosen.separation_iou (shadow after against before)."""
    problem, found = chosen.problem, chosen.search.poses
    interrupted = False
    try:
        chosen.left_mm = problem.mesh_penetration(found)[0].deepest_mm
    except KeyboardInterrupt:
        interrupted = True
    try:
        poses = separate(problem, found, stop=None)
    except Interrupted as halt:  # Ctrl-C: finish the separation from where it stood, then stop
        interrupted = True
        try:
            poses = separate(problem, halt.poses)
        except Interrupted as again:  # Ctrl-C twice: as it stands
            poses = again.poses
    try:
        chosen.separation_iou = float(iou(problem.shadows(poses)[0], problem.shadows(found)[0]))
    except KeyboardInterrupt:
        interrupted = True
    return poses, interrupted


def _result(
    targets, scenes, chosen: HandCountFit, poses: PoseBatch, config, steps, seconds, interrupted, timed_out=False
) -> FitResult:
    """The FitResult of the finished poses: measured on exactly what the pose file will hold.
    ``timed_out``: the time limit ended a search or finishing step (fit["time_limited"])."""
    hands = [
        h
        for side, batch in zip(chosen.sides, poses.hands)
        for h in batch.to_hand_poses(side, config.hand_model, shape=dict(config.hand_shape))
    ]
    posed = PosedScene(tuple(hands), scenes[0], config.forearm, more_views=tuple(scenes[1:]))
    posed = parse_pose(posed.to_json())  # the file's rounding
    meshes, masks = cast_shadows(posed, config.mano_dir)
    views = [view_fit(s, t, m > 0.5, v.weight) for s, t, m, v in zip(posed.views, targets, masks, chosen.problem.views)]
    pen = penetration(
        [m.vertices for m in meshes], [m.faces for m in meshes], [hand_parts(m) for m in chosen.problem.models]
    )
    arms = arm_check(chosen.problem, poses)
    info = fit_info(views[0].score, pen, arms, chosen.problem.reach.performers, views)
    info.update(
        search_penetration_mm=None if chosen.left_mm is None else round(chosen.left_mm, 2),
        separation_shadow_iou=None if chosen.separation_iou is None else round(chosen.separation_iou, 4),
    )
    info.update(
        iterations=steps,
        seconds=round(seconds, 2),
        seed=config.seed,
        hands=chosen.n_hands,
        limits=config.limits,
        quality=config.quality,
        interrupted=interrupted,
        time_limited=timed_out and not interrupted,
    )
    if len(views) > 1:
        info["view_angle_deg"] = config.view_angle_deg
    posed = dataclasses.replace(posed, fit=info)
    first = views[0]
    return FitResult(
        posed=posed,
        score=first.score,
        penetration=pen,
        arms=arms,
        shadow=first.shadow,
        target=first.target,
        meshes=meshes,
        steps=steps,
        seconds=seconds,
        interrupted=interrupted,
        poses=poses,
        problem=chosen.problem,
        views=views,
    )


def view_fit(scene: Scene, target: np.ndarray, shadow: np.ndarray, weight: float) -> ViewFit:
    """One view's measures, missing and extra parts, for a shadow (H, W) bool."""
    thin = thin_parts(target)
    return ViewFit(
        scene,
        target,
        shadow,
        score(shadow, target, thin),
        weight,
        uncovered_parts(target, shadow, target, thin),
        uncovered_parts(shadow, target, target, thin),
    )


def arm_check(problem: Problem, poses: PoseBatch) -> ArmCheck:
    """The arm rules (hands.arms) for a batch-1 pose in every view (Problem.arm_checks)."""
    return problem.arm_checks(poses)[0]


def fit_info(sc: FitScore, pen: Penetration, arms: ArmCheck, performers: int = 1, views: list[ViewFit] = ()) -> dict:
    """The measures pose.json's fit section holds: the shadow's (iou, boundary_f1, hd95,
    thin_recall, shadow_success), the deepest penetration in mm (between the hands, within
    each hand, overall), the arms (forearms leading back, elbows out of the picture, their
    span, the performers the pose needs), performable, and success (the shadow's and
    performable). With several views the shadow's measures are view 0's, "views" holds every
    view's (ViewFit.to_json) and shadow_success is every view's."""
    shadow = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in sc.as_dict().items()}
    shadow["shadow_success"] = shadow.pop("success")
    if len(views) > 1:
        shadow["shadow_success"] = all(v.score.success for v in views)
        shadow["views"] = [v.to_json() for v in views]
    performable = pen.performable() and arms.holdable(performers)
    return {
        **shadow,
        "penetration_mm": round(pen.deepest_mm, 2),
        "penetration_between_mm": round(pen.between_mm, 2),
        "penetration_within_mm": [round(x, 2) for x in pen.within_mm],
        "forearms_lead_back": list(arms.leads_back),
        "elbows_out_of_picture": list(arms.elbows_out),
        "elbow_span_m": round(arms.span_m, 3),
        "performers": arms.performers,
        "performable": performable,
        "success": shadow["shadow_success"] and performable,
    }


def search_plan(
    targets, scenes, config: FitConfig, extra_starts=None, anchor=None
) -> tuple[list[int], tuple[np.ndarray, np.ndarray] | None]:
    """An attempt's searches: the hand counts (hand_counts) and, for a target in two pieces
    (search.pieces.two_pieces; one view, no given starts or anchor), the pieces, (right's,
    left's). Two pieces take two hands, so with --hands auto only the two-hand search runs."""
    counts = hand_counts(config, extra_starts if extra_starts is not None else anchor)
    pieces = None
    if 2 in counts and len(targets) == 1 and extra_starts is None and anchor is None:
        pieces = two_pieces(targets[0], scenes[0])
    if pieces is not None:
        counts = [2]
    return counts, pieces


def search_budget(targets, config: FitConfig) -> tuple[int, int]:
    """(steps, searches) of an attempt's searches, for progress bars: one run of the stages per
    hand count, or for a target in two pieces one search of a run per piece and a last stage
    for both hands. ``targets``: (H, W) bool, or one per view."""
    targets = [np.asarray(targets, bool)] if isinstance(targets, np.ndarray) else [np.asarray(t, bool) for t in targets]
    scenes = view_scenes(targets, config)
    device = resolve_device(config.device)
    _, _, stages = schedule(config.quality, config.iters, targets[0].shape[0], device, len(targets))
    counts, pieces = search_plan(targets, scenes, config)
    per_search = sum(s.steps for s in stages)
    if pieces is not None:
        return 2 * per_search + stages[-1].steps, 1
    return per_search * len(counts), len(counts)


# A target in two pieces: the right hand searches the piece on the performer's right, the left
# hand the other (search.pieces). When the pieces' search ends under PIECES_ALONE_IOU, the
# two-hand search from the whole target runs too and the better is kept: a piece may want the
# other hand (arms crossed).
PIECE_SIDES = ("right", "left")
PIECES_ALONE_IOU = 0.9


def _piece_search(targets, scenes, pieces, config, progress, deadline, stop, tried: dict) -> HandCountFit:
    """The two-hand search of a target in two pieces (search.pieces): each piece searched with
    its own hand alone through the stages, the larger piece first and the other within one
    person's reach of its result (search.pieces.Partner); then both hands together through the
    last stage on the whole target. ``deadline`` (seconds, None: none) is shared by the three
    in proportion to their steps; ``tried`` holds per piece ("piece", side) the starts
    searched. Progress reports count the three as one search; each reports the pose of both
    hands (a piece not searched yet: its best start) and its shadow on the whole target."""
    t0 = time.perf_counter()
    order = sorted(range(2), key=lambda k: -int(pieces[k].sum()))
    prepared = {}
    for k in order:
        side = PIECE_SIDES[k]
        prepared[k] = _prepare(
            [pieces[k]], scenes, 1, config, None, None, tried.setdefault(("piece", side), set()), [side]
        )
    full = make_problem(targets[0], scenes[0], list(PIECE_SIDES), config)
    stages = prepared[order[0]][2]
    per_piece = sum(s.steps for s in stages)
    total = 2 * per_piece + stages[-1].steps
    best = {k: prepared[k][1].item(0) for k in order}  # the best start, until the piece is searched
    steps, interrupted, timed_out = 0, False, False
    whole: dict[int, np.ndarray] = {}  # the whole target per frame height, for progress reports

    def both() -> PoseBatch:
        return PoseBatch([best[0].hands[0], best[1].hands[0]])

    def tell(offset: int, k: int | None):
        if progress is None:
            return None

        def report(p: Progress) -> None:
            if k is None:  # both hands: the search's own report
                progress(dataclasses.replace(p, done=offset + p.done, total=total))
                return
            hands = [best[0].hands[0], best[1].hands[0]]
            hands[k] = p.poses.hands[0]
            poses = PoseBatch(hands)
            height = p.shadow.shape[0]
            shadow = full.shadows(poses, height)[0].cpu().numpy()
            if height not in whole:  # the whole target at this stage's size, off the device once
                whole[height] = full.level(height).maps.target.cpu().numpy() > 0.5
            score = float(iou(shadow > 0.5, whole[height]))
            progress(dataclasses.replace(p, done=offset + p.done, total=total, shadow=shadow, poses=poses, iou=score))

        return report

    def left_of(share: float) -> float | None:
        return None if deadline is None else max(0.0, deadline - (time.perf_counter() - t0)) * share

    partner = None
    for j, k in enumerate(order):
        problem, starts, _ = prepared[k]
        if partner is not None:
            problem = make_problem(pieces[k], scenes[0], [PIECE_SIDES[k]], config, partner=partner)
        share = per_piece / (total - j * per_piece)
        res = run_stages(problem, starts, stages, tell(j * per_piece, k), deadline_s=left_of(share), stop=stop)
        best[k] = res.poses
        steps += res.steps
        interrupted, timed_out = interrupted or res.interrupted, timed_out or res.timed_out
        if res.interrupted:
            break
        with torch.no_grad():
            out = problem.pose(res.poses.hands)[0]
        elbow = out.forearm_points[0, -1] if out.forearm_points.shape[1] else None
        partner = Partner(res.poses.hands[0].translation[0], elbow)
    if interrupted:
        ranking = rank_details(full, both())
        res = SearchResult(both(), steps, time.perf_counter() - t0, True, ranking, timed_out=timed_out)
    else:
        res = run_stages(full, both(), stages[-1:], tell(2 * per_piece, None), deadline_s=left_of(1.0), stop=stop)
        res = dataclasses.replace(
            res, steps=steps + res.steps, seconds=time.perf_counter() - t0, timed_out=timed_out or res.timed_out
        )
    return HandCountFit(2, list(PIECE_SIDES), full, res)


def _search(
    targets,
    scenes,
    n_hands,
    config,
    progress,
    deadline,
    extra_starts=None,
    anchor=None,
    stop=None,
    tried=None,
    give_up: GiveUp | None = None,
):
    t0 = time.perf_counter()  # the deadline (seconds) counts the set-up too
    problem, starts, stages = _prepare(targets, scenes, n_hands, config, extra_starts, anchor, tried)
    if deadline is not None:
        deadline -= time.perf_counter() - t0
    res = run_stages(problem, starts, stages, progress=progress, deadline_s=deadline, stop=stop, give_up=give_up)
    return HandCountFit(n_hands, ["right", "left"][:n_hands], problem, res)


def _prepare(
    targets, scenes, n_hands, config, extra_starts, anchor, tried=None, sides=None
) -> tuple[Problem, PoseBatch, list]:
    """A search's problem, starts and stages for a hand count (``sides``: the hands, default
    the right, then the left); the starts' library and atlas entries are added to ``tried``
    (and those already in it left out, SKIP_TRIED)."""
    sides = sides or ["right", "left"][:n_hands]
    weights = config.view_weights or (1.0,) * len(targets)
    more = [ViewTarget(s, t, w / weights[0]) for s, t, w in zip(scenes[1:], targets[1:], weights[1:])]
    problem = make_problem(targets[0], scenes[0], sides, config, anchor, more)
    n_random, n_keep, stages = schedule(config.quality, config.iters, targets[0].shape[0], config.device, len(targets))
    rng = np.random.default_rng(config.seed)
    atlas = (
        load_atlas(config.hand_model, config.forearm, config.limits)
        if config.atlas and config.hand_model == "anny"
        else None
    )
    tried = set() if tried is None else tried
    skip = frozenset(tried) if SKIP_TRIED else frozenset()
    starts = choose_starts(problem, sides, n_random, n_keep, rng, extra_starts, config.exclude_library, atlas, skip)
    tried.update(start_key(o) for o in starts.origins or [] if start_key(o) is not None)
    return problem, starts, stages


def make_problem(
    target: np.ndarray,
    scene: Scene,
    sides: list[str],
    config: FitConfig,
    anchor: PoseBatch | None = None,
    more_views: Sequence[ViewTarget] = (),
    partner: Partner | None = None,
) -> Problem:
    """The search's context for a target frame (H, W) bool: the config's hand model for each
    side ('right', 'left') and their joint limits (float32, on the config's device, 'auto'
    resolved); further views of the same pose when given; with one hand, the other hand held
    still (search.Problem)."""
    dtype = torch.float32
    device = resolve_device(config.device)
    models = [
        load_hand(
            config.hand_model,
            s,
            config.hand_shape or None,
            config.mano_dir,
            forearm=config.forearm,
            dtype=dtype,
            device=device,
        )
        for s in sides
    ]
    limits = [JointLimits.preset(config.limits, s, dtype=dtype, device=device) for s in sides]
    if anchor is not None:
        anchor = anchor.to(device)

    reach = Reach().for_performers(config.performers)
    return Problem(scene, target, models, limits, anchor=anchor, reach=reach, more_views=more_views, partner=partner)
