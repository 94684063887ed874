"""The README's Rerun pictures, by the browser test's path (tests/test_rerun_browser.py):
``zswarm sim`` of a scenario, ``zswarm view --web``, headless Chromium, a screenshot once the
bodies are drawn and the run's data has loaded (SETTLE s more).

    .venv/bin/python docs/screenshots.py [NAME ...]   # writes docs/figures/rerun-*.png
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests import browser  # noqa: E402

RUNS = [("thesis-3.2-fixed8", 40.0), ("thesis-5.6-hybrid7", 150.0)]
SETTLE = 90.0  # s: SwiftShader draws the whole run's series on the CPU


def main() -> int:
    path, why = browser.install_chromium()
    if path is None:
        print(why, file=sys.stderr)
        return 1
    only = set(sys.argv[1:])  # scenario names to redo (default: all)
    for name, duration in RUNS:
        if only and name not in only:
            continue
        with tempfile.TemporaryDirectory() as d:
            run = Path(d) / "run"
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "zswarm",
                    "sim",
                    str(ROOT / "topologies" / f"{name}.toml"),
                    "--duration",
                    str(duration),
                    "--out",
                    str(run),
                    "--no-plots",
                    "--quiet",
                ],
                check=True,
                cwd=ROOT,
            )
            png, title, took = browser.view_screenshot(run, ready=lambda p: browser.body_pixels(p)[0] > browser.BODIES_DRAWN, settle=SETTLE, timeout=600)
        out = ROOT / "docs" / "figures" / f"rerun-{name}.png"
        out.write_bytes(png)
        print(f"{out.relative_to(ROOT)}: {title}, drawn after {took:.1f} s, then {SETTLE:g} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
