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

    python bench/targets.py [MASK_DIR] --aspects

instead frames each mask whose shape runs off its picture (bench/recover.py's targets with
forearms, say) as a phone's photo of another aspect would show it: 16:9 with wall added left and
right (masks clear of both sides) and 3:4 with wall added above (masks clear of the top), and
compares each frame with the square picture's (``target.frame_picture``): IoU after aligning
the shapes' corners, and whether the shape meets the same frame edges. Last lines ``SUMMARY
aspect=16:9 n=... same_edges=... median_iou=... min_iou=...``. (A shape clear of its
picture's sides is letterboxed as it always was.)
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
    parser.add_argument("--aspects", action="store_true", help="frame 16:9 and 3:4 pictures of the masks instead")
    args = parser.parse_args()
    paths = sorted(Path(args.masks).glob("*.png"))
    if not paths:
        sys.exit(f"bench/targets.py: no PNG masks in {args.masks}")
    if args.aspects:
        _aspects(paths, args.size)
        return
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


def _aspects(paths: list[Path], size: int) -> None:
    """Each mask whose shape runs off its picture, framed from a 16:9 picture (wall left and
    right; masks clear of both sides) and a 3:4 one (wall above; masks clear of the top), against
    its square picture's frame: IoU once their shapes' corners meet, and the frame edges the
    shape meets."""
    from handshadow.metrics import iou
    from handshadow.target import frame_picture

    def edges(frame):
        return frame[0].any(), frame[-1].any(), frame[:, 0].any(), frame[:, -1].any()

    results = {"16:9": [], "3:4": []}
    for path in paths:
        coverage = read_shape(read_image(path)).coverage
        shape = coverage >= 0.5
        if not any(edges(shape)):
            continue  # clear of its picture's sides: letterboxed as it always was
        h, w = coverage.shape
        pictures = {}
        if not (shape[:, 0].any() or shape[:, -1].any()):
            pictures["16:9"] = np.pad(coverage, ((0, 0), ((16 * h // 9 - w) // 2,) * 2))
        if not shape[0].any():
            pictures["3:4"] = np.pad(coverage, ((4 * w // 3 - h, 0), (0, 0)))
        square = frame_picture(coverage, size, size) >= 0.5
        for aspect, picture in pictures.items():
            frame = frame_picture(picture, size, size) >= 0.5
            (sy, sx), (fy, fx) = (np.argwhere(a).min(axis=0) for a in (square, frame))
            score = iou(np.roll(frame, (sy - fy, sx - fx), axis=(0, 1)), square)
            results[aspect].append((path.stem, score, edges(frame) == edges(square)))
    for aspect, rows in results.items():
        for name, score, same in rows:
            if score < 0.99 or not same:
                print(f"{aspect:5s} {name:22s} iou={score:.3f} same_edges={same}")
        ious = [r[1] for r in rows] or [float("nan")]
        print(
            f"SUMMARY aspect={aspect} n={len(rows)} same_edges={sum(r[2] for r in rows)} "
            f"median_iou={statistics.median(ious):.3f} min_iou={min(ious):.3f}"
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
