"""The search's numbers, each with a name: stages, loss weights, learning rates, the finishing
steps. Frozen dataclasses; change one with ``dataclasses.replace``."""

from __future__ import annotations

import dataclasses

from handshadow.hands.arms import ELBOW_SPAN_M
from handshadow.hands.penetration import TOLERANCE_MM
from handshadow.metrics import NEAR_MISS_HD95

# A push between the two hands keeps this share of its gradient across the light's rays: a
# hand moved along its rays keeps its shadow (hands.proxies.SIDEWAYS does the same for spheres).
CONTACT_SIDEWAYS = 0.25


@dataclasses.dataclass(frozen=True)
class Stage:
    """One coarse-to-fine stage of the search.

    height: frame height in pixels at this stage; blur_px: Gaussian blur of shadow and target,
    in full-resolution pixels (0: the exact shadow); attract_px: reach of the pull toward
    missing parts, full-resolution pixels (0: off); steps: Adam steps; keep: hypotheses that
    survive the stage; lr_scale: factor on the learning rates; skeleton: weight factor of the
    skeleton terms (long-range guides: joints inside the target, fingers to thin parts);
    contacts_every: how often the exact mesh test (hands.penetration) finds the vertices
    inside other flesh for the objective's contacts term (0: the term is off); thin, spill,
    notches, far: the image term's extra weights on the target's thin parts, outside it, on its
    holes and notches and on the wrong regions past the HD95 bar at this stage (None: the
    Weights' own); layer: after
    the stage, each kept hypothesis whose hands pass through each other has one put in front
    of the other along the light's rays, so the stages after it fit the shadow with the hands
    apart instead of the separation pushing them apart at the end (one view only)."""

    height: int
    blur_px: float
    attract_px: float
    steps: int
    keep: int
    lr_scale: float = 1.0
    skeleton: float = 1.0
    contacts_every: int = 0  # find the exact mesh contacts afresh every this many steps (0: off)
    layer: bool = False  # after the stage, hands inside each other pass one in front (finishing.pass_in_front)
    thin: float | None = None  # Weights.thin at this stage (None: as the weights say)
    spill: float | None = None  # Weights.spill at this stage (None: as the weights say)
    notches: float | None = None  # Weights.notches at this stage (None: as the weights say)
    far: float | None = None  # Weights.far at this stage (None: as the weights say)

    def weights(self, w: Weights) -> Weights:
        """The weights this stage optimises with: w, with the stage's thin, spill, notches and
        far weights where set."""
        changes = {k: getattr(self, k) for k in ("thin", "spill", "notches", "far") if getattr(self, k) is not None}
        return dataclasses.replace(w, **changes) if changes else w


# The exact-outline stages (fit.schedule) and the settling weigh thin parts this much (twice
# Weights.thin; docs/measured.md, **Outline stages**).
OUTLINE_THIN = 8.0

# The image term's extra weight on the error regions past the HD95 bar (objective.FarOutline)
# is found afresh every this many steps at full resolution (stages, polish).
FAR_EVERY = 10


@dataclasses.dataclass(frozen=True)
class Weights:
    """Weights of the objective's terms (see search.objective)."""

    l2: float = 1.0
    thin: float = 4.0  # extra weight of the target's thin parts in the image term
    depth: float = 20.0  # extra weight per frame height of depth inside the target (holes cost more)
    depth_cap: float = 0.05  # frame heights: depth (and spill distance) beyond this weighs no more
    spill: float = 0.0  # the same outside the target, per frame height of distance (exact stages, polish)
    notches: float = 0.0  # extra weight of the target's holes and narrow notches (exact stages, polish)
    excess: float = 2.0
    attraction: float = 0.3
    penetration: float = 0.02
    contacts: float = 0.002  # vertices inside other flesh by the exact mesh test (stages with contacts_every)
    placement: float = 0.05
    reach: float = 0.05  # wrists and elbows within one person's reach (Reach)
    arms: float = 0.5  # forearms lead back: elbow no nearer the wall than its wrist (per Reach.margin_m, squared)
    elbows_out: float = (
        0.0  # elbows' shadows out of the picture, per squared frame height (off: see docs/performing.md)
    )
    inside: float = 3.0  # joints and forearm axes project into the target
    thin_pull: float = 3.0  # fingers reach the target's thin parts
    anchor: float = 0.002  # closeness to anchor poses, when the search has some
    gaps: float = 4.0  # light leaking between fingers where the target is solid (fine stages)
    far: float = 0.0  # extra image weight of the error regions past the HD95 bar (full resolution; FarOutline)


@dataclasses.dataclass(frozen=True)
class LearningRates:
    """Adam's learning rates per parameter group, before a stage's lr_scale."""

    angles: float = 0.08  # joint and wrist logits
    rotation: float = 0.02  # rotation vector, radians
    translation: float = 0.003  # metres

    def scaled(self, factor: float) -> LearningRates:
        return LearningRates(self.angles * factor, self.rotation * factor, self.translation * factor)


@dataclasses.dataclass(frozen=True)
class Reach:
    """What the performers' arms allow (docs/performing.md): the two wrists at most
    ``max_wrist_gap_m`` apart and the two elbows at most ``max_elbow_span_m`` (one person:
    shoulder breadth and two upper arms), each with a soft margin of ``margin_m``; when the
    elbows are kept out of the picture (Weights.elbows_out), by ``elbow_margin_share`` of the
    frame height. Two performers have no span limits."""

    performers: int = 1
    max_wrist_gap_m: float = 0.45
    max_elbow_span_m: float = ELBOW_SPAN_M
    margin_m: float = 0.05
    elbow_margin_share: float = 0.02

    def for_performers(self, n: int) -> Reach:
        inf = float("inf")
        return dataclasses.replace(self, performers=n) if n == 1 else Reach(n, inf, inf, self.margin_m)


@dataclasses.dataclass(frozen=True)
class Finishing:
    """The finishing steps after the search: separation and polish.

    The separation runs until the exact mesh test passes (no vertex more than
    ``tolerance_mm`` inside other flesh, hands.penetration): first one hand passes in front of
    the other along the light's rays (the smallest of ``pass_in_front_mm`` that parts them),
    fingers bent into their own hand open (their bends scaled by the first of ``relax_bends``
    that frees them), then rounds of ``separation_steps`` small steps of the joint and wrist
    angles pushing the contacts out, with the contacts found afresh each round, at most
    ``separation_rounds`` rounds. Both the separation and the polish step at ``lr_scale``.
    The polish runs ``copies`` copies of the result (all but the first jittered by
    ``jitter`` sigmas: joint logits, rotation vector in radians, translation in metres) for
    ``steps`` steps, scoring every ``check_every``, with the gaps weight times
    ``polish_gaps``, the notches and spill weights set, the wrong regions past the HD95 bar
    weighed by ``polish_far`` (objective.FarOutline) and the penetration weight times
    ``polish_penetration``."""

    tolerance_mm: float = TOLERANCE_MM
    pass_in_front_mm: tuple[float, ...] = (5, 10, 15, 20, 30, 40, 55, 70, 90)
    relax_bends: tuple[float, ...] = (0.95, 0.9, 0.85, 0.8, 0.75, 0.7, 0.65, 0.6, 0.5, 0.4)
    separation_rounds: int = 12
    separation_steps: int = 10
    lr_scale: float = 0.15
    steps: int = 60
    copies: int = 4
    check_every: int = 4
    polish_gaps: float = 10.0
    polish_notches: float = 4.0
    polish_spill: float = 20.0
    polish_penetration: float = 100.0
    # The wrong regions past the HD95 bar weigh this much more in the polish's image term
    # (objective.FarOutline). The polish runs only on a result that fails; on 15 HSP targets
    # it turned 5 first-attempt near misses into passes (docs/measured.md, **Far regions**).
    polish_far: float = 6.0
    jitter: tuple[float, float, float] = (0.15, 0.01, 0.002)

    def polish_weights(self, w: Weights) -> Weights:
        return dataclasses.replace(
            w,
            gaps=w.gaps * self.polish_gaps,
            notches=self.polish_notches,
            spill=self.polish_spill,
            penetration=w.penetration * self.polish_penetration,
            far=self.polish_far,
        )

    def stage(self, height: int, steps: int) -> Stage:
        """Small exact-shadow steps at full resolution, without the skeleton guides."""
        return Stage(height=height, blur_px=0, attract_px=0, steps=steps, keep=1, lr_scale=self.lr_scale, skeleton=0.0)


@dataclasses.dataclass(frozen=True)
class Settle:
    """The settling after the polish (finishing.settle): for each of ``passes`` (weights by
    name: "outline", the exact-outline stages' thin, spill and notches weights; "area", the
    image term alone, L2 against the target), ``steps`` steps at a steady ``lr_scale``, the
    pose scored every ``check_every`` steps; a pose wins only if it goes no deeper into other
    flesh than the start or ``tolerance_mm``. A pass ends early once ``patience`` steps have
    gone by without a win (since its start or its last win). Every pass keeps the physical
    rules (proxies apart, placement, reach, arms)."""

    passes: tuple[str, ...] = ("outline", "area")
    steps: int = 300
    lr_scale: float = 0.3
    check_every: int = 5
    # Half a pass without a win ends it. On 13 HSP first-attempt passes that took the settling
    # from 600 steps to a mean of 376, and the same pose won in all 13 (docs/measured.md,
    # **Settling that stops when nothing wins**).
    patience: int = 150
    tolerance_mm: float = TOLERANCE_MM
    outline_thin: float = OUTLINE_THIN
    outline_spill: float = Finishing.polish_spill
    outline_notches: float = Finishing.polish_notches

    def weights(self, name: str, w: Weights) -> Weights:
        if name == "outline":
            return dataclasses.replace(
                w, thin=self.outline_thin, spill=self.outline_spill, notches=self.outline_notches
            )
        if name == "area":
            return dataclasses.replace(
                w, thin=0.0, depth=0.0, excess=0.0, attraction=0.0, inside=0.0, thin_pull=0.0, gaps=0.0, far=0.0
            )
        raise ValueError(f"unknown settling pass {name!r}")


@dataclasses.dataclass(frozen=True)
class Hops:
    """A hop from a close miss (search.hops): ``copies`` copies of it, all but the first
    jittered by ``jitter`` sigmas (joint logits, rotation vector in radians, translation in
    metres: three to five times the polish's, enough to leave its basin, little enough to keep
    its shape; the last ``focused`` of them jittered only in the joints of the fingers within
    ``focus_share`` of the frame height of the outline pixels beyond the HD95 bar
    (search.hops.focused_joints), by ``focus_jitter`` logits, the rest of the pose as it is),
    go through the search's last ``stages`` stages again. A result hops while it
    fails with IoU met, thin-part recall at most ``reach_thin`` short of its bar and HD95 at
    most ``reach_hd95`` past its bar: three times the polish's near miss
    (metrics.NEAR_MISS_HD95), an outline at most twice as far off as the bar allows. On 31 HSP targets that failed with HD95 beyond 0.04, reaching 0.03
    rather than 0.01 passed 3 more (docs/measured.md, Hops)."""

    copies: int = 8
    jitter: tuple[float, float, float] = (0.5, 0.05, 0.01)
    stages: int = 2
    reach_hd95: float = 3 * NEAR_MISS_HD95
    reach_thin: float = 0.05  # and thin-part recall at most this short of its bar (0.6)
    focused: int = 3  # of the copies, this many jitter only the fingers near the failing outline
    focus_jitter: float = 1.0  # their joints' jitter, logits
    focus_share: float = 0.05  # a finger within this share of the frame height of it is near
    # The last far_hops hops weigh the wrong regions past the HD95 bar as much more in their
    # stages as the polish does (Stage.far, objective.FarOutline); the hops before them do not,
    # so the plain hops' passes stay (docs/measured.md, **A far hop**).
    far: float = Finishing.polish_far
    far_hops: int = 1


@dataclasses.dataclass(frozen=True)
class GiveUp:
    """When an attempt stops early for a fresh one (fit.fit_frame; never its last): after the
    search's stage ``after_stage`` (0 first), no surviving hypothesis, measured at full
    resolution in every view, is within reach: an IoU at most ``iou_margin`` short of the
    success test's bar and an HD95 at most ``hd95_margin`` past its bar, and not short of both
    (an IoU under the bar with an HD95 more than ``hd95_margin_short`` past its bar). Thin parts
    are not counted: a finger still moves onto a thin part late. On the 95 HSP first attempts
    (seed 0) the default, after the 128 px stage, stops 14 of the 40 that fail and none of the
    55 that pass. Of those passes there, one (a thin snake) had IoU 0.778 at best, with HD95
    0.027; the others had IoU 0.82 or more, and one HD95 0.060 at best (docs/measured.md, **Giving up**)."""

    after_stage: int = 1
    iou_margin: float = 0.03
    hd95_margin: float = 0.04
    hd95_margin_short: float = 0.02
