"""Target-reading benchmark: photo-like versions of clean masks, read back.

    python bench/targets.py [MASK_DIR] [--seed 0] [--size 256] [--show N]

For each mask (default: the shared HSP set, ../shared/targets/hsp) the seeded generator in
``handshadow.photos`` makes a photo of it as a shadow on a wall, every effect at a random
strength (tint, hot spot, vignetting up to 50 %, a shadow 40-80 % darker than the wall, soft
edges, sensor noise, JPEG, a slight perspective tilt); the photo is read as ``handshadow fit``
reads a file and compared with the clean mask under the same tilt, both letterboxed into a
size x size frame. Prints one row per mask below the bar or warned, and a last line

    SUMMARY n=95 share_iou_ge_0.95=... median_iou=... warned=... median_read_s=...

The issue's bar: share >= 0.95. Never asserts.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from handshadow import photos
from handshadow.target import read_image, read_shape

BAR_IOU = 0.95


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("masks", nargs="?", default=str(Path(__file__).resolve().parents[2] / "shared/targets/hsp"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", type=int, default=256, help="frame side in pixels (default 256, as fit)")
    parser.add_argument("--show", type=int, default=0, help="write the N worst photos and readings to out/")
    args = parser.parse_args()
    paths = sorted(Path(args.masks).glob("*.png"))
    if not paths:
        sys.exit(f"bench/targets.py: no PNG masks in {args.masks}")
    rows = []
    for k, path in enumerate(paths):
        shape = read_shape(read_image(path)).coverage >= 0.5
        rng = np.random.default_rng([args.seed, k])
        effects = photos.random_effects(rng)
        photo, truth = photos.photo_of(shape, effects, rng)
        t0 = time.perf_counter()
        iou, reading = photos.read_back(photo, truth, args.size)
        seconds = time.perf_counter() - t0
        rows.append((path.stem, iou, reading, seconds, photo))
        if iou < BAR_IOU or reading.warning:
            print(f"{path.stem:22s} iou={iou:.3f} warning={reading.warning or '-'}", flush=True)
    ious = [r[1] for r in rows]
    share = sum(i >= BAR_IOU for i in ious) / len(ious)
    warned = sum(r[2].warning is not None for r in rows)
    if args.show:
        _show(sorted(rows, key=lambda r: r[1])[: args.show], args.size)
    print(
        f"SUMMARY n={len(rows)} share_iou_ge_{BAR_IOU}={share:.3f} median_iou={statistics.median(ious):.3f} "
        f"min_iou={min(ious):.3f} warned={warned} median_read_s={statistics.median(r[3] for r in rows):.3f}"
    )


def _show(rows, size: int) -> None:
    """Each photo beside its reading, for a look."""
    from handshadow.export.files import write_png
    from handshadow.export.images import mask_image
    from handshadow.target import letterbox

    out = Path("out/bench-targets")
    out.mkdir(parents=True, exist_ok=True)
    for name, iou, reading, _, photo in rows:
        frame = letterbox(reading.coverage, size, size) >= 0.5
        write_png(out / f"{name}-photo.png", photo)
        write_png(out / f"{name}-read-{iou:.3f}.png", mask_image(frame))
    print(f"wrote {len(rows)} photos and readings to {out}/")


if __name__ == "__main__":
    main()
