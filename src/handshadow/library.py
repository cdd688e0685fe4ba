"""The library of classic hand-shadow poses (data/library/*.json, authored in
tools/make_library.py): starting points for the search and examples for people."""

from __future__ import annotations

import json

from handshadow.examples import LIBRARY
from handshadow.posefile import parse_pose
from handshadow.poses import PosedScene

__all__ = ["LIBRARY", "library_about", "library_names", "load_library_pose"]


def library_names() -> list[str]:
    return sorted(p.stem for p in LIBRARY.glob("*.json"))


def load_library_pose(name: str) -> PosedScene:
    path = LIBRARY / f"{name}.json"
    return parse_pose(json.loads(path.read_text()), str(path))


def library_about(name: str) -> str:
    return json.loads((LIBRARY / f"{name}.json").read_text()).get("about", "")
