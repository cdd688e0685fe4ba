"""The fit on a CUDA device, simulated on the CPU (tests/simulated_cuda.py): CI has no GPU,
and a CPU run cannot show a tensor left on the CPU that meets one on the GPU."""

import contextlib
import copy

import numpy as np
import pytest
import torch

from handshadow.cli import main
from handshadow.fit import FitConfig, make_problem
from handshadow.poses import HandPoseBatch
from handshadow.render import ShadowRenderer
from handshadow.scene import Scene
from handshadow.search.config import Stage
from handshadow.search.objective import objective
from handshadow.search.pieces import Partner
from tests.simulated_cuda import on_cuda, simulated_cuda
from tests.test_fit import known_target


class _Doubles(torch.autograd.Function):
    """A custom backward that builds a tensor on the CPU, as a device bug would."""

    @staticmethod
    def forward(ctx, x):
        ctx.save_for_backward(x)
        return x * 2

    @staticmethod
    def backward(ctx, grad):
        return grad * torch.full(grad.shape, 2.0)  # on the CPU, whatever grad's device


def test_the_simulation_raises_where_cuda_would():
    is_available = torch.cuda.is_available
    with simulated_cuda():
        assert torch.cuda.is_available()
        gpu = torch.arange(4.0, device="cuda")
        cpu = torch.arange(4.0)
        assert on_cuda(gpu * 2) and on_cuda(gpu[torch.tensor([1, 2])]) and not on_cuda(gpu.cpu())
        assert float((gpu + torch.tensor(1.0)).sum()) == 10.0  # CPU scalars mix, as on CUDA
        with pytest.raises(RuntimeError, match="same device"):
            gpu + cpu
        with pytest.raises(TypeError, match="numpy"):
            np.asarray(gpu)
        with pytest.raises(RuntimeError, match="indices"):
            cpu[gpu.long()]
        with pytest.raises(RuntimeError, match="generator"):
            torch.randn(3, device="cuda", generator=torch.Generator().manual_seed(0))
        leaf = torch.ones(3, device="cuda", requires_grad=True)
        with pytest.raises(RuntimeError, match="same device"):
            _Doubles.apply(leaf).sum().backward()  # custom backwards are checked too
        leaf.grad = None
        (leaf * 3).sum().backward()
        assert on_cuda(leaf.grad)
    assert torch.cuda.is_available is is_available  # undone on leaving


def test_the_renderer_on_simulated_cuda_casts_the_cpu_shadow_and_gradient(hands64):
    torch.manual_seed(0)
    scene = Scene.default(64, 64)
    hand = hands64["right"]
    pose = torch.rand(2, 15, 3, dtype=torch.float64) * 0.4
    trans = torch.tensor([[0.0, -0.1, 1.0]], dtype=torch.float64).expand(2, 3)
    results = []
    for simulated in (False, True):
        device = "cuda" if simulated else "cpu"
        with simulated_cuda() if simulated else contextlib.nullcontext():
            renderer = ShadowRenderer(scene, [hand.faces], [hand.num_vertices]).to(device)
            verts = (
                copy.deepcopy(hand)
                .to(device)(pose.to(device), None, trans.to(device))
                .vertices.detach()
                .requires_grad_(True)
            )
            mask = renderer([verts])
            assert on_cuda(mask) == simulated
            target = torch.roll(mask.detach(), 2, 1)
            ((mask - target) ** 2).sum().backward()
            results.append((mask.detach().cpu(), verts.grad.cpu()))
    (m0, g0), (m1, g1) = results
    assert torch.equal(m0, m1) and torch.allclose(g0, g1)
    assert float(g0.abs().sum()) > 0


def test_fit_command_on_simulated_cuda_writes_its_result(tmp_path):
    """The whole command, search, checks and export, on the (simulated) GPU's wider schedule."""
    out = tmp_path / "dog"
    args = "fit dog --hands 1 --size 96 --quality fast --iters 30 --attempts 1 --quiet --device cuda --out".split()
    with simulated_cuda():
        assert main([*args, str(out)]) == 0
    assert {"pose.json", "shadow.png", "overlay.png", "hands.glb", "guide.png"} <= {p.name for p in out.iterdir()}


def test_a_hand_searched_alone_keeps_its_reach_to_a_partner_on_simulated_cuda():
    """The reach term against the other hand of a target in two pieces (search.pieces.Partner),
    its wrist and elbow on the GPU, as fit._piece_search builds it."""
    target, truth = known_target("dog", 64)
    with simulated_cuda():
        problem = make_problem(target, truth.scene, ["right"], FitConfig(size=64, device="cuda"))
        hand = HandPoseBatch.from_hand_poses([truth.hands[0]], device="cuda")
        with torch.no_grad():
            elbow = problem.pose([hand])[0].forearm_points[0, -1]
        partner = Partner(hand.translation[0] + torch.tensor([0.0, 0.0, 0.7], device="cuda"), elbow)
        problem = make_problem(target, truth.scene, ["right"], FitConfig(size=64, device="cuda"), partner=partner)
        terms, _ = objective(problem, [hand], Stage(height=64, blur_px=0, attract_px=0, steps=1, keep=1))
        assert on_cuda(terms.reach) and float(terms.reach[0].cpu()) > 0.0
