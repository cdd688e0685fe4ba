"""The web app in a real browser: Debian's Chromium driven by Playwright (never `playwright
install`). The app runs as `handshadow app` on 127.0.0.1; the browser may reach nothing else."""

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
        [sys.executable, "-m", "handshadow.cli", "app", "--port", str(port)],
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
    pg.goto(app_url)
    pg.wait_for_selector("#fit")
    yield pg
    hosts = {u.split("/")[2] for u in pg.requests if u.startswith("http")}
    assert hosts <= {app_url.split("/")[2]}, f"the page reached beyond localhost: {hosts}"
    context.close()


def _choose(page, group_id: str, label: str) -> None:
    page.locator(f"#{group_id}").get_by_label(label, exact=True).check()


def _options(page, hands: str) -> None:
    page.get_by_text("Options").click()
    page.get_by_label(hands, exact=True).first.check()


def _wait_result(page, timeout_s: float = 150) -> float:
    t0 = time.time()
    page.click("#fit")
    page.wait_for_selector("#zip a[href]", timeout=timeout_s * 1000)
    return time.time() - t0


def _zip_names(page) -> tuple[set[str], zipfile.ZipFile]:
    href = page.locator("#zip a[href]").first.get_attribute("href")
    data = urllib.request.urlopen(
        href if href.startswith("http") else page.url.rstrip("/") + "/" + href.lstrip("/"), timeout=30
    ).read()
    z = zipfile.ZipFile(io.BytesIO(data))
    return set(z.namelist()), z


def _drawn_pixels(page, selector: str, background=(237, 240, 245)) -> int:
    png = page.locator(selector).screenshot()
    img = iio.imread(png)[..., :3].astype(int)
    return int((np.abs(img - np.array(background)).sum(-1) > 40).sum())


def test_upload_fit_and_download(page, tmp_path):
    from handshadow.examples import target_path

    shutil.copy(target_path("bird"), tmp_path / "bird.png")
    _choose(page, "source", "Upload")
    page.locator("#upload input[type=file]").set_input_files(str(tmp_path / "bird.png"))
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
    names, z = _zip_names(page)
    target = iio.imread(z.read("target.png")) < 128  # black shape on white
    h, w = target.shape
    assert target.sum() > 200
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
