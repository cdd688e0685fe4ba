"""What a search works on, fixed while it runs: the target, the scene, the hands with their
joint limits and collision proxies, the weights; and the same scene at the coarser
resolutions of the stages (:class:`Level`).

One pose may answer several views (:class:`View`: its own lamp, wall and target, and a weight).
View 0 is the problem's ``scene`` and ``target``; a search with one view is exactly the
single-view search."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import numpy as np
import torch
from skimage.transform import resize

from handshadow import losses
from handshadow.hands.arms import ArmCheck, arm_checks
from handshadow.hands.limits import JointLimits
from handshadow.hands.model import HandModel, HandOutput
from handshadow.hands.penetration import Penetration, hand_parts, penetration
from handshadow.hands.proxies import PenetrationModel, hand_spheres
from handshadow.losses import TargetMaps
from handshadow.metrics import ViewScores, score, thin_parts
from handshadow.poses import HandPoseBatch, PoseBatch
from handshadow.render import ShadowRenderer
from handshadow.scene import Scene
from handshadow.search.config import LearningRates, Reach, Weights
from handshadow.search.pieces import Partner


@dataclasses.dataclass(frozen=True)
class Level:
    """The search at one resolution: its scene (same frame, fewer pixels), a renderer of the
    hands, the target's maps, and scale = pixels here per full-resolution pixel."""

    scene: Scene
    renderer: ShadowRenderer
    maps: TargetMaps
    scale: float
    # Maps derived from the target that stay constant through a stage (search.objective's
    # image weights per blur and weights), computed once.
    derived: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)


@dataclasses.dataclass(frozen=True)
class ViewTarget:
    """A further view of a search: its full-resolution scene (its own lamp, wall and frame),
    the target (H, W) bool there, and its weight relative to view 0's 1."""

    scene: Scene
    target: np.ndarray
    weight: float = 1.0


class View:
    """One view inside a Problem: scene, target (H, W) bool, weight (the views' weights sum to
    1), the hands' working range in front of its wall, its levels (cached) and thin parts."""

    def __init__(self, scene: Scene, target: np.ndarray, weight: float):
        self.scene = scene
        self.target = np.asarray(target, bool)
        self.weight = weight
        self.placement_range = scene.placement_range()
        self.levels: dict[int, Level] = {}

    @functools.cached_property
    def thin(self) -> np.ndarray:
        """(H, W) bool: the target's thin parts (metrics.thin_parts), computed once."""
        return thin_parts(self.target)


class Problem:
    """The fixed parts of a search.

    Args:
        scene: the full-resolution scene of view 0 (its image size is the output size).
        target: (H, W) bool target frame at the scene's resolution.
        models: one or two HandModels on one device, in hand-slot order (right first).
        limits: per hand slot its JointLimits, on that device.
        weights: the objective's weights.
        anchor: optional PoseBatch of batch 1 the solution should stay near (a morph's other end).
        more_views: further views the same pose must answer (ViewTarget, frames of the same
            size); the views' weights are normalised to sum 1 (one view: weight 1).
        partner: with one hand, the other hand of a two-hand pose held still (search.pieces:
            a target in two pieces, one hand searched at a time); the reach term keeps this
            hand within one person's reach of it.
    """

    def __init__(
        self,
        scene: Scene,
        target: np.ndarray,
        models: list[HandModel],
        limits: list[JointLimits],
        weights: Weights | None = None,
        anchor: PoseBatch | None = None,
        rates: LearningRates = LearningRates(),
        reach: Reach = Reach(),
        more_views: Sequence[ViewTarget] = (),
        partner: Partner | None = None,
    ):
        raw = [1.0, *(float(v.weight) for v in more_views)]
        self.views = [
            View(s, t, w / sum(raw))
            for (s, t), w in zip([(scene, target), *((v.scene, v.target) for v in more_views)], raw)
        ]
        self.models = models
        self.limits = limits
        self.weights = weights or Weights()
        self.anchor = anchor
        self.rates = rates
        self.reach = reach
        self.partner = partner
        self.device = models[0].rest_vertices.device
        self.dtype = models[0].rest_vertices.dtype
        self.penetration = PenetrationModel([hand_spheres(m.rig, m.has_forearm) for m in models], dtype=self.dtype).to(
            self.device
        )
        # Collision proxies are pushed apart along a point light's rays (which keeps its
        # shadow) with one view; with several no direction keeps every shadow.
        self.light_position = (
            torch.as_tensor(scene.light.position, dtype=self.dtype, device=self.device)
            if scene.light.type == "point" and len(self.views) == 1
            else None
        )

    @property
    def n_hands(self) -> int:
        return len(self.models)

    @property
    def scene(self) -> Scene:
        """View 0's full-resolution scene."""
        return self.views[0].scene

    @property
    def target(self) -> np.ndarray:
        """View 0's (H, W) bool target."""
        return self.views[0].target

    @property
    def thin(self) -> np.ndarray:
        """View 0's thin parts (H, W) bool."""
        return self.views[0].thin

    @property
    def placement_range(self) -> tuple[float, float]:
        """View 0's working range in front of its wall (Scene.placement_range), metres."""
        return self.views[0].placement_range

    @property
    def height(self) -> int:
        """Full-resolution frame height, pixels."""
        return self.target.shape[0]

    def level(self, height: int, view: int = 0) -> Level:
        """The search at a frame height in a view (cached)."""
        v = self.views[view]
        if height not in v.levels:
            full_h, full_w = v.target.shape
            width = max(1, round(full_w * height / full_h))
            scene = v.scene.with_size(width, height)
            renderer = ShadowRenderer(scene, [m.faces for m in self.models], [m.num_vertices for m in self.models])
            small = v.target if height == full_h else resize_mask(v.target, height, width)
            maps = TargetMaps.build(small, self.device, self.dtype)
            v.levels[height] = Level(scene, renderer.to(self.device), maps, height / full_h)
        return v.levels[height]

    def pose(self, hands: list[HandPoseBatch]) -> list[HandOutput]:
        """Posed hands, one HandOutput per slot, on the problem's device (hands from any device)."""
        return [model(*h.to(self.device).args()) for model, h in zip(self.models, hands)]

    @torch.no_grad()
    def shadows(self, poses: PoseBatch, height: int | None = None, view: int = 0) -> torch.Tensor:
        """(B, H, W) exact shadows of hypotheses at a frame height (full by default) in a view."""
        renderer = self.level(height or self.height, view).renderer
        return renderer.render([o.vertices for o in self.pose(poses.hands)]).mask

    @torch.no_grad()
    def view_masks(self, poses: PoseBatch, height: int | None = None) -> list[np.ndarray]:
        """Per view, the (B, H, W) bool exact shadows of hypotheses at a frame height (full by
        default), posing the hands once."""
        vertices = [o.vertices for o in self.pose(poses.hands)]
        return [
            self.level(height or self.height, k).renderer.render(vertices).mask.cpu().numpy() > 0.5
            for k in range(len(self.views))
        ]

    def scores(self, poses: PoseBatch, height: int | None = None) -> list[ViewScores]:
        """Per hypothesis, its measures in every view at a frame height (full by default)
        against the target at that height (metrics.ViewScores)."""
        return self.judge(self.view_masks(poses, height), height)

    def judge(self, masks: list[np.ndarray], height: int | None = None) -> list[ViewScores]:
        """Per hypothesis, the measures of shadows given per view as (B, H, W) bool at a frame
        height (full by default) against the targets at that height."""
        height = height or self.height
        targets, thins = [], []
        for k, v in enumerate(self.views):
            full = height == self.height
            targets.append(v.target if full else self.level(height, k).maps.target.cpu().numpy() > 0.5)
            thins.append(v.thin if full else thin_parts(targets[-1]))
        weights = tuple(v.weight for v in self.views)
        return [
            ViewScores(tuple(score(m[i], t, th) for m, t, th in zip(masks, targets, thins)), weights)
            for i in range(len(masks[0]))
        ]

    def proxy_depths(self, hands: list[HandPoseBatch], outs: list[HandOutput], light: bool = True) -> torch.Tensor:
        """(B, P) penetration depths of the collision proxies, metres (see PenetrationModel)."""
        return self.penetration.depths(self._proxy_centres(hands, outs), self.light_position if light else None)

    def proxy_penetration(self, hands: list[HandPoseBatch], outs: list[HandOutput]) -> torch.Tensor:
        """(B,) the penetration term (losses.penetration) of the collision proxies, pushed apart
        along the light's rays: the same as from :meth:`proxy_depths`, summed over the pairs that
        touch only (a few hundred of the B x S x S the dense depths hold)."""
        b, _, _, depth = self.penetration.touching(self._proxy_centres(hands, outs), self.light_position)
        return losses.penetration(depth, item=b, batch=hands[0].batch)

    def _proxy_centres(self, hands: list[HandPoseBatch], outs: list[HandOutput]) -> torch.Tensor:
        return self.penetration.centres(
            [(o.bone_rotations, o.bone_translations) for o in outs], [(h.rotation, h.translation) for h in hands]
        )

    @torch.no_grad()
    def mesh_penetration(self, poses: PoseBatch, within: bool = True) -> list[Penetration]:
        """The exact test on the meshes (hands.penetration), per hypothesis: between the hands
        and (unless not ``within``) within each, every inside vertex listed as a contact (item
        = its hypothesis)."""
        return self.posed_penetration([o.vertices for o in self.pose(poses.hands)], within)

    @torch.no_grad()
    def posed_penetration(self, vertices: list[torch.Tensor], within: bool = True) -> list[Penetration]:
        """:meth:`mesh_penetration` of hands already posed: per hand slot its vertices (B, V, 3)."""
        faces = [m.faces.cpu().numpy() for m in self.models]
        parts = [hand_parts(m) for m in self.models] if within else None
        found = []
        for k in range(vertices[0].shape[0]):
            positions = [v[k].detach().cpu().double().numpy() for v in vertices]
            pen = penetration(positions, faces, parts)
            found.append(dataclasses.replace(pen, contacts=pen.contacts.for_item(k)))
        return found

    @torch.no_grad()
    def arm_checks(self, poses: PoseBatch) -> list[ArmCheck]:
        """Per hypothesis, the arm rules (hands.arms) in every view: a forearm leads back when
        it does so from every view's wall, an elbow is out of the picture when it is out of
        every view's."""
        poses = poses.to(self.device)
        return arm_checks(self.models, poses.hands, [v.scene for v in self.views])

    def holdable(self, poses: PoseBatch) -> list[bool]:
        """Per hypothesis, whether the performers can hold its arms (ArmCheck.holdable)."""
        return [a.holdable(self.reach.performers) for a in self.arm_checks(poses)]

    @torch.no_grad()
    def penetration_mm(self, poses: PoseBatch) -> torch.Tensor:
        """(B,) deepest overlap of any two collision proxies (within or across hands), mm."""
        return self.proxy_depths(poses.hands, self.pose(poses.hands), light=False).amax(1) * 1000


def resize_coverage(mask: np.ndarray, height: int, width: int) -> np.ndarray:
    """(height, width) float coverage of a bool mask at another resolution (area-weighted)."""
    return resize(np.asarray(mask, float), (height, width), order=1, anti_aliasing=True)


def resize_mask(mask: np.ndarray, height: int, width: int) -> np.ndarray:
    """A bool mask at another resolution (area-weighted, thresholded at half)."""
    return resize_coverage(mask, height, width) >= 0.5
