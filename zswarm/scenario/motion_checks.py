"""Checks of the agents' prescribed motions over the whole run (the loader's): rates and
positions the wire would refuse, and positions sampled for the graph checks of moving agents."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from zswarm.math import so3
from zswarm.math.limits import MAX_ABS

if TYPE_CHECKING:
    from zswarm.scenario import Formation
    from zswarm.scenario.agent_config import AgentSpec


# Motions are checked on this grid over the whole run (at most this many points): an
# expression finite at t = 0 may not be later, and 1/(1-t) used to turn the truth into NaN
# at t = 1, after which the agents dropped every sensor packet as malformed.
FINITE_CHECK_STEP = 1e-3


FINITE_CHECK_POINTS = 1_000_000

# Motions that passed the check, by (source, kind, duration, step): a basin loads its scenario
# once per draw with only the starts changed, and re-evaluating every ω_i(t) over the run
# was a third of a draw's load time (§4.5: 0.6 of 1.7 s for 100 draws).
_PASSED: set[tuple[str, str, float, float]] = set()


def _check_finite_over_run(c: Any, a: AgentSpec, fld: str, duration: float, step: float = 1e-3) -> None:
    """Every motion finite and within what the truth and the wire can carry over the run.

    ω: |ω_k|·world.step ≤ π/2, a quarter turn per integration step at most (past it the
    world's exp(ω dt) steps alias; ω = 1e13 was a traceback, ω = exp(3t) turned the truth
    wire-invalid at 9.2 s and it was dropped while the run read completed).  v: the position
    stays within the wire's ±MAX_ABS over the run, |v_k|·duration ≤ MAX_ABS/10."""
    exprs = [("omega", k, e) for k, e in enumerate(a.omega)] + [("v", k, e) for k, e in enumerate(a.velocity or ())]
    for name, k, e in exprs:
        limit, why = (0.5 * math.pi / step, f"a quarter turn per world.step of {step:g} s") if name == "omega" else (0.1 * MAX_ABS / duration, f"the positions within ±{MAX_ABS:g} over the run's {duration:g} s")
        key = (e.source, name, duration, step)
        if key in _PASSED:
            continue
        if e.constant:
            v0 = float(e(0.0))
            if abs(v0) > limit:
                raise c.err(f"{fld}.{name}[{k}]", f"must be within ±{limit:.4g} ({why})", e.source)
            _PASSED.add(key)
            continue
        n = max(1, min(FINITE_CHECK_POINTS, math.ceil(duration / FINITE_CHECK_STEP - 1e-9)))
        ts = np.arange(n + 1) * (duration / n)  # k·1 ms exactly, when the run has at most 1e6 steps of it
        with np.errstate(all="ignore"):
            v = np.broadcast_to(np.asarray(e(ts), dtype=float), ts.shape)
        bad = ~np.isfinite(v)
        if bad.any():
            raise c.err(f"{fld}.{name}[{k}]", f"is not finite at t = {ts[int(np.argmax(bad))]:g} s (checked every {duration / n:.3g} s over the run's {duration:g} s)", e.source)
        over = np.abs(v) > limit
        if over.any():
            at = int(np.argmax(over))
            raise c.err(f"{fld}.{name}[{k}]", f"reaches {v[at]:.4g} at t = {ts[at]:g} s, beyond ±{limit:.4g} ({why})", e.source)
        _PASSED.add(key)


def _snapshots(agents: list[AgentSpec], formation: Formation | None, duration: float, n: int = 200) -> list[dict[int, tuple[float, ...]]]:
    """Positions at ``n`` times over the run, for the checks of moving agents (empty if all fixed)."""
    if formation is None and all(a.velocity is None for a in agents):
        return []
    ts = np.linspace(0.0, duration, n + 1)[1:]
    p0 = np.array([a.p for a in agents])
    if formation is not None:
        out = [p0 @ so3.Ra(formation.rate * t, np.array(formation.axis)) for t in ts]
    else:
        # Midpoint rule on a grid of at most 10 ms, sampled at ts.
        h = min(0.01, duration / n)
        grid = np.arange(0.0, duration + h, h)
        P = p0.copy()
        out, k = [], 0
        for t0 in grid[:-1]:
            tm = np.array([t0 + h / 2])
            V = np.array([[float(e(tm)[0]) for e in a.velocity] if a.velocity is not None else [0.0, 0.0, 0.0] for a in agents])
            P = P + h * V
            while k < len(ts) and ts[k] <= t0 + h + 1e-12:
                out.append(P.copy())
                k += 1
        while len(out) < len(ts):
            out.append(P.copy())
    return [{a.id: tuple(row[n_]) for n_, a in enumerate(agents)} for row in out]
