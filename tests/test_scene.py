"""The scene's lamp distance: a farther lamp keeps the frame on the wall, casts a hand at its
working depth at the same size, and distances out of range are refused. The frame on the wall
is sized to a target's shape, so that every shape is as large on the wall."""

import math

import numpy as np
import pytest
import torch

from handshadow.scene import (
    FRAME_HEIGHT_M,
    GRAZING_SHARE,
    LAMP_TO_WALL_M,
    WORKING_EXTENT,
    Scene,
    SceneError,
    cropped_to_shape,
    default_views,
    frame_height_for,
)


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


def _box(frame_px: int, rows: int, cols: int) -> np.ndarray:
    shape = np.zeros((frame_px, frame_px), bool)
    shape[(frame_px - rows) // 2 :][:rows, 5 : 5 + cols] = True
    return shape


@pytest.mark.parametrize("light", ["point", "directional"])
def test_the_frame_is_sized_so_that_the_shape_has_the_working_size_on_the_wall(light):
    default = FRAME_HEIGHT_M[light]
    # A shape cropped tight (its longer side 250 of 256 px) gets a smaller frame on the wall,
    # one that leaves it the working size in metres; a small one (64 px) a larger frame.
    for longest in (250, 64):
        height = frame_height_for([_box(256, 40, longest)], light)
        assert longest / 256 * height == pytest.approx(WORKING_EXTENT * default)
        scene = Scene.default(256, 256, light=light, frame_height_m=height)
        assert scene.frame_height_m == pytest.approx(height) and scene.image.width == 256
    # The working size itself, and within the tolerance of it: the default frame.
    assert frame_height_for([_box(256, round(WORKING_EXTENT * 256), 30)], light) is None
    assert frame_height_for([_box(256, 30, round(1.04 * WORKING_EXTENT * 256))], light) is None
    # Several shapes share one frame, sized to the largest; a tiny one's frame is bounded.
    both = frame_height_for([_box(256, 64, 20), _box(256, 20, 250)], light)
    assert both == frame_height_for([_box(256, 20, 250)], light)
    assert frame_height_for([_box(256, 4, 4)], light) == pytest.approx(4.0 * default)
    assert frame_height_for([np.zeros((32, 32), bool)], light) is None
    # A shape that runs off the frame (an arm leaving the picture) has no known size.
    cut = _box(256, 40, 250)
    cut[100, 0] = True
    assert frame_height_for([cut], light) is None
    assert frame_height_for([_box(256, 20, 250), cut], light) is None


def _grazing(frame_px: int = 256, tip_px: int = 6) -> np.ndarray:
    """A lens from the frame's left edge to its right, as a picture cropped to it gives: it
    meets both edges in runs ``tip_px`` long."""
    rows, cols = np.mgrid[:frame_px, :frame_px]
    half = (frame_px - 1) / 2
    return (rows - half) ** 2 / (tip_px / 2 + 40 * (1 - ((cols - half) / half) ** 2)) ** 2 <= 1


@pytest.mark.parametrize("light", ["point", "directional"])
def test_a_shape_cropped_tight_to_its_picture_is_sized_and_one_running_off_is_not(light):
    lens = _grazing()
    assert lens[:, 0].sum() == 6 and lens[:, -1].sum() == 6 and not lens[0].any()
    assert cropped_to_shape(lens)
    assert frame_height_for([lens], light) == pytest.approx(WORKING_EXTENT * FRAME_HEIGHT_M[light])
    # Crossing an edge wide, as a forearm's shadow leaving the picture does (9 to 23 % of the
    # side in bench/recover.py's targets), or meeting one end only, it runs off the frame.
    assert not cropped_to_shape(_grazing(tip_px=round(GRAZING_SHARE * 256) + 1))
    one_end = lens.copy()
    one_end[:, :3] = False
    assert one_end[:, -1].any() and not cropped_to_shape(one_end)
    assert frame_height_for([one_end], light) is None
    arm = _box(256, 40, 200)
    arm[110:146, :40] = True  # 36 px across the left edge
    arm[120:124, 200:] = True  # and a thin part grazing the right one
    assert not cropped_to_shape(arm) and frame_height_for([arm], light) is None
    # Two thin forearms leaving through the bottom corners split each crossing between two
    # edges, every run under GRAZING_SHARE: they still run off the frame.
    corners = np.zeros((256, 256), bool)
    corners[80:140, 100:156] = True
    for r in range(140, 256):  # 10 px bands from the body down into both bottom corners
        c = round(100 - (r - 140) * 100 / 115)
        corners[r, max(0, c - 5) : c + 5] = corners[r, 255 - c - 4 : min(256, 255 - c + 6)] = True
    assert corners[-1, 0] and corners[-1, -1] and corners[0].sum() == 0
    assert not cropped_to_shape(corners) and frame_height_for([corners], light) is None


@pytest.mark.parametrize("metres", [0.0, -1.0, math.nan, math.inf])
def test_a_frame_height_that_is_no_length_is_refused(metres):
    with pytest.raises(SceneError, match="frame's height"):
        Scene.default(frame_height_m=metres)


def test_two_views_keep_the_default_frame():
    with pytest.raises(SceneError, match="two views keep the default frame"):
        default_views(32, 32, "point", (0.0, 90.0), LAMP_TO_WALL_M, 0.6)
