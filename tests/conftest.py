"""Shared fixtures. Tests run on the CPU; float64 where gradients are checked."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("HANDSHADOW_CACHE_DIR", str(ROOT / ".cache"))
os.environ.setdefault("ANNY_CACHE_DIR", str(Path(os.environ["HANDSHADOW_CACHE_DIR"]) / "anny"))
torch.set_num_threads(min(2, torch.get_num_threads()))

from handshadow.hands import load_hand  # noqa: E402
from handshadow.scene import Scene  # noqa: E402


@pytest.fixture(scope="session")
def hands64():
    """Anny right and left hands with forearms, float64."""
    return {side: load_hand("anny", side, dtype=torch.float64) for side in ("right", "left")}


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture(scope="session")
def scene():
    return Scene.default(128, 128)


def random_pose(rng: np.random.Generator, batch: int = 1) -> torch.Tensor:
    """(B, 15, 3) plausible random angles, radians: bends 0..70 deg, spreads and twists small."""
    pose = np.zeros((batch, 15, 3))
    pose[..., 2] = rng.uniform(0, 70, (batch, 15))
    pose[..., 1] = rng.uniform(-12, 12, (batch, 15))
    pose[..., 0] = rng.uniform(-8, 8, (batch, 15))
    return torch.as_tensor(np.radians(pose))


def random_rotation(rng: np.random.Generator, max_deg: float = 60.0) -> torch.Tensor:
    """(1, 3, 3) a rotation by up to max_deg about a random axis."""
    import roma

    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.radians(rng.uniform(0, max_deg))
    return roma.rotvec_to_rotmat(torch.as_tensor(axis * angle)[None])


def run_cli(args: list[str]):
    """``handshadow ARGS`` in this process, its output captured: a CompletedProcess
    (returncode, stdout, stderr). For the many checks of input a command refuses before any
    work: each saves a Python start-up and torch's import (about 3 s here). Each command's
    refusals are also checked in a process of their own, as a user meets them."""
    import contextlib
    import io
    import subprocess

    from handshadow.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as exc:  # argparse's own refusals
            code = exc.code if isinstance(exc.code, int) else 1
    return subprocess.CompletedProcess(["handshadow", *args], code, out.getvalue(), err.getvalue())
