"""A hand rig: the rest mesh, its skeleton and skinning weights, in the hand's own frame.

Both backends (Anny, MANO) reduce to a :class:`HandRig`; :class:`~handshadow.hands.model.HandModel`
poses any rig with the same linear blend skinning.

The hand frame (see ``docs/conventions.md``):
    origin at the wrist joint; +y distal (wrist -> middle-finger knuckle); +z dorsal (out of the
    back of the hand); +x = y x z. The right hand's thumb is on -x, the left hand's on +x: the
    left hand is the mirror image (x -> -x) of the right.

The 15 articulated joints, in this order (``JOINT_NAMES``): thumb, index, middle, ring, little,
each J1, J2, J3 from the palm outward (thumb: CMC, MCP, IP; fingers: MCP, PIP, DIP). Each joint
has three anatomical axes, derived from the rest skeleton (:func:`anatomical_axes`):
    twist  about the bone, positive turning the pad toward the thumb side;
    spread about the palm normal, positive moving the bone toward the thumb side (radial);
    bend   about the lateral axis, positive moving the bone toward the palm (flexion).
With these signs the same angles give mirror-image poses on the left and right hand.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

Side = Literal["right", "left"]
FINGERS = ("thumb", "index", "middle", "ring", "little")
JOINT_NAMES = tuple(f"{finger}{k}" for finger in FINGERS for k in (1, 2, 3))
N_JOINTS = 15
# Keypoints returned by HandModel: the wrist, then per finger its three joints and its tip.
KEYPOINT_NAMES = ("wrist",) + tuple(
    name for finger in FINGERS for name in (f"{finger}1", f"{finger}2", f"{finger}3", f"{finger}_tip")
)


def check_side(side: str) -> Side:
    """Normalise 'right'/'left' (also 'R'/'L', 'r'/'l'); raise ValueError otherwise."""
    s = str(side).lower()
    if s in ("right", "r"):
        return "right"
    if s in ("left", "l"):
        return "left"
    raise ValueError(f"hand side must be 'right' or 'left', got {side!r}")


@dataclasses.dataclass(frozen=True)
class HandRig:
    """Everything needed to pose one hand, in the hand frame, metres, float64 numpy.

    Fields (V vertices, F faces, K skeleton bones):
        side: 'right' or 'left'.
        model: backend name ('anny' or 'mano').
        rest_vertices: (V, 3) rest mesh.
        faces: (F, 3) int64 triangles, outward (counter-clockwise seen from outside).
        skin_weights: (V, K) linear-blend-skinning weights, rows sum to 1.
        bone_heads: (K, 3) rotation centre of each bone.
        bone_parents: (K,) parent index, -1 for the root(s).
        joint_bones: (15,) the bone that each articulated joint rotates, in JOINT_NAMES order.
        joint_axes: (15, 3, 3) per joint the unit axes [twist, spread, bend] as rows.
        tip_vertices: (5,) a vertex at each fingertip (thumb..little).
        wrist_loop: (L,) vertex indices of the open boundary at the wrist, in order, or empty.
        posedirs: optional (V*3, 9*15) pose-corrective blend shapes (MANO), applied to the
            flattened (R_j - I) of the joint rotations in the backend's native frame.
        native_rotation: (3, 3) rotation from the backend's native frame to the hand frame
            (needed to apply posedirs); identity when posedirs is None.
        size: the hand's length (:func:`hand_length_m`) as a share of its model's default
            shape's: a person's forearm grows with their hand, so the forearm's lengths scale
            by it (hands.forearm).
        forearm_direction: optional (3,) unit axis of the forearm, hand frame; None: the normal
            of the wrist opening (hands.forearm.forearm_axis). A shape other than the model's
            default takes the default's, so its forearm leads the same way.
    """

    side: Side
    model: str
    rest_vertices: np.ndarray
    faces: np.ndarray
    skin_weights: np.ndarray
    bone_heads: np.ndarray
    bone_parents: np.ndarray
    joint_bones: np.ndarray
    joint_axes: np.ndarray
    tip_vertices: np.ndarray
    wrist_loop: np.ndarray
    posedirs: np.ndarray | None = None
    native_rotation: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(3))
    size: float = 1.0
    forearm_direction: np.ndarray | None = None

    @property
    def num_vertices(self) -> int:
        return int(self.rest_vertices.shape[0])

    @property
    def joint_heads(self) -> np.ndarray:
        """(15, 3) rest position of each articulated joint."""
        return self.bone_heads[self.joint_bones]


def hand_length_m(rig: HandRig) -> float:
    """The hand's length in metres as a person measures theirs: from the wrist (the hand
    frame's origin) to the tip of the middle finger, in the rest pose."""
    return float(np.linalg.norm(rig.rest_vertices[rig.tip_vertices[2]]))


def hand_frame(
    side: Side, wrist: np.ndarray, middle_mcp: np.ndarray, index_mcp: np.ndarray, little_mcp: np.ndarray
) -> np.ndarray:
    """Rotation (3, 3) whose rows are the hand frame's x, y, z axes in native coordinates.

    y: wrist -> middle knuckle. The radial direction r (little -> index knuckle) gives the dorsal
    axis z = -r x y for a right hand and r x y for a left hand (thumb on -x resp. +x).
    """
    y = _unit(middle_mcp - wrist)
    r = index_mcp - little_mcp
    r = _unit(r - y * (r @ y))
    z = np.cross(-r if side == "right" else r, y)
    x = np.cross(y, z)
    return np.stack([x, y, z])


def anatomical_axes(side: Side, joint_heads: np.ndarray, joint_children: np.ndarray) -> np.ndarray:
    """Per-joint [twist, spread, bend] unit axes (15, 3, 3), rows, in the hand frame.

    Args:
        side: which hand; the rest skeleton is already in the hand frame.
        joint_heads: (15, 3) joint centres, JOINT_NAMES order.
        joint_children: (15, 3) the next point along each finger (next joint or the tip).
    The volar direction is -z for the fingers; for the thumb it is tilted half-way toward the
    ulnar side (across the palm), the direction in which a thumb flexes.
    """
    radial = np.array([-1.0, 0.0, 0.0]) if side == "right" else np.array([1.0, 0.0, 0.0])
    volar_palm = np.array([0.0, 0.0, -1.0])
    axes = np.zeros((N_JOINTS, 3, 3))
    for j in range(N_JOINTS):
        d = _unit(joint_children[j] - joint_heads[j])
        v = volar_palm if j >= 3 else _unit(volar_palm - radial)
        v = _unit(v - d * (v @ d))
        # The radial direction orthogonal to d and v (toward the thumb, whichever the side).
        r = _unit(np.cross(d, v)) if side == "right" else _unit(np.cross(v, d))
        bend = np.cross(d, v)  # rotating d about bend moves it toward v
        spread = np.cross(d, r)  # rotating d about spread moves it toward r
        twist = np.cross(v, r)  # rotating v about twist moves it toward r (= +-d)
        axes[j] = np.stack([_unit(twist), _unit(spread), _unit(bend)])
    return axes


def canonicalise(
    side: Side,
    model: str,
    vertices: np.ndarray,
    faces: np.ndarray,
    skin_weights: np.ndarray,
    bone_heads: np.ndarray,
    bone_parents: np.ndarray,
    joint_bones: np.ndarray,
    wrist_bone: int,
    tip_vertices: np.ndarray,
    posedirs: np.ndarray | None = None,
) -> HandRig:
    """Build a HandRig from native rest data: move the wrist to the origin and rotate into the
    hand frame, then derive the anatomical axes of the joints.

    Args are native-frame arrays as documented on HandRig; ``wrist_bone`` is the bone whose head
    is the wrist; ``joint_bones`` lists the 15 articulated bones in JOINT_NAMES order.
    """
    heads = bone_heads[joint_bones]
    frame = hand_frame(side, bone_heads[wrist_bone], heads[6], heads[3], heads[12])
    origin = bone_heads[wrist_bone]

    def to_hand(p):
        return (p - origin) @ frame.T

    verts = to_hand(vertices)
    heads_h = to_hand(bone_heads)
    jheads = heads_h[joint_bones]
    children = np.empty_like(jheads)
    for j in range(N_JOINTS):
        children[j] = jheads[j + 1] if j % 3 != 2 else verts[tip_vertices[j // 3]]
    axes = anatomical_axes(side, jheads, children)
    faces = np.asarray(faces, dtype=np.int64)
    return HandRig(
        side=side,
        model=model,
        rest_vertices=verts,
        faces=faces,
        skin_weights=skin_weights / skin_weights.sum(1, keepdims=True),
        bone_heads=heads_h,
        bone_parents=np.asarray(bone_parents, dtype=np.int64),
        joint_bones=np.asarray(joint_bones, dtype=np.int64),
        joint_axes=axes,
        tip_vertices=np.asarray(tip_vertices, dtype=np.int64),
        wrist_loop=boundary_loop(faces),
        posedirs=posedirs,
        native_rotation=frame if posedirs is not None else np.eye(3),
    )


def fingertip_vertices(
    vertices: np.ndarray, skin_weights: np.ndarray, bone_heads: np.ndarray, joint_bones: np.ndarray
) -> np.ndarray:
    """(5,) per finger the vertex farthest along its last bone, among the vertices that bone
    drives most."""
    tips = []
    for f in range(5):
        last, before = joint_bones[3 * f + 2], joint_bones[3 * f + 1]
        direction = bone_heads[last] - bone_heads[before]
        owned = np.flatnonzero(skin_weights.argmax(1) == last)
        tips.append(owned[np.argmax((vertices[owned] - bone_heads[last]) @ direction)])
    return np.asarray(tips, dtype=np.int64)


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Every loop of boundary edges (edges used by one face), each ordered against the faces
    beside it (b -> a along a face's edge a -> b), so that a face added outside the loop, or a
    fan that closes it, runs the same way as the mesh. Empty if the mesh is closed."""
    f = np.asarray(faces)
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    undirected = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(undirected, axis=0, return_inverse=True, return_counts=True)
    boundary = directed[counts[inverse.ravel()] == 1]
    nxt = {int(b): int(a) for a, b in boundary}
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt.get(v, start)
        loops.append(np.asarray(loop, dtype=np.int64))
    return loops


def boundary_loop(faces: np.ndarray) -> np.ndarray:
    """The longest of :func:`boundary_loops`; empty if the mesh is closed."""
    loops = boundary_loops(faces)
    return max(loops, key=len) if loops else np.zeros(0, dtype=np.int64)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)
