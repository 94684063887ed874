import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from zswarm.scenario.expr import ExprError, parse


@pytest.mark.parametrize(
    "src, t, want",
    [
        ("1", 3.0, 1.0),
        ("-cos(3*t)", 0.7, -math.cos(2.1)),
        ("sin(9*t)", 0.2, math.sin(1.8)),
        ("2**3**2", 0, 2.0**9),
        ("-2**2", 0, -4.0),
        ("(1+t)*(2-t)/4", 1.5, (2.5 * 0.5) / 4),
        ("0.08*pi", 0, 0.08 * math.pi),
        ("sqrt(abs(-4)) + exp(0) + tan(0)", 0, 3.0),
        ("1e-3*t", 2.0, 2e-3),
        (2.5, 9.0, 2.5),
        ("pi/6*t", 3.0, math.pi / 2),
    ],
)
def test_evaluates(src, t, want):
    assert parse(src)(t) == pytest.approx(want, rel=1e-15, abs=1e-15)


def test_vectorised_over_times():
    ts = np.linspace(0, 1, 7)
    assert np.allclose(parse("-cos(2*t)")(ts), -np.cos(2 * ts))
    assert np.allclose(parse("3")(ts), 3.0)


@pytest.mark.parametrize(
    "src, msg",
    [
        ("__import__('os')", "unexpected character"),
        ("os.system", "unexpected character"),
        ("log(t)", "unknown name 'log' \\(allowed"),
        ("sinn(t)", "unknown name 'sinn'; did you mean 'sin'\\?"),
        ("inf", "unknown name 'inf' \\(allowed"),  # "sin" is not what was meant: no guess below difflib's 0.7
        ("t[0]", "unexpected character"),
        ("sin t", "expected '\\('"),
        ("1 +", "end of expression"),
        ("(1", "end of expression"),
        ("1 2", "after a complete expression"),
        ("", "empty"),
        ("1/0", "not finite|cannot be evaluated"),
        ("lambda: 1", "unexpected character"),
        # Python's float power gave a complex number here, which escaped as TypeError:
        ("(-8)**(1/3)", "not finite at t = 0"),
        ("(t-1)**0.5", "not finite at t = 0"),
        # RecursionError before the nesting limit (parser and closures recurse per level):
        ("(" * 2000 + "t" + ")" * 2000, "nested too deeply"),
        ("-" * 5000 + "t", "nested too deeply"),
        ("**".join(["2"] * 3000), "nested too deeply"),
        ("sin(" * 100 + "t" + ")" * 100, "nested too deeply"),
    ],
)
def test_rejects(src, msg):
    with pytest.raises(ExprError, match=msg):
        parse(src)


def test_rejects_non_string():
    with pytest.raises(ExprError):
        parse(True)  # type: ignore[arg-type]
    with pytest.raises(ExprError):
        parse([1])  # type: ignore[arg-type]


def test_long_sums_and_products_are_one_level():
    # A 3000-term sum was 3000 nested closures: RecursionError at the t = 0 check.
    assert parse("+".join(["t"] * 3000))(0.5) == 1500.0
    # 3000 roundings of ≤ 0.5 ulp (1.1e-16) on each side: ≤ 3.3e-13 apart, under 1e-12.
    assert parse("*".join(["1.001"] * 3000))(0.0) == pytest.approx(1.001**3000, rel=1e-12)
    ts = np.linspace(0, 1, 5)
    assert np.array_equal(parse("t - 2*t + 3*t")(ts), ts - 2 * ts + 3 * ts)  # left to right, as written


def test_nesting_up_to_the_limit_is_accepted():
    src = "(" * 60 + "t" + ")" * 60
    assert parse(src)(0.25) == 0.25


TOKENS = ["t", "pi", "1", "0", "2.5", "1e308", "-", "+", "*", "/", "**", "(", ")", "sin(", "sqrt(", "exp(", "abs(", "tan(", " ", "x", "."]


@settings(max_examples=examples(1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(TOKENS), max_size=60))
def test_any_text_parses_or_is_an_expr_error(toks):
    """Whatever the text: an Expr finite at t = 0, or ExprError (the loader's one-line
    ``file: field: problem``); never another exception."""
    src = "".join(toks)
    try:
        e = parse(src)
    except ExprError:
        return
    assert math.isfinite(float(e(0.0)))
