"""Hybrid distributed attitude observer from relative attitudes (thesis §4.3.2).

Boughellaba (2024), (4.25)–(4.26), after Wang & Tayebi (2022):

    Ṙ̂_i = R̂_i [ω_i − k_R R̂_i^T σ_i]^x,   σ_i as in (4.25)            (flows)
    ξ̇_k  = −k_ξ (γ ξ_k + 2 u^T ψ(A R̄_k Ra(ξ_k, u)))                  (4.25), (4.13)
    R̂_i⁺ = R̂_i,  ξ_k⁺ = ξ_k* = argmin_{ξ∈Ξ} U(R̄_k, ξ)                 (4.26), on a jump

for the edges k that agent i heads (ξ_k lives at the head and is sent to the
tail, Remark 4.4).  Flow set (4.15) and jump set (4.16) of agent i:

    F_i: every headed k has  U(R̄_k, ξ_k) − min_{ξ∈Ξ} U(R̄_k, ξ) ≤ δ
    J_i: some headed k has   U(R̄_k, ξ_k) − min_{ξ∈Ξ} U(R̄_k, ξ) ≥ δ

A jump sets ξ_k to the minimiser, where the gap is 0 < δ: the state after a
jump is in the flow set, so jumps cannot chain (no Zeno loop by
construction; :func:`jump_map` asserts it).

Discretisation per step: predict ``R̂⁻ = R̂ exp(dt[ω]^x)``; check the jump set
at ``R̂⁻`` and apply the jump map (jumps have priority, as in HyEQ); then flow
with Heun's method (explicit trapezoid, second order) on the correction:
σ₁, ξ̇₁ at (R̂⁻, ξ); the Euler point ``R̂₁ = exp(−dt k_R [σ₁]^x) R̂⁻``,
``ξ₁ = ξ + dt ξ̇₁``; σ₂, ξ̇₂ there; then ``R̂⁺ = exp(−dt k_R [(σ₁+σ₂)/2]^x) R̂⁻``,
``ξ⁺ = ξ + dt (ξ̇₁+ξ̇₂)/2`` (the tail's ξ_k and the neighbours' R̂_j held).  At
the thesis gains the correction's fastest rate is k_R λ_max(A) ≈ 13/s and
k_ξ γ ≈ 6.7/s, so dt·rate ≈ 0.13 and 0.07 at 100 Hz: Euler (a factor 1 − h
per step where the flow has e^{−h}) converged 4 % early (|R̄|_I < 1e-2 at
13.9 s against 14.5 s with agents at 1 kHz); Heun gives 14.8 s against 14.6 s.

Symbols -> names: R̂_i ``R_hat``, ξ_k ``xi[k]``, k_R ``k_R``, k_ξ ``k_xi``, A ``A``,
u ``u``, γ ``gamma``, δ ``delta``, Ξ ``Xi``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from agent.algorithms import relative_attitude_continuous
from agent.algorithms.relative_attitude_continuous import Inputs
from agent.algorithms.relative_attitude_terms import EdgeData, edge_data, edge_messages, hybrid_correction, relative_error
from zswarm.families import synergistic
from zswarm.math.so3 import Mat3, Vec3, exp, mul
from zswarm.scenario.algorithm import POSE_ESTIMATE, Initial, Part, Publish, View

__all__ = ["Gains", "State", "Inputs", "Outputs", "EdgeData", "flow_set", "jump_set", "jump_map", "flow_xi", "step", "SPEC"]


@dataclass(frozen=True, slots=True)
class Gains:
    k_R: float
    k_xi: float
    A: Mat3
    u: Vec3
    gamma: float
    delta: float
    Xi: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class State:
    R_hat: Mat3
    xi: Mapping[int, float] = field(default_factory=dict)  # ξ_k of the edges this agent heads


@dataclass(frozen=True, slots=True)
class Outputs:
    sigma: Vec3  # σ_i of (4.25), inertial frame: the mean of the step's two evaluations (Heun)
    jumps: tuple[tuple[int, float, float], ...]  # (edge k, ξ before, ξ after) at this step
    U: float  # Σ_{headed k} U(R̄_k, ξ_k) after the step's jumps, at R̂⁻


def gap(R_bar: Mat3, xi: float, g: Gains) -> float:
    """``U(R̄, ξ) − min_{ξ'∈Ξ} U(R̄, ξ')`` of (4.15)–(4.16)."""
    return synergistic.potential(g.A, g.u, g.gamma, R_bar, xi) - synergistic.best_xi(g.A, g.u, g.gamma, R_bar, g.Xi)[1]


def flow_set(R_bar: Mat3, xi: float, g: Gains) -> bool:
    """Edge k is in the flow set of its head (4.15)."""
    return gap(R_bar, xi, g) <= g.delta


def jump_set(R_bar: Mat3, xi: float, g: Gains) -> bool:
    """Edge k puts its head in the jump set (4.16)."""
    return gap(R_bar, xi, g) >= g.delta


def jump_map(R_bar: Mat3, xi: float, g: Gains) -> float:
    """``ξ_k⁺ = argmin_{ξ∈Ξ} U(R̄_k, ξ)`` (4.26); the result is in the flow set."""
    new = synergistic.best_xi(g.A, g.u, g.gamma, R_bar, g.Xi)[0]
    assert gap(R_bar, new, g) <= 0.0 < g.delta  # δ > 0 is checked when the scenario loads
    return new


def flow_xi(R_bar: Mat3, xi: float, g: Gains) -> float:
    """``ξ̇_k = −k_ξ ∇_ξ U(R̄_k, ξ_k)`` (4.13), (4.25)."""
    return -g.k_xi * synergistic.grad_xi(g.A, g.u, g.gamma, R_bar, xi)


def attitude_step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs, Mat3]:
    """One step of (4.25)–(4.26); also returns the predicted attitude R̂⁻ the step used."""
    R_pred = mul(state.R_hat, exp(dt * inputs.omega))
    R_bars = {e.k: relative_error(R_pred, e) for e in inputs.edges}  # R̄ does not depend on ξ
    xi = dict(state.xi)
    jumps = []
    for e in inputs.edges:
        if not e.head:
            continue
        R_bar = R_bars[e.k]
        if R_bar.ndim > 2:  # M draws (the batched engine): each jumps or flows; NaN where it flows
            best, u_best = synergistic.best_xi(gains.A, gains.u, gains.gamma, R_bar, gains.Xi)
            hit = synergistic.potential(gains.A, gains.u, gains.gamma, R_bar, xi[e.k]) - u_best >= gains.delta
            if hit.any():
                jumps.append((e.k, xi[e.k], np.where(hit, best, np.nan)))
                xi[e.k] = np.where(hit, best, xi[e.k])
        elif jump_set(R_bar, xi[e.k], gains):
            new = jump_map(R_bar, xi[e.k], gains)
            jumps.append((e.k, xi[e.k], new))
            xi[e.k] = new
    all_xi = {e.k: (xi[e.k] if e.head else e.xi) for e in inputs.edges}
    sigma = hybrid_correction(R_bars, inputs.edges, all_xi, gains.A, gains.u)
    U = 0.0
    rate1: dict[int, float] = {}
    for e in inputs.edges:
        if e.head:
            R_bar = R_bars[e.k]
            U += synergistic.potential(gains.A, gains.u, gains.gamma, R_bar, xi[e.k])
            rate1[e.k] = flow_xi(R_bar, xi[e.k], gains)
    # Heun: the flow's rates again at the Euler end point, then their mean.
    R1 = mul(exp(-dt * gains.k_R * sigma), R_pred)
    xi1 = {k: v + dt * rate1.get(k, 0.0) for k, v in xi.items()}
    R_bars1 = {e.k: relative_error(R1, e) for e in inputs.edges}
    sigma2 = hybrid_correction(R_bars1, inputs.edges, {e.k: (xi1[e.k] if e.head else e.xi) for e in inputs.edges}, gains.A, gains.u)
    nxt = dict(xi)
    for k, r1 in rate1.items():
        nxt[k] = xi[k] + 0.5 * dt * (r1 + flow_xi(R_bars1[k], xi1[k], gains))
    sigma_mean = 0.5 * (sigma + sigma2)
    return State(mul(exp(-dt * gains.k_R * sigma_mean), R_pred), nxt), Outputs(sigma_mean, tuple(jumps), U), R_pred


def step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    """Advance (4.25)–(4.26) by ``dt`` seconds (at most one jump per edge, then a flow)."""
    nxt, out, _ = attitude_step(state, inputs, dt, gains)
    return nxt, out


def initial_state(init: Initial, gains: Gains) -> State:
    return State(init.R_hat, init.edges_headed("xi"))


def inputs(view: View, gains: Gains) -> Inputs:
    return Inputs(view.body_rate(view.t - view.dt, view.t), edge_data(view, need_xi=True))


_ZERO3 = np.zeros(3)


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    est = {"R_hat": state.R_hat, "p_hat": _ZERO3, "xi": state.xi}
    if outputs is not None:
        est["sigma"] = outputs.sigma
    return Publish(edge_messages(view, state.R_hat, _ZERO3, state.xi), est)


SPEC = replace(
    relative_attitude_continuous.SPEC,
    description="thesis §4.3.2: hybrid observer (4.25)-(4.26) from relative attitudes",
    gains={"k_R": None, "k_xi": None},
    parts=(Part("observer", inputs, step),),
    params=synergistic.HybridParams,
    initial={**POSE_ESTIMATE, "xi": synergistic.XI_INITIAL},
    estimate=synergistic.XI_ESTIMATE,
    jumps=synergistic.XI_JUMPS,
)
