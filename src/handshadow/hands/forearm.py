"""The forearm: a closed tube extruded from the hand mesh's open wrist boundary.

In a real hand shadow the forearm is lit too. The tube starts at the wrist boundary loop itself
(so hand and forearm form one closed surface), blends the loop's cross-section into an ellipse
over the first centimetres, widens toward the elbow like a real forearm, and ends in a rounded
cap. It rides on a forearm bone that turns about the wrist joint (flexion/extension and
radial/ulnar deviation, see model.py); the first 3.5 cm blend between hand and forearm so the
wrist bends smoothly. With the wrist straight it follows only the hand's global transform.

Its lengths are an adult's for the model's default hand and scale with the hand (HandRig.size):
a person's forearm grows with their hand, so a hand and forearm of another size are the default
ones scaled about the wrist.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from handshadow.hands.rig import HandRig, hand_length_m

FOREARM_LENGTH_M = 0.28  # wrist crease to elbow of an adult (about 25-28 cm); all lengths here x HandRig.size
WRIST_JOINT_DEPTH_M = 0.015  # the wrist's centre of rotation lies this far proximal of the opening
BLEND_M = 0.035  # forearm rings blend from the hand to the forearm bone over this length
WIDENING = 0.35  # cross-section scale at the widest point minus one (forearm vs. wrist)
_STATIONS_M = np.array([0.004, 0.010, 0.018, 0.028, 0.04, 0.055, 0.075, 0.10, 0.13, 0.16, 0.19, 0.22, 0.25, 0.27, 0.28])
_CAP_FRACTIONS = np.array([0.8, 0.5])  # rings of the rounded cap, as a share of the last radius


def forearm_geometry(rig: HandRig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """New vertices (N, 3) and faces (M, 3) of the forearm, indexed after the hand's vertices,
    and each new vertex's distance (N,) from the wrist opening along the forearm, metres.

    Raises ValueError if the hand mesh has no open wrist boundary.
    """
    loop = rig.wrist_loop
    if len(loop) < 3:
        raise ValueError(f"the {rig.model} {rig.side} hand mesh has no open wrist boundary for a forearm")
    ring0 = rig.rest_vertices[loop]
    centre, axis = forearm_axis(rig)
    size = rig.size
    offsets = ring0 - centre
    offsets -= np.outer(offsets @ axis, axis)
    ellipse = _ellipse_like(offsets)
    rings, station = [], []
    for s in _STATIONS_M * size:
        station.append(np.full(len(loop), s))
        blend = _smoothstep(s / (0.03 * size))
        scale = forearm_scale(s, size)
        rings.append(centre + s * axis + scale * ((1 - blend) * offsets + blend * ellipse))
    last_scale = 1.0 + WIDENING
    for k, f in enumerate(_CAP_FRACTIONS):
        depth = (FOREARM_LENGTH_M + 0.02 * np.sqrt(1 - f**2) * (k + 1) / len(_CAP_FRACTIONS)) * size
        rings.append(centre + depth * axis + f * last_scale * ellipse)
        station.append(np.full(len(loop), depth))
    tip = centre + (FOREARM_LENGTH_M + 0.025) * size * axis
    station.append(np.full(1, (FOREARM_LENGTH_M + 0.025) * size))

    n_hand, n_loop = rig.num_vertices, len(loop)
    vertices = np.concatenate([np.concatenate(rings), tip[None]])
    faces = []
    prev = loop
    for k in range(len(rings)):
        cur = n_hand + k * n_loop + np.arange(n_loop)
        for i in range(n_loop):
            j = (i + 1) % n_loop
            faces.append((prev[i], prev[j], cur[j]))
            faces.append((prev[i], cur[j], cur[i]))
        prev = cur
    tip_index = n_hand + len(rings) * n_loop
    for i in range(n_loop):
        faces.append((prev[i], prev[(i + 1) % n_loop], tip_index))
    return vertices, np.asarray(faces, dtype=np.int64), np.concatenate(station)


def wrist_centre(rig: HandRig) -> np.ndarray:
    """(3,) the wrist joint's centre of rotation, hand frame."""
    centre, axis = forearm_axis(rig)
    return centre + WRIST_JOINT_DEPTH_M * rig.size * axis


def forearm_axis(rig: HandRig) -> tuple[np.ndarray, np.ndarray]:
    """Centre of the wrist opening (3,) and the forearm's unit axis (3,): the opening's plane
    normal, pointing away from the fingers (-y in the hand frame), or the rig's own
    ``forearm_direction`` where it has one."""
    ring = rig.rest_vertices[rig.wrist_loop]
    centre = ring.mean(0)
    if rig.forearm_direction is not None:
        return centre, np.asarray(rig.forearm_direction, float)
    _, _, vt = np.linalg.svd(ring - centre)
    return centre, (vt[2] if vt[2][1] < 0 else -vt[2])


def sized_like(rig: HandRig, default: HandRig) -> HandRig:
    """``rig``, a shape of a hand model other than its default shape ``default`` (same side),
    with its size (its length against the default's, HandRig.size) and the default's forearm
    direction: a person's forearm is as long as their hand makes it and leads the same way."""
    direction = forearm_axis(default)[1] if len(default.wrist_loop) >= 3 else None
    return dataclasses.replace(rig, size=hand_length_m(rig) / hand_length_m(default), forearm_direction=direction)


def forearm_length_m(rig: HandRig) -> float:
    """Wrist crease to elbow, metres: FOREARM_LENGTH_M for the model's default hand, in
    proportion for others (HandRig.size)."""
    return FOREARM_LENGTH_M * rig.size


def forearm_scale(s: float, size: float = 1.0) -> float:
    """Cross-section scale at distance s (m) from the wrist of a forearm of HandRig.size
    ``size``: 1 at the wrist, 1 + WIDENING from 18 cm (times size) on, smoothly."""
    return 1.0 + WIDENING * _smoothstep(s / (0.18 * size))


def attach_forearm(rig: HandRig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hand plus forearm: vertices (V', 3), faces (F', 3), skin weights (V', K + 1).

    Column K is the forearm bone. Forearm rings blend from the root bone (bone 0, which only the
    global transform moves) to the forearm bone over the first BLEND_M; the hand's vertices
    keep their indices and weights.
    """
    extra_v, extra_f, station = forearm_geometry(rig)
    k = rig.skin_weights.shape[1]
    hand_w = np.concatenate([rig.skin_weights, np.zeros((rig.num_vertices, 1))], axis=1)
    w = np.array([_smoothstep(s / (BLEND_M * rig.size)) for s in station])
    weights = np.zeros((len(extra_v), k + 1))
    weights[:, 0] = 1.0 - w
    weights[:, k] = w
    return (
        np.concatenate([rig.rest_vertices, extra_v]),
        np.concatenate([rig.faces, extra_f]),
        np.concatenate([hand_w, weights]),
    )


def cap_wrist(rig: HandRig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hand alone, its wrist opening closed by a fan around the loop's centre, so the mesh is
    closed (the renderer relies on that). Returns vertices, faces, skin weights as attach_forearm."""
    loop = rig.wrist_loop
    if len(loop) < 3:
        return rig.rest_vertices, rig.faces, rig.skin_weights
    centre = rig.rest_vertices[loop].mean(0)
    c = rig.num_vertices
    fan = np.stack([loop, np.roll(loop, -1), np.full(len(loop), c)], 1)
    weights = np.zeros((1, rig.skin_weights.shape[1]))
    weights[0, 0] = 1.0
    return (
        np.concatenate([rig.rest_vertices, centre[None]]),
        np.concatenate([rig.faces, fan]),
        np.concatenate([rig.skin_weights, weights]),
    )


def _ellipse_like(offsets: np.ndarray) -> np.ndarray:
    """Points on the ellipse with the same second moments as ``offsets`` (L, 3), at the same
    angles, so the i-th ellipse point sits beside the i-th loop point."""
    cov = offsets.T @ offsets / len(offsets)
    evals, evecs = np.linalg.eigh(cov)
    a, b = evecs[:, 2], evecs[:, 1]  # in-plane principal axes
    ra, rb = np.sqrt(2 * evals[2]), np.sqrt(2 * evals[1])
    angles = np.arctan2((offsets @ b) / rb, (offsets @ a) / ra)
    return np.outer(ra * np.cos(angles), a) + np.outer(rb * np.sin(angles), b)


def _smoothstep(x: float) -> float:
    x = float(np.clip(x, 0.0, 1.0))
    return x * x * (3 - 2 * x)
