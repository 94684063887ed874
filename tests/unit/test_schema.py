"""The typed scenario schema (zswarm.scenario.schema): what msgspec accepts and what the translator says
are one declaration.  tests/component/test_golden_errors.py checks the words against the old
hand-written loader's; here, that the msgspec bounds and the worded bounds agree on every value."""

from __future__ import annotations

import math
import typing

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from zswarm.scenario import Header, ScenarioFile
from zswarm.scenario.algorithm import StalePolicy
from zswarm.scenario.clock import ClockSpec
from zswarm.scenario.links import LinksTable, LinkTable
from zswarm.scenario.reading import ScenarioError, _Ctx
from zswarm.scenario.schema import Bounds, _unwrap, bounds
from zswarm.scenario.world_config import CommandPolicy, NoiseTable, WorldTable

TABLES = (ClockSpec, LinkTable, LinksTable, CommandPolicy, NoiseTable, WorldTable, StalePolicy, Header)
BOUNDED = [
    (t, name, hint)
    for t in TABLES
    for name, hint in typing.get_type_hints(t, include_extras=True).items()
    if _unwrap(hint)[1] is not None
]
VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**12), 10**12),
    st.sampled_from([0, 0.0, -0.0, 1e-6, 1e-9, 0.001, 0.0010000001, 1, 1e4, 1e4 + 1e-9, 1e5, -1e5, 1e10, 1e22, 1.1e22, True, "1", None]),
)


def test_every_number_field_declares_bounds():
    """Each float field of a table is bounded (finite at least): no float field escapes the schema."""
    floats = [(t.__name__, n) for t in TABLES for n, h in typing.get_type_hints(t, include_extras=True).items() if _unwrap(h)[0] is float]
    assert floats and {(t.__name__, n) for t, n, _ in BOUNDED} == set(floats)


@pytest.mark.parametrize(("table", "name", "hint"), BOUNDED, ids=[f"{t.__name__}.{n}" for t, n, _ in BOUNDED])
@given(v=VALUES)
def test_msgspec_accepts_what_the_words_accept(table, name, hint, v):
    """msgspec's check (the Meta built from the bounds) and the translator's wording
    (Bounds.problem) accept exactly the same values."""
    b = _unwrap(hint)[1]
    try:
        msgspec.convert(v, hint, strict=True)
        accepted = True
    except msgspec.ValidationError:
        accepted = False
    assert accepted == (b.problem(v) is None), (v, b.problem(v))


def test_translated_errors_name_file_field_and_problem():
    c = _Ctx("s.toml")
    with pytest.raises(ScenarioError, match=r"^s\.toml: clock\.rate: must be <= 10000 \(got 20000\)$"):
        c.typed({"rate": 20000}, "clock", ClockSpec)
    with pytest.raises(ScenarioError, match=r"^s\.toml: links\.sensors\.drop: must be a probability in \[0, 1\] \(got -1\.0\)$"):
        c.typed({"sensors": {"drop": -1}}, "links", LinksTable)
    with pytest.raises(ScenarioError, match=r"^s\.toml: clock\.nope: unknown key \(allowed: drift_ppm, jitter, offset, rate\)$"):
        c.typed({"nope": 1}, "clock", ClockSpec)
    with pytest.raises(ScenarioError, match=r"^s\.toml: scenario\.duration: missing$"):
        c.typed({"name": "x"}, "scenario", Header)
    with pytest.raises(ScenarioError, match=r"^s\.toml: world\.plant: must be one of prescribed, rigid_body, kinematic \(got 'x'\)$"):
        c.typed({"plant": "x"}, "world", WorldTable)
    with pytest.raises(ScenarioError, match=r"^s\.toml: scenario: must be a table \(got 3\)$"):
        c.typed({"scenario": 3, "algorithm": {"name": "a"}, "agents": []}, "", ScenarioFile)
    # A key holding a backtick and the words msgspec puts around a path is still one key.
    with pytest.raises(ScenarioError, match=r'^s\.toml: clock\."x` - at `\$\.y": unknown key'):
        c.typed({"x` - at `$.y": 1}, "clock", ClockSpec)
    # Defaults fill what the table leaves out (an agent's clock over the scenario's).
    assert c.typed({"jitter": 0.001}, "agents[0].clock", ClockSpec, {"rate": 50.0}) == ClockSpec(rate=50.0, jitter=0.001)


def test_bounds_words_in_the_loaders_order():
    b = Bounds(positive=True, maxv=1.0, minv=0.5)
    assert [b.problem(v) for v in ("a", math.nan, -1, 2, 0.25, 0.75)] == [
        "must be a number", "must be finite", "must be > 0", "must be <= 1", "must be >= 0.5", None,
    ]
    assert bounds(within=5.0, within_open=True).gt == -5.0  # strict: ±5 itself is outside
