"""Target images -> the binary target frame: the one reading of an image file that the command
line, the Python API and the app share.

Any image that Pillow (or imageio) reads (PNG, JPEG, GIF, BMP, WebP, TIFF, ...; palette,
16-bit, CMYK, animated: the first frame; a phone's rotation tag applied), with or without
alpha, any size and aspect. With varying alpha the shape is the opaque part. Otherwise the
shape is told from the ground by the border: the brightness that dominates the image's outer
ring is the ground (a dark shadow on a light wall, or a light shape on a dark ground);
``invert`` flips the choice.

Two readings, chosen by the image:

- **Clean** (a mask, a drawing, a rendered shadow: the ground is even): stretch between the
  ground and the shape level (1st and 99th percentiles), so grey shadows count.
- **Photo** (the ground's light is uneven: a lamp's hot spot, vignetting, a sheet of paper
  lit from one side): the wall's light is estimated at a scale larger than the shape (a grey
  closing over a square 0.6 of the picture wide, on a 64-pixel copy; the image is padded by
  its edge so light falling off toward the corners is kept) and divided out; the threshold
  lies midway between the two levels that Otsu's split finds. Holes in the shape and pieces
  touching the border whose outlines are much softer than the shape's are light, not shape
  (a hot spot behind a large shadow, dark corners), and are put right.

Either way the coverage is framed (``frame_picture``) into the W x H frame and thresholded at
one half, so anti-aliased and soft edges land where they should: letterboxed (aspect kept,
centred), except that a picture of another aspect than the frame's (a phone's 4:3 or 16:9
photo) whose shape runs off its side (a forearm leaving the photo) is first cropped along its
long side to the shape and a margin, and what is left over is letterboxed with the sides the
shape runs off on the frame's edges, so an arm the photo cuts is not made to end in the air.
A clean image never takes the photo path, so masks read exactly as they always have.

A tilt of the camera is not undone: a few degrees of perspective change the shape by a few
per cent; a strongly slanted photo gives a slanted target. A photo whose frame shows more than
the wall (the edge of the paper, the lamp, furniture) reads those as shape too; crop it first.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from scipy import ndimage as ndi

from handshadow.errors import HandshadowError

MIN_SIDE_PX = 8
MAX_PIXELS = 64_000_000
LUMA = np.array([0.299, 0.587, 0.114])  # ITU-R 601 weights: RGB -> brightness

# The photo path (see the module docstring).
WORK_PX = 64  # longer side of the copy on which the wall's light is estimated
SMALLEST_SHAPE_PX = 16  # a picture with fewer shape pixels than this is empty (specks), not a small shape
ENVELOPE_SHARE = 0.6  # the closing's square, a share of that side: darker parts narrower than this are filled
UNEVEN_GROUND = 0.1  # the ground's light varies by more than this share of the contrast: read as a photo
SOFT_EDGE = 0.35  # an outline this much softer than the shape's typical one is light, not an edge
MIN_CONTRAST = 0.1  # a shape less darker (or lighter) than its ground than this is no shape
NOISE_MARGIN = 6  # ... and so is one that stands out less than this many times the ground's noise
FAINT = 0.25  # a shape this little darker (or lighter) than its ground is read, with a warning
PUT_RIGHT_SHARE = 0.005  # pieces put right over this share of the picture are worth a warning
SOFT_OUTLINE = 0.15  # a reading whose outline is this soft in part is worth a warning
EPS = 0.01  # keeps ratios of dark pixels finite


class TargetError(HandshadowError):
    """A target image that cannot be used."""


@dataclasses.dataclass(frozen=True)
class Reading:
    """How an image was read.

    coverage: (h, w) float in [0, 1], how much each pixel belongs to the shape.
    photo: True when the ground's uneven light was taken out first.
    warning: one line when the reading is unsure (say what to check), else None."""

    coverage: np.ndarray
    photo: bool = False
    warning: str | None = None


@dataclasses.dataclass(frozen=True)
class Target:
    """A target frame: frame (H, W) bool, True in the shape; warning as in Reading."""

    frame: np.ndarray
    warning: str | None = None


def read_image(path: str | Path) -> np.ndarray:
    """(h, w, 4) float RGBA in [0, 1] (alpha 1 where the file has none)."""
    from PIL import Image, ImageOps, UnidentifiedImageError

    path = Path(path)
    if path.is_dir():
        raise TargetError(f"{path} is a folder; give one image file (handshadow batch fits a folder of them)")
    if not path.is_file():
        raise TargetError(f"target not found: {path} (give an image file or a built-in example name)")
    try:
        with Image.open(path) as im:
            _check_size(path, im.width, im.height)
            image = _pixels(ImageOps.exif_transpose(im))
    except TargetError:
        raise
    except Image.DecompressionBombError:
        raise TargetError(f"{path} is too large (more than {MAX_PIXELS // 1_000_000} megapixels)") from None
    except UnidentifiedImageError:
        image = _read_with_imageio(path)  # formats only imageio's plugins know
    except Exception:  # Pillow raises many kinds for damaged files
        raise TargetError(f"{path} is not a readable image (damaged, or not a picture)") from None
    return _as_rgba(image, path)


def _check_size(path: Path, width: int, height: int) -> None:
    if width * height > MAX_PIXELS:
        raise TargetError(f"{path} is too large ({width} x {height} pixels)")


def _pixels(im) -> np.ndarray:
    """A Pillow image's first frame as an array: grey, grey + alpha, RGB or RGBA; uint8 or
    uint16 (16-bit files), bool for 1-bit ones."""
    mode = im.mode
    transparent = "transparency" in im.info
    if mode in ("1", "L", "LA", "RGB", "RGBA") and not (transparent and mode in ("L", "RGB")):
        return np.asarray(im)
    if mode.startswith("I;16"):
        return np.asarray(im).astype(np.uint16)
    if mode == "I":  # 32-bit integers: mostly 16-bit data
        values = np.asarray(im)
        return np.clip(values, 0, 65535).astype(np.uint16) if values.max() > 255 else values.astype(np.uint8)
    if mode == "F":
        values = np.asarray(im, dtype=np.float64)
        return values / max(1.0, float(values.max()))
    # Palettes, CMYK (Adobe's inverted CMYK included), YCbCr, LAB, HSV, premultiplied alpha.
    keeps_alpha = transparent or "A" in mode.upper()
    return np.asarray(im.convert("RGBA" if keeps_alpha else "RGB"))


def _read_with_imageio(path: Path) -> np.ndarray:
    import imageio.v3 as iio

    try:
        props = iio.improps(path)
        _check_size(path, *reversed(props.shape[:2]))
        return np.asarray(iio.imread(path, index=0))
    except TargetError:
        raise
    except Exception:  # imageio raises many kinds for unreadable files
        raise TargetError(f"{path} is not a readable image (not a picture format handshadow reads)") from None


def _as_rgba(image: np.ndarray, path: Path) -> np.ndarray:
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


def read_shape(rgba: np.ndarray, invert: bool | None = None) -> Reading:
    """How much each pixel of (h, w, 4) RGBA in [0, 1] belongs to the shape, and how surely.

    With varying alpha the shape is the opaque part (darkness decides only where the image is
    opaque throughout). Otherwise the ground is the brightness that dominates the border, and
    a ground with uneven light is evened out first (the photo path)."""
    alpha = rgba[..., 3]
    if alpha.min() < 0.99:
        return Reading(1.0 - alpha if invert else alpha.copy())
    grey = rgba[..., :3] @ LUMA
    dark_ground = np.median(_ring(grey)) < 0.5
    cover = grey if dark_ground else 1.0 - grey
    if invert:
        cover = 1.0 - cover
    # Stretch between the ground level and the shape level so grey shadows still count.
    lo, hi = np.percentile(cover, 1), np.percentile(cover, 99)
    if hi - lo < 0.2:  # a shape under 1 % of the picture: its level among the top 0.1 %
        hi = np.percentile(cover, 99.9)
    if hi - lo < 0.2:  # not a clean shape; a dim photo's may still be there, relative to its wall
        return _read_photo(grey, invert)
    cover = np.clip((cover - lo) / (hi - lo), 0.0, 1.0)
    # Clean: the border sits at the ground's end of the range, and the ground is even (judged
    # before ``invert``, which says the other end is the shape).
    auto = 1.0 - cover if invert else cover
    if np.median(_ring(auto)) <= UNEVEN_GROUND and _ground_spread(auto) <= UNEVEN_GROUND:
        return Reading(cover)
    return _read_photo(grey, invert)


def shape_coverage(rgba: np.ndarray, invert: bool | None = None) -> np.ndarray:
    """(h, w) in [0, 1]: how much each pixel belongs to the shape (``read_shape``'s coverage)."""
    return read_shape(rgba, invert).coverage


def _small(image: np.ndarray, side_px: int) -> np.ndarray:
    """A copy averaged over f x f blocks whose longer side is about ``side_px`` (never enlarged)."""
    f = max(1, round(max(image.shape) / side_px))
    if f == 1:
        return image
    return ndi.uniform_filter(image, f, mode="nearest")[f // 2 :: f, f // 2 :: f]


def _ground_spread(cover: np.ndarray) -> float:
    """How unevenly the ground is lit: the 2-98 % range of the coverage over the ground, away
    from the shape, on a small copy (which averages noise and JPEG ringing away)."""
    small = _small(cover, WORK_PX)
    ground = ndi.binary_erosion(small < 0.5, iterations=2, border_value=1)
    if ground.sum() < 16:
        return 0.0
    lo, hi = np.percentile(small[ground], [2, 98])
    return float(hi - lo)


def _wall_light(grey: np.ndarray, dark_shape: bool) -> np.ndarray:
    """(h, w) the ground's brightness under the shape as well: a grey closing (for a dark
    shape; an opening for a light one) over a square ENVELOPE_SHARE of the picture wide.

    The picture is padded by its own edge first: then light that falls off toward a border or
    a corner (any light whose brighter parts are convex: a lamp's spot, vignetting) comes
    through the closing unchanged, while the shape, narrower than the square, is filled."""
    from skimage.transform import resize

    small = _small(grey, WORK_PX)
    k = max(3, int(ENVELOPE_SHARE * max(small.shape)) | 1)
    padded = np.pad(small, k, mode="edge")
    envelope = ndi.grey_closing(padded, size=(k, k)) if dark_shape else ndi.grey_opening(padded, size=(k, k))
    envelope = ndi.gaussian_filter(envelope[k:-k, k:-k], 1.5, mode="nearest")  # the square's steps
    return resize(envelope, grey.shape, order=1)


def _contrast_coverage(grey: np.ndarray, light: np.ndarray, dark_shape: bool) -> tuple[np.ndarray, float]:
    """Coverage from the picture over the wall's light: 0 at the ground's level, 1 at the
    shape's, one half midway (the two levels are the medians of Otsu's two classes). Returns
    (coverage, contrast: how much darker, or lighter, the shape is than its ground)."""
    from skimage.filters import threshold_otsu

    if dark_shape:
        depth = 1 - (grey + EPS) / (light + EPS)  # 0 on the wall, 1 for a black shadow
    else:
        depth = 1 - (1 - grey + EPS) / (1 - light + EPS)
    depth = ndi.gaussian_filter(depth, max(1.0, max(grey.shape) / 600))  # sensor noise
    clipped = np.clip(depth, -0.5, 1.0)
    if np.ptp(clipped) < 1e-6:
        return np.zeros_like(grey), 0.0
    split = threshold_otsu(clipped)
    ground_depth = depth[depth < split]
    ground, shape = np.median(ground_depth), np.median(depth[depth >= split])
    contrast = float(shape - ground)
    noise = 1.4826 * float(np.median(np.abs(ground_depth - ground)))  # the ground's spread, robustly
    if contrast < NOISE_MARGIN * noise:  # Otsu split the noise of an empty picture
        contrast = 0.0
    return np.clip((depth - ground) / max(contrast, 1e-3), 0.0, 1.0), contrast


def _ring(image: np.ndarray) -> np.ndarray:
    """The image's outer ring of pixels, (2 (h + w),)."""
    return np.concatenate([image[0], image[-1], image[:, 0], image[:, -1]])


@dataclasses.dataclass(frozen=True)
class _PhotoReading:
    """One polarity's reading of a photo: coverage (h, w) in [0, 1], contrast (how much darker,
    or lighter, the shape is than its ground), put_right (share of pixels whose soft-edged
    pieces were put right), spread (the ground's unevenness left) and border (share of the
    outer ring read as shape)."""

    coverage: np.ndarray
    contrast: float
    put_right: float
    spread: float
    border: float

    @property
    def misfit(self) -> float:
        """Lower is likelier: the ground holds the border and is even once the light is out
        (the wrong polarity leaves the light's unevenness in its ground); no shape is unlikely."""
        return self.border + self.spread + (1.0 if self.contrast < MIN_CONTRAST else 0.0)


def _read_photo(grey: np.ndarray, invert: bool | None) -> Reading:
    """The photo path: even out the wall's light, split shape from ground, put soft-edged
    pieces right. Both a dark and a light shape are read; the likelier is kept (the other
    with ``invert``)."""
    readings = []
    for dark_shape in (True, False):
        coverage, contrast = _contrast_coverage(grey, _wall_light(grey, dark_shape), dark_shape)
        coverage, put_right = _soft_pieces(coverage)
        border = float((_ring(coverage) >= 0.5).mean())
        readings.append(_PhotoReading(coverage, contrast, put_right, _ground_spread(coverage), border))
    readings.sort(key=lambda r: r.misfit)
    r = readings[1 if invert else 0]
    if r.contrast < MIN_CONTRAST:
        return Reading(np.zeros_like(grey), photo=True)
    warning = None
    if r.contrast < FAINT:
        warning = f"the shape is faint ({r.contrast:.0%} from its ground): check target.png"
    elif r.put_right > PUT_RIGHT_SHARE:
        warning = f"the light is uneven across the shape ({r.put_right:.0%} read by its outline): check target.png"
    elif r.spread > UNEVEN_GROUND:
        warning = "the ground is uneven: check target.png"
    elif (soft := _soft_outline(r.coverage)) > SOFT_OUTLINE:
        warning = f"{soft:.0%} of the outline is soft, perhaps light rather than shape: check target.png"
    return Reading(r.coverage, photo=True, warning=warning)


@dataclasses.dataclass(frozen=True)
class _Outline:
    """The shape's outline in a coverage map: steepness (h, w), the coverage's gradient per
    1/128 of the picture (the same for any resolution); outline (h, w) bool, the shape's edge
    pixels; limit, the steepness below which an outline is soft (SOFT_EDGE times the shape's
    typical, 75th-percentile, steepness)."""

    steepness: np.ndarray
    outline: np.ndarray
    limit: float

    @classmethod
    def of(cls, coverage: np.ndarray) -> _Outline | None:
        unit = max(coverage.shape) / 128
        gy, gx = np.gradient(ndi.gaussian_filter(coverage, max(1.0, unit)))
        steepness = np.hypot(gx, gy) * unit
        shape = coverage >= 0.5
        outline = shape & ~ndi.binary_erosion(shape, border_value=1)
        if not outline.any():
            return None
        return cls(steepness, outline, SOFT_EDGE * float(np.percentile(steepness[outline], 75)))

    def soft_share(self) -> float:
        """The share of the outline that is soft: light, not an edge."""
        return float((self.steepness[self.outline] < self.limit).mean())


def _soft_outline(coverage: np.ndarray) -> float:
    edges = _Outline.of(coverage)
    return 0.0 if edges is None else edges.soft_share()


def _soft_pieces(coverage: np.ndarray) -> tuple[np.ndarray, float]:
    """Fill the shape's holes and drop its pieces at the border whose outlines are soft
    (see _Outline): a hot spot behind a large shadow reads as a hole with no edge, dark
    corners as pieces with no edge. Returns (coverage, share of pixels changed)."""
    edges = _Outline.of(coverage)
    if edges is None:
        return coverage, 0.0
    shape = coverage >= 0.5
    grow = max(1, round(2 * max(coverage.shape) / 128))
    # Holes: pieces of ground that do not touch the border.
    rim = ~shape & ndi.binary_dilation(shape)
    holes = _soft_components(~shape, rim, edges.steepness, edges.limit, inner=True)
    filled = holes | (ndi.binary_dilation(holes, iterations=grow) & ~shape)
    # Pieces of shape that touch the border.
    dropped = ndi.binary_dilation(
        _soft_components(shape, edges.outline, edges.steepness, edges.limit, inner=False), iterations=grow
    )
    coverage = np.where(dropped, 0.0, np.where(filled, 1.0, coverage))
    return coverage, float((filled | (dropped & shape)).mean())


def _soft_components(
    region: np.ndarray, edge: np.ndarray, steepness: np.ndarray, limit: float, inner: bool
) -> np.ndarray:
    """The connected pieces of ``region`` whose ``edge`` pixels are on average less steep than
    ``limit``: those that do not touch the border (inner) or those that do (not inner)."""
    labels, n = ndi.label(region)
    if n == 0:
        return np.zeros_like(region)
    at_border = np.zeros(n + 1, bool)
    at_border[_ring(labels)] = True
    index = np.arange(1, n + 1)
    mean = np.asarray(ndi.mean(steepness, labels=np.where(edge, labels, 0), index=index))
    has_edge = np.asarray(ndi.sum(edge, labels=labels, index=index)) > 0
    soft = np.zeros(n + 1, bool)
    soft[1:] = has_edge & (np.nan_to_num(mean) < limit) & (at_border[1:] != inner)
    return soft[labels]


def letterbox(coverage: np.ndarray, width: int, height: int, anchor: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Fit (h, w) coverage into a (height, width) frame, aspect kept; area-averaged. ``anchor``
    (rows, columns) places the picture along each axis where it leaves room: -1 at the frame's
    start (top, left), 0 centred, 1 at its end (bottom, right)."""
    from skimage.transform import resize

    h, w = coverage.shape
    scale = min(width / w, height / h)
    nw, nh = max(1, round(w * scale)), max(1, round(h * scale))
    small = resize(coverage, (nh, nw), order=1, anti_aliasing=scale < 1, mode="edge")
    frame = np.zeros((height, width))
    y0, x0 = ((room * (1 + a)) // 2 for room, a in ((height - nh, anchor[0]), (width - nw, anchor[1])))
    frame[y0 : y0 + nh, x0 : x0 + nw] = small
    return frame


# A picture cropped to its shape along its long side keeps this share of its short side as a
# margin on each side the shape does not run off.
CROP_MARGIN_SHARE = 0.05


def frame_picture(coverage: np.ndarray, width: int, height: int) -> np.ndarray:
    """Coverage (h, w) in [0, 1] -> the (height, width) frame, float. A picture of another
    aspect than the frame's whose shape (coverage >= 0.5, specks aside: SPECK_SHARE) runs off one
    of its sides is cropped along its long side to the shape with a margin of CROP_MARGIN_SHARE
    of its short side, to no less than the frame's aspect and never past a side the shape meets, then letterboxed
    (``letterbox``) with the sides the shape meets on the frame's edges: an arm that leaves the
    picture leaves the frame. Any other picture (the frame's aspect, or a shape clear of the
    picture's sides) is letterboxed centred, as it is, so the picture's pixels map onto the
    frame's as they always have."""
    h, w = coverage.shape
    if h * width == w * height:
        return letterbox(coverage, width, height)
    shape = _without_specks(coverage >= 0.5)
    if not _ring(shape).any():
        return letterbox(coverage, width, height)
    rows, cols = np.flatnonzero(shape.any(axis=1)), np.flatnonzero(shape.any(axis=0))
    margin = max(1, round(CROP_MARGIN_SHARE * min(h, w)))
    if w * height > h * width:  # wider than the frame: crop the columns
        x0, x1 = _crop_span(cols[0], cols[-1], w, math.ceil(h * width / height), margin)
        coverage, shape = coverage[:, x0:x1], shape[:, x0:x1]
    else:
        y0, y1 = _crop_span(rows[0], rows[-1], h, math.ceil(w * height / width), margin)
        coverage, shape = coverage[y0:y1], shape[y0:y1]
    anchor = tuple(
        _edge_anchor(first.any(), last.any()) for first, last in ((shape[0], shape[-1]), (shape[:, 0], shape[:, -1]))
    )
    return letterbox(coverage, width, height, anchor)


# Pieces of a picture's shape under this share of its largest piece are specks (dust, noise):
# they do not move the frame_picture's crop.
SPECK_SHARE = 0.01


def _without_specks(shape: np.ndarray) -> np.ndarray:
    """Shape (h, w) bool without its pieces (8-connected) under SPECK_SHARE of the largest."""
    labels, n = ndi.label(shape, np.ones((3, 3)))
    if n <= 1:
        return shape
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return (sizes >= SPECK_SHARE * sizes.max())[labels]


def _crop_span(first: int, last: int, length: int, at_least: int, margin: int) -> tuple[int, int]:
    """[start, end) along an axis of ``length`` pixels holding the shape's span first..last
    with ``margin`` on each side it does not meet (an end it meets stays), grown to
    ``at_least`` (away from an end the shape meets, else evenly) within the axis."""
    meets_start, meets_end = first == 0, last == length - 1
    start = 0 if meets_start else max(0, first - margin)
    end = length if meets_end else min(length, last + 1 + margin)
    short = min(at_least, length) - (end - start)
    if short > 0:
        if meets_start and not meets_end:
            end += short
        elif meets_end and not meets_start:
            start -= short
        else:
            start = max(0, start - short // 2)
            end = min(length, start + min(at_least, length))
            start = end - min(at_least, length)
    return int(start), int(end)


def _edge_anchor(meets_start: bool, meets_end: bool) -> int:
    """Where a letterboxed axis goes (letterbox's anchor): to the one end its shape meets, else centred."""
    return -1 if meets_start and not meets_end else 1 if meets_end and not meets_start else 0


def read_target(path: str | Path, width: int = 256, height: int = 256, invert: bool | None = None) -> Target:
    """The binary target frame (height, width), checked for a usable shape, with the reading's
    warning when it is unsure."""
    reading = read_shape(read_image(path), invert)
    frame = frame_picture(reading.coverage, width, height) >= 0.5
    shape = reading.coverage >= 0.5
    if _too_few(frame) and shape.sum() >= SMALLEST_SHAPE_PX:  # a shape, too small for the frame: not empty
        raise TargetError(f"{path}: {_too_small(shape)}")
    check_target(frame, str(path))
    return Target(frame, reading.warning)


def _too_few(shape: np.ndarray) -> bool:
    """Too few pixels for a shape to fit: under 0.2 % of the frame, or under 4."""
    return shape.sum() < 0.002 * shape.size or shape.sum() < 4


# A shape at least this share of its picture across that still shrinks to too little of the
# frame is drawn in lines too thin, not small: cropping would not help.
THIN_LINES_SHARE = 0.3


def _too_small(shape: np.ndarray) -> str:
    """Words for a shape (bool, the picture's pixels) that shrinks to too little of the frame:
    a small shape in a big picture is to be cropped closer, an outline or line drawing that
    spans its picture to be filled or drawn thicker."""
    rows, cols = np.nonzero(shape)
    across = max(int(np.ptp(rows)), int(np.ptp(cols))) + 1
    if across >= THIN_LINES_SHARE * max(shape.shape):
        return (
            f"the shape's lines are too thin ({int(shape.sum())} px in all across {across} px): fill the"
            " shape, or draw it with thicker lines (a shadow target is a filled silhouette)"
        )
    return (
        f"the shape is too small in its picture ({across} of its {max(shape.shape)} px across): "
        "crop the picture closer around it"
    )


def load_target(path: str | Path, width: int = 256, height: int = 256, invert: bool | None = None) -> np.ndarray:
    """The binary target frame (height, width) bool, checked for a usable shape."""
    return read_target(path, width, height, invert).frame


def check_target(frame: np.ndarray, name: str = "target") -> None:
    """Refuse shapes a fit cannot use: empty, nearly empty, or filling the frame."""
    share = float(frame.mean())
    if _too_few(frame):
        raise TargetError(
            f"{name}: no shape found (the image looks empty; use --invert if the shape is lighter than the ground)"
        )
    if share > 0.9:
        raise TargetError(
            f"{name}: the shape fills {share:.0%} of the frame; a shadow target needs a visible ground around it"
        )
