"""Built-in examples shipped with the package: poses (data/poses/*.json)."""

from __future__ import annotations

import json
from pathlib import Path

from handshadow.paths import PACKAGE_DATA

POSES = PACKAGE_DATA / "poses"


def list_poses() -> list[tuple[str, str]]:
    """(name, one-line description) of every built-in pose."""
    out = []
    for path in sorted(POSES.glob("*.json")):
        about = json.loads(path.read_text()).get("about", "")
        out.append((path.stem, about))
    return out


def pose_path(name_or_path: str) -> Path:
    """A pose file path: an existing file, else the built-in pose of that name, else the
    given path (whose absence the loader reports)."""
    path = Path(name_or_path)
    if path.exists():
        return path
    builtin = POSES / f"{name_or_path}.json"
    return builtin if builtin.is_file() else path
