"""Built-in examples shipped with the package: poses (data/poses/*.json, and the library's
classic hand shadows, data/library/*.json) and target shadows (data/examples/*.png, our own
renders of library poses, so each has a known answer)."""

from __future__ import annotations

import json
from pathlib import Path

from handshadow.paths import PACKAGE_DATA

POSES = PACKAGE_DATA / "poses"
TARGETS = PACKAGE_DATA / "examples"
LIBRARY = PACKAGE_DATA / "library"  # the classic hand shadows (library.py), also the search's starts


def list_poses(folder: Path = POSES) -> list[tuple[str, str]]:
    """(name, one-line description) of every built-in pose in ``folder``: POSES, or LIBRARY
    for the classic hand shadows."""
    out = []
    for path in sorted(folder.glob("*.json")):
        about = json.loads(path.read_text()).get("about", "")
        out.append((path.stem, about))
    return out


def pose_path(name_or_path: str) -> Path:
    """A pose file path: an existing file, else the built-in pose of that name, else the
    classic hand shadow of that name (LIBRARY), else the given path (whose absence the
    loader reports). A folder of that name (an earlier render's --out, say) does not hide
    the built-in pose."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    for folder in (POSES, LIBRARY):
        builtin = folder / f"{name_or_path}.json"
        if builtin.is_file():
            return builtin
    return path


def list_targets() -> list[tuple[str, str]]:
    """(name, description) of every built-in target."""
    out = []
    for path in sorted(TARGETS.glob("*.png")):
        about_file = path.with_suffix(".txt")
        out.append((path.stem, about_file.read_text().strip() if about_file.exists() else ""))
    return out


def target_path(name_or_path: str) -> Path:
    """An image path: an existing file, else the built-in target of that name, else the path
    (a folder of that name, an earlier fit's --out say, does not hide the built-in target)."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    builtin = TARGETS / f"{name_or_path}.png"
    return builtin if builtin.is_file() else path
