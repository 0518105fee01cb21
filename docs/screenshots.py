"""Screenshots of the built documentation site for ``docs/contributing.md`` (``make screenshots``).

Takes the landing page and one API page of ``docs/_build/html`` with headless Chromium and writes them as PNG
files into ``docs/img/``::

    python docs/screenshots.py --browser chromium --site docs/_build/html --out docs/img

Chromium is the system's package (``apt-get install chromium``); the script only drives it.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

#: page of the built site (relative to its root, with an optional #anchor to scroll to) → file name of its screenshot
PAGES = {
    "index.html": "site-landing.png",
    "api/generated/finkensim.world.html": "site-api-world.png",
}
#: browser window, CSS pixels (width, height)
WINDOW = (1280, 900)


def screenshot(browser: str, page: Path, png: Path, window: tuple[int, int] = WINDOW, anchor: str = "") -> None:
    """Write a PNG screenshot of ``page`` (a local HTML file) taken by headless ``browser``.

    Parameters
    ----------
    browser : str
        The Chromium executable (name on PATH or path).
    page : Path
        The HTML file to open.
    png : Path
        Where to write the screenshot.
    window : tuple of int
        Window width and height, CSS pixels.
    anchor : str
        An element id to scroll to (``""``: the top of the page).

    Raises
    ------
    SystemExit
        The page does not exist, or the browser failed (its output is shown).
    """
    if not page.is_file():
        raise SystemExit(f"screenshots: {page} does not exist: build the site first (make docs)")
    with tempfile.TemporaryDirectory() as profile:
        cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
               f"--user-data-dir={profile}", f"--window-size={window[0]},{window[1]}",
               f"--screenshot={png.resolve()}", page.resolve().as_uri() + (f"#{anchor}" if anchor else "")]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    if done.returncode != 0 or not png.is_file():
        raise SystemExit(f"screenshots: {' '.join(cmd)} failed (exit {done.returncode}):\n{done.stderr[-2000:]}")


def main(argv: list[str] | None = None) -> int:
    """Take every screenshot of :data:`PAGES`; the command line of this module."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--browser", default="chromium", help="Chromium executable (default: chromium)")
    p.add_argument("--site", type=Path, default=Path("docs/_build/html"), help="root of the built site")
    p.add_argument("--out", type=Path, default=Path("docs/img"), help="directory of the PNG files")
    args = p.parse_args(argv)
    if shutil.which(args.browser) is None and not Path(args.browser).is_file():
        raise SystemExit(f"screenshots: browser {args.browser!r} not found: apt-get install chromium")
    args.out.mkdir(parents=True, exist_ok=True)
    for target, name in PAGES.items():
        page, _, anchor = target.partition("#")
        screenshot(args.browser, args.site / page, args.out / name, anchor=anchor)
        print(f"screenshots: {args.site / target} -> {args.out / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
