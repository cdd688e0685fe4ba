"""Batch benchmark: `handshadow batch` on a local Dask cluster against the same targets fitted
by sequential `handshadow fit` runs, on the same machine in the same run.

    python bench/batch.py ../shared/targets/hsp [--limit 8] [--names a,b] [--workers 2]
                          [--threads-per-worker 1] [--quality default] [--size 256] [--hands auto]
                          [--out out/bench-batch]

The targets are the --limit images spread over the sorted list, as bench/fit.py picks them.
Both arms are timed as a user sees them (wall clock of the commands, start-up and export
included). Prints a row per target and ends with
RATIO batch_s=<x> sequential_s=<y> ratio=<x/y>   (below 1: the batch is faster)
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

from handshadow.batch import find_targets

CLI = [sys.executable, "-m", "handshadow.cli"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+")
    parser.add_argument("--limit", type=int, default=8, help="this many targets, spread over the sorted list")
    parser.add_argument("--names", help="comma-separated file stems instead of --limit")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--threads-per-worker", type=int, default=1)
    parser.add_argument("--hands", default="auto", choices=["1", "2", "auto"])
    parser.add_argument("--quality", default="default", choices=["fast", "default", "best"])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--out", default="out/bench-batch")
    args = parser.parse_args()
    targets = sorted(find_targets(args.folders), key=lambda t: t.source)
    if args.names:
        wanted = set(args.names.split(","))
        targets = [t for t in targets if t.name in wanted]
    elif args.limit < len(targets):
        n = args.limit
        targets = [targets[round(i * (len(targets) - 1) / (n - 1))] for i in range(n)] if n > 1 else targets[:1]
    out = Path(args.out)
    fit_options = ["--hands", args.hands, "--quality", args.quality, "--size", str(args.size), "--device", "cpu"]
    print(f"{len(targets)} targets: {', '.join(t.name for t in targets)}")
    print(f"fit options: {' '.join(fit_options)}; batch: {args.workers} workers x {args.threads_per_worker} threads")

    sequential = {}
    t0 = time.perf_counter()
    for t in targets:
        t1 = time.perf_counter()
        cmd = CLI + ["fit", t.source, "--out", str(out / "sequential" / t.name), "--force", "--quiet", *fit_options]
        subprocess.run(cmd, check=True)
        fit = json.loads((out / "sequential" / t.name / "pose.json").read_text())["fit"]
        sequential[t.name] = (time.perf_counter() - t1, fit["iou"])
        print(f"  fit {t.name:20s} {sequential[t.name][0]:7.1f} s  IoU {fit['iou']:.3f}", flush=True)
    sequential_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    cmd = CLI + ["batch", *[t.source for t in targets], "--out", str(out / "batch"), "--force", "--quiet"]
    cmd += ["--workers", str(args.workers), "--threads-per-worker", str(args.threads_per_worker), *fit_options]
    subprocess.run(cmd, check=True)
    batch_s = time.perf_counter() - t0
    with (out / "batch" / "summary.csv").open(newline="") as f:
        batch = {r["name"]: r for r in csv.DictReader(f)}

    print(f"{'target':20s} {'fit s':>7s} {'fit IoU':>7s} {'task s':>7s} {'batch IoU':>9s}  worker")
    for t in targets:
        s, iou = sequential[t.name]
        b = batch[t.name]
        print(f"{t.name:20s} {s:7.1f} {iou:7.3f} {float(b['task_s']):7.1f} {float(b['iou']):9.3f}  {b['worker']}")
    print(f"RATIO batch_s={batch_s:.1f} sequential_s={sequential_s:.1f} ratio={batch_s / sequential_s:.3f}")


if __name__ == "__main__":
    main()
