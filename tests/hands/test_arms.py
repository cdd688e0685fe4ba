"""The arm rules: elbows out of the picture, one person's reach."""

import numpy as np
import pytest
import torch

from handshadow import losses
from handshadow.hands.arms import ELBOW_SPAN_M, check_arms


def test_elbows_in_the_picture_and_too_far_apart_are_reported():
    inside = np.array([[50.0, 60.0], [300.0, 20.0]])  # the first in a 256 x 256 frame, the second beyond it
    near = np.array([[0.2, 0.0, 1.0], [-0.2, 0.0, 1.0]])
    check = check_arms(inside, near, 256, 256)
    assert check.elbows_out == (False, True) and not check.upper_arms_hidden
    assert check.span_m == 0.4 and check.performers == 1
    far = np.array([[0.6, 0.0, 1.0], [-0.6, 0.0, 1.0]])
    assert 1.2 > ELBOW_SPAN_M and check_arms(inside, far, 256, 256).performers == 2


def test_inside_frame_pushes_a_point_out_by_the_nearest_edge():
    pts = torch.tensor([[[10.0, 50.0], [-5.0, 50.0]]], requires_grad=True)  # 10 px in, and outside
    cost = losses.inside_frame(pts, 100, 100)
    assert float(cost[0].detach()) == pytest.approx((10 / 100) ** 2)
    cost.sum().backward()
    assert float(pts.grad[0, 0, 0]) > 0 and float(pts.grad[0, 1].abs().sum()) == 0  # out through x = 0
    # A margin keeps a point that is just outside still pushed.
    assert float(losses.inside_frame(pts, 100, 100, margin_px=8)[0].detach()) > (10 / 100) ** 2
