"""Where an attempt stands after each stage: the data behind search.config.GiveUp.

    python bench/stage_reach.py ../shared/targets/hsp [--names a,b] [--seed 0] [--hands 2]
                                [--stages 3] [--out out/stage_reach.jsonl]

For each target, one attempt of the default fit (seed --seed, one torch thread) runs its first
--stages stages; after each stage but the last of the search, its surviving hypotheses are
measured at full resolution (IoU, HD95, thin-part recall), as search.stages.out_of_reach sees
them. Prints per target and stage the best IoU and the best HD95 among the survivors, and
whether GiveUp would stop the attempt there; writes every survivor's measures as one JSON line
per target. The fit is deterministic, so the outcome of the same attempt run to its end
(`bench/fit.py --attempts 1`) tells which stopped attempts would have passed.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from handshadow.fit import GIVE_UP, FitConfig, _prepare, resolve_device, view_scenes
from handshadow.search import stages as stages_module
from handshadow.target import load_target


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    parser.add_argument("--names", help="comma-separated file stems to run (a subset)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--hands", type=int, default=2, choices=(1, 2))
    parser.add_argument(
        "--stages", type=int, default=3, help="stages to run (the survivors of all but the last are measured)"
    )
    parser.add_argument("--out", default="out/stage_reach.jsonl")
    args = parser.parse_args()
    torch.set_num_threads(1)
    paths = sorted(Path(args.folder).glob("*.png"))
    if args.names:
        wanted = set(args.names.split(","))
        paths = [p for p in paths if p.stem in wanted]
    give_up = GIVE_UP["default"]
    seen: list[dict] = []
    layered = stages_module.layered

    def measured(problem, poses):  # run_stages calls this with each stage's survivors
        rows = [
            {"iou": v.iou, "hd95": v.hd95, "thin": v.thin_recall} for v in (s.scores[0] for s in problem.scores(poses))
        ]
        seen.append({"out_of_reach": stages_module.out_of_reach(problem, poses, give_up), "survivors": rows})
        return layered(problem, poses)

    stages_module.layered = measured
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    print(f"{len(paths)} targets, seed {args.seed}, GiveUp after stage {give_up.after_stage}")
    with out.open("w") as f:
        for path in paths:
            config = FitConfig(hands=str(args.hands), seed=args.seed, attempts=1, device=resolve_device("auto"))
            target = load_target(path)
            seen.clear()
            t0 = time.perf_counter()
            problem, starts, stages = _prepare([target], view_scenes([target], config), args.hands, config, None, None)
            stages_module.run_stages(problem, starts, stages[: args.stages])
            cells = [
                f"{max(r['iou'] for r in st['survivors']):.3f}/{min(r['hd95'] for r in st['survivors']):.3f}"
                + (" stop" if k == give_up.after_stage and st["out_of_reach"] else "")
                for k, st in enumerate(seen)
            ]
            print(f"{path.stem:24s} {time.perf_counter() - t0:6.1f}s  " + "  ".join(cells), flush=True)
            f.write(json.dumps({"name": path.stem, "seed": args.seed, "stages": seen}) + "\n")


if __name__ == "__main__":
    main()
