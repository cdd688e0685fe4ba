"""`handshadow interpolate` between two shadows rendered from known poses."""

import json
import re

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from handshadow.cli import main
from handshadow.fit import FitConfig
from handshadow.hands.kinematics import rotation_angle_deg, rotvec_to_rotmat, slerp_rotations
from handshadow.interpolate import morph_targets, straight_path
from handshadow.pipeline import interpolate_to_folder
from handshadow.poses import HandPoseBatch, PoseBatch
from tests.test_fit import known_target


def test_slerp_follows_the_geodesic():
    r0 = rotvec_to_rotmat(torch.tensor([0.3, -0.2, 0.1], dtype=torch.float64))
    r1 = rotvec_to_rotmat(torch.tensor([-1.0, 2.0, 0.5], dtype=torch.float64))
    path = slerp_rotations(r0, r1, torch.linspace(0, 1, 11, dtype=torch.float64))
    steps = rotation_angle_deg(path[:-1], path[1:])
    total = rotation_angle_deg(r0, r1)
    assert torch.allclose(path[0], r0) and torch.allclose(path[-1], r1, atol=1e-9)
    assert torch.allclose(steps, total / 10, atol=1e-6)  # equal steps along the shortest arc
    assert torch.allclose(path @ path.transpose(-1, -2), torch.eye(3, dtype=torch.float64).expand(11, 3, 3), atol=1e-12)


def test_straight_path_blends_angles_and_keeps_the_ends():
    def one(angle, x):
        return HandPoseBatch(
            torch.full((1, 15, 3), angle),
            rotvec_to_rotmat(torch.tensor([[0.0, 0.0, angle]])),
            torch.tensor([[x, 0.0, 1.0]]),
            torch.zeros(1, 2),
        )

    path = straight_path(PoseBatch([one(0.0, 0.0)]), PoseBatch([one(1.0, 0.2)]), 5).hands[0]
    assert torch.allclose(path.pose_rad[:, 0, 0], torch.linspace(0, 1, 5))
    assert torch.allclose(path.translation[:, 0], torch.linspace(0, 0.2, 5))


def test_morph_targets_go_from_a_to_b():
    a = np.zeros((40, 40), bool)
    a[5:15, 5:15] = True
    b = np.zeros((40, 40), bool)
    b[22:38, 20:36] = True
    m = morph_targets(a, b, 5)
    assert np.array_equal(m[0], a) and np.array_equal(m[-1], b)


@pytest.fixture(scope="module")
def morph(tmp_path_factory):
    d = tmp_path_factory.mktemp("interp")
    for name in ("dog", "duck"):
        mask, _ = known_target(name, 96)
        iio.imwrite(d / f"{name}.png", np.where(mask, 0, 255).astype(np.uint8))
    out = d / "out"
    # The ends' own library poses are left out of the starts: the fits have to find them.
    config = FitConfig(hands="1", size=96, quality="fast", exclude_library=("dog", "duck"))
    interpolate_to_folder(str(d / "dog.png"), str(d / "duck.png"), out, config, frames=16, show_progress=False)
    return out


def test_interpolation_meets_the_bounds(morph, capsys):
    poses = json.loads((morph / "poses.json").read_text())
    summary = dict(re.findall(r"(\w+)=([\d.]+)", poses["summary"]))
    assert float(summary["iou_start"]) >= 0.9 and float(summary["iou_end"]) >= 0.9
    # Both ends pass the success test of the metrics note (thin parts, HD95) as well.
    assert float(summary["thin_start"]) >= 0.6 and float(summary["thin_end"]) >= 0.6
    assert float(summary["hd95_start"]) <= 0.03 and float(summary["hd95_end"]) <= 0.03
    assert float(summary["max_step_deg"]) <= 10.0
    assert int(summary["penetrating_frames"]) == 0
    assert "time_limited" not in poses["summary"]  # no limit given, none ended a part


def test_interpolation_outputs(morph, tmp_path):
    names = {p.name for p in morph.iterdir()}
    assert {"animation.gif", "animation.mp4", "poses.json", "path.png", "frames"} <= names
    assert len(list((morph / "frames").glob("frame_*_shadow.png"))) == 16
    assert len(list((morph / "frames").glob("frame_*_hands.png"))) == 16
    assert (morph / "animation.mp4").stat().st_size > 1000
    gif = iio.imread(morph / "animation.gif", index=None)
    assert gif.shape[0] == 16
    # poses.json is readable by render, frame by frame, and gives the frames' shadows.
    for k in (0, 7, 15):
        out = tmp_path / f"f{k}"
        assert main(["render", str(morph / "poses.json"), "--frame", str(k), "--out", str(out)]) == 0
        assert np.array_equal(
            iio.imread(out / "shadow.png"), iio.imread(morph / "frames" / f"frame_{k:03d}_shadow.png")
        )


def test_missing_mp4_writer_is_refused_before_the_work(tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # as if imageio-ffmpeg were not installed
    monkeypatch.setattr("handshadow.pipeline.fit_frame", lambda *a, **k: pytest.fail("fitted before refusing"))
    out = tmp_path / "out"
    code = main(["interpolate", "dog", "duck", "--quality", "fast", "--quiet", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code != 0 and "imageio-ffmpeg" in err and "Traceback" not in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_ctrl_c_while_fitting_an_end_writes_nothing(morph, tmp_path, monkeypatch, capsys):
    import handshadow.pipeline

    real, fits = handshadow.pipeline.fit_frame, []

    def first_fit_interrupted(*args, **kwargs):
        # Ctrl-C during the first search only: that fit hands back its best so far, marked interrupted.
        fits.append(1)
        return real(*args, **kwargs, stop=(lambda: True) if len(fits) == 1 else None)

    monkeypatch.setattr("handshadow.pipeline.fit_frame", first_fit_interrupted)
    out = tmp_path / "out"
    options = "--frames 6 --hands 1 --size 64 --quality fast --quiet --device cpu --out".split()
    code = main(["interpolate", str(morph.parent / "dog.png"), str(morph.parent / "duck.png")] + options + [str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 130 and err == "handshadow: interrupted"
    assert not out.exists()  # a morph needs both ends: nothing half-done is left
    assert len(fits) == 1  # and B is not fitted after A was interrupted


def test_ctrl_c_while_refining_keeps_the_path_so_far(morph, tmp_path, monkeypatch, capsys):
    import handshadow.interpolate

    real, calls = handshadow.interpolate.rotmat_to_rotvec, []

    def ctrl_c_on_the_third_step(*args):  # called once per hand and step of the refinement only
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr("handshadow.interpolate.rotmat_to_rotvec", ctrl_c_on_the_third_step)
    out = tmp_path / "out"
    options = "--frames 6 --hands 1 --size 64 --quality fast --device cpu --out".split()
    code = main(["interpolate", str(morph.parent / "dog.png"), str(morph.parent / "duck.png")] + options + [str(out)])
    printed = capsys.readouterr().out
    assert code == 130 and "interrupted: the path as refined so far" in printed
    assert printed.strip().splitlines()[-1].startswith("SUMMARY ")
    poses = json.loads((out / "poses.json").read_text())
    assert poses["interrupted"] is True and len(poses["frames"]) == 6
    assert len(list((out / "frames").glob("frame_*_shadow.png"))) == 6 and (out / "animation.mp4").exists()


def test_a_time_limit_bounds_each_end_and_the_path_and_the_summary_says_so(morph, tmp_path, monkeypatch, capsys):
    import handshadow.interpolate

    real, taken = handshadow.interpolate.optimise, []
    monkeypatch.setattr(
        "handshadow.interpolate.optimise", lambda *args, **kwargs: taken.append(real(*args, **kwargs)) or taken[-1]
    )
    out = tmp_path / "out"
    options = "--frames 4 --hands 1 --size 64 --quality fast --device cpu --time-limit 1e-6 --out".split()
    code = main(["interpolate", str(morph.parent / "dog.png"), str(morph.parent / "duck.png")] + options + [str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert captured.out.strip().splitlines()[-1].endswith(" time_limited=start,end,path")
    assert captured.err.count("; the time limit ended it)") == 2  # each end's fit, as it is said
    assert json.loads((out / "poses.json").read_text())["summary"].endswith("time_limited=start,end,path")
    assert taken[0] == 1  # the path's refinement: one step of its 200, then the limit
