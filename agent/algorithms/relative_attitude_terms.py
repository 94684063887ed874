"""Terms shared by the §4 observers of Boughellaba (2024) (relative attitudes, tree graph).

Orientation: edge k has a head h and a tail t (scenario ``[graph] edges``).
Its relative attitude error is ``R̄_k = R̃_t^T R̃_h = R̂_t R_ht^T R̂_h^T``
(Remark 4.3; ``R̃_i = R_i R̂_i^T``, ``R_ht = R_h^T R_t`` measured by h).  Agent
i computes it from its own measurement ``R_ij = R_i^T R_j`` of neighbour j:

* i heads edge k (j its tail):  ``R̄_k = R̂_j R_ij^T R̂_i^T``
* i is the tail (j the head):   ``R̄_k = R̂_i R_ij R̂_j^T``

With ``g_k = Ra(ξ_k, u) ψ(A R̄_k Ra(ξ_k, u))`` (Prop. 4.1), the correction of
(4.19)/(4.25) reads (READING-NOTES)

    σ_i = Σ_{k: i is tail} R̄_k g_k − Σ_{k: i is head} g_k,

and with every ξ_k = 0 it is (4.8), ``σ_i = −Σ_j ψ(A R̂_j R_ij^T R̂_i^T)``
(for a tail edge ``R̄ ψ(A R̄) = −ψ(A R̄^T)``).

Symbols -> names: R_ij ``R_ij``, R̂_j ``R_hat_j``, ξ_k ``xi``, b_ij^i ``b_own``,
b_ji^j ``b_nbr``, p̂_j ``p_hat_j``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from zswarm.families import synergistic
from zswarm.math.so3 import Mat3, T, Vec3, apply, dot, exp, mul, psi
from zswarm.scenario.algorithm import Field, View, number


@dataclass(frozen=True, slots=True)
class EdgeData:
    """What agent i has about tree neighbour j at a step (all aligned to the step's end).

    ``xi`` is ξ_k as received from the head j (unused when i heads the edge:
    then ξ_k is i's own state).  The bearing and position fields are used by
    the §4.4 position observer only.
    """

    k: int
    head: bool  # i heads edge k (owns ξ_k)
    R_ij: Mat3
    R_hat_j: Mat3
    xi: float = 0.0
    b_own: Vec3 | None = None
    b_nbr: Vec3 | None = None
    p_hat_j: Vec3 | None = None


def relative_error(R_hat_i: Mat3, e: EdgeData) -> Mat3:
    """``R̄_k`` of the edge between i and j, in the edge's orientation (Remark 4.3)."""
    if e.head:
        return mul(mul(e.R_hat_j, T(e.R_ij)), T(R_hat_i))
    return mul(mul(R_hat_i, e.R_ij), T(e.R_hat_j))


def continuous_correction(R_hat: Mat3, edges: tuple[EdgeData, ...], A: Mat3) -> Vec3:
    """``σ_i = −Σ_j ψ(A R̂_j R_ij^T R̂_i^T)`` of (4.8), inertial frame.  Broadcasts: with R̂_i
    and the R̂_j stacks (M, 3, 3) of M draws (R_ij shared or stacked), σ_i is (M, 3)."""
    s = np.zeros(3)
    for e in edges:
        s = s - psi(mul(mul(mul(A, e.R_hat_j), T(e.R_ij)), T(R_hat)))
    return s


def hybrid_correction(R_bars: Mapping[int, Mat3], edges: tuple[EdgeData, ...], xi: Mapping[int, float], A: Mat3, u: Vec3) -> Vec3:
    """``σ_i`` of (4.25) (READING-NOTES form); ``R_bars[k]`` (:func:`relative_error`) and ``xi[k]`` for every edge of i.
    Broadcasts over a leading draw axis of the R̄_k (and ξ_k)."""
    s = np.zeros(3)
    for e in edges:
        R_bar = R_bars[e.k]
        g = synergistic.grad_R(A, u, R_bar, xi[e.k])
        s = s - g if e.head else s + apply(R_bar, g)
    return s


def relative_position_rate(R_hat: Mat3, p_hat: Vec3, edges: tuple[EdgeData, ...]) -> Vec3:
    """``Σ_j R̂_i (P_{b_ij^i} R̂_i^T p̂_i − R_ij P_{b_ji^j} R̂_j^T p̂_j)`` of (4.30).

    Computed as ``Σ_j (P_{R̂_i b_ij^i} p̂_i − M_ij P_{R̂_j b_ji^j} p̂_j)`` with
    ``M_ij = R̂_i R_ij R̂_j^T`` (since ``R̂ P_b R̂^T = P_{R̂ b}``).
    """
    acc = np.zeros(3)
    for e in edges:
        if e.b_own is None or e.b_nbr is None or e.p_hat_j is None:
            continue
        gi = apply(R_hat, e.b_own)
        gi = gi / np.sqrt(dot(gi, gi))
        gj = apply(e.R_hat_j, e.b_nbr)
        gj = gj / np.sqrt(dot(gj, gj))
        Pj = e.p_hat_j - gj * dot(gj, e.p_hat_j)
        acc = acc + (p_hat - gi * dot(gi, p_hat)) - apply(mul(mul(R_hat, e.R_ij), e.R_hat_j.T), Pj)
    return acc



# --------------------------------------------------------------------------- inputs and messages (§4)

# What a §4 agent sends each tree neighbour: its attitude (and position) estimate,
# its gyro rate (to bring R̂_j to the receiver's tick), ξ_k when it heads the edge,
# and for the pose observer its bearing toward the receiver and R̂_j v_j^j.
EDGE_FIELDS: Mapping[str, Field] = MappingProxyType(
    {
        "R_hat": Field((3, 3), rotation=True, doc="R̂_j"),
        "p_hat": Field((3,), doc="p̂_j (zeros for the attitude observers)"),
        "w": Field((3,), doc="ω_j, the sender's gyro at its tick"),
        "xi": Field((), optional=True, doc="ξ_k, from the head of edge k"),
        "b": Field((3,), optional=True, doc="b_ji^j (§4.4)"),
        "vel": Field((3,), optional=True, doc="R̂_j v_j^j ≈ ṗ̂_j (§4.4)"),
    }
)


def edge_data(view: View, need_xi: bool) -> tuple[EdgeData, ...]:
    """Per tree neighbour j: every quantity of edge k brought to this tick.

    The measured ``R_ij = R_i^T R_j`` is from time t_s and j's estimate from
    its tick t_j; both are propagated with the gyros (ours, and j's rate
    sent with its estimate):
    ``R_ij(t) = exp(−τ_s[ω_i]) R_ij(t_s) exp(τ_s[ω_j])``,
    ``R̂_j(t) = R̂_j(t_j) exp((t − t_j)[ω_j])``.  Without this, pairing a
    10 ms old R̂_j with R_ij on an agent turning at 6.6 rad/s (§4.5, agent 5)
    biases R̄ by ≈ 0.07 rad.  Stamps are compared on this agent's clock,
    which assumes the agents' clocks are synchronised (as over one host).

    Until every neighbour has been heard once, no edge is used (only the gyro
    and velocity prediction runs): a correction from part of the tree would
    move R̂_i before its other edges are even evaluated (off the thesis'
    synchronous start, e.g. out of the §4.5 jump set before the first jump check).
    ``need_xi``: a tail edge is used only once its head's ξ_k has arrived.
    """
    if not view.heard_all():
        return ()
    edges = []
    s = view.sense
    tau_s = view.t - view.sense_t
    rel = s.get("rel_att", {})
    bearings = s.get("bearings", {})
    for j, (k, head) in view.tree_edges.items():
        R_m = rel.get(j)
        if R_m is None:
            continue
        m = view.neighbor(j)
        if m is None:
            continue  # nothing (fresh enough) from j: the edge's terms are left out
        f = m.fields
        if need_xi and not head and "xi" not in f:
            continue
        w_j = f["w"]
        tau_j = m.age
        b_own = bearings.get(j)
        if b_own is not None:
            b_t = view.body_vector(j, view.t_world) if view.moving else None
            b_own = apply(view.align, b_own) if b_t is None else b_t
        b_nbr = f.get("b")
        R_then = view.relative_attitude(j, m.t_world)
        if R_then is not None:
            # j's estimate is from its tick t_j: pair it with our measurement at t_j
            # and carry the pair to this tick with our own gyro.  R̂_j(t_j) R_ij(t_j)^T E_i
            # = R̃_j(t_j)^T R_i(t): exact but for R̃_j's own (slow, correction-driven) change
            # over τ_j, so nothing is left at convergence.  Extrapolating R̂_j and R_ij
            # separately with ω_j instead errs by ½ω̇τ² each, a floor of 1e-5–1e-4.
            R_ij = mul(T(view.rotation(m.t, view.t)), R_then)
            R_hat_j = f["R_hat"]
        else:
            # Older than the sensor history: propagate both with the gyros (first order).
            R_ij = mul(mul(view.align, R_m), exp(tau_s * w_j))
            R_hat_j = mul(f["R_hat"], exp(tau_j * w_j))
            if b_nbr is not None:
                b_nbr = apply(exp(-tau_j * w_j), b_nbr)
        if b_nbr is not None:
            b_then = view.body_vector(j, m.t_world) if (view.moving and b_own is not None) else None
            if b_then is not None and b_own is not None:
                # j's bearing is from its tick t_j; the inertial bearing b_ji = −b_ij
                # has turned since (0.5 rad/s in §4.5): our own bearing's change
                # over [t_j, t], in j's frame, corrects it.
                b_nbr = b_nbr - apply(R_ij.T, b_own - apply(view.rotation(m.t, view.t).T, b_then))
        edges.append(
            EdgeData(
                k,
                head,
                R_ij,
                R_hat_j,
                number(f.get("xi", 0.0)),
                b_own,
                b_nbr,
                f["p_hat"] + tau_j * f["vel"] if "vel" in f else f["p_hat"],
            )
        )
    return tuple(edges)


def edge_messages(view: View, R_hat: Mat3, p_hat: Vec3, xi: Mapping[int, float]) -> dict[int, dict[str, Any]]:
    """To each tree neighbour: R̂_i, p̂_i, ω_i, ξ_k of the edges we head, and (§4.4)
    our bearing toward it and R̂_i v_i^i (≈ ṗ̂_i during flows (4.30), which lets
    the receiver bring p̂_i to its tick)."""
    s = view.sense
    bearings = s.get("bearings", {})
    vel = apply(R_hat, apply(view.align, s["velocity_body"])) if "velocity_body" in s else None
    out: dict[int, dict[str, Any]] = {}
    for i in view.out_neighbors:
        fields: dict[str, Any] = {"R_hat": R_hat, "p_hat": p_hat, "w": s["gyro"]}
        b = bearings.get(i)
        if b is not None:
            b_tick = view.body_vector(i, view.t_world) if view.moving else None
            fields["b"] = apply(view.align, b) if b_tick is None else b_tick
        if vel is not None:
            fields["vel"] = vel
        k, head = view.tree_edges[i]
        if head and k in xi:
            fields["xi"] = xi[k]
        out[i] = fields
    return out
