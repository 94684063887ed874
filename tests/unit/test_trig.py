"""zswarm/math/trig.py's sin and cos (the ξ_k filter's, compiled four draws at once in
zswarm/math/_kernels.c): the compiled and the Python operations give the same bits, and the
numbers are within their derived error of the true sine and cosine.

The reference is numpy's long double (x86-64's 80-bit format, sinl/cosl: 11 more bits than a
double), so an error is measured to ~1e-3 ulp.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from zswarm.math import kernels, trig

NEEDED = "zswarm.math._kernels was not built (no C compiler at install?): pip install -e . with gcc"
# The bound: fdlibm's kernel polynomials are within 1 ulp of sin y and cos y given y and its
# tail (k_sin.c, k_cos.c); the tail dropped here is at most half an ulp of y, carried into the
# result with a factor |cos y| or |sin y| <= 1 (+0.5 ulp); and cos y is 1 - (z/2 - z r) without
# k_cos.c's split of 1 - z/2 for |y| > 0.3 (at most +0.5 ulp more).  Measured: 1.49 ulp over
# 5e6 points of [-16, 16].
MAX_ULP = 2.0


def _bits(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


def _points(rng: np.random.Generator) -> np.ndarray:
    k = np.arange(-10, 11)
    near = (k[:, None] * (np.pi / 2) + np.array([0.0, 1e-15, -1e-12, 1e-9, 1e-6, -1e-3])).ravel()  # near n pi/2, where y is small
    return np.concatenate(
        [
            rng.uniform(-trig.LIMIT, trig.LIMIT, 400_000),
            rng.uniform(-4.0, 4.0, 200_000),  # where ξ lives
            near,
            [0.0, -0.0, 5e-324, -1e-300, 1e-9, np.pi / 4, -np.pi / 4, trig.LIMIT, -trig.LIMIT, np.nextafter(trig.LIMIT, 0.0)],
        ]
    )


def test_within_their_error_of_the_truth():
    x = _points(np.random.default_rng(1))
    s, c = trig.sincos(x)
    X = x.astype(np.longdouble)
    for got, ref in ((s, np.sin(X)), (c, np.cos(X))):
        ulp = np.spacing(np.abs(ref.astype(np.float64)))
        err = np.abs((got.astype(np.longdouble) - ref) / ulp.astype(np.longdouble)).astype(np.float64)
        assert err.max() <= MAX_ULP, (err.max(), x[err.argmax()])
    assert math.copysign(1.0, trig.sincos(-0.0)[0]) == -1.0 and trig.sincos(-0.0)[1] == 1.0


def test_beyond_the_limit_is_the_c_library():
    xs = [16.000000000000004, -17.5, 1e3, -123456.789, 1e300]
    for x in xs:
        assert trig.sincos(x) == (math.sin(x), math.cos(x)) == trig.sincos_py(x)
    s, c = trig.sincos(np.array(xs))
    assert s.tolist() == [math.sin(x) for x in xs] and c.tolist() == [math.cos(x) for x in xs]
    for x in (math.inf, -math.inf, math.nan):
        assert all(math.isnan(v) for v in trig.sincos(x)) and all(math.isnan(v) for v in trig.sincos_py(x))
        assert all(np.isnan(v[0]) for v in trig.sincos(np.array([x])))


def test_compiled_python_and_numpy_give_the_same_bits():
    lib = kernels._lib
    assert lib is not None, NEEDED
    rng = np.random.default_rng(2)
    x = np.concatenate([_points(rng)[::7], [np.inf, -np.inf, np.nan, 17.0, -1e5]])
    s, c = np.empty_like(x), np.empty_like(x)
    lib.sincos(x, s, c)
    sn, cn = trig.sincos(x)
    one = [trig.sincos_py(float(v)) for v in x[:5000]]
    assert trig._one is not None, NEEDED
    assert np.array_equal(_bits(np.array([trig.sincos(float(v)) for v in x[:5000]])), _bits(np.array(one)))  # the compiled one-number call
    assert np.array_equal(np.isnan(s), np.isnan(x) | np.isinf(x))
    fin = np.isfinite(x)
    assert np.array_equal(_bits(s[fin]), _bits(sn[fin])) and np.array_equal(_bits(c[fin]), _bits(cn[fin]))
    assert np.array_equal(_bits(np.array(one)), _bits(np.stack([s[:5000], c[:5000]], axis=1)))  # Python floats, one at a time
    # Any length, in any block: a number's result does not depend on its neighbours.
    for n in (1, 3, 4, 5, 17):
        sub = x[:n].copy()
        s2, c2 = np.empty(n), np.empty(n)
        lib.sincos(sub, s2, c2)
        assert np.array_equal(_bits(s2), _bits(s[:n])) and np.array_equal(_bits(c2), _bits(c[:n]))


@pytest.mark.parametrize("bad", [np.zeros(3, dtype=np.float32), np.zeros((4, 2))[:, 0]])
def test_the_compiled_sincos_refuses_arrays_it_cannot_read(bad):
    lib = kernels._lib
    assert lib is not None, NEEDED
    with pytest.raises((TypeError, ValueError, BufferError)):
        lib.sincos(bad, np.empty(3), np.empty(3))
    with pytest.raises(ValueError):
        lib.sincos(np.zeros(3), np.empty(2), np.empty(3))
