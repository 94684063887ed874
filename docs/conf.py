"""Sphinx configuration of zswarm's documentation (``make docs``: warnings are errors)."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).parent / "_ext"))

project = "zswarm"
author = "the zswarm authors"
copyright = "2026, the zswarm authors"  # noqa: A001 - Sphinx's name

extensions = [
    "myst_parser",  # the pages are Markdown (MyST)
    "sphinxarg.ext",  # the CLI reference, read from zswarm.cli.build_parser
    "zswarm_reference",  # the scenario reference, read from the typed schema (docs/_ext/zswarm_reference.py)
]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3  # [text](page.md#a-heading) links to headings
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "examples/spin_family/**", "figures/basins/**", "reference/scenario-tables.md"]  # the last: included by reference/scenario.md
smartquotes = False  # "--set" stays two hyphens and 'quotes' stay straight: what a user types
html_theme = "furo"
html_title = "zswarm"
html_static_path: list[str] = []
# Links are checked: a missing page, heading or image is a warning, and make docs fails on warnings.
nitpicky = False
suppress_warnings: list[str] = []
