"""Recombined two-hand hypotheses: the IoU of every pairing from each hand's shadow alone, and
the right hand of one hypothesis with the left of another comes back as the known pose."""

import numpy as np
import torch

from handshadow.metrics import iou
from handshadow.poses import HandPoseBatch, Origin, PoseBatch
from handshadow.search.crossover import _hand_renderers, crossed, pairing_iou
from tests.test_search import _problem_and_truth


def _shifted(hand: HandPoseBatch, dx: float) -> HandPoseBatch:
    return hand.moved(torch.tensor([dx, 0.0, 0.0]))


def test_a_right_hand_and_a_left_hand_from_two_hypotheses_make_the_known_pose():
    problem, truth = _problem_and_truth("crocodile")
    assert truth.n_hands == 2
    right, left = truth.hands
    # A: the right hand in place, the left 6 cm off; B: the other way round; C: both off.
    poses = PoseBatch(
        [
            HandPoseBatch.cat([right, _shifted(right, 0.06), _shifted(right, -0.05)]),
            HandPoseBatch.cat([_shifted(left, 0.06), left, _shifted(left, -0.05)]),
        ],
        [Origin("random", "A"), Origin("random", "B"), Origin("random", "C")],
    )
    height = 64
    level = problem.level(height)
    target = level.maps.target > 0.5
    outs = problem.pose(poses.hands)
    alone = [r.render([o.vertices]).mask > 0.5 for r, o in zip(_hand_renderers(problem, level), outs)]
    pairs = pairing_iou(*alone, target)
    # The union algebra agrees with rendering each pairing's two hands together.
    for i in range(3):
        for j in range(3):
            both = problem.shadows(PoseBatch([poses.hands[0].select([i]), poses.hands[1].select([j])]), height)
            assert abs(float(pairs[i, j]) - iou(both[0].numpy() > 0.5, target.cpu().numpy())) < 1e-6
    known = iou(problem.shadows(truth, height)[0].numpy() > 0.5, target.cpu().numpy())  # the target, at 64 px
    assert abs(float(pairs[0, 1]) - known) < 1e-6 and float(pairs.diagonal().max()) < known - 0.1
    found = crossed(problem, poses, height, 2)
    assert found is not None and str(found.origins[0]) == "crossed random A + random B"
    for got, want in zip(found.item(0).hands, truth.hands):
        for a, b in zip(got.args(), want.args()):
            np.testing.assert_allclose(a.numpy(), b.numpy(), atol=1e-6)
    # With one hand, or nothing better than the hypotheses as they stand, nothing is added.
    assert crossed(problem, truth, height, 2) is None
    assert (
        crossed(problem, PoseBatch([HandPoseBatch.cat([right, right]), HandPoseBatch.cat([left, left])]), height, 2)
        is None
    )
