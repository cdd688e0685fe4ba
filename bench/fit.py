"""Fit benchmark: fit every image in the given folders with default settings and judge each
result as docs/metrics.md defines (IoU, boundary F1 at 2 px, HD95, thin-part recall,
success).

    python bench/fit.py ../shared/targets/hsp [--limit N] [--hands 2] [--out out/bench]

Prints one row per target, writes a contact sheet (target | shadow | overlay per row), each
shadow (shadows/NAME.png) and a JSON of the rows to --out, and ends with
SUMMARY n=<n> median_iou=<x> success=<share> median_s=<x>
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import torch

from handshadow.export.images import overlay_image
from handshadow.fit import FitConfig, fit_frame
from handshadow.target import TargetError, load_target

EXTENSIONS = {".png", ".jpg", ".jpeg", ".gif", ".bmp"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+")
    parser.add_argument("--limit", type=int, help="at most this many targets (spread over the sorted list)")
    parser.add_argument("--hands", default="auto", choices=["1", "2", "auto"])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--quality", default="default", choices=["fast", "default", "best"])
    parser.add_argument("--names", help="comma-separated file stems to run (a subset)")
    parser.add_argument("--out", default="out/bench", help="folder for the contact sheet and rows")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    files = sorted(p for folder in args.folders for p in Path(folder).iterdir() if p.suffix.lower() in EXTENSIONS)
    if args.names:
        wanted = set(args.names.split(","))
        files = [f for f in files if f.stem in wanted]
    if args.limit and args.limit < len(files):
        files = (
            [files[round(i * (len(files) - 1) / (args.limit - 1))] for i in range(args.limit)]
            if args.limit > 1
            else files[:1]
        )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(
        f"{len(files)} targets, hands={args.hands}, size={args.size}, quality={args.quality}, device={args.device}, torch threads={torch.get_num_threads()}"
    )
    print(f"{'target':24s} {'IoU':>6s} {'F1@2':>6s} {'HD95':>6s} {'thin':>6s} {'ok':>3s} {'s':>6s}")
    rows, tiles = [], []
    for path in files:
        try:
            target = load_target(path, args.size, args.size)
        except TargetError as exc:
            print(f"{path.stem:24s} skipped: {exc}")
            continue
        t0 = time.perf_counter()
        result = fit_frame(
            target, FitConfig(hands=args.hands, size=args.size, quality=args.quality, device=args.device)
        )
        seconds = time.perf_counter() - t0
        s = result.score
        row = {
            "target": str(path),
            "iou": s.iou,
            "f1": s.boundary_f1,
            "hd95": s.hd95,
            "thin": s.thin_recall,
            "success": s.success,
            "seconds": seconds,
            "hands": len(result.posed.hands),
        }
        rows.append(row)
        print(
            f"{path.stem:24s} {s.iou:6.3f} {s.boundary_f1:6.3f} {s.hd95:6.3f} {s.thin_recall:6.2f} {'yes' if s.success else 'no':>3s} {seconds:6.1f}",
            flush=True,
        )
        tiles.append(_sheet_row(target, result.shadow, path.stem, s.success))
        (out / "shadows").mkdir(exist_ok=True)
        iio.imwrite(out / "shadows" / f"{path.stem}.png", np.where(result.shadow, 0, 255).astype(np.uint8))
        (out / "rows.json").write_text(json.dumps(rows, indent=1))
    if tiles:
        iio.imwrite(out / "contact_sheet.png", np.concatenate(tiles, 0))
    n = len(rows)
    median_iou = statistics.median(r["iou"] for r in rows) if rows else float("nan")
    success = sum(r["success"] for r in rows) / n if n else float("nan")
    median_s = statistics.median(r["seconds"] for r in rows) if rows else float("nan")
    print(f"contact sheet: {out / 'contact_sheet.png'}")
    print(f"SUMMARY n={n} median_iou={median_iou:.3f} success={success:.3f} median_s={median_s:.1f}")
    sys.stdout.flush()


def _sheet_row(target: np.ndarray, shadow: np.ndarray, name: str, success: bool, tile: int = 128) -> np.ndarray:
    from skimage.transform import resize

    def small(img):
        return (
            resize(img.astype(float), (tile, tile * img.shape[1] // img.shape[0]), order=1, anti_aliasing=True) * 255
        ).astype(np.uint8)

    t = 255 - small(target)
    s = 255 - small(shadow)
    grey = [np.stack([x] * 3, -1) for x in (t, s)]
    ov = (resize(overlay_image(target, shadow).astype(float) / 255, (tile, grey[0].shape[1]), order=1) * 255).astype(
        np.uint8
    )
    row = np.concatenate(grey + [ov], 1)
    row[:3, :, :] = (60, 170, 60) if success else (200, 60, 60)  # a green or red bar per row
    return row


if __name__ == "__main__":
    main()
