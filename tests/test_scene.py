"""The scene's lamp distance: a farther lamp keeps the frame on the wall, casts a hand at its
working depth at the same size, and distances out of range are refused."""

import math

import pytest
import torch

from handshadow.scene import LAMP_TO_WALL_M, Scene, SceneError, default_views


def test_a_farther_lamp_keeps_the_frame_and_casts_the_working_depth_at_the_same_size():
    near, far = Scene.default(64, 64), Scene.default(64, 64, lamp_to_wall_m=4.0)
    assert far.light.position == (0.0, 0.0, 4.0) and far.image == near.image
    assert (near.working_depth(), far.working_depth()) == (1.0, 2.0)
    assert far.placement_range()[1] == pytest.approx(4.0 - 0.25)
    # A 10 cm offset at each scene's working depth casts the same shadow offset (twice its size) ...
    for scene in (near, far):
        d = scene.working_depth()
        xy, _ = scene.project(torch.tensor([[0.0, 0.0, d], [0.1, 0.0, d]], dtype=torch.float64))
        assert float(xy[1, 0] - xy[0, 0]) == pytest.approx(0.2 / 0.8 * 64)
    # ... but 28 cm nearer the lamp (an elbow behind its wrist) it grows less under the far lamp.
    growth = []
    for scene in (near, far):
        d = scene.working_depth() + 0.28
        xy, _ = scene.project(torch.tensor([[0.0, 0.0, d], [0.1, 0.0, d]], dtype=torch.float64))
        growth.append(float(xy[1, 0] - xy[0, 0]) / (0.2 / 0.8 * 64))
    assert growth[0] == pytest.approx(1 / (1 - 0.28), rel=1e-9)
    assert growth[1] == pytest.approx(2 / (2 - 0.28), rel=1e-9) and growth[1] < growth[0]


@pytest.mark.parametrize("metres", [1.5, 5.5, math.nan, -2.0])
def test_a_lamp_distance_out_of_range_is_refused(metres):
    with pytest.raises(SceneError, match="2 to 5 m"):
        Scene.default(lamp_to_wall_m=metres)


def test_two_views_keep_the_default_lamp_distance():
    assert len(default_views(32, 32, "point", (0.0, 90.0), LAMP_TO_WALL_M)) == 2
    with pytest.raises(SceneError, match="two views"):
        default_views(32, 32, "point", (0.0, 90.0), 3.0)
