"""Arms one person can hold: where the elbows are, and the rules they keep (docs/performing.md).

The performer stands between the lamp and the wall, on the lamp's side of their hands, so each
forearm leads back from the wrist toward them: its elbow is no nearer the wall than its wrist
(within BACK_SLACK_M). One person reaches with both arms from one body: the elbows are at most
ELBOW_SPAN_M apart (shoulder breadth, about 0.40 m, plus two upper arms of about 0.33 m each,
arms spread wide; adult anthropometry, rounded down for comfort). The model ends at the elbow:
where an elbow's shadow falls inside the picture, the upper arm beyond it would show too, which
is reported.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import torch

ELBOW_SPAN_M = 1.0
BACK_SLACK_M = 0.02


@dataclasses.dataclass(frozen=True)
class ArmCheck:
    """leads_back: per hand, whether its forearm leads back toward the performer (the elbow no
    nearer the wall than the wrist, within BACK_SLACK_M); elbows_out: per hand, whether its
    elbow's shadow lies outside the picture; span_m: the distance between the two elbows (0
    with one hand); performers: how many people the pose needs (1, or 2 when the elbows are
    farther apart than one person's arms reach)."""

    leads_back: tuple[bool, ...]
    elbows_out: tuple[bool, ...]
    span_m: float
    performers: int

    @property
    def upper_arms_hidden(self) -> bool:
        return all(self.elbows_out)

    def holdable(self, performers: int = 1) -> bool:
        """Forearms lead back, and the arms are within the performers' reach."""
        return all(self.leads_back) and self.performers <= performers


def check_arms(
    elbows_xy: np.ndarray,
    elbows: np.ndarray,
    elbow_heights: np.ndarray,
    wrist_heights: np.ndarray,
    height: int,
    width: int,
) -> ArmCheck:
    """The rules for one pose of n hands: elbows_xy (n, 2) the elbows' shadows in pixels of a
    height x width frame, elbows (n, 3) world positions, elbow_heights and wrist_heights (n,)
    distances from the wall, metres."""
    x, y = elbows_xy[:, 0], elbows_xy[:, 1]
    out = (x < 0) | (x > width) | (y < 0) | (y > height)
    back = elbow_heights >= wrist_heights - BACK_SLACK_M
    span = float(np.linalg.norm(elbows[0] - elbows[1])) if len(elbows) == 2 else 0.0
    return ArmCheck(tuple(bool(b) for b in back), tuple(bool(o) for o in out), span, 1 if span <= ELBOW_SPAN_M else 2)


def arm_checks(models: Sequence, hands: Sequence, scenes: Sequence) -> list[ArmCheck]:
    """Per pose of a batch, the rules in every view: a forearm leads back when it does so
    from every view's wall, an elbow is out of the picture when it is out of every view's.
    models: per hand a HandModel; hands: per hand a HandPoseBatch of B poses (on the models'
    device); scenes: every view's Scene, view 0 first. Hands without forearms have nothing
    beyond the wrist to check."""
    arms = [(h, m.forearm_points(h.rotation, h.translation, h.wrist_rad)) for m, h in zip(models, hands)]
    arms = [(h, points) for h, points in arms if points.shape[1]]
    batch = hands[0].batch
    if not arms:
        return [ArmCheck((), (), 0.0, 1)] * batch
    elbows = torch.stack([points[:, -1] for _, points in arms], 1)  # (B, n, 3)
    wrists = torch.stack([h.translation for h, _ in arms], 1)
    as_np = lambda t: t.detach().cpu().double().numpy()  # noqa: E731
    per_view = []  # per view: elbow pixels (B, n, 2), elbow and wrist heights (B, n), all at once
    for scene in scenes:
        xy, elbow_heights = scene.project(elbows)
        _, wrist_heights = scene.project(wrists)
        per_view.append((as_np(xy), as_np(elbow_heights), as_np(wrist_heights), scene.image))
    elbows_np = as_np(elbows)
    found = []
    for k in range(batch):
        checks = [
            check_arms(xy[k], elbows_np[k], eh[k], wh[k], image.height, image.width) for xy, eh, wh, image in per_view
        ]
        back = tuple(all(c) for c in zip(*(x.leads_back for x in checks)))
        out = tuple(all(c) for c in zip(*(x.elbows_out for x in checks)))
        found.append(dataclasses.replace(checks[0], leads_back=back, elbows_out=out))
    return found
