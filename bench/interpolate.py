"""Morph benchmark: run `handshadow interpolate` on pairs of targets and check the issue's bars.

    python bench/interpolate.py [A:B ...] [--frames 30] [--quality best] [--out out/bench_morph]

A pair is two targets (image files or built-in example names) joined by a colon; the default
is the built-in rabbit and bird. Each pair's result folder goes to --out/<k>_<a>-to-<b>. Prints one
row per pair (the command's SUMMARY values, its seconds, and which bars it misses) and ends with
SUMMARY pairs=<n> bars_met=<n> median_s=<x>

The bars: both ends pass the success test of shared/notes/metrics.md with IoU >= 0.85,
max_step_deg <= 10, no penetrating frame, the whole run within 10 minutes.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import torch

from handshadow.fit import FitConfig
from handshadow.metrics import SUCCESS_HD95, SUCCESS_IOU, SUCCESS_THIN
from handshadow.pipeline import interpolate_to_folder

END_IOU, MAX_STEP_DEG, MAX_SECONDS = 0.85, 10.0, 600.0


def missed_bars(rep, seconds: float) -> list[str]:
    """The names of the bars a run misses (empty: all met)."""
    missed = ["interrupted"] if rep.interrupted else []
    for end, iou, thin, hd in (
        ("start", rep.iou_start, rep.thin_start, rep.hd95_start),
        ("end", rep.iou_end, rep.thin_end, rep.hd95_end),
    ):
        if iou < max(END_IOU, SUCCESS_IOU):
            missed.append(f"iou_{end}")
        if thin < SUCCESS_THIN:
            missed.append(f"thin_{end}")
        if hd > SUCCESS_HD95:
            missed.append(f"hd95_{end}")
    if rep.max_step_deg > MAX_STEP_DEG:
        missed.append("max_step")
    if rep.penetrating_frames:
        missed.append("penetration")
    if seconds > MAX_SECONDS:
        missed.append("time")
    return missed


def _label(source: str) -> str:
    """'rabbit' for a built-in example, 'hsp/rabbit' for an image file."""
    path = Path(source)
    return f"{path.parent.name}/{path.stem}" if path.suffix else source


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="*", default=["rabbit:bird"], help="A:B pairs (default rabbit:bird)")
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--hands", default="2", choices=["1", "2"])
    parser.add_argument("--quality", default="best", choices=["fast", "default", "best"])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", default="out/bench_morph", help="folder for the result folders")
    args = parser.parse_args()
    pairs = []
    for pair in args.pairs:
        a, sep, b = pair.rpartition(":")
        if not sep or not a or not b:
            parser.error(f"a pair is A:B, got {pair!r}")
        pairs.append((a, b))
    config = FitConfig(hands=args.hands, size=args.size, quality=args.quality, device=args.device)
    print(
        f"{len(pairs)} pairs, frames={args.frames}, hands={args.hands}, quality={args.quality}, "
        f"size={args.size}, device={args.device}, torch threads={torch.get_num_threads()}"
    )
    head = ("iou_a", "iou_b", "thin_a", "thin_b", "hd95_a", "hd95_b", "step", "pen", "s")
    print(f"{'pair':28s} " + " ".join(f"{h:>7s}" for h in head) + "  missed")
    seconds, met = [], 0
    for k, (a, b) in enumerate(pairs, 1):
        name = f"{_label(a)}-to-{_label(b)}"
        t0 = time.perf_counter()
        folder = Path(args.out) / f"{k}_{name.replace('/', '_')}"
        _, rep = interpolate_to_folder(a, b, folder, config, frames=args.frames, force=True, show_progress=False)
        s = time.perf_counter() - t0
        seconds.append(s)
        missed = missed_bars(rep, s)
        met += not missed
        values = (rep.iou_start, rep.iou_end, rep.thin_start, rep.thin_end)
        print(
            f"{name:28s} "
            + " ".join(f"{v:7.3f}" for v in values)
            + f" {rep.hd95_start:7.4f} {rep.hd95_end:7.4f} {rep.max_step_deg:7.2f} {rep.penetrating_frames:7d}"
            + f" {s:7.1f}  {', '.join(missed) or '-'}",
            flush=True,
        )
        print(f"  {rep.summary()}", flush=True)
        if rep.interrupted:  # Ctrl-C during the path refinement: this row is partial, stop here
            print("interrupted: the row above is the path as refined so far")
            break
    print(f"SUMMARY pairs={len(pairs)} bars_met={met} median_s={statistics.median(seconds):.1f}")


if __name__ == "__main__":
    main()
