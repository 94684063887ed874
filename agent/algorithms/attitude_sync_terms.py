"""Terms shared by the attitude synchronization laws of Boughellaba (2024), Chapter 5.

Rigid bodies (5.1) on an undirected tree with an arbitrary orientation: edge k
has a head h and a tail t, and ``R̄_k = R_t^T R_h`` (§5.2).  Agent i measures
``R_ij = R_i^T R_j`` (5.2) of each tree neighbour j, so it has R̄_k directly:

* i heads edge k (j its tail): ``R̄_k = R_j^T R_i = R_ij^T``
* i is the tail (j the head):  ``R̄_k = R_i^T R_j = R_ij``

With the potential (4.23) ``U(R̄, ξ) = tr(A(I − R̄ Ra(ξ,u))) + (γ/2)ξ²`` and
``g_k = ψ(R̄_k^T ∇_R̄ U) = Ra(ξ_k,u) ψ(A R̄_k Ra(ξ_k,u))`` (Prop. 4.1), the
coupling of (5.6)/(5.16) is (READING-NOTES)

    σ_i = Σ_{k: i is tail} R̄_k g_k − Σ_{k: i is head} g_k,

(5.19) is this sum written per neighbour (``R̄ ψ(A R̄ Q) ... `` with
``M ψ(A M) = −ψ(A M^T)``), and with every ξ_k = 0 it is (5.24)'s
``σ_i = −Σ_{j∈N_i} ψ(A R_j^T R_i)``.  ξ_k (5.21) lives at the head and is
sent to the tail (§5.5).

Sampled data.  The world holds each torque until the next one (ZOH), so a
torque computed from the state at t acts over [t, t + T] (T the agent's
period): on average T/2 late.  Against the spring of the coupling, whose
stiffness is about k_R·λ(A)·(edges) ≈ 12 per unit inertia at §5.6's gains, a
delay T/2 = 5 ms takes ≈ 12 × 0.005 = 0.06 off the damping k_ω = 0.1: the
hybrid law computed at t and held 10 ms never reached max_k |R̄_k|_I < 0.1 in
150 s (centralised integration), where the continuous-time law (0.5 ms)
does at 61.7 s.  So every law evaluates its torque at the middle of its hold
interval (t + T/2 on sim; over Zenoh also the measurement's age at the tick and
the transit to the world, View.command_lead): R̄_k carried on along its last measured change
(:func:`predict`), ξ_k flowed on to that R̄_k, ω_i as measured (a lag on the
damping term changes the stiffness, not the damping, to first order).  The
same centralised integration then gives 65.5 s / 103.3 s (0.1 / 0.01) against
61.7 s / 99.9 s for dt -> 0; predicting R̄ alone, with ξ at t, gave 49.4 s
(too fast: ξ and R̄ out of step).  The price: R̄'s measurement noise enters
the torque ×1.58 (the extrapolation (3/2)R̄(t) − (1/2)R̄(t − T)).

Lyapunov functions (Appendix C), used by the tests:

    V  = k_R Σ_k U(R̄_k, ξ_k) + Σ_i ω_i^T J_i ω_i                              (C.1)
    V̇  = −k_R k_ξ Σ_k (∇_ξ U_k)² − 2 k_ω Σ_i ‖ω_i‖²                           (C.6)
    V̂  = V + k_Q̃ Σ_i U(Q̃_i, ζ_i)   (without the k_ω term)                     (C.10)
    V̂̇  = −k_R k_ξ Σ_k (∇_ξ U_k)² − 2 k_Q̃ k_Q Σ_i ‖h_i‖² − k_Q̃ k_ζ Σ_i (∇_ζ U_i)²   (C.11)

with ``h_i = Ra(ζ_i,u) ψ(A Q̃_i Ra(ζ_i,u))``; a jump lowers V by at least
k_R δ_R̄ (C.7), and V̂ by at least min(k_R δ_R̄, k_Q̃ δ_Q̃).

Symbols -> names: R̄_k ``R_bar``, ξ_k ``xi``, ω_i ``omega``, τ_i ``tau``,
k_ω ``k_omega``, Q̃_i ``Q_tilde``, ζ_i ``zeta``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from zswarm.math import kernels
from zswarm.math.so3 import Mat3, T, Vec3, apply, dot, exp_batch, hat, log_batch, mul, psi, trace
from zswarm.math.trig import sincos
from zswarm.scenario.algorithm import Field, View, number


@dataclass(frozen=True, slots=True)
class Edge:
    """Edge k of agent i at a step's end: R̄_k (its orientation), and ξ_k as received
    from the head when i is the tail (unused when i heads k: then ξ_k is i's state)."""

    k: int
    head: bool
    R_bar: Mat3
    xi: float | None = None  # tail: ξ_k from the head's newest message (None: none yet)


# Head -> tail: ξ_k (5.21) lives at the head and is sent to the tail (§5.5).
EDGE_FIELDS: Mapping[str, Field] = MappingProxyType({"xi": Field((), optional=True, doc="ξ_k, from the head of edge k")})
COMMAND: Mapping[str, Field] = MappingProxyType({"tau": Field((3,), doc="τ_i, body-frame torque (5.1)")})


def measured_edges(view: View, need_xi: bool) -> tuple[Edge, ...]:
    """Every tree edge of this agent with R̄_k from the step's measurement of R_ij.

    The step ends at a sensor packet (the runtime steps to the newest
    measurement), so R_ij is measured at the step's time; if the world skipped
    samples there, the history is interpolated.  ``need_xi``: a tail reads
    ξ_k from its head's newest message at or before the step (None until one
    has arrived: :func:`tail_xi` then uses ξ_k(0), which every agent knows).
    """
    rel = view.sense.get("rel_att", {})
    at_packet = view.t == view.sense_t
    out = []
    for j, (k, head) in view.tree_edges.items():
        R_ij = rel.get(j) if at_packet else view.relative_attitude(j, view.t_world)
        if R_ij is None:
            continue
        xi = None
        if need_xi and not head:
            m = view.neighbor(j)
            if m is not None and "xi" in m.fields:
                xi = number(m.fields["xi"])
        out.append(Edge(k, head, T(R_ij) if head else R_ij, xi))
    return tuple(out)


def _trig(x: Any) -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
    """sin and cos for a float (math: a tenth of numpy's cost on one number) or a stack of draws."""
    return (np.sin, np.cos) if isinstance(x, np.ndarray) else (math.sin, math.cos)


def _times(R: Mat3, v: Vec3) -> Vec3:
    """``R v`` for one matrix, or for stacks (M, 3, 3) and (M, 3) (so3.apply: no BLAS, the same bits either way)."""
    return apply(R, v)


class Terms:
    """Everything the potential (4.23) needs about one R̄, for every ξ at once.

    With ``M = A R̄`` and ``K = [u]^x``, ``Ra(ξ,u) = I + sin ξ K + (1 − cos ξ) K²`` makes
    ``ψ(A R̄ Ra(ξ,u)) = p0 + sin ξ p1 + (1 − cos ξ) p2`` and
    ``tr(A R̄ Ra(ξ,u)) = t0 + sin ξ t1 + (1 − cos ξ) t2`` (ψ and tr are linear), so U,
    ∇_ξ U (Prop. 4.1), the gradient g and the ξ-rate coefficients cost a few flops per ξ:
    the jump test, the coupling and the ξ sub-steps all read one Terms per edge and step.
    With R̄ a stack (M, 3, 3) of M draws every term has the leading draw axis, and so do
    ξ and what the methods return.
    """

    __slots__ = ("p0", "p1", "p2", "t0", "t1", "t2", "abc", "K", "K2", "trA")

    def __init__(self, A: Mat3, u: Vec3, R_bar: Mat3) -> None:
        K, K2, trA = _geometry(A, u)
        one = R_bar.ndim == 2
        R = R_bar[None] if one else R_bar  # one draw goes the way of a stack of one: the same numbers
        if kernels.terms is not None:
            o = kernels.terms(A, K, u, R)  # the lines below, compiled (zswarm/math/_kernels.c)
        else:
            M = mul(A, R)  # so3.mul, so3.dot: the compiled loop's sums, no BLAS on either side
            MK = mul(M, K)
            MK2 = mul(MK, K)
            p = (psi(M), psi(MK), psi(MK2))
            o = np.concatenate([*(q.T for q in p), *(trace(X)[None] for X in (M, MK, MK2)), *(dot(q, u)[None] for q in p)])
        # o: (15, M), a row per quantity
        if one:
            r = o[:, 0]
            self.p0, self.p1, self.p2 = r[0:3], r[3:6], r[6:9]
            self.t0, self.t1, self.t2 = float(r[9]), float(r[10]), float(r[11])
            self.abc = (float(r[12]), float(r[13]), float(r[14]))
        else:
            self.p0, self.p1, self.p2 = o[0:3].T, o[3:6].T, o[6:9].T
            self.t0, self.t1, self.t2 = o[9], o[10], o[11]
            self.abc = (o[12], o[13], o[14])
        self.K, self.K2, self.trA = K, K2, trA

    def U(self, xi: float, gamma: float) -> float:
        """``U(R̄, ξ) = tr(A) − tr(A R̄ Ra(ξ,u)) + (γ/2) ξ²`` (4.23)."""
        sin, cos = _trig(xi)
        s, c = sin(xi), 1.0 - cos(xi)
        return self.trA - (self.t0 + s * self.t1 + c * self.t2) + 0.5 * gamma * xi * xi

    def grad_xi(self, xi: float, gamma: float) -> float:
        """``∇_ξ U = γ ξ + 2 u^T ψ(A R̄ Ra(ξ,u))`` (Prop. 4.1)."""
        a, b, c = self.abc
        sin, cos = _trig(xi)
        return gamma * xi + 2.0 * (a + b * sin(xi) + c * (1.0 - cos(xi)))

    def g(self, xi: float) -> Vec3:
        """``g = Ra(ξ,u) ψ(A R̄ Ra(ξ,u))`` (Prop. 4.1)."""
        if isinstance(xi, np.ndarray):
            s, c = np.sin(xi)[:, None], 1.0 - np.cos(xi)[:, None]
            p = self.p0 + s * self.p1 + c * self.p2
            return p + s * apply(self.K, p) + c * apply(self.K2, p)
        s, c = math.sin(xi), 1.0 - math.cos(xi)
        p = self.p0 + s * self.p1 + c * self.p2
        return p + s * apply(self.K, p) + c * apply(self.K2, p)


_GEOM: dict[bytes, tuple[Mat3, Mat3, float]] = {}


def _geometry(A: Mat3, u: Vec3) -> tuple[Mat3, Mat3, float]:
    """``([u]^x, [u]^x², tr A)``, cached per (A, u)."""
    key = A.tobytes() + u.tobytes()
    got = _GEOM.get(key)
    if got is None:
        K = hat(u)
        got = _GEOM[key] = (K, mul(K, K), float(np.trace(A)))
    return got


def tail_xi(edges: tuple[Edge, ...], xi_in: Mapping[int, float]) -> dict[int, float]:
    """ξ_k of the edges this agent is the tail of: as received, or ξ_k(0) until the head's first message."""
    return {e.k: (e.xi if e.xi is not None else number(xi_in.get(e.k, 0.0))) for e in edges if not e.head}


def coupling(edges: tuple[Edge, ...], xi: Mapping[int, float], A: Mat3, u: Vec3, terms: Mapping[int, Terms] | None = None) -> Vec3:
    """``σ_i`` of (5.6)/(5.16) in the form of (5.19): ``Σ_tail R̄_k g_k − Σ_head g_k``; ``xi[k]``
    for every edge of i (``terms[k]``: the edge's :class:`Terms`, if already built)."""
    s = np.zeros(edges[0].R_bar.shape[:-1] if edges else 3)
    for e in edges:
        t = terms[e.k] if terms is not None else Terms(A, u, e.R_bar)
        g = t.g(xi[e.k])
        s = s - g if e.head else s + _times(e.R_bar, g)
    return s


def continuous_coupling(edges: tuple[Edge, ...], A: Mat3) -> Vec3:
    """``σ_i = −Σ_{j∈N_i} ψ(A R_j^T R_i)`` of (5.24) (``R_j^T R_i`` is R̄_k at a head, R̄_k^T at a
    tail).  Broadcasts: with every R̄_k a stack (M, 3, 3) of M draws, σ_i is (M, 3)."""
    s = np.zeros(edges[0].R_bar.shape[:-1] if edges else 3)
    for e in edges:
        s = s - psi(mul(A, e.R_bar if e.head else T(e.R_bar)))
    return s


# Longest sub-step of the ξ_k (and ζ_i) flow.  ξ is a fast variable: near R̄ = I, ξ = 0,
# ∂ξ̇/∂ξ = −k_ξ (γ + u^T (tr(A) I − A) u) = −20 (1.93 + 15.0) = −338 /s at §5.6's gains,
# so one explicit step of the agents' 10 ms (dt·338 = 3.4) is unstable: the ξ_k of a
# first version swung past the jump set every step (6000 jumps in 20 s).  Heun at
# 0.5 ms has h·338 = 0.17 (local error (0.17)³/6 ≈ 1e-3 of the fast mode per sub-step).
XI_SUBSTEP_S = 5e-4


def xi_coefficients(A: Mat3, u: Vec3, R_bar: Mat3) -> tuple[float, float, float]:
    """``(a, b, c)`` with ``u^T ψ(A R̄ Ra(ξ,u)) = a + b sin ξ + c (1 − cos ξ)`` for every ξ
    (:class:`Terms`): the rate (5.21) of a fixed R̄ is a scalar function of ξ, so
    sub-steps cost a few flops each."""
    return Terms(A, u, R_bar).abc


def flow_xi(c0: tuple[float, float, float], c1: tuple[float, float, float], xi: float, dt: float, k_xi: float, gamma: float) -> float:
    """ξ after ``dt`` of (5.21) (or (5.23)), ``ξ̇ = −k_ξ(γξ + 2(a + b sin ξ + c(1 − cos ξ)))``,
    with (a, b, c) going linearly from ``c0`` (R̄ at the step's start) to ``c1`` (at its
    end; linear in R̄, so this is R̄ on the chord between the two measurements, within
    O(|ΔR̄|²) of the geodesic): Heun's method in sub-steps of at most XI_SUBSTEP_S, sin and cos
    by zswarm/math/trig.py (four draws to an instruction when compiled)."""
    if dt <= 0:
        return xi
    n = max(1, math.ceil(dt / XI_SUBSTEP_S - 1e-9))
    if kernels.flow_xi is not None:  # the loop below, compiled (zswarm/math/_kernels.c): the same numbers
        return kernels.flow_xi(c0, c1, xi, dt, k_xi, gamma, n)
    h = dt / n
    a0, b0, q0 = c0
    da, db, dq = c1[0] - a0, c1[1] - b0, c1[2] - q0
    two_k = 2.0 * k_xi
    kg = k_xi * gamma
    s, c = sincos(xi)  # zswarm/math/trig.py: the compiled loop's sin and cos, bit for bit
    f = -kg * xi - two_k * (a0 + b0 * s + q0 * (1.0 - c))
    for m in range(n):
        s1 = (m + 1) / n
        a1, b1, q1 = a0 + s1 * da, b0 + s1 * db, q0 + s1 * dq  # at the sub-step's end (both evaluations there)
        x1 = xi + h * f
        s, c = sincos(x1)
        f1 = -kg * x1 - two_k * (a1 + b1 * s + q1 * (1.0 - c))
        xi = xi + 0.5 * h * (f + f1)
        if m + 1 < n:  # the rate at the last sub-step's end is not needed
            s, c = sincos(xi)
            f = -kg * xi - two_k * (a1 + b1 * s + q1 * (1.0 - c))
    return xi


def jump(A: Mat3, u: Vec3, gamma: float, delta: float, S: tuple[float, ...], R_bar: Mat3, x: float, terms: Terms | None = None) -> float | None:
    """The jump map of (5.7)/(5.12): ``argmin_{x'∈S} U(R̄, x')`` (the first of equal minima)
    when ``U(R̄, x) − min_S U ≥ δ``, else None (flow).  With x a stack of M draws: an array
    of the draws' ξ⁺, NaN where a draw flows."""
    t = terms if terms is not None else Terms(A, u, R_bar)
    if isinstance(x, np.ndarray):
        Us = np.array([t.U(np.full_like(x, y), gamma) for y in S])  # (|S|, M)
        first = np.argmin(Us, axis=0)  # the first of equal minima, as the loop below
        u_best = Us[first, np.arange(len(x))]
        return np.where(t.U(x, gamma) - u_best >= delta, np.asarray(S, dtype=float)[first], np.nan)
    best, u_best = S[0], t.U(S[0], gamma)
    for y in S[1:]:
        v = t.U(y, gamma)
        if v < u_best:
            best, u_best = y, v
    if t.U(x, gamma) - u_best >= delta:
        return best
    return None


def predict(R_prev: Mat3 | None, R_now: Mat3, dt: float, lead: float) -> Mat3:
    """R̄ ``lead`` seconds after its newest measurement, on the geodesic through the last two
    (``dt`` apart): ``R̄ exp((lead/dt) log(R̄_prev^T R̄))`` (first order in the rate).
    Broadcasts over stacks (M, 3, 3); one draw goes the way of a stack of one, compiled
    (zswarm/math/_kernels.c) or in numpy: the same numbers."""
    if R_prev is None or dt <= 0 or lead <= 0:
        return R_now
    one = R_now.ndim == 2
    Rp, Rn = (R_prev[None], R_now[None]) if one else (np.broadcast_to(R_prev, R_now.shape), R_now)
    ratio = lead / dt
    if kernels.predict is not None:
        out = kernels.predict(Rp, Rn, ratio)
        near_pi = np.isnan(out[:, 0, 0])  # left to numpy (so3.log's branch near π)
        if near_pi.any():
            out[near_pi] = _predict(Rp[near_pi], Rn[near_pi], ratio)
    else:
        out = _predict(Rp, Rn, ratio)
    return out[0] if one else out


def _predict(Rp: np.ndarray, Rn: np.ndarray, ratio: float) -> np.ndarray:
    return mul(Rn, exp_batch(ratio * log_batch(mul(T(Rp), Rn))))


def published_xi(view: View, xi: Mapping[int, float]) -> dict[int, dict[str, Any]]:
    """To the tail of each edge this agent heads: ξ_k (the tails need nothing else)."""
    out: dict[int, dict[str, Any]] = {}
    for j in view.out_neighbors:
        k, head = view.tree_edges[j]
        if head and k in xi:
            out[j] = {"xi": xi[k]}
    return out
