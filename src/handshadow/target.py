"""Target images -> the binary target frame.

Any image that imageio reads (PNG, JPEG, GIF, BMP, ...), with or without alpha, any size and
aspect, binary or anti-aliased. The shape is told from the ground by the border: the colour
that covers most of the image's outer ring is the ground (a dark shadow on a light wall, or a
light shape on a dark ground); ``invert`` overrides. With alpha, transparent pixels are ground.
The shape is letterboxed (aspect kept, centred) into the W x H frame and thresholded at half
coverage, so anti-aliased edges land where they should.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handshadow.errors import HandshadowError

MIN_SIDE_PX = 8
MAX_PIXELS = 64_000_000


class TargetError(HandshadowError):
    """A target image that cannot be used."""


def read_image(path: str | Path) -> np.ndarray:
    """(h, w, 4) float RGBA in [0, 1] (alpha 1 where the file has none)."""
    import imageio.v3 as iio

    path = Path(path)
    if not path.is_file():
        raise TargetError(f"target not found: {path} (give an image file or a built-in example name)")
    try:
        props = iio.improps(path)
        if int(np.prod(props.shape[:2])) > MAX_PIXELS:
            raise TargetError(f"{path} is too large ({props.shape[1]} x {props.shape[0]} pixels)")
        image = np.asarray(iio.imread(path, index=0))
    except TargetError:
        raise
    except Exception as exc:  # imageio raises many kinds for unreadable files
        raise TargetError(f"{path} is not a readable image ({exc.__class__.__name__})") from None
    if image.dtype == bool:
        image = image.astype(np.uint8) * 255
    scale = 65535.0 if image.dtype == np.uint16 else 255.0 if image.dtype.kind in "ui" else 1.0
    image = image.astype(np.float64) / scale
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    if image.ndim != 3 or image.shape[2] not in (1, 2, 3, 4):
        raise TargetError(f"{path} has an unsupported pixel layout {image.shape}")
    if image.shape[2] == 1:
        image = np.repeat(image, 3, axis=2)
    if image.shape[2] == 2:  # grey + alpha
        image = np.concatenate([np.repeat(image[..., :1], 3, axis=2), image[..., 1:]], axis=2)
    if image.shape[2] == 3:
        image = np.concatenate([image, np.ones_like(image[..., :1])], axis=2)
    if min(image.shape[:2]) < MIN_SIDE_PX:
        raise TargetError(
            f"{path} is too small ({image.shape[1]} x {image.shape[0]} pixels; need {MIN_SIDE_PX} or more a side)"
        )
    return np.clip(image, 0.0, 1.0)


def shape_coverage(rgba: np.ndarray, invert: bool | None = None) -> np.ndarray:
    """(h, w) in [0, 1]: how much each pixel belongs to the shape.

    With varying alpha the shape is the opaque part (darkness decides only where the image is
    opaque throughout). Otherwise the ground is the brightness that dominates the border.
    """
    alpha = rgba[..., 3]
    grey = rgba[..., :3] @ np.array([0.299, 0.587, 0.114])
    if alpha.min() < 0.99:
        cover = alpha.copy()
        if invert:
            cover = 1.0 - cover
        return cover
    border = np.concatenate([grey[0], grey[-1], grey[:, 0], grey[:, -1]])
    dark_ground = np.median(border) < 0.5
    cover = grey if dark_ground else 1.0 - grey
    if invert:
        cover = 1.0 - cover
    # Stretch between the ground level and the shape level so grey shadows still count.
    lo, hi = np.percentile(cover, 1), np.percentile(cover, 99)
    if hi - lo < 0.2:
        return np.zeros_like(cover)
    return np.clip((cover - lo) / (hi - lo), 0.0, 1.0)


def letterbox(coverage: np.ndarray, width: int, height: int) -> np.ndarray:
    """Fit (h, w) coverage into a (height, width) frame, aspect kept, centred; area-averaged."""
    from skimage.transform import resize

    h, w = coverage.shape
    scale = min(width / w, height / h)
    nw, nh = max(1, round(w * scale)), max(1, round(h * scale))
    small = resize(coverage, (nh, nw), order=1, anti_aliasing=scale < 1, mode="edge")
    frame = np.zeros((height, width))
    y0, x0 = (height - nh) // 2, (width - nw) // 2
    frame[y0 : y0 + nh, x0 : x0 + nw] = small
    return frame


def load_target(path: str | Path, width: int = 256, height: int = 256, invert: bool | None = None) -> np.ndarray:
    """The binary target frame (height, width) bool, checked for a usable shape."""
    frame = letterbox(shape_coverage(read_image(path), invert), width, height) >= 0.5
    check_target(frame, str(path))
    return frame


def check_target(frame: np.ndarray, name: str = "target") -> None:
    """Refuse shapes a fit cannot use: empty, nearly empty, or filling the frame."""
    share = float(frame.mean())
    if frame.sum() < 0.002 * frame.size or frame.sum() < 4:
        raise TargetError(
            f"{name}: no shape found (the image looks empty; use --invert if the shape is lighter than the ground)"
        )
    if share > 0.9:
        raise TargetError(
            f"{name}: the shape fills {share:.0%} of the frame; a shadow target needs a visible ground around it"
        )
