"""The scene: a light, a wall plane and an image frame on the wall (metres, world frame).

World frame (docs/conventions.md): the wall is the plane z = 0 and faces +z; the lamp stands
2 m in front of it on the z axis; +y is up and +x is to the right of a person who stands by the
lamp and looks at the wall. The image frame is centred on the foot of the lamp.

Pixel convention: the centre of pixel (row i, column j) is
    origin + (j + 0.5) / W * u + (i + 0.5) / H * v,
with ``origin`` the frame's outer top-left corner, ``u`` its full width (left to right) and
``v`` its full height (top to bottom). Continuous pixel coordinates (x, y) = (column, row)
measured from the top-left corner put pixel centres at (j + 0.5, i + 0.5).

``scene.json`` contract (written by :meth:`Scene.to_json`):
    {"light": {"type": "point", "position": [x, y, z]}  or  {"type": "directional",
     "direction": [x, y, z]},
     "wall": {"point": [...], "normal": [...]},
     "image": {"width": W, "height": H, "origin": [...], "u": [...], "v": [...]},
     "meshes": ["left.obj", "right.obj"]}

Several views (one pose, one lamp and wall per target): ``scene.json`` is then a list of such
objects, view 0 first, each complete under the contract above (:func:`views_to_json`,
:func:`views_from_json`). View k > 0 is view 0 turned about the vertical axis through
VIEW_AXIS_POINT_M, where the hands work (:meth:`Scene.turned`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Literal

import numpy as np

from handshadow.errors import HandshadowError

if TYPE_CHECKING:
    import torch

LightType = Literal["point", "directional"]
LAMP_TO_WALL_M = 2.0
# The lamp's distance from the wall a user may choose (Scene.default's lamp_to_wall_m), metres:
# from the default out to a long room's length. A farther lamp casts the same picture from
# hands farther from the wall, with less perspective (a forearm behind its hand is magnified
# less than it, docs/performing.md).
LAMP_TO_WALL_RANGE_M = (LAMP_TO_WALL_M, 5.0)
# A fit's lamp unless told otherwise (one view; two views keep LAMP_TO_WALL_M): a forearm
# 28 cm behind its hand is magnified 1.16 times the hand's scale here, 1.39 times at 2 m, so
# it hides behind the hand far better (docs/measured.md, "Lamp distance": 16 HSP targets, 10 against 8).
FIT_LAMP_TO_WALL_M = 4.0
FRAME_HEIGHT_M = {"point": 0.8, "directional": 0.4}  # a hand's shadow fills about half of it
# The shape's size on the wall that the search works at: its longer side is this share of the
# default frame's height (each of the 95 HSP masks: 0.711 to 0.719). A fit sizes its frame on
# the wall (one view) so that the target's shape has that size whatever the picture's margins
# (frame_height_for): a tightly cropped shape, drawn larger in its frame, would otherwise ask for
# hands nearer the lamp, whose forearms then show (docs/measured.md, "A shape's size in its frame").
WORKING_EXTENT = 0.715
FRAME_SIZE_TOLERANCE = 0.05  # a shape within this share of that size keeps the default frame
FRAME_SCALE_RANGE = (0.25, 4.0)  # the frame's height, times the default, at the most
# A shape that meets its frame's edge has run off it (a forearm's shadow leaving the picture,
# each crossing 9 to 23 % of the side in bench/recover.py's targets), unless it meets both
# ends of one side's span only in short runs, under this share of the side each: then the
# picture was cropped to the shape, which grazes the edges (frame_height_for).
GRAZING_SHARE = 0.05
# Where hands belong, as distances in front of the wall (Scene.placement_range):
WALL_CLEARANCE_M = 0.03  # the nearest a hand comes to the wall while the search runs
LAMP_CLEARANCE_M = 0.25  # room kept before the lamp (a point light)
FARTHEST_M = 3.0  # the farthest from the wall (a directional light has no lamp to stop at)
RESULT_MARGIN_M = 0.005  # a result keeps at least this from the wall and the lamp's plane
# Further views turn the lamp, the wall and the frame about the vertical line through this
# point: midway between the default lamp and wall, where the hands work (1 m from each).
VIEW_AXIS_POINT_M = (0.0, 0.0, LAMP_TO_WALL_M / 2)
# The turn of a second view, degrees, either way: from 45 the frames of both views stay in
# front of the other view's wall (a frame 0.8 m high, 1 m from the axis: 1 - cos a >= 0.4 sin a);
# up to 135 the second lamp stays LAMP_CLEARANCE_M in front of the first wall (1 + cos a >= 0.25).
VIEW_ANGLE_MIN_DEG = 45.0
VIEW_ANGLE_MAX_DEG = 135.0
TURN_DIGITS = 12  # a turned scene's coordinates are rounded to this many decimals (1e-12 m)
UNIT_ROUNDS = 4  # normalisations that bring a direction's length to exactly 1.0


class SceneError(HandshadowError):
    """A scene description that cannot be used."""


@dataclasses.dataclass(frozen=True)
class Light:
    """A point light at ``position`` or a directional light shining along ``direction``."""

    type: LightType
    position: tuple[float, float, float] | None = None
    direction: tuple[float, float, float] | None = None


@dataclasses.dataclass(frozen=True)
class Wall:
    point: tuple[float, float, float]
    normal: tuple[float, float, float]  # unit, facing the light


@dataclasses.dataclass(frozen=True)
class ImageFrame:
    width: int
    height: int
    origin: tuple[float, float, float]
    u: tuple[float, float, float]
    v: tuple[float, float, float]

    def pixel_centres(self) -> np.ndarray:
        """(H, W, 3) world positions of the pixel centres, float64."""
        j = (np.arange(self.width) + 0.5) / self.width
        i = (np.arange(self.height) + 0.5) / self.height
        o, u, v = (np.asarray(a, dtype=np.float64) for a in (self.origin, self.u, self.v))
        return o + j[None, :, None] * u + i[:, None, None] * v


@dataclasses.dataclass(frozen=True)
class Scene:
    light: Light
    wall: Wall
    image: ImageFrame

    # -- construction -------------------------------------------------------------------
    @staticmethod
    def default(
        width: int = 256,
        height: int = 256,
        light: LightType = "point",
        lamp_to_wall_m: float = LAMP_TO_WALL_M,
        frame_height_m: float | None = None,
    ) -> Scene:
        """A lamp ``lamp_to_wall_m`` (default 2 m, within LAMP_TO_WALL_RANGE_M) in front of a
        wall, the image frame centred on the wall; the frame's size does not depend on it. The
        frame is ``frame_height_m`` high on the wall (None: FRAME_HEIGHT_M of the light)."""
        check_lamp_distance(lamp_to_wall_m)
        if light not in ("point", "directional"):
            raise SceneError(f"light must be 'point' or 'directional', got {light!r}")
        if width < 1 or height < 1:
            raise SceneError(f"image size must be positive, got {width} x {height}")
        h_m = FRAME_HEIGHT_M[light] if frame_height_m is None else float(frame_height_m)
        if not (math.isfinite(h_m) and h_m > 0):
            raise SceneError(f"the frame's height must be a positive number of metres, got {h_m:g}")
        w_m = h_m * width / height
        lamp = (0.0, 0.0, float(lamp_to_wall_m))
        return Scene(
            light=Light("point", position=lamp)
            if light == "point"
            else Light("directional", direction=(0.0, 0.0, -1.0)),
            wall=Wall(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0)),
            image=ImageFrame(
                width=width, height=height, origin=(-w_m / 2, h_m / 2, 0.0), u=(w_m, 0.0, 0.0), v=(0.0, -h_m, 0.0)
            ),
        )

    def turned(self, angle_deg: float, about: tuple[float, float, float] = VIEW_AXIS_POINT_M) -> Scene:
        """The same lamp, wall and frame turned by angle_deg about the vertical (+y) axis
        through ``about`` (metres): positive turns the lamp from in front of the wall toward
        +x, the performer's right; 90 puts it 1 m to the right of the hands and the wall 1 m
        to their left, facing it."""
        a = math.radians(angle_deg)
        rot = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
        pivot = np.asarray(about, float)

        def point(p):
            return _clean(rot @ (np.asarray(p, float) - pivot) + pivot)

        def vector(d):
            return _clean(rot @ np.asarray(d, float))

        def direction(d):
            return _unit(vector(d))

        light = (
            Light("point", position=point(self.light.position))
            if self.light.type == "point"
            else Light("directional", direction=direction(self.light.direction))
        )
        im = self.image
        return Scene(
            light=light,
            wall=Wall(point=point(self.wall.point), normal=direction(self.wall.normal)),
            image=ImageFrame(im.width, im.height, point(im.origin), vector(im.u), vector(im.v)),
        )

    @property
    def frame_height_m(self) -> float:
        """The image frame's height on the wall (metres)."""
        return float(np.linalg.norm(self.image.v))

    def with_size(self, width: int, height: int) -> Scene:
        """The same frame rasterised at another resolution."""
        return dataclasses.replace(self, image=dataclasses.replace(self.image, width=width, height=height))

    # -- geometry -----------------------------------------------------------------------
    def light_depth_range(self) -> tuple[float, float]:
        """Distances along the wall normal (from the wall) between which geometry casts a
        shadow: (0, lamp distance) for a point light, (0, inf) for a directional one."""
        if self.light.type == "point":
            n = np.asarray(self.wall.normal)
            return 0.0, float((np.asarray(self.light.position) - np.asarray(self.wall.point)) @ n)
        return 0.0, math.inf

    def placement_range(self) -> tuple[float, float]:
        """Distances from the wall (metres, along its normal) where the search keeps the hands:
        off the wall by WALL_CLEARANCE_M, and LAMP_CLEARANCE_M short of a point light or at most
        FARTHEST_M out under a directional one. Inside :meth:`light_depth_range`, which is the
        physical bound."""
        _, hi = self.light_depth_range()
        return WALL_CLEARANCE_M, hi - LAMP_CLEARANCE_M if math.isfinite(hi) else FARTHEST_M

    def working_depth(self) -> float:
        """Distance from the wall (metres) where a hand's shadow is about twice its size, which
        fills about half the frame: halfway to a point light (1 m under the default lamp), 1 m
        under a directional one (whose frame is half as high). Starts are placed there."""
        _, hi = self.light_depth_range()
        return hi / 2 if math.isfinite(hi) else 1.0

    def projection_matrix(self) -> np.ndarray:
        """(4, 4) matrix M mapping a world point p to (x', y', w', h) = M [p, 1], with the pixel
        coordinates (x'/w', y'/w') of its shadow and its height h above the wall (metres).

        Point light L, wall n . q = c: the ray L + s (p - L) meets the wall where
        s = (c - n.L) / n.(p - L), so both pixel coordinates are ratios of affine functions of
        p with the common denominator w' = n.(p - L). A directional light gives w' = 1.
        """
        n = np.asarray(self.wall.normal, float)
        c = float(n @ np.asarray(self.wall.point, float))
        o, u, v = (np.asarray(a, float) for a in (self.image.origin, self.image.u, self.image.v))
        scaled = [u / (u @ u) * self.image.width, v / (v @ v) * self.image.height]
        m = np.zeros((4, 4))
        if self.light.type == "point":
            lamp = np.asarray(self.light.position, float)
            k = c - n @ lamp
            for row, a in enumerate(scaled):  # a . (L - o) w' + k a . (p - L)
                m[row, :3] = (a @ (lamp - o)) * n + k * a
                m[row, 3] = -(a @ (lamp - o)) * (n @ lamp) - k * (a @ lamp)
            m[2, :3], m[2, 3] = n, -(n @ lamp)
        else:
            d = np.asarray(self.light.direction, float)
            for row, a in enumerate(scaled):  # a . (p + d (c - n.p) / n.d - o)
                m[row, :3] = a - (a @ d) / (n @ d) * n
                m[row, 3] = (a @ d) * c / (n @ d) - a @ o
            m[2, 3] = 1.0
        m[3, :3], m[3, 3] = n, -c
        return m

    def project(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Project points from the light onto the wall, in continuous pixel coordinates.

        Args:
            points: (..., 3) world positions, metres.
        Returns:
            xy: (..., 2) (column, row) pixel coordinates; pixel centres at (j+0.5, i+0.5).
            height: (...,) distance of each point in front of the wall along its normal, metres.
                The projection is valid for 0 < height < lamp distance (point light).
        Differentiable in ``points``; constants follow the points' device and dtype.
        """
        import torch

        m = torch.as_tensor(self.projection_matrix(), dtype=points.dtype, device=points.device)
        out = points @ m[:, :3].T + m[:, 3]
        return out[..., :2] / out[..., 2:3], out[..., 3]

    def pixel_size_m(self) -> float:
        """Edge length of one pixel on the wall, metres (pixels are square by construction)."""
        return float(np.linalg.norm(self.image.v)) / self.image.height

    # -- scene.json ---------------------------------------------------------------------
    def to_json(self, meshes: list[str] | None = None) -> dict:
        light = {"type": self.light.type}
        if self.light.type == "point":
            light["position"] = list(map(float, self.light.position))
        else:
            light["direction"] = list(map(float, self.light.direction))
        out = {
            "light": light,
            "wall": {"point": list(map(float, self.wall.point)), "normal": list(map(float, self.wall.normal))},
            "image": {
                "width": int(self.image.width),
                "height": int(self.image.height),
                "origin": list(map(float, self.image.origin)),
                "u": list(map(float, self.image.u)),
                "v": list(map(float, self.image.v)),
            },
        }
        if meshes is not None:
            out["meshes"] = list(meshes)
        return out

    @staticmethod
    def from_json(data: dict) -> Scene:
        """Parse and check the scene.json contract (``meshes`` is ignored here)."""
        try:
            lt = data["light"]["type"]
            if lt == "point":
                light = Light("point", position=_vec3(data["light"]["position"], "light.position"))
            elif lt == "directional":
                direction = np.asarray(_vec3(data["light"]["direction"], "light.direction"))
                if np.linalg.norm(direction) == 0:
                    raise SceneError("light.direction must not be zero")
                light = Light("directional", direction=tuple(direction / np.linalg.norm(direction)))
            else:
                raise SceneError(f"light.type must be 'point' or 'directional', got {lt!r}")
            normal = np.asarray(_vec3(data["wall"]["normal"], "wall.normal"))
            if np.linalg.norm(normal) == 0:
                raise SceneError("wall.normal must not be zero")
            wall = Wall(point=_vec3(data["wall"]["point"], "wall.point"), normal=tuple(normal / np.linalg.norm(normal)))

            im = data["image"]
            width, height = int(im["width"]), int(im["height"])
            if width < 1 or height < 1 or width > 8192 or height > 8192:
                raise SceneError(f"image size must be 1..8192 pixels, got {width} x {height}")
            image = ImageFrame(
                width, height, _vec3(im["origin"], "image.origin"), _vec3(im["u"], "image.u"), _vec3(im["v"], "image.v")
            )
        except (KeyError, TypeError) as exc:
            raise SceneError(f"scene is missing or has a malformed field: {exc}") from None
        scene = Scene(light, wall, image)
        scene._check()
        return scene

    def _check(self) -> None:
        n = np.asarray(self.wall.normal)
        u, v = np.asarray(self.image.u), np.asarray(self.image.v)
        if (
            abs(u @ v) > 1e-6 * np.linalg.norm(u) * np.linalg.norm(v)
            or abs(u @ n) > 1e-6 * np.linalg.norm(u)
            or abs(v @ n) > 1e-6 * np.linalg.norm(v)
        ):
            raise SceneError("image.u and image.v must be orthogonal and lie in the wall plane")
        if (
            abs(np.linalg.norm(u) / self.image.width - np.linalg.norm(v) / self.image.height)
            > 1e-6 * np.linalg.norm(v) / self.image.height
        ):
            raise SceneError("image pixels must be square (|u|/width == |v|/height)")
        if self.light.type == "point":
            if (np.asarray(self.light.position) - np.asarray(self.wall.point)) @ n <= 0:
                raise SceneError("the point light must be in front of the wall (on the side its normal faces)")
        elif np.asarray(self.light.direction) @ n >= 0:
            raise SceneError("the directional light must shine toward the wall (direction . normal < 0)")


def check_view_angle(angle_deg: float) -> None:
    """Raise SceneError unless VIEW_ANGLE_MIN_DEG <= |angle_deg| <= VIEW_ANGLE_MAX_DEG."""
    if not (math.isfinite(angle_deg) and VIEW_ANGLE_MIN_DEG <= abs(angle_deg) <= VIEW_ANGLE_MAX_DEG):
        raise SceneError(
            f"the view angle must be between {VIEW_ANGLE_MIN_DEG:g} and {VIEW_ANGLE_MAX_DEG:g} degrees"
            f" (or -{VIEW_ANGLE_MAX_DEG:g} and -{VIEW_ANGLE_MIN_DEG:g}), got {angle_deg:g}"
        )


def default_views(
    width: int,
    height: int,
    light: LightType = "point",
    angles_deg: tuple[float, ...] = (0.0,),
    lamp_to_wall_m: float = LAMP_TO_WALL_M,
    frame_height_m: float | None = None,
) -> list[Scene]:
    """One default scene per view: view k is :meth:`Scene.default` turned by angles_deg[k]
    (0 for view 0) about the vertical axis through VIEW_AXIS_POINT_M. Several views need the
    default lamp distance and frame (the turns are laid out for them); SceneError otherwise."""
    if len(angles_deg) > 1 and lamp_to_wall_m != LAMP_TO_WALL_M:
        raise SceneError(f"two views need the default lamp distance ({LAMP_TO_WALL_M:g} m), got {lamp_to_wall_m:g} m")
    if len(angles_deg) > 1 and frame_height_m is not None:
        raise SceneError("two views keep the default frame on the wall")
    base = Scene.default(width, height, light=light, lamp_to_wall_m=lamp_to_wall_m, frame_height_m=frame_height_m)
    return [base if a == 0 else base.turned(a) for a in angles_deg]


def frame_height_for(shapes: list[np.ndarray], light: LightType = "point") -> float | None:
    """The frame's height on the wall (metres) at which the largest of ``shapes`` (each (H, W)
    bool, True in the shape, one frame size) has its longer side WORKING_EXTENT of the default
    frame's height; None (the default frame) when it already has within FRAME_SIZE_TOLERANCE
    of that size, when a shape runs off the frame (it meets the frame's edge, so its size is
    not known: a forearm's shadow leaving the picture; a shape that only grazes both ends of
    the frame, a picture cropped to it, does not: :func:`cropped_to_shape`) or when no shape
    has a pixel. The frame's scale stays in FRAME_SCALE_RANGE."""
    longest = 0
    for shape in shapes:
        shape = np.asarray(shape, bool)
        meets_edge = shape[0].any() or shape[-1].any() or shape[:, 0].any() or shape[:, -1].any()
        if meets_edge and not cropped_to_shape(shape):
            return None
        rows, cols = np.nonzero(shape)
        if len(rows):
            longest = max(longest, int(np.ptp(rows)) + 1, int(np.ptp(cols)) + 1)
    if longest == 0:
        return None
    height = np.asarray(shapes[0]).shape[0]
    scale = WORKING_EXTENT * height / longest  # the frame's height on the wall, times the default
    if abs(scale - 1.0) <= FRAME_SIZE_TOLERANCE:
        return None
    return FRAME_HEIGHT_M[light] * float(np.clip(scale, *FRAME_SCALE_RANGE))


def cropped_to_shape(shape: np.ndarray) -> bool:
    """Whether a shape (H, W) bool that meets its frame's edge comes from a picture cropped to
    it: it meets both ends of the rows' or of the columns' span (a crop to its bounding box;
    a letterboxed picture's other axis has margins), and every run of it along the edge is
    shorter than GRAZING_SHARE of that edge, where a forearm's shadow running off crosses it
    wide. A shape in a corner of the frame runs off there (a forearm leaving through the
    corner splits its crossing between two edges), whatever its runs."""
    shape = np.asarray(shape, bool)
    top, bottom, left, right = shape[0], shape[-1], shape[:, 0], shape[:, -1]
    if not ((top.any() and bottom.any()) or (left.any() and right.any())):
        return False
    if shape[0, 0] or shape[0, -1] or shape[-1, 0] or shape[-1, -1]:
        return False
    for edge in (top, bottom, left, right):
        padded = np.concatenate([[False], edge, [False]]).astype(np.int8)
        starts, ends = np.flatnonzero(np.diff(padded) == 1), np.flatnonzero(np.diff(padded) == -1)
        if len(starts) and (ends - starts).max() >= GRAZING_SHARE * len(edge):
            return False
    return True


def check_lamp_distance(metres: float) -> None:
    """SceneError unless the lamp's distance from the wall lies in LAMP_TO_WALL_RANGE_M."""
    lo, hi = LAMP_TO_WALL_RANGE_M
    if not lo <= metres <= hi:  # also refuses NaN
        raise SceneError(f"the lamp's distance from the wall must be {lo:g} to {hi:g} m, got {metres:g}")


def views_to_json(views: list[Scene], meshes: list[str] | None = None) -> dict | list[dict]:
    """scene.json for one view (the object of the contract) or several (a list of them, view 0
    first)."""
    out = [v.to_json(meshes=meshes) for v in views]
    return out[0] if len(out) == 1 else out


def views_from_json(data) -> list[Scene]:
    """The views of a scene.json: one object (one view) or a non-empty list of them."""
    if isinstance(data, list):
        if not data:
            raise SceneError("a list of views must not be empty")
        return [Scene.from_json(v) for v in data]
    if not isinstance(data, dict):
        raise SceneError("a scene must be an object or a list of views")
    return [Scene.from_json(data)]


def _clean(values: np.ndarray) -> tuple[float, float, float]:
    """Three coordinates with the rounding noise of a turn removed (1e-12 m), no -0.0."""
    return tuple(float(x) + 0.0 for x in np.round(values, TURN_DIGITS))


def _unit(values) -> tuple[float, float, float]:
    """A unit vector that reading scene.json (which normalises) leaves as it is."""
    v = np.asarray(values, float)
    for _ in range(UNIT_ROUNDS):
        norm = float(np.linalg.norm(v))
        if norm == 1.0:
            break
        v = v / norm
    return tuple(float(x) + 0.0 for x in v)


def _vec3(value, name: str) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{name} must be three numbers") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise SceneError(f"{name} must be three finite numbers, got {value!r}")
    return tuple(float(a) for a in arr)
