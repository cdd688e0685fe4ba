"""A target in two pieces: each hand casts one.

A hand's shadow is connected: it is the projection of one connected mesh (the hand with its
forearm, or the hand alone). So a target of two separate pieces needs both hands, one for each,
and the two-hand problem falls apart into two one-hand problems: which hand casts which piece
is settled before the search. fit.py searches each piece with one hand, the larger piece first
and the other within one person's reach of it (:class:`Partner`), then both hands together.

    pieces = two_pieces(target, scene)      # (right's piece, left's piece) (H, W) bool, or None

Which hand takes which piece: the right hand the piece on the performer's right (the performer
faces the wall from the lamp's side), so the arms do not cross.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from scipy import ndimage

from handshadow.scene import Scene

# A piece counts when it holds at least this share of the target's area; smaller specks are
# left out of the pieces (the two-hand search that follows still sees the whole target).
PIECE_MIN_SHARE = 0.05


@dataclasses.dataclass(frozen=True)
class Partner:
    """The other hand of a two-hand pose, held still while this one is searched alone (a target
    in two pieces): its wrist and elbow, (3,) metres each (elbow None without a forearm). The
    objective's reach term keeps the searched hand within one person's reach of it."""

    wrist: torch.Tensor
    elbow: torch.Tensor | None


def two_pieces(target: np.ndarray, scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
    """The target's two pieces when it has exactly two of at least PIECE_MIN_SHARE of its area
    (pixels touching at a corner count as one piece): (the piece on the performer's right,
    the other), (H, W) bool each; None otherwise (one piece, or more than two)."""
    target = np.asarray(target, bool)
    labels, n = ndimage.label(target, structure=np.ones((3, 3), bool))
    if n < 2:
        return None
    sizes = np.bincount(labels.ravel())[1:]
    big = np.flatnonzero(sizes >= PIECE_MIN_SHARE * sizes.sum()) + 1
    if len(big) != 2:
        return None
    pieces = [labels == k for k in big]
    columns = [np.nonzero(p)[1].mean() for p in pieces]
    if (columns[0] > columns[1]) != columns_run_right(scene):
        pieces.reverse()
    return pieces[0], pieces[1]


def columns_run_right(scene: Scene) -> bool:
    """Whether the frame's columns run toward the performer's right: the performer faces the
    wall from the lamp's side, head up the frame (against its rows)."""
    n = np.asarray(scene.wall.normal, float)
    up = -np.asarray(scene.image.v, float)
    right = np.cross(-n, up)
    return float(np.asarray(scene.image.u, float) @ right) > 0
