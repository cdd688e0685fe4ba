"""Where handshadow keeps its caches and finds its packaged data."""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DATA = Path(__file__).resolve().parent / "data"


def cache_dir() -> Path:
    """The one cache folder: $HANDSHADOW_CACHE_DIR, else ~/.cache/handshadow.

    Anny's own model cache (built once, about 90 s) lives in its ``anny`` subfolder unless
    $ANNY_CACHE_DIR names another place.
    """
    root = os.environ.get("HANDSHADOW_CACHE_DIR")
    return Path(root) if root else Path.home() / ".cache" / "handshadow"


def anny_cache_dir() -> Path:
    env = os.environ.get("ANNY_CACHE_DIR")
    return Path(env) if env else cache_dir() / "anny"
