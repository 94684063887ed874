"""Prescribed motions of the thesis' simulations.

Attitudes follow Ṙ_i = R_i [ω_i(t)]^x ((3.1), (3.20), (4.1)), integrated for
all agents together (batched) with the exponential map at a fixed step:
``R(t+h) = R(t) exp(h [ω(t + h/2)]^x)`` (Lie midpoint, O(h³) per step, never
leaves SO(3)).

Positions ((3.21), (4.27)) are one of:

* fixed (§3.2);
* a rigidly rotating formation (§3.3.4, §4.5): ``p_i(t) = R_f(t)^T p_i(0)``
  with ``R_f(t) = Ra(rate·t, axis)``, evaluated in closed form; the inertial
  velocity is ``v_i = −rate · axis × p_i(t)``;
* per-agent inertial velocities ``v_i(t)`` (expressions), integrated with the
  midpoint rule at the same step.

The body-frame velocity of (4.30) is ``v_i^i = R_i^T v_i``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zswarm.math.so3 import Ra, exp_batch
from zswarm.scenario.expr import Expr
from zswarm.scenario.programs import WorldProgram


class PrescribedMotion:
    """Truth for n agents: attitudes from ω_i(t), positions fixed, rotating or from v_i(t)."""

    def __init__(
        self,
        R0: NDArray[np.float64],
        p0: NDArray[np.float64],
        omega: Sequence[Sequence[Expr]],
        step: float,
        formation: tuple[NDArray[np.float64], float] | None = None,
        velocity: Sequence[Sequence[Expr] | None] | None = None,
    ) -> None:
        self.R = np.array(R0, dtype=float).reshape(-1, 3, 3)
        self.p0 = np.array(p0, dtype=float).reshape(-1, 3)
        self.p = self.p0.copy()
        self.omega_exprs = [list(w) for w in omega]
        self.step = step
        self.formation = None if formation is None else (np.asarray(formation[0], dtype=float), float(formation[1]))
        self.velocity_exprs = None if velocity is None or all(v is None for v in velocity) else [None if v is None else list(v) for v in velocity]
        self.t = 0.0
        self._omega_at: tuple[float, NDArray[np.float64]] | None = None
        # Planned intervals (see plan): (t_from, t_to) -> (ω at the step midpoints, ω at t_to,
        # v at the midpoints or None, v at t_to or None).
        self._planned: dict[tuple[float, float], tuple[Any, Any, Any, Any]] = {}
        self._v_at: tuple[float, NDArray[np.float64]] | None = None
        self._horizon = -np.inf

    def plan(self, times: NDArray[np.floating[Any]]) -> None:
        """Evaluate ω_i(t) (and v_i(t)) for the coming intervals, ``self.t`` to ``times[0]``,
        ``times[0]`` to ``times[1]``, …, in one call per expression instead of one per
        interval and expression (the world's sample times; 24 calls per sample for §3.2 were
        a tenth of a ``sim`` run).  The same numbers as :meth:`advance_to` computes: the
        same step midpoints by the same float operations, and numpy's elementwise
        functions give each element the same value whatever the array's length (tested
        against unplanned runs, bit for bit).  Only the leading intervals that have whole
        steps and the same number of them are planned; the rest are computed as they come."""
        ts = np.asarray(times, dtype=float)
        if ts.size == 0:
            return
        self._horizon = float(ts[-1])  # not planned again before then, planned or not
        prev = np.concatenate(([self.t], ts[:-1]))
        n_full = np.floor((ts - prev) / self.step + 1e-9)
        rest = ts - prev - n_full * self.step
        ok = (n_full == n_full[0]) & (rest <= 1e-12) & (n_full >= 1) & (ts > prev)
        m = int(np.argmin(ok)) if not ok.all() else ts.size
        if m == 0:
            self._planned = {}
            return
        n = int(n_full[0])
        h = np.array([self.step] * n)
        mids = prev[:m, None] + np.cumsum(h)[None, :] - (h / 2)[None, :]  # as advance_to: (t + Σh) − h/2
        W = self.omega(np.concatenate((mids.ravel(), ts[:m])))
        Wm, Wt = W[: m * n].reshape(m, n, *W.shape[1:]), W[m * n :]
        Vm = Vt = None
        if self.formation is None and self.velocity_exprs is not None:
            V = self._v_expr(np.concatenate((mids.ravel(), ts[:m])))
            Vm, Vt = V[: m * n].reshape(m, n, *V.shape[1:]), V[m * n :]
        self._planned = {
            (float(prev[k]), float(ts[k])): (Wm[k], Wt[k], None if Vm is None else Vm[k], None if Vt is None else Vt[k]) for k in range(m)
        }

    def planned_through(self) -> float:
        """The last time the latest :meth:`plan` was asked for (−inf: none yet)."""
        return self._horizon

    def omega_now(self) -> NDArray[np.float64]:
        """True ω of every agent at the current time ``self.t``, shape (n, 3)."""
        if self._omega_at is not None and self._omega_at[0] == self.t:
            return self._omega_at[1]
        return self.omega(self.t)

    def omega(self, t: NDArray[np.float64] | float) -> NDArray[np.float64]:
        """True body-frame ω at times ``t``: shape (len(t), n, 3), or (n, 3) for a scalar."""
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        W = np.empty((ts.size, len(self.omega_exprs), 3))
        for a, w in enumerate(self.omega_exprs):
            for c in range(3):
                W[:, a, c] = w[c](ts)
        return W[0] if np.ndim(t) == 0 else W

    def _v_expr(self, ts: NDArray[np.float64]) -> NDArray[np.float64]:
        V = np.zeros((ts.size, self.p0.shape[0], 3))
        if self.velocity_exprs is not None:
            for a, v in enumerate(self.velocity_exprs):
                if v is not None:
                    for c in range(3):
                        V[:, a, c] = v[c](ts)
        return V

    def velocity(self) -> NDArray[np.float64]:
        """True inertial velocities v_i at the current time, shape (n, 3)."""
        if self.formation is not None:
            axis, rate = self.formation
            return -rate * np.cross(axis[None, :], self.p)
        if self._v_at is not None and self._v_at[0] == self.t:
            return self._v_at[1]
        return self._v_expr(np.array([self.t]))[0]

    def positions_at(self, t: float) -> NDArray[np.float64]:
        """Positions of a rotating formation (or fixed ones) at time ``t``."""
        if self.formation is None:
            return self.p0.copy()
        axis, rate = self.formation
        return self.p0 @ Ra(rate * t, axis)  # rows: (R_f^T p_i(0))^T = p_i(0)^T R_f

    def advance_to(self, t: float) -> None:
        """Integrate from ``self.t`` to ``t`` with steps of ``self.step`` (the last one may be shorter)."""
        if t <= self.t:
            return
        n_full = int(np.floor((t - self.t) / self.step + 1e-9))
        hs = [self.step] * n_full
        rest = t - self.t - n_full * self.step
        if rest > 1e-12:
            hs.append(rest)
        h = np.array(hs)
        planned = self._planned.pop((self.t, t), None)
        if planned is not None:
            W, W_t, V_mid, V_t = planned
            self._omega_at = (t, W_t)
            self._v_at = None if V_t is None else (t, V_t)
        else:
            mids = self.t + np.cumsum(h) - h / 2
            # ω at the midpoints and at t itself (what the gyro reads there) in one call.
            W_all = self.omega(np.append(mids, t))
            W = W_all[:-1]
            self._omega_at = (t, W_all[-1])
            V_mid = self._v_expr(mids) if self.formation is None and self.velocity_exprs is not None else None
            self._v_at = None
        # One Rodrigues call for every step and agent (same numbers as step by step).
        n = W.shape[1]
        E = exp_batch((h[:, None, None] * W).reshape(-1, 3)).reshape(h.size, n, 3, 3)
        for k in range(h.size):
            self.R = self.R @ E[k]
        if self.formation is not None:
            self.p = self.positions_at(t)
        elif self.velocity_exprs is not None:
            self.p = self.p + np.einsum("k,kaj->aj", h, V_mid)
        self.t = t


def prescribed_key(w: WorldProgram) -> tuple[Any, ...]:
    """What :func:`prescribed` makes a truth of: equal for worlds that share their truth."""
    f = w.formation
    bodies = tuple((b.R_matrix.tobytes(), tuple(b.p), repr(b.omega), repr(b.velocity), tuple(b.gyro_bias)) for b in w.bodies)
    return (w.step, w.sensor_rate, None if f is None else (tuple(f.axis), f.rate), bodies)


def prescribed(w: WorldProgram) -> PrescribedMotion:
    """The truth of a world with the prescribed plant: every body's R_i(0), p_i(0), ω_i(t)
    and v_i(t), and the formation's rotation."""
    f = w.formation
    return PrescribedMotion(
        np.array([b.R_matrix for b in w.bodies]),
        np.array([b.p for b in w.bodies]),
        [b.omega for b in w.bodies],
        w.step,
        formation=None if f is None else (np.array(f.axis), f.rate),
        velocity=[b.velocity for b in w.bodies],
    )
