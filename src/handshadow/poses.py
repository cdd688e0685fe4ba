"""One vocabulary for poses. Four types, from a person's file to the optimiser's parameters:

    HandPose         one hand's pose as people read it: side, model, shape, joint angles in
                     degrees, rotation, wrist position (numpy, float64)
    PosedScene       a result with its scene: one or two HandPoses, the scene, whether the
                     hands have forearms, and the fit's measures (what pose.json holds)
    HandPoseBatch    B poses of one hand as tensors, radians: HandModel.forward's arguments
    PoseBatch        B hypotheses of one or two hands: a HandPoseBatch per hand slot (right
                     first when there are two) and, for search starts, where each came from
    PoseParameters   the optimiser's parameters for a PoseBatch: joint angles inside their
                     limits by construction, rotations and translations free

Conversions: :meth:`HandPoseBatch.from_hand_poses` and :meth:`HandPoseBatch.to_hand_poses`
are the only bridge between the file form and tensors. Reading and checking pose files is
:mod:`handshadow.posefile`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np

from handshadow.scene import Scene, views_to_json

if TYPE_CHECKING:
    import torch

    from handshadow.hands.limits import JointLimits

FORMAT = "handshadow.pose/1"


# -- the file form ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class HandPose:
    """One posed hand. pose_deg (15, 3) twist/spread/bend degrees; rotation (3, 3) hand frame
    -> world; translation (3,) wrist position, metres; wrist_deg (2,) flexion and deviation,
    degrees."""

    side: str
    model: str
    shape: dict
    pose_deg: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    wrist_deg: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(2))

    def to_json(self) -> dict:
        return {
            "side": self.side,
            "model": self.model,
            "shape": self.shape,
            "pose_deg": np.round(np.asarray(self.pose_deg, float), 4).tolist(),
            "wrist_deg": np.round(np.asarray(self.wrist_deg, float), 4).tolist(),
            "rotation": np.round(np.asarray(self.rotation, float), 9).tolist(),
            "translation": np.round(np.asarray(self.translation, float), 9).tolist(),
        }


@dataclasses.dataclass(frozen=True)
class PosedScene:
    """A result with its scene: what a pose file holds. ``scene`` is view 0's lamp, wall and
    frame; ``more_views`` those of further views (one pose casting a shadow per view), which
    the file holds as a list of views under "scene"."""

    hands: tuple[HandPose, ...]
    scene: Scene
    forearm: bool = True
    fit: dict | None = None
    more_views: tuple[Scene, ...] = ()

    @property
    def views(self) -> list[Scene]:
        """Every view's scene, view 0 first."""
        return [self.scene, *self.more_views]

    def to_json(self) -> dict:
        out = {
            "format": FORMAT,
            "scene": views_to_json(self.views),
            "forearm": self.forearm,
            "hands": [h.to_json() for h in self.hands],
        }
        if self.fit is not None:
            out["fit"] = self.fit
        return out


# -- tensors -----------------------------------------------------------------------------------
@dataclasses.dataclass
class HandPoseBatch:
    """B poses of one hand: pose_rad (B, 15, 3) twist/spread/bend, rotation (B, 3, 3),
    translation (B, 3) metres, wrist_rad (B, 2) flexion and deviation. The arguments of
    :meth:`HandModel.forward <handshadow.hands.model.HandModel.forward>`, in order."""

    pose_rad: torch.Tensor
    rotation: torch.Tensor
    translation: torch.Tensor
    wrist_rad: torch.Tensor

    @property
    def batch(self) -> int:
        return self.pose_rad.shape[0]

    def args(self) -> tuple[torch.Tensor, ...]:
        """HandModel.forward's arguments."""
        return self.pose_rad, self.rotation, self.translation, self.wrist_rad

    def select(self, idx) -> HandPoseBatch:
        return HandPoseBatch(*(t[idx] for t in self.args()))

    def to(self, device=None, dtype=None) -> HandPoseBatch:
        return HandPoseBatch(*(t.to(device=device, dtype=dtype) for t in self.args()))

    def detach(self) -> HandPoseBatch:
        return HandPoseBatch(*(t.detach().clone() for t in self.args()))

    def moved(self, shift) -> HandPoseBatch:
        """The same poses with every wrist moved by shift ((3,) or (B, 3) metres)."""
        return HandPoseBatch(self.pose_rad, self.rotation, self.translation + shift, self.wrist_rad)

    @staticmethod
    def cat(items: Sequence[HandPoseBatch]) -> HandPoseBatch:
        import torch

        return HandPoseBatch(*(torch.cat(ts) for ts in zip(*(i.args() for i in items))))

    @staticmethod
    def from_hand_poses(hands: Sequence[HandPose], dtype=None, device="cpu") -> HandPoseBatch:
        """Stack file poses of one hand into a batch (float32 unless dtype)."""
        import torch

        t = dict(dtype=dtype or torch.float32, device=device)
        return HandPoseBatch(
            torch.as_tensor(np.radians(np.stack([h.pose_deg for h in hands])), **t),
            torch.as_tensor(np.stack([h.rotation for h in hands]), **t),
            torch.as_tensor(np.stack([h.translation for h in hands]), **t),
            torch.as_tensor(np.radians(np.stack([h.wrist_deg for h in hands])), **t),
        )

    def to_hand_poses(self, side: str, model: str, shape: dict | None = None) -> list[HandPose]:
        """One file pose per batch item (float64 numpy, degrees)."""
        arrays = [t.detach().cpu().double().numpy() for t in self.args()]
        return [
            HandPose(
                side=side,
                model=model,
                shape=dict(shape or {}),
                pose_deg=np.degrees(arrays[0][k]),
                rotation=arrays[1][k],
                translation=arrays[2][k],
                wrist_deg=np.degrees(arrays[3][k]),
            )
            for k in range(self.batch)
        ]


@dataclasses.dataclass(frozen=True)
class Origin:
    """Where a search start came from: a library pose (by name, maybe mirrored), a random
    hand, an atlas entry (by number; two hands: 'first+second'), a start the caller gave
    (e.g. a morph's other end), or one hypothesis's right hand with another's left
    (search.crossover; name: theirs joined by ' + '); ``aligned`` when it was moved onto the
    target by the 2D alignment."""

    kind: Literal["library", "random", "given", "atlas", "crossed"]
    name: str = ""
    mirrored: bool = False
    aligned: bool = False

    def __str__(self) -> str:
        text = self.kind + (f" {self.name}" if self.name else "") + (" mirrored" if self.mirrored else "")
        return text + (" aligned" if self.aligned else "")


@dataclasses.dataclass
class PoseBatch:
    """B hypotheses of one or two hands: hands[k] is hand slot k's HandPoseBatch (right first
    when there are two); origins, when known, says where each hypothesis came from."""

    hands: list[HandPoseBatch]
    origins: list[Origin] | None = None

    @property
    def batch(self) -> int:
        return self.hands[0].batch

    @property
    def n_hands(self) -> int:
        return len(self.hands)

    def select(self, idx) -> PoseBatch:
        """Hypotheses at idx (a slice, or a sequence or tensor of indices)."""
        import torch

        if isinstance(idx, slice):
            origins = self.origins[idx] if self.origins is not None else None
            return PoseBatch([h.select(idx) for h in self.hands], origins)
        index = torch.as_tensor(idx, dtype=torch.long, device=self.hands[0].pose_rad.device).reshape(-1)
        origins = [self.origins[int(i)] for i in index] if self.origins is not None else None
        return PoseBatch([h.select(index) for h in self.hands], origins)

    def item(self, i: int) -> PoseBatch:
        """Hypothesis i as a batch of one."""
        return self.select(slice(i, i + 1))

    def to(self, device=None, dtype=None) -> PoseBatch:
        return PoseBatch([h.to(device, dtype) for h in self.hands], self.origins)

    def detach(self) -> PoseBatch:
        return PoseBatch([h.detach() for h in self.hands], self.origins)

    def repeat(self, n: int) -> PoseBatch:
        """n copies of hypothesis 0."""
        return self.select([0] * n)

    def with_origins(self, origins: list[Origin]) -> PoseBatch:
        return PoseBatch(self.hands, list(origins))

    @staticmethod
    def cat(items: Sequence[PoseBatch]) -> PoseBatch:
        hands = [HandPoseBatch.cat([b.hands[k] for b in items]) for k in range(items[0].n_hands)]
        known = all(b.origins is not None for b in items)
        return PoseBatch(hands, [o for b in items for o in b.origins] if known else None)


# -- the optimiser's parameters ------------------------------------------------------------------
# A start whose joint sits within this share of its range from a limit gets the slope of a
# start at that share: the sigmoid is not flat there, so the joint can still leave the limit.
START_SLOPE_SHARE = 0.02


class PoseParameters:
    """Optimisable parameters of a PoseBatch: per hand slot, joint and wrist angles inside
    their limits by construction, a rotation vector applied in world axes on top of the
    starting rotation, and the translation in metres.

    An angle v with limits [lo, hi] reads v = g(sigmoid(z)). For a start inside the band of
    [2 %, 98 %] of its range (START_SLOPE_SHARE) g is the usual lo + (hi - lo) s, z starting at
    the start's logit. A start nearer a limit (at it, say) starts z at the band edge's logit
    s0 and reads v = v0 + (hi - lo) (s - s0), held within [lo, hi]: the start v0 comes back
    exactly, and the joint has the full slope both ways. The hold passes its gradient through,
    so a joint pushed against its limit can always come back (a flat piece would leave it
    there for good: Adam never moves a parameter whose gradient is exactly zero). So building
    parameters from a pose and reading them back returns the pose unchanged, at its limits too.

    Args:
        start: the PoseBatch to start from.
        limits: per hand slot its JointLimits (on the start's device).
    """

    def __init__(self, start: PoseBatch, limits: Sequence[JointLimits]):
        import torch

        self.n_hands = start.n_hands
        self._angles: list[list[tuple]] = []  # per hand, joints and wrist: (z, lo, hi, v0, s0, inside band)
        self.rotvecs, self.translations, self._rot0 = [], [], []
        for hand, lim in zip(start.hands, limits):
            groups = []
            for value, bounds in ((hand.pose_rad, lim.joints), (hand.wrist_rad, lim.wrist)):
                lo, hi = bounds[..., 0].expand_as(value), bounds[..., 1].expand_as(value)
                v0 = torch.minimum(torch.maximum(value.detach(), lo), hi)
                share = (v0 - lo) / (hi - lo).clamp(min=1e-9)
                s0 = share.clamp(START_SLOPE_SHARE, 1 - START_SLOPE_SHARE)
                z = torch.nn.Parameter(torch.log(s0 / (1 - s0)))
                groups.append((z, lo, hi, v0, torch.sigmoid(z.detach()), share == s0))
            self._angles.append(groups)
            self._rot0.append(hand.rotation.detach().clone())
            self.rotvecs.append(torch.nn.Parameter(torch.zeros_like(hand.translation.detach())))
            self.translations.append(torch.nn.Parameter(hand.translation.detach().clone()))

    @property
    def batch(self) -> int:
        return self.translations[0].shape[0]

    @staticmethod
    def _angle(z, lo, hi, v0, s0, inside_band):
        """The angles of logits z; s0 = sigmoid of z's start (so that the start reads v0 exactly)."""
        import torch

        s = torch.sigmoid(z)
        # Inside the band g is lo + (hi - lo) s, computed as such; the hold only catches rounding.
        raw = torch.where(inside_band, lo + (hi - lo) * s, v0 + (hi - lo) * (s - s0))
        held = torch.minimum(torch.maximum(raw, lo), hi)
        return held.detach() + (raw - raw.detach())  # exactly the held value; the gradient is raw's

    def hand(self, i: int) -> HandPoseBatch:
        """Hand slot i's current poses (differentiable)."""
        from handshadow.hands.kinematics import rotvec_to_rotmat

        joints, wrist = (self._angle(*g) for g in self._angles[i])
        rotation = rotvec_to_rotmat(self.rotvecs[i]) @ self._rot0[i]
        return HandPoseBatch(joints, rotation, self.translations[i], wrist)

    def hands(self) -> list[HandPoseBatch]:
        """Every hand slot's current poses (differentiable)."""
        return [self.hand(i) for i in range(self.n_hands)]

    def poses(self) -> PoseBatch:
        """Current values as a PoseBatch, detached."""
        import torch

        with torch.no_grad():
            return PoseBatch([self.hand(i).detach() for i in range(self.n_hands)])

    def parameters(self) -> list[torch.Tensor]:
        return [p for i in range(self.n_hands) for p in self.hand_parameters(i)]

    def hand_parameters(self, i: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(joint logits, wrist logits, rotation vector, translation) of hand slot i."""
        return self._angles[i][0][0], self._angles[i][1][0], self.rotvecs[i], self.translations[i]

    def param_groups(self, rates, angles_only: bool = False) -> list[dict]:
        """Adam groups per hand: angles, rotation, translation, at ``rates``
        (search.config.LearningRates, already scaled); only the angles when ``angles_only``
        (the hands' placement stays)."""
        groups = []
        for i in range(self.n_hands):
            joints, wrist, rotvec, trans = self.hand_parameters(i)
            groups.append({"params": [joints, wrist], "lr": rates.angles})
            if not angles_only:
                groups += [{"params": [rotvec], "lr": rates.rotation}, {"params": [trans], "lr": rates.translation}]
        return groups
