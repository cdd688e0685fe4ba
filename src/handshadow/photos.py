"""Photo-like pictures of a clean shape, seeded: a shadow on a lamp-lit wall (or a drawing on
paper) as a phone takes it. The tests and ``bench/targets.py`` use them to check that
``target.py`` reads a photo as the shape it shows.

The picture is made in the wall's frame and then seen through the camera:

    wall     = exposure * light(x, y) * tint         light: hot spot and vignetting
    picture  = wall * (1 - darkness * soft(shape))   soft: the penumbra, a Gaussian blur
    photo    = jpeg(noise(tilt(picture)))            tilt: a small perspective warp

``truth`` is the clean shape under the same tilt: the reading cannot undo the camera's angle,
so a tilted photo is judged against the tilted shape.
"""

from __future__ import annotations

import dataclasses
import io

import numpy as np

PHOTO_SIDE_PX = 600  # the camel photo: 600 x 600


@dataclasses.dataclass(frozen=True)
class PhotoEffects:
    """How far a photo is from a clean mask; the defaults are a clean, black-on-white picture."""

    tint: float = 0.0  # colour cast, 0 (none) to 1 (strong: warm lamp light)
    hot_spot: float = 0.0  # extra light where the lamp points, relative to the wall (0 to 1)
    vignetting: float = 0.0  # how much darker the corners are than the middle (0 to 0.5)
    darkness: float = 1.0  # how much darker the shadow is than the wall (0.4 to 0.8 for grey shadows)
    blur_px: float = 0.0  # penumbra: Gaussian sigma in pixels of a 600-pixel photo (up to 5)
    noise: float = 0.0  # sensor noise: standard deviation on [0, 1] (up to 0.05)
    jpeg_quality: int | None = None  # JPEG compression (30 to 95), None for none
    tilt: float = 0.0  # perspective: largest corner shift as a share of the side (up to 0.04)
    exposure: float = 0.85  # the wall's brightness in the middle of the photo


# Each effect alone at the strength the issue names (strong end); ALL is every one together.
EFFECTS = {
    "uneven light": PhotoEffects(hot_spot=0.6, vignetting=0.5),
    "grey shadow": PhotoEffects(darkness=0.4),
    "soft edges": PhotoEffects(blur_px=5.0),
    "noise": PhotoEffects(noise=0.05),
    "jpeg": PhotoEffects(jpeg_quality=30),
    "tint": PhotoEffects(tint=1.0),
    "tilt": PhotoEffects(tilt=0.04),
}
ALL = PhotoEffects(
    tint=1.0, hot_spot=0.6, vignetting=0.5, darkness=0.6, blur_px=5.0, noise=0.04, jpeg_quality=50, tilt=0.03
)


def random_effects(rng: np.random.Generator) -> PhotoEffects:
    """Every effect at once, each at a random strength within the ranges above."""
    return PhotoEffects(
        tint=float(rng.uniform(0, 1)),
        hot_spot=float(rng.uniform(0, 0.8)),
        vignetting=float(rng.uniform(0, 0.5)),
        darkness=float(rng.uniform(0.4, 0.8)),
        blur_px=float(rng.uniform(0, 5)),
        noise=float(rng.uniform(0, 0.05)),
        jpeg_quality=int(rng.integers(30, 96)),
        tilt=float(rng.uniform(0, 0.04)),
        exposure=float(rng.uniform(0.6, 0.95)),
    )


def photo_of(
    shape: np.ndarray, effects: PhotoEffects, rng: np.random.Generator, side_px: int = PHOTO_SIDE_PX
) -> tuple[np.ndarray, np.ndarray]:
    """A photo of ``shape`` (h, w) bool as a dark shadow on a light wall.

    Returns (photo (H, W, 3) uint8 RGB, truth (H, W) bool), H x W = the shape's aspect with the
    longer side ``side_px``."""
    from scipy.ndimage import gaussian_filter
    from skimage.transform import resize, warp

    h, w = shape.shape
    scale = side_px / max(h, w)
    size = (max(8, round(h * scale)), max(8, round(w * scale)))
    cover = resize(np.asarray(shape, float), size, order=1, anti_aliasing=scale < 1)
    H, W = size
    yy, xx = np.mgrid[:H, :W]
    u, v = (xx + 0.5) / W - 0.5, (yy + 0.5) / H - 0.5  # -0.5..0.5 across the photo

    # The lamp points near the shape: its spot is centred near the shape's middle, a third of the photo wide.
    cy, cx = (np.argwhere(cover > 0.5).mean(0) if (cover > 0.5).any() else (H / 2, W / 2)) / np.array([H, W]) - 0.5
    cy, cx = cy + rng.normal(0, 0.08), cx + rng.normal(0, 0.08)
    spot = np.exp(-((u - cx) ** 2 + (v - cy) ** 2) / (2 * rng.uniform(0.15, 0.3) ** 2))
    corner = (u**2 + v**2) / 0.5  # 0 in the middle, 1 at the corners
    light = (1 + effects.hot_spot * spot) * (1 - effects.vignetting * corner)
    light = light / (1 + effects.hot_spot * spot[H // 2, W // 2])
    warm = np.array([1.0, 0.82, 0.6])  # a tungsten lamp's cast, mixed with a random colour
    colour = 1 - effects.tint * (1 - (0.6 * warm + 0.4 * rng.uniform(0.55, 1.0, 3)))
    soft = gaussian_filter(cover, effects.blur_px * side_px / PHOTO_SIDE_PX) if effects.blur_px > 0 else cover
    picture = (effects.exposure * light * (1 - effects.darkness * soft))[..., None] * colour

    truth = cover
    if effects.tilt > 0:
        corners = np.array([[0, 0], [W, 0], [W, H], [0, H]], float)
        moved = corners + rng.uniform(-1, 1, (4, 2)) * effects.tilt * np.array([W, H])
        tform = _projective(moved, corners)  # warp() maps output points back to input points
        picture = np.stack([warp(picture[..., c], tform, order=1, mode="edge") for c in range(3)], -1)
        truth = warp(cover, tform, order=1, mode="edge")
    if effects.noise > 0:
        picture = picture + rng.normal(0, effects.noise, picture.shape)
    photo = (np.clip(picture, 0, 1) * 255 + 0.5).astype(np.uint8)
    if effects.jpeg_quality is not None:
        photo = _jpeg(photo, effects.jpeg_quality)
    return photo, truth >= 0.5


def _projective(src: np.ndarray, dst: np.ndarray):
    from skimage.transform import ProjectiveTransform

    if hasattr(ProjectiveTransform, "from_estimate"):  # scikit-image >= 0.26
        return ProjectiveTransform.from_estimate(src, dst)
    tform = ProjectiveTransform()
    tform.estimate(src, dst)
    return tform


def _jpeg(rgb: np.ndarray, quality: int) -> np.ndarray:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(rgb).save(buffer, format="JPEG", quality=quality)
    buffer.seek(0)
    return np.asarray(Image.open(buffer).convert("RGB"))


def read_back(photo: np.ndarray, truth: np.ndarray, size_px: int = 256):
    """Read ``photo`` (H, W, 3) uint8's shape as ``target.py`` reads a file's and compare it
    with ``truth`` (H, W) bool, both letterboxed (centred) into a size x size frame.

    Returns (IoU, the target.Reading)."""
    from handshadow.metrics import iou
    from handshadow.target import letterbox, read_shape

    rgba = np.concatenate([photo / 255.0, np.ones(photo.shape[:2] + (1,))], axis=2)
    reading = read_shape(rgba)
    frame = letterbox(reading.coverage, size_px, size_px) >= 0.5
    expected = letterbox(truth.astype(float), size_px, size_px) >= 0.5
    return iou(frame, expected), reading
