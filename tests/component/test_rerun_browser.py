"""Rerun's web viewer in a real browser (issue 32): ``zswarm view RUN --web`` serves a short
run, headless Chromium (Debian's, installed by the test if missing) loads the page, and the
screenshot must show the run: the page is Rerun's viewer, the image is not one colour, and the
3-D view holds the true bodies' blue (the colour zswarm draws them in, shaded by the viewer's
light; the viewer's empty 3-D view and its welcome page have none).

The page is polled every 2 s until the bodies are drawn: SwiftShader renders WebGL on the
CPU, which a busy core slows, so no fixed wait would be both short and safe.  The README's
pictures come from the same path at longer runs (docs/screenshots.py).
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests import browser
from tests.conftest import ROOT, TOPO


@pytest.fixture(scope="module")
def chromium():
    """Debian's chromium, installed if missing (tests/browser.py); the tests skip, saying why,
    only where it cannot be."""
    path, why = browser.install_chromium()
    if path is None:
        pytest.skip(why)
    return path


BLUE = browser.BODIES_DRAWN  # why this share: tests/browser.py


@pytest.mark.parametrize("name, duration", [("thesis-3.2-fixed8", 6.0), ("thesis-5.6-hybrid7", 6.0)])
def test_the_web_viewer_shows_the_run(name, duration, tmp_path, chromium):
    run = tmp_path / "run"
    r = subprocess.run(
        [sys.executable, "-m", "zswarm", "sim", str(TOPO / f"{name}.toml"), "--duration", str(duration), "--out", str(run), "--no-plots", "--quiet"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    png, title, took = browser.view_screenshot(run, ready=lambda p: browser.body_pixels(p)[0] > BLUE)
    blue, std = browser.body_pixels(png)
    assert title == "Rerun Viewer", title
    # Not one colour: a page of one colour (the viewer before it starts drawing) has std 0 on
    # the 0-255 scale; with the run drawn it measured 22-36, so 10 is far from both.
    assert std > 10, std
    assert blue > BLUE, blue  # the bodies are drawn
    print(f"{name}: drawn after {took:.1f} s, blue share {blue:.4f}, std {std:.1f}")
