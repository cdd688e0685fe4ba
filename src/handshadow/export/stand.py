"""A stand that casts no shadow in the picture: a board in the wall's place, a foot, and rods
hidden behind the hands along the lamp's rays.

Why not a base on the table with struts up to the hands: a fitted shadow lies inside the image
frame without touching its edges, so every point of the hands projects inside the frame, and
anything that joins them to a base outside the frame's cone of light must, somewhere, project
onto the frame's edge, where the wall is lit. Only two places are dark from every part of the
picture: the hands' own shadow and the wall behind it. So the stand is

- the **board**: a plate whose front face is the wall (the picture falls on it) and that lies
  behind the wall plane, where nothing casts a shadow;
- the **rods**: cones with their apex at the lamp, from inside the hands back to the board. A
  cone with its apex at a point light casts the same small disc wherever it is cut, so a rod
  is hidden when the disc it casts from the hand lies inside the hands' shadow; the rods widen
  toward the board (stiff where they carry the most);
- the **foot**: a plate on the table under the frame's bottom edge, in front of the board, below
  the lowest ray of the picture.

Print coordinates (millimetres): x to the right of the performer, y up (the table is y = 0),
z from the back of the board toward the lamp. Laid on its back the board is the print bed.
"""

from __future__ import annotations

import dataclasses

import manifold3d as m3
import numpy as np
from scipy.ndimage import binary_dilation, distance_transform_edt

from handshadow.scene import Scene

ROD_SEGMENTS = 24
HIDE_MARGIN_PX = 1.5  # the disc a rod casts stays this far inside the hands' shadow
RODS_PER_PART = 2
CANDIDATE_RAYS = 600


@dataclasses.dataclass(frozen=True)
class StandSize:
    """Sizes of the stand, millimetres. board: thickness of the board (and the foot); margin:
    gap between the frame's bottom edge and the top of the foot; foot_min: shortest foot;
    mark: arms of the cross cut into the board where the torch points; rod_min, rod_max:
    a rod's radius where it leaves a hand (it widens toward the board)."""

    board: float = 2.5
    margin: float = 3.0
    foot_min: float = 30.0
    mark: float = 12.0
    rod_min: float = 1.0
    rod_max: float = 3.0

    @staticmethod
    def for_height(height_mm: float) -> StandSize:
        """Sizes that suit a print of this height (the defaults at 150 mm); the thinnest
        stay printable and stiff (a 2 mm board, 2 mm rods)."""
        k = height_mm / 150.0
        return StandSize(
            board=max(2.0, 2.5 * k), foot_min=max(20.0, 30.0 * k), mark=max(6.0, 12.0 * k), rod_max=max(1.2, 3.0 * k)
        )


@dataclasses.dataclass(frozen=True)
class Rod:
    """A cone along a lamp ray, from ``start`` (inside a hand, radius ``start_radius``) to
    ``end`` (inside the board, radius ``end_radius``); points (3,) in print millimetres.
    ``part``: index of the hand part it holds."""

    start: np.ndarray
    end: np.ndarray
    start_radius: float
    end_radius: float
    part: int


class StandError(ValueError):
    """No hidden rod can hold a part of the hands."""


def board_and_foot(scene: Scene, size: StandSize, foot_length: float) -> tuple[m3.Manifold, m3.Manifold]:
    """The board (behind the wall plane, spanning the image frame from the table up, with a
    shallow cross where the torch points) and the foot (on the table in front of it).
    Assumes print coordinates (see the module docstring): the wall is z = size.board facing
    +z, the frame's rectangle is axis-aligned in x and y, and the table is y = 0."""
    lo, hi = frame_box(scene)
    board = m3.Manifold.cube((hi[0] - lo[0], hi[1], size.board)).translate((lo[0], 0.0, 0.0))
    aim = np.asarray(scene.wall.point, float)  # the lamp's foot
    groove = (size.mark, 0.8, 1.2)  # length, width, depth * 2 (half of it cuts in)
    for arm in (groove, (groove[1], groove[0], groove[2])):
        board -= m3.Manifold.cube(arm, center=True).translate(tuple(aim))
    foot_top = lo[1] - size.margin
    foot = m3.Manifold.cube((hi[0] - lo[0], min(size.board, foot_top), foot_length + size.board / 2))
    return board, foot.translate((lo[0], 0.0, size.board / 2))


def frame_corners(scene: Scene) -> np.ndarray:
    """(4, 3) the image frame's corners on the wall."""
    o, u, v = (np.asarray(a, float) for a in (scene.image.origin, scene.image.u, scene.image.v))
    return np.stack([o, o + u, o + v, o + u + v])


def frame_box(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """The image frame's lowest and highest corners (3,) each."""
    corners = frame_corners(scene)
    return corners.min(0), corners.max(0)


def choose_rods(scene: Scene, parts: list[m3.Manifold], shadow: np.ndarray, size: StandSize) -> list[Rod]:
    """Up to RODS_PER_PART hidden rods for each part of the hands.

    Candidate rays run from the lamp through pixels deep inside the shadow (H, W) bool; along
    each, the longest stretch inside a part gives the rod's start (its middle), and the
    distance from the pixel to the nearest lit pixel bounds the disc the rod may cast, hence
    its radius. Per part the thickest rod is taken, then the thickest that stands apart from
    it. Raises StandError when a part has no ray deep enough in the shadow.
    """
    lamp = np.asarray(scene.light.position, float)
    pixel = float(np.linalg.norm(scene.image.v)) / scene.image.height
    depth_px = distance_transform_edt(shadow) - HIDE_MARGIN_PX  # room for the disc, pixels
    rows, cols = np.nonzero(depth_px * pixel >= size.rod_min)
    if len(rows) > CANDIDATE_RAYS:
        pick = np.random.default_rng(0).choice(len(rows), CANDIDATE_RAYS, replace=False)
        rows, cols = rows[pick], cols[pick]
    targets = scene.image.pixel_centres()[rows, cols]
    rods: list[Rod] = []
    for index, part in enumerate(parts):
        found = []
        for target, room_px in zip(targets, depth_px[rows, cols]):
            rod = _rod_through(part, index, lamp, target, room_px * pixel, size)
            if rod is not None:
                found.append(rod)
        if not found:
            raise StandError(f"part {index + 1} of the hands has no spot deep enough in the shadow for a rod")
        rods.extend(_spread(found, RODS_PER_PART))
    return rods


def _rod_through(
    part: m3.Manifold, index: int, lamp: np.ndarray, target: np.ndarray, room_mm: float, size: StandSize
) -> Rod | None:
    """The rod along the ray lamp -> target (a wall point) that starts in the middle of the
    ray's longest stretch inside ``part``, or None. room_mm: radius of the disc the rod may
    cast on the wall."""
    hits = part.ray_cast(lamp, target)
    if len(hits) < 2:
        return None
    t = np.array([h.distance for h in hits])[: len(hits) // 2 * 2].reshape(-1, 2)  # (in, out) pairs
    length = np.linalg.norm(target - lamp)
    best = int(np.argmax(t[:, 1] - t[:, 0]))
    stretch = (t[best, 1] - t[best, 0]) * length
    direction = (target - lamp) / length
    cos_wall = abs(direction[2])
    start_t = 0.5 * (t[best, 0] + t[best, 1])
    # A cone with apex at the lamp casts a disc of radius r_start * length / distance.
    radius = min(size.rod_max, 0.5 * stretch, room_mm * start_t * cos_wall**2)
    if radius < size.rod_min:
        return None
    end_t = 1.0 + (target[2] - size.board / 2) / (length * cos_wall)  # half-way into the board
    return Rod(
        start=lamp + start_t * (target - lamp),
        end=lamp + end_t * (target - lamp),
        start_radius=radius,
        end_radius=radius * end_t / start_t,
        part=index,
    )


def _spread(rods: list[Rod], count: int) -> list[Rod]:
    """The thickest rod, then each next the thickest among those far enough from the chosen
    (a third of the spread of all starts)."""
    starts = np.stack([r.start for r in rods])
    spacing = np.linalg.norm(starts.max(0) - starts.min(0)) / 3
    order = sorted(range(len(rods)), key=lambda i: -rods[i].start_radius)
    chosen = [order[0]]
    for i in order[1:]:
        if len(chosen) == count:
            break
        if all(np.linalg.norm(starts[i] - starts[j]) >= spacing for j in chosen):
            chosen.append(i)
    return [rods[i] for i in chosen]


def rod_solid(rod: Rod, stop_z: float | None = None) -> m3.Manifold:
    """The rod as a manifold3d cone; with ``stop_z`` it ends where it crosses z = stop_z
    (the wall plane, to cast its shadow alone)."""
    end, end_radius = rod.end, rod.end_radius
    axis = end - rod.start
    if stop_z is not None:
        s = (stop_z - rod.start[2]) / axis[2]
        end, end_radius = rod.start + s * axis, rod.start_radius + s * (rod.end_radius - rod.start_radius)
        axis = end - rod.start
    height = float(np.linalg.norm(axis))
    cone = m3.Manifold.cylinder(height, rod.start_radius, end_radius, ROD_SEGMENTS)
    return cone.transform(_frame_along(axis / height, rod.start))


def _frame_along(direction: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(3, 4) affine map taking +z to ``direction`` and the origin to ``origin``."""
    z = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z, origin])


def hidden(stand_mask: np.ndarray, shadow: np.ndarray) -> bool:
    """Whether a part of the stand casting ``stand_mask`` (H, W) bool adds no shadow to
    ``shadow`` (H, W) bool, with one pixel to spare."""
    return not (binary_dilation(stand_mask) & ~shadow).any()
