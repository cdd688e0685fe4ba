"""Recovery benchmark: shadows that hands made, fitted back. It measures the search alone:
every target is the exact shadow of a random, anatomically valid, performable pose of two
hands (or of one with --hands 1; with forearms, or without with --no-forearm) at a random
place between lamp and wall. With --target-shape the hands that cast the targets are of another
build (Anny phenotypes), each wrist moved along the light by the hand's size as the guide says,
and the fit keeps the default hand: shadows that another person's hands made.

    python bench/recover.py [--n 40] [--seed 2026] [--hands 2] [--no-forearm] [--quality default]
                            [--out out/recover] [--part K/N] [--target-shape weight=0.8,muscle=0.8]

--part K/N fits only the targets k with k % N == K (all are still drawn, so each keeps its pose):
N processes with K = 0 .. N-1, e.g. on one GPU, share the work; each writes rows-K-of-N.json.

The poses come from their own generator (uniform joint angles within the limits, any
orientation whose forearm leads back toward the lamp, hands within a person's reach), never
from the search's starts. A pose is kept only if it is performable (no vertex more than 3 mm
inside other flesh: the other hand's, or a finger inside its own palm or another finger; and
arms a person can hold: each forearm leads back toward the performer, docs/performing.md) and
its shadow lies well inside the frame. Each target
is fitted with the defaults (FitConfig(), hands auto: with --hands 1 the fit must find that one
hand does) and judged by the success test. With --hands 1 each target's hand is the right or
the left one at random. Runs before 2026-12-06's stop 54 also kept poses with a forearm
leading toward the wall (12 of the 40 two-hand targets with forearms), and runs before
2026-12-07's stop 56 poses with fingers more than 3 mm inside their own palm or each other, which
no fit may return (27 of the 40 with forearms, 26 of the 40 without); their targets differ.
Prints one row per target and
SUMMARY n=<n> success=<share> performable_success=<share> median_iou=<x> median_s=<x>
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import torch

from handshadow.cli import parse_hand_shape
from handshadow.errors import HandshadowError
from handshadow.export.images import mask_image
from handshadow.fit import FitConfig, fit_frame
from handshadow.guide import held_by
from handshadow.hands.limits import joint_limits_deg, wrist_limits_deg
from handshadow.hands.posed import arm_check, cast_shadow, hand_models, pose_penetration
from handshadow.poses import HandPose, PosedScene
from handshadow.scene import FIT_LAMP_TO_WALL_M, LAMP_TO_WALL_M, Scene

SIZE = 256
DEPTH_M = (0.85, 1.25)  # wrist distance from a lamp 2 m from the wall (scaled with the fit's lamp)
ARM_CONE_DEG = 70.0  # forearms within this angle of the ray back toward the lamp
MAX_WRIST_GAP_M = 0.3
AREA_SHARE = (0.04, 0.45)  # the shadow's share of the frame
EDGE_PX = 3  # the hands' shadow keeps this far from the frame's border (forearms may leave)


def random_hand(side: str, rng: np.random.Generator, centre: np.ndarray, back: np.ndarray | None = None) -> HandPose:
    """A hand with joint angles uniform within the anatomical limits (bends skewed toward
    straight, as people hold shadow hands), the wrist anywhere within its limits, the forearm
    within ARM_CONE_DEG of the ray back toward the lamp (or of the unit vector ``back``, e.g.
    toward a performer between two lamps), rolled any way."""
    lim = joint_limits_deg("anatomical", side)
    pose = rng.uniform(lim[..., 0], lim[..., 1])
    pose[:, 2] = lim[:, 2, 0] + (lim[:, 2, 1] - lim[:, 2, 0]) * rng.uniform(0, 1, 15) ** 1.5
    wrist = rng.uniform(*wrist_limits_deg().T)
    tilt = np.radians(ARM_CONE_DEG) * np.sqrt(rng.uniform())
    azimuth = rng.uniform(0, 2 * np.pi)
    arm = np.array([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)])
    if back is not None:
        arm = _turn_z_to(np.asarray(back, float)) @ arm
    fingers = -arm + rng.normal(0, 0.5, 3)  # the hand frame's +y, roughly away from the forearm
    fingers /= np.linalg.norm(fingers)
    back = rng.normal(size=3)
    back -= fingers * (back @ fingers)
    back /= np.linalg.norm(back)
    rotation = np.stack([np.cross(fingers, back), fingers, back], 1)
    return HandPose(side, "anny", {}, pose, rotation, centre, wrist)


def _turn_z_to(axis: np.ndarray) -> np.ndarray:
    """(3, 3) the rotation that takes +z to the unit vector axis (about their common normal)."""
    z = np.array([0.0, 0.0, 1.0])
    normal = np.cross(z, axis)
    sin, cos = float(np.linalg.norm(normal)), float(z @ axis)
    if sin < 1e-12:
        return np.eye(3) if cos > 0 else np.diag([1.0, -1.0, -1.0])
    k = normal / sin
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + sin * cross + (1 - cos) * cross @ cross


def random_target(
    rng: np.random.Generator,
    forearm: bool,
    tries: int = 200,
    n_hands: int = 2,
    shape: dict | None = None,
    lamp_m: float = FIT_LAMP_TO_WALL_M,
) -> tuple[PosedScene, np.ndarray]:
    """A performable pose of ``n_hands`` hands (2: right and left; 1: either) whose shadow lies
    well inside the frame, and the shadow. Performable: no vertex more than 3 mm inside other
    flesh (the other hand's, or its own hand's: a fingertip in the palm), and arms one person
    can hold by the rules every fit keeps (hands.arms: each forearm leads back toward the performer, the elbows within one person's span); the cone the
    forearm is drawn in, tilted by the hand's own turn and the wrist's bend, does not ensure it. ``shape``: the hands' build (Anny phenotypes; None:
    the default hand); a hand k times the default's length (HandRig.size) stands k times as far
    from the lamp, so the draws, and the shadows' sizes, are those of the default hand.
    ``lamp_m``: the lamp's distance from the wall (default: the one a default fit uses)."""
    scene = Scene.default(SIZE, SIZE, lamp_to_wall_m=lamp_m)
    lamp = np.asarray(scene.light.position)
    for _ in range(tries):
        depth = rng.uniform(*DEPTH_M) * lamp_m / LAMP_TO_WALL_M  # the same sizes of shadow
        middle = lamp + np.array([rng.normal(0, 0.04), rng.normal(0, 0.04), -depth])
        offset = rng.normal(0, 1, 3) * np.array([1.0, 0.6, 0.3])
        offset *= rng.uniform(0.06, MAX_WRIST_GAP_M / 2) / np.linalg.norm(offset)
        if n_hands == 1:
            side = "right" if rng.uniform() < 0.5 else "left"
            hands = (random_hand(side, rng, middle + offset),)
        else:
            hands = (random_hand("right", rng, middle + offset), random_hand("left", rng, middle - offset))
        posed = PosedScene(hands, scene, forearm)
        if shape:  # another build, held as the guide says
            posed = held_by(posed, shape)
        try:
            meshes, mask = cast_shadow(posed)
        except Exception:  # through the wall or the lamp: draw again
            continue
        shadow = mask > 0.5
        if not AREA_SHARE[0] <= shadow.mean() <= AREA_SHARE[1]:
            continue
        hands_xy = scene.project(torch.as_tensor(np.concatenate([m.keypoints for m in meshes])))[0].numpy()
        if hands_xy.min() < EDGE_PX or hands_xy.max() > SIZE - EDGE_PX:
            continue
        models = hand_models(posed)
        # No hand into the other, or a finger into its own palm, past what skin gives; each
        # forearm leads back toward its performer: what a fit's result must keep.
        if not pose_penetration(posed, meshes, models=models).performable():
            continue
        if not arm_check(posed, models=models).holdable():
            continue
        return posed, shadow
    raise RuntimeError("no performable pose found; widen the generator's ranges")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=40)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--hands", type=int, default=2, choices=[1, 2], help="hands that cast each target")
    parser.add_argument("--no-forearm", action="store_true")
    parser.add_argument("--quality", default="default", choices=["fast", "default", "best"])
    parser.add_argument("--out", default="out/recover")
    parser.add_argument("--part", default="0/1", help="K/N: fit only targets k with k %% N == K")
    parser.add_argument(
        "--target-shape",
        help="the build of the hands that cast the targets (handshadow fit --hand-shape, Anny), e.g."
        " weight=0.8,muscle=0.8; the fit keeps the default hand",
    )
    parser.add_argument(
        "--target-lamp",
        type=float,
        default=FIT_LAMP_TO_WALL_M,
        metavar="M",
        help=f"the lamp that casts the targets, metres from the wall (default {FIT_LAMP_TO_WALL_M:g}, a default"
        " fit's own); the fit keeps its default lamp",
    )
    args = parser.parse_args()
    try:
        part, parts = (int(x) for x in args.part.split("/"))
        assert 0 <= part < parts
    except (ValueError, AssertionError):
        raise SystemExit(f"--part must be K/N with 0 <= K < N, got {args.part!r}") from None
    rows_file = "rows.json" if parts == 1 else f"rows-{part}-of-{parts}.json"
    out = Path(args.out)
    (out / "targets").mkdir(parents=True, exist_ok=True)
    try:
        shape = parse_hand_shape(args.target_shape, "anny") if args.target_shape else None
    except HandshadowError as exc:
        raise SystemExit(str(exc)) from None
    rng = np.random.default_rng(args.seed)
    forearm = not args.no_forearm
    kind = "two-hand" if args.hands == 2 else "one-hand"
    build = f", cast by hands of {args.target_shape}" if shape else ""
    if args.target_lamp != FIT_LAMP_TO_WALL_M:
        build += f", cast from a lamp {args.target_lamp:g} m from the wall"
    print(f"{args.n} random {kind} poses, forearm={forearm}, seed={args.seed}, quality={args.quality}{build}")
    print(
        f"{'target':10s} {'IoU':>6s} {'HD95':>6s} {'thin':>5s} {'ok':>3s} {'pen':>5s} {'hold':>4s} {'hands':>5s} {'s':>6s}"
    )
    rows = []
    for k in range(args.n):
        truth, target = random_target(rng, forearm, n_hands=args.hands, shape=shape, lamp_m=args.target_lamp)
        if k % parts != part:
            continue
        name = f"pose{k:02d}"
        iio.imwrite(out / "targets" / f"{name}.png", mask_image(target))
        (out / "targets" / f"{name}.json").write_text(json.dumps(truth.to_json(), indent=1))
        t0 = time.perf_counter()
        result = fit_frame(target, FitConfig(size=SIZE, quality=args.quality, forearm=forearm))
        seconds = time.perf_counter() - t0
        s = result.score
        rows.append(
            dict(
                name=name,
                iou=s.iou,
                hd95=s.hd95,
                thin=s.thin_recall,
                shadow_success=s.success,
                penetration_mm=result.penetration.deepest_mm,
                success=result.success,
                hands=len(result.posed.hands),
                seconds=seconds,
            )
        )
        r = rows[-1]
        print(
            f"{name:10s} {s.iou:6.3f} {s.hd95:6.3f} {s.thin_recall:5.2f} {'yes' if s.success else 'no':>3s} "
            f"{r['penetration_mm']:5.1f} {'yes' if result.performable else 'no':>4s} {r['hands']:5d} {seconds:6.1f}",
            flush=True,
        )
        (out / rows_file).write_text(json.dumps(rows, indent=1))
    n = len(rows)
    print(
        f"SUMMARY n={n} success={sum(r['shadow_success'] for r in rows) / n:.3f} "
        f"performable_success={sum(r['success'] for r in rows) / n:.3f} "
        f"median_iou={statistics.median(r['iou'] for r in rows):.3f} "
        f"median_s={statistics.median(r['seconds'] for r in rows):.1f}"
    )


if __name__ == "__main__":
    main()
