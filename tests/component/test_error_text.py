"""User text echoed in an error stays on one line (issue 34): every path that quotes what
a user wrote — a key, a value, a file name, a --set/--vary/--fault flag, an unknown
command-line argument — escapes a newline, a tab and a terminal escape (``\\x1b[2J``
clears the screen) instead of printing them."""

from __future__ import annotations

import subprocess
import sys
import tomllib

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tests.conftest import ROOT, TOPO, examples
from zswarm.scenario import ScenarioError, fault_override, load, loads, parse_override
from zswarm.studies import sweep
from zswarm.util import quoting as text

ODD = ["a\nb", "a\tb", "a\x1b[2Jb"]
FIXED8 = TOPO / "thesis-3.2-fixed8.toml"


def _one_line(msg: str) -> None:
    """Printable throughout: no character that a terminal or str.splitlines() acts on."""
    assert msg.isprintable(), repr(msg)
    assert len(msg.splitlines()) == 1, repr(msg)


@settings(max_examples=examples(300))
@given(st.text(max_size=40))
@example("\n")
@example('a"b\\c\x1b[2J\u2028\x85\udc80')
def test_quoted_reads_back_as_the_same_toml_string(s):
    """``quoted`` is a TOML basic string: printable, and tomllib reads it back to ``s``
    (lone surrogates, which no TOML file can hold, only need to stay printable)."""
    q = text.quoted(s)
    _one_line(q)
    if not any(0xD800 <= ord(c) <= 0xDFFF for c in s):
        assert tomllib.loads(f"v = {q}")["v"] == s
    assert text.shown(s) == (s if s.isprintable() else q)
    _one_line(text.one_line(f"x{s}y"))


@pytest.mark.parametrize("odd", ODD)
def test_an_odd_key_is_quoted(fixed8_text, odd):
    doc = fixed8_text.replace("seed = 1\n", f"seed = 1\n{text.quoted(odd)} = 1\n", 1)
    with pytest.raises(ScenarioError) as e:
        loads(doc, "f.toml")
    msg = str(e.value)
    _one_line(msg)
    assert msg.startswith(f"f.toml: scenario.{text.quoted(odd)}: unknown key"), msg


@pytest.mark.parametrize("odd", ODD)
def test_an_odd_value_is_escaped(fixed8_text, odd):
    doc = fixed8_text.replace("seed = 1\n", f"seed = {text.quoted(odd)}\n", 1)
    with pytest.raises(ScenarioError) as e:
        loads(doc, "f.toml")
    _one_line(str(e.value))
    assert str(e.value).startswith("f.toml: scenario.seed: must be an integer"), e.value


@pytest.mark.parametrize("odd", ODD)
def test_an_odd_edge_index_key_is_quoted(odd):
    doc = (TOPO / "thesis-4.5-hybrid5.toml").read_text().replace("xi = { 1 = 0.0 }", f"xi = {{ 1 = 0.0, {text.quoted(odd)} = 1 }}", 1)
    with pytest.raises(ScenarioError) as e:
        loads(doc, "f.toml")
    _one_line(str(e.value))
    assert f"estimate.xi.{text.quoted(odd)}: keys are edge indices" in str(e.value), e.value


@pytest.mark.parametrize("odd", ODD)
def test_an_odd_file_name_is_quoted(tmp_path, odd):
    missing = tmp_path / f"no{odd}such.toml"
    with pytest.raises(ScenarioError) as e:
        load(missing)
    _one_line(str(e.value))
    assert str(e.value).startswith(text.quoted(str(missing)) + ": cannot read file"), e.value
    bad = tmp_path / f"bad{odd}.toml"
    bad.write_text("not toml [[[")
    with pytest.raises(ScenarioError) as e:
        load(bad)
    _one_line(str(e.value))
    assert str(e.value).startswith(text.quoted(str(bad)) + ": TOML syntax"), e.value


@pytest.mark.parametrize("odd", ODD)
def test_odd_overrides_are_escaped(odd):
    q = text.quoted(odd)
    # a value as typed in a shell (the raw character between quotes): the error names the flag as given, escaped
    typed = f'scenario.seed="{odd}"'
    with pytest.raises(ScenarioError) as e:
        load(FIXED8, [parse_override(typed)])
    _one_line(str(e.value))
    assert str(e.value).startswith(f"--set {text.quoted(typed)}: scenario.seed: must be an integer"), e.value
    # a field that does not parse, and a quoted key the table does not have
    for bad in (f"scen{odd}ario.seed=1", f"scenario.{q}=1"):
        with pytest.raises(ScenarioError) as e:
            load(FIXED8, [parse_override(bad)])
        _one_line(str(e.value))
    for call in (lambda: sweep.parse_vary(f"a{odd}b"), lambda: sweep.parse_vary(f"scen{odd}ario.seed=1,2"), lambda: load(FIXED8, [fault_override(f"ki{odd}ll")])):
        with pytest.raises(ScenarioError) as e:
            call()
        _one_line(str(e.value))


def test_the_scenario_as_run_stays_valid_toml_with_an_odd_override():
    """``render`` heads the scenario as run with the overrides in a TOML comment: a newline
    in one would have ended the comment and put the rest of the flag in the document."""
    o = parse_override('scenario.description="line one\nline two"')  # a raw newline, as a shell passes it
    sc = load(FIXED8, [o])
    assert sc.text.splitlines()[0] == f"# {FIXED8}, with {o.label}"  # the whole flag on the comment's line, escaped
    back = loads(sc.text, "scenario.toml")
    assert back.description == sc.description == '"line one\nline two"'  # not TOML, so taken as the string typed


def _cli(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "zswarm", *argv], cwd=ROOT, capture_output=True, text=True, check=False, timeout=120)


def test_the_cli_prints_one_line_for_a_key_a_value_and_a_set(tmp_path, fixed8_text):
    """Issue 34's case as a user meets it: exit 2, exactly one line on stderr."""
    key = tmp_path / "key.toml"
    key.write_text(fixed8_text.replace("seed = 1\n", 'seed = 1\n"a\\nb" = 1\n', 1))
    value = tmp_path / "value.toml"
    value.write_text(fixed8_text.replace("seed = 1\n", 'seed = "a\\nb\\u001b[2J"\n', 1))
    for argv in ((str(key),), (str(value),), (str(FIXED8), "--set", 'scenario.seed="a\nb"'), (str(FIXED8), "--set", "scen\tario.seed=1")):
        r = _cli("sim", *argv, "--out", str(tmp_path / "o"))
        assert r.returncode == 2, r
        assert len(r.stderr.splitlines()) == 1 and r.stderr.startswith("error: "), repr(r.stderr)
        _one_line(r.stderr.rstrip("\n"))


def test_argparse_echoes_an_unknown_argument_escaped():
    r = _cli("sim", str(FIXED8), "x\n\x1b[2Jy")
    assert r.returncode == 2
    last = r.stderr.rstrip("\n").splitlines()[-1]
    assert last == "zswarm: error: unrecognized arguments: x\\n\\u001B[2Jy", repr(r.stderr)
