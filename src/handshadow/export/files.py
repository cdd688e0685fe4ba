"""Writing a result folder completely or not at all."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from handshadow.errors import HandshadowError


class OutputError(HandshadowError):
    """The output folder cannot be used."""


# Every result folder lists the names handshadow wrote there (one a line), so that a result
# written over it with --force drops the old result's files and keeps only the person's own.
MANIFEST = ".handshadow-files"


class ResultFolder:
    """Collects a result in a hidden sibling folder and renames it into place on ``commit``.

    A non-empty target folder is refused unless ``force``, and so is a place where no folder
    can be made (checked at once, before any work). If anything fails (or the process is
    interrupted or killed) before ``commit``, the target folder is left as it was; ``commit``
    swaps whole folders by rename, so the target never holds part of a result, even when the
    process dies in the middle of it.

        with ResultFolder(out, force) as folder:
            write_png(folder / "shadow.png", image)
            folder.commit()
    """

    def __init__(self, path: str | Path, force: bool = False):
        self.path = Path(path)
        here = Path.cwd().resolve()
        whole = self.path.resolve()
        if whole == here or whole in here.parents:  # '.', '', '..', a root: swapped by rename, never
            raise OutputError(f"output folder '{path}' holds the current folder: give a folder of its own (--out NAME)")
        if self.path.exists() and not self.path.is_dir():
            raise OutputError(f"output path {self.path} exists and is not a folder")
        if self.path.is_dir() and any(self.path.iterdir()) and not force:
            raise OutputError(f"output folder {self.path} is not empty (use --force to overwrite)")
        _check_writable(self.path)
        self.staging = self.path.parent / f".{self.path.name}.partial-{os.getpid()}"

    def __enter__(self) -> ResultFolder:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging.mkdir()
        except OSError as exc:
            raise OutputError(f"cannot write to {self.path.parent}: {exc.strerror}") from None
        return self

    def __truediv__(self, name: str) -> Path:
        return self.staging / name

    def commit(self) -> Path:
        """Put the staged files in place of the target folder, with their MANIFEST; files
        already there that the result does not have are kept (same-named ones are replaced),
        except those an earlier result's MANIFEST lists: they belonged to that result.

        A missing or empty target folder is replaced by one rename. A non-empty one (``force``)
        first lends its other files to the staged folder (hard links, else copies), then is
        renamed aside, the staged folder renamed in, and the old one removed: at every instant
        the target is the old result or the new one, never a mix."""
        names = sorted(p.name for p in self.staging.iterdir())
        (self.staging / MANIFEST).write_text("".join(f"{n}\n" for n in names))
        if self.path.is_dir() and any(self.path.iterdir()):
            earlier = _listed(self.path) | {MANIFEST}
            for item in self.path.iterdir():
                if item.name not in earlier and not os.path.lexists(self.staging / item.name):
                    _link_or_copy(item, self.staging / item.name)
            old = self.path.parent / f".{self.path.name}.old-{os.getpid()}"
            shutil.rmtree(old, ignore_errors=True)
            os.replace(self.path, old)
            os.replace(self.staging, self.path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(self.staging, self.path)  # rename(2) replaces an empty folder at once
        return self.path

    def __exit__(self, *exc) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)


class StagedFiles:
    """Writes files beside their final names and moves them all into place on ``commit``;
    for outputs that join an existing folder (a result's print.stl). Until ``commit`` every
    final path is left as it was; a failure removes what was staged.

        with StagedFiles([out / "a.stl", out / "a.json"]) as files:
            write_json(files["a.json"], data)   # a hidden sibling of out / "a.json"
            ...
            files.commit()
    """

    def __init__(self, paths: list[Path]):
        self.paths = [Path(p) for p in paths]
        self.staged = {p.name: p.parent / f".{p.name}.partial-{os.getpid()}" for p in self.paths}

    def __enter__(self) -> StagedFiles:
        for path in self.paths:
            if path.is_dir():
                raise OutputError(f"output path {path} is a folder")
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise OutputError(f"cannot write to {path.parent}: {exc.strerror}") from None
        return self

    def __getitem__(self, name: str) -> Path:
        return self.staged[name]

    def commit(self) -> list[Path]:
        for path in self.paths:
            os.replace(self.staged[path.name], path)
        for path in self.paths:  # files joining a result folder join its MANIFEST too
            manifest = path.parent / MANIFEST
            if manifest.is_file() and path.name not in _listed(path.parent):
                text = manifest.read_text(errors="replace")
                with manifest.open("a") as f:
                    f.write(("\n" if text and not text.endswith("\n") else "") + f"{path.name}\n")
        return self.paths

    def __exit__(self, *exc) -> None:
        for staged in self.staged.values():
            staged.unlink(missing_ok=True)


def _listed(folder: Path) -> set[str]:
    """The names a result folder's MANIFEST lists (none without one)."""
    try:
        return {line for line in (folder / MANIFEST).read_text().splitlines() if line}
    except (OSError, UnicodeDecodeError):
        return set()


def _check_writable(path: Path) -> None:
    """OutputError unless a folder can be made at ``path``: its nearest existing ancestor
    must be a folder that takes new entries (tried with a temporary folder, removed at once)."""
    ancestor = path.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OutputError(f"cannot write to {path}: {ancestor} is not a folder")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".handshadow-check-", dir=ancestor))
    except OSError as exc:
        raise OutputError(f"cannot write to {path}: no folder can be made in {ancestor} ({exc.strerror})") from None


def _link_or_copy(src: Path, dest: Path) -> None:
    """Hard-link a file (or a folder's files) to dest, copying where links are not possible;
    symbolic links stay links."""

    def link(a, b):
        try:
            os.link(a, b)
        except OSError:
            shutil.copy2(a, b)

    if src.is_symlink():
        os.symlink(os.readlink(src), dest)
    elif src.is_dir():
        shutil.copytree(src, dest, copy_function=link, symlinks=True)
    else:
        link(src, dest)


def write_png(path: Path, image: np.ndarray) -> None:
    """Write a uint8 (H, W) or (H, W, 3|4) image."""
    iio.imwrite(path, np.ascontiguousarray(image), extension=".png")


def write_json(path: Path, data: dict) -> None:
    Path(path).write_text(json.dumps(data, indent=1) + "\n")


def write_gif(path: Path, frames: list[np.ndarray], seconds_per_frame: float = 0.12, hold_last_s: float = 1.5) -> None:
    """An animated GIF that loops; the last frame is held a little longer."""
    if not frames:
        return
    if len(frames) == 1:
        iio.imwrite(path, frames[0], extension=".gif")
        return
    durations = [seconds_per_frame * 1000] * (len(frames) - 1) + [hold_last_s * 1000]
    iio.imwrite(path, np.stack(frames), extension=".gif", duration=durations, loop=0)


def require_mp4() -> None:
    """Raise HandshadowError unless MP4s can be written (call it before long work)."""
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        raise HandshadowError("writing animation.mp4 needs imageio-ffmpeg: pip install imageio-ffmpeg") from None


def write_mp4(path: Path, frames: list[np.ndarray], fps: int = 12) -> None:
    """An H.264 MP4 through imageio's ffmpeg plugin (imageio-ffmpeg from PyPI carries ffmpeg)."""
    require_mp4()
    if not frames:
        return
    h, w = frames[0].shape[:2]
    pad = ((0, h % 2), (0, w % 2), (0, 0))  # yuv420p wants even sizes
    iio.imwrite(
        path,
        np.stack([np.pad(f, pad, mode="edge") for f in frames]),
        extension=".mp4",
        plugin="FFMPEG",
        fps=fps,
        codec="libx264",
        macro_block_size=1,
    )


def shadow_image(mask: np.ndarray) -> np.ndarray:
    """(H, W) mask in [0, 1] -> uint8 black shadow on a white wall."""
    return ((1.0 - np.clip(mask, 0, 1)) * 255 + 0.5).astype(np.uint8)
