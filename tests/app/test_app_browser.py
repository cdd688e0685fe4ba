"""The web app in a real browser: Debian's Chromium driven by Playwright (never `playwright
install`). One `handshadow app` on 127.0.0.1 serves every test; the browser may reach nothing
else. Fits are kept short (quality fast, a 64-pixel frame, one hand where it does not matter,
and the app's own bound on each fit, APP_TIME_LIMIT_S): CI has two cores."""

import io
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
import zipfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

from handshadow.export.images import BOTH, MISSING

CHROMIUM = "/usr/bin/chromium"
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1",
]
APP_TIME_LIMIT_S = 12  # handshadow app --time-limit: a fit's search ends then, its best finished
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
RESULT_FILES = {
    "target.png",
    "shadow.png",
    "overlay.png",
    "scene.json",
    "pose.json",
    "hands.glb",
    "guide.png",
    "progress.gif",
    "print.stl",  # the model to 3D-print (handshadow print)
}

playwright = pytest.importorskip("playwright.sync_api")
pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason="Debian's chromium is not installed (make test installs it)"
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def app_url():
    port = _free_port()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "handshadow.cli", "app", "--port", str(port), "--time-limit", str(APP_TIME_LIMIT_S)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    url = f"http://127.0.0.1:{port}/"
    deadline = time.time() + 120
    while time.time() < deadline:
        try:
            urllib.request.urlopen(url, timeout=2)
            break
        except OSError:
            if proc.poll() is not None:
                raise RuntimeError("the app exited: " + proc.stdout.read()) from None
            time.sleep(0.5)
    else:
        proc.kill()
        raise RuntimeError("the app did not start")
    yield url
    proc.terminate()
    proc.wait(timeout=30)


@pytest.fixture(scope="module")
def browser():
    with playwright.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        yield b
        b.close()


@pytest.fixture
def page(browser, app_url):
    context = browser.new_context(viewport={"width": 1400, "height": 1500})
    pg = context.new_page()
    pg.requests = []
    pg.on("request", lambda r: pg.requests.append(r.url))
    _open(pg, app_url)
    yield pg
    hosts = {u.split("/")[2] for u in pg.requests if u.startswith("http")}
    assert hosts <= {app_url.split("/")[2]}, f"the page reached beyond localhost: {hosts}"
    context.close()


def _open(page, url: str) -> None:
    """Load the page and wait until it has read the default example (its first event), so
    later events are not overtaken by it."""
    page.goto(url)
    page.wait_for_selector("#fit")
    page.wait_for_function("() => /as it will be read/.test(document.querySelector('#status').innerText)")


def _choose(page, group_id: str, label: str) -> None:
    page.locator(f"#{group_id}").get_by_label(label, exact=True).check()


def _options(page, hands: str, size: str = "64", quality: str = "fast") -> None:
    """Open Options and choose hands, detail and quality (fast by default here: the page's
    own default is the command line's, minutes on these two cores)."""
    page.get_by_text("Options").click()
    _choose(page, "hands", hands)
    _choose(page, "size", size)
    _choose(page, "quality", quality)


def _upload(page, path) -> None:
    """Upload a file and wait until the page has read it (a reading or a message)."""
    _choose(page, "source", "Upload")
    page.wait_for_function("() => /Pick a shape/.test(document.querySelector('#status').innerText)")
    page.locator("#upload input[type=file]").set_input_files(str(path))
    page.wait_for_function("() => !/Pick a shape/.test(document.querySelector('#status').innerText)", timeout=30000)


def _fetch(page, href: str) -> bytes:
    return urllib.request.urlopen(
        href if href.startswith("http") else page.url.rstrip("/") + "/" + href.lstrip("/"), timeout=30
    ).read()


def _reading(page, size: int = 64) -> np.ndarray:
    """The shape as the page says it will be read, (size, size) bool: the page shows it
    enlarged by a whole factor."""
    page.wait_for_selector("#reading img[src]", timeout=30000)
    return _shrunk(_dark(_fetch(page, page.locator("#reading img").get_attribute("src"))), size)


def _shrunk(picture: np.ndarray, size: int) -> np.ndarray:
    k = picture.shape[0] // size
    assert picture.shape[:2] == (size * k, size * k), f"not a {size}-pixel frame enlarged: {picture.shape}"
    small = picture[::k, ::k]
    assert np.array_equal(np.repeat(np.repeat(small, k, 0), k, 1), picture)
    return small


def _dark(png: bytes) -> np.ndarray:
    """A black-on-white picture's shape, (H, W) bool."""
    image = iio.imread(png)
    return (image if image.ndim == 2 else image[..., :3].mean(-1)) < 128


def _cropped_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two masks after cropping each to its bounding box and bringing b to a's crop size."""

    def crop(m):
        rows, cols = np.nonzero(m)
        return m[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]

    a, b = crop(a), crop(b)
    b = np.asarray(Image.fromarray(b).resize(a.shape[::-1], Image.Resampling.NEAREST))
    return float((a & b).sum() / (a | b).sum())


def _wait_result(page, timeout_s: float = 150) -> float:
    t0 = time.time()
    page.click("#fit")
    page.wait_for_selector("#zip a[href]", timeout=timeout_s * 1000)
    return time.time() - t0


def _zip_names(page, selector: str = "#zip") -> tuple[set[str], zipfile.ZipFile]:
    z = zipfile.ZipFile(io.BytesIO(_fetch(page, page.locator(f"{selector} a[href]").first.get_attribute("href"))))
    return set(z.namelist()), z


def _zip_target(page) -> np.ndarray:
    _, z = _zip_names(page)
    return _dark(z.read("target.png"))


def _drawn_pixels(page, selector: str, background=(237, 240, 245)) -> int:
    png = page.locator(selector).screenshot()
    img = iio.imread(png)[..., :3].astype(int)
    return int((np.abs(img - np.array(background)).sum(-1) > 40).sum())


def test_the_page_says_the_hosts_time_limit(page):
    assert f"This app ends each fit after {APP_TIME_LIMIT_S} s." in page.locator("#intro").inner_text()


def test_upload_fit_and_download(page, tmp_path):
    from handshadow.examples import target_path

    shutil.copy(target_path("bird"), tmp_path / "bird.png")
    _upload(page, tmp_path / "bird.png")
    _options(page, "2")
    seconds = _wait_result(page)
    names, _ = _zip_names(page)
    assert RESULT_FILES <= names
    time.sleep(4)  # let the 3D viewer load and draw
    canvas_pixels = _drawn_pixels(page, "#model3d canvas")
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "app-after-fit.png"), full_page=True)
    assert canvas_pixels > 2000, "the 3D view drew nothing"
    assert "IoU" in page.locator("#status").inner_text()
    print(f"upload -> result in {seconds:.1f} s")


def test_drawing_reaches_the_fit(page):
    _choose(page, "source", "Draw")
    pad = page.locator("#sketchpad")
    pad.get_by_role("button", name="Brush").first.click()
    time.sleep(0.5)
    box = pad.locator("canvas").first.bounding_box()
    # A fat blob left of and above the middle: parallel strokes, drawn at a human pace (the
    # canvas drops strokes fed faster than it renders).
    for k in range(6):
        y = box["y"] + box["height"] * (0.25 + 0.03 * k)
        page.mouse.move(box["x"] + box["width"] * 0.3, y)
        time.sleep(0.15)
        page.mouse.down()
        time.sleep(0.15)
        for step in range(1, 16):
            page.mouse.move(box["x"] + box["width"] * (0.3 + 0.01 * step), y)
            time.sleep(0.03)
        page.mouse.up()
        time.sleep(0.15)
    _options(page, "1")
    _wait_result(page)
    target = _zip_target(page)
    h, w = target.shape
    assert target.sum() > 50
    ys, xs = np.nonzero(target)
    assert xs.mean() < 0.5 * w and ys.mean() < 0.5 * h  # where it was drawn


def test_oversized_upload_is_refused_in_the_page(page, tmp_path):
    rng = np.random.default_rng(0)
    big = tmp_path / "huge.png"
    iio.imwrite(big, rng.integers(0, 255, (1800, 1800, 4), dtype=np.uint8))
    assert big.stat().st_size > 9_000_000
    _choose(page, "source", "Upload")
    page.locator("#upload input[type=file]").set_input_files(str(big))
    page.wait_for_function("() => /exceed|too large|size/i.test(document.body.innerText)", timeout=20000)
    assert page.locator("#zip a[href]").count() == 0


# -- Every image the command line reads, through the upload (issue 18) ---------------------


def _blob(h: int = 150, w: int = 200, kind: str = "bird") -> np.ndarray:
    """A test shape, (h, w) bool: 'bird' (a body, a neck and a beak) or 'cross' (a plus)."""
    yy, xx = np.mgrid[:h, :w]
    if kind == "cross":
        return ((abs(yy - 0.5 * h) < 0.1 * h) & (abs(xx - 0.5 * w) < 0.35 * w)) | (
            (abs(xx - 0.5 * w) < 0.08 * w) & (abs(yy - 0.5 * h) < 0.4 * h)
        )
    body = ((yy - 0.6 * h) / (0.22 * h)) ** 2 + ((xx - 0.45 * w) / (0.3 * w)) ** 2 <= 1
    neck = (abs(xx - 0.7 * w) < 0.05 * w) & (yy > 0.25 * h) & (yy < 0.6 * h)
    head = ((yy - 0.25 * h) / (0.08 * h)) ** 2 + ((xx - 0.72 * w) / (0.08 * w)) ** 2 <= 1
    beak = (yy > 0.22 * h) & (yy < 0.27 * h) & (xx > 0.72 * w) & (xx < 0.9 * w)
    return body | neck | head | beak


def _write(path: Path, kind: str) -> np.ndarray:
    """Write the test shape in one of the formats; returns the shape as the file shows it."""
    shape = _blob()
    dark, light = np.uint8(25), np.uint8(235)
    if kind == "transparent.png":  # one ink colour everywhere: only alpha tells the shape
        rgba = np.zeros(shape.shape + (4,), np.uint8)
        rgba[..., :3] = (40, 40, 40)
        rgba[..., 3] = np.where(shape, 255, 0)
        Image.fromarray(rgba).save(path)
    elif kind == "grey16.png":
        Image.fromarray(np.where(shape, 3000, 62000).astype(np.uint16)).save(path)
    elif kind == "cmyk.jpg":
        Image.fromarray(np.where(shape[..., None], dark, light).repeat(3, 2)).convert("CMYK").save(path, quality=92)
    elif kind == "animated.gif":  # the first frame counts
        frames = [Image.fromarray(np.where(m, dark, light)).convert("P") for m in (shape, np.roll(shape, 40, 1))]
        frames[0].save(path, save_all=True, append_images=frames[1:], duration=300, loop=0)
    elif kind == "light-on-dark.gif":  # issue 18's MPEG-7 GIF: a white shape on black, touching the top edge
        shape[:40, 136:146] = True
        Image.fromarray(np.where(shape, 255, 0).astype(np.uint8)).convert("P").save(path)
        assert path.read_bytes()[:6] == b"GIF87a"
    elif kind == "palette.png":
        rgb = np.where(shape[..., None], np.array([30, 40, 120], np.uint8), np.array([250, 235, 200], np.uint8))
        Image.fromarray(rgb).convert("P", palette=Image.Palette.ADAPTIVE, colors=4).save(path)
    return shape


FORMATS = ["transparent.png", "grey16.png", "cmyk.jpg", "animated.gif", "light-on-dark.gif", "palette.png"]
FITTED = {"cmyk.jpg", "light-on-dark.gif"}  # these go on through a fit; every format is read by the same code


@pytest.mark.parametrize("kind", FORMATS)
def test_every_format_is_read_from_the_upload_itself(page, tmp_path, kind):
    shape = _write(tmp_path / f"shape-{kind}", kind)
    _options(page, "1")  # and a 64-pixel frame, before the upload: the reading shown is at that size
    _upload(page, tmp_path / f"shape-{kind}")
    assert "Press Fit" in page.locator("#status").inner_text()
    read = _reading(page)
    assert read.shape == (64, 64), f"the reading is not at the chosen size: {read.shape}"
    assert _cropped_iou(shape, read) >= 0.9, "the reading shown is not the upload's shape"
    if kind in FITTED:
        _wait_result(page)
        target = _zip_target(page)
        assert np.array_equal(target, read)  # the fit read what the page showed
        assert _cropped_iou(shape, target) >= 0.9


def test_an_image_with_no_shape_says_so_in_the_status_line(page, tmp_path):
    iio.imwrite(tmp_path / "blank.png", np.full((80, 120), 240, np.uint8))
    _upload(page, tmp_path / "blank.png")
    status = page.locator("#status").inner_text()
    assert "no shape found" in status and "blank.png" in status and "/tmp" not in status
    page.click("#fit")
    page.wait_for_function("() => /no shape found/.test(document.querySelector('#status').innerText)")
    time.sleep(3)  # it stays: no toast that fades, no result
    assert "no shape found" in page.locator("#status").inner_text()
    assert page.locator("#zip a[href]").count() == 0


def test_two_visitors_at_once_each_get_their_own_result(browser, app_url, tmp_path):
    pages, shapes = [], {}
    for kind in ("bird", "cross"):
        context = browser.new_context(viewport={"width": 1400, "height": 1500})
        pg = context.new_page()
        _open(pg, app_url)
        shapes[kind] = _blob(kind=kind)
        iio.imwrite(tmp_path / f"{kind}.png", np.where(shapes[kind], 0, 255).astype(np.uint8))
        _options(pg, "1")
        _upload(pg, tmp_path / f"{kind}.png")
        pages.append((kind, pg))
    for _, pg in pages:
        pg.click("#fit")  # both at once: the second waits in line for the first
    for kind, pg in pages:
        pg.wait_for_selector("#zip a[href]", timeout=150_000)
        other = shapes["cross" if kind == "bird" else "bird"]
        target = _zip_target(pg)
        assert _cropped_iou(shapes[kind], target) >= 0.9 and _cropped_iou(other, target) < 0.7
        assert "IoU" in pg.locator("#status").inner_text()
        # The last picture in the preview is this visitor's own overlay: its target is this target.
        overlay = iio.imread(_fetch(pg, pg.locator("#preview img").get_attribute("src")))[..., :3].astype(int)
        overlay = _shrunk(overlay, 64)
        in_target = (np.abs(overlay - BOTH).sum(-1) < 30) | (np.abs(overlay - MISSING).sum(-1) < 30)
        assert np.array_equal(in_target, target)
    for _, pg in pages:
        pg.context.close()


# -- Cancel and the Morph tab (issue 12: untested until now) --------------------------------


def test_cancel_keeps_the_best_result_so_far(page):
    _options(page, "1", quality="best")  # long enough to be cancelled: minutes uncancelled
    page.click("#fit")
    searching = "() => /Fitting\\.\\.\\. IoU/.test(document.querySelector('#status').innerText)"
    page.wait_for_function(searching, timeout=60_000)
    t0 = time.time()
    page.click("#cancel")
    page.wait_for_selector("#zip a[href]", timeout=90_000)
    seconds = time.time() - t0
    status = page.locator("#status").inner_text()
    assert status.startswith("Cancelled: best result so far"), status
    names, _ = _zip_names(page)
    assert RESULT_FILES <= names
    print(f"cancel -> complete result in {seconds:.1f} s")
    assert seconds < 60


def test_morph_tab_makes_a_performance(page):
    import json

    page.get_by_role("tab", name="Morph").click()
    frames = page.locator("#frames input[type=number]")
    _choose(page, "morph-hands", "1")
    _choose(page, "morph-size", "64")
    _choose(page, "morph-quality", "fast")  # the page's default fits each end for minutes here
    # The tab's fields mount when it is first shown; a value typed before its default settles
    # was once overwritten (a morph of the default 30 frames). Type it last and see it held.
    for _ in range(10):
        frames.fill("8")
        frames.press("Enter")
        page.wait_for_timeout(200)
        if frames.input_value() == "8":
            break
    page.click("#morph")
    page.wait_for_selector("#morph-zip a[href]", timeout=240_000)
    names, z = _zip_names(page, "#morph-zip")
    assert {"animation.gif", "animation.mp4", "poses.json", "path.png", "target_a.png", "target_b.png"} <= names
    assert len(json.loads(z.read("poses.json"))["frames"]) == 8
    assert "SUMMARY" in page.locator("#morph-status").inner_text()
    assert page.locator("#video video").count() == 1
