"""The search with several views: the objective weighs each view's image terms and keeps the
physical rules in every view; the placement step keeps the hands off every wall."""

import numpy as np
import torch

from handshadow.fit import FitConfig, make_problem
from handshadow.poses import HandPoseBatch, PoseBatch
from handshadow.scene import default_views
from handshadow.search import Stage, ViewTarget, keep_between_light_and_wall, objective, view_objective
from tests.test_fit import known_target

SIZE = 64
STAGE = Stage(height=SIZE, blur_px=2, attract_px=4, steps=1, keep=1)
IMAGE_TERMS = ("image", "excess", "gaps", "attraction", "inside", "thin_pull")


def _dog():
    target, truth = known_target("dog", SIZE)
    poses = PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in truth.hands])
    moved = PoseBatch([h.moved(torch.tensor([0.03, 0.0, 0.0])) for h in poses.hands])  # off the target
    return target, truth.scene, PoseBatch.cat([poses, moved])


def test_two_views_of_one_scene_weigh_as_one_and_keep_the_rules_twice():
    target, scene, poses = _dog()
    one = make_problem(target, scene, ["right"], FitConfig(size=SIZE, device="cpu"))
    two = make_problem(
        target, scene, ["right"], FitConfig(size=SIZE, device="cpu"), None, [ViewTarget(scene, target, 3.0)]
    )
    assert [v.weight for v in two.views] == [0.25, 0.75]  # relative weights, normalised
    single, shadow = objective(one, poses.hands, STAGE)
    terms, shadows = view_objective(two, poses.hands, STAGE)
    assert (
        len(shadows) == 2
        and torch.equal(shadows[0].mask, shadows[1].mask)
        and torch.equal(shadow.mask, shadows[0].mask)
    )
    for name in IMAGE_TERMS:  # 0.25 x + 0.75 x
        assert torch.allclose(getattr(terms, name), getattr(single, name), rtol=1e-5, atol=1e-7), name
    assert torch.allclose(terms.placement, 2 * single.placement) and torch.allclose(terms.arms, 2 * single.arms)
    assert torch.equal(terms.penetration, single.penetration) and torch.equal(terms.reach, single.reach)
    assert float(terms.image[1]) > 3 * float(terms.image[0])  # the true pose is still the better one


def test_a_second_view_sees_what_the_first_cannot():
    target, scene, poses = _dog()
    front, side = default_views(SIZE, SIZE, "point", (0.0, 90.0))
    side_target = make_problem(
        target, front, ["right"], FitConfig(size=SIZE, device="cpu"), None, [ViewTarget(side, target)]
    )
    side_target = side_target.view_masks(poses.item(0))[1][0]
    problem = make_problem(
        target, front, ["right"], FitConfig(size=SIZE, device="cpu"), None, [ViewTarget(side, side_target)]
    )
    # 5 cm along view 0's lamp axis: view 0's shadow barely changes, view 1's moves.
    deeper = PoseBatch([h.moved(torch.tensor([0.0, 0.0, 0.05])) for h in poses.item(0).hands])
    near, far = problem.scores(PoseBatch.cat([poses.item(0), deeper]))
    assert near.success and near.scores[1].iou == 1.0
    assert far.scores[0].iou > 0.85 and far.scores[1].iou < 0.6
    assert near.key() < far.key()


def test_hands_too_near_the_second_wall_are_moved_off_it():
    target, _, poses = _dog()
    front, side = default_views(SIZE, SIZE, "point", (0.0, 90.0))
    problem = make_problem(
        target, front, ["right"], FitConfig(size=SIZE, device="cpu"), None, [ViewTarget(side, target)]
    )
    near_wall = PoseBatch([h.moved(torch.tensor([-0.9, 0.0, 0.0])) for h in poses.item(0).hands])  # x = -0.95
    kept = keep_between_light_and_wall(problem, near_wall)
    vertices = torch.cat([o.vertices[0] for o in problem.pose(kept.hands)])
    for view in problem.views:
        n = torch.as_tensor(view.scene.wall.normal, dtype=vertices.dtype)
        heights = (vertices - torch.as_tensor(view.scene.wall.point, dtype=vertices.dtype)) @ n
        lo, hi = view.scene.light_depth_range()
        assert float(heights.min()) >= lo + 0.004 and float(heights.max()) <= hi - 0.004
    assert np.isclose(float(kept.hands[0].translation[0, 2]), float(near_wall.hands[0].translation[0, 2]))


def test_the_objective_keeps_its_image_maps_per_weights_and_blur():
    """The image maps are worked out once per level, blur and weights: a problem that has
    seen other weights and blurs gives the same terms as a fresh one."""
    import dataclasses

    target, scene, poses = _dog()
    config = FitConfig(size=SIZE, device="cpu")
    used = make_problem(target, scene, ["right"], config)
    w = used.weights
    variants = [w] + [
        dataclasses.replace(w, **{k: 2 * getattr(w, k) + 1}) for k in ("thin", "depth", "spill", "notches")
    ]
    variants.append(dataclasses.replace(w, depth_cap=w.depth_cap / 2))
    stages = (STAGE, dataclasses.replace(STAGE, blur_px=0))
    for weights in variants:
        for stage in stages:
            objective(used, poses.hands, stage, weights)
    for weights in variants[::-1]:
        for stage in stages[::-1]:
            fresh = make_problem(target, scene, ["right"], config)
            seen, _ = objective(used, poses.hands, stage, weights)
            new, _ = objective(fresh, poses.hands, stage, weights)
            assert torch.equal(seen.image, new.image)
    spilled, _ = objective(used, poses.hands, STAGE, variants[3])
    plain, _ = objective(used, poses.hands, STAGE)
    assert float(spilled.image[1]) > float(plain.image[1])  # the moved pose spills: spill weighs it more


def test_a_stage_sets_its_own_spill_and_notch_weights():
    """Stage.thin / spill / notches replace the weights' own at that stage (the schedule's
    exact-outline stages weigh spills as the polish does); unset, the weights stand."""
    import dataclasses

    target, scene, poses = _dog()
    problem = make_problem(target, scene, ["right"], FitConfig(size=SIZE, device="cpu"))
    exact = dataclasses.replace(STAGE, blur_px=0)
    assert exact.weights(problem.weights) is problem.weights
    plain, _ = objective(problem, poses.hands, exact)
    spilled, _ = objective(problem, poses.hands, dataclasses.replace(exact, spill=20.0, notches=4.0))
    assert float(spilled.image[1]) > 1.2 * float(plain.image[1])  # the moved pose spills: it weighs more
    zero, _ = objective(problem, poses.hands, dataclasses.replace(exact, spill=0.0, notches=0.0, thin=4.0))
    assert problem.weights.thin == 4.0
    assert torch.equal(zero.image, plain.image)  # the weights' own: the same terms
