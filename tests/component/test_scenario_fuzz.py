"""The scenario loader under Hypothesis (issue 14): any document — a shipped scenario with
fields replaced by arbitrary TOML values, tables dropped or added, or arbitrary text —
either loads or raises ScenarioError with one ``file: field: problem`` line, never
anything else; and the CLI turns that into exit 2 with that line."""

from __future__ import annotations

import re
import subprocess
import sys
import time
import tomllib

import pytest
import tomli_w
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tests.conftest import ROOT, TOPO, examples
from zswarm.scenario import ScenarioError, loads

BASES = {p.name: tomllib.loads(p.read_text()) for p in sorted(TOPO.glob("*.toml")) if "noisy" not in p.name}
PATH = "fuzz.toml"
LINE = re.compile(rf"^{re.escape(PATH)}: \S.*: .+$")  # file: field: problem, one line
# The loader evaluates each time-varying motion on a 1 ms grid over the run (at most 10⁶
# points, scenario._check_finite_over_run): a few seconds on this machine at worst; a
# document that took longer would be a hang, not a slow load.
SLOW_S = 30.0

scalars = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=30),
    st.sampled_from(["t", "sin(t)", "1/(1-t)", "(t-1)**0.5", "2**2**2**2**2", "(" * 100 + "1" + ")" * 100, "pi", "exp(1e3*t)"]),
)
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4), max_leaves=12)


def _paths(doc, prefix=()):
    """Every (path) to a value of the document, tables and arrays included."""
    out = [prefix] if prefix else []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += _paths(v, (*prefix, i))
    return out


def _set(doc, path, value):
    node = doc
    for k in path[:-1]:
        node = node[k]
    if value is _DROP:
        del node[path[-1]]
    else:
        node[path[-1]] = value


_DROP = object()


def _check(text: str) -> None:
    t0 = time.monotonic()
    try:
        loads(text, PATH)
    except ScenarioError as exc:
        msg = str(exc)
        # One line: no character a terminal or str.splitlines() would act on (\n, \x1b, \u2028, ...).
        assert msg.isprintable() and LINE.match(msg), repr(msg)
    assert time.monotonic() - t0 < SLOW_S


# A mutation: (which path, by its index modulo the paths there are then; the new value).
mutations = st.lists(st.tuples(st.integers(0, 10_000), st.one_of(values, st.just(_DROP))), min_size=1, max_size=3)


@settings(max_examples=examples(300), deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.sampled_from(sorted(BASES)), mutations)
# Found by a random run on 2026-12-03 (issue 34): the [scenario] table replaced by one
# whose key is a newline (path 0 is ("scenario",)); its error came out on two lines.
@example("thesis-3.2-fixed8.toml", [(0, {"\n": 0})])
@example("thesis-3.2-fixed8.toml", [(0, {"a\tb\x1b[2J": 0})])
def test_a_mutated_scenario_loads_or_names_one_field(name, changes):
    import copy

    doc = copy.deepcopy(BASES[name])
    for index, value in changes:
        paths = _paths(doc)
        if not paths:
            break
        try:
            _set(doc, paths[index % len(paths)], value)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier change removed or replaced its parent
    try:
        text = tomli_w.dumps(doc)
    except (TypeError, ValueError):
        return  # not expressible in TOML (a NaN key, a bare None): no file can hold it
    _check(text)


@settings(max_examples=examples(300), deadline=None)
@given(st.text(max_size=300))
def test_arbitrary_text_loads_or_names_one_field(text):
    _check(text)


@pytest.mark.parametrize("text", ["[scenario]\nname = 1\n", "not toml at all [[[", "[scenario]\nname='x'\nduration=1e400\n"])
def test_the_cli_exits_2_with_that_line(tmp_path, text):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    r = subprocess.run([sys.executable, "-m", "zswarm", "sim", str(f), "--out", str(tmp_path / "o")], cwd=ROOT, capture_output=True, text=True, check=False)
    assert r.returncode == 2 and r.stderr.strip().startswith(f"error: {f}: "), r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
