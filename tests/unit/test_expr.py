import math

import numpy as np
import pytest

from zswarm.expr import ExprError, parse


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
        ("log(t)", "unknown name 'log'"),
        ("t[0]", "unexpected character"),
        ("sin t", "expected '\\('"),
        ("1 +", "end of expression"),
        ("(1", "end of expression"),
        ("1 2", "after a complete expression"),
        ("", "empty"),
        ("1/0", "not finite|cannot be evaluated"),
        ("lambda: 1", "unexpected character"),
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
