"""Command line: arguments -> configuration -> pipeline. No tensor code here.

Every expected failure (bad input, missing files, unusable output folder) ends with a one-line
message on stderr and exit status 2; an interrupt exits with 130.
"""

from __future__ import annotations

import argparse
import logging
import sys

from handshadow import examples
from handshadow.errors import HandshadowError

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


def cmd_render(args: argparse.Namespace) -> int:
    from handshadow.posefile import load_pose_file

    pose_set = load_pose_file(examples.pose_path(args.pose))  # checked before the heavy imports
    from handshadow.pipeline import render_pose_set

    out = render_pose_set(pose_set, args.out, force=args.force, mano_dir=args.mano_dir)
    print(
        f"wrote {out}/: shadow.png scene.png scene.json hands.glb " + " ".join(f"{h.side}.obj" for h in pose_set.hands)
    )
    return 0


def cmd_examples(args: argparse.Namespace) -> int:
    print("Built-in poses (handshadow render NAME --out DIR):")
    for name, about in examples.list_poses():
        print(f"  {name:14s} {about}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="handshadow", description="Hand shadows: find, render and morph poses of your hands."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log details")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("render", help="render a pose file (or a built-in pose) into a result folder")
    p.add_argument("pose", help="pose.json written by 'fit', or the name of a built-in pose")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--force", action="store_true", help="write into a non-empty folder")
    p.add_argument("--mano-dir", help="folder with MANO_RIGHT.pkl / MANO_LEFT.pkl, for poses that use MANO")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("examples", help="list the built-in examples")
    p.set_defaults(func=cmd_examples)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("handshadow: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except HandshadowError as exc:
        print(f"handshadow: error: {exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
