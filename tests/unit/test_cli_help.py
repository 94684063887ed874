"""Issue 48 (a CLI that explains itself), first part: ``zswarm --version``, and on every
subcommand's ``--help`` a description, examples that are valid command lines, and its exit codes.
Read from the parser itself, so that no command (a family's own ones too) is forgotten."""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
from importlib.metadata import version

import pytest

from tests.conftest import ROOT
from zswarm.cli import build_parser
from zswarm.transport import procutil


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    p = build_parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _examples(parser: argparse.ArgumentParser) -> list[str]:
    text = parser.epilog or ""
    block = text.split("examples:\n", 1)[1].split("\n\n", 1)[0]
    return [line.strip() for line in block.splitlines() if line.strip()]


def test_version_prints_the_installed_version_and_exits_0():
    r = subprocess.run([sys.executable, "-m", "zswarm", "--version"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == f"zswarm {version('zswarm')}"


def test_every_subcommand_says_what_it_does_how_to_call_it_and_its_exit_codes():
    cmds = _subcommands()
    assert {"run", "sim", "sweep", "basin", "router", "record", "replay", "view", "report", "generate", "certs", "compose", "design-hybrid"} <= set(cmds)
    for name, p in cmds.items():
        assert p.description and len(p.description) > 60, name
        help_text = p.format_help()
        assert "examples:\n" in help_text and "exit codes:\n" in help_text, name
        for code in ("0", "1", "2", "130"):
            assert f"\n  {code} " in help_text.split("exit codes:", 1)[1], (name, code)
        assert _examples(p) and all(e.startswith(f"zswarm {name}") for e in _examples(p)), name


@pytest.mark.parametrize("name", sorted(_subcommands()))
def test_every_example_is_a_valid_command_line(name):
    """Each example parses as it is written; a scenario it names exists and loads with its
    --set and --fault (what the command checks before anything runs)."""
    parser = build_parser()
    for example in _examples(_subcommands()[name]):
        argv = shlex.split(example)[1:]
        args = parser.parse_args(argv)
        topology = getattr(args, "topology", None)
        if topology is not None:
            assert (ROOT / topology).exists(), example
            if hasattr(args, "overrides"):
                args.topology = str(ROOT / topology)
                procutil.load_args(args)


def test_the_cheap_examples_run(tmp_path):
    """The examples that write nothing big run for real and exit 0."""
    for name in ("generate", "design-hybrid"):
        for example in _examples(_subcommands()[name]):
            r = subprocess.run([sys.executable, "-m", "zswarm", *shlex.split(example)[1:]], capture_output=True, text=True, timeout=120, cwd=tmp_path)
            assert r.returncode == 0, (example, r.stderr[-500:])
