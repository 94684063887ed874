"""Velocity-free hybrid distributed attitude synchronization (thesis §5.4, explicit form §5.5).

Boughellaba (2024), Theorem 5.2 (global asymptotic stability without ω_i):

    τ_i = k_R σ_i − k_Q̃ h_i,   h_i = Ra(ζ_i,u) ψ(A Q̃_i Ra(ζ_i,u)),  Q̃_i = Q_i^T R_i   (5.16), (5.20)
    Q̇_i = k_Q Q_i [Q̃_i h_i]^x                                                      (5.22)
    ζ̇_i = −k_ζ (γ ζ_i + 2 u^T ψ(A Q̃_i Ra(ζ_i,u)))                                 (5.23)
    ζ_i⁺ = argmin_{ζ∈Π} U(Q̃_i, ζ)  when U(Q̃_i, ζ_i) − min_Π U ≥ δ_Q̃                 (5.12)
    ξ_k as in the hybrid law: (5.21) and the jumps (5.7)

with σ_i the coupling of :mod:`attitude_sync_terms` (READING-NOTES: the
sign of ζ̇ in the stacked vector field (5.18) is a typo; (5.23) is right).
The auxiliary (Q_i, ζ_i) is a filter of the agent's own attitude R_i
(measured: the attitude sensor, §5.6's R_i exp([n_R]^x)) whose output h_i
supplies the damping that −k_ω ω_i gives the hybrid law.  No gyro.

Discretisation.  Q̃_i's error dynamics are stiff: near Q̃ = I they decay at
k_Q·½(tr A − λ_j(A)) = 204–308 /s at §5.6's gains (k_Q = 30), so one
explicit step of the agent's 10 ms would be unstable (dt·308 ≈ 3).  Each
step therefore integrates (Q_i, ζ_i) over its interval in sub-steps of at
most 1 ms (h·308 ≈ 0.3) with Heun's method on SO(3) × R (second order:
``Q⁺ = Q exp(h (w₁ + w₂)/2)``, ``w = k_Q Q̃ h_i``), R_i along the interval
interpolated on the geodesics between the attitude samples of the sensor
history (200 Hz); in practice it integrates Q̃_i by (5.14) with R_i's rate on that
path, which is the same flow.  Then the jump sets of ξ_k and ζ_i are checked at the
step's end and τ_i is computed there and sent (zero-order hold at the world),
its coupling k_R σ_i evaluated at the middle of the hold like the hybrid
law's (attitude_sync_terms, "Sampled data"); the damping term k_Q̃ h_i is
taken at t (a lag there changes the stiffness, not the damping, to first order).

Symbols -> names: Q_i ``Q``, Q̃_i ``Q_tilde``, ζ_i ``zeta``, ξ_k ``xi[k]``,
k_Q ``k_Q``, k_Q̃ ``k_Qt``, k_ζ ``k_zeta``, k_ξ ``k_xi``, δ_Q̃ ``delta_Q``, Π ``Pi``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agent.algorithms.attitude_sync_hybrid import flow_and_jump, held_coupling
from agent.algorithms.attitude_sync_terms import COMMAND, EDGE_FIELDS, Edge, Terms, jump, measured_edges, published_xi, tail_xi
from zswarm.families import synergistic
from zswarm.math import kernels
from zswarm.math.so3 import Mat3, Ra, T, Vec3, apply, exp, exp_batch, hat, log, mul, psi
from zswarm.math.trig import sincos
from zswarm.scenario.algorithm import IDENTITY, POSE_ESTIMATE, AlgorithmSpec, Initial, InitialField, Part, Publish, StalePolicy, View

SUBSTEP_S = 1e-3  # longest sub-step of the (Q_i, ζ_i) filter (see the module docstring)


@dataclass(frozen=True, slots=True)
class Gains:
    k_R: float
    k_xi: float
    k_Q: float
    k_Qt: float
    k_zeta: float
    A: Mat3
    u: Vec3
    gamma: float
    delta: float
    Xi: tuple[float, ...]
    delta_Q: float
    Pi: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class State:
    Q: Mat3
    zeta: float
    xi: Mapping[int, float] = field(default_factory=dict)
    xi_in: Mapping[int, float] = field(default_factory=dict)
    coef_prev: Mapping[int, tuple[float, float, float]] = field(default_factory=dict)
    R_prev: Mapping[int, Mat3] = field(default_factory=dict)  # R̄_k of every edge at the last step


@dataclass(frozen=True, slots=True)
class Inputs:
    R: tuple[tuple[float, Mat3], ...]  # own attitude samples (time relative to the step's end, ≤ 0; R_i), oldest first
    edges: tuple[Edge, ...]
    lead: float = 0.0  # s: the coupling is evaluated this far ahead (half the hold interval)


@dataclass(frozen=True, slots=True)
class Outputs:
    tau: Vec3
    sigma: Vec3
    h: Vec3  # h_i = Ra(ζ_i,u) ψ(A Q̃_i Ra(ζ_i,u))
    Q_tilde: Mat3
    jumps: tuple[tuple[int, float, float], ...]
    agent_jumps: tuple[tuple[float, float], ...]  # (ζ before, ζ after)


def _mv(Z: Any, p: Any) -> Any:
    """``Z p`` for one 3x3 or a stack (M, 3, 3) with (M, 3), summed ``(Z_r0 p_0 + Z_r1 p_1) + Z_r2 p_2``
    with every product rounded: an order that C can repeat (numpy's own matrix-vector
    kernels sum in an order of their own), so the compiled filter gives the same bits."""
    return (Z[..., 0] * p[..., 0, None] + Z[..., 1] * p[..., 1, None]) + Z[..., 2] * p[..., 2, None]


def _dot(p: Any, u: Vec3) -> Any:
    """``p · u`` for a 3-vector or a stack (M, 3): ``(p_0 u_0 + p_1 u_1) + p_2 u_2``, as :func:`_mv`."""
    return (p[..., 0] * u[0] + p[..., 1] * u[1]) + p[..., 2] * u[2]


def damping(Q_tilde: Mat3, zeta: float, g: Gains) -> tuple[Vec3, Vec3]:
    """``(h_i, ψ(A Q̃ Ra(ζ,u)))``: the gradient term of (5.20) and the ψ of (5.23)."""
    Z = Ra(zeta, g.u)
    p = psi(mul(mul(g.A, Q_tilde), Z))
    return apply(Z, p), p


class _Rates:
    """The flow (5.14) of Q̃_i = Q_i^T R_i and (5.23) of ζ_i for one set of gains, with
    ``Ra(ζ,u) = I + sin ζ K + (1 − cos ζ) K²`` from a precomputed ``K = [u]^x`` (the
    sub-steps call it 20 times a step)."""

    __slots__ = ("A", "K", "K2", "k_Q", "k_zeta", "gamma", "u2")

    def __init__(self, g: Gains) -> None:
        self.A = np.ascontiguousarray(g.A, dtype=float)
        self.K = hat(np.asarray(g.u, dtype=float))
        self.K2 = mul(self.K, self.K)
        self.k_Q, self.k_zeta, self.gamma = float(g.k_Q), float(g.k_zeta), float(g.gamma)
        self.u2 = 2.0 * np.asarray(g.u, dtype=float)

    def __call__(self, Qt: np.ndarray, zeta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(k_Q h_i, ζ̇)`` of M draws, Q̃ (M, 3, 3) and ζ (M,): Q̃̇ = Q̃ [ω_i − k_Q h_i]^x
        (5.14), equivalent to (5.22) for Q_i, and (5.23).  The operations of
        zswarm/math/_kernels.c's flow_aux, in its order."""
        sn, cs = sincos(zeta)  # zswarm/math/trig.py, as the compiled loop's
        Z = _EYE + sn[:, None, None] * self.K + (1.0 - cs)[:, None, None] * self.K2
        p = psi(mul(mul(self.A, Qt), Z))  # so3.mul: the compiled loop's sums (no BLAS)
        return self.k_Q * _mv(Z, p), -self.k_zeta * (self.gamma * zeta + _dot(p, self.u2))


_EYE = np.eye(3)
_RATES: dict[int, _Rates] = {}


def _rates(g: Gains) -> _Rates:
    r = _RATES.get(id(g))
    if r is None or r.k_Q != g.k_Q:
        r = _RATES[id(g)] = _Rates(g)
    return r


def attitude_path(samples: tuple[tuple[float, Mat3], ...]) -> list[tuple[float, float, Mat3, Vec3]]:
    """The geodesic segments between consecutive samples: ``(t0, t1, R0, log(R0^T R1))``."""
    return [(t0, t1, R0, log(mul(T(R0), R1))) for (t0, R0), (t1, R1) in zip(samples, samples[1:], strict=False) if t1 > t0]


def attitude_at(samples: tuple[tuple[float, Mat3], ...], s: float, path: list[tuple[float, float, Mat3, Vec3]] | None = None) -> Mat3:
    """R_i at time ``s`` (relative to the step's end) on the geodesic between the samples around it."""
    if s <= samples[0][0] or len(samples) == 1:
        return samples[0][1]
    for t0, t1, R0, w in path if path is not None else attitude_path(samples):
        if s <= t1:
            x = ((s - t0) / (t1 - t0)) * w  # one draw (3,) goes the way of a stack of one: exp_batch, as the stack's
            return mul(R0, exp_batch(np.reshape(x, (-1, 3))).reshape(np.shape(x)[:-1] + (3, 3)))
    return samples[-1][1]


def substep_rates(path: list[tuple[float, float, Mat3, Vec3]], s0: float, h: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The body rate of R_i on the piecewise geodesic at the middle of each of ``n`` sub-steps
    of ``h`` from ``s0``: a table of the segments' rates ``w/(t1 − t0)`` and a zero row last,
    (segments + 1, M, 3) (M = 1 for one draw), and each sub-step's row (0 before or after
    the samples)."""
    table = [w / (t1 - t0) for t0, t1, _R0, w in path]
    shape = (1, 3) if not path or np.ndim(path[0][3]) == 1 else np.shape(path[0][3])
    table.append(np.zeros(shape))
    rows = np.empty(n, dtype=np.int64)
    s = s0
    for m in range(n):
        mid = s + 0.5 * h
        rows[m] = next((i if mid >= t0 else len(path) for i, (t0, t1, _R0, _w) in enumerate(path) if mid <= t1), len(path))
        s += h
    return np.ascontiguousarray(np.stack([np.reshape(r, shape) for r in table])), rows


def flow_aux(Q: Mat3, zeta: Any, samples: tuple[tuple[float, Mat3], ...], dt: float, g: Gains) -> tuple[Mat3, Any]:
    """(Q_i, ζ_i) over the step ``[−dt, 0]``: Heun sub-steps of at most SUBSTEP_S on
    (Q̃_i, ζ_i) by (5.14), (5.23), with ω_i the rate of R_i's piecewise geodesic between the
    samples (taken at each sub-step's middle); then ``Q_i = R_i Q̃_i^T`` at the newest sample.
    The same flow as (5.22) for Q_i, without interpolating R_i at every sub-step.  One draw
    (Q (3, 3), ζ a float) or M (stacks): one draw goes the stacked way with M = 1, so that
    sim and the batched engine do the same arithmetic, compiled (zswarm/math/_kernels.c) or not."""
    n = max(1, math.ceil(dt / SUBSTEP_S - 1e-9))
    h = dt / n
    path = attitude_path(samples)
    Qt = mul(T(Q), attitude_at(samples, -dt, path))
    one = Qt.ndim == 2
    z = np.array([zeta], dtype=float) if one else np.asarray(zeta, dtype=float)
    Qt = Qt[None] if one else Qt
    table, rows = substep_rates(path, -dt, h, n)
    rates = _rates(g)
    if kernels.flow_aux is not None:
        Qt, z = kernels.flow_aux(Qt, z, table, rows, h, rates.A, rates.K, rates.K2, rates.u2, rates.k_Q, rates.k_zeta, rates.gamma)
    else:
        hh = 0.5 * h
        kh1, z1 = rates(Qt, z)
        for r in rows:
            w = table[r]
            v1 = w - kh1
            Qt1 = mul(Qt, exp(h * v1))
            kh2, z2 = rates(Qt1, z + h * z1)
            Qt = mul(Qt, exp(hh * (v1 + w - kh2)))
            z = z + hh * (z1 + z2)
            kh1, z1 = rates(Qt, z)
    if one:
        return mul(samples[-1][1], T(Qt[0])), float(z[0])
    return mul(samples[-1][1], T(Qt)), z


def step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    """Flow (Q_i, ζ_i) and ξ over ``dt``, jump, and compute τ_i at the step's end."""
    Q, zeta = state.Q, state.zeta
    if dt > 0:
        Q, zeta = flow_aux(Q, zeta, inputs.R, dt, gains)
    R = inputs.R[-1][1]
    Qt = mul(T(Q), R)
    agent_jumps = []
    tq = Terms(gains.A, gains.u, Qt)
    new = jump(gains.A, gains.u, gains.gamma, gains.delta_Q, gains.Pi, Qt, zeta, tq)
    if isinstance(new, np.ndarray):  # M draws: NaN where a draw flows
        hit = np.isfinite(new)
        if hit.any():
            agent_jumps.append((zeta, new))
            zeta = np.where(hit, new, zeta)
    elif new is not None:
        agent_jumps.append((zeta, new))
        zeta = new
    xi, jumps, coefs, terms = flow_and_jump(state.xi, state.coef_prev, inputs.edges, dt, gains)
    all_xi = tail_xi(inputs.edges, state.xi_in) | xi
    sigma = held_coupling(inputs.edges, all_xi, state.R_prev, dt, inputs.lead, gains, terms)
    h = tq.g(zeta)
    tau = gains.k_R * sigma - gains.k_Qt * h
    R_prev = {e.k: e.R_bar for e in inputs.edges}
    return State(Q, zeta, xi, state.xi_in, coefs, R_prev), Outputs(tau, sigma, h, Qt, tuple(jumps), tuple(agent_jumps))


def initial_state(init: Initial, gains: Gains) -> State:
    return State(np.array(init.values["Q"], dtype=float), float(init.values["zeta"]), init.edges_headed("xi"), init.edges_tailed("xi"))


def inputs(view: View, gains: Gains) -> Inputs | None:
    samples = view.series("attitude", view.t - view.dt, view.t)
    if not samples:
        return None
    rel = tuple((t - view.t, R) for t, R in samples)
    if rel[-1][0] < 0:
        rel = rel + ((0.0, rel[-1][1]),)  # the world skipped samples at the end: hold the newest
    return Inputs(rel, measured_edges(view, need_xi=True), view.command_lead)


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    est: dict[str, object] = {"xi": state.xi}
    if outputs is not None:
        est.update(tau=outputs.tau, sigma=outputs.sigma, Q=state.Q, zeta=state.zeta)
    return Publish(published_xi(view, state.xi), est, {"tau": outputs.tau} if outputs is not None else None)


SPEC = AlgorithmSpec(
    description="thesis §5.4/(5.20): velocity-free hybrid attitude synchronization with (Q_i, ζ_i) (5.22)-(5.23) and jumps (5.7), (5.12)",
    gains={"k_R": None, "k_xi": None, "k_Q": None, "k_Qt": None, "k_zeta": None},
    sensors=frozenset({"rel_att", "attitude"}),
    edge_in=EDGE_FIELDS,
    edge_out=EDGE_FIELDS,
    parts=(Part("control", inputs, step),),
    command=COMMAND,
    graph="tree",
    report="sync",
    params=synergistic.VelocityFreeParams,
    initial={
        **POSE_ESTIMATE,
        "xi": synergistic.XI_INITIAL,
        "Q": InitialField("rotation", IDENTITY, "Q_i(0), the auxiliary attitude (5.20)"),
        "zeta": InitialField("number", 0.0, "ζ_i(0) (5.22)"),
    },
    estimate=synergistic.XI_ESTIMATE,
    jumps={**synergistic.XI_JUMPS, **synergistic.ZETA_JUMPS},
    stale=StalePolicy(0.2, "hold"),
    batched=True,
    draw_gains=frozenset({"k_R", "k_Qt"}),  # τ = k_R σ − k_Q̃ h only (k_Q, k_ζ, k_ξ: the compiled filters take one)
    sensor_use={"attitude": "R_i, for Q̃_i = Q_i^T R_i of (5.20)-(5.23)", "rel_att": "R_ij, the coupling and the jump logic"},
)
