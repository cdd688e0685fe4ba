"""Arms one person can hold: where the elbows are, and the rules they keep (docs/performing.md).

The model ends at the elbow (hands and forearms). The upper arms and the body behind them are
not modelled, so they must stay out of the picture: every elbow's shadow falls outside the
image frame. One person reaches with both arms from one body: the elbows are at most
ELBOW_SPAN_M apart (shoulder breadth, about 0.40 m, plus two upper arms of about 0.33 m
each, arms spread wide; adult anthropometry, rounded down for comfort).
"""

from __future__ import annotations

import dataclasses

import numpy as np

ELBOW_SPAN_M = 1.0


@dataclasses.dataclass(frozen=True)
class ArmCheck:
    """elbows_out: per hand, whether its elbow's shadow lies outside the picture; span_m: the
    distance between the two elbows (0 with one hand); performers: how many people the pose
    needs (1, or 2 when the elbows are farther apart than one person's arms reach)."""

    elbows_out: tuple[bool, ...]
    span_m: float
    performers: int

    @property
    def upper_arms_hidden(self) -> bool:
        return all(self.elbows_out)


def check_arms(elbows_xy: np.ndarray, elbows: np.ndarray, height: int, width: int) -> ArmCheck:
    """The rules for one pose: elbows_xy (n, 2) their shadows in pixels of a height x width
    frame, elbows (n, 3) world positions, metres."""
    x, y = elbows_xy[:, 0], elbows_xy[:, 1]
    out = (x < 0) | (x > width) | (y < 0) | (y > height)
    span = float(np.linalg.norm(elbows[0] - elbows[1])) if len(elbows) == 2 else 0.0
    return ArmCheck(tuple(bool(o) for o in out), span, 1 if span <= ELBOW_SPAN_M else 2)
