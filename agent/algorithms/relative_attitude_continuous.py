"""Continuous distributed attitude observer from relative attitudes (thesis §4.3.1).

Boughellaba (2024), (4.3) with the correction (4.8), on an undirected tree:

    Ṙ̂_i = R̂_i [ω_i − k_R R̂_i^T σ_i]^x                                       (4.3)
    σ_i  = −Σ_{j∈N_i} ψ(A R̂_j R_ij^T R̂_i^T)                                 (4.8)

Theorem 4.1: almost global; the undesired equilibria (R̄_k = U D_β U^T) are
unstable but are equilibria, so a start on them stays there in exact
arithmetic.  Discretisation: predict ``R̂⁻ = R̂ exp(dt [ω]^x)``, then Heun's
method on the correction (second order, as in :mod:`relative_attitude_hybrid`,
whose gains give the same dt·k_R λ_max(A) ≈ 0.13 at 100 Hz): σ₁ at R̂⁻, σ₂ at
``exp(−dt k_R [σ₁]^x) R̂⁻``, ``R̂⁺ = exp(−dt k_R [(σ₁+σ₂)/2]^x) R̂⁻``.

Symbols -> names: R̂_i ``R_hat``, ω_i ``omega``, k_R ``k_R``, A ``A``,
R_ij ``EdgeData.R_ij``, R̂_j ``EdgeData.R_hat_j``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.algorithms.relative_attitude_terms import EDGE_FIELDS, EdgeData, continuous_correction, edge_data, edge_messages
from zswarm.families import synergistic
from zswarm.math.so3 import Mat3, Vec3, exp, mul
from zswarm.scenario.algorithm import AlgorithmSpec, Initial, Part, Publish, StalePolicy, View


@dataclass(frozen=True, slots=True)
class Gains:
    k_R: float
    A: Mat3


@dataclass(frozen=True, slots=True)
class State:
    R_hat: Mat3


@dataclass(frozen=True, slots=True)
class Inputs:
    omega: Vec3  # body-frame angular velocity measurement, rad/s
    edges: tuple[EdgeData, ...]


@dataclass(frozen=True, slots=True)
class Outputs:
    sigma: Vec3  # σ_i of (4.8), inertial frame


def step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    """Advance (4.3)+(4.8) by ``dt`` seconds."""
    R_pred = mul(state.R_hat, exp(dt * inputs.omega))
    sigma = continuous_correction(R_pred, inputs.edges, gains.A)
    # Heun (see the module docstring): σ again at the Euler point, then the mean.
    sigma2 = continuous_correction(mul(exp(-dt * gains.k_R * sigma), R_pred), inputs.edges, gains.A)
    sigma_mean = 0.5 * (sigma + sigma2)
    return State(mul(exp(-dt * gains.k_R * sigma_mean), R_pred)), Outputs(sigma_mean)


def initial_state(init: Initial, gains: Gains) -> State:
    return State(init.R_hat)


def inputs(view: View, gains: Gains) -> Inputs:
    return Inputs(view.body_rate(view.t - view.dt, view.t), edge_data(view, need_xi=False))


_ZERO3 = np.zeros(3)


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    est = {"R_hat": state.R_hat, "p_hat": _ZERO3}
    if outputs is not None:
        est["sigma"] = outputs.sigma
    return Publish(edge_messages(view, state.R_hat, _ZERO3, {}), est)


SPEC = AlgorithmSpec(
    description="thesis §4.3.1: continuous observer (4.3) + (4.8) from relative attitudes",
    gains={"k_R": None},
    sensors=frozenset({"gyro", "rel_att"}),
    edge_in=EDGE_FIELDS,
    edge_out=EDGE_FIELDS,
    parts=(Part("observer", inputs, step),),
    graph="tree",
    report="tree",
    params=synergistic.ContinuousParams,
    # Drop: a neighbour's R̂_j is brought to the tick with its last ω_j, an
    # extrapolation whose error grows with the age (½ω̇τ²).
    stale=StalePolicy(0.2, "drop"),
    batched=True,
    draw_gains=frozenset({"k_R"}),  # exp(−dt k_R σ) only
)
