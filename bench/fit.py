"""Fit benchmark: fit every image in the given folders with default settings and judge each
result as docs/metrics.md defines (IoU, boundary F1 at 2 px, HD95, thin-part recall,
success). It runs on `handshadow batch` (Dask), so it scales out with --workers or --scheduler.

    python bench/fit.py ../shared/targets/hsp [--limit N] [--names a,b] [--hands 2] [--out out/bench]
                        [--workers N] [--threads-per-worker T] [--scheduler tcp://HOST:8786] [--resume]
                        [--fits-only] [--sheets-only] [--no-forearm] [--lamp-distance M] [--hops N] [--attempts N] [--skip-attempts N]
                        [--hand-shape SHAPE]

Prints one row per target as it finishes: the shadow's measures, the deepest penetration
between or within the hands (pen, mm, exact on the meshes), whether the pose can be held
(perf), whether the shadow alone passes (shadow) and the success test (ok: shadow and
performable), then the fit's other measures (whatever pose.json's "fit" holds) as key=value.
It writes a contact sheet (target | shadow | overlay per row, contact_sheet.png), one of
successes beside failures (contact_pairs.png, up to PAIR_ROWS of each spread over their IoU,
named and measured: the README's), the result folders (NAME/), summary.csv, index.html and a
JSON of the rows to --out; --sheets-only writes the two sheets again from --out's rows. The targets whose frame has a hole
of at least HOLE_SHARE of its area (found in each written target.png) are listed as a group.
It ends with
SUMMARY n=<n> median_iou=<x> success=<share> shadow_success=<share> performable_success=<share>
        penetrating_share=<share over 3 mm> median_s=<x> holes_n=<n> holes_success=<share>
With --fits-only it runs the fits alone in --workers local processes (fit.fit_frame, the same
measures, no result folders, no contact sheet): on a small machine writing one result folder
(progress GIF, pictures, meshes) slows the other worker's fit.
(success and performable_success are the same number: this project's success test counts a
result only when it is performable; s: the fit's own seconds, as `handshadow fit` reports
them, without start-up or export.)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from scipy import ndimage

from handshadow.batch import find_targets, run_batch
from handshadow.cli import parse_hand_shape
from handshadow.errors import HandshadowError
from handshadow.fit import FitConfig, attempts_of, hops_of, skipped_attempts
from handshadow.hands.penetration import TOLERANCE_MM as PENETRATION_TOLERANCE_MM
from handshadow.scene import FIT_LAMP_TO_WALL_M

#: Columns of the table; every other measure of the fit is printed after them as key=value.
TABLE = {"iou": "IoU", "boundary_f1": "F1@2", "hd95": "HD95", "thin_recall": "thin"}
NOT_MEASURES = {"name", "hands", "success", "seconds", "worker", "error", "status", "attempts", "task_s", "source"}
NOT_MEASURES |= {"iterations", "seed", "limits", "quality", "interrupted", "penetration_mm", "performable"}
NOT_MEASURES |= {"shadow_success"}
#: contact_pairs.png shows at most this many successes and as many failures.
PAIR_ROWS = 8
#: A target belongs to the holes group when a hole of its frame covers at least this share of it.
HOLE_SHARE = 0.005


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", help="folders of images (or images, globs)")
    parser.add_argument("--limit", type=int, help="at most this many targets (spread over the sorted list)")
    parser.add_argument("--hands", default="auto", choices=["1", "2", "auto"])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--quality", default="default", choices=["fast", "default", "best"])
    parser.add_argument("--names", help="comma-separated file stems to run (a subset)")
    parser.add_argument("--out", default="out/bench", help="folder for the results, contact sheet and rows")
    parser.add_argument("--device", default="auto", help="cpu, cuda or auto (default: CUDA when present)")
    parser.add_argument(
        "--no-forearm", action="store_true", help="hands without forearms (handshadow fit --no-forearm)"
    )
    parser.add_argument(
        "--lamp-distance",
        type=float,
        default=None,
        help="metres from lamp to wall (handshadow fit --lamp-distance)",
    )
    parser.add_argument("--hops", type=int, default=None, help="hops from a near miss (handshadow fit --hops)")
    parser.add_argument("--attempts", type=int, default=None, help="fresh starts (handshadow fit --attempts)")
    parser.add_argument(
        "--skip-attempts",
        type=int,
        default=0,
        help="run only the attempts after the first N (their starts left out as if searched): a further"
        " attempt measured on an earlier run's failures alone",
    )
    parser.add_argument("--hand-shape", help="the hands' build (handshadow fit --hand-shape), e.g. height=0.8")
    parser.add_argument("--workers", type=int, default=1, help="local Dask workers, each fitting one target at a time")
    parser.add_argument("--threads-per-worker", type=int, help="torch threads per worker (default: cores / workers)")
    parser.add_argument("--scheduler", help="an existing Dask cluster instead of a local one")
    parser.add_argument("--resume", action="store_true", help="keep complete result folders in --out (default: refit)")
    parser.add_argument("--fits-only", action="store_true", help="fit and judge in local processes, write no folders")
    parser.add_argument(
        "--sheets-only", action="store_true", help="write the contact sheets again from --out's rows.json, fit nothing"
    )
    args = parser.parse_args()
    if args.sheets_only:
        rows_file = Path(args.out) / "rows.json"
        if not rows_file.is_file():
            parser.error(f"no rows.json in {args.out}: run the bench with --out {args.out} first")
        write_sheets(Path(args.out), json.loads(rows_file.read_text()))
        return
    targets = sorted(find_targets(args.folders), key=lambda t: t.source)
    if args.names:
        wanted = set(args.names.split(","))
        targets = [t for t in targets if t.name in wanted]
    if args.limit and args.limit < len(targets):
        targets = (
            [targets[round(i * (len(targets) - 1) / (args.limit - 1))] for i in range(args.limit)]
            if args.limit > 1
            else targets[:1]
        )
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    threads = args.threads_per_worker or max(1, cores // args.workers)
    where = args.scheduler or f"{args.workers} workers x {threads} torch threads"
    print(
        f"{len(targets)} targets, hands={args.hands}, size={args.size}, quality={args.quality}, device={args.device},"
        f" forearms={'no' if args.no_forearm else 'yes'}, lamp {args.lamp_distance or FIT_LAMP_TO_WALL_M:g} m, {where}"
    )
    print(
        f"{'target':24s} {'IoU':>6s} {'F1@2':>6s} {'HD95':>6s} {'thin':>6s} {'pen':>5s} {'perf':>4s} {'shadow':>6s}"
        f" {'ok':>3s} {'s':>6s}",
        flush=True,
    )
    config = FitConfig(
        hands=args.hands,
        size=args.size,
        quality=args.quality,
        device=args.device,
        forearm=not args.no_forearm,
        lamp_to_wall_m=args.lamp_distance,
        hops=args.hops,
        attempts=args.attempts,
        skip_attempts=args.skip_attempts,
    )
    try:  # a bad count fails here in one line, not in every worker
        attempts_of(config), hops_of(config), skipped_attempts(config)
        if args.hand_shape:
            config = dataclasses.replace(config, hand_shape=parse_hand_shape(args.hand_shape, config.hand_model))
    except HandshadowError as e:
        parser.error(str(e))
    if args.fits_only:
        fits_only(targets, config, args.workers, threads)
        return
    report = run_batch(
        targets,
        args.out,
        config,
        force=not args.resume,
        workers=None if args.scheduler else args.workers,
        threads_per_worker=None if args.scheduler else threads,
        scheduler=args.scheduler,
        show_progress=False,
        say=lambda line: None,
        on_row=print_row,
    )
    out = Path(args.out)
    rows = report.fitted
    (out / "rows.json").write_text(json.dumps(rows, indent=1))
    write_sheets(out, rows)
    holes = [r for r in rows if largest_hole_share(out / r["name"] / "target.png") >= HOLE_SHARE]
    print(f"results: {out / 'index.html'}")
    _summary(rows, holes)


def write_sheets(out: Path, rows: list[dict]) -> None:
    """contact_sheet.png (every row) and contact_pairs.png (successes | failures) in ``out``."""
    rows = [r for r in rows if r.get("status") != "failed" and (out / r["name"] / "overlay.png").is_file()]
    if not rows:
        return
    iio.imwrite(out / "contact_sheet.png", np.concatenate([_sheet_row(out / r["name"], r["success"]) for r in rows], 0))
    iio.imwrite(out / "contact_pairs.png", _pairs_sheet(out, rows))
    print(f"contact sheets: {out / 'contact_sheet.png'}, {out / 'contact_pairs.png'}")


def _spread(rows: list[dict], n: int) -> list[dict]:
    """At most n of rows, spread evenly over them sorted by IoU (best first)."""
    rows = sorted(rows, key=lambda r: -r["iou"])
    if len(rows) <= n:
        return rows
    return [rows[round(i * (len(rows) - 1) / (n - 1))] for i in range(n)] if n > 1 else rows[:1]


def _pairs_sheet(out: Path, rows: list[dict], n: int = PAIR_ROWS) -> np.ndarray:
    """Successes (left) beside failures (right), each row target | shadow | overlay under a
    line naming the target and its IoU, HD95 and thin-part recall; a title above each side."""
    from PIL import Image, ImageDraw

    sides = [_spread([r for r in rows if r["success"]], n), _spread([r for r in rows if not r["success"]], n)]
    tiles = [[_labelled(out, r) for r in side] for side in sides]
    h, w = max(t.shape[0] for side in tiles for t in side), max(t.shape[1] for side in tiles for t in side)
    gap, head = 12, 22
    sheet = np.full((head + max(map(len, tiles)) * h, 2 * w + gap, 3), 255, np.uint8)
    for c, side in enumerate(tiles):
        for i, tile in enumerate(side):
            sheet[head + i * h : head + i * h + tile.shape[0], c * (w + gap) : c * (w + gap) + tile.shape[1]] = tile
    image = Image.fromarray(sheet)
    draw = ImageDraw.Draw(image)
    ok = sum(bool(r["success"]) for r in rows)
    titles = (f"successes: {ok} of {len(rows)}", f"failures: {len(rows) - ok} of {len(rows)}")
    for c, title in enumerate(titles):
        draw.text((c * (w + gap) + 4, 5), title + f" (showing {len(sides[c])}, spread over IoU)", fill=(0, 0, 0))
    return np.asarray(image)


def _labelled(out: Path, row: dict, tile: int = 128) -> np.ndarray:
    """A sheet row of a result folder under a line of its name and measures."""
    from PIL import Image, ImageDraw

    body = _sheet_row(out / row["name"], row["success"], tile)
    label = Image.new("RGB", (body.shape[1], 16), (255, 255, 255))
    text = f"{row['name']}  IoU {row['iou']:.3f}  HD95 {row['hd95']:.3f}  thin {row['thin_recall']:.2f}"
    ImageDraw.Draw(label).text((4, 2), text, fill=(0, 0, 0))
    return np.concatenate([np.asarray(label), body], 0)


def fits_only(targets, config: FitConfig, workers: int, threads: int) -> None:
    """Fit and judge every target in ``workers`` local processes of ``threads`` torch threads
    each; print a row per target as it finishes and the SUMMARY."""
    from concurrent.futures import ProcessPoolExecutor, as_completed

    rows, holes = [], []
    with ProcessPoolExecutor(workers, initializer=_set_threads, initargs=(threads,)) as pool:
        jobs = [pool.submit(_fit_one, t.name, t.source, config) for t in targets]
        for job in as_completed(jobs):
            row, hole = job.result()
            print_row(row)
            rows.append(row)
            if hole >= HOLE_SHARE:
                holes.append(row)
    _summary(rows, holes)


def _set_threads(threads: int) -> None:
    import torch

    torch.set_num_threads(threads)


def _fit_one(name: str, source: str, config: FitConfig) -> tuple[dict, float]:
    from handshadow.fit import fit_frame
    from handshadow.pipeline import resolve_target

    target = resolve_target(source, config.size, config.size)
    result = fit_frame(target, config)
    return {"name": name, "status": "done", **result.posed.fit}, largest_hole_share(target)


def _summary(rows: list[dict], holes: list[dict]) -> None:
    print(f"holes group (a hole of at least {HOLE_SHARE:.1%} of the frame): {len(holes)} targets")
    for r in holes:
        print(f"  {r['name']:22s} {r['iou']:6.3f} {'yes' if r['success'] else 'no'}")
    share = lambda rs, key: sum(bool(r[key]) for r in rs) / len(rs) if rs else float("nan")  # noqa: E731
    median = lambda key: float(np.median([r[key] for r in rows])) if rows else float("nan")  # noqa: E731
    penetrating = [r for r in rows if float(r.get("penetration_mm") or 0.0) > PENETRATION_TOLERANCE_MM]
    print(
        f"SUMMARY n={len(rows)} median_iou={median('iou'):.3f} success={share(rows, 'success'):.3f} "
        f"shadow_success={share(rows, 'shadow_success'):.3f} performable_success={share(rows, 'success'):.3f} "
        f"penetrating_share={len(penetrating) / max(len(rows), 1):.2f} median_s={median('seconds'):.1f} "
        f"holes_n={len(holes)} holes_success={share(holes, 'success'):.3f}"
    )
    sys.stdout.flush()


def largest_hole_share(frame) -> float:
    """The largest hole of a target frame (a bool array, or a written target.png) (a
    background region that does not reach the frame's edge) as a share of the frame's area;
    0 without holes."""
    if isinstance(frame, np.ndarray):
        shape = frame.astype(bool)
    else:
        grey = iio.imread(frame)
        shape = (grey if grey.ndim == 2 else grey[..., :3].mean(-1)) < 128  # target.png: black shape on white
    labels, n = ndimage.label(~shape)
    if n == 0:
        return 0.0
    edge = set(np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])))
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    inner = [sizes[k] for k in range(1, n + 1) if k not in edge]
    return max(inner, default=0) / shape.size


def print_row(row: dict) -> None:
    if row["status"] == "failed":
        print(f"{row['name']:24s} skipped: {row['error']}", flush=True)
        return
    table = " ".join(f"{row[k]:6.3f}" if k != "thin_recall" else f"{row[k]:6.2f}" for k in TABLE)
    extra = " ".join(f"{k}={v}" for k, v in row.items() if k not in NOT_MEASURES and k not in TABLE and v != "")
    ok = "yes" if row["success"] else "no"
    pen = f"{float(row.get('penetration_mm') or 0.0):5.1f}"
    perf = "yes" if row.get("performable") else "no"
    shadow = "yes" if row.get("shadow_success") else "no"
    print(
        f"{row['name']:24s} {table} {pen} {perf:>4s} {shadow:>6s} {ok:>3s} {row['seconds']:6.1f} {extra}".rstrip(),
        flush=True,
    )


def _sheet_row(folder: Path, success: bool, tile: int = 128) -> np.ndarray:
    """target | shadow | overlay of a result folder, ``tile`` pixels high, with a green or
    red bar on top."""
    from skimage.transform import resize

    def small(name: str) -> np.ndarray:
        img = iio.imread(folder / name)
        img = np.repeat(img[..., None], 3, -1) if img.ndim == 2 else img[..., :3]
        size = (tile, tile * img.shape[1] // img.shape[0])
        return (resize(img.astype(float) / 255, size, order=1, anti_aliasing=True) * 255).astype(np.uint8)

    row = np.concatenate([small(name) for name in ("target.png", "shadow.png", "overlay.png")], 1)
    row[:3, :, :] = (60, 170, 60) if success else (200, 60, 60)  # a green or red bar per row
    return row


if __name__ == "__main__":
    main()
