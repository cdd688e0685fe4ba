"""What a print starts from: a result folder (scene, closed hand meshes, shadow) and the
similarity from the scene's metres to the print's millimetres.

Print coordinates (millimetres): x to the performer's right, y up with the table at y = 0, z
from the back of the board toward the lamp; the board is the wall (its front face, z = board
thickness). Without a stand y = 0 is the print's lowest point and z = 0 the wall.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from handshadow.errors import HandshadowError
from handshadow.export import stand as stands
from handshadow.scene import ImageFrame, Light, Scene, SceneError, Wall

MIN_HEIGHT_MM = 20.0


class PrintError(HandshadowError):
    """A result folder that cannot be printed, or settings that cannot work."""


@dataclasses.dataclass(frozen=True)
class PrintSettings:
    """height_mm: the whole print's height (stand included); stand: add the board, foot and
    rods; min_wall_mm: the thinnest part the printer makes."""

    height_mm: float = 150.0
    stand: bool = True
    min_wall_mm: float = 1.2

    @property
    def stand_size(self) -> stands.StandSize:
        """The stand's sizes for this height."""
        return stands.StandSize.for_height(self.height_mm)


@dataclasses.dataclass(frozen=True)
class ResultMeshes:
    """A result folder's contents: the scene (metres), the hand meshes (name, vertices (V, 3)
    metres, faces (F, 3)), its shadow.png as (H, W) bool (None when absent), its folder."""

    folder: Path
    scene: Scene
    meshes: tuple[tuple[str, np.ndarray, np.ndarray], ...]
    shadow: np.ndarray | None


# -- 1. reading --------------------------------------------------------------------------


def load_result(result_dir: str | Path) -> ResultMeshes:
    """Read a result folder written by ``fit`` or ``render``; raises PrintError with one line."""
    folder = Path(result_dir)
    if not folder.is_dir():
        raise PrintError(f"no result folder at {folder}")
    scene_path = folder / "scene.json"
    if not scene_path.is_file():
        raise PrintError(f"{folder} has no scene.json (print a folder written by 'handshadow fit' or 'render')")
    try:
        data = json.loads(scene_path.read_text())
        if isinstance(data, list):
            raise PrintError(
                f"{scene_path} holds {len(data)} views: printing a result fitted to several views is not"
                " supported (its stand is kept out of one lamp's picture only)"
            )
        scene = Scene.from_json(data)

    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PrintError(f"{scene_path} is not valid JSON ({exc})") from None
    except SceneError as exc:
        raise PrintError(f"{scene_path}: {exc}") from None
    if scene.light.type != "point":
        raise PrintError("only results lit by a point light can be printed (a torch is a point light)")
    names = data.get("meshes") or sorted(p.name for p in folder.glob("*.obj"))
    if not isinstance(names, list) or not names:
        raise PrintError(f"{folder} holds no hand meshes (left.obj, right.obj)")
    meshes = tuple((str(name), *read_closed_mesh(folder / str(name), scene)) for name in names)
    return ResultMeshes(folder=folder, scene=scene, meshes=meshes, shadow=read_shadow(folder / "shadow.png"))


def read_closed_mesh(path: Path, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 and outward faces (F, 3) of an OBJ that must be a closed
    surface strictly between the lamp and the wall."""
    import trimesh

    if not path.is_file():
        raise PrintError(f"{path} is missing")
    try:
        mesh = trimesh.load(path, file_type=path.suffix.lstrip(".") or "obj", process=False, force="mesh")
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except Exception as exc:  # trimesh raises many kinds on a corrupt file
        raise PrintError(f"{path} is not a readable mesh ({exc.__class__.__name__})") from None
    if len(faces) == 0 or not np.isfinite(vertices).all():
        raise PrintError(f"{path} has no triangles or non-finite vertices")
    mesh = trimesh.Trimesh(vertices, faces, process=True)  # merges duplicate corners, drops degenerates
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
    if not (mesh.is_watertight and mesh.is_winding_consistent):
        raise PrintError(f"{path} is not a closed surface; re-create it with 'handshadow render' on pose.json")
    if mesh.volume < 0:
        mesh.invert()
    height = (mesh.vertices - np.asarray(scene.wall.point)) @ np.asarray(scene.wall.normal)
    lamp = scene.light_depth_range()[1]
    if height.min() <= 0 or height.max() >= lamp:
        raise PrintError(f"{path} does not lie between the lamp and the wall")
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def shadow_of(scene: Scene, meshes: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """(H, W) bool exact shadow of closed meshes, each vertices (V, 3) and faces (F, 3) in the
    scene's units (the project's renderer, float64)."""
    from handshadow.render import exact_shadow

    return exact_shadow(scene, [v for v, _ in meshes], [f for _, f in meshes]) > 0.5


def read_shadow(path: Path) -> np.ndarray | None:
    """shadow.png as (H, W) bool (dark = shadow), or None when there is none."""
    if not path.is_file():
        return None
    import imageio.v3 as iio

    try:
        image = np.asarray(iio.imread(path))
    except Exception as exc:
        raise PrintError(f"{path} is not a readable image ({exc.__class__.__name__})") from None
    if image.ndim == 3:
        image = image[..., :3].mean(-1)
    return image < 128


# -- 2. the print's frame ------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class PrintFrame:
    """Scene metres -> print millimetres: p_mm = mm_per_m * rotation @ p_m + translation.

    Print axes: x to the performer's right (the image's u), y up (against the image's v),
    z toward the lamp (the wall's normal); the table is y = 0.
    """

    mm_per_m: float
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,) mm

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) metres, scene frame -> (..., 3) millimetres, print frame."""
        return self.mm_per_m * np.asarray(points, float) @ self.rotation.T + self.translation

    def direction(self, vectors: np.ndarray) -> np.ndarray:
        """(..., 3) scene vectors (metres) -> print vectors (millimetres)."""
        return self.mm_per_m * np.asarray(vectors, float) @ self.rotation.T

    def matrix(self) -> np.ndarray:
        """(4, 4) homogeneous form of :meth:`apply`."""
        m = np.eye(4)
        m[:3, :3] = self.mm_per_m * self.rotation
        m[:3, 3] = self.translation
        return m

    def scene(self, scene: Scene) -> Scene:
        """The scene mapped into print millimetres (same contract as scene.json)."""
        im = scene.image
        return Scene(
            light=Light("point", position=tuple(self.apply(scene.light.position))),
            wall=Wall(point=tuple(self.apply(scene.wall.point)), normal=tuple(self.rotation @ scene.wall.normal)),
            image=ImageFrame(
                im.width,
                im.height,
                tuple(self.apply(im.origin)),
                tuple(self.direction(im.u)),
                tuple(self.direction(im.v)),
            ),
        )


def print_rotation(scene: Scene) -> np.ndarray:
    """(3, 3) rows: the print's x, y, z axes in scene coordinates (image right, image up,
    wall normal). Raises PrintError for a mirrored frame or a wall that is not upright."""
    u = np.asarray(scene.image.u, float)
    v = np.asarray(scene.image.v, float)
    n = np.asarray(scene.wall.normal, float)
    rotation = np.stack([u / np.linalg.norm(u), -v / np.linalg.norm(v), n / np.linalg.norm(n)])
    if np.linalg.det(rotation) < 0.5:
        raise PrintError("the image frame in scene.json is mirrored; a print needs a right-handed frame")
    return rotation


def print_frame(scene: Scene, vertices: np.ndarray, settings: PrintSettings) -> PrintFrame:
    """The frame that makes the print ``settings.height_mm`` tall.

    vertices: (V, 3) metres, all hands. With the stand the print reaches from the table (the
    foot's underside) to the top of the image frame or of the hands, whichever is higher; the
    foot's top stays ``margin`` below the frame's bottom edge and below the hands. Without the
    stand it is the hands' height. x is centred on the frame; z = 0 is the board's back (or
    the wall without a stand).
    """
    rotation = print_rotation(scene)
    q = np.asarray(vertices, float) @ rotation.T
    corners = stands.frame_corners(scene) @ rotation.T
    wall_z = float(rotation[2] @ np.asarray(scene.wall.point, float))
    centre_x = float(corners[:, 0].mean())
    size = settings.stand_size
    if settings.stand:
        top = max(corners[:, 1].max(), q[:, 1].max())
        bottom = min(corners[:, 1].min(), q[:, 1].min())
        below = size.board + size.margin  # foot and gap under the frame, mm
    else:
        top, bottom, below = q[:, 1].max(), q[:, 1].min(), 0.0
    if settings.height_mm < max(MIN_HEIGHT_MM, 2 * below):
        raise PrintError(f"--height-mm must be at least {max(MIN_HEIGHT_MM, 2 * below):.0f}")
    mm_per_m = (settings.height_mm - below) / (top - bottom)
    back = size.board if settings.stand else 0.0
    translation = np.array([-mm_per_m * centre_x, below - mm_per_m * bottom, back - mm_per_m * wall_z])
    return PrintFrame(mm_per_m=float(mm_per_m), rotation=rotation, translation=translation)
