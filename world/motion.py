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

import numpy as np
from numpy.typing import NDArray

from zswarm.expr import Expr
from zswarm.so3 import Ra, exp_batch


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
        mids = self.t + np.cumsum(h) - h / 2
        # ω at the midpoints and at t itself (what the gyro reads there) in one call.
        W_all = self.omega(np.append(mids, t))
        W = W_all[:-1]
        self._omega_at = (t, W_all[-1])
        # One Rodrigues call for every step and agent (same numbers as step by step).
        n = W.shape[1]
        E = exp_batch((h[:, None, None] * W).reshape(-1, 3)).reshape(h.size, n, 3, 3)
        for k in range(h.size):
            self.R = self.R @ E[k]
        if self.formation is not None:
            self.p = self.positions_at(t)
        elif self.velocity_exprs is not None:
            self.p = self.p + np.einsum("k,kaj->aj", h, self._v_expr(mids))
        self.t = t
