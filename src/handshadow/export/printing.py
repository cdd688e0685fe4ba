"""Print it: a result folder -> one watertight solid of the hands (with forearms) on a stand
that casts no shadow in the picture, scaled to a height, with the lamp's place.

    report = print_result("out/bird", height_mm=150)   # print.stl, print.3mf, print.json, print.png

Steps, each in its own function:

1. :func:`load_result` reads scene.json, the hand meshes it names and shadow.png, and checks
   that each mesh is a closed surface between the lamp and the wall.
2. :func:`print_frame` picks the similarity (uniform scale, rotation, shift) from the scene's
   metres to the print's millimetres: the whole print is ``height_mm`` tall. A point light's
   shadow is unchanged when the lamp, the wall and the hands scale together, so the print's
   lamp and wall (in print.json) are the scene's, mapped the same way.
3. :func:`build_print` unites the hands (:mod:`handshadow.export.solid`: a clean manifold even
   where skinning folds the skin or hands pass through each other), measures their thickness,
   thickens parts thinner than the minimum wall (or refuses, naming them, with the smallest
   height that needs no thickening), and adds the stand (:mod:`handshadow.export.stand`),
   checking with the exact shadow renderer that no part of it casts a shadow in the frame.
4. :func:`save_print` checks the solid as an STL will store it and writes the STL (and 3MF),
   print.json and print.png (:mod:`handshadow.export.printsheet`), all or nothing.

Print coordinates (millimetres): x to the performer's right, y up with the table at y = 0, z
from the back of the board toward the lamp; the board is the wall (its front face, z =
board thickness). Without a stand y = 0 is the print's lowest point and z = 0 the wall.

print.json::

    {"format": "handshadow.print/1", "units": "mm", "height_mm": 150, "scale": 0.18,
     "scene_to_print": {"matrix": 4 x 4, "mm_per_m": 181.2, "rotation": 3 x 3,
                        "translation_mm": [...]},          # p_mm = mm_per_m * R p_m + t
     "light": ..., "wall": ..., "image": ...,               # scene.json's contract, in mm
     "lamp": {"position_mm", "height_mm", "height_above", "distance_to_wall_mm",
              "right_of_centre_mm"},                     # where the torch goes
     "up": [0, 1, 0], "stand": {"board_mm", "foot_length_mm", "rods": [...]} or null,
     "thickness": {"min_wall_mm", "thinnest_mm", "thickened_spots"}, "mesh": {...}}
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import manifold3d as m3
import numpy as np

from handshadow.errors import HandshadowError
from handshadow.export import solid as solids
from handshadow.export import stand as stands
from handshadow.metrics import iou
from handshadow.scene import ImageFrame, Light, Scene, SceneError, Wall

FORMAT = "handshadow.print/1"
SHADOW_IOU_MIN = 0.985  # a thickened print's shadow against the fit's, at the least
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


# -- 3. the solid ------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class PrintModel:
    """The print, millimetres, print frame.

    solid: the whole print, ready to write (one volume with a stand); hands: the hands alone
    as printed (thickened); stand: board, foot and rods alone (None without a stand); scene:
    lamp, wall and frame in print coordinates; frame: scene -> print; rods: the stand's rods;
    foot_length_mm: 0 without a stand; thinnest_mm: the hands' thinnest part before
    thickening; thickened: (K, 3) centres of the balls that thickened thin parts.
    """

    solid: m3.Manifold
    hands: m3.Manifold
    stand: m3.Manifold | None
    scene: Scene
    frame: PrintFrame
    rods: tuple[stands.Rod, ...]
    foot_length_mm: float
    thinnest_mm: float
    thickened: np.ndarray


class ThinPartsError(PrintError):
    """Parts thinner than the minimum wall whose thickening would change the shadow."""


def build_print(result: ResultMeshes, settings: PrintSettings) -> PrintModel:
    """Unite, measure, thicken and stand the hands of a result (see the module docstring)."""
    from handshadow.render import mesh_shadow

    frame = print_frame(result.scene, np.concatenate([v for _, v, _ in result.meshes]), settings)
    scene = frame.scene(result.scene)
    hands, thinnest, thickened = printable_hands(result, frame, scene, settings)
    rods, foot_length, stand, whole = (), 0.0, None, hands
    if settings.stand:
        rods, foot_length, stand = _stand(
            scene, hands, mesh_shadow(scene, *solids.to_arrays(hands)), settings.stand_size
        )
        whole = m3.Manifold.batch_boolean([hands, stand], m3.OpType.Add)
    return PrintModel(
        solid=solids.for_stl(whole),
        hands=hands,
        stand=stand,
        scene=scene,
        frame=frame,
        rods=tuple(rods),
        foot_length_mm=foot_length,
        thinnest_mm=thinnest,
        thickened=thickened,
    )


def printable_hands(
    result: ResultMeshes, frame: PrintFrame, scene: Scene, settings: PrintSettings
) -> tuple[m3.Manifold, float, np.ndarray]:
    """The hands as one clean solid in print millimetres, thickened where thinner than the
    minimum wall; also the thinnest part before thickening (mm) and the thickening balls'
    centres (K, 3). Raises ThinPartsError, naming the parts and the smallest height that
    works, when the thickened hands' shadow would match the fit's by less than
    SHADOW_IOU_MIN (IoU)."""
    from handshadow.render import mesh_shadow

    reference = mesh_shadow(result.scene, *solids.side_by_side([(v, f) for _, v, f in result.meshes]))
    hands = solids.clean_solid([(frame.apply(v), f) for _, v, f in result.meshes])
    thickness = solids.local_thickness(hands, max_depth=10 * settings.min_wall_mm + 20)
    cast = mesh_shadow(scene, *solids.to_arrays(hands))  # in pixels the same at any height
    thick = thickening(thickness, scene, settings.min_wall_mm, cast, reference)
    if len(thick.balls) and thick.shadow_iou < SHADOW_IOU_MIN:
        where = ", ".join(name_places(result, frame, thick.centres)) or f"{len(thick.centres)} spots"
        height = smallest_height(result, frame, thickness, cast, reference, settings)
        raise ThinPartsError(
            f"thinner than {settings.min_wall_mm:g} mm at {settings.height_mm:g} mm tall: {where}"
            f" (thinnest {thick.thinnest:.2f} mm); thickened, its shadow would drift from the fit's"
            f" (IoU {thick.shadow_iou:.3f}); print at --height-mm {height:.0f} or more"
        )
    if len(thick.balls):
        hands = m3.Manifold.batch_boolean([hands, *thick.balls], m3.OpType.Add)
    return hands, thick.thinnest, thick.centres


@dataclasses.dataclass(frozen=True)
class Thickening:
    """What thickening a solid would take. thinnest: its thinnest part (mm); centres: (K, 3)
    ball centres; balls: the balls (diameter: the minimum wall); shadow_iou: the thickened
    solid's shadow against the reference."""

    thinnest: float
    centres: np.ndarray
    balls: list[m3.Manifold]
    shadow_iou: float


def thickening(
    thickness: solids.Thickness, scene: Scene, min_wall: float, cast: np.ndarray, reference: np.ndarray
) -> Thickening:
    """The balls that bring a solid's thin parts to ``min_wall`` (mm), and how well the
    thickened solid's shadow, ``cast`` (H, W) bool (the solid's) with the balls', would match
    ``reference`` (H, W) bool (the shadow of a union is the union of the shadows)."""
    from handshadow.render import mesh_shadow

    centres = solids.thickening_balls(thickness, min_wall)
    balls = solids.balls(centres, min_wall / 2)
    if balls:
        cast = cast | mesh_shadow(scene, *solids.side_by_side([solids.to_arrays(b) for b in balls]))
    return Thickening(float(thickness.part.min()), centres, balls, iou(cast, reference))


def smallest_height(
    result: ResultMeshes,
    frame: PrintFrame,
    thickness: solids.Thickness,
    cast: np.ndarray,
    reference: np.ndarray,
    settings: PrintSettings,
) -> float:
    """About the smallest height (mm, up to the next 5) at which the thickened hands' shadow
    still matches ``reference`` by SHADOW_IOU_MIN: four bisection steps between this height
    and one at which nothing is thinner than the minimum wall. The hands' thickness (in
    ``frame``'s coordinates) and shadow ``cast`` scale with the print; the stand's
    millimetres do not."""
    vertices = np.concatenate([v for _, v, _ in result.meshes])

    def works(height: float) -> bool:
        other = print_frame(result.scene, vertices, dataclasses.replace(settings, height_mm=height))
        moved = thickness.moved(other.mm_per_m / frame.mm_per_m, frame.translation, other.translation)
        match = thickening(moved, other.scene(result.scene), settings.min_wall_mm, cast, reference).shadow_iou
        return match >= SHADOW_IOU_MIN + 0.002  # a little to spare: the measure is not smooth in the height

    below = settings.stand_size.board + settings.stand_size.margin if settings.stand else 0.0
    low = settings.height_mm
    high = max(low * 1.1, below + (low - below) * settings.min_wall_mm / thickness.part.min() * 1.05)
    for _ in range(5):
        middle = 0.5 * (low + high)
        low, high = (low, middle) if works(middle) else (middle, high)
    return float(5 * np.ceil(high / 5))


def name_places(result: ResultMeshes, frame: PrintFrame, points: np.ndarray) -> list[str]:
    """Names of the hand parts nearest to points (K, 3) in print millimetres ("left index",
    "right palm", "left forearm"), most points first; empty when the result's pose.json
    cannot be posed here (the names are a courtesy, not a requirement)."""
    from handshadow.hands.rig import FINGERS
    from handshadow.posefile import load_pose_file

    if len(points) == 0:
        return []
    try:
        pose_set = load_pose_file(result.folder / "pose.json")
        keypoints = {h.side: frame.apply(_keypoints(h, pose_set.forearm)) for h in pose_set.hands}
    except (HandshadowError, OSError, ValueError):
        return []
    labels = []
    for p in np.asarray(points, float):
        best = (np.inf, "")
        for side, k in keypoints.items():
            for f, finger in enumerate(FINGERS):
                chain = k[[0, *range(1 + 4 * f, 5 + 4 * f)]]  # wrist, the finger's joints, its tip
                d, t = _to_polyline(p, chain)
                name = f"{side} {finger}" if t >= 1 else (f"{side} palm" if t > 0 else f"{side} forearm")
                best = min(best, (d, name))
        labels.append(best[1])
    names, counts = np.unique(labels, return_counts=True)
    return [str(n) for n in names[np.argsort(-counts, kind="stable")]]


def _keypoints(hand, forearm: bool) -> np.ndarray:
    """(21, 3) keypoints of a posed hand, scene metres."""
    import torch

    from handshadow.hands import load_hand

    model = load_hand(hand.model, hand.side, hand.shape, forearm=forearm, dtype=torch.float64)
    with torch.no_grad():
        return model(*hand.tensors(dtype=torch.float64)).keypoints[0].numpy()


def _to_polyline(p: np.ndarray, chain: np.ndarray) -> tuple[float, float]:
    """Distance from p (3,) to the polyline chain (N, 3), and where its nearest point lies as
    segment index plus fraction (below 0: before the first point)."""
    best = (np.inf, 0.0)
    for i, (a, b) in enumerate(zip(chain[:-1], chain[1:])):
        t_raw = float((p - a) @ (b - a) / max((b - a) @ (b - a), 1e-12))
        t = min(max(t_raw, 0.0), 1.0)
        d = float(np.linalg.norm(a + t * (b - a) - p))
        best = min(best, (d, i + t if i or t_raw >= 0 else t_raw))
    return best


def _stand(
    scene: Scene, hands: m3.Manifold, shadow: np.ndarray, size: stands.StandSize
) -> tuple[list[stands.Rod], float, m3.Manifold]:
    """Rods, the foot's length and the stand (board, foot, rods) as one solid; raises
    PrintError when some part of it would cast a shadow in the frame (shadow: (H, W) bool,
    the hands')."""
    from handshadow.render import mesh_shadow

    parts = solids.parts(hands)
    try:
        candidates = stands.choose_rods(scene, parts, shadow, size)
    except stands.StandError as exc:
        raise PrintError(f"no hidden stand: {exc}; print with --no-stand") from None
    rods = [
        r
        for r in candidates
        if stands.hidden(mesh_shadow(scene, *solids.to_arrays(stands.rod_solid(r, size.board))), shadow)
    ]
    missing = sorted(set(range(len(parts))) - {r.part for r in rods})
    if missing:
        raise PrintError(
            f"no hidden stand: the rods for part {missing[0] + 1} of the hands would show; print with --no-stand"
        )
    board, _ = stands.board_and_foot(scene, size, 0.0)
    rods_and_board = m3.Manifold.batch_boolean([board, *(stands.rod_solid(r) for r in rods)], m3.OpType.Add)
    foot_length = max(size.foot_min, 1.5 * (_centre_of_mass([hands, rods_and_board])[2] - size.board))
    _, foot = stands.board_and_foot(scene, size, foot_length)
    foot_front = foot.trim_by_plane((0.0, 0.0, 1.0), size.board)  # the part in front of the wall
    if mesh_shadow(scene, *solids.to_arrays(foot_front)).any():
        raise PrintError("the foot would cast a shadow in the frame; print with --no-stand")
    return rods, float(foot_length), m3.Manifold.batch_boolean([rods_and_board, foot], m3.OpType.Add)


def _centre_of_mass(pieces: list[m3.Manifold]) -> np.ndarray:
    """(3,) centre of mass of solids of one density (overlaps counted twice: a rough guide)."""
    import trimesh

    meshes = [trimesh.Trimesh(*solids.to_arrays(p), process=False) for p in pieces]
    return np.average([m.center_mass for m in meshes], axis=0, weights=[m.volume for m in meshes])


# -- 4. writing --------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class PrintReport:
    """What ``print_result`` wrote and measured. files: the paths written; size_mm: (3,)
    width, height, depth; life_scale: print length per real length; volumes: disjoint solids
    in the file (1 with a stand); shadow_iou: the print's shadow (exact renderer) against
    shadow.png, None without one; lamp_mm: (3,) the torch in print coordinates;
    lamp_to_wall_mm; seconds: wall time."""

    files: tuple[Path, ...]
    height_mm: float
    size_mm: tuple[float, float, float]
    life_scale: float
    triangles: int
    volumes: int
    thinnest_mm: float
    min_wall_mm: float
    thickened_spots: int
    rods: int
    lamp_mm: tuple[float, float, float]
    lamp_to_wall_mm: float
    shadow_iou: float | None
    instructions: tuple[str, ...]
    seconds: float

    def lines(self) -> list[str]:
        """A summary for people, one fact a line."""
        out = [
            f"wrote {', '.join(str(p) for p in self.files)}",
            f"{self.triangles} triangles, watertight, {self.volumes} {'volume' if self.volumes == 1 else 'volumes'}"
            + (f", {self.rods} rods hidden in the shadow" if self.rods else ""),
        ]
        if self.shadow_iou is not None:
            out.append(f"its shadow against shadow.png: IoU {self.shadow_iou:.3f}")
        return out + list(self.instructions)


def print_result(
    result_dir: str | Path,
    out: str | Path | None = None,
    height_mm: float = 150.0,
    stand: bool = True,
    min_wall_mm: float = 1.2,
) -> PrintReport:
    """Turn a result folder into a printable solid and its sheet (see the module docstring).

    out: the mesh file, ending in .stl or .3mf; print.json and print.png go beside it with
    the same stem. Default: RESULT_DIR/print.stl, plus print.3mf when lxml is installed.
    Raises PrintError (one line) and writes nothing when the result cannot be printed.
    """
    started = time.perf_counter()
    if min_wall_mm <= 0:
        raise PrintError(f"--min-wall-mm must be positive, got {min_wall_mm:g}")
    settings = PrintSettings(height_mm=float(height_mm), stand=stand, min_wall_mm=float(min_wall_mm))
    paths = output_paths(Path(result_dir), out)
    result = load_result(result_dir)
    model = build_print(result, settings)
    return save_print(model, result, settings, paths, started)


def save_print(
    model: PrintModel,
    result: ResultMeshes,
    settings: PrintSettings,
    paths: tuple[list[Path], tuple[Path, Path]],
    started: float | None = None,
) -> PrintReport:
    """Check the print, write its files (paths: from :func:`output_paths`) and report."""
    from handshadow.export.printsheet import instructions
    from handshadow.render import mesh_shadow

    meshes, sidecar = paths
    vertices, faces = check_printable(model, settings)
    wall_z = float(model.scene.wall.point[2])
    cast = mesh_shadow(model.scene, *solids.to_arrays(model.solid.trim_by_plane((0.0, 0.0, 1.0), wall_z + 1e-6)))
    facts = sheet_facts(model, settings, vertices, name_places(result, model.frame, model.thickened))
    data = print_json(model, settings, result, meshes[0].name, len(faces))
    files = write_print(vertices, faces, data, _picture(model, cast, facts), meshes, sidecar)
    return PrintReport(
        files=tuple(files),
        height_mm=settings.height_mm,
        size_mm=tuple(float(a) for a in np.ptp(vertices, axis=0)),
        life_scale=model.frame.mm_per_m / 1000.0,
        triangles=len(faces),
        volumes=len(solids.parts(model.solid)),
        thinnest_mm=model.thinnest_mm,
        min_wall_mm=settings.min_wall_mm,
        thickened_spots=len(model.thickened),
        rods=len(model.rods),
        lamp_mm=tuple(float(a) for a in model.scene.light.position),
        lamp_to_wall_mm=float(model.scene.light.position[2]) - wall_z,
        shadow_iou=None if result.shadow is None else iou(cast, result.shadow),
        instructions=tuple(instructions(facts)),
        seconds=time.perf_counter() - (started if started is not None else time.perf_counter()),
    )


def output_paths(folder: Path, out: str | Path | None) -> tuple[list[Path], tuple[Path, Path]]:
    """The mesh files and (print.json, print.png) to write."""
    if out is None:
        meshes = [folder / "print.stl"] + ([folder / "print.3mf"] if can_write_3mf() else [])
        return meshes, (folder / "print.json", folder / "print.png")
    out = Path(out)
    if out.suffix.lower() not in (".stl", ".3mf"):
        raise PrintError(f"--out must end in .stl or .3mf, got {out.name}")
    if out.suffix.lower() == ".3mf" and not can_write_3mf():
        raise PrintError("writing 3MF needs lxml: pip install lxml (or use --out FILE.stl)")
    return [out], (out.with_suffix(".json"), out.with_suffix(".png"))


def can_write_3mf() -> bool:
    """Whether trimesh can write 3MF here (its writer needs lxml)."""
    try:
        import lxml  # noqa: F401
    except ImportError:
        return False
    return True


def check_printable(model: PrintModel, settings: PrintSettings) -> tuple[np.ndarray, np.ndarray]:
    """The print's vertices (V, 3) and faces (F, 3) after checking that, read back from an
    STL (32-bit positions, corners at one position fused), it is a watertight, consistently
    wound solid of positive volume with no flat triangle, and in one piece with a stand."""
    import trimesh

    vertices, faces = solids.to_arrays(model.solid)
    stored, index = np.unique(vertices.astype(np.float32), axis=0, return_inverse=True)
    mesh = trimesh.Trimesh(stored.astype(np.float64), index.reshape(-1)[faces], process=False)
    closed = mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0 and (mesh.area_faces > 0).all()
    if model.solid.status() != m3.Error.NoError or not closed:
        raise PrintError("the united solid is not watertight (a bug: please report it with the result folder)")
    pieces = len(solids.parts(model.solid))
    if settings.stand and pieces != 1:
        raise PrintError(f"the print fell into {pieces} pieces (a bug: please report it with the result folder)")
    return vertices, faces


def sheet_facts(model: PrintModel, settings: PrintSettings, vertices: np.ndarray, thickened_parts: list[str]):
    """What print.png and the command state (vertices: (V, 3) the print's, mm)."""
    from handshadow.export.printsheet import SheetFacts

    lo, hi = stands.frame_box(model.scene)
    return SheetFacts(
        lamp=np.asarray(model.scene.light.position, float),
        wall_z=float(model.scene.wall.point[2]),
        frame=(float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])),
        height_mm=settings.height_mm,
        life_scale=model.frame.mm_per_m / 1000.0,
        min_wall_mm=settings.min_wall_mm,
        thinnest_mm=model.thinnest_mm,
        thickened=len(model.thickened),
        stand=settings.stand,
        foot_mm=(model.foot_length_mm, settings.stand_size.board if settings.stand else 0.0),
        bounds_mm=np.stack([vertices.min(0), vertices.max(0)]),
        thickened_parts=tuple(thickened_parts),
    )


def _picture(model: PrintModel, shadow: np.ndarray, facts) -> np.ndarray:
    from handshadow.export.printsheet import print_picture

    stand = None if model.stand is None else solids.to_arrays(model.stand)
    return print_picture(solids.to_arrays(model.hands), stand, shadow, facts)


def print_json(
    model: PrintModel, settings: PrintSettings, result: ResultMeshes, mesh_name: str, triangles: int
) -> dict:
    """print.json's content (see the module docstring)."""
    frame, scene = model.frame, model.scene
    lamp = np.asarray(scene.light.position, float)
    wall_z = float(scene.wall.point[2])
    return {
        "format": FORMAT,
        "units": "mm",
        "mesh": {"file": mesh_name, "triangles": int(triangles)},
        "height_mm": settings.height_mm,
        "scale": frame.mm_per_m / 1000.0,
        "scene_to_print": {
            "matrix": frame.matrix().tolist(),
            "mm_per_m": frame.mm_per_m,
            "rotation": frame.rotation.tolist(),
            "translation_mm": frame.translation.tolist(),
        },
        **scene.to_json(),
        "up": [0.0, 1.0, 0.0],
        "lamp": {
            "position_mm": lamp.tolist(),
            "height_mm": float(lamp[1]),
            "height_above": "table" if settings.stand else "the print's lowest point",
            "distance_to_wall_mm": float(lamp[2] - wall_z),
            "right_of_centre_mm": float(lamp[0]),
        },
        "stand": None
        if not settings.stand
        else {
            "board_mm": settings.stand_size.board,
            "board_front_z_mm": wall_z,
            "foot_length_mm": model.foot_length_mm,
            "rods": [
                {
                    "start": r.start.tolist(),
                    "end": r.end.tolist(),
                    "start_radius": r.start_radius,
                    "end_radius": r.end_radius,
                }
                for r in model.rods
            ],
        },
        "thickness": {
            "min_wall_mm": settings.min_wall_mm,
            "thinnest_mm": model.thinnest_mm,
            "thickened_spots": len(model.thickened),
        },
        "result": {"scene": "scene.json", "meshes": [name for name, _, _ in result.meshes]},
    }


def write_print(
    vertices: np.ndarray,
    faces: np.ndarray,
    data: dict,
    picture: np.ndarray,
    meshes: list[Path],
    sidecar: tuple[Path, Path],
) -> list[Path]:
    """Write the mesh files, print.json and print.png together (all or none)."""
    import trimesh

    from handshadow.export.files import StagedFiles, write_json, write_png

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    json_path, png_path = sidecar
    with StagedFiles([*meshes, json_path, png_path]) as files:
        for path in meshes:
            files[path.name].write_bytes(mesh.export(file_type=path.suffix.lower().lstrip(".")))
        write_json(files[json_path.name], data)
        write_png(files[png_path.name], picture)
        return files.commit()
