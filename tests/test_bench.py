"""The benches' own rules: a bad count is refused in one line before any fit starts, the
recovery bench draws only poses a fit may return, and the reading bench frames pictures of
another aspect."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

BENCH = Path(__file__).resolve().parents[1] / "bench" / "fit.py"


@pytest.mark.parametrize(
    "option, message",
    [("--attempts=0", "at least one attempt"), ("--hops=-1", "negative"), ("--skip-attempts=5", "skip_attempts")],
)
def test_the_fit_bench_refuses_a_bad_count_in_one_line(tmp_path, option, message):
    frame = np.zeros((32, 32), np.uint8)
    frame[8:24, 8:24] = 255
    Image.fromarray(frame).save(tmp_path / "square.png")
    run = subprocess.run(
        [sys.executable, str(BENCH), str(tmp_path), "--fits-only", option], capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 2
    assert message in run.stderr and "Traceback" not in run.stderr


def test_the_recovery_bench_draws_only_poses_a_fit_may_return():
    # Every recovery target is a pose a fit may return: no hand into the other or into itself
    # (a fingertip in its own palm) past 3 mm, arms one person can hold. Its generator once
    # tested the hands against each other only, and 27 of its 40 targets sank fingers 3 to
    # 15 mm into their own palm.
    import runpy

    from handshadow.hands.posed import arm_check, cast_shadows, pose_penetration

    recover = runpy.run_path(str(BENCH.parent / "recover.py"), run_name="recover")
    rng = np.random.default_rng(2026)
    for _ in range(3):
        posed, shadow = recover["random_target"](rng, forearm=True)
        meshes, masks = cast_shadows(posed)
        assert np.array_equal(masks[0] > 0.5, shadow)
        pen = pose_penetration(posed, meshes)
        assert pen.between_mm <= 3.0 and max(pen.within_mm) <= 3.0, pen
        assert arm_check(posed).holdable()


def test_the_reading_bench_frames_a_photo_of_another_aspect_as_its_square_picture(tmp_path):
    """bench/targets.py --aspects: an arm running off the bottom of a square mask, framed from
    16:9 and 3:4 pictures, as the square picture frames it; a shape clear of its sides is left
    out (letterboxed as always)."""
    with_arm, clear = np.full((96, 96), 255, np.uint8), np.full((96, 96), 255, np.uint8)
    with_arm[20:50, 30:70] = 0
    with_arm[50:, 45:60] = 0
    clear[20:70, 30:70] = 0
    Image.fromarray(with_arm).save(tmp_path / "arm.png")
    Image.fromarray(clear).save(tmp_path / "clear.png")
    bench = BENCH.with_name("targets.py")
    run = subprocess.run(
        [sys.executable, str(bench), str(tmp_path), "--aspects", "--size", "64"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    summaries = [
        dict(kv.split("=") for kv in line.split()[1:]) for line in run.stdout.splitlines() if line.startswith("SUMMARY")
    ]
    assert [r["aspect"] for r in summaries] == ["16:9", "3:4"]
    for r in summaries:  # the arm's mask alone, its arm still leaving the frame, the same shape moved
        assert r["n"] == "1" and r["same_edges"] == "1" and float(r["min_iou"]) >= 0.95
