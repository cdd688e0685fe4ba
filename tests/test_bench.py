"""The fit bench's own options: a bad count is refused in one line before any fit starts."""

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
