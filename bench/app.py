"""Web-app benchmark: click-to-result time of a fit in a real browser.

    python bench/app.py [--runs 3] [--quality fast] [--size 256] [--example bird]

Starts `handshadow app` on 127.0.0.1, drives Debian's Chromium with Playwright, picks a built-in
example with the page's defaults (hands: auto; quality and detail as asked), presses Fit and
waits for the downloadable result. Prints each run and a last line app_click_to_result_s=<median>.
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import time
import urllib.request

from playwright.sync_api import sync_playwright

from handshadow.app import DEFAULT_QUALITY

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--quality", default="fast")
    parser.add_argument("--size", default="256", choices=["64", "128", "256"], help="the page's Detail option")
    parser.add_argument("--example", default="bird")
    args = parser.parse_args()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "handshadow.cli", "app", "--port", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=os.environ.copy(),
    )
    url = f"http://127.0.0.1:{port}/"
    try:
        for _ in range(240):
            try:
                urllib.request.urlopen(url, timeout=2)
                break
            except OSError:
                time.sleep(0.5)
        times = []
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=FLAGS)
            for run in range(args.runs):
                page = browser.new_page(viewport={"width": 1400, "height": 1500})
                page.goto(url)
                page.wait_for_selector("#fit")
                page.locator("#example input").fill(args.example)
                page.keyboard.press("Enter")
                if args.quality != DEFAULT_QUALITY or args.size != "256":  # not the page's own choice
                    page.get_by_text("Options").click()
                    page.locator("#quality").get_by_label(args.quality, exact=True).check()
                    page.locator("#size").get_by_label(args.size, exact=True).check()
                t0 = time.perf_counter()
                page.click("#fit")
                page.wait_for_selector("#zip a[href]", timeout=600_000)
                times.append(time.perf_counter() - t0)
                print(
                    f"run {run + 1}: {times[-1]:.1f} s ({page.locator('#status').inner_text().splitlines()[0]})",
                    flush=True,
                )
                page.close()
            browser.close()
        print(f"app_click_to_result_s={statistics.median(times):.1f}")
    finally:
        proc.terminate()
        proc.wait(timeout=30)


if __name__ == "__main__":
    main()
