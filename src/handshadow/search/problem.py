"""What a search works on, fixed while it runs: the target, the scene, the hands with their
joint limits and collision proxies, the weights; and the same scene at the coarser
resolutions of the stages (:class:`Level`)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import torch
from skimage.transform import resize

from handshadow.hands.limits import JointLimits
from handshadow.hands.model import HandModel, HandOutput
from handshadow.hands.penetration import Penetration, hand_parts, penetration
from handshadow.hands.proxies import PenetrationModel, hand_spheres
from handshadow.losses import TargetMaps
from handshadow.metrics import thin_parts
from handshadow.poses import HandPoseBatch, PoseBatch
from handshadow.render import ShadowRenderer
from handshadow.scene import Scene
from handshadow.search.config import LearningRates, Reach, Weights


@dataclasses.dataclass(frozen=True)
class Level:
    """The search at one resolution: its scene (same frame, fewer pixels), a renderer of the
    hands, the target's maps, and scale = pixels here per full-resolution pixel."""

    scene: Scene
    renderer: ShadowRenderer
    maps: TargetMaps
    scale: float


class Problem:
    """The fixed parts of a search.

    Args:
        scene: the full-resolution scene (its image size is the output size).
        target: (H, W) bool target frame at the scene's resolution.
        models: one or two HandModels on one device, in hand-slot order (right first).
        limits: per hand slot its JointLimits, on that device.
        weights: the objective's weights.
        anchor: optional PoseBatch of batch 1 the solution should stay near (a morph's other end).
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
    ):
        self.scene = scene
        self.target = np.asarray(target, bool)
        self.models = models
        self.limits = limits
        self.weights = weights or Weights()
        self.anchor = anchor
        self.rates = rates
        self.reach = reach
        self.device = models[0].rest_vertices.device
        self.dtype = models[0].rest_vertices.dtype
        self.penetration = PenetrationModel([hand_spheres(m.rig, m.has_forearm) for m in models], dtype=self.dtype).to(
            self.device
        )
        self.light_position = (
            torch.as_tensor(scene.light.position, dtype=self.dtype, device=self.device)
            if scene.light.type == "point"
            else None
        )
        self.placement_range = scene.placement_range()
        self._levels: dict[int, Level] = {}

    @property
    def n_hands(self) -> int:
        return len(self.models)

    @property
    def height(self) -> int:
        """Full-resolution frame height, pixels."""
        return self.target.shape[0]

    @functools.cached_property
    def thin(self) -> np.ndarray:
        """(H, W) bool: the target's thin parts (metrics.thin_parts), computed once."""
        return thin_parts(self.target)

    def level(self, height: int) -> Level:
        """The search at a frame height (cached)."""
        if height not in self._levels:
            full_h, full_w = self.target.shape
            width = max(1, round(full_w * height / full_h))
            scene = self.scene.with_size(width, height)
            renderer = ShadowRenderer(scene, [m.faces for m in self.models], [m.num_vertices for m in self.models])
            small = self.target if height == full_h else resize_mask(self.target, height, width)
            maps = TargetMaps.build(small, self.device, self.dtype)
            self._levels[height] = Level(scene, renderer.to(self.device), maps, height / full_h)
        return self._levels[height]

    def pose(self, hands: list[HandPoseBatch]) -> list[HandOutput]:
        """Posed hands, one HandOutput per slot."""
        return [model(*h.args()) for model, h in zip(self.models, hands)]

    @torch.no_grad()
    def shadows(self, poses: PoseBatch, height: int | None = None) -> torch.Tensor:
        """(B, H, W) exact shadows of hypotheses at a frame height (full by default)."""
        renderer = self.level(height or self.height).renderer
        return renderer.render([o.vertices for o in self.pose(poses.hands)]).mask

    def proxy_depths(self, hands: list[HandPoseBatch], outs: list[HandOutput], light: bool = True) -> torch.Tensor:
        """(B, P) penetration depths of the collision proxies, metres (see PenetrationModel)."""
        centres = self.penetration.centres(
            [(o.bone_rotations, o.bone_translations) for o in outs], [(h.rotation, h.translation) for h in hands]
        )
        return self.penetration.depths(centres, self.light_position if light else None)

    @torch.no_grad()
    def mesh_penetration(self, poses: PoseBatch, within: bool = True) -> list[Penetration]:
        """The exact test on the meshes (hands.penetration), per hypothesis: between the hands
        and (unless not ``within``) within each, every inside vertex listed as a contact (item
        = its hypothesis)."""
        outs = self.pose(poses.hands)
        faces = [m.faces.cpu().numpy() for m in self.models]
        parts = [hand_parts(m) for m in self.models] if within else None
        found = []
        for k in range(poses.batch):
            positions = [o.vertices[k].detach().cpu().double().numpy() for o in outs]
            pen = penetration(positions, faces, parts)
            found.append(dataclasses.replace(pen, contacts=pen.contacts.for_item(k)))
        return found

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
