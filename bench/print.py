"""Print benchmark: fitted results -> prints, each checked from its files as a person with a
slicer and a torch would.

    python bench/print.py [RESULT_DIR ...] [--fits out/bench/print] [--height-mm 150]

Without result folders it prints the ten dev targets below, fitting each once with
`handshadow fit --quality fast` into --fits (a folder that already holds a result is reused).
Per result it writes print.stl, print.3mf, print.json and print.png into the result folder and
reports:

- watertight: the STL reloaded as a slicer does (corners merged) is closed, consistently
  wound, of positive volume and one piece;
- cross: edges passing through a triangle (0 for a surface that does not cross itself);
- IoU: the STL's shadow cast with numpy from print.json's lamp onto its wall, against the
  result's shadow.png (bar: >= 0.98 for every result);
- stand px: pixels of the frame that the stand darkens beyond the hands' own shadow (bar: 0);
- thin mm: the hands' thinnest part at this height before thickening, the spots thickened,
  and the thinnest part of the hands as printed;
- triangles and seconds (build and write, this machine).

A result that cannot be printed at this height (thin parts whose thickening would change the
shadow) is a row saying so. Ends with SUMMARY n=<n> refused=<n> watertight=<share of the
printed> min_iou=<x> stand_px=<max> median_s=<x>.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import trimesh

from handshadow.cli import main as handshadow
from handshadow.export import printcheck, printing, solid
from handshadow.metrics import iou

HSP = Path(__file__).resolve().parents[2] / "shared" / "targets" / "hsp"
DEV = ("bird", "rabbit", "dog", "deer", "duck", "eagle", "wolf", "crab", "Heart-1", "spider")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="*", help="result folders (default: fit the dev targets)")
    parser.add_argument("--fits", default="out/bench/print", help="where the dev targets' fits go")
    parser.add_argument("--targets", default=str(HSP), help="folder of the dev targets' images")
    parser.add_argument("--height-mm", type=float, default=150.0)
    args = parser.parse_args()
    folders = [Path(r) for r in args.results] or [
        fitted(Path(args.targets) / f"{n}.png", Path(args.fits) / n) for n in DEV
    ]
    print(
        f"{'result':12s} {'watertight':>10s} {'cross':>5s} {'IoU':>6s} {'stand px':>8s} {'thin mm':>8s} {'thickened':>9s} {'after':>6s} {'triangles':>9s} {'s':>6s}"
    )
    rows = [measure(folder, args.height_mm) for folder in folders]
    printed = [r for r in rows if "refused" not in r]
    n = len(printed)
    print(
        f"SUMMARY n={len(rows)} refused={len(rows) - n} watertight={sum(r['watertight'] for r in printed) / max(n, 1):.2f}"
        f" min_iou={min((r['iou'] for r in printed), default=float('nan')):.3f}"
        f" stand_px={max((r['stand_px'] for r in printed), default=0)}"
        f" median_s={statistics.median(r['seconds'] for r in rows):.1f}"
    )


def fitted(target: Path, folder: Path) -> Path:
    """The folder, after fitting the target into it unless it already holds a result."""
    if not (folder / "scene.json").is_file():
        code = handshadow(["fit", str(target), "--quality", "fast", "--out", str(folder), "--force", "--quiet"])
        if code != 0:
            raise SystemExit(f"fitting {target} failed ({code})")
    return folder


def measure(folder: Path, height_mm: float) -> dict:
    """Print one result folder and check the files; prints and returns its row."""
    started = time.perf_counter()
    result = printing.load_result(folder)
    settings = printing.PrintSettings(height_mm=height_mm)
    try:
        model = printing.build_print(result, settings)
    except printing.PrintError as exc:
        row = {"result": folder.name, "refused": str(exc), "seconds": time.perf_counter() - started}
        print(f"{folder.name:12s} refused: ...{str(exc)[-40:]}", flush=True)
        return row
    report = printing.save_print(model, result, settings, printing.output_paths(folder, None))
    seconds = time.perf_counter() - started
    stl = folder / "print.stl"
    mesh = trimesh.load(stl, force="mesh")
    watertight = bool(
        mesh.is_watertight
        and mesh.is_winding_consistent
        and mesh.volume > 0
        and len(mesh.split(only_watertight=False)) == 1
    )
    vertices, faces, info = printcheck.load_print(stl, folder / "print.json")
    cast = printcheck.cast_shadow(vertices, faces, info)
    hands = printcheck.cast_shadow(*solid.to_arrays(model.hands), info)
    row = {
        "result": folder.name,
        "watertight": watertight,
        "crossing": printcheck.crossing_edges(vertices, faces),
        "iou": iou(cast, result.shadow),
        "stand_px": int((cast & ~hands).sum()),
        "thin_mm": report.thinnest_mm,
        "thickened": report.thickened_spots,
        "thin_after_mm": float(solid.local_thickness(model.hands, 32.0).part.min()),
        "triangles": report.triangles,
        "seconds": seconds,
    }
    print(
        f"{row['result']:12s} {'yes' if watertight else 'NO':>10s} {row['crossing']:5d} {row['iou']:6.3f} {row['stand_px']:8d}"
        f" {row['thin_mm']:8.2f} {row['thickened']:9d} {row['thin_after_mm']:6.2f} {row['triangles']:9d} {seconds:6.1f}",
        flush=True,
    )
    return row


if __name__ == "__main__":
    main()
