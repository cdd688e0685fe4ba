"""Author the library of classic hand-shadow poses (src/handshadow/data/library/*.json) and
render a contact sheet of their shadows (out/library.png) to look at. Each authored pose is
made one a person can hold (the fit's finishing steps) before it is written.

Conventions (docs/conventions.md): world +y up, +x right as the performer sees the wall, the
lamp at +z. A hand frame has +y toward the fingertips and +z out of the back of the hand; the
identity rotation holds a hand up, fingers to the ceiling, palm to the wall. Finger angles are
(twist, spread, bend) degrees: bend flexes toward the palm, spread moves toward the thumb.
Wrist: (flexion toward the palm, deviation toward the thumb) degrees.

Run:  .venv/bin/python tools/make_library.py
      .venv/bin/python tools/make_library.py --fix-arms   (only lead back forearms that do not)
      .venv/bin/python tools/make_library.py --fix-depth  (only part hands and fingers that pass
                                                           into each other, by the exact mesh test)
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
from scipy.spatial.transform import Rotation

from handshadow.library import LIBRARY
from handshadow.scene import Scene

FINGERS = ("thumb", "index", "middle", "ring", "little")
STRAIGHT = ((0, 0, 0), (0, 0, 0), (0, 0, 0))
CURLED = ((0, 0, 80), (0, 0, 95), (0, 0, 60))
HALF = ((0, 0, 40), (0, 0, 45), (0, 0, 30))


def frame(fingers_to, back_to) -> np.ndarray:
    """Rotation putting the hand's +y (fingers) along fingers_to and +z (back) toward back_to."""
    y = np.asarray(fingers_to, float)
    y /= np.linalg.norm(y)
    z = np.asarray(back_to, float)
    z = z - y * (z @ y)
    z /= np.linalg.norm(z)
    return np.stack([np.cross(y, z), y, z], 1)


def hand(side, rotation, translation, fingers=None, wrist=(0, 0)):
    pose = np.zeros((15, 3))
    for name, joints in (fingers or {}).items():
        f = FINGERS.index(name)
        pose[3 * f : 3 * f + 3] = np.asarray(joints, float)
    rot = (
        rotation if isinstance(rotation, np.ndarray) else Rotation.from_euler("xyz", rotation, degrees=True).as_matrix()
    )
    return {
        "side": side,
        "model": "anny",
        "shape": {},
        "pose_deg": pose.round(3).tolist(),
        "wrist_deg": list(map(float, wrist)),
        "rotation": np.asarray(rot).round(9).tolist(),
        "translation": list(map(float, translation)),
    }


def deg(a):
    return np.radians(a)


def direction(angle_deg, z=0.0):
    """A unit vector in the wall plane at angle_deg from +x (counter-clockwise), tilted by z."""
    return (np.cos(deg(angle_deg)), np.sin(deg(angle_deg)), z)


POSES = {
    "rabbit": (
        "Bunny: fist with two fingers up as the ears, thumb meeting the ring finger as the face.",
        [
            hand(
                "right",
                frame(direction(100), (0.3, 0, 1)),
                (0.0, -0.08, 1.0),
                {
                    "index": ((0, 6, 0), (0, 0, 5), (0, 0, 5)),
                    "middle": ((0, -10, 0), (0, 0, 5), (0, 0, 5)),
                    "ring": CURLED,
                    "little": CURLED,
                    "thumb": ((10, 10, 40), (0, 0, 35), (0, 0, 30)),
                },
                wrist=(10, 0),
            )
        ],
    ),
    "dog": (
        "Dog: hand sideways, thumb up as the ear, little finger dropped as the jaw.",
        [
            hand(
                "right",
                frame(direction(0), (0, 0, 1)),
                (-0.05, 0.0, 1.0),
                {
                    "thumb": ((0, 40, 0), (0, 0, 0), (0, 0, 0)),
                    "index": ((0, -4, 5), (0, 0, 5), (0, 0, 5)),
                    "middle": ((0, -2, 5), (0, 0, 5), (0, 0, 5)),
                    "ring": ((0, 2, 5), (0, 0, 5), (0, 0, 5)),
                    "little": ((0, -20, 10), (0, 0, 10), (0, 0, 5)),
                },
                wrist=(0, -10),
            )
        ],
    ),
    "bird": (
        "Bird: hands crossed at the wrists, palms to the lamp, thumbs linked as the head, fingers as wings.",
        [
            hand(
                "right",
                frame(direction(145), (0, 0, -1)),
                (0.03, -0.05, 1.0),
                {
                    "thumb": ((0, 35, 0), (0, 0, 10), (0, 0, 10)),
                    "index": ((0, 10, 0),) + STRAIGHT[1:],
                    "ring": ((0, -8, 0),) + STRAIGHT[1:],
                    "little": ((0, -16, 0),) + STRAIGHT[1:],
                },
                wrist=(0, 10),
            ),
            hand(
                "left",
                frame(direction(35), (0, 0, -1)),
                (-0.03, -0.05, 1.0),
                {
                    "thumb": ((0, 35, 0), (0, 0, 10), (0, 0, 10)),
                    "index": ((0, 10, 0),) + STRAIGHT[1:],
                    "ring": ((0, -8, 0),) + STRAIGHT[1:],
                    "little": ((0, -16, 0),) + STRAIGHT[1:],
                },
                wrist=(0, 10),
            ),
        ],
    ),
    "swan": (
        "Swan: the forearm upright as the neck, the hand bent down at the wrist as the head and beak.",
        [
            hand(
                "right",
                frame(direction(-15), (0, 1, 0.3)),
                (-0.02, 0.08, 1.0),
                {
                    "thumb": ((0, -5, 20), (0, 0, 10), (0, 0, 0)),
                    "index": ((0, -3, 10),) + STRAIGHT[1:],
                    "little": ((0, 3, 10),) + STRAIGHT[1:],
                },
                wrist=(75, 0),
            )
        ],
    ),
    "deer": (
        "Deer: one hand as the head, the other behind it with spread fingers as the antlers.",
        [
            hand(
                "right",
                frame(direction(-10), (0, 0, 1)),
                (0.0, -0.05, 1.0),
                {
                    "thumb": ((0, 10, 10), (0, 0, 0), (0, 0, 0)),
                    "index": ((0, -4, 5),) + STRAIGHT[1:],
                    "ring": ((0, 2, 5),) + STRAIGHT[1:],
                    "little": ((0, 4, 5),) + STRAIGHT[1:],
                },
                wrist=(0, 0),
            ),
            hand(
                "left",
                frame(direction(95), (0, 0, 1)),
                (-0.05, 0.02, 0.95),
                {
                    "thumb": ((0, 30, 0),) + STRAIGHT[1:],
                    "index": ((0, 20, 0),) + STRAIGHT[1:],
                    "middle": ((0, 5, 0),) + STRAIGHT[1:],
                    "ring": ((0, -12, 0),) + STRAIGHT[1:],
                    "little": ((0, -20, 0),) + STRAIGHT[1:],
                },
                wrist=(0, 0),
            ),
        ],
    ),
    "wolf": (
        "Wolf: both hands, palms together: the top hand's fingers the snout, its thumb the ear, the lower hand the jaw.",
        [
            hand(
                "right",
                frame(direction(5), (0, 0, 1)),
                (-0.04, 0.01, 1.0),
                {
                    "thumb": ((0, 35, 0), (0, 0, 0), (0, 0, 0)),
                    "index": ((0, -4, 0),) + STRAIGHT[1:],
                    "ring": ((0, 4, 0),) + STRAIGHT[1:],
                    "little": ((0, 8, 0),) + STRAIGHT[1:],
                },
            ),
            hand(
                "left",
                frame(direction(-8), (0, 0, -1)),
                (-0.04, -0.035, 0.97),
                {
                    "thumb": ((0, 0, 40), (0, 0, 40), (0, 0, 30)),
                    "index": ((0, -3, 10),) + STRAIGHT[1:],
                    "ring": ((0, 3, 10),) + STRAIGHT[1:],
                    "little": ((0, 6, 10),) + STRAIGHT[1:],
                },
            ),
        ],
    ),
    "duck": (
        "Duck: fingers together as the upper bill, thumb below as the lower bill.",
        [
            hand(
                "right",
                frame(direction(5), (0, 0, 1)),
                (-0.05, 0.0, 1.0),
                {
                    "thumb": ((0, -10, 30), (0, 0, 10), (0, 0, 0)),
                    "index": ((0, -4, 15), (0, 0, 20), (0, 0, 10)),
                    "middle": ((0, 0, 15), (0, 0, 20), (0, 0, 10)),
                    "ring": ((0, 4, 15), (0, 0, 20), (0, 0, 10)),
                    "little": ((0, 8, 15), (0, 0, 20), (0, 0, 10)),
                },
                wrist=(-20, 0),
            )
        ],
    ),
    "crocodile": (
        "Crocodile: hands stacked, fingers forward as the jaws, slightly open.",
        [
            hand(
                "right",
                frame(direction(8), (0, 1, 0.4)),
                (-0.06, 0.0, 1.0),
                {
                    "index": ((0, -3, 0),) + STRAIGHT[1:],
                    "ring": ((0, 3, 0),) + STRAIGHT[1:],
                    "little": ((0, 6, 0),) + STRAIGHT[1:],
                    "thumb": ((0, -10, 20),) + STRAIGHT[1:],
                },
            ),
            hand(
                "left",
                frame(direction(-8), (0, -1, 0.4)),
                (-0.06, -0.05, 0.98),
                {
                    "index": ((0, -3, 0),) + STRAIGHT[1:],
                    "ring": ((0, 3, 0),) + STRAIGHT[1:],
                    "little": ((0, 6, 0),) + STRAIGHT[1:],
                    "thumb": ((0, -10, 20),) + STRAIGHT[1:],
                },
            ),
        ],
    ),
    "butterfly": (
        "Butterfly: palms to the lamp, hands crossed at the thumbs, fingers spread wide.",
        [
            hand(
                "right",
                frame(direction(125), (0, 0, -1)),
                (0.05, -0.1, 1.0),
                {
                    "thumb": ((0, 30, 10),) + STRAIGHT[1:],
                    "index": ((0, 18, 0),) + STRAIGHT[1:],
                    "middle": ((0, 4, 0),) + STRAIGHT[1:],
                    "ring": ((0, -10, 0),) + STRAIGHT[1:],
                    "little": ((0, -25, 0),) + STRAIGHT[1:],
                },
            ),
            hand(
                "left",
                frame(direction(55), (0, 0, -1)),
                (-0.05, -0.1, 1.0),
                {
                    "thumb": ((0, 30, 10),) + STRAIGHT[1:],
                    "index": ((0, 18, 0),) + STRAIGHT[1:],
                    "middle": ((0, 4, 0),) + STRAIGHT[1:],
                    "ring": ((0, -10, 0),) + STRAIGHT[1:],
                    "little": ((0, -25, 0),) + STRAIGHT[1:],
                },
            ),
        ],
    ),
    "snail": (
        "Snail: a fist as the shell, the other hand's index and middle up as the feelers.",
        [
            hand(
                "right",
                frame(direction(60), (0.2, 0, 1)),
                (0.04, -0.06, 1.0),
                {
                    "thumb": ((0, 0, 30), (0, 0, 40), (0, 0, 40)),
                    "index": CURLED,
                    "middle": CURLED,
                    "ring": CURLED,
                    "little": CURLED,
                },
                wrist=(30, 0),
            ),
            hand(
                "left",
                frame(direction(80), (0, 0, 1)),
                (-0.05, -0.1, 0.97),
                {
                    "thumb": ((0, 0, 40), (0, 0, 40), (0, 0, 30)),
                    "index": ((0, 8, 0),) + STRAIGHT[1:],
                    "middle": ((0, -8, 0),) + STRAIGHT[1:],
                    "ring": CURLED,
                    "little": CURLED,
                },
            ),
        ],
    ),
    "eagle": (
        "Eagle: wrists crossed, palms to the wall, thumbs up as the head, fingers spread as the wings.",
        [
            hand(
                "right",
                frame(direction(160), (0, 0, 1)),
                (0.02, -0.08, 1.0),
                {
                    "thumb": ((0, 45, 0),) + STRAIGHT[1:],
                    "index": ((0, 12, 0),) + STRAIGHT[1:],
                    "ring": ((0, -10, 0),) + STRAIGHT[1:],
                    "little": ((0, -20, 0),) + STRAIGHT[1:],
                },
            ),
            hand(
                "left",
                frame(direction(20), (0, 0, 1)),
                (-0.02, -0.08, 1.0),
                {
                    "thumb": ((0, 45, 0),) + STRAIGHT[1:],
                    "index": ((0, 12, 0),) + STRAIGHT[1:],
                    "ring": ((0, -10, 0),) + STRAIGHT[1:],
                    "little": ((0, -20, 0),) + STRAIGHT[1:],
                },
            ),
        ],
    ),
    "heart": (
        "Heart: both hands, fingers curled over to meet at the top, thumbs meeting below.",
        [
            hand(
                "right",
                frame(direction(110), (0, 0, 1)),
                (0.05, -0.09, 1.0),
                {
                    "thumb": ((0, 20, 10), (0, 0, 10), (0, 0, 10)),
                    "index": HALF,
                    "middle": HALF,
                    "ring": HALF,
                    "little": HALF,
                },
                wrist=(0, -10),
            ),
            hand(
                "left",
                frame(direction(70), (0, 0, 1)),
                (-0.05, -0.09, 1.0),
                {
                    "thumb": ((0, 20, 10), (0, 0, 10), (0, 0, 10)),
                    "index": HALF,
                    "middle": HALF,
                    "ring": HALF,
                    "little": HALF,
                },
                wrist=(0, -10),
            ),
        ],
    ),
    "spider": (
        "Spider: palms to the lamp, hands crossed, thumbs hooked, fingers bent as legs.",
        [
            hand(
                "right",
                frame(direction(100), (0, 0, -1)),
                (0.03, -0.1, 1.0),
                {
                    "thumb": ((0, 30, 20),) + STRAIGHT[1:],
                    "index": ((0, 15, 30), (0, 0, 40), (0, 0, 20)),
                    "middle": ((0, 5, 30), (0, 0, 40), (0, 0, 20)),
                    "ring": ((0, -8, 30), (0, 0, 40), (0, 0, 20)),
                    "little": ((0, -18, 30), (0, 0, 40), (0, 0, 20)),
                },
            ),
            hand(
                "left",
                frame(direction(80), (0, 0, -1)),
                (-0.03, -0.1, 1.0),
                {
                    "thumb": ((0, 30, 20),) + STRAIGHT[1:],
                    "index": ((0, 15, 30), (0, 0, 40), (0, 0, 20)),
                    "middle": ((0, 5, 30), (0, 0, 40), (0, 0, 20)),
                    "ring": ((0, -8, 30), (0, 0, 40), (0, 0, 20)),
                    "little": ((0, -18, 30), (0, 0, 40), (0, 0, 20)),
                },
            ),
        ],
    ),
    "goose": (
        "Goose: the arm raised as the neck, the hand bent forward at the wrist, thumb and fingers as the bill.",
        [
            hand(
                "right",
                frame(direction(10), (0, 1, 0.2)),
                (-0.02, 0.1, 1.0),
                {
                    "thumb": ((0, -10, 10),) + STRAIGHT[1:],
                    "index": ((0, -3, 25), (0, 0, 20), (0, 0, 10)),
                    "middle": ((0, 0, 25), (0, 0, 20), (0, 0, 10)),
                    "ring": ((0, 3, 25), (0, 0, 20), (0, 0, 10)),
                    "little": ((0, 6, 25), (0, 0, 20), (0, 0, 10)),
                },
                wrist=(70, 0),
            ),
        ],
    ),
}


def holdable(data: dict) -> tuple[dict, str]:
    """The authored pose made one a person can hold (docs/performing.md): the finishing steps
    of a fit part hands that pass through each other and open fingers curled into the palm,
    then the polish brings the shadow back toward the authored one. Returns the pose data and
    a line on what changed."""
    from handshadow.search import polish, separate

    target, problem, poses = _problem_of(data)
    sides = [h["side"] for h in data["hands"]]
    before = problem.mesh_penetration(poses)[0].deepest_mm
    poses = polish(problem, separate(problem, lead_back(problem, poses)), rounds=3, always=True)
    after = problem.mesh_penetration(poses)[0].deepest_mm
    hands = [h.to_json() for b, side in zip(poses.hands, sides) for h in b.to_hand_poses(side, "anny")]
    shadow = problem.shadows(poses)[0].numpy() > 0.5
    iou = float((shadow & target).sum() / (shadow | target).sum())
    return {**data, "hands": hands}, f"penetration {before:.1f} -> {after:.1f} mm, shadow IoU {iou:.3f}"


def _problem_of(data: dict):
    """(its own shadow (H, W) bool, a search problem fitting it, the pose as a PoseBatch of
    one) for a pose file's data."""
    from handshadow.fit import FitConfig, make_problem
    from handshadow.hands.posed import cast_shadow
    from handshadow.posefile import parse_pose
    from handshadow.poses import HandPoseBatch, PoseBatch

    posed = parse_pose(data)
    target = cast_shadow(posed)[1] > 0.5
    sides = [h.side for h in posed.hands]
    config = FitConfig(size=posed.scene.image.height, hands=str(len(sides)), device="cpu")
    problem = make_problem(target, posed.scene, sides, config)
    return target, problem, PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in posed.hands])


# The wrist angles lead_back tries, degrees apart, within the wrist's limits.
WRIST_STEP_DEG = 5.0
# The whole-hand tilts lead_back tries beyond the least that levels the forearm, degrees.
TILT_STEPS_DEG = np.arange(0.0, 12.5, 2.5)


def lead_back(problem, poses):
    """Poses (a PoseBatch of one) whose forearms lead back toward the performer
    (hands.arms): each hand whose elbow is nearer the wall than its wrist gets, of the wrist
    angles on a WRIST_STEP_DEG grid within its limits (they turn only the forearm) and the
    whole hand tilted about its wrist across the wall (TILT_STEPS_DEG), the one that leads it
    back and changes the shadow least (IoU with the pose's own shadow)."""
    import torch

    with torch.no_grad():
        return _lead_back(problem, poses)


def _lead_back(problem, poses):
    import torch

    from handshadow.hands.arms import BACK_SLACK_M
    from handshadow.poses import PoseBatch

    shadow = problem.shadows(poses)[0] > 0.5
    hands = list(poses.hands)
    for k in range(len(problem.models)):
        out = problem.pose(hands)[k]
        if not out.forearm_points.shape[1]:
            continue
        elbow_height = float(out.forearm_points[0, -1, 2])
        if elbow_height >= float(hands[k].translation[0, 2]) - BACK_SLACK_M:
            continue
        lo, hi = problem.limits[k].wrist.cpu().numpy()[:, 0], problem.limits[k].wrist.cpu().numpy()[:, 1]
        grid = np.radians(WRIST_STEP_DEG)
        flex = np.arange(lo[0], hi[0] + 1e-9, grid)
        dev = np.arange(lo[1], hi[1] + 1e-9, grid)
        wrists = torch.as_tensor(
            np.stack(np.meshgrid(flex, dev, indexing="ij"), -1).reshape(-1, 2), dtype=torch.float32
        )
        # ... and the whole hand tilted about its wrist, across the wall, until the forearm
        # lies level with the wrist or behind it (TILT_STEPS_DEG beyond the least tilt).
        wrist = hands[k].translation[0].double().numpy()
        along = out.forearm_points[0, -1].double().numpy() - wrist
        along /= np.linalg.norm(along)
        axis = np.cross(along, [0.0, 0.0, 1.0])
        axis /= np.linalg.norm(axis)
        least = np.arcsin(np.clip(-along[2], -1.0, 1.0))
        turns = Rotation.from_rotvec(np.outer(least + np.radians(TILT_STEPS_DEG), axis)).as_matrix()
        rotations = torch.as_tensor(turns, dtype=torch.float32) @ hands[k].rotation[0]
        n_wrist, n = len(wrists), len(wrists) + len(turns)
        tried = [h.select([0] * n) for h in hands]
        tried[k] = dataclasses.replace(
            tried[k],
            wrist_rad=torch.cat([wrists, tried[k].wrist_rad[n_wrist:]]),
            rotation=torch.cat([tried[k].rotation[:n_wrist], rotations]),
        )
        batch = PoseBatch(tried)
        elbows = problem.pose(tried)[k].forearm_points[:, -1, 2]
        back = elbows >= tried[k].translation[:, 2]  # level with the wrist or behind it
        masks = problem.shadows(batch) > 0.5
        overlap = (masks & shadow).flatten(1).sum(1) / (masks | shadow).flatten(1).sum(1)
        overlap = torch.where(back, overlap, torch.full_like(overlap, -1.0))
        best = int(overlap.argmax())
        if overlap[best] < 0:
            raise ValueError(f"no wrist angle within its limits leads hand {k}'s forearm back")
        hands[k] = tried[k].select([best])
    return PoseBatch(hands)


def fix_arms() -> None:
    """Lead back the forearms of the library's poses that do not (lead_back), keeping every
    other value of their files; the poses whose arms are already holdable stay byte for byte."""
    for path in sorted(LIBRARY.glob("*.json")):
        data = json.loads(path.read_text())
        target, problem, poses = _problem_of(data)
        if problem.holdable(poses)[0]:
            continue
        fixed = lead_back(problem, poses)
        shadow = problem.shadows(fixed)[0].numpy() > 0.5
        iou = float((shadow & target).sum() / (shadow | target).sum())
        for h, batch in zip(data["hands"], fixed.hands):
            new = batch.to_hand_poses(h["side"], h["model"])[0].to_json()
            h.update(wrist_deg=new["wrist_deg"], rotation=new["rotation"])  # all lead_back changes
        path.write_text(json.dumps(data, indent=1) + "\n")
        print(f"{path.stem:10s} forearms led back: holdable {problem.holdable(fixed)[0]}, shadow IoU {iou:.3f}")


def fix_depth() -> None:
    """Part the hands and fingers of the library's poses that pass into each other deeper than
    the performable tolerance by the exact mesh test (metrics.md; a fit's separation, then the
    polish toward the pose's own shadow), keeping the rest of their files; the poses that pass
    stay byte for byte."""
    from handshadow.search import polish, separate
    from handshadow.search.config import Finishing

    tolerance = Finishing().tolerance_mm
    for path in sorted(LIBRARY.glob("*.json")):
        data = json.loads(path.read_text())
        target, problem, poses = _problem_of(data)
        before = problem.mesh_penetration(poses)[0].deepest_mm
        if before <= tolerance:
            continue
        fixed = polish(problem, separate(problem, poses), rounds=3, always=True)
        after = problem.mesh_penetration(fixed)[0].deepest_mm
        shadow = problem.shadows(fixed)[0].numpy() > 0.5
        iou = float((shadow & target).sum() / (shadow | target).sum())
        for h, batch in zip(data["hands"], fixed.hands):
            h.update(batch.to_hand_poses(h["side"], h["model"])[0].to_json())
        path.write_text(json.dumps(data, indent=1) + "\n")
        held = problem.holdable(fixed)[0]
        print(f"{path.stem:10s} penetration {before:.1f} -> {after:.1f} mm, arms holdable {held}, shadow IoU {iou:.3f}")


if __name__ == "__main__":
    import sys

    import imageio.v3 as iio
    import torch

    from handshadow.hands.posed import cast_shadow
    from handshadow.posefile import parse_pose

    if sys.argv[1:] == ["--fix-arms"]:
        fix_arms()
        raise SystemExit
    if sys.argv[1:] == ["--fix-depth"]:
        fix_depth()
        raise SystemExit
    LIBRARY.mkdir(parents=True, exist_ok=True)
    scene = Scene.default(192, 192)
    tiles = []
    for name, (about, hands) in POSES.items():
        data = {
            "format": "handshadow.pose/1",
            "about": about,
            "scene": Scene.default(256, 256).to_json(),
            "forearm": True,
            "hands": hands,
        }
        data, change = holdable(data)
        (LIBRARY / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")
        pose_set = parse_pose({**data, "scene": scene.to_json()})
        with torch.no_grad():
            mask = cast_shadow(pose_set)[1]
        tile = (1 - mask) * 255
        tile[:2], tile[:, :2] = 128, 128
        tiles.append(tile)
        print(f"{name:10s} {change}  {about}")
    cols = 5
    while len(tiles) % cols:
        tiles.append(np.full_like(tiles[0], 255))
    sheet = np.concatenate([np.concatenate(tiles[i : i + cols], 1) for i in range(0, len(tiles), cols)], 0)
    iio.imwrite("out/library.png", sheet.astype(np.uint8))
    print("wrote", LIBRARY, "and out/library.png")
