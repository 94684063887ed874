"""Timing alignment: bringing sampled measurements and neighbours' data to one instant.

Pure functions on sample histories (numpy and the standard library only).
An agent's :class:`zswarm.scenario.algorithm.View` offers them on its own histories;
algorithms call them while building their inputs, so that everything a step
uses refers to the same instant (the equations are synchronous; a real
agent's data are not).

* :func:`interval_mean_rate` — gyro pre-integration (the mean of a sampled
  rate over an interval);
* :func:`body_vector_at` — a body-frame vector (a bearing, a body velocity)
  at any instant of the sensor history, rotation-compensated with the gyro;
* :func:`rotation_over` — the body rotation over an interval from the gyro.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

import numpy as np

from zswarm.math.kernels import rate_integral
from zswarm.math.so3 import T, apply, dot, exp, log, mul

Sample = tuple[float, np.ndarray]


def window(samples: Sequence[Sample], t0: float, t1: float) -> list[Sample]:
    """The samples in ``(t0, t1]``, with the newest one at or before t0 first when there is one
    (View.series: what a step from t0 to t1 measured)."""
    out: list[Sample] = []
    for t, v in reversed(samples):
        if t <= t1 + 1e-12:
            out.append((t, v))
            if t <= t0 + 1e-12:
                break
    out.reverse()
    return out


def interval_mean_rate(samples: Sequence[Sample], t0: float, t1: float) -> np.ndarray:
    """Mean of a sampled rate over ``[t0, t1]``.

    The rate is linearly interpolated between samples (``(time, vector)``,
    increasing times), held before the first, and past the newest sample
    extrapolated linearly from the last two for at most one sample gap (then
    held); the resulting piecewise-linear function is integrated exactly.

    This is the gyro pre-integration of an IMU-driven estimator.  Using only
    the newest sample over a 10 ms step lags by half a step (≈ ω̇·dt/2 rate
    error); holding the newest sample until the tick — which over Zenoh
    arrives 0–5 ms before it — leaves a ½ω̇τ² error per step of the same sign
    as ω̇, measured as a 1e-3 attitude floor on the §3.2 run.
    """
    return _integrate(samples, t0, t1, False)


def rotation_rate(samples: Sequence[Sample], t0: float, t1: float) -> np.ndarray:
    """The constant body rate ω̄ with ``exp((t1 − t0)[ω̄]^x) = R(t0)^T R(t1)`` for
    ``Ṙ = R[ω(t)]^x``, ω the gyro as in :func:`interval_mean_rate` (third-order).

    On each linear piece ``[ta, tb]`` of the rate, the Magnus expansion gives
    ``Ω = h (ω_a + ω_b)/2 + (h²/12) ω_a × ω_b`` (exact to O(h⁵) for a linear
    rate), and the pieces compose by BCH, ``log(e^A e^B) ≈ A + B + ½ A × B``.
    The mean rate alone, ``exp(h ω̄)``, misses the ``(h²/12) ω × ω̇ h`` term:
    about 1e-6 rad per 10 ms step at |ω × ω̇| ≈ 10 rad²/s³, a drift of 1e-4
    rad/s that an observer's correction balances with a 1e-5–1e-4 error floor.
    """
    return _integrate(samples, t0, t1, True)


def _integrate(samples: Sequence[Sample], t0: float, t1: float, magnus: bool) -> np.ndarray:
    """The piecewise-linear rate of the samples, integrated over ``[t0, t1]`` (``magnus``: as a rotation)."""
    # Plain Python on the few samples that matter (numpy's per-call overhead made
    # this a tenth of a §3.2 sim): those from the last one at or before t0 on.
    n = len(samples)
    if n == 1 or t1 <= t0:
        return np.array(samples[-1][1] if t1 <= t0 else samples[0][1], dtype=float)
    if rate_integral is not None:
        # One agent's samples in C, the same operations in the same order (zswarm/math/_kernels.c):
        # 20 -> 1 µs a step (2026-12-06).  False: a stack of draws (the batched engine), done below.
        out = np.empty(3)
        if rate_integral(samples, t0, t1, magnus, out):
            return out
    ts_all = [s[0] for s in samples]
    first = max(0, min(bisect.bisect_right(ts_all, t0) - 1, n - 2))
    ts = ts_all[first:]
    # Each rate as its three components: floats, or for a stack of M draws (the batched engine's
    # per-draw noise) arrays (M,), on which the same operations give each draw its own numbers.
    W = [_components(s[1]) for s in samples[first:]]
    gap = ts_all[-1] - ts_all[-2]
    Wl, Wp = _components(samples[-1][1]), _components(samples[-2][1])
    slope = [(Wl[c] - Wp[c]) / gap if gap > 0 else 0.0 * Wl[c] for c in range(3)]
    t_last = ts_all[-1]
    t_cap = t_last + max(gap, 0.0)

    def value(t: float, k: int) -> tuple[float, float, float]:
        """The rate at t; k: index into ts of the last sample at or before t (-1: none)."""
        if k < 0:
            return W[0]  # type: ignore[return-value]
        if k >= len(ts) - 1:
            tau = min(max(t - t_last, 0.0), t_cap - t_last)
            w = W[-1]
            return (w[0] + tau * slope[0], w[1] + tau * slope[1], w[2] + tau * slope[2])
        ta, tb = ts[k], ts[k + 1]
        a, b = W[k], W[k + 1]
        u = (t - ta) / (tb - ta) if tb > ta else 1.0
        return (a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]))

    # Breakpoints of the piecewise-linear rate inside (t0, t1): sample times and t_cap.
    # The rate is continuous, so one value per breakpoint serves both segments.
    grid = sorted({t0, t1, *(t for t in (*ts, t_cap) if t0 < t < t1)})
    vals = [value(g, bisect.bisect_right(ts, g) - 1) for g in grid]
    acc = [0.0, 0.0, 0.0]
    for n_ in range(len(grid) - 1):
        h = grid[n_ + 1] - grid[n_]
        lo, hi = vals[n_], vals[n_ + 1]
        a = (0.5 * (lo[0] + hi[0]) * h, 0.5 * (lo[1] + hi[1]) * h, 0.5 * (lo[2] + hi[2]) * h)
        if magnus:
            c = h * h / 12.0
            # BCH with the rotation so far (½ acc × a), then this piece's own Magnus term.
            x = 0.5 * (acc[1] * a[2] - acc[2] * a[1]) + c * (lo[1] * hi[2] - lo[2] * hi[1])
            y = 0.5 * (acc[2] * a[0] - acc[0] * a[2]) + c * (lo[2] * hi[0] - lo[0] * hi[2])
            z = 0.5 * (acc[0] * a[1] - acc[1] * a[0]) + c * (lo[0] * hi[1] - lo[1] * hi[0])
            acc[0] += a[0] + x
            acc[1] += a[1] + y
            acc[2] += a[2] + z
        else:
            acc[0] += a[0]
            acc[1] += a[1]
            acc[2] += a[2]
    return _vector(acc) / (t1 - t0)


def _components(v: object) -> tuple[object, object, object]:
    """A rate's three components: floats for one vector, arrays (M,) for a stack (M, 3)."""
    if type(v) is np.ndarray and v.ndim > 1:
        return (v[..., 0], v[..., 1], v[..., 2])
    if type(v) is np.ndarray:
        x, y, z = v.tolist()
        return (x, y, z)
    return (float(v[0]), float(v[1]), float(v[2]))  # type: ignore[index]


def _vector(acc: Sequence[object]) -> np.ndarray:
    """The components back as a vector (3,) or a stack (M, 3)."""
    if isinstance(acc[0], np.ndarray):
        return np.stack(acc, axis=-1)  # type: ignore[arg-type]
    return np.array(acc)


def rotation_over(gyro: Sequence[Sample], t0: float, t1: float) -> np.ndarray:
    """Body rotation from ``t0`` to ``t1``, ``R(t1) = R(t0) · rotation_over(...)``,
    as ``exp((t1 − t0)[ω̄]^x)`` with ω̄ the gyro's mean over the interval."""
    if t1 == t0:
        return np.eye(3)
    if t1 < t0:
        return T(rotation_over(gyro, t1, t0))
    return exp((t1 - t0) * rotation_rate(gyro, t0, t1))


def relative_attitude_at(hist: Sequence[tuple[float, np.ndarray]], gyro: Sequence[Sample], t: float, max_ahead: float = 0.05) -> np.ndarray | None:
    """A measured relative attitude ``R_ij = R_i^T R_j`` at time ``t`` from its samples
    ``(time, R_ij)`` and the gyro of i.

    Between two samples, i's own rotation comes from its gyro
    (:func:`rotation_over`, accurate), and what is left — j's rotation over
    the gap, ``E_j = R_ij(t0)^T E_i R_ij(t1)`` — is interpolated (or, up to
    ``max_ahead`` past the newest sample, extrapolated) at a constant rate:
    ``R_ij(t) = E_i(t0, t)^T R_ij(t0) exp(s log E_j)``.  Exact at the sample
    times.  None outside the history.  Without gyro samples, ``R_ij`` is taken on
    the geodesic through the two samples around (or before) ``t``.
    """
    if not hist:
        return None
    if len(hist) == 1:
        return hist[0][1] if hist[0][0] == t else None
    (t0, R0), (t1, R1) = hist[-2], hist[-1]
    if t == t1:
        return R1
    if not t1 < t <= t1 + max_ahead:
        for k in range(len(hist) - 1):
            (t0, R0), (t1, R1) = hist[k], hist[k + 1]
            if t0 <= t <= t1:
                break
        else:
            return None
        if t == t0:
            return R0
        if t == t1:
            return R1
    if t1 <= t0:
        return None
    if not gyro:
        # No gyro (a velocity-free agent): R_ij itself on the geodesic through the two samples.
        return mul(R0, exp(((t - t0) / (t1 - t0)) * log(mul(T(R0), R1))))
    E_j = mul(mul(T(R0), rotation_over(gyro, t0, t1)), R1)
    s_ = (t - t0) / (t1 - t0)
    return mul(mul(T(rotation_over(gyro, t0, t)), R0), exp(s_ * log(E_j)))


def body_vector_at(hist: Sequence[tuple[float, np.ndarray, np.ndarray]], t: float, max_ahead: float = 0.05, unit: bool = True) -> np.ndarray | None:
    """A body-frame vector at time ``t`` from its history ``(time, vector, gyro)``.

    At a sample's time, that sample.  Otherwise from the two samples around
    ``t`` (or the newest two, up to ``max_ahead`` s past the newest): the
    older one is turned into the newer one's body frame with the gyro, so what
    is left between them is the vector's own (e.g. translational) change, slow
    next to the body's rotation; that is interpolated or extrapolated linearly
    and the result turned to the body frame at ``t``.  The rotations are the
    gyro history's (:func:`rotation_over`, third order): the newer sample's
    rate held over the gap is off by ≈ ½|ω̇|h², 1e-3 rad over the 25 ms gap of
    three skipped samples at §3.3's |ω̇| ≈ 3 rad/s².  A plain linear
    extrapolation of body-frame vectors holds only for a sample gap (5 ms),
    and over Zenoh the newest sample is often older than that.  ``unit``
    normalises (bearings).  None outside the history.
    """
    n = len(hist)
    if n < 2:
        return None
    for k in range(n - 1, -1, -1):  # the common case: t is a sample's time (steps end at packets)
        tk = hist[k][0]
        if tk == t:
            v = hist[k][1]
            return _unit(v) if unit else np.array(v, dtype=float)
        if tk < t:
            break
    (t0, b0, _), (t1, b1, _) = hist[-2], hist[-1]
    if not t1 < t <= t1 + max_ahead:
        for k in range(n - 1):
            (t0, b0, _), (t1, b1, _) = hist[k], hist[k + 1]
            if t0 <= t <= t1:
                break
        else:
            return None
    if t1 <= t0:
        return None
    gyro = [(h[0], h[2]) for h in hist]
    b0_in_1 = apply(T(rotation_over(gyro, t0, t1)), b0)
    s_ = (t - t0) / (t1 - t0)
    v = apply(T(rotation_over(gyro, t1, t)), (1 - s_) * b0_in_1 + s_ * b1)
    return _unit(v) if unit else v


def _unit(v: np.ndarray) -> np.ndarray:
    """``v / |v|`` of a vector (3,) or of each of a stack (M, 3)."""
    if v.ndim > 1:
        return v / np.sqrt(dot(v, v))[..., None]  # type: ignore[no-any-return]
    return v / math.sqrt(dot(v, v))  # type: ignore[no-any-return]  # the stack's sum, (x² + y²) + z²


class HistoryReads:
    """The reads of a View (zswarm.scenario.algorithm.View) that come from the sensor history:
    ``series``, ``mean_rate``, ``body_rate`` and ``rotation``, on the samples a subclass gives
    by ``_samples(name)`` (the rates by ``_rates(name)``, the same unless a subclass says
    otherwise), with ``rotation`` cached per tick in the subclass's ``_cache``.  The runtime's
    TickView and the batched engine's view both read their histories through these."""

    _cache: dict[object, object]

    def _samples(self, name: str) -> list[Sample]:
        raise NotImplementedError

    def _rates(self, name: str) -> list[Sample]:
        return self._samples(name)

    def series(self, name: str, t0: float, t1: float) -> list[Sample]:
        return window(self._samples(name), t0, t1)

    def mean_rate(self, name: str, t0: float, t1: float) -> np.ndarray:
        return interval_mean_rate(self._rates(name), t0, t1)

    def body_rate(self, t0: float, t1: float) -> np.ndarray:
        return rotation_rate(self._rates("gyro"), t0, t1)

    def rotation(self, t0: float, t1: float) -> np.ndarray:
        ck = ("rot", t0, t1)  # algorithms ask for the same interval per neighbour and per term
        if ck not in self._cache:
            self._cache[ck] = rotation_over(self._rates("gyro"), t0, t1)
        return self._cache[ck]  # type: ignore[return-value]

