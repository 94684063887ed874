"""sin and cos by range reduction and polynomials: the same operations as the compiled
``sincos4`` of zswarm/math/_kernels.c, so the ξ_k filter (attitude_sync_terms.flow_xi) gives the
same bits compiled or not, one draw or a stack of draws.

Why not the C library's: its sin and cos are one call per number (17 ns each on the ξ filter's
chain of sub-steps, a third of the batched hybrid law's time, issue 31), where these are
straight-line IEEE operations that the compiler puts four numbers to an AVX2 instruction.

``x = n π/2 + y`` with n the nearest integer (rounded by adding and subtracting 1.5·2^52) and
y by Cody and Waite's reduction, π/2 in four parts (fdlibm's pio2_1, pio2_2, pio2_3 of 33 bits
each, so the first three products are exact for |n| < 2^20, and pio2_3t); sin y and cos y by
fdlibm's kernel polynomials on [−π/4, π/4] (k_sin.c, k_cos.c, without the tail of y); the
quadrant n mod 4 picks and signs them.  Accuracy, measured against the correctly rounded values
(tests/unit/test_trig.py): at most 1.5 ulp for |x| ≤ LIMIT, where glibc's are within 1 ulp of
these.  Beyond LIMIT, and for inf and NaN, the C library's (math.sin, math.cos; NaN for ±inf).
"""

from __future__ import annotations

import math
from typing import overload

import numpy as np

from zswarm.math import kernels

LIMIT = 16.0
_one = getattr(kernels._lib, "sincos1", None)
PIO2_1, PIO2_2, PIO2_3, PIO2_3T = 1.57079632673412561417e00, 6.07710050630396597660e-11, 2.02226624871116645580e-21, 8.47842766036889956997e-32
INVPIO2, RND = 6.36619772367581382433e-01, 6755399441055744.0
S1, S2, S3, S4, S5, S6 = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
C1, C2, C3, C4, C5, C6 = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)


@overload
def sincos(x: float) -> tuple[float, float]: ...
@overload
def sincos(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...
def sincos(x):  # type: ignore[no-untyped-def]
    """``(sin x, cos x)`` of a float, or elementwise of a float64 array."""
    if isinstance(x, np.ndarray):
        return _sincos_array(x)
    if _one is not None:
        return _one(x)  # the compiled sincos1: the same bits, a tenth of the time
    return sincos_py(x)


def sincos_py(x: float) -> tuple[float, float]:
    """:func:`sincos` of a float in Python's arithmetic."""
    x = float(x)
    if not -LIMIT <= x <= LIMIT:
        return (math.sin(x), math.cos(x)) if math.isfinite(x) else (math.nan, math.nan)
    fn = (x * INVPIO2 + RND) - RND
    y = (((x - fn * PIO2_1) - fn * PIO2_2) - fn * PIO2_3) - fn * PIO2_3T
    f4 = fn * 0.25
    r4 = (f4 + RND) - RND
    q = fn - 4.0 * (r4 - 1.0 if r4 > f4 else r4)
    z = y * y
    v = z * y
    s = y + v * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))))
    r = z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))))
    c = 1.0 - (0.5 * z - z * r)
    ss, cc = (c, s) if q in (1.0, 3.0) else (s, c)
    return (x if x == 0.0 else -ss if q >= 2.0 else ss), (-cc if q in (1.0, 2.0) else cc)


def _sincos_array(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(all="ignore"):  # inf and NaN lanes are the C library's below
        return _lanes(np.asarray(x, dtype=np.float64))


def _lanes(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    fn = (x * INVPIO2 + RND) - RND
    y = (((x - fn * PIO2_1) - fn * PIO2_2) - fn * PIO2_3) - fn * PIO2_3T
    f4 = fn * 0.25
    r4 = (f4 + RND) - RND
    q = fn - 4.0 * np.where(r4 > f4, r4 - 1.0, r4)
    z = y * y
    v = z * y
    s = y + v * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))))
    r = z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))))
    c = 1.0 - (0.5 * z - z * r)
    odd = (q == 1.0) | (q == 3.0)
    ss, cc = np.where(odd, c, s), np.where(odd, s, c)
    so = np.where(x == 0.0, x, np.where(q >= 2.0, -ss, ss))
    co = np.where((q == 1.0) | (q == 2.0), -cc, cc)
    out = ~((x <= LIMIT) & (x >= -LIMIT))
    if out.any():
        for i in zip(*np.nonzero(out), strict=True):
            so[i], co[i] = sincos_py(float(x[i]))
    return so, co
