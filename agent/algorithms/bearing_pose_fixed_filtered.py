"""Filtered bearing-based distributed pose observer (thesis §3.2.3, §3.2.4).

Boughellaba (2024), attitude observer (3.8)–(3.9) and position observer (3.14):

    Ṙ̂_i = R̂_i [ω_i − R̂_i^T Ω_i]^x                                   (3.8)
    Ω̇_i = −k_Ω Ω_i + Σ_{j∈N_i} k_ij (R̂_j b_ij^j × R̂_i b_ij^i)       (3.9)
    ṗ̂_i = −[Ω_i]^x p̂_i − k_p Σ_{j∈N_i} R̂_i P_{b_ij^i} R̂_i^T (p̂_i − p̂_j)   (3.14), σ_i = Ω_i

Discretisation as in :mod:`bearing_pose_fixed`: predict ``R̂⁻ = R̂ exp(dt[ω]^x)``,
evaluate the innovation at ``R̂⁻``, correct ``R̂⁺ = exp(−dt[Ω]^x) R̂⁻`` and
Euler-step Ω and p̂.
Symbols -> names: R̂_i ``R_hat``, p̂_i ``p_hat``, Ω_i ``Omega``, k_Ω ``k_Omega``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from agent.algorithms import bearing_pose_fixed
from agent.algorithms.bearing_terms import NeighborData, bearing_correction, edge_messages, neighbor_data, position_rate
from zswarm.math.so3 import Mat3, Vec3, exp, mul
from zswarm.scenario.algorithm import Initial, Part, Publish, View


@dataclass(frozen=True, slots=True)
class Gains:
    k_Omega: float
    k_p: float


@dataclass(frozen=True, slots=True)
class State:
    R_hat: Mat3
    p_hat: Vec3
    Omega: Vec3


@dataclass(frozen=True, slots=True)
class Inputs:
    omega: Vec3
    neighbors: tuple[NeighborData, ...]


@dataclass(frozen=True, slots=True)
class Outputs:
    sigma: Vec3  # Σ k_ij (…), the raw innovation fed to (3.9)


def step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    """Advance (3.8)–(3.9)+(3.14) by ``dt`` seconds."""
    Omega = state.Omega
    R_pred = mul(state.R_hat, exp(dt * inputs.omega))
    innov = bearing_correction(R_pred, inputs.neighbors)
    p_dot = position_rate(R_pred, state.p_hat, Omega, gains.k_p, inputs.neighbors)
    R_next = mul(exp(-dt * Omega), R_pred)
    Omega_next = Omega + dt * (-gains.k_Omega * Omega + innov)
    return State(R_next, state.p_hat + dt * p_dot, Omega_next), Outputs(innov)


def initial_state(init: Initial, gains: Gains) -> State:
    return State(init.R_hat, init.p_hat, init.Omega)


def inputs(view: View, gains: Gains) -> Inputs:
    return Inputs(view.body_rate(view.t - view.dt, view.t), neighbor_data(view))


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    est = {"R_hat": state.R_hat, "p_hat": state.p_hat, "Omega": state.Omega}
    if outputs is not None:
        est["sigma"] = outputs.sigma
    return Publish(edge_messages(view, state.R_hat, state.p_hat), est)


SPEC = replace(
    bearing_pose_fixed.SPEC,
    description="thesis §3.2: filtered attitude observer (3.8)-(3.9) + position observer (3.14)",
    gains={"k_Omega": None, "k_p": None},
    draw_gains=frozenset({"k_Omega", "k_p"}),  # −k_Ω Ω, k_p Σ… only
    parts=(Part("observer", inputs, step),),
)
