"""Other people's hands: how a fit's shadow carries over to hands of another size.

For every result folder under DIR (pose.json and target.png, as `handshadow fit` or
`bench/fit.py` writes them), the same pose is held by Anny's people of other sizes and builds
(phenotypes, hands.anny; their forearms in proportion, HandRig.size), each wrist either where the
fit put it ("as is") or moved as the guide says (a hand k times as long, its wrist k times as far
from the lamp, along the light: "moved"). Each shadow is compared with the fit's own (IoU) and
judged against the target by the success test.

    python bench/handsize.py DIR [--names a,b] [--people gender1,smaller]

Prints one row per result and person and
SUMMARY person=<name> k=<size> n=<n> as_is_iou=<median> moved_iou=<median> success_fit=<share>
success_as_is=<share> success_moved=<share>
The first phenotype of a run builds Anny (about a minute here); the rigs are cached after that.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
from pathlib import Path

from handshadow.errors import HandshadowError
from handshadow.guide import held_by
from handshadow.hands import load_rig
from handshadow.hands.posed import cast_shadow
from handshadow.metrics import iou, score
from handshadow.posefile import load_pose_file
from handshadow.target import load_target

# Anny phenotypes (0..1, 0.5 the default) of people other than the default one, named by
# what they set (Anny's hands change mostly in size with them: bench's k column).
PEOPLE = {
    "gender1": {"gender": 1.0},
    "gender0": {"gender": 0.0},
    "taller": {"height": 0.8},
    "heavier": {"weight": 0.8, "muscle": 0.8, "height": 0.8},
    "younger": {"age": 0.3},
    "smaller": {"age": 0.3, "height": 0.3},
}


def as_built(posed, shape: dict):
    """The pose file's hands with another build, each wrist where the fit put it."""
    return dataclasses.replace(posed, hands=tuple(dataclasses.replace(h, shape=dict(shape)) for h in posed.hands))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dir", help="a folder of result folders (or one result folder)")
    parser.add_argument("--names", default="", help="comma-separated result names (default: all)")
    parser.add_argument("--people", default=",".join(PEOPLE), help=f"of {', '.join(PEOPLE)}")
    args = parser.parse_args()
    root = Path(args.dir)
    folders = [root] if (root / "pose.json").is_file() else sorted(p.parent for p in root.glob("*/pose.json"))
    if args.names:
        wanted = set(args.names.split(","))
        folders = [f for f in folders if f.name in wanted]
    people = [p for p in args.people.split(",") if p]
    unknown = [p for p in people if p not in PEOPLE]
    if not folders or unknown:
        raise SystemExit(f"no result folders under {root}" if not folders else f"unknown people: {', '.join(unknown)}")
    print(
        f"{'result':22s} {'person':9s} {'k':>5s} {'IoU as is':>9s} {'IoU moved':>9s} {'fit':>4s} {'as is':>5s} {'moved':>5s}"
    )
    rows = {p: [] for p in people}
    for folder in folders:
        try:
            posed = load_pose_file(folder / "pose.json")
            target = load_target(folder / "target.png", posed.scene.image.width, posed.scene.image.height)
        except HandshadowError as exc:
            print(f"{folder.name:22s} skipped: {exc}")
            continue
        if posed.scene.light.type != "point" or len(posed.views) > 1:
            print(f"{folder.name:22s} skipped: the guide's move needs one point lamp")
            continue
        own = cast_shadow(posed)[1] > 0.5
        fit_ok = score(own, target).success
        for person in people:
            shape = PEOPLE[person]
            k = load_rig(posed.hands[0].model, posed.hands[0].side, shape).size
            row = dict(k=k, fit=fit_ok)
            for label, move in (("as_is", False), ("moved", True)):
                held = held_by(posed, shape) if move else as_built(posed, shape)
                try:
                    mask = cast_shadow(held)[1] > 0.5
                except HandshadowError:  # the moved hands reach the wall or the lamp
                    row[label], row[f"{label}_ok"] = 0.0, False
                    continue
                row[label], row[f"{label}_ok"] = iou(mask, own), score(mask, target).success
            rows[person].append(row)
            print(
                f"{folder.name:22s} {person:9s} {k:5.3f} {row['as_is']:9.3f} {row['moved']:9.3f} "
                f"{'yes' if fit_ok else 'no':>4s} {'yes' if row['as_is_ok'] else 'no':>5s} "
                f"{'yes' if row['moved_ok'] else 'no':>5s}",
                flush=True,
            )
    for person, found in rows.items():
        if not found:
            continue
        n = len(found)
        print(
            f"SUMMARY person={person} k={found[0]['k']:.3f} n={n} "
            f"as_is_iou={statistics.median(r['as_is'] for r in found):.3f} "
            f"moved_iou={statistics.median(r['moved'] for r in found):.3f} "
            f"success_fit={sum(r['fit'] for r in found) / n:.3f} "
            f"success_as_is={sum(r['as_is_ok'] for r in found) / n:.3f} "
            f"success_moved={sum(r['moved_ok'] for r in found) / n:.3f}"
        )


if __name__ == "__main__":
    main()
