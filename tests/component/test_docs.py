"""The documentation site (docs/, Sphinx + MyST) builds without a warning, its generated references
hold what the code declares, the README is a landing page whose links resolve, and every command
line the pages show is one the CLI accepts (the ones that print something shown, run)."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys

import pytest

from tests.conftest import ROOT
from zswarm.cli import build_parser
from zswarm.transport import procutil

DOCS = ROOT / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts and p.name != "scenario-tables.md")
# Commands of a family that is not installed here (the tutorial's, which tests/component/test_own_family.py runs).
OTHER_COMMANDS = {"spin-info"}


def _commands(path):
    """Each ``zswarm ...`` command line in the code blocks of a page: continuation lines joined,
    comments and a ``$`` prompt removed."""
    out = []
    for m in re.finditer(r"```(\w*)\n(.*?)```", path.read_text(), re.S):
        for line in m.group(2).replace("\\\n", " ").splitlines():
            line = line.strip().removeprefix("$ ")
            if line.startswith("zswarm "):
                out.append(re.split(r"\s+#", line, maxsplit=1)[0].strip())
    return out


def test_the_site_builds_without_a_warning(tmp_path):
    """``make docs``' build: any warning (a broken internal link, a missing image, markup that does
    not parse) fails it."""
    p = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(tmp_path / "html")], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    cli = (tmp_path / "html" / "reference" / "cli.html").read_text()
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    for name, parser in sub.choices.items():  # every command and each of its options, from the parser itself
        assert f"<h3>{name}<" in cli, name
        for action in parser._actions:
            for flag in action.option_strings:
                assert flag in cli, (name, flag)
    scenario = (tmp_path / "html" / "reference" / "scenario.html").read_text()
    from zswarm.scenario.clock import ClockSpec
    from zswarm.scenario.links import LinksTable
    from zswarm.scenario.world_config import NoiseTable, WorldTable

    for table in (LinksTable, NoiseTable, WorldTable, ClockSpec):
        for field in table.__struct_fields__:
            assert f"<code class=\"docutils literal notranslate\"><span class=\"pre\">{field}</span></code>" in scenario, (table, field)
    assert "must be a probability" not in scenario and "a probability in [0, 1]" in scenario  # the bound, worded for a reader


def test_the_readme_is_a_landing_page_whose_links_resolve():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    assert text.index("make demo") < text.index("## ")  # the two commands first
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not target.startswith(("http://", "https://")):
            assert (ROOT / target).exists(), target


@pytest.mark.parametrize("page", [ROOT / "README.md", *PAGES], ids=lambda p: str(p.relative_to(ROOT)))
def test_every_documented_command_line_is_one_the_cli_accepts(page):
    """Each parses as written; a scenario it names that ships with zswarm loads with its --set and
    --fault (what the command checks before anything runs)."""
    parser = build_parser()
    for line in _commands(page):
        argv = shlex.split(line)[1:]
        if argv[0] in OTHER_COMMANDS:
            continue
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"{page.name}: {line!r} does not parse (exit {exc.code})")
        topology = getattr(args, "topology", None)
        if topology is not None and (ROOT / topology).exists() and hasattr(args, "overrides"):
            args.topology = str(ROOT / topology)
            procutil.load_args(args)


def test_the_quickstarts_design_hybrid_prints_what_the_page_shows():
    text = (DOCS / "quickstart.md").read_text()
    block = re.search(r"```\n\$ (zswarm design-hybrid [^\n]*)\n(.*?)```", text, re.S)
    assert block is not None
    p = subprocess.run([sys.executable, "-m", "zswarm", *shlex.split(block.group(1))[1:]], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines() == block.group(2).strip().splitlines()
