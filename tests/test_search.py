"""The search's parts: the objective's named terms, the parameters' limits, the stages, and
the finishing steps (separation, polish) that never hand back worse."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from handshadow.fit import CONTACTS_EVERY, OUTLINE_THIN, FitConfig, fit_frame, make_problem, schedule
from handshadow.hands.limits import JointLimits
from handshadow.metrics import rank_key, score
from handshadow.poses import HandPoseBatch, PoseBatch, PoseParameters
from handshadow.scene import LAMP_TO_WALL_M
from handshadow.search import (
    Finishing,
    GiveUp,
    Hops,
    Interrupted,
    Settle,
    Stage,
    Weights,
    finishing,
    hop,
    objective,
    polish,
    separate,
    settle,
)
from handshadow.search import stages as stages_module
from handshadow.search.hops import focused_joints
from handshadow.search.objective import FarOutline, view_objective
from tests.test_fit import known_target

SIZE = 96


def _problem_and_truth(name="dog"):
    target, truth = known_target(name, SIZE)
    problem = make_problem(target, truth.scene, [h.side for h in truth.hands], FitConfig(size=SIZE))
    poses = PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in truth.hands])
    return problem, poses


def _key(problem, poses):
    return rank_key(score(problem.shadows(poses)[0].numpy() > 0.5, problem.target))


def _moved(poses, dx=0.03, curl=1.0):
    return PoseBatch(
        [
            HandPoseBatch(h.pose_rad * curl, h.rotation, h.translation + torch.tensor([dx, 0.0, 0.0]), h.wrist_rad)
            for h in poses.hands
        ]
    )


def test_objective_names_its_terms_and_they_sum_to_the_total():
    problem, truth = _problem_and_truth()
    stage = Stage(height=64, blur_px=4, attract_px=8, steps=1, keep=1)
    terms, shadow = objective(problem, truth.hands, stage)
    assert shadow.mask.shape == (1, 64, 64)
    values = terms.values(0)
    assert set(values) >= {"image", "excess", "penetration", "placement", "inside", "thin_pull"}
    assert sum(values.values()) == pytest.approx(float(terms.total[0]), rel=1e-5)
    # The true pose: its shadow is the target's, so the image term is small, the off pose's larger.
    off, _ = objective(problem, _moved(truth, 0.06).hands, stage)
    assert float(off.image[0]) > 3 * float(terms.image[0])
    assert float(off.total[0]) > float(terms.total[0])


def test_parameters_keep_a_pose_at_its_limits_through_ten_rebuilds():
    limits = JointLimits.preset("paper", "right")
    lo, hi = limits.joints[..., 0], limits.joints[..., 1]
    pose = torch.where(torch.arange(45).reshape(15, 3) % 2 == 0, lo, hi)[None]  # every joint at a limit
    wrist = limits.wrist[:, 0][None].clone()
    start = PoseBatch([HandPoseBatch(pose, torch.eye(3)[None], torch.tensor([[0.0, 0.0, 1.0]]), wrist)])
    poses = start
    for _ in range(10):
        poses = PoseParameters(poses, [limits]).poses()
    assert torch.equal(poses.hands[0].pose_rad, pose)
    assert torch.equal(poses.hands[0].wrist_rad, wrist)
    # ... and inside the limits any value reads back as itself (to float rounding).
    mid = PoseBatch([HandPoseBatch(0.5 * (lo + hi)[None], torch.eye(3)[None], torch.zeros(1, 3), torch.zeros(1, 2))])
    assert torch.allclose(PoseParameters(mid, [limits]).poses().hands[0].pose_rad, mid.hands[0].pose_rad, atol=1e-6)


def test_a_joint_pushed_against_its_limit_can_come_back():
    limits = JointLimits.preset("anatomical", "right")
    lo, hi = limits.joints[..., 0], limits.joints[..., 1]
    start = PoseBatch([HandPoseBatch(lo[None].clone(), torch.eye(3)[None], torch.zeros(1, 3), torch.zeros(1, 2))])
    params = PoseParameters(start, [limits])
    joints = params.hand_parameters(0)[0]
    opt = torch.optim.Adam([joints], lr=0.1)
    for sign, steps in ((1.0, 5), (-1.0, 20)):  # pushed below the limit for a while, then pulled back up
        for _ in range(steps):
            opt.zero_grad()
            (sign * params.hand(0).pose_rad.sum()).backward()
            opt.step()
    moving = hi > lo
    assert bool((params.hand(0).pose_rad[0][moving] > lo[moving] + 1e-3).all())


def test_parameters_stay_within_the_limits_whatever_the_step():
    limits = JointLimits.preset("anatomical", "right")
    start = PoseBatch(
        [HandPoseBatch(torch.zeros(4, 15, 3), torch.eye(3).expand(4, 3, 3), torch.zeros(4, 3), torch.zeros(4, 2))]
    )
    params = PoseParameters(start, [limits])
    with torch.no_grad():
        for p in params.parameters()[:2]:
            p.add_(torch.randn(p.shape) * 50)
    hand = params.hand(0)
    assert bool(((hand.pose_rad >= limits.joints[..., 0]) & (hand.pose_rad <= limits.joints[..., 1])).all())
    assert bool(((hand.wrist_rad >= limits.wrist[:, 0]) & (hand.wrist_rad <= limits.wrist[:, 1])).all())


def test_separate_parts_hands_that_pass_through_each_other_and_keeps_the_shadow():
    # The library's bird before 2026-12-07: palms 18 mm into each other.
    target, truth = known_target("bird-inside", SIZE)
    problem = make_problem(target, truth.scene, [h.side for h in truth.hands], FitConfig(size=SIZE))
    poses = PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in truth.hands])
    assert problem.mesh_penetration(poses)[0].between_mm > 10
    apart = separate(problem, poses)
    assert problem.mesh_penetration(apart)[0].deepest_mm <= 3.0
    assert score(problem.shadows(apart)[0].numpy() > 0.5, target).success
    # A pose that passes comes back as it is.
    assert separate(problem, apart) is apart


def test_separate_opens_a_fist_curled_into_its_palm():
    target, truth = known_target("rabbit-inside", SIZE)  # ring and little finger 12 mm into the palm
    problem = make_problem(target, truth.scene, [h.side for h in truth.hands], FitConfig(size=SIZE))
    poses = PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in truth.hands])
    assert problem.mesh_penetration(poses)[0].within_mm[0] > 10
    apart = separate(problem, poses)
    assert problem.mesh_penetration(apart)[0].deepest_mm <= 3.0
    assert score(problem.shadows(apart)[0].numpy() > 0.5, target).iou > 0.95


def test_a_stage_that_layers_its_hypotheses_refits_the_shadow_with_the_hands_apart():
    # The library's bird before 2026-12-07: palms 18 mm into each other.
    target, truth = known_target("bird-inside", SIZE)
    problem = make_problem(target, truth.scene, [h.side for h in truth.hands], FitConfig(size=SIZE))
    inside = PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in truth.hands])
    refit = Stage(
        height=SIZE, blur_px=0, attract_px=2, steps=60, keep=1, lr_scale=0.15, skeleton=0.0, contacts_every=10
    )
    found = {}
    for layer in (False, True):
        first = Stage(height=SIZE, blur_px=1, attract_px=4, steps=1, keep=1, layer=layer)
        result = stages_module.run_stages(problem, inside, [first, refit])
        found[layer] = problem.mesh_penetration(result.poses)[0].between_mm, _key(problem, result.poses)
    assert found[False][0] > 10  # the stages alone leave the palms inside each other
    assert found[True][0] <= 3.0
    assert found[True][1][0] is False  # ... and with the layering the shadow still passes


def test_a_fit_whose_search_ends_in_penetration_comes_out_apart(monkeypatch):
    result, calls = _fit_ending_inside(monkeypatch)
    target, _ = known_target("bird-inside", SIZE)
    assert calls and calls[0][0] > 10  # the search's result had the hands inside each other
    assert result.penetration.deepest_mm <= 3.0 and result.penetration.performable()
    assert result.posed.fit["penetration_mm"] == round(result.penetration.deepest_mm, 2)
    assert result.posed.fit["performable"] == result.performable
    assert result.posed.fit["time_limited"] is False  # no limit given
    assert result.score == score(result.shadow, target)  # the shadow is scored as written
    assert result.score.success


def test_polish_improves_a_failing_pose_and_keeps_a_passing_one():
    problem, truth = _problem_and_truth()
    assert not _key(problem, truth)[0]  # the true pose passes the success test
    assert polish(problem, truth) is truth  # ... and is left alone
    off = _moved(truth, 0.03, 1.15)  # the hand slides 3 cm sideways and the fingers curl a little
    before = _key(problem, off)
    assert before[0], "the knocked-off pose should fail the success test"
    settings = finishing.Finishing(steps=24, copies=2)
    polished = polish(problem, off, rounds=1, settings=settings)
    assert _key(problem, polished) < before  # strictly better by the ranking
    assert float(problem.penetration_mm(polished).max()) <= max(1.0, float(problem.penetration_mm(off).max()))


def test_settle_brings_a_slightly_moved_pose_back_into_its_shadow():
    problem, truth = _problem_and_truth()
    off = _moved(truth, 0.006, 1.05)  # 6 mm sideways, the fingers a little more bent
    before = score(problem.shadows(off)[0].numpy() > 0.5, problem.target)
    settled = settle(problem, off, Settle(steps=60))
    after = score(problem.shadows(settled)[0].numpy() > 0.5, problem.target)
    assert rank_key(after) < rank_key(before)
    assert before.iou < 0.95 and after.iou > 0.98, (before, after)
    assert problem.mesh_penetration(settled)[0].deepest_mm <= Settle().tolerance_mm
    assert settle(problem, truth, Settle(steps=10)) is truth  # nothing beats the truth: it comes back as it is


def test_a_settling_pass_ends_once_nothing_has_won_for_its_patience(monkeypatch):
    problem, truth = _problem_and_truth()
    calls = {"n": 0}
    real = finishing.view_objective

    def counted(*args, **kwargs):
        calls["n"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(finishing, "view_objective", counted)
    assert settle(problem, truth, Settle(steps=60, patience=10)) is truth  # nothing beats the truth
    assert calls["n"] == 2 * 11  # each pass looks at steps 0, 5 and 10, and ends there
    calls["n"] = 0
    settle(problem, truth, Settle(steps=60, patience=1000))
    assert calls["n"] == 2 * 61  # with patience past its length, each pass runs to its end


def test_ctrl_c_in_the_settling_hands_back_the_best_so_far(monkeypatch):
    problem, truth = _problem_and_truth()
    off = _moved(truth, 0.006, 1.05)
    calls = {"n": 0}
    real = finishing.view_objective

    def interrupted_on_the_twelfth_step(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 12:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(finishing, "view_objective", interrupted_on_the_twelfth_step)
    with pytest.raises(Interrupted) as stop:
        settle(problem, off, Settle(steps=40))
    assert _key(problem, stop.value.poses) <= _key(problem, off)


def test_ctrl_c_in_the_polish_hands_back_poses(monkeypatch):
    problem, truth = _problem_and_truth()
    off = _moved(truth)
    calls = {"n": 0}
    real = finishing.view_objective

    def interrupted_on_the_third_step(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(finishing, "view_objective", interrupted_on_the_third_step)
    with pytest.raises(Interrupted) as stop:
        polish(problem, off, rounds=1, settings=finishing.Finishing(steps=10, copies=2))
    assert stop.value.poses.batch == 1 and stop.value.poses.hands[0].pose_rad.shape == (1, 15, 3)
    assert _key(problem, stop.value.poses) <= _key(problem, off)  # no worse than where it started


def test_stop_ends_the_polish_at_once_with_the_best_so_far():
    problem, truth = _problem_and_truth()
    off = _moved(truth, 0.03, 1.15)
    asked = []

    def stop():  # the app's Cancel button, pressed during the third step
        asked.append(1)
        return len(asked) >= 3

    with pytest.raises(Interrupted) as halt:
        polish(problem, off, rounds=1, settings=finishing.Finishing(steps=24, copies=2), stop=stop)
    assert len(asked) == 3  # asked at every step, obeyed at once
    assert [h.pose_rad.shape for h in halt.value.poses.hands] == [(1, 15, 3)] * off.n_hands


def test_stop_ends_a_fit_early_and_marks_it_interrupted(monkeypatch):
    from handshadow import fit as fit_module

    target, _ = known_target("dog", SIZE)
    asked, finished = [], []

    def stop():
        asked.append(1)
        return len(asked) > 5

    real_separate, real_polish = fit_module.separate, fit_module.polish
    monkeypatch.setattr(
        fit_module, "separate", lambda *a, **k: finished.append(("separate", k)) or real_separate(*a, **k)
    )
    monkeypatch.setattr(fit_module, "polish", lambda *a, **k: finished.append(("polish", k)) or real_polish(*a, **k))
    result = fit_frame(target, FitConfig(hands="1", size=SIZE, quality="fast"), stop=stop)
    assert result.interrupted and result.posed.fit["interrupted"] is True
    assert result.steps == 6  # the search obeys on its sixth step
    assert result.shadow.shape == target.shape and result.shadow.any()
    # After a stopped search the separation still runs to its end (a result must not
    # penetrate, although the stop stays pressed) and no polish follows.
    assert finished == [("separate", {"stop": None})]


def test_time_limit_ends_search_and_polish_without_marking_an_interruption():
    target, _ = known_target("dog", SIZE)
    result = fit_frame(target, FitConfig(hands="1", size=SIZE, quality="fast", time_limit_s=1e-6))
    assert result.steps == 1 and not result.interrupted  # the deadline is checked after each step
    assert result.posed.fit["time_limited"] and result.shadow.any()
    roomy = FitConfig(hands="1", size=SIZE, quality="fast", iters=12, attempts=1, hops=0, time_limit_s=3600)
    assert fit_frame(target, roomy).posed.fit["time_limited"] is False  # a limit not reached ended nothing


def test_progress_sees_the_loss_terms_by_name():
    target, _ = known_target("dog", SIZE)
    seen = []
    fit_frame(target, FitConfig(hands="1", size=SIZE, quality="fast", iters=12), progress=seen.append)
    assert seen and {"image", "penetration"} <= set(seen[-1].terms)
    assert seen[-1].done == 12 and seen[-1].poses.batch == 1


def test_the_stages_rank_by_the_fit_measures():
    problem, truth = _problem_and_truth()
    poses = PoseBatch.cat([_moved(truth, 0.08), truth, _moved(truth, 0.03)])
    assert stages_module.rank_at(problem, poses, SIZE) == [1, 2, 0]


def _scripted_rounds(monkeypatch, hd95s):
    """Make each polish round return the next HD95 of ``hd95s`` (IoU 0.9, thin 0.9); count them."""
    from handshadow.metrics import FitScore, ViewScores

    played = []

    def round_(problem, poses, best_score, *args):
        played.append(hd95s[len(played)])
        return ViewScores((FitScore(iou=0.9, boundary_f1=0.5, hd95=played[-1], thin_recall=0.9),), (1.0,)), poses

    monkeypatch.setattr(finishing, "polish_round", round_)
    return played


def test_polish_rounds_go_on_only_for_an_improving_near_miss(monkeypatch):
    problem, truth = _problem_and_truth()
    off = _moved(truth)
    start = score(problem.shadows(off)[0].numpy() > 0.5, problem.target)
    assert not start.near_miss and not start.success  # far from the bar
    # A near miss that keeps improving gets every further round.
    played = _scripted_rounds(monkeypatch, [0.038, 0.036, 0.034, 0.033, 0.032, 0.031, 0.0305])
    polish(problem, off, rounds=2, near_rounds=4)
    assert len(played) == 6
    # ... but stops when a round brings nothing.
    played = _scripted_rounds(monkeypatch, [0.038, 0.036, 0.036, 0.036, 0.036, 0.036])
    polish(problem, off, rounds=2, near_rounds=4)
    assert len(played) == 3
    # A result far from the bar gets only the base rounds; a success ends the polish at once.
    played = _scripted_rounds(monkeypatch, [0.09, 0.08, 0.07, 0.06])
    polish(problem, off, rounds=2, near_rounds=4)
    assert len(played) == 2
    played = _scripted_rounds(monkeypatch, [0.036, 0.029, 0.028])
    polish(problem, off, rounds=2, near_rounds=4)
    assert len(played) == 2


def test_a_near_miss_polish_waits_patience_rounds_for_the_next_improvement(monkeypatch):
    problem, truth = _problem_and_truth()
    off = _moved(truth)
    # Two rounds that bring nothing, then one that passes: patience 3 waits for it, 1 does not.
    hd95s = [0.038, 0.036, 0.036, 0.036, 0.029, 0.028, 0.027]
    played = _scripted_rounds(monkeypatch, hd95s)
    polish(problem, off, rounds=2, near_rounds=6, patience=3)
    assert played == hd95s[:5]
    played = _scripted_rounds(monkeypatch, hd95s)
    polish(problem, off, rounds=2, near_rounds=6, patience=1)
    assert played == hd95s[:3]
    # Patience runs out: three rounds in a row bring nothing after the last improvement.
    played = _scripted_rounds(monkeypatch, [0.038, 0.036, 0.036, 0.036, 0.036, 0.035, 0.035, 0.035])
    polish(problem, off, rounds=2, near_rounds=8, patience=3)
    assert len(played) == 5
    # ... and the near rounds never exceed near_rounds.
    played = _scripted_rounds(monkeypatch, [0.039 - 0.001 * k for k in range(12)])
    polish(problem, off, rounds=2, near_rounds=3, patience=3)
    assert len(played) == 5


def test_fit_frame_leaves_the_global_random_state_alone():
    target, _ = known_target("dog", 64)
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    fit_frame(target, FitConfig(hands="1", size=64, quality="fast", iters=3, seed=7))
    assert torch.equal(torch.rand(3), expected)


def test_result_shadow_and_score_are_those_of_the_pose_file():
    from handshadow.hands.posed import cast_shadow
    from handshadow.posefile import parse_pose

    target, _ = known_target("dog", 64)
    result = fit_frame(target, FitConfig(hands="1", size=64, quality="fast", iters=20))
    _, mask = cast_shadow(parse_pose(result.posed.to_json()))
    assert np.array_equal(mask > 0.5, result.shadow)
    assert result.score == score(result.shadow, target)
    assert result.posed.fit["iou"] == round(result.score.iou, 4)
    assert dataclasses.asdict(result.score)["hd95"] == result.score.hd95


def test_a_failed_fit_starts_afresh_with_fresh_starts_and_keeps_the_better(monkeypatch):
    from handshadow import fit as fit_module
    from handshadow.search.starts import start_key

    target, _ = known_target("dog", 64)
    # No polish and no hops: a first attempt of a few steps a stage fails (the polish alone, 60
    # steps at 64 px, passes the dog from the wider fast's starts).
    monkeypatch.setitem(fit_module.POLISH_ROUNDS, "fast", (0, 0, 1))
    base = FitConfig(hands="1", size=64, quality="fast", iters=2, exclude_library=("dog",), hops=0)  # far from passing
    single = fit_frame(target, dataclasses.replace(base, attempts=1))
    assert not single.success
    attempts, starts = [], []
    real_attempt, real_choose = fit_module._attempt, fit_module.choose_starts
    monkeypatch.setattr(fit_module, "_attempt", lambda *a, **k: attempts.append(real_attempt(*a, **k)) or attempts[-1])
    monkeypatch.setattr(fit_module, "choose_starts", lambda *a, **k: starts.append(real_choose(*a, **k)) or starts[-1])
    seen = []
    both = fit_frame(target, dataclasses.replace(base, attempts=2), progress=seen.append)
    assert both.posed.fit["attempts_run"] == 2 and sorted({p.attempt for p in seen}) == [0, 1]
    # The first attempt is the single fit, to the bit; the second searched none of its
    # library and atlas starts again, with the next seed.
    assert np.array_equal(attempts[0].shadow, single.shadow) and attempts[0].score == single.score
    keys = [{start_key(o) for o in s.origins} - {None} for s in starts]
    assert keys[0] and not keys[0] & keys[1] and attempts[1].posed.fit["seed"] == 1
    # The steps reported are the search steps of both attempts.
    assert both.steps == attempts[0].steps + attempts[1].steps == both.posed.fit["iterations"]
    # The better attempt is kept.
    better = min(range(2), key=lambda k: fit_module.result_key(attempts[k]))
    assert both.posed.fit["attempt"] == better + 1 and both.score == attempts[better].score
    assert np.array_equal(both.shadow, attempts[better].shadow)
    # With the first attempt skipped, the second runs alone and gives its result to the bit
    # (a benchmark measures a further attempt on an earlier run's failures).
    skipped = fit_frame(target, dataclasses.replace(base, attempts=2, skip_attempts=1))
    assert skipped.posed.fit["attempt"] == 2 and skipped.posed.fit["attempts_run"] == 1
    assert np.array_equal(skipped.shadow, attempts[1].shadow) and skipped.score == attempts[1].score
    # A success ends the attempts: the first attempt's result, scored as passing, is kept.
    monkeypatch.setattr(fit_module.FitResult, "success", property(lambda self: True))
    once = fit_frame(target, dataclasses.replace(base, attempts=3))
    assert once.posed.fit["attempts_run"] == 1 and np.array_equal(once.shadow, single.shadow)


def test_fast_starts_afresh_only_from_a_result_within_reach(monkeypatch):
    from handshadow import fit as fit_module

    target, _ = known_target("dog", 64)
    monkeypatch.setitem(fit_module.POLISH_ROUNDS, "fast", (0, 0, 1))  # so the first attempt fails (as above)
    assert fit_module.ATTEMPTS["fast"] > 1 and fit_module.AFRESH_ONLY_WITHIN_REACH["fast"]
    base = FitConfig(hands="1", size=64, quality="fast", iters=2, exclude_library=("dog",), hops=0)
    far = fit_frame(target, base)  # far from passing after two steps a stage: fast's own attempts end
    assert not far.success and not fit_module.within_reach(far)
    assert far.posed.fit["attempts_run"] == 1
    # An explicit count is run in full, near or far.
    assert fit_frame(target, dataclasses.replace(base, attempts=2)).posed.fit["attempts_run"] == 2
    # Within reach, fast's own attempts go on to the last while none passes.
    results = []
    monkeypatch.setattr(fit_module, "within_reach", lambda r: results.append(r) or True)
    near = fit_frame(target, base)
    assert near.posed.fit["attempts_run"] == fit_module.ATTEMPTS["fast"] == len(results) + 1
    assert not any(r.success for r in results)


def test_a_stop_in_a_later_attempt_keeps_the_best_so_far(monkeypatch):
    from handshadow import fit as fit_module

    target, _ = known_target("dog", 64)
    monkeypatch.setitem(fit_module.POLISH_ROUNDS, "fast", (0, 0, 1))  # so the first attempt fails (as above)
    base = FitConfig(hands="1", size=64, quality="fast", iters=4, exclude_library=("dog",), attempts=3, hops=0)
    attempts, seen = [], []
    real_attempt = fit_module._attempt
    monkeypatch.setattr(fit_module, "_attempt", lambda *a, **k: attempts.append(real_attempt(*a, **k)) or attempts[-1])
    # Stop at the second attempt's second step, as Ctrl-C would.
    result = fit_frame(
        target, base, progress=seen.append, stop=lambda: bool(seen) and seen[-1].attempt == 1 and seen[-1].done >= 2
    )
    assert len(attempts) == 2 and not attempts[0].interrupted and attempts[1].interrupted
    assert result.interrupted and result.posed.fit["interrupted"] is True and result.posed.fit["attempts_run"] == 2
    better = min(range(2), key=lambda k: fit_module.result_key(attempts[k]))
    assert result.score == attempts[better].score and np.array_equal(result.shadow, attempts[better].shadow)


def test_ctrl_c_while_a_later_attempt_sets_up_keeps_the_first(monkeypatch):
    from handshadow import fit as fit_module

    target, _ = known_target("dog", 64)
    monkeypatch.setitem(fit_module.POLISH_ROUNDS, "fast", (0, 0, 1))  # so the first attempt fails (as above)
    base = FitConfig(hands="1", size=64, quality="fast", iters=2, exclude_library=("dog",), attempts=3, hops=0)
    first = fit_frame(target, dataclasses.replace(base, attempts=1))
    assert not first.success  # so a second attempt starts
    real_choose, calls = fit_module.choose_starts, []

    def ctrl_c_on_the_second(*a, **k):  # Ctrl-C while the second attempt picks its starts
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_choose(*a, **k)

    monkeypatch.setattr(fit_module, "choose_starts", ctrl_c_on_the_second)
    result = fit_frame(target, base)
    assert len(calls) == 2 and result.interrupted and result.posed.fit["interrupted"] is True
    assert result.posed.fit["attempt"] == 1 and result.posed.fit["attempts_run"] == 1
    assert result.score == first.score and np.array_equal(result.shadow, first.shadow)


def _fit_ending_inside(monkeypatch, stop=None, ctrl_c=False):
    """A two-hand bird fit whose search ends with the palms 18 mm inside each other (the
    search's result is the true pose, so the fit's lamp is the one the target was cast by),
    the separation's calls recorded (the poses' deepest mm and the stop it was given);
    ``ctrl_c``: Ctrl-C at the separation's first step."""
    from handshadow import fit as fit_module

    target, truth = known_target("bird-inside", SIZE)
    inside = PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in truth.hands])
    real_search, real_separate, calls = fit_module.run_stages, fit_module.separate, []

    def search_ending_inside(problem, starts, stages, **kw):
        result = real_search(problem, starts, stages, **kw)
        result.poses = inside
        return result

    def watched(problem, poses, **kw):
        calls.append((problem.mesh_penetration(poses)[0].deepest_mm, kw.get("stop")))
        if len(calls) == 1 and ctrl_c:
            raise Interrupted(poses)
        return real_separate(problem, poses, **kw)

    monkeypatch.setattr(fit_module, "run_stages", search_ending_inside)
    monkeypatch.setattr(fit_module, "separate", watched)
    config = FitConfig(hands="2", size=SIZE, quality="fast", iters=6, lamp_to_wall_m=truth.scene.light.position[2])
    return fit_frame(target, config, stop=stop), calls


def test_ctrl_c_during_the_separation_still_ends_with_the_hands_apart(monkeypatch):
    result, calls = _fit_ending_inside(monkeypatch, ctrl_c=True)
    assert calls[0][0] > 10 and len(calls) == 2  # interrupted at once, then run to its end
    assert result.interrupted and result.posed.fit["interrupted"] is True
    assert result.penetration.deepest_mm <= 3.0 and result.penetration.performable()


def test_a_stop_during_the_separation_still_ends_with_the_hands_apart(monkeypatch):
    pressed = []  # the app's Cancel, pressed once the search is over

    def stop():
        return bool(pressed)

    from handshadow import fit as fit_module

    real_separated = fit_module._separated
    monkeypatch.setattr(fit_module, "_separated", lambda chosen: pressed.append(1) or real_separated(chosen))
    result, calls = _fit_ending_inside(monkeypatch, stop=stop)
    assert pressed and calls and all(given is None for _, given in calls)  # the separation is not stopped
    assert result.penetration.deepest_mm <= 3.0 and result.penetration.performable()


def test_the_time_limit_counts_the_set_up(monkeypatch):
    import time

    from handshadow import fit as fit_module

    target, _ = known_target("dog", 64)
    real_choose = fit_module.choose_starts

    def slow(*a, **k):  # a set-up slower than the whole limit (the atlas's first build takes minutes)
        time.sleep(0.6)
        return real_choose(*a, **k)

    monkeypatch.setattr(fit_module, "choose_starts", slow)
    result = fit_frame(target, FitConfig(hands="auto", size=64, quality="fast", time_limit_s=0.5))
    assert result.steps == 2 and not result.interrupted  # one step per hand count: each found its time spent


@pytest.mark.parametrize("quality", ["fast", "default", "best"])
def test_the_first_stage_never_runs_the_exact_mesh_test(quality):
    # A 64-pixel frame brings every stage to full resolution; the first stage's many
    # hypotheses (a broad search) still go without the slow exact test (it made a 64-px fast
    # fit 1.7 times as slow), and the later stages keep it as at any size.
    big = schedule(quality, None, 256)[2]
    small = schedule(quality, None, 64)[2]
    assert all(st.height == 64 for st in small)
    assert [st.contacts_every for st in small] == [0] + [CONTACTS_EVERY] * (len(small) - 1)
    assert big[0].contacts_every == 0 and big[-1].contacts_every == CONTACTS_EVERY > 0
    two_views = schedule(quality, None, 64, views=2)[2]
    assert two_views[0].contacts_every == 0 and two_views[-1].contacts_every == CONTACTS_EVERY


@pytest.mark.parametrize("quality", ["fast", "default", "best"])
def test_the_exact_outline_stages_weigh_spills_as_the_polish_does(quality):
    # The blurred, skeleton-guided stages find the shape; the exact ones at the end fit its
    # outline, weigh spills and notches as the polish does and thin parts more (the spill
    # weight alone pulled them in). The last stage is always one.
    polish = Finishing()
    for views in (1, 2):
        stages = schedule(quality, None, 256, views=views)[2]
        assert stages[0].spill is None and stages[-1].spill == polish.polish_spill
        assert stages[-1].notches == polish.polish_notches
        for st in stages:
            exact = st.blur_px <= 1 and st.skeleton <= 0.05
            want = (OUTLINE_THIN, polish.polish_spill, polish.polish_notches) if exact else (None, None, None)
            assert (st.thin, st.spill, st.notches) == want
        # Only the polish, which runs on a result that fails, weighs the wrong regions past the
        # HD95 bar; the stages do not (their passes stay as they were).
        assert all(st.weights(Weights()).far == 0 for st in stages)
        assert polish.polish_weights(Weights()).far == polish.polish_far > 0


def _near_miss(truth):
    """The dog pose 10 cm nearer the lamp with its fingers bent 1.6 times: a near miss."""
    return PoseBatch(
        [
            HandPoseBatch(h.pose_rad * 1.6, h.rotation, h.translation + torch.tensor([0.0, 0.0, 0.1]), h.wrist_rad)
            for h in truth.hands
        ]
    )


def test_a_hop_turns_a_near_miss_into_a_success_and_leaves_others_alone():
    problem, truth = _problem_and_truth()
    near = _near_miss(truth)
    start = problem.scores(near)[0]
    assert start.near_miss
    fine = [Stage(height=SIZE, blur_px=1, attract_px=4, steps=30, keep=2, lr_scale=0.4)]
    fine.append(Stage(height=SIZE, blur_px=0, attract_px=2, steps=20, keep=1, lr_scale=0.15))
    finished = []

    def finish(poses):
        finished.append(poses.batch)
        return separate(problem, poses)

    settings = Hops(copies=4)
    seen = []
    out = hop(
        problem,
        near,
        fine,
        finish,
        rounds=2,
        settings=settings,
        generator=torch.Generator().manual_seed(0),
        progress=seen.append,
    )
    end = problem.scores(out)[0]
    assert end.success and end.key() < start.key()
    assert finished == [1]  # one hop, finished as a fit is; no second hop after a success
    assert seen and {(p.hop, p.hops) for p in seen} == {(1, 2)} and seen[-1].done == seen[-1].total == 50
    # A pose that is not a near miss (a success, or one far from the bar) comes back as it is.
    assert hop(problem, truth, fine, finish, rounds=2, settings=settings) is truth
    far = _moved(truth)
    assert not problem.scores(far)[0].near_miss
    assert hop(problem, far, fine, finish, rounds=2, settings=settings) is far
    assert finished == [1]
    # The reach decides what hops: none at all, the near miss comes back as it is.
    assert hop(problem, near, fine, finish, rounds=2, settings=Hops(copies=4, reach_hd95=0.0)) is near
    assert finished == [1]


class _ScriptedProblem:
    """What hop asks of a problem, scripted per pose: (rank key, deepest mm, arms holdable)."""

    def __init__(self, table):
        self.table = table

    def scores(self, poses):
        key = self.table[poses][0]
        return [SimpleNamespace(within=lambda *a: True, key=lambda: (key,))]

    def mesh_penetration(self, poses):
        return [SimpleNamespace(deepest_mm=self.table[poses][1])]

    def holdable(self, poses):
        return [self.table[poses][2]]


def test_a_hop_never_trades_arms_that_can_be_held_for_arms_that_cannot(monkeypatch):
    from handshadow.search import hops as hops_module

    # The start's arms cannot be held; hop 1 ranks better and can be held; hop 2 ranks better
    # still but cannot: hop 1's result must stay.
    problem = _ScriptedProblem({"start": (3, 0.0, False), "hop 1": (2, 0.0, True), "hop 2": (1, 0.0, False)})
    results = iter(["hop 1", "hop 2"])
    monkeypatch.setattr(hops_module, "_copies", lambda problem, best, *a: best)
    monkeypatch.setattr(hops_module, "run_stages", lambda p, c, *a, **k: SimpleNamespace(poses=c, interrupted=False))
    out = hop(
        problem, "start", [Stage(height=SIZE, blur_px=0, attract_px=0, steps=1, keep=1)], lambda p: next(results), 2
    )
    assert out == "hop 1"
    # No stages to run: no hop.
    assert hop(problem, "start", [], lambda p: next(results), 2) == "start"


def test_only_the_last_hop_weighs_the_wrong_regions_past_the_hd95_bar(monkeypatch):
    from handshadow.search import hops as hops_module

    # Every hop ranks worse than the start, so all three run and the start stays.
    problem = _ScriptedProblem({"start": (3, 0.0, True), "hopped": (4, 0.0, True)})
    weighed = []

    def run_stages(p, copies, stages, *a, **k):
        weighed.append([st.weights(Weights()).far for st in stages])
        return SimpleNamespace(poses=copies, interrupted=False)

    monkeypatch.setattr(hops_module, "_copies", lambda problem, best, *a: best)
    monkeypatch.setattr(hops_module, "run_stages", run_stages)
    fine = [Stage(height=SIZE, blur_px=b, attract_px=0, steps=1, keep=1) for b in (1, 0)]
    settings = Hops(far=6.0, far_hops=1)
    assert hop(problem, "start", fine, lambda p: "hopped", 3, settings) == "start"
    assert weighed == [[0.0, 0.0], [0.0, 0.0], [6.0, 6.0]]
    weighed.clear()
    assert hop(problem, "start", fine, lambda p: "hopped", 2, dataclasses.replace(settings, far_hops=2)) == "start"
    assert weighed == [[6.0, 6.0], [6.0, 6.0]]
    assert fine[0].far is None  # the caller's stages are left as they were


def test_a_stopped_hop_hands_back_the_pose_it_started_from():
    problem, truth = _problem_and_truth()
    near = _near_miss(truth)
    fine = [Stage(height=SIZE, blur_px=1, attract_px=4, steps=30, keep=1, lr_scale=0.4)]
    asked = []

    def stop():
        asked.append(1)
        return len(asked) >= 3

    with pytest.raises(Interrupted) as halt:
        hop(problem, near, fine, lambda p: p, rounds=2, settings=Hops(copies=2), stop=stop)
    assert halt.value.poses is near and len(asked) == 3
    # Ctrl-C while the hop's result is being finished (separated, polished): the start again.

    def ctrl_c(poses):
        raise KeyboardInterrupt

    with pytest.raises(Interrupted) as halt:
        hop(problem, near, [dataclasses.replace(fine[0], steps=2)], ctrl_c, rounds=2, settings=Hops(copies=2))
    assert halt.value.poses is near


def test_a_fit_hops_through_its_last_two_stages_as_its_quality_says(monkeypatch):
    from handshadow import fit as fit_module

    target, _ = known_target("dog", 64)
    calls = []

    def recording_hop(problem, poses, stages, finish, rounds, settings, generator, stop=None, progress=None):
        calls.append((rounds, stages))
        progress(dataclasses.replace(seen[-1], hop=1, hops=rounds))  # what a hop's stages report
        return poses

    monkeypatch.setattr(fit_module, "hop", recording_hop)
    base = FitConfig(hands="1", size=64, quality="fast", iters=4, attempts=1, hops=0)
    seen = []
    fit_frame(target, base, progress=seen.append)
    assert calls == [] and not any(p.hop for p in seen)  # --hops 0 makes none
    fit_frame(target, dataclasses.replace(base, hops=3), progress=seen.append)
    _, _, stages = schedule("fast", 4, 64)
    assert calls == [(3, stages[-2:])]
    assert (seen[-1].hop, seen[-1].hops, seen[-1].attempt) == (1, 3, 0)  # the fit's progress sees the hops
    assert fit_module.HOPS["default"] >= 1 and fit_module.HOPS["fast"] >= 1


def test_a_fit_settles_a_result_that_passes_with_the_default_quality_only(monkeypatch):
    from handshadow import fit as fit_module

    problem, truth = _problem_and_truth()
    calls = []

    def recording_settle(problem, poses, settings, stop=None):
        calls.append((bool(problem.scores(poses)[0].success), settings))
        return poses

    monkeypatch.setattr(fit_module, "settle", recording_settle)
    base = FitConfig(size=SIZE, quality="fast", iters=4, attempts=1, hops=0, lamp_to_wall_m=LAMP_TO_WALL_M)
    assert fit_frame(problem.target, base, extra_starts=truth).success  # from the truth: a pass
    assert calls == []  # fast does not settle
    fit_frame(problem.target, dataclasses.replace(base, quality="default"), extra_starts=truth)
    assert calls == [(True, fit_module.SETTLE["default"])]


def _bent(poses, finger, by=0.8):
    """The poses with one finger of the first hand bent ``by`` radians more at each joint."""
    hands = [HandPoseBatch(*(t.clone() for t in h.args())) for h in poses.hands]
    hands[0].pose_rad[:, 3 * finger : 3 * finger + 3, 2] += by
    return PoseBatch(hands)


def test_the_fingers_near_the_failing_outline_are_found():
    problem, truth = _problem_and_truth()
    assert not any(n.any() for n in focused_joints(problem, truth, 0.05))  # nothing fails
    index = focused_joints(problem, _bent(truth, finger=1), 0.05)[0]
    assert index[3:6].any() and not index[:3].any() and not index[12:].any()  # the index, not the thumb or little
    thumb = focused_joints(problem, _bent(truth, finger=0), 0.05)[0]
    assert thumb[:3].any() and not thumb[3:].any()


def test_a_focused_jitter_moves_only_the_joints_it_names():
    problem, truth = _problem_and_truth()
    params = PoseParameters(truth.repeat(4), problem.limits)
    before = [p.detach().clone() for p in params.hand_parameters(0)]
    near = [torch.zeros(15, dtype=torch.bool)]
    near[0][3:6] = True
    finishing.jitter(params, (1.0, 0.1, 0.1), torch.Generator().manual_seed(0), rows=slice(2, None), joints_only=near)
    joints, wrist, rotvec, trans = params.hand_parameters(0)
    assert torch.equal(joints[:2], before[0][:2])  # rows before 2 as they were
    assert not torch.equal(joints[2:, 3:6], before[0][2:, 3:6])
    assert torch.equal(joints[:, :3], before[0][:, :3]) and torch.equal(joints[:, 6:], before[0][:, 6:])
    assert torch.equal(wrist, before[1]) and torch.equal(rotvec, before[2]) and torch.equal(trans, before[3])


def test_a_hops_last_copies_move_only_the_fingers_near_the_failing_outline(monkeypatch):
    from handshadow.search import hops as hops_module

    problem, truth = _problem_and_truth()
    bent = _near_miss(truth)
    near = focused_joints(problem, bent, Hops().focus_share)[0]
    assert problem.scores(bent)[0].within(Hops().reach_hd95) and 0 < int(near.sum()) < 15
    starts = []

    def no_stages(problem, poses, stages, progress=None, stop=None):
        starts.append(poses)
        raise KeyboardInterrupt  # the hop hands back its start

    monkeypatch.setattr(hops_module, "run_stages", no_stages)
    with pytest.raises(Interrupted):
        hop(problem, bent, [Stage(height=SIZE, blur_px=0, attract_px=0, steps=1, keep=1)], lambda p: p, rounds=1)
    copies = starts[0].hands[0]
    start = PoseParameters(bent, problem.limits).poses().hands[0]  # within the joint limits
    assert copies.batch == Hops().copies and torch.equal(copies.pose_rad[0], start.pose_rad[0])
    focused = copies.select(slice(-Hops().focused, None))
    moved = (focused.pose_rad - start.pose_rad).abs().amax((0, 2)) > 0
    assert moved.any() and torch.equal(moved, moved & near)  # only near joints, and some of them
    assert torch.equal(focused.translation, start.translation.expand_as(focused.translation))
    assert torch.equal(focused.wrist_rad, start.wrist_rad.expand_as(focused.wrist_rad))
    plain = copies.select(slice(1, -Hops().focused))
    assert ((plain.pose_rad - start.pose_rad).abs().amax((0, 2)) > 0).all()  # the others move all over


def test_the_starts_stay_diverse_at_most_two_per_library_pose_and_a_share_from_the_atlas():
    from handshadow.poses import Origin
    from handshadow.search.starts import ATLAS_SHARE, PER_LIBRARY_POSE, _pick_diverse

    # Best first: four of one library pose, then atlas entries, then random hands.
    origins = [Origin("library", "dog")] * 4 + [Origin("atlas", str(k)) for k in range(10)] + [Origin("random")] * 10
    order = list(range(len(origins)))
    n_keep = 12
    picked = _pick_diverse(order, origins, n_keep, picked=[23])  # a given start comes first and counts
    kinds = [origins[i].kind for i in picked]
    assert picked[0] == 23 and len(picked) == n_keep and len(set(picked)) == n_keep
    assert kinds.count("library") == PER_LIBRARY_POSE and picked[1:3] == [0, 1]
    assert kinds.count("atlas") == round(ATLAS_SHARE * n_keep)
    assert all(origins[i].kind == "random" for i in picked[3 + round(ATLAS_SHARE * n_keep) :])


def test_the_far_weight_pulls_hardest_where_the_outline_fails_the_hd95_bar():
    problem, truth = _problem_and_truth()
    bent = _bent(truth, finger=1, by=1.2)  # the index curled in: the target's index is missing
    both = PoseBatch(
        [HandPoseBatch(*(torch.cat(ab) for ab in zip(t.args(), b.args()))) for t, b in zip(truth.hands, bent.hands)]
    )
    stage = Finishing().stage(SIZE, 1)
    grads, images = {}, {}
    for weight in (0.0, 6.0):
        params = PoseParameters(both, problem.limits)
        far = FarOutline(every=10)
        weights = dataclasses.replace(problem.weights, far=weight)
        terms, shadows = view_objective(problem, params.hands(), stage, weights, far=far)
        terms.image.sum().backward()
        grads[weight] = params.hand_parameters(0)[0].grad[1].norm(dim=1)  # (15,) per joint of the bent pose
        images[weight] = terms.image.detach()
        if weight:
            # The true pose casts the target: nothing of it fails, so no extra weight.
            assert float(images[weight][0]) == float(images[0.0][0])
            assert float(images[weight][1]) > 2 * float(images[0.0][1])
            # The map holds between its refreshes: another mask in between changes nothing.
            held = far(0, problem.level(SIZE), torch.zeros_like(shadows[0].mask))
            assert held is not None and held[1].sum() > 0 and held[0].sum() == 0
    index = slice(3, 6)
    assert float(grads[6.0][index].sum()) > 2 * float(grads[0.0][index].sum())


def test_out_of_reach_is_no_hypothesis_near_the_success_test():
    problem, truth = _problem_and_truth()
    give_up = GiveUp()
    assert not stages_module.out_of_reach(problem, truth, give_up)  # the pose that cast the target
    far = _moved(truth, dx=0.12)
    assert not problem.scores(far)[0].scores[0].success and stages_module.out_of_reach(problem, far, give_up)
    both = PoseBatch(
        [HandPoseBatch(*(torch.cat(t) for t in zip(a.args(), b.args()))) for a, b in zip(far.hands, truth.hands)]
    )
    assert not stages_module.out_of_reach(problem, both, give_up)  # one hypothesis within reach is enough


@pytest.mark.parametrize(
    ("iou", "hd95", "reach"),
    [
        (0.78, 0.026, True),  # IoU short by less than its margin, the outline met
        (0.76, 0.026, False),  # IoU short by more
        (0.85, 0.065, True),  # IoU met, HD95 past its bar by less than its margin
        (0.85, 0.075, False),  # by more
        (0.79, 0.045, True),  # short of both, HD95 within the smaller margin
        (0.79, 0.055, False),  # short of both by more
    ],
)
def test_a_hypothesis_is_within_reach_by_both_measures_but_not_short_of_both(iou, hd95, reach):
    from handshadow.metrics import FitScore, ViewScores

    scores = [ViewScores((FitScore(iou, 0.5, hd95, 0.0),), (1.0,)), ViewScores((FitScore(0.5, 0.1, 0.2, 0.0),), (1.0,))]
    problem = SimpleNamespace(scores=lambda poses: scores)
    assert stages_module.out_of_reach(problem, None, GiveUp()) is not reach


def _nine_squares() -> np.ndarray:
    target = np.zeros((64, 64), bool)  # nine squares apart: no hand casts them
    for r in (8, 28, 48):
        for c in (8, 28, 48):
            target[r : r + 8, c : c + 8] = True
    return target


def test_an_attempt_out_of_reach_gives_up_for_a_fresh_one_and_the_last_always_finishes(monkeypatch):
    from handshadow import fit as fit_module

    target = _nine_squares()
    base = FitConfig(hands="1", size=64, quality="default", iters=12)
    monkeypatch.setitem(fit_module.POLISH_ROUNDS, "default", (0, 0, 1))  # the polish is not what this tests
    searches = []
    real = fit_module.run_stages
    monkeypatch.setattr(
        fit_module, "run_stages", lambda *a, **k: searches.append((real(*a, **k), k)) or searches[-1][0]
    )
    result = fit_frame(target, dataclasses.replace(base, attempts=2))
    # The first attempt stopped after the 128 px stage (here 64 px, the frame's height), unfinished.
    _, _, stages = schedule("default", 12, 64)
    after = fit_module.GIVE_UP["default"].after_stage
    assert [s.gave_up for s, _ in searches] == [True, False]
    assert searches[0][0].steps == sum(st.steps for st in stages[: after + 1]) < searches[1][0].steps
    # The second, the last, always finishes: its result is the fit's.
    assert searches[1][1]["give_up"] is None
    assert result.posed.fit["attempt"] == 2 and result.posed.fit["attempts_run"] == 2
    assert result.steps == searches[0][0].steps + searches[1][0].steps == result.posed.fit["iterations"]
    assert result.penetration.performable()


@pytest.mark.parametrize("how", ["ctrl-c", "stop"])
def test_a_ctrl_c_or_stop_after_an_attempt_gave_up_finishes_that_attempt(how, monkeypatch):
    from handshadow import fit as fit_module

    monkeypatch.setitem(fit_module.POLISH_ROUNDS, "default", (0, 0, 1))
    config = FitConfig(hands="1", size=64, quality="default", iters=12, attempts=3)
    searches, calls = [], []
    real_run, real_choose = fit_module.run_stages, fit_module.choose_starts
    monkeypatch.setattr(fit_module, "run_stages", lambda *a, **k: searches.append(real_run(*a, **k)) or searches[-1])

    def choose(*a, **k):  # Ctrl-C while the second attempt picks its starts
        calls.append(1)
        if how == "ctrl-c" and len(calls) == 2:
            raise KeyboardInterrupt
        return real_choose(*a, **k)

    monkeypatch.setattr(fit_module, "choose_starts", choose)
    stop = (lambda: bool(searches) and searches[-1].gave_up) if how == "stop" else None
    result = fit_frame(_nine_squares(), config, stop=stop)
    # The first attempt gave up; no second search ran; the first is finished and kept.
    assert len(searches) == 1 and searches[0].gave_up and len(calls) == (2 if how == "ctrl-c" else 1)
    assert result.interrupted and result.posed.fit["interrupted"] is True
    assert result.posed.fit["attempt"] == 1 and result.posed.fit["attempts_run"] == 1
    assert result.steps == searches[0].steps and result.penetration.performable()


def test_the_time_limit_after_an_attempt_gave_up_finishes_that_attempt(monkeypatch):
    import time

    from handshadow import fit as fit_module

    monkeypatch.setitem(fit_module.POLISH_ROUNDS, "default", (2, 0, 1))
    config = FitConfig(hands="1", size=64, quality="default", iters=12, attempts=3, time_limit_s=3600)
    searches, late = [], [0.0]
    real_run, real_clock = fit_module.run_stages, time.perf_counter

    def run(*a, **k):  # once the first attempt gives up, the clock is past the limit
        searches.append(real_run(*a, **k))
        if searches[-1].gave_up:
            late[0] = 7200.0
        return searches[-1]

    monkeypatch.setattr(fit_module, "run_stages", run)
    monkeypatch.setattr(time, "perf_counter", lambda: real_clock() + late[0])
    result = fit_frame(_nine_squares(), config)
    # No second attempt starts; the first is finished (separated; the polish stops at the limit).
    assert len(searches) == 1 and searches[0].gave_up
    assert result.posed.fit["attempt"] == 1 and result.posed.fit["attempts_run"] == 1
    assert not result.interrupted and result.steps == searches[0].steps and result.penetration.performable()
    assert result.posed.fit["time_limited"]
