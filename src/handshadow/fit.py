"""Fitting hands to a target shadow: configuration, starts, search, result. No file output.

result = fit_frame(target_frame, FitConfig(hands="2"))
result.pose_set     # PoseSet (hands + scene + fit info), ready to save or render
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable

import numpy as np
import torch

from handshadow.hands import load_hand
from handshadow.hands.limits import joint_limits_deg, wrist_limits_deg
from handshadow.metrics import FitScore, score
from handshadow.posefile import HandPose, PoseSet
from handshadow.scene import Scene
from handshadow.search import HandPoses, Interrupted, Limits, Progress, Searcher, Stage
from handshadow.starts import (
    Candidates,
    apply_similarity,
    library_candidates,
    pivot_pixel,
    random_candidates,
    similarity_align,
)

log = logging.getLogger(__name__)
QUALITY = ("fast", "default", "best")
# Polish rounds, at most and only while the result fails the success test: (rounds, further
# rounds while it is a near miss and still improving).
POLISH_ROUNDS = {"fast": (1, 0), "default": (2, 4), "best": (3, 6)}


@dataclasses.dataclass(frozen=True)
class FitConfig:
    """Everything a fit needs besides the target.

    hands: '1', '2' or 'auto' (tries both, prefers one hand when it does as well);
    size: frame height in pixels (width follows the target frame); iters: total optimisation
    steps (None: the quality's default); quality: 'fast', 'default' or 'best'."""

    hands: str = "auto"
    size: int = 256
    iters: int | None = None
    device: str = "cpu"
    seed: int = 0
    hand_model: str = "anny"
    mano_dir: str | None = None
    limits: str = "anatomical"
    light: str = "point"
    forearm: bool = True
    quality: str = "default"
    time_limit_s: float | None = None


@dataclasses.dataclass
class FitResult:
    pose_set: PoseSet
    score: FitScore
    shadow: np.ndarray  # (H, W) bool, the exact shadow of the result at full resolution
    target: np.ndarray  # (H, W) bool
    steps: int
    seconds: float
    interrupted: bool
    poses: list[HandPoses]  # the result as tensors (batch 1 per hand, pose_set's hand order)
    searcher: Searcher  # the search's context (hands, limits, renderers) for follow-up work


def schedule(quality: str, iters: int | None, size: int) -> tuple[int, int, list[Stage]]:
    """(random starts, kept starts, stages) for a quality, scaled to a total step budget."""
    if quality not in QUALITY:
        raise ValueError(f"quality must be one of {', '.join(QUALITY)}")
    n_random, n_keep, stages = {
        "fast": (
            24,
            8,
            [Stage(64, 6, 12, 60, 3, 1.0, 1.0), Stage(128, 2, 6, 50, 1, 0.7, 0.3), Stage(size, 0, 3, 40, 1, 0.4, 0.05)],
        ),
        "default": (
            128,
            32,
            [
                Stage(64, 8, 16, 160, 8, 1.0, 1.0),
                Stage(128, 3, 8, 120, 4, 0.7, 0.3),
                Stage(size, 1, 4, 160, 3, 0.4, 0.05),
                Stage(size, 0, 2, 100, 1, 0.15, 0.0),
            ],
        ),
        "best": (
            192,
            48,
            [
                Stage(64, 8, 16, 240, 12, 1.0, 1.0),
                Stage(128, 3, 8, 160, 4, 0.7, 0.3),
                Stage(size, 1, 4, 220, 3, 0.4, 0.05),
                Stage(size, 0, 2, 140, 1, 0.15, 0.0),
            ],
        ),
    }[quality]
    stages = [dataclasses.replace(s, height=min(s.height, size)) for s in stages]
    if iters is not None:
        total = sum(s.steps for s in stages)
        stages = [dataclasses.replace(s, steps=max(1, round(s.steps * iters / total))) for s in stages]
    return n_random, n_keep, stages


def fit_frame(
    target: np.ndarray,
    config: FitConfig = FitConfig(),
    progress: Callable[[Progress], None] | None = None,
    extra_starts: list[HandPoses] | None = None,
    anchor: list[HandPoses] | None = None,
    stop: Callable[[], bool] | None = None,
) -> FitResult:
    """Fit one or two hands to a binary target frame (H, W).

    extra_starts: hypotheses (per hand slot, right first) always tried, as given and aligned
    to the target; anchor: batch-1 poses the solution should stay close to (a morph's other
    end). Both fix the number of hands to theirs. stop: checked at every step of the search
    and of the finishing steps; True stops the fit as Ctrl-C does (the best result so far,
    marked interrupted; the separation of overlapping hands still runs after a stopped search).
    config.time_limit_s bounds the search and the polish (not marked interrupted); the
    separation always completes."""
    t0 = time.perf_counter()
    torch.manual_seed(config.seed)
    height, width = target.shape
    scene = Scene.default(width, height, light=config.light)
    options = ["1", "2"] if config.hands == "auto" else [config.hands]
    if extra_starts is not None or anchor is not None:
        options = [str(len(extra_starts if extra_starts is not None else anchor))]
    if any(o not in ("1", "2") for o in options):
        raise ValueError(f"--hands must be 1, 2 or auto, got {config.hands!r}")
    results = []
    limit = config.time_limit_s or None  # seconds; None or 0: no limit
    deadline = limit / len(options) if limit else None
    for option in options:
        results.append(_fit_hands(target, scene, int(option), config, progress, deadline, extra_starts, anchor, stop))
        if results[-1][1].interrupted:
            break
    # Prefer one hand unless two are clearly better.
    best = min(results, key=lambda r: (r[2]["key"][0], r[2]["key"][1] - (0.02 if r[0] == 1 else 0.0)))
    n_hands, res, _, searcher, sides = best
    finish_interrupted, timed_out = False, False

    def polish_stop() -> bool:
        nonlocal timed_out
        if stop is not None and stop():
            return True
        timed_out = limit is not None and time.perf_counter() - t0 > limit
        return timed_out

    try:  # the separation always runs to its end after a stopped search: a result must not penetrate
        poses = searcher.separate(res.poses, stop=None if res.interrupted else stop)
        if not res.interrupted:
            rounds, near_rounds = POLISH_ROUNDS[config.quality]
            poses = searcher.polish(poses, rounds=rounds, near_rounds=near_rounds, stop=polish_stop)
    except Interrupted as halt:  # Ctrl-C, stop or the time limit in the finishing steps: keep what they reached
        poses, finish_interrupted = halt.poses, not timed_out
        if timed_out:
            log.info("the polish stopped at the time limit")
    poses = keep_between_light_and_wall(searcher, poses)
    shadow = searcher.shadows(poses)[0].cpu().numpy() > 0.5
    sc = score(shadow, target)
    hand_poses = [
        HandPose(
            side=side,
            model=config.hand_model,
            shape={},
            pose_deg=np.degrees(p.pose_rad[0].detach().cpu().double().numpy()),
            rotation=p.rotation[0].detach().cpu().double().numpy(),
            translation=p.translation[0].detach().cpu().double().numpy(),
            wrist_deg=np.degrees(p.wrist_rad[0].detach().cpu().double().numpy()),
        )
        for side, p in zip(sides, poses)
    ]
    seconds = time.perf_counter() - t0
    steps = sum(r[1].steps for r in results)
    info = {
        **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in sc.as_dict().items()},
        "iterations": steps,
        "seconds": round(seconds, 2),
        "seed": config.seed,
        "hands": n_hands,
        "limits": config.limits,
        "quality": config.quality,
        "interrupted": finish_interrupted or any(r[1].interrupted for r in results),
    }
    pose_set = PoseSet(hands=tuple(hand_poses), scene=scene, forearm=config.forearm, fit=info)
    return FitResult(
        pose_set, sc, shadow, np.asarray(target, bool), steps, seconds, info["interrupted"], poses, searcher
    )


@torch.no_grad()
def keep_between_light_and_wall(searcher: Searcher, poses: list[HandPoses], margin_m: float = 0.005) -> list[HandPoses]:
    """The placement penalty is soft; if any vertex still reaches the wall (or the light's
    plane), move both hands along the wall normal just enough, so the result is physical."""
    n = torch.as_tensor(searcher.scene.wall.normal, dtype=searcher.dtype, device=searcher.device)
    w0 = torch.as_tensor(searcher.scene.wall.point, dtype=searcher.dtype, device=searcher.device)
    heights = torch.cat([((hand(*p.args()).vertices - w0) @ n).flatten() for hand, p in zip(searcher.hands, poses)])
    lo, hi = searcher.scene.light_depth_range()
    shift = 0.0
    if float(heights.min()) < lo + margin_m:
        shift = lo + margin_m - float(heights.min())
    elif float(heights.max()) > hi - margin_m:
        shift = hi - margin_m - float(heights.max())
    if shift == 0.0:
        return poses
    log.info("moved the hands %.1f mm along the wall normal to keep them off the wall and the light", shift * 1000)
    return [HandPoses(p.pose_rad, p.rotation, p.translation + shift * n, p.wrist_rad) for p in poses]


def _fit_hands(target, scene, n_hands, config, progress, deadline, extra_starts=None, anchor=None, stop=None):
    sides = ["right", "left"][:n_hands] if n_hands == 2 else ["right"]
    searcher = make_searcher(target, scene, sides, config, anchor)
    limits = searcher.limits
    n_random, n_keep, stages = schedule(config.quality, config.iters, target.shape[0])
    starts = initial_hypotheses(
        searcher, sides, limits, n_random, n_keep, np.random.default_rng(config.seed), extra_starts
    )
    res = searcher.run([h for h in starts.hands], stages, progress=progress, deadline_s=deadline, stop=stop)
    return n_hands, res, res.ranking[0], searcher, sides


def make_searcher(
    target: np.ndarray, scene: Scene, sides: list[str], config: FitConfig, anchor: list[HandPoses] | None = None
) -> Searcher:
    """The search context for a target frame (H, W) bool: the config's hand model for each
    side ('right', 'left'), their joint limits (float32, on the config's device)."""
    dtype = torch.float32
    hands = [
        load_hand(
            config.hand_model, s, mano_dir=config.mano_dir, forearm=config.forearm, dtype=dtype, device=config.device
        )
        for s in sides
    ]
    limits = [
        Limits(
            torch.as_tensor(np.radians(joint_limits_deg(config.limits, s)), dtype=dtype, device=config.device),
            torch.as_tensor(np.radians(wrist_limits_deg(config.limits)), dtype=dtype, device=config.device),
        )
        for s in sides
    ]
    return Searcher(scene, target, hands, limits, anchor=anchor)


def initial_hypotheses(
    searcher: Searcher, sides, limits, n_random: int, n_keep: int, rng, extra: list[HandPoses] | None = None
) -> Candidates:
    """Library and random candidates, aligned to the target, the best n_keep of them (at most
    two from any one library pose, so the starts stay diverse); ``extra`` starts are always
    kept, both as given and aligned."""
    device = searcher.device
    lib = library_candidates(len(sides), sides)
    parts = [
        lib,
        random_candidates(n_random, sides, [Limits(lim.joints.cpu(), lim.wrist.cpu()) for lim in limits], rng),
    ]
    if extra is not None:
        parts.append(
            Candidates(
                [HandPoses(*(t.detach().cpu() for t in h.args())) for h in extra],
                ["extra"] * extra[0].pose_rad.shape[0],
            )
        )
    cand = Candidates.cat(parts)
    cand = Candidates([h.to(device) for h in cand.hands], cand.origin)
    small = 64
    shadows = searcher.shadows(cand.hands, small)
    target_small = searcher.level(small)[2].target
    pivot = pivot_pixel(searcher.scene, small)
    scales = np.array([0.8, 1.0, 1.25]) if searcher.scene.light.type == "point" else np.array([1.0])
    angle, scale, shift, _ = similarity_align(shadows.cpu(), target_small.cpu(), pivot, np.arange(0, 360, 20), scales)
    if searcher.scene.light.type != "point":
        scale = torch.ones_like(scale)
    moved = apply_similarity(
        Candidates([HandPoses(*(t.cpu() for t in h.args())) for h in cand.hands], cand.origin),
        angle,
        scale,
        shift,
        searcher.scene,
        small,
    )
    moved = Candidates([HandPoses(*(t.to(device) for t in h.args())) for h in moved.hands], moved.origin)
    shadows = searcher.shadows(moved.hands, small).cpu()
    t = target_small.cpu()
    inter = (shadows * t).sum((1, 2))
    iou = inter / (shadows.sum((1, 2)) + t.sum() - inter).clamp(min=1e-6)
    order = torch.argsort(iou, descending=True).tolist()
    picked, per_source = [], {}
    if extra is not None:  # as given, and aligned
        n_extra = extra[0].pose_rad.shape[0]
        picked = list(range(len(cand.origin) - n_extra, len(cand.origin)))
        given = Candidates([HandPoses(*(t.to(device) for t in h.args())) for h in extra], ["extra:given"] * n_extra)
    for i in order:
        if i in picked:
            continue
        src = moved.origin[i].split(":")[1] if moved.origin[i].startswith("library") else f"random{i}"
        if per_source.get(src, 0) >= 2:
            continue
        per_source[src] = per_source.get(src, 0) + 1
        picked.append(i)
        if len(picked) == n_keep:
            break
    log.info("starts: %s", ", ".join(f"{moved.origin[i]} {float(iou[i]):.2f}" for i in picked[:8]))
    chosen = moved.select(picked)
    return Candidates.cat([given, chosen]) if extra is not None else chosen
