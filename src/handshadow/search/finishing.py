"""Finishing steps after the search, on its best hypothesis (a PoseBatch of batch 1):

    separate   resolve the penetration the search's soft penalty left
    polish     aim a few more steps at the success test
    settle     longer steps at a steady rate, the outline's weights and then the area's
    keep_between_light_and_wall   a rigid shift so that nothing touches the wall or the lamp

Ctrl-C, or a ``stop`` callable returning True, raises :class:`Interrupted` carrying the poses
reached, so the caller can still write the best result.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import torch

from handshadow.hands.penetration import contact_penalty, hand_parts
from handshadow.metrics import ViewScores
from handshadow.poses import HandPoseBatch, PoseBatch, PoseParameters
from handshadow.scene import RESULT_MARGIN_M
from handshadow.search.config import CONTACT_SIDEWAYS, FAR_EVERY, Finishing, Settle, Stage
from handshadow.search.loop import optimise
from handshadow.search.objective import FarOutline, view_objective
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
    """Resolve what penetration the search left (its penalty is soft, on proxies, so that
    hands may pass through each other on the way), until the exact mesh test passes: first
    one hand passes in front of the other (:func:`pass_in_front`), fingers curled into their
    palm open a little (:func:`relax_fingers`), then rounds of small steps
    that push the vertices found inside other flesh out along its surface's normal, the
    contacts found afresh each round. Only the contacts move the pose, and only its joint and
    wrist angles: Adam takes a full step for any gradient, however small, so an image term
    or the rounding in a hand's rigid motion would let every parameter wander. The polish
    then aims at the shadow again. A pose that passes comes back as it is."""
    current = poses
    try:
        current = pass_in_front(problem, current, settings)
        current = relax_fingers(problem, current, settings)
        rates = problem.rates.scaled(settings.lr_scale)
        for _ in range(settings.separation_rounds):
            found = problem.mesh_penetration(current)[0]
            if found.deepest_mm <= settings.tolerance_mm:
                break
            params = PoseParameters(current, problem.limits)

            def evaluate(params=params, contacts=found.contacts):
                outs = problem.pose(params.hands())
                light, sideways = problem.light_position, CONTACT_SIDEWAYS
                push = contact_penalty([o.vertices for o in outs], contacts, light=light, sideways=sideways)
                return push, None

            try:
                optimise(params, evaluate, settings.separation_steps, rates, stop=stop, angles_only=True)
            finally:
                current = params.poses()
        else:
            found = problem.mesh_penetration(current)[0]
            if found.deepest_mm > settings.tolerance_mm:
                # Not a warning: hops and attempts separate candidates that may not be kept, and
                # the result's own penetration is measured and reported at the end.
                log.info("the hands still pass %.1f mm into each other after the separation", found.deepest_mm)
    except KeyboardInterrupt:  # Ctrl-C keeps the result as it stands
        raise Interrupted(current) from None
    return current


def pass_in_front(problem: Problem, poses: PoseBatch, settings: Finishing = Finishing()) -> PoseBatch:
    """Two hands that pass through each other (palms crossing, say) are parted the way a
    performer would do it: one hand goes in front of the other, each moving along the light's
    ray through its wrist (half the distance each: the nearer the lamp, the larger its
    shadow, a few per cent for a few centimetres). The smallest shift of SHIFTS_MM that passes
    the exact test between the hands wins (either hand in front); if none passes, the one
    that leaves the least. One hand, or hands apart, come back as they are."""
    if poses.n_hands < 2 or problem.mesh_penetration(poses, within=False)[0].between_mm <= settings.tolerance_mm:
        return poses
    light = problem.scene.light
    rays = []
    for h in poses.hands:
        if light.type == "point":
            ray = h.translation[0] - torch.as_tensor(light.position, dtype=problem.dtype, device=problem.device)
        else:
            ray = torch.as_tensor(light.direction, dtype=problem.dtype, device=problem.device)
        rays.append(ray / ray.norm())
    best, best_depth = poses, float("inf")
    for shift_mm in settings.pass_in_front_mm:
        for front in (0, 1):
            half = shift_mm / 2000
            moved = PoseBatch(
                [h.moved((-half if k == front else half) * rays[k]) for k, h in enumerate(poses.hands)],
                poses.origins,
            )
            depth = problem.mesh_penetration(moved, within=False)[0].between_mm
            if depth < best_depth:
                best, best_depth = moved, depth
        if best_depth <= settings.tolerance_mm:
            break
    log.info("one hand in front of the other: %.1f mm between them left", best_depth)
    return best


def relax_fingers(problem: Problem, poses: PoseBatch, settings: Finishing = Finishing()) -> PoseBatch:
    """Fingers bent into their own palm or another finger open, each only as far as needed:
    its three bends scaled by the first of ``relax_bends`` that leaves it no deeper than the
    tolerance (a fist's fingers lie in the palm's shadow, so the shadow barely changes). The
    deepest finger first; the test is the exact one within the hand."""
    found = problem.mesh_penetration(poses)[0]
    if max(found.within_mm, default=0.0) <= settings.tolerance_mm:
        return poses
    c = found.contacts
    current = poses
    for h in range(poses.n_hands):
        parts = hand_parts(problem.models[h])
        finger_of = np.full(problem.models[h].num_vertices, -1)
        for f, part in enumerate(parts.fingers):
            finger_of[part.vertices] = f
        own = (c.mesh == h) & (c.other == h) & (c.depth_m * 1000 > settings.tolerance_mm)
        depth_by_finger = {}
        for f, d in zip(finger_of[c.vertex[own]], c.depth_m[own]):
            depth_by_finger[f] = max(d, depth_by_finger.get(f, 0.0))
        for f in sorted(depth_by_finger, key=depth_by_finger.get, reverse=True):
            if f < 0:
                continue
            start = current
            for scale in settings.relax_bends:
                pose = start.hands[h].pose_rad.clone()
                pose[:, 3 * f : 3 * f + 3, 2] *= scale
                hands = list(start.hands)
                hands[h] = HandPoseBatch(pose, *start.hands[h].args()[1:])
                current = PoseBatch(hands, start.origins)
                if _finger_depth_mm(problem, current, h, f, finger_of) <= settings.tolerance_mm:
                    break
    return current


def _finger_depth_mm(problem: Problem, poses: PoseBatch, hand: int, finger: int, finger_of: np.ndarray) -> float:
    """The deepest vertex of one finger inside its own hand's other parts, mm."""
    c = problem.mesh_penetration(poses)[0].contacts
    sel = (c.mesh == hand) & (c.other == hand) & (finger_of[c.vertex] == finger)
    return float(c.depth_m[sel].max(initial=0.0)) * 1000


def polish(
    problem: Problem,
    poses: PoseBatch,
    rounds: int = 2,
    near_rounds: int = 0,
    settings: Finishing = Finishing(),
    patience: int = 1,
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
    near miss (:attr:`ViewScores.near_miss`) and one of the last ``patience`` rounds improved
    it (each round's jitter differs, so a round that brings nothing does not end the hunt
    for the last pixels of a near miss unless ``patience`` is 1). A start that
    already passes is returned as it is unless ``always``. Scores are every view's
    (metrics.ViewScores)."""
    best = poses
    try:
        best_score = problem.scores(poses)[0]
        allowed = max(settings.tolerance_mm, problem.mesh_penetration(poses)[0].deepest_mm)
        generator = generator or torch.Generator(device="cpu").manual_seed(0)
        stale = patience  # rounds since the last improvement (none yet: a near miss must improve first)
        for i in range(rounds + near_rounds):
            if best_score.success and not always:
                break
            if i >= rounds and not (best_score.near_miss and stale < patience):
                break
            previous = best_score
            best_score, best = polish_round(problem, best, best_score, settings, allowed, generator, stop)
            stale = 0 if best_score.key() < previous.key() else stale + 1
    except KeyboardInterrupt:  # between steps, or while scoring the start
        raise Interrupted(best) from None
    return best


def polish_round(
    problem: Problem,
    poses: PoseBatch,
    best_score: ViewScores,
    settings: Finishing,
    allowed_mm: float,
    generator: torch.Generator,
    stop: Callable[[], bool] | None = None,
) -> tuple[ViewScores, PoseBatch]:
    """One round of the polish: (the best score met, its poses), the start's if none beat it.
    A pose wins only if it goes no deeper into other flesh than ``allowed_mm`` and, when the
    start's arms could be held, its arms can be held too."""
    stage = settings.stage(problem.height, settings.steps)
    weights = settings.polish_weights(problem.weights)
    params = PoseParameters(poses.repeat(settings.copies), problem.limits)
    jitter(params, settings.jitter, generator)
    best = {"score": best_score, "key": best_score.key(), "poses": poses}
    keep_holdable = problem.holdable(poses)[0]  # a pose whose arms can be held never gives that up
    far = FarOutline(FAR_EVERY)

    def evaluate():
        terms, shadows = view_objective(problem, params.hands(), stage, weights, far=far)
        return terms.total, shadows

    def look(step, shadows):
        if step % settings.check_every and step != settings.steps:
            return False
        current = params.poses()
        for i, s in enumerate(problem.judge([sh.mask.detach().cpu().numpy() > 0.5 for sh in shadows])):
            if wins(problem, current.item(i), s, best["key"], keep_holdable, allowed_mm):
                best.update(score=s, key=s.key(), poses=current.item(i))
        return False

    try:
        optimise(
            params, evaluate, stage.steps, problem.rates.scaled(stage.lr_scale), observe=look, look_last=True, stop=stop
        )
    except KeyboardInterrupt:
        raise Interrupted(best["poses"]) from None
    return best["score"], best["poses"]


def settle(
    problem: Problem,
    poses: PoseBatch,
    settings: Settle = Settle(),
    stop: Callable[[], bool] | None = None,
) -> PoseBatch:
    """Let the result settle into its shadow: the search's last stage anneals its rate to zero
    within 100 steps, and a shadow a few pixels off all along its outline (a forearm turned a
    degree, a hand a few millimetres too deep) stops moving before it fits. For each of
    ``settings.passes`` (the last stage's weights, then the image term alone, each keeping
    the physical rules), ``settings.steps`` steps at a steady ``settings.lr_scale`` from the
    best so far; the best-scoring pose met on the way wins (metrics.ViewScores.key: a pass
    first, then IoU, thin parts and HD95), if it goes no deeper into other flesh than the
    start (or the tolerance) and keeps arms that could be held. A pass ends early after
    ``settings.patience`` steps without a win."""
    best = poses
    try:
        best_score = problem.scores(poses)[0]
        allowed = max(settings.tolerance_mm, problem.mesh_penetration(poses)[0].deepest_mm)
        keep_holdable = problem.holdable(poses)[0]
        for name in settings.passes:
            stage = Stage(problem.height, 0.0, 0.0, settings.steps, 1, settings.lr_scale, 0.0)
            weights = settings.weights(name, problem.weights)
            params = PoseParameters(best, problem.limits)
            found = {"score": best_score, "key": best_score.key(), "poses": best, "step": 0}

            def evaluate(params=params, stage=stage, weights=weights):
                terms, shadows = view_objective(problem, params.hands(), stage, weights)
                return terms.total, shadows

            def look(step, shadows, params=params, found=found):
                if step % settings.check_every and step != settings.steps:
                    return False
                s = problem.judge([sh.mask.detach().cpu().numpy() > 0.5 for sh in shadows])[0]
                current = params.poses()
                if wins(problem, current, s, found["key"], keep_holdable, allowed):
                    found.update(score=s, key=s.key(), poses=current, step=step)
                return step - found["step"] >= settings.patience  # nothing has won for a while: the pass ends

            try:
                optimise(
                    params,
                    evaluate,
                    stage.steps,
                    problem.rates.scaled(stage.lr_scale),
                    observe=look,
                    look_last=True,
                    stop=stop,
                )
            finally:
                best_score, best = found["score"], found["poses"]
    except KeyboardInterrupt:
        raise Interrupted(best) from None
    return best


def wins(
    problem: Problem, pose: PoseBatch, score: ViewScores, best_key: tuple, keep_holdable: bool, allowed_mm: float
) -> bool:
    """Whether a batch-1 pose met in the polish or the settling replaces the best so far: it
    ranks better (``score``, metrics.ViewScores.key, below ``best_key``), keeps arms that can
    be held when the start's could (``keep_holdable``), and goes no deeper into other flesh
    than ``allowed_mm``. The exact mesh test runs last, only for a pose that would win: it is
    the costly part."""
    if score.key() >= best_key or (keep_holdable and not problem.holdable(pose)[0]):
        return False
    return problem.mesh_penetration(pose)[0].deepest_mm <= allowed_mm


def jitter(
    params: PoseParameters,
    sigmas: tuple[float, float, float],
    generator: torch.Generator,
    rows: slice = slice(1, None),
    joints_only: list[torch.Tensor] | None = None,
) -> None:
    """Add Gaussian noise to the copies ``rows`` (default every copy but the first): sigmas
    for the angle logits, the rotation vector (radians) and the translation (metres).
    joints_only: per hand slot a (15,) bool, the joints that get noise (then the wrist's
    logits get none)."""
    with torch.no_grad():
        for i in range(params.n_hands):
            joints, wrist, rotvec, trans = params.hand_parameters(i)
            for group, sigma in zip(((joints, wrist), (rotvec,), (trans,)), sigmas):
                for p in group:
                    noise = torch.randn(p.shape, generator=generator).to(p) * sigma
                    if joints_only is not None:
                        noise *= joints_only[i].to(p)[None, :, None] if p is joints else 0.0
                    p[rows] += noise[rows]


@torch.no_grad()
def keep_between_light_and_wall(problem: Problem, poses: PoseBatch, margin_m: float = RESULT_MARGIN_M) -> PoseBatch:
    """The placement penalty is soft; if any vertex still comes within margin_m of the wall
    (or of the light's plane), move both hands along the wall normal just enough, so the
    result is physical. With several views, each view in turn (its own wall's normal)."""
    for view in problem.views:
        n = torch.as_tensor(view.scene.wall.normal, dtype=problem.dtype, device=problem.device)
        w0 = torch.as_tensor(view.scene.wall.point, dtype=problem.dtype, device=problem.device)
        heights = torch.cat([((o.vertices - w0) @ n).flatten() for o in problem.pose(poses.hands)])
        lo, hi = view.scene.light_depth_range()
        shift = 0.0
        if float(heights.min()) < lo + margin_m:
            shift = lo + margin_m - float(heights.min())
        elif float(heights.max()) > hi - margin_m:
            shift = hi - margin_m - float(heights.max())
        if shift != 0.0:
            log.info("moved the hands %.1f mm along a wall's normal to keep them off it and its light", shift * 1000)
            poses = PoseBatch([h.moved(shift * n) for h in poses.hands], poses.origins)
    return poses
