"""Where the search starts: library poses and random hands, placed over the target.

Each candidate (one or two posed hands) is rendered small; its shadow is matched to the target
by a 2D similarity (rotation about the lamp's foot, scale, shift) found by trying rotations and
scales and aligning centroids. The similarity maps back to 3D exactly for the rotation (turning
the hands about the lamp's axis turns the shadow), and closely for scale (moving the hands along
the lamp's axis changes their magnification) and shift (moving them parallel to the wall).
Mirror images (swapping left and right hands) double the candidates.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import torch
import torch.nn.functional as F

from handshadow.hands.limits import JointLimits
from handshadow.hands.rig import FINGERS
from handshadow.library import library_names, load_library_pose
from handshadow.metrics import iou
from handshadow.poses import HandPose, HandPoseBatch, Origin, PoseBatch
from handshadow.scene import FRAME_HEIGHT_M
from handshadow.search.atlas import WRIST_DEPTH_M, Atlas, shape_descriptor

log = logging.getLogger(__name__)
MIRROR = torch.diag(torch.tensor([-1.0, 1.0, 1.0]))
# Two library hands at one depth cannot pass in front of each other: the right one starts
# this much nearer the lamp.
PAIR_DEPTH_OFFSET_M = 0.02
ALIGN_FRAME_PX = 64  # the alignment works on shadows this many pixels high
ALIGN_ANGLES_DEG = np.arange(0, 360, 20)
ALIGN_SCALES = np.array([0.8, 1.0, 1.25])  # times the area ratio (a point light; else 1)
PER_LIBRARY_POSE = 2  # at most this many starts from any one library pose
ATLAS_ONE = 48  # one hand: atlas entries nearest the target
ATLAS_FIRST = 12  # two hands: entries nearest the target, as the first hand
ATLAS_SECOND = 6  # ... and for each, entries nearest what it leaves uncovered, as the other
HOLE_PENALTY = 0.3  # how much a start that fills the target's holes and notches loses (see start_score)
ATLAS_SHARE = 0.5  # at most this share of the kept starts from the atlas (the rest stay diverse)
SECOND_HAND_MIN_SHARE = 0.05  # less left uncovered than this share of the target: cover it all
# Random hands are drawn this many times over and those whose arms can be held kept first
# (three random hands in four have a forearm pointing toward the wall).
RANDOM_OVERSAMPLE = 4
ALIGN_WALL_CLEARANCE_M = 0.15  # the alignment's scaling keeps hands this far from the wall
ALIGN_LAMP_CLEARANCE_M = 0.35  # ... and this far from a point light


def library_starts(n_hands: int, sides: list[str], dtype=torch.float32, exclude: tuple[str, ...] = ()) -> PoseBatch:
    """Library poses with the requested number of hands, in the order of ``sides``; a one-hand
    pose of the other side is mirrored to fit, and every pose also comes mirrored. Poses
    named in ``exclude`` are left out."""
    out_hands: list[list[HandPoseBatch]] = [[] for _ in sides]
    origins = []
    for name in library_names():
        if name in exclude:
            continue
        posed = load_library_pose(name)
        if len(posed.hands) != n_hands:
            continue
        by_side = {h.side: h for h in posed.hands}
        for mirrored in (False, True):
            picked = []
            for side in sides:
                source_side = side if not mirrored else ("left" if side == "right" else "right")
                h = by_side.get(source_side)
                if h is None:  # one-hand pose of the other side: use its mirror image
                    h = next(iter(by_side.values()))
                    mirror_this = h.side != side
                else:
                    mirror_this = mirrored
                picked.append(_hand_poses(h, mirror_this, dtype))
            if len(picked) == 2:  # hands at one depth cannot pass in front of each other: part them
                picked[0].translation[:, 2] += PAIR_DEPTH_OFFSET_M
            for k, hp in enumerate(picked):
                out_hands[k].append(hp)
            origins.append(Origin("library", name, mirrored))
    return PoseBatch([HandPoseBatch.cat(h) for h in out_hands], origins)


def _hand_poses(h: HandPose, mirrored: bool, dtype) -> HandPoseBatch:
    batch = HandPoseBatch.from_hand_poses([h], dtype=dtype)
    if mirrored:
        m = MIRROR.to(dtype)
        batch = HandPoseBatch(batch.pose_rad, m @ batch.rotation @ m, batch.translation @ m.T, batch.wrist_rad)
    return batch


def random_starts(
    n: int,
    sides: list[str],
    limits: list[JointLimits],
    rng: np.random.Generator,
    depth_m: float = 1.0,
    dtype=torch.float32,
) -> PoseBatch:
    """n random hypotheses: each finger extended, half bent or curled; hands facing the wall,
    the lamp or sideways, pointing any way in the wall plane; two hands side by side."""
    hands = []
    for side, lim in zip(sides, limits):
        lo, hi = lim.joints[..., 0].cpu().numpy(), lim.joints[..., 1].cpu().numpy()
        pose = np.zeros((n, 15, 3))
        for f in range(len(FINGERS)):
            mode = rng.choice(3, size=n, p=[0.5, 0.25, 0.25])
            bend = np.array([0.0, 45.0, 85.0])[mode][:, None] + rng.normal(0, 8, (n, 3))
            pose[:, 3 * f : 3 * f + 3, 2] = np.radians(bend * np.array([1.0, 1.1, 0.8]))
            pose[:, 3 * f, 1] = np.radians(rng.normal(0, 10, n))
        pose = np.clip(pose, lo, hi)
        wlo, whi = lim.wrist[:, 0].cpu().numpy(), lim.wrist[:, 1].cpu().numpy()
        wrist = np.clip(np.radians(rng.normal(0, 25, (n, 2))), wlo, whi)
        rots = []
        for _ in range(n):
            angle = rng.uniform(0, 2 * math.pi)
            fingers = np.array([math.cos(angle), math.sin(angle), rng.normal(0, 0.2)])
            face = rng.choice(3, p=[0.5, 0.3, 0.2])
            back = [
                np.array([0, 0, 1.0]),
                np.array([0, 0, -1.0]),
                np.cross(fingers, [0, 0, 1.0]) * rng.choice([-1, 1]),
            ][face]
            rots.append(_frame(fingers, back + rng.normal(0, 0.15, 3)))
        x = (0.06 if side == "right" else -0.06) if len(sides) == 2 else 0.0
        trans = np.stack([np.full(n, x), np.full(n, -0.08), np.full(n, depth_m)], 1) + rng.normal(
            0, [0.03, 0.03, 0.05], (n, 3)
        )
        hands.append(HandPoseBatch(*(torch.as_tensor(a, dtype=dtype) for a in (pose, np.stack(rots), trans, wrist))))
    return PoseBatch(hands, [Origin("random")] * n)


def _frame(fingers, back) -> np.ndarray:
    y = fingers / np.linalg.norm(fingers)
    z = back - y * (back @ y)
    z /= np.linalg.norm(z)
    return np.stack([np.cross(y, z), y, z], 1)


def similarity_align(
    shadows: torch.Tensor,
    target: torch.Tensor,
    pivot: tuple[float, float],
    angles_deg: np.ndarray,
    scales: np.ndarray,
    base: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Best 2D similarity per shadow, about a pivot.

    Args:
        shadows: (B, H, W) candidate shadows; target: (H, W).
        pivot: (x, y) pixel coordinates the rotation and scale turn about (the lamp's foot).
        angles_deg: rotations to try; scales: scale factors to try, times ``base`` (B,) (None:
            the square root of the area ratio, target over shadow).
    Returns:
        angle (B,) radians, scale (B,), shift (B, 2) pixels (x, y), and the IoU (B,) reached.
    A shadow point q (pixels from the pivot) goes to scale * R(angle) q + shift.
    """
    b, h, w = shadows.shape
    yy, xx = torch.meshgrid(
        torch.arange(h, dtype=shadows.dtype) + 0.5 - pivot[1],
        torch.arange(w, dtype=shadows.dtype) + 0.5 - pivot[0],
        indexing="ij",
    )
    area = shadows.sum((1, 2)).clamp(min=1)
    t_area = target.sum().clamp(min=1)
    c_s = torch.stack([(shadows * xx).sum((1, 2)) / area, (shadows * yy).sum((1, 2)) / area], 1)
    c_t = torch.stack([(target * xx).sum() / t_area, (target * yy).sum() / t_area])
    base = torch.sqrt(t_area / area) if base is None else base.to(shadows.dtype)
    best = (torch.full((b,), -1.0), torch.zeros(b), torch.ones(b), torch.zeros(b, 2))
    for a in np.radians(angles_deg):
        rot = torch.tensor([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]], dtype=shadows.dtype)
        for s in scales:
            scale = base * s
            # Centroid after rotation and scale, then shift onto the target's centroid.
            shift = c_t[None] - scale[:, None] * (c_s @ rot.T)
            warped = _warp(shadows, rot, scale, shift, pivot)
            overlap = iou(warped, target)
            better = overlap > best[0]
            best = (
                torch.where(better, overlap, best[0]),
                torch.where(better, torch.full_like(overlap, a), best[1]),
                torch.where(better, scale, best[2]),
                torch.where(better[:, None], shift, best[3]),
            )
    return best[1], best[2], best[3], best[0]


def _warp(images, rot, scale, shift, pivot):
    """Resample images (B, H, W) under q -> scale R q + shift (pixels from the pivot)."""
    b, h, w = images.shape
    # grid_sample wants, for each output pixel, its source: q_src = R^T (q_out - shift) / scale.
    inv = rot.T[None] / scale[:, None, None]
    to_norm = torch.tensor([2.0 / w, 2.0 / h], dtype=images.dtype)
    theta = torch.zeros(b, 2, 3, dtype=images.dtype)
    # Normalised coordinates n = D (q + c0), c0 = pivot - centre: q_src_n = D inv D^-1 n_out
    # + D (c0 - inv (c0 + shift)).
    d = torch.diag(to_norm)
    d_inv = torch.diag(1 / to_norm)
    c0 = torch.tensor([pivot[0] - w / 2, pivot[1] - h / 2], dtype=images.dtype)
    theta[:, :, :2] = d @ inv @ d_inv
    theta[:, :, 2] = (d @ (c0[None, :, None] - inv @ (c0[None] + shift)[..., None]))[..., 0]
    grid = F.affine_grid(theta, (b, 1, h, w), align_corners=False)
    return F.grid_sample(images[:, None], grid, mode="bilinear", padding_mode="zeros", align_corners=False)[:, 0]


def apply_similarity(
    poses: PoseBatch, angle: torch.Tensor, scale: torch.Tensor, shift_px: torch.Tensor, scene, frame_px: int
) -> PoseBatch:
    """Move the hypotheses' hands so that their shadows undergo the 2D similarity
    (angle (B,) radians, scale (B,), shift_px (B, 2), as :func:`similarity_align` gives).

    shift_px is in pixels of a frame frame_px pixels high. Rotation: about the wall normal
    through the lamp (the frame centre's normal for a directional light). Scale: for a point
    light, a move along the lamp's axis to magnification times scale (directional lights keep
    the size), kept between ALIGN_WALL_CLEARANCE_M and ALIGN_LAMP_CLEARANCE_M. Shift: a move
    parallel to the wall by shift / magnification.
    """
    n = torch.as_tensor(scene.wall.normal, dtype=angle.dtype)
    metres_per_px = float(np.linalg.norm(scene.image.v)) / frame_px
    u = torch.as_tensor(np.asarray(scene.image.u) / np.linalg.norm(scene.image.u), dtype=angle.dtype)
    v = torch.as_tensor(np.asarray(scene.image.v) / np.linalg.norm(scene.image.v), dtype=angle.dtype)
    # A rotation by +angle in image coordinates (x right, y down) is clockwise on the wall as
    # seen from the lamp when u x v points into the wall (the usual frame): a turn by -angle
    # about the wall normal. A mirrored frame turns the other way.
    handed = torch.sign(torch.cross(u, v, dim=0) @ n)
    rot = _axis_rotation(n, angle * handed)  # (B, 3, 3)
    point = scene.light.type == "point"
    lamp_h = (
        float((np.asarray(scene.light.position) - np.asarray(scene.wall.point)) @ np.asarray(scene.wall.normal))
        if point
        else None
    )
    axis_point = torch.as_tensor(pivot_point(scene), dtype=angle.dtype)
    hands = []
    mean_h = torch.stack(
        [((h.translation - torch.as_tensor(scene.wall.point, dtype=angle.dtype)) @ n) for h in poses.hands]
    ).mean(0)
    if point:
        mag = lamp_h / (lamp_h - mean_h)
        new_h = lamp_h - lamp_h / (mag * scale)
        new_h = new_h.clamp(ALIGN_WALL_CLEARANCE_M, lamp_h - ALIGN_LAMP_CLEARANCE_M)
        dz = new_h - mean_h
        new_mag = lamp_h / (lamp_h - new_h)
    else:
        dz = torch.zeros_like(scale)
        new_mag = torch.ones_like(scale)
    shift_m = (shift_px[:, :1] * u + shift_px[:, 1:] * v) * metres_per_px / new_mag[:, None]
    for h in poses.hands:
        rel = h.translation - axis_point
        t = (rot @ rel[..., None])[..., 0] + axis_point + dz[:, None] * n + shift_m
        hands.append(HandPoseBatch(h.pose_rad, rot @ h.rotation, t, h.wrist_rad))
    origins = [dataclasses.replace(o, aligned=True) for o in poses.origins] if poses.origins is not None else None
    return PoseBatch(hands, origins)


def pivot_point(scene) -> np.ndarray:
    """(3,) the point the alignment turns about: the lamp (point light) or the frame centre."""
    if scene.light.type == "point":
        return np.asarray(scene.light.position, float)
    return np.asarray(scene.image.origin) + 0.5 * np.asarray(scene.image.u) + 0.5 * np.asarray(scene.image.v)


def pivot_pixel(scene, frame_px: int) -> tuple[float, float]:
    """(x, y) pixel coordinates, in a frame frame_px high, of the pivot's foot on the wall."""
    import torch as _torch

    p = np.asarray(pivot_point(scene), float)
    n = np.asarray(scene.wall.normal, float)
    foot = p - n * ((p - np.asarray(scene.wall.point)) @ n)
    small = scene.with_size(max(1, round(scene.image.width * frame_px / scene.image.height)), frame_px)
    xy = small.project(_torch.as_tensor(foot + 1e-3 * n)[None])[0][0]
    return float(xy[0]), float(xy[1])


def _axis_rotation(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    from handshadow.hands.kinematics import rotvec_to_rotmat

    return rotvec_to_rotmat(axis[None] * angle[:, None])


def choose_starts(
    problem,
    sides: list[str],
    n_random: int,
    n_keep: int,
    rng: np.random.Generator,
    given: PoseBatch | None = None,
    exclude: tuple[str, ...] = (),
    atlas: Atlas | None = None,
    skip: frozenset = frozenset(),
) -> PoseBatch:
    """The search's starts: library poses (but those named in ``exclude``), ``n_random``
    random hands (drawn RANDOM_OVERSAMPLE times over, holdable ones first) and, given an atlas, its entries nearest the target (:func:`atlas_starts`),
    each aligned to the target in 2D, the best ``n_keep`` by IoU, those whose arms can be
    held (Problem.holdable) first (at most PER_LIBRARY_POSE
    from any one library pose and ATLAS_SHARE from the atlas, so the starts stay diverse). ``given`` starts (one PoseBatch,
    e.g. a morph's other end) are always kept, both as given and aligned. ``skip``: library
    and atlas starts an earlier attempt searched (:func:`start_key`); they rank behind every
    other start whose arms can be held.
    With several views each candidate is also turned about the vertical (:func:`view_turns_rad`),
    each is aligned to each view's target in turn and judged in every view
    (:func:`views_start_score`); the atlas answers view 0's target.

    problem: a search.problem.Problem; returns a PoseBatch on its device, with origins."""

    randoms = random_starts(RANDOM_OVERSAMPLE * n_random, sides, problem.limits, rng, problem.scene.working_depth())
    held = problem.holdable(randoms)
    randoms = randoms.select(sorted(range(randoms.batch), key=lambda i: not held[i])[:n_random])
    parts = [library_starts(len(sides), sides, exclude=exclude), randoms]
    if atlas is not None:
        parts.append(atlas_starts(atlas, problem.level(ALIGN_FRAME_PX).maps.target.cpu(), sides, problem.scene))
    turns = view_turns_rad(problem)
    if len(turns) > 1:  # several views: each candidate also turned toward the other lamps
        parts = [turned_about_vertical(PoseBatch.cat(parts), a) for a in turns]
    if given is not None:
        parts.append(given.detach().to("cpu").with_origins([Origin("given")] * given.batch))
    cand = PoseBatch.cat(parts).to(problem.device)
    # Aligned to each view in turn (view 0's first), judged in every view (weighted).
    moved = PoseBatch.cat([align_to_view(problem, cand, k) for k in range(len(problem.views))])
    overlap = views_start_score(problem, moved)
    # Starts whose arms can be held come first (the alignment keeps that: it turns the hands
    # about the lamp's axis and moves them along it or parallel to the wall): the arms term
    # would have to turn the others, undoing their alignment.
    held = torch.as_tensor(problem.holdable(moved), device=overlap.device)
    if skip:  # an earlier attempt searched these: the next best instead
        tried = torch.tensor([start_key(o) in skip for o in moved.origins], device=overlap.device)
        held = held & ~tried
    order = torch.argsort(overlap - 2.0 * (~held).to(overlap.dtype), descending=True).tolist()
    picked = list(range(cand.batch - given.batch, cand.batch)) if given is not None else []  # aligned
    picked = _pick_diverse(order, moved.origins, n_keep, picked)
    log.info("starts: %s", ", ".join(f"{moved.origins[i]} {float(overlap[i]):.2f}" for i in picked[:8]))
    chosen = moved.select(picked)
    return PoseBatch.cat([cand.select(slice(cand.batch - given.batch, None)), chosen]) if given is not None else chosen


def _pick_diverse(order: list[int], origins: list[Origin], n_keep: int, picked: list[int]) -> list[int]:
    """``picked`` followed by candidates in ``order`` (best first) up to ``n_keep`` in all, at
    most PER_LIBRARY_POSE from any one library pose and ATLAS_SHARE of n_keep from the atlas."""
    picked = list(picked)
    per_pose: dict[str, int] = {}
    for i in order:
        if len(picked) >= n_keep:
            break
        if i in picked:
            continue
        o = origins[i]
        source = o.name if o.kind == "library" else o.kind if o.kind == "atlas" else None
        cap = PER_LIBRARY_POSE if o.kind == "library" else round(ATLAS_SHARE * n_keep)
        if source is not None:
            if per_pose.get(source, 0) >= cap:
                continue
            per_pose[source] = per_pose.get(source, 0) + 1
        picked.append(i)
    return picked


def start_key(origin) -> tuple | None:
    """What identifies a library or atlas start across attempts (kind, name, mirrored);
    None for random and given starts."""
    if origin.kind not in ("library", "atlas"):
        return None
    return origin.kind, origin.name, origin.mirrored


def start_score(shadows: torch.Tensor, maps) -> torch.Tensor:
    """(B,) how good a start is: its IoU with the target, less HOLE_PENALTY times the share of
    the target's holes and narrow notches (losses.notches, graded) that it fills; a shadow
    that closes the counter of a letter rarely opens it again. shadows (B, H, W) in [0, 1];
    maps: the target's maps (losses.TargetMaps) at that resolution."""
    target, notches = maps.target.cpu(), maps.notches.cpu()
    score = iou(shadows, target)
    if float(notches.sum()) > 0:
        score = score - HOLE_PENALTY * (shadows * notches).sum((1, 2)) / notches.sum()
    return score


def atlas_starts(atlas: Atlas, target: torch.Tensor, sides: list[str], scene) -> PoseBatch:
    """Starts from the atlas for a target (H, W) at ALIGN_FRAME_PX: with one hand, the
    ATLAS_ONE entries nearest the target's shape; with two, for each of the ATLAS_FIRST
    nearest (as the first hand, aligned to the target) the ATLAS_SECOND nearest what it leaves
    uncovered (as the other hand, turned and moved onto that, PAIR_DEPTH_OFFSET_M nearer the
    wall). The other hand keeps the first's scale within ALIGN_SCALES: both stand about as far
    from the wall, as one person's two hands do (scaled alone onto a small remainder, it would
    stand a metre or more nearer the wall, its elbow out of that person's reach).
    Origins are ('atlas', entry numbers)."""
    if tuple(target.shape) != atlas.masks.shape[1:]:
        return _no_starts(sides)  # a frame of another shape than the atlas's
    first_side = sides[0]
    nearest = atlas.nearest(shape_descriptor(target[None])[0].numpy(), ATLAS_ONE if len(sides) == 1 else ATLAS_FIRST)
    depth = scene.working_depth()
    first = _atlas_hands(atlas, nearest, first_side, depth)
    if len(sides) == 1:
        return PoseBatch([first], [Origin("atlas", str(i)) for i in nearest])
    pivot = pivot_pixel(scene, target.shape[0])
    zoom = atlas_zoom(scene)
    masks = _atlas_masks(atlas, nearest, first_side, zoom, pivot)
    angle, scale, shift, _ = similarity_align(masks, target, pivot, ALIGN_ANGLES_DEG, ALIGN_SCALES)
    placed = apply_similarity(PoseBatch([first]), angle, scale, shift, scene, target.shape[0])
    covered = _warp_each(masks, angle, scale, shift, pivot)
    rights, lefts, origins = [], [], []
    for k, i in enumerate(nearest):
        rest = (target * (1 - covered[k])).clamp(min=0)
        if float(rest.sum()) < SECOND_HAND_MIN_SHARE * float(target.sum()):
            rest = target  # the first hand covers it: the other hand goes over the whole shape
        second_idx = atlas.nearest(shape_descriptor(rest[None])[0].numpy(), ATLAS_SECOND)
        second_masks = _atlas_masks(atlas, second_idx, sides[1], zoom, pivot)
        same_size = scale[k].expand(len(second_idx))  # atlas entries share one depth, so one size
        a2, s2, t2, _ = similarity_align(second_masks, rest, pivot, ALIGN_ANGLES_DEG, ALIGN_SCALES, base=same_size)
        second = apply_similarity(
            PoseBatch([_atlas_hands(atlas, second_idx, sides[1], depth)]), a2, s2, t2, scene, target.shape[0]
        )
        rights.append(placed.hands[0].select([k] * len(second_idx)))
        lefts.append(second.hands[0].moved(torch.tensor([0.0, 0.0, -PAIR_DEPTH_OFFSET_M])))
        origins += [Origin("atlas", f"{i}+{j}") for j in second_idx]
    return PoseBatch([HandPoseBatch.cat(rights), HandPoseBatch.cat(lefts)], origins)


def _no_starts(sides) -> PoseBatch:
    empty = HandPoseBatch(torch.zeros(0, 15, 3), torch.zeros(0, 3, 3), torch.zeros(0, 3), torch.zeros(0, 2))
    return PoseBatch([empty for _ in sides], [])


def _atlas_hands(atlas: Atlas, idx: np.ndarray, side: str, depth_m: float) -> HandPoseBatch:
    """Entries idx as the given side's hand (the atlas holds right hands; a left one is the
    mirror image), the wrist moved along the lamp's axis to depth_m from the wall (the scene's
    working depth, where the shadow has the atlas's size)."""
    hands = atlas.poses.select(torch.as_tensor(idx)).moved(torch.tensor([0.0, 0.0, depth_m - WRIST_DEPTH_M]))
    if side == "right":
        return hands
    m = MIRROR.to(hands.rotation.dtype)
    return HandPoseBatch(hands.pose_rad, m @ hands.rotation @ m, hands.translation @ m.T, hands.wrist_rad)


def atlas_zoom(scene) -> float:
    """How much larger, in pixels, a shadow cast at the scene's working depth is than the same
    hand's atlas entry: the default frame's height over the scene's (a frame sized to its
    target, scene.frame_height_for, is smaller or larger on the wall)."""
    return FRAME_HEIGHT_M[scene.light.type] / scene.frame_height_m


def _atlas_masks(atlas: Atlas, idx: np.ndarray, side: str, zoom: float = 1.0, pivot=None) -> torch.Tensor:
    """(k, H, W) float shadows of entries idx as the given side's hand (mirrored for the left:
    the frame is centred on the lamp's foot), enlarged ``zoom`` times about ``pivot`` (the
    lamp's foot, pixels) into the scene's frame (:func:`atlas_zoom`)."""
    masks = torch.as_tensor(atlas.masks[idx], dtype=torch.float32)
    masks = masks if side == "right" else torch.flip(masks, [2])
    if zoom == 1.0 or len(masks) == 0:
        return masks
    k = len(masks)
    return _warp(masks, torch.eye(2), torch.full((k,), zoom), torch.zeros(k, 2), pivot)


def _warp_each(masks, angle, scale, shift, pivot) -> torch.Tensor:
    """Each mask (B, H, W) under its own similarity."""
    out = []
    for k in range(masks.shape[0]):
        a = float(angle[k])
        rot = torch.tensor([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]], dtype=masks.dtype)
        out.append(_warp(masks[k : k + 1], rot, scale[k : k + 1], shift[k : k + 1], pivot))
    return torch.cat(out)


def align_to_view(problem, cand: PoseBatch, view: int = 0) -> PoseBatch:
    """Candidates (a PoseBatch on the problem's device) moved so that their shadows in one of
    the problem's views best match its target in 2D (similarity_align, apply_similarity)."""
    scene = problem.views[view].scene
    point = scene.light.type == "point"
    target = problem.level(ALIGN_FRAME_PX, view).maps.target.cpu()
    angle, scale, shift, _ = similarity_align(
        problem.shadows(cand, ALIGN_FRAME_PX, view).cpu(),
        target,
        pivot_pixel(scene, ALIGN_FRAME_PX),
        ALIGN_ANGLES_DEG,
        ALIGN_SCALES if point else np.array([1.0]),
    )
    if not point:
        scale = torch.ones_like(scale)
    return apply_similarity(cand.to("cpu"), angle, scale, shift, scene, ALIGN_FRAME_PX).to(problem.device)


def views_start_score(problem, poses: PoseBatch) -> torch.Tensor:
    """(B,) :func:`start_score` at ALIGN_FRAME_PX in every view of the problem, weighted by
    the views' weights (view 0's alone with one view)."""
    scores = [
        start_score(problem.shadows(poses, ALIGN_FRAME_PX, k).cpu(), problem.level(ALIGN_FRAME_PX, k).maps)
        for k in range(len(problem.views))
    ]
    if len(scores) == 1:
        return scores[0]
    return sum(v.weight * s for v, s in zip(problem.views, scores))


def view_turns_rad(problem) -> list[float]:
    """The turns about the vertical (+y, radians) tried on every candidate: none with one
    view; with more, also half and all of each further view's turn from view 0. Candidates
    are mostly held toward view 0's lamp, their forearms hidden behind the hands; turned by
    half, the forearms point between the lamps, where a performer lit by both stands."""
    turns = [0.0]
    n0 = np.asarray(problem.views[0].scene.wall.normal, float)
    for view in problem.views[1:]:
        n = np.asarray(view.scene.wall.normal, float)
        angle = math.atan2(float(np.cross(n0, n)[1]), float(n0 @ n))
        turns += [angle / 2, angle]
    return turns


def turned_about_vertical(poses: PoseBatch, angle_rad: float) -> PoseBatch:
    """Each hypothesis turned by angle_rad about the vertical (+y) through its wrists' mean
    (positive: from +z toward +x, as scene.Scene.turned)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    dtype = poses.hands[0].rotation.dtype
    rot = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], dtype=dtype, device=poses.hands[0].rotation.device)
    centre = torch.stack([h.translation for h in poses.hands]).mean(0)
    hands = [
        HandPoseBatch(h.pose_rad, rot @ h.rotation, (h.translation - centre) @ rot.T + centre, h.wrist_rad)
        for h in poses.hands
    ]
    return PoseBatch(hands, poses.origins)
