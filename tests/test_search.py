"""The search's last steps: the polish aimed at the success test never hands back worse."""

import torch

from handshadow.fit import FitConfig, make_searcher
from handshadow.metrics import score
from handshadow.search import HandPoses, rank_key
from tests.test_fit import known_target

SIZE = 96


def _searcher_and_truth(name="dog"):
    target, truth = known_target(name, SIZE)
    searcher = make_searcher(target, truth.scene, [h.side for h in truth.hands], FitConfig(size=SIZE))
    poses = [HandPoses(*h.tensors()) for h in truth.hands]
    return searcher, poses


def _key(searcher, poses):
    return rank_key(score(searcher.shadows(poses)[0].numpy() > 0.5, searcher.target))


def test_polish_improves_a_failing_pose_and_keeps_a_passing_one():
    searcher, truth = _searcher_and_truth()
    assert not _key(searcher, truth)[0]  # the true pose passes the success test
    assert searcher.polish(truth) is truth  # ... and is left alone

    # Knocked off: the hand slides 3 cm sideways and the fingers curl a little.
    off = [
        HandPoses(p.pose_rad * 1.15, p.rotation, p.translation + torch.tensor([0.03, 0.0, 0.0]), p.wrist_rad)
        for p in truth
    ]
    before = _key(searcher, off)
    assert before[0], "the knocked-off pose should fail the success test"
    polished = searcher.polish(off, rounds=1, steps=24, copies=2)
    after = _key(searcher, polished)
    assert after < before  # strictly better by the ranking
    assert float(searcher.penetration_mm(polished).max()) <= max(1.0, float(searcher.penetration_mm(off).max()))


def test_ctrl_c_in_the_polish_hands_back_poses(monkeypatch):
    import pytest

    from handshadow.search import Interrupted, Searcher

    searcher, truth = _searcher_and_truth()
    off = [
        HandPoses(p.pose_rad, p.rotation, p.translation + torch.tensor([0.03, 0.0, 0.0]), p.wrist_rad) for p in truth
    ]
    calls = {"n": 0}
    objective = Searcher.objective

    def interrupted_on_the_third_step(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return objective(self, *args, **kwargs)

    monkeypatch.setattr(Searcher, "objective", interrupted_on_the_third_step)
    with pytest.raises(Interrupted) as stop:
        searcher.polish(off, rounds=1, steps=10, copies=2)
    assert len(stop.value.poses) == 1 and stop.value.poses[0].pose_rad.shape == (1, 15, 3)
    # What it hands back scores no worse than where it started.
    assert _key(searcher, stop.value.poses) <= _key(searcher, off)


def test_stop_ends_the_polish_at_once_with_the_best_so_far():
    import pytest

    from handshadow.search import Interrupted

    searcher, truth = _searcher_and_truth()
    off = [
        HandPoses(p.pose_rad * 1.15, p.rotation, p.translation + torch.tensor([0.03, 0.0, 0.0]), p.wrist_rad)
        for p in truth
    ]
    asked = []

    def stop():  # the app's Cancel button, pressed during the third step
        asked.append(1)
        return len(asked) >= 3

    with pytest.raises(Interrupted) as halt:
        searcher.polish(off, rounds=1, steps=24, copies=2, stop=stop)
    assert len(asked) == 3  # asked before every step, obeyed at once
    assert [p.pose_rad.shape for p in halt.value.poses] == [(1, 15, 3)] * len(off)


def test_stop_ends_a_fit_early_and_marks_it_interrupted(monkeypatch):
    from handshadow.fit import fit_frame
    from handshadow.search import Searcher

    target, _ = known_target("dog", SIZE)
    asked, finishing = [], []

    def stop():
        asked.append(1)
        return len(asked) > 5

    separate, polish = Searcher.separate, Searcher.polish
    monkeypatch.setattr(
        Searcher, "separate", lambda self, p, **k: finishing.append(("separate", k)) or separate(self, p, **k)
    )
    monkeypatch.setattr(
        Searcher, "polish", lambda self, p, **k: finishing.append(("polish", k)) or polish(self, p, **k)
    )
    result = fit_frame(target, FitConfig(hands="1", size=SIZE, quality="fast"), stop=stop)
    assert result.interrupted and result.pose_set.fit["interrupted"] is True
    assert result.steps == 6  # the search obeys on its sixth step
    assert result.shadow.shape == target.shape and result.shadow.any()
    # After a stopped search the separation still runs to its end (a result must not
    # penetrate, although the stop stays pressed) and no polish follows.
    assert finishing == [("separate", {"stop": None})]


def test_time_limit_ends_search_and_polish_without_marking_an_interruption():
    from handshadow.fit import fit_frame

    target, _ = known_target("dog", SIZE)
    result = fit_frame(target, FitConfig(hands="1", size=SIZE, quality="fast", time_limit_s=1e-6))
    assert result.steps == 1 and not result.interrupted  # the deadline is checked after each step
    assert result.shadow.any()


def _scripted_rounds(monkeypatch, hd95s):
    """Make each polish round return the next HD95 of ``hd95s`` (IoU 0.9, thin 0.9); count them."""
    from handshadow.metrics import FitScore
    from handshadow.search import Searcher

    played = []

    def round_(self, poses, best_score, *args):
        played.append(hd95s[len(played)])
        return FitScore(iou=0.9, boundary_f1=0.5, hd95=played[-1], thin_recall=0.9), poses

    monkeypatch.setattr(Searcher, "_polish_round", round_)
    return played


def test_polish_rounds_go_on_only_for_an_improving_near_miss(monkeypatch):
    searcher, truth = _searcher_and_truth()
    off = [
        HandPoses(p.pose_rad, p.rotation, p.translation + torch.tensor([0.03, 0.0, 0.0]), p.wrist_rad) for p in truth
    ]
    start = score(searcher.shadows(off)[0].numpy() > 0.5, searcher.target)
    assert not start.near_miss and not start.success  # far from the bar
    # A near miss that keeps improving gets every further round.
    played = _scripted_rounds(monkeypatch, [0.038, 0.036, 0.034, 0.033, 0.032, 0.031, 0.0305])
    searcher.polish(off, rounds=2, near_rounds=4)
    assert len(played) == 6
    # ... but stops when a round brings nothing.
    played = _scripted_rounds(monkeypatch, [0.038, 0.036, 0.036, 0.036, 0.036, 0.036])
    searcher.polish(off, rounds=2, near_rounds=4)
    assert len(played) == 3
    # A result far from the bar gets only the base rounds; a success ends the polish at once.
    played = _scripted_rounds(monkeypatch, [0.09, 0.08, 0.07, 0.06])
    searcher.polish(off, rounds=2, near_rounds=4)
    assert len(played) == 2
    played = _scripted_rounds(monkeypatch, [0.036, 0.029, 0.028])
    searcher.polish(off, rounds=2, near_rounds=4)
    assert len(played) == 2
