"""Prescribed motions: attitude kinematics Ṙ_i = R_i [ω_i(t)]^x (thesis (3.1)), fixed positions.

All agents are integrated together (batched over agents) with the exponential
map at a fixed step: ``R(t+h) = R(t) exp(h [ω(t + h/2)]^x)`` (Lie midpoint),
which is exact on SO(3) up to O(h^3) per step and never leaves the group.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from zswarm.expr import Expr
from zswarm.so3 import exp_batch


class PrescribedAttitudes:
    """Truth for n agents whose body-frame angular velocities are expressions in ``t``."""

    def __init__(self, R0: NDArray[np.float64], p0: NDArray[np.float64], omega: Sequence[Sequence[Expr]], step: float) -> None:
        self.R = np.array(R0, dtype=float).reshape(-1, 3, 3)
        self.p = np.array(p0, dtype=float).reshape(-1, 3)
        self.omega_exprs = [list(w) for w in omega]
        self.step = step
        self.t = 0.0

    def omega(self, t: NDArray[np.float64] | float) -> NDArray[np.float64]:
        """True body-frame ω at times ``t``: shape (len(t), n, 3), or (n, 3) for a scalar."""
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        W = np.empty((ts.size, len(self.omega_exprs), 3))
        for a, w in enumerate(self.omega_exprs):
            for c in range(3):
                W[:, a, c] = w[c](ts)
        return W[0] if np.ndim(t) == 0 else W

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
        W = self.omega(mids)
        for k in range(h.size):
            self.R = self.R @ exp_batch(h[k] * W[k])
        self.t = t
