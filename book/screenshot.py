"""Screenshots of the built book in headless Chromium, and a count of the equations it typeset.

Usage (after ``book/build.sh``)::

    python book/screenshot.py                       # the front page and every chapter
    python book/screenshot.py --page notebooks/01_frenet_kinematics.html --height 6000

Saves one PNG per page to ``book/_build/screenshots/`` (CI keeps them as artifacts). For each page
it also asks Chromium for the page as MathJax left it and counts the typeset equations against
the math elements of the built HTML: a page whose MathJax did not load, or that MathJax could not
parse, typesets fewer. Fails when Chromium is missing, a page is missing, a screenshot is not
written or is (nearly) blank, or an equation was not typeset.

The book serves its own MathJax (``sphinx-mathjax-offline``, copied to ``_static/mathjax``), so
the pages typeset with no network; Chromium runs with a fresh profile and without background
networking, sync or updates, so it touches nothing outside a temporary directory.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

BOOK = Path(__file__).resolve().parent
HTML = BOOK / "_build" / "html"
OUT = BOOK / "_build" / "screenshots"
#: The front page, the notation and exercises pages, and every chapter (notebooks/*.html).
FIXED_PAGES = ("book/intro.html", "book/notation.html", "book/exercises.html")
WINDOW = (1280, 1600)  # [px] width, default height
#: A math element of the built page (display or inline), and one MathJax typeset.
_MATH_ELEMENT = re.compile(r'<(?:div|span) class="math(?: [^"]*)?"')
_TYPESET = re.compile(r"<mjx-container\b")


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


def default_pages() -> list[str]:
    """The front page, the exercises page and every chapter page of the built book."""
    chapters = sorted(p.relative_to(HTML).as_posix() for p in (HTML / "notebooks").glob("*.html"))
    return [*FIXED_PAGES, *chapters]


def _chromium_cmd(chromium: str, profile: str, height: int) -> list[str]:
    return [
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
        f"--window-size={WINDOW[0]},{height}",
        "--virtual-time-budget=8000",  # let MathJax and the theme's scripts finish
    ]


def typeset_count(chromium: str, page: Path) -> tuple[int, int]:
    """(math elements in the built HTML, equations MathJax typeset in Chromium) of a page."""
    want = len(_MATH_ELEMENT.findall(page.read_text(encoding="utf-8")))
    with tempfile.TemporaryDirectory(prefix="racing-lab-chromium-") as profile:
        cmd = [*_chromium_cmd(chromium, profile, WINDOW[1]), "--dump-dom", page.as_uri()]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    if proc.returncode != 0:
        raise RuntimeError(f"chromium could not load {page}:\n{proc.stderr[-2000:]}")
    return want, len(_TYPESET.findall(proc.stdout))


def screenshot(chromium: str, page: Path, png: Path, height: int = WINDOW[1]) -> None:
    """Render ``page`` (an HTML file) to ``png`` with headless Chromium."""
    with tempfile.TemporaryDirectory(prefix="racing-lab-chromium-") as profile:
        cmd = [*_chromium_cmd(chromium, profile, height), f"--screenshot={png}", page.as_uri()]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    if proc.returncode != 0 or not png.exists():
        raise RuntimeError(
            f"chromium could not screenshot {page} (exit {proc.returncode}):\n{proc.stderr[-2000:]}"
        )


def shoot_page(chromium: str, rel: str, height: int) -> tuple[str, list[str]]:
    """Screenshot one page and count its typeset equations: (report line, problems found).

    Parameters
    ----------
    chromium : str
        The browser's executable.
    rel : str
        The page, relative to ``book/_build/html``.
    height : int
        Window height, px.
    """
    page = HTML / rel
    if not page.exists():
        return "", [f"screenshot: {page} does not exist; build the book first"]
    png = OUT / (rel.replace("/", "_").removesuffix(".html") + ".png")
    png.unlink(missing_ok=True)
    screenshot(chromium, page, png, height)
    width, got_height, levels = _png_stats(png)
    want, typeset = typeset_count(chromium, page)
    report = (
        f"screenshot: {png.relative_to(BOOK.parent)} {width}x{got_height}, {levels} grey levels; "
        f"{typeset} of {want} equations typeset"
    )
    problems = []
    if (width, got_height) != (WINDOW[0], height) or 0 <= levels < 8:
        problems.append(f"screenshot: {png.name} looks blank or has the wrong size")
    if typeset < want:
        problems.append(
            f"screenshot: {rel}: MathJax typeset {typeset} of {want} equations (is "
            "_static/mathjax there? does the browser console show a TeX error?)"
        )
    return report, problems


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--page",
        action="append",
        help="page to shoot, relative to book/_build/html (repeatable; default: the front page, "
        "the exercises page and every chapter)",
    )
    parser.add_argument(
        "--height", type=int, default=WINDOW[1], help="window height in px (taller shows more)"
    )
    args = parser.parse_args(argv)
    pages = args.page or default_pages()
    chromium = find_chromium()
    if chromium is None:
        print(
            "screenshot: no chromium found; install it (apt-get install chromium)", file=sys.stderr
        )
        return 2
    OUT.mkdir(parents=True, exist_ok=True)
    # Each page is two Chromium processes; one page per core at a time, reported in page order.
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        results = list(pool.map(lambda rel: shoot_page(chromium, rel, args.height), pages))
    failed = False
    for report, problems in results:
        if report:
            print(report)
        for problem in problems:
            print(problem, file=sys.stderr)
        failed = failed or bool(problems)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
