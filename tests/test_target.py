"""Target images of every kind become the same binary frame; bad ones are refused clearly."""

import imageio.v3 as iio
import numpy as np
import pytest

from handshadow.target import TargetError, load_target


def _shape(h=120, w=90):
    """A filled ellipse with a thin antenna: a shape with a thin part."""
    yy, xx = np.mgrid[:h, :w]
    body = ((yy - 0.6 * h) / (0.3 * h)) ** 2 + ((xx - 0.5 * w) / (0.35 * w)) ** 2 <= 1
    body[int(0.1 * h) : int(0.4 * h), int(0.48 * w) : int(0.52 * w) + 1] = True
    return body


@pytest.fixture
def shape():
    return _shape()


def _reference(shape, size=64):
    from handshadow.target import letterbox

    return letterbox(shape.astype(float), size, size) >= 0.5


@pytest.mark.parametrize(
    "kind",
    [
        "dark-on-light.png",
        "light-on-dark.png",
        "alpha.png",
        "grey.png",
        "gif.gif",
        "bmp.bmp",
        "jpeg.jpg",
        "sixteen.png",
        "antialiased.png",
    ],
)
def test_every_kind_of_image_gives_the_same_frame(tmp_path, shape, kind):
    path = tmp_path / kind
    white, black = np.uint8(255), np.uint8(0)
    if kind.startswith("dark-on-light"):
        iio.imwrite(path, np.where(shape[..., None], black, white).repeat(3, 2))
    elif kind.startswith("light-on-dark"):
        iio.imwrite(path, np.where(shape[..., None], white, black).repeat(3, 2))
    elif kind == "alpha.png":
        rgba = np.zeros(shape.shape + (4,), np.uint8)
        rgba[..., :3] = 40  # dark ink everywhere; only alpha tells the shape
        rgba[..., 3] = np.where(shape, 255, 0)
        iio.imwrite(path, rgba)
    elif kind == "grey.png":
        iio.imwrite(path, np.where(shape, 30, 220).astype(np.uint8))
    elif kind == "gif.gif":
        iio.imwrite(path, np.where(shape, 0, 255).astype(np.uint8))
    elif kind == "bmp.bmp":
        iio.imwrite(path, np.where(shape[..., None], black, white).repeat(3, 2))
    elif kind == "jpeg.jpg":
        iio.imwrite(path, np.where(shape[..., None], black, white).repeat(3, 2), quality=90)
    elif kind == "sixteen.png":
        iio.imwrite(path, np.where(shape, 0, 65535).astype(np.uint16))
    elif kind == "antialiased.png":
        from skimage.transform import resize

        big = _shape(480, 360)
        iio.imwrite(path, (255 - resize(big.astype(float), (120, 90), anti_aliasing=True) * 255).astype(np.uint8))
    frame = load_target(path, 64, 64)
    ref = _reference(shape)
    assert frame.shape == (64, 64) and frame.dtype == bool
    assert (frame ^ ref).sum() <= 0.03 * ref.sum()


def test_letterbox_keeps_aspect_and_centres(tmp_path):
    wide = np.zeros((50, 200), bool)
    wide[10:40, 20:180] = True
    iio.imwrite(tmp_path / "wide.png", np.where(wide, 0, 255).astype(np.uint8))
    frame = load_target(tmp_path / "wide.png", 100, 100)
    rows, cols = np.nonzero(frame)
    # 200 x 50 image -> a 100 x 25 band in rows 37..62; the shape's rows 10..40 land on 42..57.
    assert 41 <= rows.min() <= 43 and 55 <= rows.max() <= 58
    assert 9 <= cols.min() <= 11 and 88 <= cols.max() <= 90


def test_invert_overrides_the_border_rule(tmp_path, shape):
    from handshadow.target import letterbox

    iio.imwrite(tmp_path / "s.png", np.where(shape, 0, 255).astype(np.uint8))
    inverted = load_target(tmp_path / "s.png", 64, 64, invert=True)  # the ground becomes the shape
    expected = letterbox((~shape).astype(float), 64, 64) >= 0.5
    assert (inverted ^ expected).sum() <= 0.03 * expected.sum()


@pytest.mark.parametrize("case", ["missing", "text", "empty", "full", "one-pixel", "truncated"])
def test_bad_targets_are_refused(tmp_path, case):
    path = tmp_path / f"{case}.png"
    if case == "text":
        path.write_text("this is not an image\n")
    elif case == "empty":
        iio.imwrite(path, np.full((50, 50), 255, np.uint8))
    elif case == "full":
        img = np.zeros((50, 50), np.uint8)
        img[0, :] = img[-1, :] = img[:, 0] = img[:, -1] = 255  # a light frame around a dark fill
        iio.imwrite(path, img)
    elif case == "one-pixel":
        iio.imwrite(path, np.zeros((1, 1), np.uint8))
    elif case == "truncated":
        iio.imwrite(path, np.where(_shape(), 0, 255).astype(np.uint8))
        path.write_bytes(path.read_bytes()[:60])
    with pytest.raises(TargetError) as err:
        load_target(path, 64, 64)
    assert "\n" not in str(err.value)
