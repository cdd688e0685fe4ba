"""Two-hand hypotheses recombined: one hypothesis's right hand with another's left.

A two-hand start is only as good as both of its hands, and after a broad stage one hypothesis
may hold the right hand where the target wants it while another holds the left. The shadow
of two hands is the union of each hand's shadow, so the IoU of every pairing follows from the
hands' shadows rendered once each, without posing or rendering the pairs:

    pairs = crossed(problem, poses, height, n)   # up to n new pairings (PoseBatch), or None

With B hypotheses that is B * (B - 1) pairings for the price of two renders of B.
"""

from __future__ import annotations

import torch

from handshadow.poses import Origin, PoseBatch
from handshadow.render import ShadowRenderer
from handshadow.search.problem import Level, Problem


def pairing_iou(right: torch.Tensor, left: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(B, B) IoU with the target of the union of right hand i's shadow and left hand j's.

    right, left: (B, H, W) bool, each hand's shadow alone; target (H, W) bool. Entry (i, i)
    is hypothesis i as it stands."""
    b = right.shape[0]
    r = right.reshape(b, -1).float()
    lf = left.reshape(b, -1).float()
    t = target.reshape(-1).float()
    inter = (r @ t)[:, None] + (lf @ t)[None, :] - (r * t) @ lf.T  # |(R_i | L_j) & T|
    shadow = r.sum(1)[:, None] + lf.sum(1)[None, :] - r @ lf.T  # |R_i | L_j|
    return inter / (shadow + t.sum() - inter).clamp(min=1.0)


def crossed(problem: Problem, poses: PoseBatch, height: int, n: int) -> PoseBatch | None:
    """Up to ``n`` pairings of one hypothesis's right hand with another's left whose shadow
    at frame height ``height`` covers the target better (IoU) than every hypothesis of
    ``poses`` as it stands, best first, no hand used twice; None when there is none, with one
    hand, or with several views (one pose casts every view's shadow: a pairing good in one
    view says little of the others)."""
    if poses.n_hands != 2 or len(problem.views) > 1 or poses.batch < 2 or n < 1:
        return None
    level = problem.level(height)
    with torch.no_grad():
        outs = problem.pose(poses.hands)
        right, left = (r.render([o.vertices]).mask > 0.5 for r, o in zip(_hand_renderers(problem, level), outs))
        iou = pairing_iou(right, left, level.maps.target > 0.5)
    bar = float(iou.diagonal().max())
    order = torch.argsort(iou.flatten(), descending=True).tolist()
    b, used_r, used_l, pairs = poses.batch, set(), set(), []
    for k in order:
        i, j = divmod(k, b)
        if float(iou[i, j]) <= bar or len(pairs) == n:
            break
        if i != j and i not in used_r and j not in used_l:
            pairs.append((i, j))
            used_r.add(i)
            used_l.add(j)
    if not pairs:
        return None
    device = poses.hands[0].pose_rad.device
    ri = torch.as_tensor([i for i, _ in pairs], device=device)
    lj = torch.as_tensor([j for _, j in pairs], device=device)
    origins = None
    if poses.origins is not None:
        origins = [Origin("crossed", f"{poses.origins[i]} + {poses.origins[j]}") for i, j in pairs]
    return PoseBatch([poses.hands[0].select(ri), poses.hands[1].select(lj)], origins)


def _hand_renderers(problem: Problem, level: Level) -> list[ShadowRenderer]:
    """One renderer per hand slot at a level (cached in it): each hand's shadow alone."""
    if "hand_renderers" not in level.derived:
        level.derived["hand_renderers"] = [
            ShadowRenderer(level.scene, [m.faces], [m.num_vertices]).to(problem.device) for m in problem.models
        ]
    return level.derived["hand_renderers"]
