"""Time-series helpers every report family uses: settle times, final values, values held on a grid.

One settle-time function (:func:`settle_time`) for every figure of every family:
the first time after which a series stays below a threshold, where NaN (no
estimate, no truth) counts as not below.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def settle_time(t: np.ndarray, v: np.ndarray, thr: float) -> float | None:
    """First time after which ``v`` stays below ``thr``; None if it is not below at the end.

    NaN (no estimate yet, or no truth to compare with) counts as not below.
    """
    bad = np.nonzero(~(v < thr))[0]
    if len(bad) == 0:
        return float(t[0])
    if bad[-1] + 1 >= len(t):
        return None
    return float(t[bad[-1] + 1])


def leave_time(t: np.ndarray, v: np.ndarray, start: float = 0.9) -> float | None:
    """When ``v`` first drops below ``start`` (None: it never did): e.g. the continuous
    synchronization law's escape from its undesired equilibrium."""
    below = np.nonzero(v < start)[0]
    return float(t[below[0]]) if len(below) else None


def held(ts: np.ndarray, vs: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The newest value at or before each grid time (NaN before the first)."""
    idx = np.searchsorted(ts, grid + 1e-9, side="right") - 1
    out = np.full((len(grid),) + vs.shape[1:], np.nan)
    ok = idx >= 0
    out[ok] = vs[idx[ok]]
    return out


def final(t: np.ndarray, v: np.ndarray, t_end: float, window: float = 1.0) -> float:
    """Mean of ``v`` over the last ``window`` of the run (``t >= t_end − window``), of the finite
    values (NaN if none: a recording cut before the end has no final error)."""
    w = v[t >= t_end - window]
    w = w[np.isfinite(w)]
    return float(np.mean(w)) if len(w) else float("nan")


FINAL_WINDOW_S = 1.0  # a run's "final" error: its mean over the last second


def final_of_grid(t: np.ndarray, v: np.ndarray, window: float = FINAL_WINDOW_S) -> float:
    """Mean of ``v`` over the last ``window`` of its own grid ``t``, NaN left out."""
    sel = t >= t[-1] - window
    return float(np.nanmean(v[sel])) if np.any(sel) else float("nan")


def max_over(series: dict[Any, np.ndarray]) -> np.ndarray:
    """The max over edges / agents at each grid time (NaN where none has a value)."""
    x = np.stack(list(series.values()))
    out = np.full(x.shape[1], np.nan)
    ok = ~np.all(np.isnan(x), axis=0)
    out[ok] = np.nanmax(x[:, ok], axis=0)
    return out


def norm_I(R: np.ndarray) -> np.ndarray:
    """``|R|_I = sqrt((3 − tr R) / 4)`` (= sin(θ/2)) of one rotation or a stack of them."""
    return np.sqrt(np.clip((3.0 - np.trace(R, axis1=-2, axis2=-1)) / 4.0, 0.0, 1.0))


def nanmean(xs: list[float | None]) -> float | None:
    """Mean of the finite values (None if none)."""
    v = [x for x in xs if x is not None and np.isfinite(x)]
    return float(np.mean(v)) if v else None
