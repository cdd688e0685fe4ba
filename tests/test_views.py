"""Several views of one pose: the turned scene, scene.json as a list of views, rendering every
view, single-view files from before, and bad view options."""

import contextlib
import io
import json
import math
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import torch
import trimesh

from handshadow.cli import main
from handshadow.examples import pose_path
from handshadow.scene import (
    VIEW_AXIS_POINT_M,
    Scene,
    SceneError,
    check_view_angle,
    default_views,
    views_from_json,
    views_to_json,
)
from tests.conftest import run_cli
from tests.test_render_command import recompute_shadow

PY = [sys.executable, "-m", "handshadow.cli"]
BEFORE = Path(__file__).parent / "data" / "single_view"


def test_a_turned_view_keeps_the_hands_between_its_lamp_and_its_wall():
    front, side = default_views(64, 48, "point", (0.0, 90.0))
    assert front == Scene.default(64, 48)
    assert side.light.position == pytest.approx((1.0, 0.0, 1.0))  # 1 m to the performer's right
    assert side.wall.normal == pytest.approx((1.0, 0.0, 0.0))  # the wall 1 m to the left, facing it
    axis = torch.tensor([VIEW_AXIS_POINT_M], dtype=torch.float64)
    for scene in (front, side):  # the working point casts onto each frame's centre, 1 m from each wall
        xy, height = scene.project(axis)
        assert xy[0].tolist() == pytest.approx([32.0, 24.0]) and float(height[0]) == pytest.approx(1.0)
        assert scene.placement_range()[0] < 1.0 < scene.placement_range()[1]
    # A point 10 cm nearer view 0's lamp shifts view 1's shadow to the left (its u runs toward view 0's wall).
    xy, _ = side.project(axis + torch.tensor([[0.0, 0.0, 0.1]], dtype=torch.float64))
    assert float(xy[0, 0]) < 32.0
    left = Scene.default(64, 48).turned(-90.0)
    assert left.light.position == pytest.approx((-1.0, 0.0, 1.0))


@pytest.mark.parametrize("angle", [45.0, 90.0, 135.0, -60.0])
def test_view_angles_in_range_are_accepted(angle):
    check_view_angle(angle)
    front, side = default_views(32, 32, "point", (0.0, angle))
    # The frame of each view lies in front of the other view's wall.
    for a, b in ((front, side), (side, front)):
        corners = [np.asarray(a.image.origin) + s * np.asarray(a.image.u) for s in (0.0, 1.0)]
        assert all((c - np.asarray(b.wall.point)) @ np.asarray(b.wall.normal) >= -1e-9 for c in corners)


@pytest.mark.parametrize("angle", [0.0, 30.0, 140.0, 180.0, -20.0, math.nan])
def test_view_angles_out_of_range_are_refused(angle):
    with pytest.raises(SceneError, match="between 45 and 135"):
        check_view_angle(angle)


def test_scene_json_holds_one_view_as_before_and_several_as_a_list():
    views = default_views(40, 30, "point", (0.0, 70.0))
    one = views_to_json(views[:1], meshes=["right.obj"])
    assert isinstance(one, dict) and one == views[0].to_json(meshes=["right.obj"])
    both = views_to_json(views, meshes=["right.obj"])
    assert isinstance(both, list) and [v["meshes"] for v in both] == [["right.obj"]] * 2
    assert views_from_json(json.loads(json.dumps(both))) == views
    assert views_from_json(one) == views[:1]
    for bad in ([], "scene", [{"light": {"type": "laser"}}]):
        with pytest.raises(SceneError):
            views_from_json(bad)


@pytest.mark.parametrize("name, source", [("two-hands", None), ("directional", str(BEFORE / "directional_pose.json"))])
def test_single_view_files_from_before_render_identically(tmp_path, name, source):
    """Files written before views existed (the built-in two-hand pose of that day, and a pose
    file with a directional light): rendering the source and re-rendering the pose.json
    written then give the same scene.json, pose.json and shadow.png, byte for byte. (The
    built-in two-hand pose has since moved its hands 15 mm apart, out of each other, so its
    old files are rendered from their pose.json alone.)"""
    before = BEFORE / name
    assert isinstance(json.loads((before / "scene.json").read_text()), dict)
    for k, pose in enumerate(p for p in (source, str(before / "pose.json")) if p is not None):
        out = tmp_path / f"again{k}"
        assert main(["render", pose, "--out", str(out)]) == 0
        for file in ("scene.json", "pose.json", "shadow.png"):
            assert (out / file).read_bytes() == (before / file).read_bytes(), file
        assert not list(out.glob("shadow_*.png"))


@pytest.fixture(scope="module")
def two_view_render(tmp_path_factory):
    """The built-in two-hand pose in a pose file with two views (view 1 turned 90 degrees),
    rendered."""
    folder = tmp_path_factory.mktemp("views")
    pose = json.loads(pose_path("two-hands").read_text())
    pose["scene"] = views_to_json(default_views(96, 80, "point", (0.0, 90.0)))
    (folder / "pose.json").write_text(json.dumps(pose))
    assert main(["render", str(folder / "pose.json"), "--out", str(folder / "out")]) == 0
    return folder / "out"


def test_render_reproduces_every_view_from_the_pose_file(two_view_render):
    out = two_view_render
    names = {p.name for p in out.iterdir()}
    assert {"shadow_0.png", "shadow_1.png", "scene.json", "pose.json", "scene.png", "hands.glb"} <= names
    assert "shadow.png" not in names
    views = json.loads((out / "scene.json").read_text())
    assert isinstance(views, list) and len(views) == 2
    shadows = [iio.imread(out / f"shadow_{k}.png") < 128 for k in range(2)]
    assert all(s.shape == (80, 96) and s.sum() > 200 for s in shadows)
    assert (shadows[0] != shadows[1]).sum() > 200  # two different shadows of one pose
    glb = trimesh.load(out / "hands.glb")
    assert {"wall", "wall_1", "light", "light_1", "right_hand", "left_hand"} <= set(glb.geometry)


def test_every_view_recomputed_from_scene_json_and_the_meshes_equals_its_shadow(two_view_render):
    views = json.loads((two_view_render / "scene.json").read_text())
    for k, view in enumerate(views):
        shadow = iio.imread(two_view_render / f"shadow_{k}.png") < 128
        assert (recompute_shadow(two_view_render, view) != shadow).sum() <= 2, k


def test_a_two_view_pose_file_renders_back_the_same(two_view_render, tmp_path):
    assert main(["render", str(two_view_render / "pose.json"), "--out", str(tmp_path / "again")]) == 0
    for k in range(2):
        assert (tmp_path / "again" / f"shadow_{k}.png").read_bytes() == (
            two_view_render / f"shadow_{k}.png"
        ).read_bytes()


def _run(args):
    return subprocess.run(PY + args, capture_output=True, text=True)


@pytest.mark.parametrize(
    "args, message",
    [
        (["dog", "MISSING.png"], "not found"),
        (["dog", "--view-angle", "90"], "needs a second target"),
        (["dog", "--view-weights", "1,1"], "needs a second target"),
        (["dog", "rabbit", "--view-angle", "30"], "between 45 and 135"),
        (["dog", "rabbit", "--view-angle", "160"], "between 45 and 135"),
        (["dog", "rabbit", "bird"], "two targets"),
        (["dog", "rabbit", "--view-weights", "1"], "one per target"),
        (["dog", "rabbit", "--view-weights", "1,-2"], "positive"),
    ],
)
def test_bad_view_input_fails_cleanly_and_writes_nothing(tmp_path, args, message):
    out = tmp_path / "o"
    res = run_cli(["fit", *[str(tmp_path / a) if a == "MISSING.png" else a for a in args], "--out", str(out)])
    assert res.returncode == 2, res.stderr
    assert res.stderr.startswith("handshadow: error: ") and res.stderr.count("\n") == 1, res.stderr
    assert message in res.stderr and "Traceback" not in res.stderr
    assert not out.exists()
    assert not any(p.name.startswith(".o.partial") for p in tmp_path.iterdir())


def test_a_missing_second_target_is_refused_by_the_python_api_too(tmp_path):
    from handshadow.errors import HandshadowError
    from handshadow.fit import FitConfig
    from handshadow.pipeline import fit_to_folder

    with pytest.raises(HandshadowError, match="not found"):
        fit_to_folder(["dog", str(tmp_path / "nope.png")], tmp_path / "o", FitConfig(size=32))
    with pytest.raises(HandshadowError, match="between 45 and 135"):
        fit_to_folder(["dog", "rabbit"], tmp_path / "o", FitConfig(size=32, view_angle_deg=10.0))
    assert not (tmp_path / "o").exists()


SIZE = 128


@pytest.fixture(scope="module")
def two_view_fit(tmp_path_factory):
    """The library's rabbit, opened so that no finger passes into the palm, rendered in two
    views at 90 degrees (a pose known to be findable: the library's own rabbit is among the
    starts, and its forearm leads back from both walls), fitted from the two images."""
    from handshadow.fit import FitConfig, make_problem
    from handshadow.library import load_library_pose
    from handshadow.poses import HandPoseBatch, PoseBatch
    from handshadow.search import ViewTarget, separate

    folder = tmp_path_factory.mktemp("fit_views")
    truth = load_library_pose("rabbit")
    front, side = default_views(SIZE, SIZE, "point", (0.0, 90.0))
    blank = np.zeros((SIZE, SIZE), bool)
    problem = make_problem(
        blank, front, ["right"], FitConfig(hands="1", size=SIZE, device="cpu"), None, [ViewTarget(side, blank)]
    )
    pose = separate(problem, PoseBatch([HandPoseBatch.from_hand_poses([h]) for h in truth.hands]))
    targets = [m[0] for m in problem.view_masks(pose)]
    for k, t in enumerate(targets):
        iio.imwrite(folder / f"view{k}.png", np.where(t, 0, 255).astype(np.uint8))
    out, printed = folder / "out", io.StringIO()
    args = ["fit", str(folder / "view0.png"), str(folder / "view1.png"), "--view-angle", "90", "--hands", "1"]
    with contextlib.redirect_stdout(printed):
        assert main([*args, "--size", str(SIZE), "--quality", "fast", "--device", "cpu", "--out", str(out)]) == 0
    return out, json.loads((out / "pose.json").read_text()), targets, printed.getvalue().splitlines()


def test_a_pose_rendered_in_two_views_comes_back_in_both(two_view_fit):
    out, pose, targets, printed = two_view_fit
    for k, target in enumerate(targets):
        shadow = iio.imread(out / f"shadow_{k}.png") < 128
        inter, union = (shadow & target).sum(), (shadow | target).sum()
        # Thin fingers make the IoU move by pixels: the outline is what comes back, within a
        # pixel and a half of the truth's in each view (fast at b135c10: IoU 0.968 and 0.937,
        # HD95 0.008 in both; the shorter fast before it: 0.982 and 0.964; since the library's
        # rabbit start has its fingers out of its palm, 2026-12-07: IoU 0.942 and 0.924, view
        # 0's HD95 0.011, 1.4 px).
        assert inter / union >= 0.92, (k, inter / union)
        assert pose["fit"]["views"][k]["hd95"] <= 1.5 / SIZE, (k, pose["fit"]["views"][k])
        assert pose["fit"]["views"][k]["iou"] == pytest.approx(inter / union, abs=1e-4)
        assert np.array_equal(iio.imread(out / f"target_{k}.png") < 128, target)
    assert pose["fit"]["success"] and pose["fit"]["performable"] and all(pose["fit"]["forearms_lead_back"])
    assert printed[0].startswith("success")


def test_a_two_view_fit_folder_has_every_view(two_view_fit, tmp_path):
    out, _, _, lines = two_view_fit

    names = {p.name for p in out.iterdir()}
    per_view = {f"{stem}_{k}.png" for stem in ("target", "shadow", "overlay") for k in range(2)}
    assert per_view | {"scene.json", "pose.json", "right.obj", "hands.glb", "scene.png", "guide.png"} <= names
    assert not {"target.png", "shadow.png", "overlay.png"} & names
    fit = json.loads((out / "pose.json").read_text())["fit"]
    assert len(fit["views"]) == 2 and fit["view_angle_deg"] == 90.0
    assert {"iou", "hd95", "thin_recall", "shadow_success", "weight", "missing", "extra"} <= set(fit["views"][1])
    assert any(line.startswith("View 1: the lamp") for line in lines)  # where the second lamp goes
    assert any(line.startswith("View 1: IoU") for line in lines)  # how its shadow came out
    glb = trimesh.load(out / "hands.glb")
    assert {"wall", "wall_1", "light", "light_1"} <= set(glb.geometry)
    # The fit's every shadow from scene.json and the written meshes alone, and from the pose file.
    views = json.loads((out / "scene.json").read_text())
    assert main(["render", str(out / "pose.json"), "--out", str(tmp_path / "again")]) == 0
    for k, view in enumerate(views):
        shadow = iio.imread(out / f"shadow_{k}.png") < 128
        assert (recompute_shadow(out, view) != shadow).sum() <= 2, k
        assert (tmp_path / "again" / f"shadow_{k}.png").read_bytes() == (out / f"shadow_{k}.png").read_bytes()


def test_printing_a_two_view_result_is_refused_in_one_line(two_view_render, capsys):
    assert main(["print", str(two_view_render)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("handshadow: error: ") and "\n" not in err and "several views" in err
    assert not list(two_view_render.glob("print*"))
