"""An atlas of one-hand shadows: thousands of hand poses seen from many directions, each with a
shape descriptor, built once into the cache; the search retrieves the nearest entries as
starts, for the whole target and, with two hands, for what the first hand leaves uncovered.

Entries. Finger configurations mix straight, half-bent and curled fingers (curled no further
than a fist whose fingertips stay out of the palm), spread, thumb postures, and rings where the
thumb's tip meets the index or middle fingertip (holes in the shadow). Each is seen from many
directions: mostly with the forearm leading back toward the lamp, where it hides behind the
hand and the wrist bends the hand across the beam, and some with the forearm in view (leading
back from the wall all the same, as a performer's forearm does).

Descriptor. Around its centroid the shadow is sampled on a polar grid whose radius follows the
shadow's size; the magnitudes of the first harmonics over the angle make it blind to turning,
mirroring, shifting and scaling, so one descriptor serves every alignment. Holes and notches
change the radial profile, so they count.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time

import numpy as np
import torch
import torch.nn.functional as F

from handshadow.hands import load_hand
from handshadow.hands.kinematics import rotvec_to_rotmat
from handshadow.hands.limits import JointLimits
from handshadow.hands.rig import KEYPOINT_NAMES
from handshadow.paths import cache_dir
from handshadow.poses import HandPoseBatch
from handshadow.scene import Scene

log = logging.getLogger(__name__)
VERSION = 2  # 2: every forearm leads back from the wall
FRAME_PX = 64  # atlas shadows are this many pixels high (the alignment's resolution)
CONFIGS = 160  # random finger configurations
RINGS = 16  # configurations whose thumb tip meets the index or middle fingertip
VIEWS = 24  # directions each configuration is seen from
HIDDEN_SHARE = 0.75  # of the views, this share has the forearm leading back toward the lamp
HIDDEN_CONE_DEG = 8.0  # ... within this angle of the light's ray (farther, its shadow shows)
BENT_WRIST_SHARE = 0.6  # hidden views bend the wrist at least this share of its range
WRIST_DEPTH_M = 1.0  # entries hold the wrist this far from the wall, on the lamp's axis
POLAR_RADII = 24
POLAR_ANGLES = 64
POLAR_REACH = 2.5  # the polar grid reaches this many equivalent radii from the centroid
HARMONICS = 9
# Finger states (MCP, PIP, DIP bends, degrees) and how often each is drawn.
FINGER_STATES = np.array([[0.0, 0.0, 0.0], [40.0, 45.0, 30.0], [50.0, 60.0, 40.0], [0.0, 60.0, 40.0]])
FINGER_STATE_P = [0.4, 0.25, 0.25, 0.1]


@dataclasses.dataclass(frozen=True)
class Atlas:
    """N right-hand entries: poses (HandPoseBatch of N, the wrist at (0, 0, WRIST_DEPTH_M) in
    the default scene), their shadows (N, FRAME_PX, FRAME_PX) bool in the default scene's
    frame, and descriptors (N, D) float32, unit length."""

    poses: HandPoseBatch
    masks: np.ndarray
    descriptors: np.ndarray

    def nearest(self, descriptor: np.ndarray, k: int) -> np.ndarray:
        """Indices of the k entries nearest a descriptor (D,), nearest first."""
        d = ((self.descriptors - descriptor[None]) ** 2).sum(1)
        k = min(k, len(d))
        idx = np.argpartition(d, k - 1)[:k]
        return idx[np.argsort(d[idx])]


def shape_descriptor(masks: torch.Tensor) -> torch.Tensor:
    """Descriptors (B, D) of shadows (B, H, W) in [0, 1]: harmonic magnitudes of a polar
    resampling about each centroid, radius scaled to the shadow's equivalent radius; blind to
    turning, mirroring, shifting and scaling. Unit length; an empty shadow gives zeros."""
    b, h, w = masks.shape
    m = masks.float()
    area = m.sum((1, 2)).clamp(min=1.0)
    ys, xs = torch.meshgrid(torch.arange(h) + 0.5, torch.arange(w) + 0.5, indexing="ij")
    cx, cy = (m * xs).sum((1, 2)) / area, (m * ys).sum((1, 2)) / area
    r0 = torch.sqrt(area / math.pi)
    radii = torch.linspace(0.05, POLAR_REACH, POLAR_RADII)
    angles = torch.arange(POLAR_ANGLES) * (2 * math.pi / POLAR_ANGLES)
    px = cx[:, None, None] + r0[:, None, None] * radii[None, :, None] * torch.cos(angles)[None, None]
    py = cy[:, None, None] + r0[:, None, None] * radii[None, :, None] * torch.sin(angles)[None, None]
    grid = torch.stack([px / w * 2 - 1, py / h * 2 - 1], -1)  # (B, R, A, 2)
    polar = F.grid_sample(m[:, None], grid, align_corners=False, padding_mode="zeros")[:, 0]
    spectrum = torch.fft.rfft(polar, dim=-1).abs()[..., :HARMONICS] / POLAR_ANGLES  # (B, R, K)
    out = spectrum.flatten(1)
    return out / out.norm(dim=1, keepdim=True).clamp(min=1e-9)


def finger_configurations(n: int, rings: int, limits: JointLimits, rng: np.random.Generator) -> np.ndarray:
    """(n + rings, 15, 3) radians: random finger states with spread, and thumb postures; the
    last ``rings`` are starting guesses for rings that :func:`close_rings` closes."""
    lo, hi = limits.joints[..., 0].cpu().numpy(), limits.joints[..., 1].cpu().numpy()
    pose = np.zeros((n + rings, 15, 3))
    for f in range(1, 5):
        state = rng.choice(len(FINGER_STATES), size=n + rings, p=FINGER_STATE_P)
        pose[:, 3 * f : 3 * f + 3, 2] = np.radians(FINGER_STATES[state] + rng.normal(0, 6, (n + rings, 3)))
        pose[:, 3 * f, 1] = np.radians(rng.normal(0, 9, n + rings))
    # Thumb: CMC twist, abduction and flexion anywhere in their ranges; MCP and IP from straight to bent.
    pose[:, 0] = rng.uniform(lo[0], hi[0], (n + rings, 3))
    pose[:, 1:3, 2] = rng.uniform(0.0, 1.0, (n + rings, 2)) * hi[1:3, 2]
    for k in range(rings):  # rings: the index (or middle) finger half bent toward the thumb
        f = 1 if k % 2 == 0 else 2
        pose[n + k, 3 * f : 3 * f + 3, 2] = np.radians([35.0, 40.0, 25.0]) + rng.normal(0, 0.05, 3)
        pose[n + k, 0] = np.radians([20.0, 30.0, 30.0]) + rng.normal(0, 0.08, 3)
    return np.clip(pose, lo, hi)


def close_rings(model, pose: torch.Tensor, fingers: list[int], limits: JointLimits, steps: int = 150) -> torch.Tensor:
    """Bend thumb and finger so that their tips meet: pose (R, 15, 3) radians, fingers (R,)
    1 (index) or 2 (middle). Returns the poses, within the limits."""
    lo, hi = limits.joints[..., 0], limits.joints[..., 1]
    moving = torch.zeros(15, 3, dtype=torch.bool)
    moving[0:3] = True
    moving[3:9, 2] = True
    z = pose.clone().requires_grad_(True)
    opt = torch.optim.Adam([z], lr=0.02)
    tips = torch.as_tensor(model.tip_vertices)
    finger = torch.as_tensor(fingers)
    for _ in range(steps):
        opt.zero_grad()
        angles = torch.minimum(torch.maximum(torch.where(moving, z, pose), lo), hi)
        v = model(angles).vertices
        gap = v[:, tips[0]] - v[torch.arange(len(finger)), tips[finger]]
        (gap**2).sum().backward()
        opt.step()
    with torch.no_grad():
        return torch.minimum(torch.maximum(torch.where(moving, z, pose), lo), hi)


def wrist_angles(n: int, limits: JointLimits, rng: np.random.Generator) -> np.ndarray:
    """(n, 2) wrist flexion and deviation, radians, in VIEWS-long runs: in the hidden views
    (the first HIDDEN_SHARE of each run) the wrist bends far (at least BENT_WRIST_SHARE of its
    range either way), so the hand turns across the beam its forearm hides along; elsewhere
    anywhere in its range."""
    (flo, fhi), (dlo, dhi) = limits.wrist.cpu().numpy()
    out = np.stack([rng.uniform(flo, fhi, n), rng.uniform(dlo, dhi, n)], 1)
    hidden = (np.arange(n) % VIEWS) < round(VIEWS * HIDDEN_SHARE)
    far = rng.uniform(BENT_WRIST_SHARE, 1.0, n) * np.where(rng.uniform(size=n) < 0.5, flo, fhi)
    out[hidden, 0] = far[hidden]
    return out


def arm_directions(n: int, rng: np.random.Generator, hidden_share: float = HIDDEN_SHARE) -> np.ndarray:
    """(n, 3) unit directions for the forearm (wrist to elbow), world frame, in VIEWS-long
    runs: the first ``hidden_share`` of each run within HIDDEN_CONE_DEG of the ray toward the
    lamp (+z), the rest any way that leads back from the wall (z >= 0): a forearm toward the
    wall is one no performer can hold (hands.arms), so no start should have it."""
    tilt = np.radians(HIDDEN_CONE_DEG) * np.sqrt(rng.uniform(size=n))
    azimuth = rng.uniform(0, 2 * np.pi, n)
    toward_lamp = np.stack([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)], 1)
    free = rng.normal(size=(n, 3))
    free /= np.linalg.norm(free, axis=1, keepdims=True)
    free[:, 2] = np.abs(free[:, 2])
    hidden = (np.arange(n) % VIEWS) < round(VIEWS * hidden_share)
    return np.where(hidden[:, None], toward_lamp, free)


def arm_axis(out) -> torch.Tensor:
    """(B, 3) the direction from the wrist toward the elbow of posed hands (HandOutput): along
    the forearm's axis, or for a hand without one, from the middle finger's base back through
    the wrist (the way the arm would go)."""
    if out.forearm_points.shape[1]:
        return out.forearm_points[:, -1] - out.forearm_points[:, 0]
    return out.keypoints[:, 0] - out.keypoints[:, KEYPOINT_NAMES.index("middle1")]


def turn_onto(a: np.ndarray, b: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations taking unit vectors a (n, 3) onto b (n, 3), then turning by roll
    (n,) radians about b."""
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=1, keepdims=True)
    c = (a * b).sum(1, keepdims=True)
    angle = np.arctan2(s, c)
    axis = np.where(s > 1e-9, axis / np.maximum(s, 1e-12), np.array([1.0, 0.0, 0.0]))
    align = rotvec_to_rotmat(torch.as_tensor(axis * angle)).numpy()
    spin = rotvec_to_rotmat(torch.as_tensor(b * roll[:, None])).numpy()
    return spin @ align


def build_atlas(model, limits: JointLimits, seed: int = 0, batch: int = 256) -> Atlas:
    """Pose, render and describe every entry (the right hand ``model``, float32, CPU)."""
    from handshadow.render import ShadowRenderer

    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    configs = torch.as_tensor(finger_configurations(CONFIGS, RINGS, limits, rng), dtype=torch.float32)
    ring_fingers = [1 if k % 2 == 0 else 2 for k in range(RINGS)]
    configs[CONFIGS:] = close_rings(model, configs[CONFIGS:], ring_fingers, limits)
    n = len(configs) * VIEWS
    pose = configs.repeat_interleave(VIEWS, 0)
    wrist = torch.as_tensor(wrist_angles(n, limits, rng), dtype=torch.float32)
    with torch.no_grad():  # each entry's forearm direction in its hand frame, its wrist bent
        axis = arm_axis(model(pose, wrist_rad=wrist)).double().numpy()
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    # A hand without a forearm has nothing to hide along the beam: every view any way at all.
    directions = arm_directions(n, rng, HIDDEN_SHARE if model.has_forearm else 0.0)
    rotation = torch.as_tensor(turn_onto(axis, directions, rng.uniform(0, 2 * np.pi, n)), dtype=torch.float32)
    translation = torch.tensor([0.0, 0.0, WRIST_DEPTH_M]).expand(n, 3).clone()
    poses = HandPoseBatch(pose, rotation, translation, wrist)
    scene = Scene.default(FRAME_PX, FRAME_PX)
    renderer = ShadowRenderer(scene, [model.faces], [model.num_vertices])
    masks = []
    with torch.no_grad():
        for i in range(0, n, batch):
            masks.append(renderer.render([model(*poses.select(slice(i, i + batch)).args()).vertices]).mask > 0.5)
    masks = torch.cat(masks)
    descriptors = shape_descriptor(masks.float())
    log.info("built the shadow atlas: %d entries in %.1f s", n, time.perf_counter() - t0)
    return Atlas(poses, masks.numpy(), descriptors.numpy())


def load_atlas(hand_model: str = "anny", forearm: bool = True, preset: str = "anatomical") -> Atlas:
    """The right-hand atlas of a hand model and joint-limit preset, from the cache (built on
    first use, on the CPU, in well under a minute)."""
    key = f"atlas-v{VERSION}-{hand_model}-{'forearm' if forearm else 'hand'}-{preset}"
    path = cache_dir() / "atlas" / f"{key}.npz"
    if path.is_file():
        try:
            with np.load(path) as f:
                poses = HandPoseBatch(*(torch.as_tensor(f[k]) for k in ("pose", "rotation", "translation", "wrist")))
                masks = np.unpackbits(f["masks"], axis=-1)[..., :FRAME_PX].astype(bool)
                return Atlas(poses, masks, f["descriptors"])
        except (OSError, KeyError, ValueError):
            log.info("the cached atlas at %s is unreadable: building it again", path)
    model = load_hand(hand_model, "right", forearm=forearm)
    atlas = build_atlas(model, JointLimits.preset(preset, "right"))
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".partial.npz")
    p = atlas.poses
    np.savez_compressed(
        partial,
        pose=p.pose_rad.numpy(),
        rotation=p.rotation.numpy(),
        translation=p.translation.numpy(),
        wrist=p.wrist_rad.numpy(),
        masks=np.packbits(atlas.masks, axis=-1),
        descriptors=atlas.descriptors,
    )
    partial.replace(path)
    return atlas
