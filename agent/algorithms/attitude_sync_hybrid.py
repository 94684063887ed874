"""Hybrid distributed attitude synchronization (thesis §5.3, explicit form §5.5).

Boughellaba (2024), Theorem 5.1 (global asymptotic stability, finitely many
jumps), on the rigid bodies (5.1) of an undirected tree:

    τ_i = −k_ω ω_i + k_R σ_i,  σ_i = Σ_tail R̄_k g_k − Σ_head g_k        (5.6), (5.19)
    ξ̇_k = −k_ξ (γ ξ_k + 2 u^T ψ(A R̄_k Ra(ξ_k, u)))                        (5.21)
    ξ_k⁺ = argmin_{ξ∈Ξ} U(R̄_k, ξ)  when U(R̄_k, ξ_k) − min_Ξ U ≥ δ_R̄      (5.7)

for the edges k that agent i heads; the tail receives ξ_k (§5.5).

Sampled-data implementation: each step ends at a measurement (ω_i, R_ij at
t).  ξ_k flows over the step in Heun sub-steps of at most 0.5 ms (ξ is fast:
338 /s near the equilibrium at §5.6's gains, see attitude_sync_terms) with R̄_k
between the two measured ones (the previous step's and this one's), then the jump set is checked at t
(jumps have priority, as in HyEQ: at most one per edge and step, and the
state after a jump is in the flow set since δ > 0), then τ_i(t) is computed
and sent; the world holds it until the next one, so it is evaluated at the
middle of that hold (R̄_k and ξ_k predicted half a period ahead; see
attitude_sync_terms, "Sampled data").

Symbols -> names: ω_i ``omega``, τ_i ``tau``, ξ_k ``xi[k]``, R̄_k ``R_bar``,
k_ω ``k_omega``, k_R ``k_R``, k_ξ ``k_xi``, A ``A``, u ``u``, γ ``gamma``,
δ_R̄ ``delta``, Ξ ``Xi``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agent.algorithms.attitude_sync_terms import (
    COMMAND,
    EDGE_FIELDS,
    Edge,
    Terms,
    coupling,
    flow_xi,
    jump,
    measured_edges,
    number,
    predict,
    published_xi,
    tail_xi,
)
from zswarm.families import synergistic
from zswarm.math.so3 import Mat3, Vec3
from zswarm.scenario.algorithm import POSE_ESTIMATE, AlgorithmSpec, Initial, Part, Publish, StalePolicy, View


@dataclass(frozen=True, slots=True)
class Gains:
    k_R: float
    k_omega: float
    k_xi: float
    A: Mat3
    u: Vec3
    gamma: float
    delta: float
    Xi: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class State:
    xi: Mapping[int, float] = field(default_factory=dict)  # ξ_k of the edges this agent heads
    xi_in: Mapping[int, float] = field(default_factory=dict)  # ξ_k(0) of the edges it is the tail of
    coef_prev: Mapping[int, tuple[float, float, float]] = field(default_factory=dict)  # ξ-rate coefficients of the headed edges at the last step
    R_prev: Mapping[int, Mat3] = field(default_factory=dict)  # R̄_k of every edge at the last step (the prediction's baseline)


@dataclass(frozen=True, slots=True)
class Inputs:
    omega: Vec3  # ω_i measured at the step's end
    edges: tuple[Edge, ...]
    lead: float = 0.0  # s: the torque is evaluated this far ahead (half the hold interval, see attitude_sync_terms)


@dataclass(frozen=True, slots=True)
class Outputs:
    tau: Vec3
    sigma: Vec3
    jumps: tuple[tuple[int, float, float], ...]  # (edge k, ξ before, ξ after)
    U: float  # Σ_{headed k} U(R̄_k, ξ_k) after the step


def flow_and_jump(
    state_xi: Mapping[int, float], coef_prev: Mapping[int, tuple[float, float, float]], edges: tuple[Edge, ...], dt: float, g: Any
) -> tuple[dict[int, float], list[tuple[int, float, float]], dict[int, tuple[float, float, float]], dict[int, Terms]]:
    """ξ of the headed edges after the step's flow (5.21) and the jumps (5.7) at its end;
    also this step's ξ-rate coefficients (the next step's start) and every edge's Terms."""
    xi = dict(state_xi)
    jumps = []
    coefs = {}
    terms = {e.k: Terms(g.A, g.u, e.R_bar) for e in edges}
    for e in edges:
        if not e.head:
            continue
        x = xi[e.k]
        t = terms[e.k]
        c1 = coefs[e.k] = t.abc
        x = flow_xi(coef_prev.get(e.k, c1), c1, x, dt, g.k_xi, g.gamma)
        new = jump(g.A, g.u, g.gamma, g.delta, g.Xi, e.R_bar, x, t)
        if isinstance(new, np.ndarray):  # M draws: NaN where a draw flows
            hit = np.isfinite(new)
            if hit.any():
                jumps.append((e.k, x, new))
                x = np.where(hit, new, x)
        elif new is not None:
            jumps.append((e.k, x, new))
            x = new
        xi[e.k] = x
    return xi, jumps, coefs, terms


def held_coupling(
    edges: tuple[Edge, ...], xi: Mapping[int, float], R_prev: Mapping[int, Mat3], dt: float, lead: float, g: Any, terms: Mapping[int, Terms]
) -> Vec3:
    """σ_i at the middle of the hold interval: each R̄_k predicted ``lead`` ahead along its last
    change (:func:`predict`) and ξ_k flowed (5.21) to it (attitude_sync_terms, "Sampled data");
    ``terms``: each edge's Terms at its measured R̄_k."""
    if lead <= 0 or not R_prev:
        return coupling(edges, xi, g.A, g.u, terms)
    ahead = []
    xi_ahead = {}
    terms_ahead = {}
    for e in edges:
        Rp = predict(R_prev.get(e.k), e.R_bar, dt, lead)
        ahead.append(Edge(e.k, e.head, Rp, e.xi))
        t = terms_ahead[e.k] = Terms(g.A, g.u, Rp)
        xi_ahead[e.k] = flow_xi(terms[e.k].abc, t.abc, xi[e.k], lead, g.k_xi, g.gamma)
    return coupling(tuple(ahead), xi_ahead, g.A, g.u, terms_ahead)


def step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    """Flow ξ over ``dt``, jump, and compute τ_i for the hold interval that starts at the step's end."""
    xi, jumps, coefs, terms = flow_and_jump(state.xi, state.coef_prev, inputs.edges, dt, gains)
    all_xi = tail_xi(inputs.edges, state.xi_in) | xi
    sigma = held_coupling(inputs.edges, all_xi, state.R_prev, dt, inputs.lead, gains, terms)
    tau = -gains.k_omega * inputs.omega + gains.k_R * sigma
    U = sum(terms[e.k].U(xi[e.k], gains.gamma) for e in inputs.edges if e.head)
    R_prev = {e.k: e.R_bar for e in inputs.edges}
    return State(xi, state.xi_in, coefs, R_prev), Outputs(tau, sigma, tuple(jumps), number(U))


def initial_state(init: Initial, gains: Gains) -> State:
    return State(init.edges_headed("xi"), init.edges_tailed("xi"))


def inputs(view: View, gains: Gains) -> Inputs:
    return Inputs(np.asarray(view.sense["gyro"]), measured_edges(view, need_xi=True), view.command_lead)


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    est: dict[str, object] = {"xi": state.xi}
    if outputs is not None:
        est.update(tau=outputs.tau, sigma=outputs.sigma)
    return Publish(published_xi(view, state.xi), est, {"tau": outputs.tau} if outputs is not None else None)


SPEC = AlgorithmSpec(
    description="thesis §5.3/(5.19): hybrid attitude synchronization with ξ_k (5.21) and jumps (5.7)",
    gains={"k_R": None, "k_omega": None, "k_xi": None},
    sensors=frozenset({"gyro", "rel_att"}),
    edge_in=EDGE_FIELDS,
    edge_out=EDGE_FIELDS,
    parts=(Part("control", inputs, step),),
    command=COMMAND,
    graph="tree",
    report="sync",
    params=synergistic.HybridParams,
    initial={**POSE_ESTIMATE, "xi": synergistic.XI_INITIAL},
    estimate=synergistic.XI_ESTIMATE,
    jumps=synergistic.XI_JUMPS,
    # Hold: ξ_k changes slowly between jumps, and a tail without its head's ξ_k
    # would otherwise drop the edge from its torque.
    stale=StalePolicy(0.2, "hold"),
    sensor_use={"gyro": "ω_i, the damping −k_ω ω_i", "rel_att": "R_ij, the coupling and the jump logic"},
    batched=True,
    draw_gains=frozenset({"k_R", "k_omega"}),  # τ = −k_ω ω + k_R σ only (k_ξ: the compiled ξ filter takes one)
)
