"""Screenshots of the built book in headless Chromium: proof that its pages render.

Usage (after ``book/build.sh``)::

    python book/screenshot.py [--page book/intro.html --page notebooks/01_frenet_kinematics.html]

Saves one PNG per page to ``book/_build/screenshots/`` (CI keeps them as artifacts) and fails when
Chromium is missing, a page is missing, or a screenshot is not written or is (nearly) blank.
Chromium runs with a fresh profile and without background networking, sync or updates, so it
touches nothing outside a temporary directory.

Mathematics: the book loads MathJax from a CDN, which a sandboxed CI machine cannot reach. When
Debian's ``libjs-mathjax`` is installed (``apt-get install libjs-mathjax``), the page is shot from a
temporary copy that loads that local MathJax instead (``--cdn`` keeps the page as built), so the
screenshot shows typeset equations rather than raw TeX. The built book itself is not changed.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import zlib
from pathlib import Path

BOOK = Path(__file__).resolve().parent
HTML = BOOK / "_build" / "html"
OUT = BOOK / "_build" / "screenshots"
#: The front page and one chapter page.
DEFAULT_PAGES = ("book/intro.html", "notebooks/01_frenet_kinematics.html")
WINDOW = (1280, 1600)  # [px] width, height
#: Debian's MathJax 2 (package libjs-mathjax), used for offline screenshots.
LOCAL_MATHJAX = Path("/usr/share/javascript/mathjax/MathJax.js")
_CDN_SCRIPT = re.compile(
    r'<script[^>]*src="https://cdn\.jsdelivr\.net/npm/mathjax@3[^"]*"[^>]*></script>'
)
_MATHJAX3_CONFIG = re.compile(r"<script>window\.MathJax = .*?</script>", re.S)
_MATHJAX2 = (
    '<script type="text/x-mathjax-config">MathJax.Hub.Config({tex2jax: {inlineMath: '
    "[['\\\\(', '\\\\)']], displayMath: [['\\\\[', '\\\\]']], processEscapes: true, "
    # MyST marks the page tex2jax_ignore and lists the classes to typeset (MathJax 3 style)
    "processClass: 'tex2jax_process|mathjax_process|math|output_area'}});</script>"
    '<script src="{src}?config=TeX-AMS-MML_HTMLorMML"></script>'
)


def find_chromium() -> str | None:
    """Path of a Chromium executable (Debian's ``chromium`` or another common name), or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return None


def _png_stats(path: Path) -> tuple[int, int, int]:
    """(width, height, number of distinct grey levels in a sample) of an 8-bit RGB(A) PNG.

    Enough of a PNG decoder to tell a rendered page from a blank one without extra packages.
    """
    data = path.read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path} is not a PNG file")
    pos, idat, header = 8, b"", None
    while pos < len(data):
        length = int.from_bytes(data[pos : pos + 4], "big")
        kind = data[pos + 4 : pos + 8]
        chunk = data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            header = chunk
        elif kind == b"IDAT":
            idat += chunk
        pos += 12 + length
    width, height = int.from_bytes(header[0:4], "big"), int.from_bytes(header[4:8], "big")
    depth, colour = header[8], header[9]
    channels = {2: 3, 6: 4}.get(colour)
    if depth != 8 or channels is None:
        return width, height, -1  # another format: do not judge the content
    raw = zlib.decompress(idat)
    stride = width * channels
    levels: set[int] = set()
    prev = bytearray(stride)
    # Undo the PNG row filters on every row; sample the middle pixel column band of each row.
    for row in range(height):
        start = row * (stride + 1)
        ftype = raw[start]
        line = bytearray(raw[start + 1 : start + 1 + stride])
        for i in range(stride):
            left = line[i - channels] if i >= channels else 0
            up = prev[i]
            ul = prev[i - channels] if i >= channels else 0
            if ftype == 1:
                line[i] = (line[i] + left) & 0xFF
            elif ftype == 2:
                line[i] = (line[i] + up) & 0xFF
            elif ftype == 3:
                line[i] = (line[i] + (left + up) // 2) & 0xFF
            elif ftype == 4:
                p = left + up - ul
                pa, pb, pc = abs(p - left), abs(p - up), abs(p - ul)
                pred = left if pa <= pb and pa <= pc else (up if pb <= pc else ul)
                line[i] = (line[i] + pred) & 0xFF
        prev = line
        if row % 16 == 0:
            for x in range(0, width, 16):
                r, g, b = line[x * channels : x * channels + 3]
                levels.add((r + g + b) // 3)
    return width, height, len(levels)


def offline_copy(page: Path) -> Path | None:
    """A copy of ``page`` beside it that loads the local MathJax 2 instead of the CDN's MathJax 3.

    None when there is no local MathJax or the page loads no MathJax.
    """
    if not LOCAL_MATHJAX.exists():
        return None
    html = page.read_text(encoding="utf-8")
    if not _CDN_SCRIPT.search(html):
        return None
    html = _MATHJAX3_CONFIG.sub("", html)
    html = _CDN_SCRIPT.sub(lambda _: _MATHJAX2.replace("{src}", LOCAL_MATHJAX.as_uri()), html)
    copy = page.with_name(page.stem + ".offline-screenshot.html")
    copy.write_text(html, encoding="utf-8")
    return copy


def screenshot(chromium: str, page: Path, png: Path) -> None:
    """Render ``page`` (an HTML file) to ``png`` with headless Chromium."""
    with tempfile.TemporaryDirectory(prefix="racing-lab-chromium-") as profile:
        cmd = [
            chromium,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--hide-scrollbars",
            f"--user-data-dir={profile}",
            f"--window-size={WINDOW[0]},{WINDOW[1]}",
            "--virtual-time-budget=5000",  # let MathJax and the theme's scripts finish
            f"--screenshot={png}",
            page.as_uri(),
        ]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    if proc.returncode != 0 or not png.exists():
        raise RuntimeError(
            f"chromium could not screenshot {page} (exit {proc.returncode}):\n{proc.stderr[-2000:]}"
        )


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--page",
        action="append",
        help="page to shoot, relative to book/_build/html (repeatable; default: front page and "
        "chapter 01)",
    )
    parser.add_argument(
        "--cdn", action="store_true", help="do not substitute a local MathJax for the CDN's"
    )
    args = parser.parse_args(argv)
    pages = args.page or list(DEFAULT_PAGES)
    chromium = find_chromium()
    if chromium is None:
        print(
            "screenshot: no chromium found; install it (apt-get install chromium)", file=sys.stderr
        )
        return 2
    OUT.mkdir(parents=True, exist_ok=True)
    failed = False
    for rel in pages:
        page = HTML / rel
        if not page.exists():
            print(f"screenshot: {page} does not exist; build the book first", file=sys.stderr)
            failed = True
            continue
        png = OUT / (rel.replace("/", "_").removesuffix(".html") + ".png")
        png.unlink(missing_ok=True)
        copy = None if args.cdn else offline_copy(page)
        try:
            screenshot(chromium, copy or page, png)
        finally:
            if copy is not None:
                copy.unlink(missing_ok=True)
        width, height, levels = _png_stats(png)
        ok = (width, height) == WINDOW and (levels < 0 or levels >= 8)
        print(f"screenshot: {png.relative_to(BOOK.parent)} {width}x{height}, {levels} grey levels")
        if not ok:
            print(f"screenshot: {png.name} looks blank or has the wrong size", file=sys.stderr)
            failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
