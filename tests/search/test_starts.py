"""The starts' 2D alignment: a known rotation and scale come back, and moving the hands in 3D
moves their shadow as the alignment said."""

import math

import numpy as np
import pytest
import torch

from handshadow.metrics import iou
from handshadow.search.starts import _warp, apply_similarity, pivot_pixel, similarity_align
from tests.test_fit import known_target
from tests.test_search import _problem_and_truth


def test_similarity_align_finds_a_known_rotation_and_scale():
    target, _ = known_target("dog", 64)
    shape = torch.as_tensor(target, dtype=torch.float32)
    pivot = (32.0, 32.0)
    angle, scale = math.radians(60), 1.2
    rot = torch.tensor([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    # The target is the shape turned by 60 degrees and grown by 1.2 about the pivot.
    turned = _warp(shape[None], rot, torch.tensor([scale]), torch.zeros(1, 2), pivot)[0]
    got_angle, got_scale, _, got_iou = similarity_align(
        shape[None], (turned > 0.5).float(), pivot, np.arange(0, 360, 20), np.array([0.8, 1.0, 1.25])
    )
    assert abs(math.degrees(float(got_angle[0])) - 60) < 1e-3
    assert abs(float(got_scale[0]) - scale) < 0.05
    assert float(got_iou[0]) > 0.8  # a soft IoU: the warped shadow is resampled


def test_apply_similarity_moves_the_shadow_as_aligned():
    problem, truth = _problem_and_truth()
    small = 64
    shadow = problem.shadows(truth, small).cpu()
    angle, scale, shift = torch.tensor([math.radians(40)]), torch.tensor([1.1]), torch.tensor([[3.0, -2.0]])
    pivot = pivot_pixel(problem.scene, small)
    rot = torch.tensor(
        [[math.cos(float(angle)), -math.sin(float(angle))], [math.sin(float(angle)), math.cos(float(angle))]]
    )
    predicted = _warp(shadow, rot, scale, shift, pivot)[0] > 0.5
    moved = apply_similarity(truth.to("cpu"), angle, scale, shift, problem.scene, small)
    got = problem.shadows(moved, small)[0].cpu().numpy() > 0.5
    # Rotation is exact; scale and shift come from a move in depth, so close, not exact.
    assert iou(got, predicted.numpy()) > 0.7  # the forearm beyond the frame turns in: the 2D warp cannot know it
    assert iou(got, shadow[0].numpy() > 0.5) < 0.6  # it did move


def test_starts_whose_arms_can_be_held_come_first():
    from handshadow.fit import FitConfig, make_problem
    from handshadow.search.starts import choose_starts, random_starts

    target, truth = known_target("bird", 64)
    problem = make_problem(target, truth.scene, ["right", "left"], FitConfig(size=64))
    drawn = random_starts(64, ["right", "left"], problem.limits, np.random.default_rng(0))
    assert not all(problem.holdable(drawn))  # random hands often point a forearm at the wall
    starts = choose_starts(problem, ["right", "left"], 16, 12, np.random.default_rng(0))
    assert starts.batch == 12 and all(problem.holdable(starts))


def test_a_later_attempt_starts_from_the_library_and_atlas_starts_not_yet_searched():
    from handshadow.fit import FitConfig, make_problem
    from handshadow.search.atlas import load_atlas
    from handshadow.search.starts import choose_starts, start_key

    target, truth = known_target("bird", 64)
    problem = make_problem(target, truth.scene, ["right", "left"], FitConfig(size=64))
    atlas = load_atlas("anny", True, "anatomical")
    sides = ["right", "left"]
    first = choose_starts(problem, sides, 16, 12, np.random.default_rng(0), atlas=atlas)
    tried = {start_key(o) for o in first.origins} - {None}
    assert tried  # the library and the atlas gave starts
    second = choose_starts(problem, sides, 16, 12, np.random.default_rng(1), atlas=atlas, skip=frozenset(tried))
    assert second.batch == 12 and not tried & {start_key(o) for o in second.origins}
    assert all(problem.holdable(second))  # still holdable ones first


def test_two_hand_atlas_starts_can_be_held_by_one_person_and_some_are_kept():
    """Each atlas pair's other hand keeps the first's size, so both stand about as far from
    the wall and one person reaches both (scaled alone onto what the first leaves uncovered,
    it stood a metre or more nearer the wall and no atlas pair could be held); every entry's
    forearm leads back. So atlas pairs compete with the random hands for the kept starts."""
    from handshadow.fit import FitConfig, make_problem
    from handshadow.search.atlas import load_atlas
    from handshadow.search.starts import ALIGN_FRAME_PX, ATLAS_FIRST, ATLAS_SECOND, atlas_starts, choose_starts

    target, truth = known_target("bird", 64)
    sides = ["right", "left"]
    problem = make_problem(target, truth.scene, sides, FitConfig(size=64))
    atlas = load_atlas("anny", True, "anatomical")
    pairs = atlas_starts(atlas, problem.level(ALIGN_FRAME_PX).maps.target.cpu(), sides, problem.scene)
    assert pairs.batch == ATLAS_FIRST * ATLAS_SECOND
    assert all(problem.holdable(pairs))
    n = torch.as_tensor(problem.scene.wall.normal, dtype=torch.float32)
    depths = [(h.translation - torch.as_tensor(problem.scene.wall.point, dtype=torch.float32)) @ n for h in pairs.hands]
    assert float((depths[0] - depths[1]).abs().max()) < 0.5  # metres: a person's two hands
    chosen = choose_starts(problem, sides, 16, 12, np.random.default_rng(0), atlas=atlas)
    assert any(o.kind == "atlas" for o in chosen.origins)


def test_atlas_shadows_are_enlarged_into_a_frame_sized_to_its_target():
    """An atlas entry stands for the shadow its hand casts at the scene's working depth. In a
    frame smaller on the wall (a target cropped tight, scene.frame_height_for) that shadow is
    larger in pixels, and the entry is enlarged to match it; unenlarged it would be off by the
    frames' ratio, and the pairs' second hands placed at the wrong size."""
    from handshadow.fit import FitConfig, make_problem
    from handshadow.poses import PoseBatch
    from handshadow.scene import FIT_LAMP_TO_WALL_M, Scene
    from handshadow.search.atlas import load_atlas
    from handshadow.search.starts import _atlas_hands, _atlas_masks, atlas_zoom

    atlas = load_atlas("anny", True, "anatomical")
    idx = np.array([5, 300, 1200])
    target = np.zeros((64, 64), bool)
    target[20:40, 20:40] = True
    for frame_m, zoom in ((None, 1.0), (0.6, 0.8 / 0.6), (1.2, 0.8 / 1.2)):
        scene = Scene.default(64, 64, lamp_to_wall_m=FIT_LAMP_TO_WALL_M, frame_height_m=frame_m)
        assert atlas_zoom(scene) == pytest.approx(zoom)
        problem = make_problem(target, scene, ["right"], FitConfig(size=64))
        cast = problem.shadows(PoseBatch([_atlas_hands(atlas, idx, "right", scene.working_depth())]), 64).cpu() > 0.5
        entries = _atlas_masks(atlas, idx, "right", atlas_zoom(scene), pivot_pixel(scene, 64)) > 0.5
        for k in range(len(idx)):
            area = float(entries[k].sum()) / float(cast[k].sum())
            assert 0.9 < area < 1.1, (frame_m, k, area)  # unenlarged: 0.56 or 2.25
            assert iou(entries[k].numpy(), cast[k].numpy()) > 0.8
