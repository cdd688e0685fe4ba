"""`handshadow render`: outputs, the scene.json contract, and bad input."""

import json
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest
import trimesh

from handshadow.cli import main
from handshadow.examples import pose_path
from tests.conftest import run_cli

PY = [sys.executable, "-m", "handshadow.cli"]


def recompute_shadow(folder, scene: dict | None = None) -> np.ndarray:
    """The shadow from scene.json and the OBJ files alone, in numpy, following the contract:
    pixel (i, j) is in shadow when the segment from its centre on the wall to the light (or
    the ray against a directional light) meets a triangle. ``scene``: one view of a
    scene.json that lists several (default: the folder's scene.json, one view)."""
    scene = scene if scene is not None else json.loads((folder / "scene.json").read_text())
    im = scene["image"]

    w, h = im["width"], im["height"]
    o, u, v = (np.asarray(im[k], float) for k in ("origin", "u", "v"))
    n = np.asarray(scene["wall"]["normal"], float)
    w0 = np.asarray(scene["wall"]["point"], float)
    shadow = np.zeros((h, w), bool)
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    for name in scene["meshes"]:
        verts, faces = read_obj(folder / name)
        # Project every vertex from the light onto the wall, then into (column, row) pixels.
        if scene["light"]["type"] == "point":
            lamp = np.asarray(scene["light"]["position"], float)
            s = ((w0 - lamp) @ n) / ((verts - lamp) @ n)
            on_wall = lamp + (verts - lamp) * s[:, None]
        else:
            d = np.asarray(scene["light"]["direction"], float)
            on_wall = verts + d * (((w0 - verts) @ n) / (d @ n))[:, None]
        px = np.stack([(on_wall - o) @ u / (u @ u) * w, (on_wall - o) @ v / (v @ v) * h], 1)
        for tri in px[faces]:
            x0, y0 = np.floor(tri.min(0)).astype(int)
            x1, y1 = np.ceil(tri.max(0)).astype(int)
            x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
            if x0 >= x1 or y0 >= y1:
                continue
            p = np.stack([jj[y0:y1, x0:x1], ii[y0:y1, x0:x1]], -1)
            e = [(tri[(k + 1) % 3] - tri[k]) for k in range(3)]
            sides = [e[k][0] * (p[..., 1] - tri[k][1]) - e[k][1] * (p[..., 0] - tri[k][0]) for k in range(3)]
            inside = (np.min(sides, 0) >= 0) | (np.max(sides, 0) <= 0)
            shadow[y0:y1, x0:x1] |= inside
    return shadow


def read_obj(path):
    verts, faces = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts and parts[0] == "f":
            faces.append([int(x.split("/")[0]) - 1 for x in parts[1:4]])
    return np.asarray(verts), np.asarray(faces)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("render") / "two"
    assert main(["render", "two-hands", "--out", str(out)]) == 0
    return out


def test_render_writes_every_output(rendered):
    names = {p.name for p in rendered.iterdir()}
    assert {"shadow.png", "scene.json", "left.obj", "right.obj", "hands.glb", "scene.png", "pose.json"} <= names
    shadow = iio.imread(rendered / "shadow.png")
    assert shadow.shape == (256, 256) and set(np.unique(shadow)) == {0, 255}
    picture = iio.imread(rendered / "scene.png")
    assert picture.shape[2] == 3 and picture.std() > 10  # a real picture, not a blank
    glb = trimesh.load(rendered / "hands.glb")
    assert {"right_hand", "left_hand", "wall", "light"} <= set(glb.geometry)
    for side in ("left", "right"):
        mesh = trimesh.load(rendered / f"{side}.obj", process=False)
        assert mesh.is_watertight  # hand and forearm, one closed surface


def test_scene_json_and_meshes_reproduce_the_shadow(rendered):
    shadow = iio.imread(rendered / "shadow.png") < 128
    again = recompute_shadow(rendered)
    assert shadow.sum() > 1000
    assert (shadow != again).sum() <= 2  # identical up to pixel centres lying on an edge


def test_directional_light_scene_reproduces_too(tmp_path):
    pose = json.loads(pose_path("open-hand").read_text())
    from handshadow.scene import Scene

    pose["scene"] = Scene.default(160, 120, light="directional").to_json()
    pose["hands"][0]["translation"] = [0.0, -0.1, 0.5]
    (tmp_path / "p.json").write_text(json.dumps(pose))
    assert main(["render", str(tmp_path / "p.json"), "--out", str(tmp_path / "out")]) == 0
    shadow = iio.imread(tmp_path / "out" / "shadow.png") < 128
    assert shadow.shape == (120, 160) and shadow.sum() > 500
    assert (shadow != recompute_shadow(tmp_path / "out")).sum() <= 2


def test_a_classic_hand_shadow_renders_by_name_with_how_to_hold_it(tmp_path, capsys):
    # The library's classic poses (handshadow examples lists them) render by name; the folder
    # has a guide (the hands as the performer sees them, the shadow, the instructions) and the
    # command says how to hold the hands.
    out = tmp_path / "bird"
    assert main(["render", "bird", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "Can be held: yes." in said
    assert "Left hand: fingers point" in said and "Right hand: fingers point" in said
    guide = iio.imread(out / "guide.png")
    assert guide.shape[0] > 560 and guide.std() > 10
    shadow = iio.imread(out / "shadow.png") < 128
    assert (shadow != recompute_shadow(out)).sum() <= 2


def test_pose_file_round_trips(rendered, tmp_path):
    assert main(["render", str(rendered / "pose.json"), "--out", str(tmp_path / "again")]) == 0
    assert np.array_equal(iio.imread(rendered / "shadow.png"), iio.imread(tmp_path / "again" / "shadow.png"))


BAD_POSES = {
    "not-json": "{this is not json",
    "no-hands": json.dumps({"hands": []}),
    "bad-side": json.dumps({"hands": [{"side": "middle", "translation": [0, 0, 1]}]}),
    "bad-shape": json.dumps({"hands": [{"side": "right", "pose_deg": [[0, 0]], "translation": [0, 0, 1]}]}),
    "not-rotation": json.dumps(
        {"hands": [{"side": "right", "rotation": [[2, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 1]}]}
    ),
    "behind-wall": json.dumps({"hands": [{"side": "right", "translation": [0, 0, -0.5]}]}),
    "at-the-lamp": json.dumps({"hands": [{"side": "right", "translation": [0, 0, 1.95]}]}),
    "bad-scene": json.dumps(
        {"scene": {"light": {"type": "laser"}}, "hands": [{"side": "right", "translation": [0, 0, 1]}]}
    ),
    "two-rights": json.dumps(
        {"hands": [{"side": "right", "translation": [0, 0, 1]}, {"side": "right", "translation": [0.1, 0, 1]}]}
    ),
    "mano-without-dir": json.dumps({"hands": [{"side": "right", "model": "mano", "translation": [0, 0, 1]}]}),
}


@pytest.mark.parametrize("name", sorted(BAD_POSES))
def test_bad_pose_files_fail_cleanly(tmp_path, name):
    path = tmp_path / f"{name}.json"
    path.write_text(BAD_POSES[name])
    out = tmp_path / "out"
    res = run_cli(["render", str(path), "--out", str(out)])
    assert res.returncode == 2
    assert res.stderr.startswith("handshadow: error: ") and res.stderr.count("\n") == 1, res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists()  # nothing half-written
    assert not any(p.name.startswith(".out.partial") for p in tmp_path.iterdir())


def test_missing_pose_file_and_missing_mano_files(tmp_path):
    res = subprocess.run(
        PY + ["render", str(tmp_path / "nope.json"), "--out", str(tmp_path / "o")], capture_output=True, text=True
    )
    assert res.returncode == 2 and "not found" in res.stderr
    pose = {"hands": [{"side": "left", "model": "mano", "translation": [0, 0, 1]}]}
    (tmp_path / "m.json").write_text(json.dumps(pose))
    res = subprocess.run(
        PY + ["render", str(tmp_path / "m.json"), "--out", str(tmp_path / "o"), "--mano-dir", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 2 and "MANO_LEFT.pkl" in res.stderr and res.stderr.count("\n") == 1


def test_non_empty_output_needs_force(rendered):
    res = subprocess.run(PY + ["render", "two-hands", "--out", str(rendered)], capture_output=True, text=True)
    assert res.returncode == 2 and "--force" in res.stderr


def test_render_holds_a_pose_with_hands_of_another_build_as_the_guide_says(tmp_path):
    from handshadow.hands import load_rig
    from tests.hands.fake_mano import write_synthetic_mano

    for side in ("right", "left"):
        write_synthetic_mano(tmp_path / f"MANO_{side.upper()}.pkl", side)
    pose = {"hands": [{"side": "right", "model": "mano", "translation": [0.0, 0.0, 1.0]}]}
    (tmp_path / "m.json").write_text(json.dumps(pose))
    out = tmp_path / "o"
    args = ["render", str(tmp_path / "m.json"), "--mano-dir", str(tmp_path), "--hand-shape", "1.5,-0.5"]
    assert main([*args, "--out", str(out)]) == 0
    written = json.loads((out / "pose.json").read_text())
    hand = written["hands"][0]
    lamp = np.asarray(written["scene"]["light"]["position"])
    k = load_rig("mano", "right", {"betas": [1.5, -0.5]}, str(tmp_path)).size
    assert hand["shape"] == {"betas": [1.5, -0.5]} and k != pytest.approx(1.0, abs=1e-3)
    np.testing.assert_allclose(hand["translation"], lamp + k * (np.array([0.0, 0.0, 1.0]) - lamp), atol=1e-8)
    # A distant light (or an Anny build for MANO hands) allows no such move: one line, nothing written.
    directional = {**pose, "scene": {**written["scene"], "light": {"type": "directional", "direction": [0, 0, -1]}}}
    (tmp_path / "d.json").write_text(json.dumps(directional))
    for source, shape, words in (("d.json", "1.5", "one point lamp"), ("m.json", "weight=0.8", "MANO betas")):
        res = subprocess.run(
            PY
            + ["render", str(tmp_path / source), "--mano-dir", str(tmp_path), "--hand-shape", shape]
            + ["--out", str(tmp_path / "bad")],
            capture_output=True,
            text=True,
        )
        assert res.returncode == 2 and words in res.stderr and res.stderr.count("\n") == 1, res.stderr
        assert not (tmp_path / "bad").exists()


def test_render_says_whether_a_person_can_hold_the_pose(tmp_path, capsys):
    # The built-in two-hand pose can be held. Moved into each other, the hands pass through
    # each other; a hand turned about its wrist leads its forearm toward the wall. Each is
    # said, with how deep or which forearm, and the files are still written.
    pose = json.loads(pose_path("two-hands").read_text())
    assert main(["render", str(pose_path("two-hands")), "--out", str(tmp_path / "ok")]) == 0
    assert "Can be held: yes." in capsys.readouterr().out
    right, left = (next(h for h in pose["hands"] if h["side"] == s) for s in ("right", "left"))
    left["translation"] = list(np.asarray(right["translation"]) + [0.02, 0.0, 0.0])
    turn = np.diag([-1.0, 1.0, -1.0])  # half a turn about the vertical: the left forearm now leads to the wall
    left["rotation"] = (turn @ np.asarray(left["rotation"])).tolist()
    (tmp_path / "bad.json").write_text(json.dumps(pose))
    assert main(["render", str(tmp_path / "bad.json"), "--out", str(tmp_path / "no")]) == 0
    said = capsys.readouterr().out.splitlines()[-1]
    assert said.startswith("Can be held: no, the hands pass ") and "mm into each other" in said, said
    assert "the left forearm leads toward the wall" in said and "right forearm" not in said, said
    assert (tmp_path / "no" / "shadow.png").exists()


def test_render_says_when_a_hand_passes_into_itself_or_past_its_limits(tmp_path, capsys):
    # The right hand of the built-in pose made a full fist, every finger bent as far as its
    # joints allow: the fingertips sink into the palm (the model's flesh does not give), and
    # the index finger spread 40 degrees, past every preset's limit (20), is named.
    pose = json.loads(pose_path("two-hands").read_text())
    right = next(h for h in pose["hands"] if h["side"] == "right")
    for finger in range(1, 5):
        for joint, bend in enumerate((90, 105, 80)):
            right["pose_deg"][3 * finger + joint][2] = bend
    (tmp_path / "fist.json").write_text(json.dumps(pose))
    assert main(["render", str(tmp_path / "fist.json"), "--out", str(tmp_path / "fist")]) == 0
    said = capsys.readouterr().out.splitlines()[-1]
    assert said.startswith("Can be held: no, the right hand's fingers pass ") and "mm into its palm" in said, said
    assert "left hand" not in said and "limits" not in said, said
    right["pose_deg"] = [[0.0, 0.0, 0.0]] * 15
    right["pose_deg"][3] = [0.0, 40.0, 0.0]
    (tmp_path / "spread.json").write_text(json.dumps(pose))
    assert main(["render", str(tmp_path / "spread.json"), "--out", str(tmp_path / "spread")]) == 0
    said = capsys.readouterr().out.splitlines()[-1]
    assert said == (
        "Can be held: no, the right hand goes past its joints' limits: index knuckle spread 40 deg (-20 to 20)."
    ), said
    # Without forearms a wrist angle moves nothing, so a leftover one is not a reason.
    pose["forearm"] = False
    right["pose_deg"][3] = [0.0, 0.0, 0.0]
    right["wrist_deg"] = [120.0, 0.0]
    (tmp_path / "wrist.json").write_text(json.dumps(pose))
    assert main(["render", str(tmp_path / "wrist.json"), "--out", str(tmp_path / "wrist")]) == 0
    assert "limits" not in capsys.readouterr().out.splitlines()[-1]
    pose["forearm"] = True
    (tmp_path / "wrist.json").write_text(json.dumps(pose))
    assert main(["render", str(tmp_path / "wrist.json"), "--out", str(tmp_path / "wrist_arm"), "--force"]) == 0
    assert "wrist flexion 120 deg" in capsys.readouterr().out.splitlines()[-1]


def test_an_angle_past_a_full_turn_is_read_as_the_joint_holds_it():
    # A rotation turns alike every 360 degrees: a pose file's 370-degree spread is the joint at
    # 10 (within its limits, not named), and -400 is -40 (named as such).
    from handshadow.hands.limits import beyond_limits

    pose = np.zeros((15, 3))
    pose[3, 1] = 370.0
    assert beyond_limits(pose, np.array([0.0, 365.0]), "right") == []
    pose[3, 1] = -400.0
    assert beyond_limits(pose, None, "right") == ["index knuckle spread -40 deg (-20 to 20)"]
    # A pose file is read so: the guide's words and the limits see the joint as it is held.
    from handshadow.posefile import parse_pose

    data = json.loads(pose_path("two-hands").read_text())
    data["hands"][0]["pose_deg"][4][2] = 370.0
    data["hands"][0]["wrist_deg"] = [-350.0, 5.0]
    read = parse_pose(data).hands[0]
    assert read.pose_deg[4, 2] == pytest.approx(10.0) and read.wrist_deg.tolist() == pytest.approx([10.0, 5.0])


def test_the_holding_line_names_what_stops_a_pose():
    from handshadow.guide import holding_line
    from handshadow.hands.arms import ArmCheck

    fine = ArmCheck((True, True), (True, True), 0.4, 1)
    assert holding_line(["right", "left"], 2.9, fine) == "Can be held: yes."
    wide = ArmCheck((True, True), (True, True), 1.3, 2)
    assert holding_line(["right", "left"], 0.0, wide).startswith("Can be held: by two people (the elbows are 1.30 m")
    both = holding_line(["right", "left"], 3.5, ArmCheck((True, False), (True, True), 1.3, 2))
    assert both.startswith("Can be held: no, the hands pass 3.5 mm into each other")
    assert "the left forearm leads toward the wall" in both and "1.30 m apart" in both
    angles = [f"index knuckle bend 12{k} deg (0 to 105)" for k in range(5)]
    many = holding_line(["right", "left"], 3.5, fine, (0.0, 4.2), ([], angles))
    assert many == (
        "Can be held: no, the hands pass 3.5 mm into each other; the left hand's fingers pass 4.2 mm into its"
        " palm or each other (skin gives about 3 mm); the left hand goes past its joints' limits:"
        f" {', '.join(angles[:3])} and 2 more."
    ), many


def test_the_fit_command_says_which_flesh_a_pose_passes_into():
    # The fit's own line on penetration names the hands passing into each other only when that
    # is the deepest; a fingertip in its own palm is said as such.
    from types import SimpleNamespace

    from handshadow.cli import performance_lines
    from handshadow.hands.arms import ArmCheck
    from handshadow.hands.penetration import Penetration

    arms = ArmCheck((True, True), (True, True), 0.4, 1)

    def said(between_mm, within_mm):
        pen = Penetration(between_mm, within_mm, None)
        return performance_lines(SimpleNamespace(penetration=pen, arms=arms))[0]

    assert said(1.0, (2.0, 0.5)) == "deepest penetration 2.0 mm (within what skin gives)"
    assert said(5.0, (2.0, 0.5)).endswith("(the hands pass through each other: not performable)")
    assert said(1.0, (0.0, 6.5)) == (
        "deepest penetration 6.5 mm (fingers pass into their own palm or each other: not performable)"
    )
