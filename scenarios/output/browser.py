"""A run's report checked in a real browser: headless Chromium loads it and says whether every
image decoded; it can also take a screenshot of the page.

    python -m scenarios.output.browser RUN_DIR [--screenshot PNG]

Chromium comes from Debian's packages (``apt-get install -y chromium``); it runs with a fresh
profile and no network services, so nothing outside the page is read or sent.
"""

from __future__ import annotations

import argparse
import html
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from scenarios.errors import RunError

#: Headless, sandbox-free (containers), no GPU, and none of the browser's own network traffic.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--hide-scrollbars")
CHROMIUM_NAMES = ("chromium", "chromium-browser")
#: Seconds of page time the browser grants scripts before it dumps the page.
VIRTUAL_TIME_BUDGET_MS = 5000
TIMEOUT_S = 120

#: Appended to a copy of the page: after load, one record per image (decoded or not).
_IMAGE_CHECK = """<script>window.addEventListener("load", () => {
  const out = [...document.images].map(i => ({alt: i.alt, ok: i.complete && i.naturalWidth > 0,
                                              width: i.naturalWidth, height: i.naturalHeight}));
  const pre = document.createElement("pre"); pre.id = "image-check"; pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});</script>"""


def find_chromium() -> str:
    """The Chromium executable; RunError saying how to install it when there is none."""
    for name in CHROMIUM_NAMES:
        path = shutil.which(name)
        if path:
            return path
    raise RunError("no Chromium found (looked for " + ", ".join(CHROMIUM_NAMES) + "); on Debian: "
                   "apt-get install -y chromium")


def _chromium(*args: str) -> str:
    with tempfile.TemporaryDirectory(prefix="grindtwin-chromium-") as profile:
        cmd = [find_chromium(), *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args]
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise RunError(f"Chromium did not finish within {TIMEOUT_S} s: {' '.join(cmd)}") from None
    if res.returncode != 0:
        raise RunError(f"Chromium failed (exit {res.returncode}): {res.stderr.strip()[-500:]}")
    return res.stdout


def image_check(html_path: Path) -> list[dict]:
    """Load a copy of the page with a check appended; one record per image: ``alt``, ``ok``
    (decoded), ``width`` and ``height`` [px]."""
    text = Path(html_path).read_text(encoding="utf-8")
    if "</body>" not in text:
        raise RunError(f"{html_path}: not an HTML page with a body")
    with tempfile.TemporaryDirectory(prefix="grindtwin-page-") as tmp:
        page = Path(tmp) / "page.html"
        page.write_text(text.replace("</body>", _IMAGE_CHECK + "</body>"), encoding="utf-8")
        dom = _chromium(f"--virtual-time-budget={VIRTUAL_TIME_BUDGET_MS}", "--dump-dom", page.as_uri())
    found = re.search(r'<pre id="image-check">(.*?)</pre>', dom, re.S)
    if not found:
        raise RunError(f"{html_path}: the browser's page has no image check (did the page load?)")
    return json.loads(html.unescape(found.group(1)))


def screenshot(html_path: Path, png: Path, width_px: int = 1000, height_px: int = 1400) -> Path:
    """A screenshot of the top ``height_px`` of the page at ``width_px`` wide."""
    png = Path(png).resolve()
    _chromium(f"--window-size={width_px},{height_px}", f"--screenshot={png}", Path(html_path).resolve().as_uri())
    if not png.is_file():
        raise RunError(f"Chromium wrote no screenshot {png}")
    return png


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m scenarios.output.browser", description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir", help="a run folder with report.html (grindtwin report RUN_DIR)")
    p.add_argument("--screenshot", help="also save a screenshot of the page's top here (PNG)")
    args = p.parse_args(argv)
    page = Path(args.run_dir) / "report.html"
    images = image_check(page)
    bad = [i["alt"] for i in images if not i["ok"]]
    print(f"{page}: {len(images) - len(bad)} of {len(images)} images decoded" + (": broken " + "; ".join(bad) if bad else ""))
    if args.screenshot:
        print(screenshot(page, Path(args.screenshot)))
    return 1 if bad or not images else 0


if __name__ == "__main__":
    sys.exit(main())
