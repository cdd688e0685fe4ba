"""The search's objective: named loss terms of hypotheses at one stage.

    terms, shadow = objective(problem, hands, stage)   # LossTerms of (B,) tensors, Shadow
    terms.total                                       # (B,) what the optimiser minimises
    terms, shadows = view_objective(problem, hands, stage)   # every view's Shadow

The image term is the paper's L2 between the (blurred) shadow and target, weighted toward thin
parts and toward depth inside the target; the others pull the outline and the skeleton toward
what is missing, push back spills and light leaking between fingers, and keep the hands
physical (proxies apart, between lamp and wall, within one person's reach). With several
views (one pose, a lamp and wall per target) each view's image terms count by its weight and
the physical rules hold in every view. Each term's
function is in :mod:`handshadow.losses`; the weights are :class:`~handshadow.search.config.Weights`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from handshadow import losses
from handshadow.hands.arms import BACK_SLACK_M
from handshadow.hands.kinematics import rotmat_to_rotvec
from handshadow.hands.penetration import Contacts, contact_penalty
from handshadow.hands.rig import KEYPOINT_NAMES
from handshadow.metrics import far_regions
from handshadow.poses import HandPoseBatch
from handshadow.render import Shadow, gaussian_blur
from handshadow.scene import Scene
from handshadow.search.config import CONTACT_SIDEWAYS, Stage, Weights
from handshadow.search.problem import Level, Problem

# Finger segments between keypoints (rig.KEYPOINT_NAMES: wrist, then per finger 3 joints + tip).
SEGMENT_STARTS = [1 + 4 * f + k for f in range(5) for k in range(3)]
SEGMENT_ENDS = [2 + 4 * f + k for f in range(5) for k in range(3)]
# The anchor term: this much wrist travel (metres) or turn (radians) from the anchor counts one.
ANCHOR_TRAVEL_M = 0.05
ANCHOR_TURN_RAD = 0.5


@dataclasses.dataclass(frozen=True)
class LossTerms:
    """The objective's terms per hypothesis, each (B,) and already weighted; a term that is
    off at this stage is zero. ``total`` is their sum."""

    image: torch.Tensor  # weighted L2 of the blurred shadow against the blurred target
    excess: torch.Tensor  # shadow outside the target, by its distance
    gaps: torch.Tensor  # light leaking between fingers where the target is solid
    attraction: torch.Tensor  # the outline drawn to missing parts
    inside: torch.Tensor  # joints and forearm axes outside the target
    thin_pull: torch.Tensor  # thin parts far from every finger
    anchor: torch.Tensor  # placement away from the anchor poses
    penetration: torch.Tensor  # collision proxies overlapping
    contacts: torch.Tensor  # vertices inside other flesh, by the exact mesh test (ExactContacts)
    placement: torch.Tensor  # vertices off the working range between wall and lamp
    reach: torch.Tensor  # wrists or elbows farther apart than the performers reach
    arms: torch.Tensor  # forearms that do not lead back toward the performer (and elbows in the picture)

    @property
    def total(self) -> torch.Tensor:
        out = self.image
        for f in dataclasses.fields(self)[1:]:
            out = out + getattr(self, f.name)
        return out

    def values(self, i: int) -> dict[str, float]:
        """Hypothesis i's terms as floats, by name."""
        return {f.name: float(getattr(self, f.name)[i].detach()) for f in dataclasses.fields(self)}


class ExactContacts:
    """The exact mesh contacts (hands.penetration) of a stage's B hypotheses for the
    objective's ``contacts`` term: found afresh every ``every`` evaluations from the posed
    hands and held in between (the term pushes those vertices out along the other surface's
    normal as they move). The test costs about 0.1 s per hypothesis on a CPU core, so it runs
    every few steps rather than every step. every = 0: never (the term is zero)."""

    def __init__(self, problem: Problem, every: int):
        self.problem, self.every, self.calls = problem, every, 0
        self.found: Contacts | None = None

    def __call__(self, outs) -> Contacts | None:
        """The contacts to push out at this evaluation, from the posed hands (HandOutput per
        slot, batch B); None when off."""
        if not self.every:
            return None
        if self.calls % self.every == 0:
            found = self.problem.posed_penetration([o.vertices for o in outs])
            self.found = Contacts.cat([p.contacts for p in found])
        self.calls += 1
        return self.found


class FarOutline:
    """Where a shadow fails the HD95 bar, for the image term's extra weight (Weights.far): the
    wrong regions (shadow XOR target) that touch an outline pixel farther than the bar from the
    other outline (metrics.far_regions: a part missing or added, a notch or hole filled), as
    (B, H, W) 0/1 maps. The HD95 counts outline pixels, so a small region past the bar fails a
    fit that much larger shallow errors would not; the image term alone weighs it by its area.
    Found afresh from the exact masks every ``every`` evaluations per view, at full resolution,
    and held in between (every = 0: never)."""

    def __init__(self, every: int):
        self.every, self.calls = every, {}
        self.maps: dict[int, torch.Tensor | None] = {}

    def __call__(self, view: int, level: Level, mask: torch.Tensor) -> torch.Tensor | None:
        """(B, H, W) regions of the view's masks (B, H, W) at a level, or None (none, or off)."""
        if not self.every or level.scale != 1.0:
            return None
        calls = self.calls.get(view, 0)
        if calls % self.every == 0:
            self.maps[view] = self._find(level, mask.detach())
        self.calls[view] = calls + 1
        return self.maps[view]

    def _find(self, level: Level, mask: torch.Tensor) -> torch.Tensor | None:
        target = level.maps.target.cpu().numpy() > 0.5
        regions = np.stack([far_regions(m, target) for m in mask.cpu().numpy() > 0.5])
        if not regions.any():
            return None
        return torch.as_tensor(regions, dtype=mask.dtype, device=mask.device)


def objective(
    problem: Problem, hands: list[HandPoseBatch], stage: Stage, weights: Weights | None = None
) -> tuple[LossTerms, Shadow]:
    """The loss terms of B hypotheses (one HandPoseBatch per hand slot, differentiable) at a
    stage, and their exact shadow at the stage's resolution in view 0 (every view's:
    :func:`view_objective`)."""
    terms, shadows = view_objective(problem, hands, stage, weights)
    return terms, shadows[0]


def view_objective(
    problem: Problem,
    hands: list[HandPoseBatch],
    stage: Stage,
    weights: Weights | None = None,
    contacts: ExactContacts | None = None,
    far: FarOutline | None = None,
) -> tuple[LossTerms, list[Shadow]]:
    """The loss terms of B hypotheses at a stage over all the problem's views, and their exact
    shadow per view at the stage's resolution. weights: the problem's unless given, with the
    stage's own where it sets them (Stage.weights). The image terms (image, excess, gaps,
    attraction, inside, thin_pull) are each view's weighted by its weight; placement and the
    arms' rules hold in every view (summed); penetration, contacts, reach and the anchor are
    counted once. contacts: the stage's exact mesh contacts (None: that term is zero). far: the
    wrong regions past the HD95 bar that Weights.far weighs (None: that weight is off). With
    one view this is the single-view objective exactly (its terms are built in the same
    order, so even the gradients' rounding is the same)."""
    w = stage.weights(weights or problem.weights)
    outs = problem.pose(hands)
    levels = [problem.level(stage.height, k) for k in range(len(problem.views))]
    views = [_view_image_terms(level, outs, stage, w, far, k) for k, level in enumerate(levels)]
    shadows = [shadow for _, shadow in views]
    zero = shadows[0].mask.new_zeros(shadows[0].mask.shape[0])
    anchor = w.anchor * anchor_distance(hands, problem.anchor.hands) if problem.anchor is not None else zero
    with_forearm, elbows = _elbows(hands, outs)
    reach = _reach_term(problem, hands, elbows, w)
    no_arms = hands[0].translation.new_zeros(hands[0].batch)
    arms = _summed(
        [_arms_term(problem, v.scene, lv, with_forearm, elbows, no_arms, w) for v, lv in zip(problem.views, levels)]
    )
    for (terms, shadow), level in zip(views, levels):
        terms["excess"] = w.excess * losses.excess(shadow.mask, level.maps.outside_dist)
    penetration = w.penetration * problem.proxy_penetration(hands, outs)
    found = contacts(outs) if contacts is not None and w.contacts else None
    contact = zero
    if found is not None and len(found.item):
        vertices = [o.vertices for o in outs]
        contact = w.contacts * contact_penalty(vertices, found, light=problem.light_position, sideways=CONTACT_SIDEWAYS)
    placement = _summed(
        [w.placement * losses.placement(s.heights, *v.placement_range) for s, v in zip(shadows, problem.views)]
    )
    image_terms = {
        name: views[0][0][name]
        if len(views) == 1
        else _summed([v.weight * terms[name] for v, (terms, _) in zip(problem.views, views)])
        for name in IMAGE_TERMS
    }
    terms = LossTerms(
        **image_terms,
        anchor=anchor,
        penetration=penetration,
        contacts=contact,
        placement=placement,
        reach=reach,
        arms=arms,
    )
    return terms, shadows


# The terms each view weighs by its weight (the rest are physical rules or counted once).
IMAGE_TERMS = ("image", "excess", "gaps", "attraction", "inside", "thin_pull")


def _summed(values: list[torch.Tensor]) -> torch.Tensor:
    """The sum of (B,) terms, the first as it is when it is alone."""
    out = values[0]
    for v in values[1:]:
        out = out + v
    return out


def _view_image_terms(
    level: Level, outs, stage: Stage, w: Weights, far: FarOutline | None = None, view: int = 0
) -> tuple[dict[str, torch.Tensor], Shadow]:
    """One view's image terms but the excess (image, gaps, attraction, inside, thin_pull,
    each (B,) and weighted as Weights says, not by the view's weight) and its exact shadow at
    the level's resolution."""
    shadow = level.renderer.render([o.vertices for o in outs])
    mask, maps = shadow.mask, level.maps
    zero = mask.new_zeros(mask.shape[0])
    blur = stage.blur_px * level.scale
    blurred = gaussian_blur(mask, blur)
    target, weight = _image_maps(level, blur, w)
    regions = far(view, level, mask) if far is not None and w.far else None
    if regions is not None:
        weight = weight + w.far * regions
    image = w.l2 * losses.weighted_l2(blurred, target, weight)
    gaps = zero
    if w.gaps and stage.blur_px <= 1:
        gaps = w.gaps * losses.gaps(mask, maps.target, max(1, round(2 * level.scale)))
    attraction = zero
    if w.attraction and stage.attract_px > 0:
        attraction = w.attraction * losses.attraction(mask, maps.target, stage.attract_px * level.scale)
    inside = thin_pull = zero
    if stage.skeleton > 0:
        inside, thin_pull = _skeleton_terms(level, outs)
        inside, thin_pull = stage.skeleton * w.inside * inside, stage.skeleton * w.thin_pull * thin_pull
    return {"image": image, "gaps": gaps, "attraction": attraction, "inside": inside, "thin_pull": thin_pull}, shadow


def _elbows(hands, outs) -> tuple[list, list[torch.Tensor]]:
    """The hands that have forearms as (HandPoseBatch, HandOutput) pairs, and their elbows
    (B, 3) each."""
    with_forearm = [(h, o) for h, o in zip(hands, outs) if o.forearm_points.shape[1]]
    return with_forearm, [o.forearm_points[:, -1] for _, o in with_forearm]


def _reach_term(problem: Problem, hands, elbows: list[torch.Tensor], w: Weights) -> torch.Tensor:
    """Weighted (B,) term (hands.arms): wrists and elbows within the performers' reach (of each
    other, or with one hand of the problem's partner, search.pieces.Partner)."""
    r = problem.reach
    reach = hands[0].translation.new_zeros(hands[0].batch)
    partner = problem.partner if len(hands) == 1 else None
    if len(hands) == 2 or partner is not None:
        other = hands[1].translation if partner is None else partner.wrist.to(hands[0].translation)
        gap = (hands[0].translation - other).norm(dim=-1)
        reach = losses.soft_range(gap, 0.0, r.max_wrist_gap_m, r.margin_m)
        if partner is not None and partner.elbow is not None and elbows:
            elbows = [elbows[0], partner.elbow.to(elbows[0]).expand_as(elbows[0])]
        if len(elbows) == 2:
            span = (elbows[0] - elbows[1]).norm(dim=1)
            reach = reach + losses.soft_range(span, 0.0, r.max_elbow_span_m, r.margin_m)
        reach = w.reach * reach
    return reach


def _arms_term(
    problem: Problem, scene: Scene, level: Level, with_forearm, elbows: list[torch.Tensor], zero, w: Weights
) -> torch.Tensor:
    """Weighted (B,) term (hands.arms) in one view: forearms leading back toward the
    performer (no elbow nearer the view's wall than its wrist), and, when Weights.elbows_out
    is set, every elbow's shadow out of the view's picture. with_forearm, elbows: _elbows();
    zero: (B,) zeros."""
    r = problem.reach
    arms = zero
    if elbows and w.arms:
        normal = torch.as_tensor(scene.wall.normal, dtype=arms.dtype, device=arms.device)
        for (h, _), elbow in zip(with_forearm, elbows):
            toward_wall = ((h.translation - elbow) @ normal) - BACK_SLACK_M  # wrist's height minus elbow's
            arms = arms + w.arms * (torch.relu(toward_wall) / r.margin_m) ** 2
    if elbows and w.elbows_out:
        xy, _ = level.scene.project(torch.stack(elbows, 1))
        height, width = level.scene.image.height, level.scene.image.width
        arms = arms + w.elbows_out * losses.inside_frame(xy, height, width, r.elbow_margin_share * height)
    return arms


def _image_maps(level: Level, blur: float, w: Weights) -> tuple[torch.Tensor, torch.Tensor]:
    """The blurred target (H, W) and the image term's pixel weights (H, W) at a level: 1, plus
    the target's thin parts, plus depth inside it, plus (when set) distance outside it and its
    holes and notches. Constant through a stage, so computed once per level, blur and weights."""
    key = ("image_maps", blur, w.thin, w.depth, w.depth_cap, w.spill, w.notches)
    if key not in level.derived:
        level.derived[key] = _build_image_maps(level.maps, blur, w)
    return level.derived[key]


def _build_image_maps(maps, blur: float, w: Weights) -> tuple[torch.Tensor, torch.Tensor]:
    target = gaussian_blur(maps.target[None], blur)[0]
    weight = (
        1.0
        + w.thin * gaussian_blur(maps.thin[None], max(blur, 1.0))[0]
        + w.depth * maps.inside_depth.clamp(max=w.depth_cap)
    )
    if w.spill:
        weight = weight + w.spill * maps.outside_dist.clamp(max=w.depth_cap)
    if w.notches:
        weight = weight + w.notches * gaussian_blur(maps.notches[None], blur)[0]
    return target, weight


def _skeleton_terms(level: Level, outs) -> tuple[torch.Tensor, torch.Tensor]:
    """Unweighted (B,) terms on the projected skeleton: joints and forearm axes outside the
    target, and the target's thin parts far from every finger segment."""
    kp = torch.cat([torch.cat([o.keypoints, o.forearm_points], 1) for o in outs], 1)
    kp_xy, _ = level.scene.project(kp)
    segments, offset = [], 0
    for o in outs:
        k = kp_xy[:, offset : offset + len(KEYPOINT_NAMES)]
        segments.append(torch.stack([k[:, SEGMENT_STARTS], k[:, SEGMENT_ENDS]], 2))
        offset += o.keypoints.shape[1] + o.forearm_points.shape[1]
    return losses.points_outside(kp_xy, level.maps), losses.thin_coverage(torch.cat(segments, 1), level.maps)


def anchor_distance(hands: list[HandPoseBatch], anchor: list[HandPoseBatch]) -> torch.Tensor:
    """(B,) squared distance of each hand's placement from the anchor's (batch 1): wrist
    travel in units of ANCHOR_TRAVEL_M plus turn in units of ANCHOR_TURN_RAD."""
    out = 0
    for h, a in zip(hands, anchor):
        out = out + (((h.translation - a.translation) / ANCHOR_TRAVEL_M) ** 2).sum(1)
        out = out + (rotmat_to_rotvec(a.rotation.transpose(-1, -2) @ h.rotation).norm(dim=1) / ANCHOR_TURN_RAD) ** 2
    return out
