"""The search, in small parts (no I/O here):

    problem.py    Problem: the target, the scene, the hands and their limits, fixed while a
                  search runs, and further views of the same pose (View); Level: the same
                  at a stage's resolution
    objective.py  objective(): named loss terms (LossTerms) of hypotheses at a stage
    loop.py       optimise(): the one Adam loop
    starts.py     library poses and random hands, aligned to the target in 2D
    stages.py     run_stages(): coarse to fine, ranked and pruned after each stage (and
                  stopped early when every hypothesis is out of reach)
    finishing.py  separate(), polish(), settle(), keep_between_light_and_wall()
    hops.py       hop(): a close miss's fine stages again from harder-jittered copies
    config.py     the numbers: Stage, Weights, LearningRates, Reach, Finishing, Settle, Hops,
                  GiveUp

A hypothesis is one or two hands (poses.PoseBatch). Joint angles stay inside their limits by
construction (poses.PoseParameters); rotations are a rotation vector applied in world axes on
top of the start's rotation; translations are metres. Ranking is by the fit measures
(metrics.rank_key; with several views metrics.ViewScores: every view's together).
"""

from handshadow.search.config import Finishing, GiveUp, Hops, LearningRates, Reach, Settle, Stage, Weights
from handshadow.search.finishing import Interrupted, keep_between_light_and_wall, polish, separate, settle
from handshadow.search.hops import hop
from handshadow.search.objective import LossTerms, objective, view_objective
from handshadow.search.problem import Level, Problem, View, ViewTarget
from handshadow.search.stages import Progress, SearchResult, run_stages

__all__ = [
    "Finishing",
    "GiveUp",
    "Hops",
    "Interrupted",
    "LearningRates",
    "Level",
    "LossTerms",
    "Problem",
    "Progress",
    "Reach",
    "SearchResult",
    "Settle",
    "Stage",
    "View",
    "ViewTarget",
    "Weights",
    "hop",
    "keep_between_light_and_wall",
    "objective",
    "polish",
    "run_stages",
    "separate",
    "settle",
    "view_objective",
]
