"""Renderer benchmark: forward + backward of the exact shadow of two hands with forearms.

    python bench/render.py [--quick] [--devices cpu,cuda]

Per resolution (256, 512, 1024), batch (1, 16) and device it prints the median milliseconds of
  render        projection + exact shadow + L2 loss + backward to the vertices;
  hands+render  the same plus posing both hands (LBS) and backward to the joint angles,
and the peak memory: CUDA allocator peak, or on the CPU the rise of the process's peak RSS
over the set-up (each configuration runs in its own process). The last line is
render_ms_256=<median render ms, two hands, batch 1, CPU>.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time

import numpy as np
import torch

SIZES = (256, 512, 1024)
BATCHES = (1, 16)


def run_config(size: int, batch: int, device: str, iters: int) -> dict:
    from handshadow.hands import load_hand
    from handshadow.render import ShadowRenderer
    from handshadow.scene import Scene

    torch.manual_seed(0)
    hands = [load_hand("anny", side, device=device) for side in ("right", "left")]
    scene = Scene.default(size, size)
    renderer = ShadowRenderer(scene, [h.faces for h in hands], [h.num_vertices for h in hands]).to(device)
    pose = (torch.rand(batch, 15, 3, device=device) * torch.tensor([0.1, 0.2, 1.0], device=device)).requires_grad_(True)
    rot = torch.eye(3, device=device).expand(batch, 3, 3)
    trans = [torch.tensor([[x, -0.12, 1.0]], device=device).expand(batch, 3) for x in (0.08, -0.08)]
    with torch.no_grad():
        target = renderer([h(pose * 0.5, rot, t).vertices for h, t in zip(hands, trans)])
        verts = [h(pose, rot, t).vertices for h, t in zip(hands, trans)]

    def render_only():
        v = [x.detach().requires_grad_(True) for x in verts]
        loss = ((renderer(v) - target) ** 2).sum()
        loss.backward()

    def hands_and_render():
        pose.grad = None
        v = [h(pose, rot, t).vertices for h, t in zip(hands, trans)]
        loss = ((renderer(v) - target) ** 2).sum()
        loss.backward()

    def timed(fn):
        for _ in range(3):
            fn()
        out = []
        for _ in range(iters):
            if device == "cuda":
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            fn()
            if device == "cuda":
                torch.cuda.synchronize()
            out.append((time.perf_counter() - t0) * 1000)
        return statistics.median(out)

    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    render_ms = timed(render_only)
    full_ms = timed(hands_and_render)
    if device == "cuda":
        peak_mib = torch.cuda.max_memory_allocated() / 2**20
    else:
        peak_mib = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) / 1024
    return dict(size=size, batch=batch, device=device, render_ms=render_ms, full_ms=full_ms, peak_mib=peak_mib)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer iterations")
    parser.add_argument("--devices", default="cpu,cuda")
    parser.add_argument("--one", help=argparse.SUPPRESS)  # internal: size,batch,device,iters
    args = parser.parse_args()
    if args.one:
        size, batch, device, iters = args.one.split(",")
        torch.set_num_threads(min(torch.get_num_threads(), 16))
        print(json.dumps(run_config(int(size), int(batch), device, int(iters))))
        return
    devices = [d for d in args.devices.split(",") if d == "cpu" or torch.cuda.is_available()]
    gpu = torch.cuda.get_device_name(0) if "cuda" in devices else None
    print(f"two Anny hands with forearms ({2 * 1950} vertices, {2 * 3896} triangles); torch {torch.__version__}")
    print(f"CPU threads: {torch.get_num_threads()}" + (f"; GPU: {gpu}" if gpu else ""))
    print(f"{'device':6s} {'size':>5s} {'batch':>5s} {'render ms':>10s} {'hands+render ms':>16s} {'peak MiB':>9s}")
    rows = []
    for device in devices:
        for size in SIZES:
            for batch in BATCHES:
                work = size * size * batch / 256**2
                iters = max(5, int((10 if args.quick else 40) / max(1.0, work**0.5)))
                res = subprocess.run(
                    [sys.executable, __file__, "--one", f"{size},{batch},{device},{iters}"],
                    capture_output=True,
                    text=True,
                    check=True,
                )
                row = json.loads(res.stdout.strip().splitlines()[-1])
                rows.append(row)
                print(
                    f"{device:6s} {size:5d} {batch:5d} {row['render_ms']:10.2f} {row['full_ms']:16.2f} {row['peak_mib']:9.1f}",
                    flush=True,
                )
    base = [r for r in rows if r["device"] == "cpu" and r["size"] == 256 and r["batch"] == 1]
    print(f"render_ms_256={np.round(base[0]['render_ms'], 2) if base else 'nan'}")


if __name__ == "__main__":
    main()
