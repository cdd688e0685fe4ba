"""The one optimisation loop: Adam on PoseParameters, used by the stages, the finishing steps
and the morph's path refinement."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch

from handshadow.poses import PoseParameters
from handshadow.search.config import LearningRates


def optimise(
    params: PoseParameters,
    evaluate: Callable[[], tuple[torch.Tensor, Any]],
    steps: int,
    rates: LearningRates,
    *,
    cosine: bool = False,
    observe: Callable[[int, Any], bool] | None = None,
    after: Callable[[int, Any], bool] | None = None,
    look_last: bool = False,
    stop: Callable[[], bool] | None = None,
    grad_mask: torch.Tensor | None = None,
    angles_only: bool = False,
) -> int:
    """Take up to ``steps`` Adam steps; returns how many were taken.

    Args:
        params: what moves.
        evaluate: () -> (loss (B,) or scalar, anything the hooks want to see); the loss's sum
            is minimised.
        steps: the number of updates.
        rates: learning rates, already scaled for this run.
        cosine: anneal the rates to zero over the steps (else constant).
        observe: (step, evaluation) -> stop now?, called after each evaluation, before its
            update (and once more after the last update when ``look_last``).
        after: (step, evaluation) -> stop now?, called after each update.
        stop: checked after every update; True raises KeyboardInterrupt, as Ctrl-C does.
        grad_mask: (B,) factors on every parameter's gradient per hypothesis (0 holds one still).
        angles_only: move the joint and wrist angles only, not the hands' placement.
    """
    opt = torch.optim.Adam(params.param_groups(rates, angles_only))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(1, steps), eta_min=0.0) if cosine else None
    for step in range(steps + 1 if look_last else steps):
        opt.zero_grad(set_to_none=True)
        loss, seen = evaluate()
        if observe is not None and observe(step, seen):
            return step
        if step == steps:
            break
        loss.sum().backward()
        if grad_mask is not None:
            for p in params.parameters():
                if p.grad is not None:
                    p.grad *= grad_mask.view(-1, *([1] * (p.dim() - 1)))
        opt.step()
        if sched is not None:
            sched.step()
        if after is not None and after(step, seen):
            return step + 1
        if stop is not None and stop():
            raise KeyboardInterrupt
    return steps
