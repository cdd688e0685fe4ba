"""The shadow's gradient against finite differences of the exact (pixel-sampled) shadow.

A pixel-sampled loss is piecewise constant, so a finite difference only means something on
average over where the outline sits between pixel centres: every check averages both the
analytic directional derivative and the central difference (step 1 px at most) over 16 random
sub-pixel offsets of the whole configuration. Tolerance: 5 % of the finite difference plus
three standard errors of its mean.
"""

import numpy as np
import pytest
import roma
import torch

from handshadow.render.shadow import MeshTopology, shadow_mask
from handshadow.render.soft import gaussian_blur
from handshadow.scene import Scene

SIZE = 256
JITTERS = 16


@pytest.fixture(scope="module")
def config(hands64):
    """Two hands, thumbs overlapping in the shadow (hidden contours, folds, a junction)."""
    right, left = hands64["right"], hands64["left"]
    pose = torch.zeros(1, 15, 3, dtype=torch.float64)
    pose[..., 2] = np.radians(20)

    def place(hand, angle, x):
        rot = roma.rotvec_to_rotmat(torch.tensor([[0.0, 0.0, angle]], dtype=torch.float64))
        return hand(pose, rot, torch.tensor([[x, -0.12, 1.0]], dtype=torch.float64)).vertices

    verts = torch.cat([place(right, 0.3, 0.07), place(left, -0.3, -0.07)], 1)
    topo = MeshTopology.from_faces(torch.cat([right.faces, left.faces + right.num_vertices]))
    xy = Scene.default(SIZE, SIZE).project(verts)[0]
    return xy, topo


def _targets(config):
    xy, topo = config
    yy, xx = torch.meshgrid(torch.arange(SIZE) + 0.5, torch.arange(SIZE) + 0.5, indexing="ij")
    checker = ((((xx + 7) // 24 + (yy + 3) // 24) % 2).double())[None]
    other = shadow_mask((xy - xy.mean(1, keepdim=True)) * 1.15 + xy.mean(1, keepdim=True) + 4, topo, SIZE, SIZE)
    soft = gaussian_blur(other, 3.0)  # an anti-aliased target, like a hand-drawn one
    disc = ((((xx - 120) ** 2 + (yy - 150) ** 2) < 60**2).double())[None]
    return {
        "overlap-binary": lambda m: (m * checker).sum(),
        "overlap-soft": lambda m: (m * soft).sum(),
        "paper-L2": lambda m: ((m - disc) ** 2).sum(),
    }


def _directions(xy, rng):
    c = xy.mean(1, keepdim=True)
    waves = torch.zeros_like(xy)
    for _ in range(3):
        k = torch.as_tensor(rng.normal(size=2) / 30)
        waves += torch.as_tensor(rng.normal(size=2)) * torch.sin((xy * k).sum(-1, keepdim=True) + rng.uniform(0, 6.3))
    dirs = {
        "x": torch.tensor([1.0, 0.0], dtype=torch.float64).expand_as(xy),
        "y": torch.tensor([0.0, 1.0], dtype=torch.float64).expand_as(xy),
        "scale": xy - c,
        "rotate": torch.stack([-(xy - c)[..., 1], (xy - c)[..., 0]], -1),
        "warp": waves,
    }
    return {k: v / v.norm(dim=-1).max() for k, v in dirs.items()}  # at most 1 px per vertex


@pytest.mark.parametrize("loss_name", ["overlap-binary", "overlap-soft", "paper-L2"])
def test_directional_derivatives_match_finite_differences(config, loss_name):
    rng = np.random.default_rng(7)
    xy, topo = config
    loss = _targets(config)[loss_name]
    failures = []
    for name, d in _directions(xy, rng).items():
        analytic, finite = [], []
        for _ in range(JITTERS):
            shifted = xy + torch.as_tensor(rng.uniform(0, 1, 2))
            p = shifted.clone().requires_grad_(True)
            loss(shadow_mask(p, topo, SIZE, SIZE)).backward()
            analytic.append(float((p.grad * d).sum()))
            plus, minus = (
                loss(shadow_mask(shifted + d, topo, SIZE, SIZE)),
                loss(shadow_mask(shifted - d, topo, SIZE, SIZE)),
            )
            finite.append(float(plus - minus) / 2)
        an, fd = np.mean(analytic), np.mean(finite)
        tol = 0.05 * abs(fd) + 3 * np.std(finite) / np.sqrt(JITTERS)
        if abs(an - fd) > tol:
            failures.append(f"{name}: analytic {an:.2f} vs finite {fd:.2f} (tol {tol:.2f})")
    assert not failures, failures


def test_gradient_reaches_only_outline_vertices(config):
    xy, topo = config
    p = xy.clone().requires_grad_(True)
    shadow_mask(p, topo, SIZE, SIZE).sum().backward()
    moved = p.grad.norm(dim=-1)[0] > 0
    assert 0 < moved.sum() < 0.25 * len(moved)  # contour vertices only
    # Growing the shadow everywhere (d area / d outward) is positive: the gradient of the
    # shadow's area points outward on average.
    c = xy.mean(1, keepdim=True)
    assert float((p.grad * (xy - c)).sum()) > 0
