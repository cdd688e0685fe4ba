"""`handshadow print`: one watertight volume, the same shadow from the files alone, a stand
that casts nothing in the frame, thin parts, and result folders that cannot be printed.

The fixture renders a fitted two-hand bird (data/fitted_bird_pose.json, from `handshadow fit`
with --quality fast): its skin crosses itself at bent joints (a few hundred crossing edges per
hand), which the print must not inherit.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import manifold3d as m3
import numpy as np
import pytest
import trimesh

from handshadow.cli import main
from handshadow.export import printcheck, printing, solid
from handshadow.metrics import iou

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def result_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("print") / "bird"
    assert main(["render", str(DATA / "fitted_bird_pose.json"), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def built(result_dir, tmp_path_factory):
    """The print built once (default settings) and saved: (result, model, report)."""
    result = printing.load_result(result_dir)
    settings = printing.PrintSettings()
    model = printing.build_print(result, settings)
    out = tmp_path_factory.mktemp("printed") / "bird.stl"
    report = printing.save_print(model, result, settings, printing.output_paths(result_dir, out))
    return result, model, report


def test_the_raw_skin_crosses_itself(result_dir):
    """The case the print has to handle (so the next test means something)."""
    mesh = trimesh.load(result_dir / "left.obj", process=False, force="mesh")
    assert printcheck.crossing_edges(mesh.vertices, mesh.faces, tolerance=1e-7) > 20


def test_print_is_one_watertight_volume_without_crossings(built):
    _, _, report = built
    stl = report.files[0]
    mesh = trimesh.load(stl, force="mesh")  # merges the STL's corners, as a slicer does
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    assert len(mesh.split(only_watertight=False)) == 1
    solid_ = m3.Manifold(
        m3.Mesh(vert_properties=np.asarray(mesh.vertices, np.float32), tri_verts=np.asarray(mesh.faces, np.uint32))
    )
    assert solid_.status() == m3.Error.NoError and len(solid_.decompose()) == 1
    assert printcheck.crossing_edges(mesh.vertices, mesh.faces) == 0
    assert report.volumes == 1 and report.rods >= 2
    assert mesh.bounds[1][1] - mesh.bounds[0][1] == pytest.approx(150.0, abs=0.05)  # --height-mm


def test_shadow_from_the_files_alone_matches_shadow_png(built, result_dir):
    _, _, report = built
    stl, json_path = report.files[0], [p for p in report.files if p.suffix == ".json"][0]
    vertices, faces, info = printcheck.load_print(stl, json_path)
    cast = printcheck.cast_shadow(vertices, faces, info)
    target = printing.read_shadow(result_dir / "shadow.png")
    assert cast.shape == target.shape
    assert iou(cast, target) >= 0.98
    assert (target & ~cast).sum() == 0  # uniting and printing only ever adds a hair


def test_numpy_caster_agrees_with_the_renderer(result_dir):
    """printcheck, given scene.json and the OBJs, reproduces shadow.png pixel for pixel."""
    import json

    scene = json.loads((result_dir / "scene.json").read_text())
    meshes = [trimesh.load(result_dir / name, process=False, force="mesh") for name in scene["meshes"]]
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    vertices = np.concatenate([m.vertices for m in meshes])
    faces = np.concatenate([m.faces + o for m, o in zip(meshes, offsets)])
    cast = printcheck.cast_shadow(vertices, faces, scene)
    assert (cast == printing.read_shadow(result_dir / "shadow.png")).all()


def test_stand_adds_no_shadow_pixel_in_the_frame(built):
    _, model, report = built
    info = model.scene.to_json()
    with_stand = printcheck.cast_shadow(*solid.to_arrays(model.solid), info)
    hands = printcheck.cast_shadow(*solid.to_arrays(model.hands), info)
    assert hands.any()
    assert (with_stand & ~hands).sum() == 0
    stand_alone = printcheck.cast_shadow(*solid.to_arrays(model.stand), info)
    assert stand_alone.any() and (stand_alone & ~hands).sum() == 0  # the rods are there, hidden


def test_print_json_maps_the_scene(built, result_dir):
    import json

    result, model, report = built
    data = json.loads([p for p in report.files if p.suffix == ".json"][0].read_text())
    matrix = np.asarray(data["scene_to_print"]["matrix"])
    lamp_m = np.r_[result.scene.light.position, 1.0]
    assert np.allclose(matrix @ lamp_m, np.r_[data["light"]["position"], 1.0])
    assert data["lamp"]["distance_to_wall_mm"] == pytest.approx(2000 * data["scale"], rel=1e-6)
    assert data["units"] == "mm" and data["up"] == [0.0, 1.0, 0.0]
    assert report.files[-1].suffix == ".png" and report.files[-1].stat().st_size > 10_000


def test_thin_parts_are_refused_with_the_height_that_works(result_dir):
    with pytest.raises(printing.ThinPartsError, match=r"--height-mm (\d+) or more") as info:
        printing.build_print(printing.load_result(result_dir), printing.PrintSettings(height_mm=45.0))
    assert "little" in str(info.value) or "index" in str(info.value)  # names the fingers


def test_thickening_reaches_the_minimum_wall():
    """A 0.8 mm rod on a block, min wall 1.2: balls along the rod, none on the block."""
    block = trimesh.creation.box((10, 10, 10))
    rod = trimesh.creation.cylinder(radius=0.4, height=8, sections=16).subdivide().subdivide()
    rod.apply_translation((0, 0, 8))
    hands = solid.clean_solid([(block.vertices, block.faces), (rod.vertices, rod.faces)])
    thickness = solid.local_thickness(hands, max_depth=30)
    assert thickness.part.min() == pytest.approx(0.8, abs=0.1)
    centres = solid.thickening_balls(thickness, 1.2)
    assert len(centres) > 3 and np.all(centres[:, 2] > 4.5)  # along the rod only
    thick = m3.Manifold.batch_boolean([hands, *solid.balls(centres, 0.6)], m3.OpType.Add)
    after = solid.local_thickness(solid.fill(thick), max_depth=30)
    assert after.part[after.points[:, 2] > 6].min() >= 1.2 - 0.05  # the rod, clear of where it meets the block


def test_clean_solid_unites_a_surface_that_crosses_itself():
    """Two overlapping boxes written as one mesh: one volume, the union's, no crossings."""
    a, b = trimesh.creation.box((2, 2, 2)), trimesh.creation.box((2, 2, 2))
    b.apply_translation((1, 1, 0))
    mesh = trimesh.util.concatenate([a, b])
    united = solid.clean_solid([(mesh.vertices, mesh.faces)], shell=1e-3)
    assert len(solid.parts(united)) == 1
    assert united.volume() == pytest.approx(8 + 8 - 2, rel=0.01)
    assert printcheck.crossing_edges(*solid.to_arrays(united), tolerance=1e-6) == 0


def _broken_copies(result_dir: Path, tmp_path: Path) -> dict[str, Path]:
    cases = {}
    for case in ("missing", "garbage", "open", "no_scene"):
        folder = tmp_path / case
        shutil.copytree(result_dir, folder)
        cases[case] = folder
    (cases["missing"] / "right.obj").unlink()
    (cases["garbage"] / "left.obj").write_bytes(b"\x00\x01 not an obj \xff" * 10)
    lines = (cases["open"] / "left.obj").read_text().splitlines()
    faces = [i for i, line in enumerate(lines) if line.startswith("f ")]
    for i in reversed(faces[: len(faces) // 3]):  # a third of the skin gone: no way to close it
        del lines[i]
    (cases["open"] / "left.obj").write_text("\n".join(lines) + "\n")
    (cases["no_scene"] / "scene.json").unlink()
    return cases


def test_bad_result_folders_get_one_line_and_nothing_written(result_dir, tmp_path, capsys):
    for case, folder in _broken_copies(result_dir, tmp_path).items():
        assert main(["print", str(folder)]) == 2, case
        err = capsys.readouterr().err.strip()
        assert err.startswith("handshadow: error: ") and "\n" not in err, (case, err)
        assert not list(folder.glob("print*")) and not list(folder.glob(".print*")), case


def test_a_small_hole_is_closed(result_dir, tmp_path):
    lines = (result_dir / "left.obj").read_text().splitlines()
    faces = [i for i, line in enumerate(lines) if line.startswith("f ")]
    del lines[faces[len(faces) // 2]]
    (tmp_path / "left.obj").write_text("\n".join(lines) + "\n")
    result = printing.load_result(result_dir)
    vertices, faces_ = printing.read_closed_mesh(tmp_path / "left.obj", result.scene)
    assert trimesh.Trimesh(vertices, faces_, process=False).is_watertight


def test_command_writes_every_file_by_default(result_dir, tmp_path, capsys):
    folder = tmp_path / "bird"
    shutil.copytree(result_dir, folder)
    assert main(["print", str(folder), "--no-stand", "--height-mm", "120"]) == 0
    out = capsys.readouterr().out
    assert "Torch:" in out and "IoU" in out
    names = {p.name for p in folder.glob("print*")}
    assert names == {"print.stl", "print.json", "print.png"} | ({"print.3mf"} if printing.can_write_3mf() else set())
    mesh = trimesh.load(folder / "print.stl", force="mesh")
    assert mesh.is_watertight
    assert mesh.bounds[1][1] - mesh.bounds[0][1] == pytest.approx(120.0, abs=0.05)
    assert main(["print", str(folder), "--out", str(tmp_path / "x.obj")]) == 2
