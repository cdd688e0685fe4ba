"""CUDA check: the renderer and the fit run unchanged on a GPU and agree with the CPU.

    python bench/cuda_check.py

Prints, for random two-hand poses at 256 x 256 (batch 8), how many shadow pixels differ between
CPU and CUDA and the relative difference of the vertex gradients, then times a default fit of
two built-in examples on CUDA. Needs a CUDA device.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from handshadow.fit import FitConfig, fit_frame
from handshadow.hands import load_hand
from handshadow.pipeline import resolve_target
from handshadow.render import ShadowRenderer
from handshadow.scene import Scene


def parity() -> None:
    torch.manual_seed(0)
    scene = Scene.default(256, 256)
    results = {}
    pose = torch.rand(8, 15, 3) * torch.tensor([0.1, 0.3, 1.2]) - torch.tensor([0.05, 0.15, 0.1])
    trans = [torch.tensor([[x, -0.1, 1.0]]).expand(8, 3) + torch.randn(8, 3) * 0.02 for x in (0.07, -0.07)]
    target = None
    for device in ("cpu", "cuda"):
        hands = [load_hand("anny", s, dtype=torch.float64, device=device) for s in ("right", "left")]
        renderer = ShadowRenderer(scene, [h.faces for h in hands], [h.num_vertices for h in hands]).to(device)
        verts = [
            h(pose.double().to(device), None, t.double().to(device)).vertices.detach().requires_grad_(True)
            for h, t in zip(hands, trans)
        ]
        mask = renderer(verts)
        if target is None:
            target = torch.roll(mask.detach().cpu(), shifts=(3, -2), dims=(1, 2))
        ((mask - target.to(device)) ** 2).sum().backward()
        results[device] = (mask.detach().cpu(), torch.cat([v.grad.cpu() for v in verts], 1))
    m_cpu, g_cpu = results["cpu"]
    m_gpu, g_gpu = results["cuda"]
    differ = int((m_cpu != m_gpu).sum())
    rel = float((g_cpu - g_gpu).norm() / g_cpu.norm().clamp(min=1e-12))
    print(
        f"parity (float64, 8 x 256 x 256): {differ} of {m_cpu.numel()} shadow pixels differ; gradient relative difference {rel:.2e}"
    )


def fits() -> None:
    for name in ("bird", "dog"):
        target = resolve_target(name, 256, 256)
        t0 = time.perf_counter()
        result = fit_frame(target, FitConfig(hands="2", device="cuda"))
        torch.cuda.synchronize()
        s = result.score
        print(
            f"fit {name} on CUDA: IoU {s.iou:.3f}, HD95 {s.hd95:.3f}, thin {s.thin_recall:.2f}, success {s.success}, {time.perf_counter() - t0:.1f} s"
        )


if __name__ == "__main__":
    if not torch.cuda.is_available():
        raise SystemExit("no CUDA device")
    print("GPU:", torch.cuda.get_device_name(0), "torch", torch.__version__)
    parity()
    fits()
    print(np.__version__)
