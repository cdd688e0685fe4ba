"""Command line: arguments -> configuration -> pipeline. No tensor code here.

Every expected failure (bad input, missing files, unusable output folder) ends with a one-line
message on stderr and exit status 2; an interrupt (Ctrl-C, or a SIGTERM such as a job
runner's or ``timeout``'s) exits with 130, a fit keeping its best result so far; a batch in
which some targets failed (and the others were fitted) exits with 1.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import os
import signal
import sys
from pathlib import Path

from handshadow import examples
from handshadow.errors import HandshadowError

EXIT_FAILED_TARGETS = 1  # batch: every target was tried, some could not be fitted
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
DEFAULT_VIEW_ANGLE = 90.0  # fit.FitConfig.view_angle_deg


def cmd_render(args: argparse.Namespace) -> int:
    from handshadow.posefile import load_pose_file

    posed = load_pose_file(examples.pose_path(args.pose), frame=args.frame)  # checked before the heavy imports
    if args.hand_shape:
        posed = _held_by(posed, args.hand_shape, args.mano_dir)
    from handshadow.pipeline import render_to_folder, view_name

    out, holding, lines = render_to_folder(posed, args.out, force=args.force, mano_dir=args.mano_dir)
    shadows = " ".join(view_name("shadow", k, len(posed.views)) for k in range(len(posed.views)))
    guide = " guide.png" if len(posed.views) == 1 else ""
    hands = " ".join(f"{h.side}.obj" for h in posed.hands)
    print(f"wrote {out}/: {shadows} scene.png scene.json pose.json hands.glb {hands}{guide}")
    for line in lines:
        print(line)
    print(holding)
    return 0


def _held_by(posed, text: str, mano_dir: str | None):
    """render --hand-shape: the pose held by hands of that build as the guide says
    (guide.held_by); HandshadowError with a one-line reason when the file's lamps allow no such
    move or the build is not one of its hand model's."""
    if posed.scene.light.type != "point" or len(posed.views) > 1:
        raise HandshadowError(
            "--hand-shape moves the wrists along the light of one point lamp; this pose has no such lamp"
        )
    models = {h.model for h in posed.hands}
    if len(models) != 1:
        raise HandshadowError("--hand-shape needs the pose's hands to be of one hand model")
    shape = parse_hand_shape(text, models.pop())
    from handshadow.guide import held_by

    try:
        return held_by(posed, shape, mano_dir)
    except ValueError as exc:
        raise HandshadowError(f"--hand-shape: {exc}") from None


def cmd_examples(args: argparse.Namespace) -> int:
    print("Built-in targets (handshadow fit NAME):")
    for name, about in examples.list_targets():
        print(f"  {name:14s} {about}")
    print("Built-in poses (handshadow render NAME --out DIR):")
    for name, about in examples.list_poses():
        print(f"  {name:14s} {about}")
    print("Classic hand shadows, each with how to hold it (handshadow render NAME --out DIR):")
    for name, about in examples.list_poses(examples.LIBRARY):
        print(f"  {name:14s} {about}")
    return 0


def resolve_device(name: str) -> str:
    """'cpu', 'cuda' (checked) or 'auto' (CUDA when present)."""
    from handshadow.fit import resolve_device as resolve

    return resolve(name)


def cmd_fit(args: argparse.Namespace) -> int:
    from handshadow.export.files import ResultFolder

    check_views(args)
    out = Path(args.out) if args.out else Path("out") / "-".join(Path(t).stem for t in args.target)
    ResultFolder(out, args.force)  # refuse a non-empty folder before any work
    for target in args.target:  # bad targets fail fast, before torch loads
        _check_target(target, args.invert)
    config = _fit_config(args)
    from handshadow.pipeline import fit_to_folder

    sources = args.target[0] if len(args.target) == 1 else args.target
    folder, result, lines = fit_to_folder(
        sources, out, config, force=args.force, invert=args.invert, show_progress=not args.quiet
    )
    s = result.score if len(result.views) == 1 else "every view below"
    if not args.quiet:
        state = "interrupted; best so far" if result.interrupted else ("success" if result.success else "done")
        if not (result.interrupted or result.success) and result.posed.fit.get("time_limited"):
            state = "time limit reached; best so far"
        print(f"{state}: {s}, {result.steps} steps, {result.seconds:.0f} s")
        for line in performance_lines(result):
            print(line)
        for line in lines:
            print(line)
        print(f"results in {folder}/ (guide.png shows how to hold your hands)")
    return EXIT_INTERRUPTED if result.interrupted else 0


def performance_lines(result) -> list[str]:
    """What the CLI says about holding the pose: penetration, arms, performers."""
    pen, arms = result.penetration, result.arms
    if pen.performable():
        held = "within what skin gives"
    elif pen.between_mm >= max(pen.within_mm, default=0.0):
        held = "the hands pass through each other: not performable"
    else:
        held = "fingers pass into their own palm or each other: not performable"
    lines = [f"deepest penetration {pen.deepest_mm:.1f} mm ({held})"]
    if arms.performers > 1:
        lines.append(
            f"the elbows are {arms.span_m:.2f} m apart: more than one person reaches"
            + (" (two performers, as asked)" if result.problem.reach.performers > 1 else "; try --performers 2")
        )
    if not all(arms.leads_back):
        lines.append("a forearm points toward the wall: the elbow should be on your side of the hand")
    if not arms.upper_arms_hidden:
        lines.append("an elbow's shadow falls in the picture: your upper arm may show there too")
    return lines


MAX_TARGETS = 2  # fit.MAX_VIEWS, checked here before torch loads


def check_views(args: argparse.Namespace) -> None:
    """One-line errors for view options that cannot work: too many targets, --view-angle or
    --view-weights without a second target, an angle out of range, weights that do not fit,
    --lamp-distance with two targets."""
    from handshadow.scene import check_view_angle

    n = len(args.target)
    if n > MAX_TARGETS:
        raise HandshadowError(f"give one target, or two targets for two views of one pose (FRONT SIDE); got {n}")
    if n == 1 and (args.view_angle is not None or args.view_weights is not None):
        option = "--view-angle" if args.view_angle is not None else "--view-weights"
        raise HandshadowError(f"{option} needs a second target: handshadow fit FRONT SIDE {option} ...")
    if n > 1:
        if args.lamp_distance is not None:
            raise HandshadowError("--lamp-distance works with one target; two views keep the default lamp distance")
        check_view_angle(args.view_angle if args.view_angle is not None else DEFAULT_VIEW_ANGLE)
        if args.view_weights is not None:
            weights = parse_weights(args.view_weights)
            if len(weights) != n:
                raise HandshadowError(f"--view-weights needs {n} weights (one per target), got {args.view_weights!r}")


def check_time_limit(seconds: float | None, option: str = "--time-limit") -> None:
    """A time limit must be a positive, finite number of seconds (None: no limit)."""
    if seconds is not None and not 0 < seconds < float("inf"):
        raise HandshadowError(f"{option} must be a positive number of seconds, got {seconds:g}")


def parse_weights(text: str) -> tuple[float, ...]:
    """'1,0.5' -> (1.0, 0.5); each weight a positive finite number."""
    try:
        weights = tuple(float(w) for w in text.split(","))
    except ValueError:
        raise HandshadowError(f"--view-weights must be numbers separated by commas, got {text!r}") from None
    if not all(0 < w < float("inf") for w in weights):
        raise HandshadowError(f"--view-weights must be positive, got {text!r}")
    return weights


def _check_target(source: str, invert: bool | None = None) -> None:
    """Read a target once, small, before the heavy imports: an unusable one raises its
    one-line error; an unsure reading prints its one-line warning."""
    from handshadow.target import read_target

    target = read_target(examples.target_path(source), 64, 64, invert)
    if target.warning:
        print(f"handshadow: warning: {source}: {target.warning}", file=sys.stderr)


def _fit_config(args: argparse.Namespace, resolve: bool = True):
    """A FitConfig from the fit options; ``resolve=False`` leaves the device as given (a batch
    resolves it on each worker)."""
    from handshadow.fit import FitConfig, check_seed
    from handshadow.scene import check_lamp_distance

    if args.size < 32 or args.size > 2048:
        raise HandshadowError(f"--size must be between 32 and 2048 pixels, got {args.size}")
    if args.iters is not None and args.iters < 1:
        raise HandshadowError(f"--iters must be positive, got {args.iters}")
    if args.attempts is not None and not 1 <= args.attempts <= 20:
        raise HandshadowError(f"--attempts must be between 1 and 20, got {args.attempts}")
    if args.hops is not None and not 0 <= args.hops <= 20:
        raise HandshadowError(f"--hops must be between 0 and 20, got {args.hops}")
    check_seed(args.seed, "--seed")
    check_time_limit(args.time_limit)
    config = FitConfig(
        hands=args.hands,
        size=args.size,
        iters=args.iters,
        device=resolve_device(args.device) if resolve else args.device,
        seed=args.seed,
        hand_model=args.hand_model,
        mano_dir=args.mano_dir,
        limits=args.limits,
        light=args.light,
        forearm=not args.no_forearm,
        quality=args.quality,
        performers=args.performers,
        attempts=args.attempts,
        hops=args.hops,
        time_limit_s=args.time_limit,
    )
    if args.lamp_distance is not None:
        if args.light != "point":
            raise HandshadowError("--lamp-distance needs a point light (a directional light has no lamp to move)")
        check_lamp_distance(args.lamp_distance)
        config = dataclasses.replace(config, lamp_to_wall_m=args.lamp_distance)
    if getattr(args, "view_angle", None) is not None:
        config = dataclasses.replace(config, view_angle_deg=args.view_angle)
    if getattr(args, "view_weights", None) is not None:
        config = dataclasses.replace(config, view_weights=parse_weights(args.view_weights))
    if getattr(args, "hand_shape", None):
        config = dataclasses.replace(config, hand_shape=parse_hand_shape(args.hand_shape, config.hand_model))
    if config.hand_model == "mano":
        from handshadow.hands import load_rig

        for side in ("right", "left"):
            load_rig("mano", side, config.hand_shape or None, config.mano_dir)
    return config


def parse_hand_shape(text: str, hand_model: str) -> dict:
    """--hand-shape: 'name=value,...' Anny phenotypes (checked) or, for MANO, 'b1,b2,...'
    betas, as FitConfig.hand_shape; raises HandshadowError with a one-line reason."""
    items = [t.strip() for t in text.split(",") if t.strip()]
    named = [t for t in items if "=" in t]
    try:
        if hand_model == "anny":
            if not items or len(named) != len(items):
                raise ValueError("give Anny phenotype values as name=value, e.g. weight=0.8,muscle=0.7")
            from handshadow.hands.anny import normalise_shape

            shape = {k.strip(): _number(v, t) for k, v, t in ((*t.split("=", 1), t) for t in items)}
            normalise_shape(shape)
            return shape
        if not items or named:
            raise ValueError("give MANO betas as numbers, e.g. 0.5,-1.2")
        betas = [_number(t, t) for t in items]
        if len(betas) > 10 or not all(math.isfinite(b) for b in betas):
            raise ValueError(f"give up to 10 finite MANO betas, got {text!r}")
        return {"betas": betas}
    except ValueError as exc:
        raise HandshadowError(f"--hand-shape: {exc}") from None


def _number(text: str, item: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{item!r} does not give a number") from None


def cmd_interpolate(args: argparse.Namespace) -> int:
    from handshadow.export.files import ResultFolder

    out = Path(args.out) if args.out else Path("out") / f"{Path(args.a).stem}-to-{Path(args.b).stem}"
    ResultFolder(out, args.force)
    for source in (args.a, args.b):
        _check_target(source)
    config = _fit_config(args)
    from handshadow.pipeline import interpolate_to_folder

    folder, report = interpolate_to_folder(
        args.a, args.b, out, config, frames=args.frames, force=args.force, show_progress=not args.quiet
    )
    if not args.quiet:
        if report.interrupted:
            print("interrupted: the path as refined so far")
        print(f"results in {folder}/ (animation.mp4, animation.gif, poses.json, path.png, frames/)")
    print(report.summary())
    return EXIT_INTERRUPTED if report.interrupted else 0


def _add_fit_options(
    p: argparse.ArgumentParser,
    hands_default: str = "auto",
    quality_default: str = "default",
    force_help: str = "write into a non-empty folder",
    morph: bool = False,
) -> None:
    """The options of a fit, shared by fit, interpolate (``morph``: a fit for each end) and batch."""
    p.add_argument(
        "--hands",
        default=hands_default,
        choices=["1", "2", "auto"] if hands_default == "auto" else ["1", "2"],
        help=f"number of hands (default: {hands_default})"
        + ("; auto tries both, one hand when it passes the success test" if hands_default == "auto" else ""),
    )
    p.add_argument("--size", type=int, default=256, help="frame height and width in pixels (default 256)")
    p.add_argument("--iters", type=int, help="total optimisation steps (default: set by --quality)")
    p.add_argument(
        "--quality",
        default=quality_default,
        choices=["fast", "default", "best"],
        help=f"search effort (default: {quality_default}); on a 2-core CPU a two-hand fit takes about 14 s fast"
        " (short attempts: a rough look, three in five HSP shapes pass; a far miss ends after one,"
        " a near miss hops and tries again, up to about 4 min), default about 30 s when its first"
        " attempt passes and up to about 7 min when every attempt fails, best longer",
    )
    p.add_argument(
        "--time-limit",
        type=float,
        metavar="SECONDS",
        help=(
            "end each end's fit, and then the path's smoothing, after about this many seconds each, the best so far"
            " finished (the separations follow: a morph takes about three times as long; default: no limit)"
            if morph
            else "end each fit's search, polish and hops after about this many seconds and finish the best so far"
            " (its separation and measuring follow; default: no limit)"
        ),
    )
    p.add_argument("--device", default="auto", help="cpu, cuda or auto (default)")
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the search's random starts (default 0; attempts use seed+1, ...)"
    )
    p.add_argument(
        "--attempts",
        type=int,
        help="fresh starts (seed, seed+1, ...) while the result fails the success test, the best kept; "
        "with default and best an attempt but the last gives up early when it is out of reach "
        "(default: 5 default, 6 best; fast up to 4, a further one only after a near miss; a number given runs in full)",
    )
    p.add_argument(
        "--hops",
        type=int,
        help="from a result within reach of the success test (IoU met, thin parts within 0.05 and HD95 "
        "within 0.03 of their bars), each attempt's fine stages again from jittered copies, the better kept; about 40 s "
        "each at 256 px, the last weighing where the outline fails the HD95 bar (default: 3 fast, 3 default, 4 best)",
    )
    p.add_argument(
        "--hand-model",
        default="anny",
        choices=["anny", "mano"],
        help="anny (default, open and built in) or mano (your own licensed files, with --mano-dir)",
    )
    p.add_argument("--mano-dir", help="folder with MANO_RIGHT.pkl and MANO_LEFT.pkl")
    p.add_argument(
        "--hand-shape",
        metavar="SHAPE",
        help="your hands' build, for a pose your own hands make: Anny phenotype values from 0 to 1,"
        " e.g. weight=0.8,muscle=0.7 (gender, age, muscle, weight, height, proportions; 0.5 each"
        " by default; a new one takes about a minute to build, once), or with --hand-model mano"
        " up to 10 betas, e.g. 0.5,-1.2; the guide says how long the hands are",
    )
    p.add_argument("--limits", default="anatomical", choices=["anatomical", "paper"], help="joint-limit preset")
    p.add_argument(
        "--light",
        default="point",
        choices=["point", "directional"],
        help="point: a lamp (default); directional: sunlight, parallel rays",
    )
    p.add_argument(
        "--lamp-distance",
        type=float,
        metavar="M",
        help="metres from the point lamp to the wall (default 4"
        + ("" if morph else " with one target, 2 with two")
        + "; 2 to 5: a farther lamp casts the same picture with less perspective, from hands farther from the wall"
        + (")" if morph else "; one target only)"),
    )
    p.add_argument("--no-forearm", action="store_true", help="hands without forearms")
    p.add_argument(
        "--performers",
        type=int,
        default=1,
        choices=[1, 2],
        help="people holding the hands (default 1; 2 lifts the limit on how far apart the arms are)",
    )
    p.add_argument("--force", action="store_true", help=force_help)
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="log details")


def cmd_print(args: argparse.Namespace) -> int:
    from handshadow.export.printing import print_result

    report = print_result(
        args.result, out=args.out, height_mm=args.height_mm, stand=not args.no_stand, min_wall_mm=args.min_wall_mm
    )
    for line in report.lines():
        print(line)
    return 0


def cmd_batch(args: argparse.Namespace) -> int:
    from handshadow.batch import find_targets, run_batch

    for flag, value in (("--workers", args.workers), ("--threads-per-worker", args.threads_per_worker)):
        if value is not None and value < 1:
            raise HandshadowError(f"{flag} must be positive, got {value}")
        if value is not None and args.scheduler:
            raise HandshadowError(f"{flag} sizes the local cluster; the workers of --scheduler keep their own")
    targets = find_targets(args.inputs)
    config = _fit_config(args, resolve=False)
    say = (lambda line: None) if args.quiet else print
    try:  # Ctrl-C or SIGTERM (main): finished results kept, cluster shut down
        report = run_batch(
            targets,
            args.out,
            config,
            invert=args.invert,
            force=args.force,
            workers=args.workers,
            threads_per_worker=args.threads_per_worker,
            scheduler=args.scheduler,
            dashboard=args.dashboard,
            show_progress=not args.quiet,
            say=say,
        )
    except KeyboardInterrupt:
        print(
            f"handshadow: interrupted; finished results are kept in {args.out}/ (run the same command to go on)",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    m = report.medians()
    say(f"results in {report.out}/ (index.html, summary.csv)")
    print(
        f"SUMMARY n={m['n']} failed={len(report.failed)} median_iou={m['median_iou']:.3f} "
        f"success={m['success']:.3f} median_s={m['median_s']:.1f}"
    )
    return EXIT_FAILED_TARGETS if report.failed else 0


def cmd_app(args: argparse.Namespace) -> int:
    if args.port is not None and not 0 < args.port < 65536:
        raise HandshadowError(f"--port must be 1..65535, got {args.port}")
    check_time_limit(args.time_limit)
    from handshadow.app import launch

    launch(args.host, args.port, block=True, time_limit_s=args.time_limit)  # prints its address once it listens
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line errors: the reason and where the help is, not the
    whole usage block."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("handshadow")
    except PackageNotFoundError:  # run from a source tree that was not installed
        return "unknown"


def out_path(text: str) -> str:
    """--out's type: any path but an empty one (a shell variable left unset), which would
    otherwise mean the default folder or the current one."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty name: give a folder (or file) name")
    return text


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="handshadow", description="Hand shadows: find, render and morph poses of your hands.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log details")
    parser.add_argument("--version", action="version", version=f"handshadow {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("render", help="render a pose file (or a built-in pose) into a result folder")
    p.add_argument("pose", help="pose.json written by 'fit', or the name of a built-in pose")
    p.add_argument("--out", type=out_path, required=True, help="output folder")
    p.add_argument("--force", action="store_true", help="write into a non-empty folder")
    p.add_argument("--mano-dir", help="folder with MANO_RIGHT.pkl / MANO_LEFT.pkl, for poses that use MANO")
    p.add_argument("--frame", type=int, default=0, help="which frame of a poses.json (from interpolate) to render")
    p.add_argument(
        "--hand-shape",
        metavar="SHAPE",
        help="hold the pose with hands of another build (as fit --hand-shape), each wrist moved along"
        " the light by the hand's size as the guide says: the shadow your own hands cast",
    )
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("fit", help="find hand poses whose shadow matches a target image (or two, from two lamps)")
    p.add_argument(
        "target",
        nargs="+",
        help="an image file (PNG, JPEG, GIF, BMP, WebP, TIFF) or a built-in example name; a second target (SIDE) fits"
        " one pose whose shadow from a second lamp, turned --view-angle about the hands, matches it",
    )
    p.add_argument(
        "--view-angle",
        type=float,
        help=f"degrees the second lamp and wall are turned about the hands (default {DEFAULT_VIEW_ANGLE:g};"
        " 45 to 135 either way, positive to your right)",
    )
    p.add_argument("--view-weights", help="one weight per target, e.g. 1,0.5 (default: equal)")
    p.add_argument("--out", type=out_path, help="output folder (default: out/<target name>)")
    _add_fit_options(p)
    p.add_argument(
        "--invert",
        action="store_true",
        default=None,
        help="the shape is lighter than the ground (overrides the automatic choice)",
    )
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("interpolate", help="morph one hand shadow into another: a pose path to perform")
    p.add_argument("a", help="the first target (image file or built-in example)")
    p.add_argument("b", help="the last target")
    p.add_argument("--frames", type=int, default=30, help="number of frames, ends included (default 30)")
    p.add_argument("--out", type=out_path, help="output folder (default: out/<a>-to-<b>)")
    # Both ends must be good: a morph is judged by them.
    _add_fit_options(p, hands_default="2", quality_default="best", morph=True)
    p.set_defaults(func=cmd_interpolate)

    p = sub.add_parser("print", help="a 3D-printable sculpture of a result's hands, on a stand, with the torch's place")
    p.add_argument("result", help="a result folder written by 'fit' or 'render'")
    p.add_argument("--out", type=out_path, help="the mesh file, .stl or .3mf (default: RESULT/print.stl and print.3mf)")
    p.add_argument("--height-mm", type=float, default=150.0, help="height of the whole print (default 150)")
    p.add_argument("--no-stand", action="store_true", help="the hands alone, without board, foot and rods")
    p.add_argument("--min-wall-mm", type=float, default=1.2, help="thinnest part the printer makes (default 1.2)")
    p.set_defaults(func=cmd_print)

    p = sub.add_parser("batch", help="fit many targets on a Dask cluster (local by default), one folder each")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="image files, folders of images, globs or example names")
    p.add_argument(
        "--out", type=out_path, required=True, help="output folder: OUT/NAME/ per target, summary.csv, index.html"
    )
    p.add_argument("--workers", type=int, help="local cluster: worker processes (default: fitted to cores and memory)")
    p.add_argument(
        "--threads-per-worker", type=int, help="local cluster: threads (torch threads) per worker (default 1)"
    )
    p.add_argument("--scheduler", metavar="ADDRESS", help="use an existing Dask cluster, e.g. tcp://HOST:8786")
    p.add_argument("--dashboard", action="store_true", help="serve the Dask dashboard (needs bokeh)")
    _add_fit_options(p, force_help="fit again the targets whose folders are complete")
    p.add_argument("--invert", action="store_true", default=None, help="the shapes are lighter than the ground")
    p.set_defaults(func=cmd_batch)

    p = sub.add_parser("app", help="a local web page to make hand shadows (needs the [app] extra: Gradio)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1, this computer only)")
    p.add_argument("--port", type=int, help="port (default: 7860 or the next free one)")
    p.add_argument(
        "--time-limit",
        type=float,
        metavar="SECONDS",
        help="end each visitor's fit after about this many seconds, the best so far finished and shown"
        " (a shared computer: one fit runs at a time; default: no limit)",
    )
    p.set_defaults(func=cmd_app)

    p = sub.add_parser("examples", help="list the built-in examples")
    p.set_defaults(func=cmd_examples)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:  # bare `handshadow`: what it can do
        parser.print_help()
        return EXIT_USAGE
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    # A SIGTERM (a job runner's, ``timeout``'s) ends a command as Ctrl-C does: a fit writes its
    # best result so far, a batch keeps its finished targets. Not SIGKILL: nothing can.
    on_term = signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("handshadow: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except HandshadowError as exc:
        print(f"handshadow: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # the reader went away (`handshadow examples | head -1`): nothing more to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        return 0
    finally:
        signal.signal(signal.SIGTERM, on_term)


if __name__ == "__main__":
    sys.exit(main())
