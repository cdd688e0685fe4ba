"""A target in two pieces: found, each piece given its hand, and the reach between the hands
kept while one is searched alone."""

import dataclasses

import numpy as np
import torch

from handshadow.fit import FitConfig, make_problem, search_plan
from handshadow.poses import HandPoseBatch, PoseBatch
from handshadow.scene import Scene
from handshadow.search.config import Stage
from handshadow.search.objective import objective
from handshadow.search.pieces import Partner, columns_run_right, two_pieces
from tests.test_fit import known_target


def _frame(*boxes, size=64):
    frame = np.zeros((size, size), bool)
    for r0, r1, c0, c1 in boxes:
        frame[r0:r1, c0:c1] = True
    return frame


def test_two_pieces_are_found_and_the_right_hand_takes_the_one_on_the_performers_right():
    scene = Scene.default(64, 64)
    assert columns_run_right(scene)  # the default frame: seen from the lamp, columns run to the right
    left, right = (10, 40, 4, 20), (20, 50, 40, 60)
    pieces = two_pieces(_frame(left, right), scene)
    assert pieces is not None
    assert pieces[0].sum() == 30 * 20 and pieces[0][30, 50]  # the right hand's piece
    assert pieces[1].sum() == 30 * 16 and pieces[1][20, 10]
    # A speck beside them changes nothing; pixels touching at a corner are one piece.
    speck = _frame(left, right, (60, 62, 0, 2))
    assert all((a == b).all() for a, b in zip(two_pieces(speck, scene), pieces))
    assert two_pieces(_frame((0, 10, 0, 10), (10, 20, 10, 20)), scene) is None
    # One piece, or three that count, is no two-piece target.
    assert two_pieces(_frame(left), scene) is None
    assert two_pieces(_frame(left, right, (52, 62, 20, 40)), scene) is None
    # A frame whose columns run the other way (mirrored): the sides swap.
    image = scene.image
    mirrored = dataclasses.replace(scene, image=dataclasses.replace(image, u=tuple(-x for x in image.u)))
    assert not columns_run_right(mirrored)
    swapped = two_pieces(_frame(left, right), mirrored)
    assert (swapped[0] == pieces[1]).all() and (swapped[1] == pieces[0]).all()


def test_a_target_in_two_pieces_takes_two_hands_even_with_hands_auto():
    target = _frame((10, 40, 4, 20), (20, 50, 40, 60))
    scenes = [Scene.default(64, 64)]
    counts, pieces = search_plan([target], scenes, FitConfig(hands="auto"))
    assert counts == [2] and pieces is not None
    counts, pieces = search_plan([target], scenes, FitConfig(hands="1"))  # asked for one: one
    assert counts == [1] and pieces is None
    counts, pieces = search_plan([_frame((10, 40, 4, 60))], scenes, FitConfig(hands="auto"))
    assert counts == [1, 2] and pieces is None


def test_a_hand_searched_alone_is_kept_within_reach_of_its_partner():
    target, truth = known_target("dog", 64)
    hand = PoseBatch([HandPoseBatch.from_hand_poses([truth.hands[0]])])
    stage = Stage(height=64, blur_px=0, attract_px=0, steps=1, keep=1)
    wrist = hand.hands[0].translation[0]

    def reach(partner):
        problem = make_problem(target, truth.scene, ["right"], FitConfig(size=64), partner=partner)
        return float(objective(problem, hand.hands, stage)[0].reach[0])

    assert reach(None) == 0.0
    assert reach(Partner(wrist + torch.tensor([0.3, 0.0, 0.0]), None)) == 0.0  # within reach
    far = reach(Partner(wrist + torch.tensor([0.0, 0.0, 0.7]), None))  # 70 cm apart in depth
    assert far > 0.0
    assert reach(Partner(wrist + torch.tensor([0.0, 0.0, 0.9]), None)) > far
