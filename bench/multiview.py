"""Multi-view benchmark: one pose, two shadows (view 1 turned --view-angle about the hands).

    python bench/multiview.py [--recovery 20] [--art 10] [--size 256] [--quality default]
                              [--out out/bench_multiview]

- recovery: random two-hand poses a person can hold (RECOVERY_RULE), rendered in two views,
  fitted with two hands; the success test (docs/metrics.md) per view. Bar: both views
  succeed on >= 90 %.
- art: pairs of shared HSP targets chosen by ART_RULE, fitted with two hands; success per view
  and in both views; a contact sheet (target, shadow, overlay for each view per row).
- time: every two-view fit is followed by a single-view fit of its view 0 target with the same
  settings, timed in the same run. Bar: median two-view time <= 3 x median single-view time.

Prints one row per fit and ends with
SUMMARY recovery_both=<share> art_both=<share> art_view0=<share> art_view1=<share>
median_s=<x> median_single_s=<x> ratio=<x>
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import recover  # bench/recover.py: this folder is on sys.path when the bench runs
import torch

from handshadow.export.images import overlay_image
from handshadow.fit import FitConfig, arm_check, fit_frame, make_problem
from handshadow.poses import HandPoseBatch, PoseBatch
from handshadow.scene import RESULT_MARGIN_M, VIEW_AXIS_POINT_M, default_views
from handshadow.search import ViewTarget
from handshadow.target import load_target

HSP = Path(__file__).resolve().parents[1] / ".." / "shared" / "targets" / "hsp"
RECOVERY_RULE = (
    "bench/recover.py's generator (never the search's starts): joint angles uniform within the"
    " limits, both wrists near the vertical axis the views turn about, each forearm within 70"
    " degrees of the direction between the two lamps; redrawn until every vertex lies between each"
    " lamp and its wall, both forearms lead back from both walls, no vertex is 3 mm inside other"
    " flesh, the hands' shadows keep 3 px inside both frames and each covers 4 to 45 % of its frame"
)
ART_RULE = (
    "the N HSP targets sorted by name; 2n of them evenly spread (index round(j * N / 2n),"
    " j = 0..2n-1); pair i fronts the i-th and sides the (n + i)-th, half the list further on"
)
MAX_DRAWS = 200
TIME_BAR = 3.0
SIDES = (("right", 1.0), ("left", -1.0))
RECOVERY_BAR = 0.9


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recovery", type=int, default=20, help="random poses (default 20)")
    parser.add_argument("--art", type=int, default=10, help="HSP pairs (default 10)")
    parser.add_argument("--seed", type=int, default=2026, help="the random poses' generator")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--quality", default="default", choices=["fast", "default", "best"])
    parser.add_argument("--view-angle", type=float, default=90.0)
    parser.add_argument("--hsp", default=str(HSP), help="folder of HSP targets")
    parser.add_argument("--out", default="out/bench_multiview")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    config = FitConfig(
        hands="2", size=args.size, quality=args.quality, device=args.device, view_angle_deg=args.view_angle
    )
    print(
        f"size={args.size} quality={args.quality} view_angle={args.view_angle:g} device={args.device}"
        f" torch threads={torch.get_num_threads()}"
    )
    print(f"recovery rule: {RECOVERY_RULE}\nart rule: {ART_RULE}")
    print(
        f"{'fit':28s} {'view 0 (IoU thin HD95)':>24s} {'view 1 (IoU thin HD95)':>24s} {'both':>4s} {'s':>6s} {'1-view s':>8s}"
    )
    rows = []
    rng = np.random.default_rng(args.seed)
    for k in range(args.recovery):
        targets = recovery_targets(rng, config)
        rows.append(run("recovery", f"pose {k:02d}", targets, config))
        _save(out, rows)
    for front, side in art_pairs(Path(args.hsp), args.art):
        targets = [load_target(p, args.size, args.size) for p in (front, side)]
        rows.append(run("art", f"{front.stem}+{side.stem}", targets, config))
        _save(out, rows)
    for kind in ("recovery", "art"):
        tiles = [r.pop("tile") for r in rows if r["kind"] == kind]
        if tiles:
            iio.imwrite(out / f"contact_sheet_{kind}.png", np.concatenate(tiles, 0))
    print(summary(rows))


def recovery_targets(rng: np.random.Generator, config: FitConfig) -> list[np.ndarray]:
    """The two views' shadows (H, W) bool of a random pose (RECOVERY_RULE)."""
    scenes = default_views(config.size, config.size, config.light, (0.0, config.view_angle_deg))
    blank = np.zeros((config.size, config.size), bool)
    problem = make_problem(blank, scenes[0], ["right", "left"], config, None, [ViewTarget(scenes[1], blank)])
    axis = np.asarray(VIEW_AXIS_POINT_M)
    lamps = [np.asarray(s.light.position) - axis for s in scenes]
    back = np.sum([lamp / np.linalg.norm(lamp) for lamp in lamps], axis=0)
    back /= np.linalg.norm(back)
    for _ in range(MAX_DRAWS):
        middle = axis + rng.normal(0, 0.04, 3)
        offset = rng.normal(0, 1, 3) * np.array([1.0, 0.6, 1.0])
        offset *= rng.uniform(0.06, recover.MAX_WRIST_GAP_M / 2) / np.linalg.norm(offset)
        hands = tuple(recover.random_hand(side, rng, middle + sign * offset, back) for side, sign in SIDES)
        poses = PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in hands])
        if _keeps_the_rules(problem, poses):
            masks = [m[0] for m in problem.view_masks(poses)]
            if all(recover.AREA_SHARE[0] <= m.mean() <= recover.AREA_SHARE[1] for m in masks):
                return masks
    raise RuntimeError(f"no holdable pose in {MAX_DRAWS} draws")


def _keeps_the_rules(problem, poses: PoseBatch) -> bool:
    """Every vertex between each lamp and its wall, forearms leading back from both walls, no
    vertex 3 mm inside other flesh, the hands' shadows EDGE_PX inside both frames."""
    vertices = np.concatenate([o.vertices[0].double().numpy() for o in problem.pose(poses.hands)])
    keypoints = torch.cat([o.keypoints[0] for o in problem.pose(poses.hands)])
    for view in problem.views:
        lo, hi = view.scene.light_depth_range()
        heights = (vertices - np.asarray(view.scene.wall.point)) @ np.asarray(view.scene.wall.normal)
        xy, _ = view.scene.project(keypoints.double())
        if heights.min() <= lo + RESULT_MARGIN_M or heights.max() >= hi - RESULT_MARGIN_M:
            return False
        if float(xy.min()) < recover.EDGE_PX or float(xy.max()) > view.scene.image.height - recover.EDGE_PX:
            return False
    return all(arm_check(problem, poses).leads_back) and problem.mesh_penetration(poses)[0].performable()


def art_pairs(folder: Path, n: int) -> list[tuple[Path, Path]]:
    """ART_RULE: n (front, side) pairs of the folder's images, sorted by name."""
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".png")
    spread = [files[round(j * len(files) / (2 * n))] for j in range(2 * n)]
    return list(zip(spread[:n], spread[n:]))


def run(kind: str, name: str, targets: list[np.ndarray], config: FitConfig) -> dict:
    """A two-view fit and a single-view fit of view 0's target, timed; a printed row."""
    t0 = time.perf_counter()
    result = fit_frame(targets, config)
    seconds = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit_frame(targets[0], config)
    single_s = time.perf_counter() - t0
    scores = [v.score for v in result.views]
    row = {
        "kind": kind,
        "name": name,
        "views": [s.as_dict() for s in scores],
        "both": all(s.success for s in scores),
        "performable": result.performable,
        "seconds": seconds,
        "single_seconds": single_s,
        "tile": _sheet_row(result, name),
    }
    cells = [f"{s.iou:.3f} {s.thin_recall:.2f} {s.hd95:.3f}{'*' if s.success else ' '}" for s in scores]
    both = "yes" if row["both"] else "no"
    print(
        f"{kind[:3]} {name:24s} {cells[0]:>24s} {cells[1]:>24s} {both:>4s} {seconds:6.1f} {single_s:8.1f}", flush=True
    )
    return row


def summary(rows: list[dict]) -> str:
    def share(selected, test):
        return sum(test(r) for r in selected) / len(selected) if selected else float("nan")

    rec = [r for r in rows if r["kind"] == "recovery"]
    art = [r for r in rows if r["kind"] == "art"]
    median = statistics.median(r["seconds"] for r in rows) if rows else float("nan")
    single = statistics.median(r["single_seconds"] for r in rows) if rows else float("nan")
    parts = [
        f"recovery_both={share(rec, lambda r: r['both']):.2f}",
        f"art_both={share(art, lambda r: r['both']):.2f}",
        f"art_view0={share(art, lambda r: r['views'][0]['success']):.2f}",
        f"art_view1={share(art, lambda r: r['views'][1]['success']):.2f}",
        f"median_s={median:.1f}",
        f"median_single_s={single:.1f}",
        f"ratio={median / single:.2f}",
    ]
    bars = f"bars: recovery >= {RECOVERY_BAR:.0%} both views, time ratio <= {TIME_BAR:g}"
    return f"{bars}\nSUMMARY " + " ".join(parts)


def _sheet_row(result, name: str, tile: int = 128) -> np.ndarray:
    """target, shadow, overlay per view, side by side; a green or red bar per view."""
    from skimage.transform import resize

    def small(image):
        return (resize(image.astype(float), (tile, tile), order=1, anti_aliasing=True) * 255).astype(np.uint8)

    cells = []
    for view in result.views:
        grey = [np.stack([255 - small(m)] * 3, -1) for m in (view.target, view.shadow)]
        overlay = small(overlay_image(view.target, view.shadow) / 255.0)
        block = np.concatenate([*grey, overlay, np.full((tile, 6, 3), 255, np.uint8)], 1)
        block[:3] = (60, 170, 60) if view.score.success else (200, 60, 60)
        cells.append(block)
    return np.concatenate(cells, 1)


def _save(out: Path, rows: list[dict]) -> None:
    (out / "rows.json").write_text(json.dumps([{k: v for k, v in r.items() if k != "tile"} for r in rows], indent=1))


if __name__ == "__main__":
    main()
