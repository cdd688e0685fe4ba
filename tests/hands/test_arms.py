"""The arm rules: elbows out of the picture, one person's reach."""

import numpy as np
import pytest
import torch

from handshadow import losses
from handshadow.hands.arms import ELBOW_SPAN_M, check_arms


def test_forearms_elbows_and_reach_are_reported():
    inside = np.array([[50.0, 60.0], [300.0, 20.0]])  # the first in a 256 x 256 frame, the second beyond it
    near = np.array([[0.2, 0.0, 1.0], [-0.2, 0.0, 1.0]])
    wrists = np.array([1.0, 1.0])
    check = check_arms(inside, near, np.array([1.1, 0.9]), wrists, 256, 256)
    assert check.elbows_out == (False, True) and not check.upper_arms_hidden
    assert check.leads_back == (True, False)  # the second elbow is 10 cm nearer the wall than its wrist
    assert check.span_m == 0.4 and check.performers == 1 and not check.holdable()
    far = np.array([[0.6, 0.0, 1.0], [-0.6, 0.0, 1.0]])
    spread = check_arms(inside, far, np.array([1.1, 1.0]), wrists, 256, 256)
    assert 1.2 > ELBOW_SPAN_M and spread.performers == 2
    assert not spread.holdable() and spread.holdable(performers=2)


def test_inside_frame_pushes_a_point_out_by_the_nearest_edge():
    pts = torch.tensor([[[10.0, 50.0], [-5.0, 50.0]]], requires_grad=True)  # 10 px in, and outside
    cost = losses.inside_frame(pts, 100, 100)
    assert float(cost[0].detach()) == pytest.approx((10 / 100) ** 2)
    cost.sum().backward()
    assert float(pts.grad[0, 0, 0]) > 0 and float(pts.grad[0, 1].abs().sum()) == 0  # out through x = 0
    # A margin keeps a point that is just outside still pushed.
    assert float(losses.inside_frame(pts, 100, 100, margin_px=8)[0].detach()) > (10 / 100) ** 2


def test_every_library_pose_is_one_a_person_can_hold():
    # The library's poses start the search; one whose forearm points at the wall is ranked
    # behind every start a person can hold (search.starts), so it would never be tried. They
    # are also the classic hand shadows `handshadow render NAME` teaches, and the built-in
    # targets' answers: no hand or finger may pass into flesh deeper than skin gives (9 of
    # the 14 did, 4.7 to 25.6 mm, until tools/make_library.py --fix-depth).
    from handshadow.fit import FitConfig, make_problem
    from handshadow.hands.penetration import TOLERANCE_MM
    from handshadow.library import library_names, load_library_pose
    from handshadow.poses import HandPoseBatch, PoseBatch

    for name in library_names():
        posed = load_library_pose(name)
        sides = [h.side for h in posed.hands]
        blank = np.zeros((64, 64), bool)
        problem = make_problem(blank, posed.scene, sides, FitConfig(hands=str(len(sides)), device="cpu"))
        poses = PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in posed.hands])
        check = problem.arm_checks(poses)[0]
        assert check.holdable(), f"{name}: forearms lead back {check.leads_back}, {check.performers} performers"
        depth = problem.mesh_penetration(poses)[0].deepest_mm
        assert depth <= TOLERANCE_MM, f"{name}: {depth:.1f} mm into flesh"


def test_forearm_points_alone_are_where_the_posed_hand_puts_them(hands64, rng):
    """The arm checks place the forearm without posing the hand's vertices: the same points."""
    from tests.conftest import random_pose, random_rotation

    for side, hand in hands64.items():
        pose = random_pose(rng, 4)
        rotation = torch.cat([random_rotation(rng, 90) for _ in range(4)])
        translation = torch.as_tensor(rng.normal(0, 0.2, (4, 3)))
        wrist = torch.as_tensor(rng.uniform(-0.8, 0.8, (4, 2)))
        for args in ((rotation, translation, wrist), (None, translation, None), (rotation, None, wrist)):
            posed = hand(pose, *args).forearm_points
            assert posed.shape[1] > 1, side
            assert torch.equal(hand.forearm_points(*args), posed), (side, [a is None for a in args])


def test_a_pose_files_arms_are_checked_as_the_search_checks_them():
    # hands.posed.arm_check (the recovery bench draws its targets by it) and the search's
    # Problem.arm_checks share the rules; a hand turned about its wrist so that its forearm
    # points at the wall no longer leads back.
    import dataclasses

    from scipy.spatial.transform import Rotation

    from handshadow.fit import FitConfig, make_problem
    from handshadow.hands.posed import arm_check
    from handshadow.library import library_names, load_library_pose
    from handshadow.poses import HandPoseBatch, PoseBatch

    posed = load_library_pose(next(n for n in library_names() if len(load_library_pose(n).hands) == 2))
    sides = [h.side for h in posed.hands]
    problem = make_problem(np.zeros((64, 64), bool), posed.scene, sides, FitConfig(hands="2", device="cpu"))
    hand = HandPoseBatch.from_hand_poses([posed.hands[0]])
    axis = problem.models[0].forearm_points(*hand.args()[1:])[0].double().numpy()
    lead = axis[-1] - axis[0]  # wrist to elbow
    wall = -np.asarray(posed.scene.wall.normal, float)
    to_wall, _ = Rotation.align_vectors([wall], [lead])  # the forearm turned to lead toward the wall
    turned = dataclasses.replace(
        posed,
        hands=(
            dataclasses.replace(posed.hands[0], rotation=to_wall.as_matrix() @ posed.hands[0].rotation),
            posed.hands[1],
        ),
    )
    for p, back in ((posed, (True, True)), (turned, (False, True))):
        check = arm_check(p)
        searched = problem.arm_checks(PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in p.hands]))[0]
        assert check.leads_back == searched.leads_back == back
        assert check.span_m == pytest.approx(searched.span_m, abs=1e-5)
    assert arm_check(posed).holdable() and not arm_check(turned).holdable()
