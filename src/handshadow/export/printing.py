"""Print it: a result folder -> one watertight solid of the hands (with forearms) on a stand
that casts no shadow in the picture, scaled to a height, with the lamp's place.

    report = print_result("out/bird", height_mm=150)   # print.stl, print.3mf, print.json, print.png

Steps:

1. :func:`load_result` (:mod:`~handshadow.export.printframe`) reads scene.json, the hand
   meshes it names and shadow.png, and checks that each mesh is a closed surface between the
   lamp and the wall.
2. :func:`print_frame` (same module) picks the similarity (uniform scale, rotation, shift) from
   the scene's metres to the print's millimetres (x right, y up from the table, z toward the
   lamp): the whole print is ``height_mm`` tall. A point light's shadow is unchanged when the
   lamp, the wall and the hands scale together, so the print's lamp and wall (in print.json)
   are the scene's, mapped the same way.
3. :func:`build_print` unites the hands (:mod:`~handshadow.export.solid`: a clean manifold even
   where skinning folds the skin or hands pass through each other), thickens parts thinner
   than the minimum wall or refuses with the height that works
   (:mod:`~handshadow.export.thinparts`), and adds the stand (:mod:`~handshadow.export.stand`),
   checking with the exact shadow renderer that no part of it casts a shadow in the frame.
4. :func:`save_print` checks the solid as an STL will store it and writes the STL (and 3MF),
   print.json and print.png (:mod:`~handshadow.export.printsheet`), all or nothing.

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
import time
from pathlib import Path

import manifold3d as m3
import numpy as np

from handshadow.export import solid as solids
from handshadow.export import stand as stands
from handshadow.export.printframe import (
    PrintError,
    PrintFrame,
    PrintSettings,
    ResultMeshes,
    load_result,
    print_frame,
    read_closed_mesh,
    read_shadow,
    shadow_of,
)
from handshadow.export.thinparts import ThinPartsError, name_places, printable_hands
from handshadow.metrics import iou
from handshadow.scene import Scene

__all__ = [
    "PrintError",
    "PrintFrame",
    "PrintReport",
    "PrintSettings",
    "ResultMeshes",
    "ThinPartsError",
    "build_print",
    "load_result",
    "print_result",
    "read_closed_mesh",
    "read_shadow",
    "save_print",
]

FORMAT = "handshadow.print/1"


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


def build_print(result: ResultMeshes, settings: PrintSettings) -> PrintModel:
    """Unite, measure, thicken and stand the hands of a result (see the module docstring)."""
    frame = print_frame(result.scene, np.concatenate([v for _, v, _ in result.meshes]), settings)
    scene = frame.scene(result.scene)
    hands, thinnest, thickened = printable_hands(result, frame, scene, settings)
    rods, foot_length, stand, whole = (), 0.0, None, hands
    if settings.stand:
        rods, foot_length, stand = _stand(
            scene, hands, shadow_of(scene, [solids.to_arrays(hands)]), settings.stand_size
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


def _stand(
    scene: Scene, hands: m3.Manifold, shadow: np.ndarray, size: stands.StandSize
) -> tuple[list[stands.Rod], float, m3.Manifold]:
    """Rods, the foot's length and the stand (board, foot, rods) as one solid; raises
    PrintError when some part of it would cast a shadow in the frame (shadow: (H, W) bool,
    the hands')."""
    parts = solids.parts(hands)
    try:
        candidates = stands.choose_rods(scene, parts, shadow, size)
    except stands.StandError as exc:
        raise PrintError(f"no hidden stand: {exc}; print with --no-stand") from None
    rods = [
        r
        for r in candidates
        if stands.hidden(shadow_of(scene, [solids.to_arrays(stands.rod_solid(r, size.board))]), shadow)
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
    if shadow_of(scene, [solids.to_arrays(foot_front)]).any():
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

    meshes, sidecar = paths
    vertices, faces = check_printable(model, settings)
    wall_z = float(model.scene.wall.point[2])
    cast = shadow_of(model.scene, [solids.to_arrays(model.solid.trim_by_plane((0.0, 0.0, 1.0), wall_z + 1e-6))])
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
