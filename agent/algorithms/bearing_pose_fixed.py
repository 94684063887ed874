"""Bearing-based distributed pose observer, fixed positions (thesis §3.2.2, §3.2.4).

Boughellaba (2024), attitude observer (3.3) and position observer (3.14):

    Ṙ̂_i = R̂_i [ω_i − k_R R̂_i^T σ_i]^x,
    σ_i  = Σ_{j∈N_i} k_ij (R̂_j b_ij^j × R̂_i b_ij^i)           (the k_R is applied above)
    ṗ̂_i = −[k_R σ_i]^x p̂_i − k_p Σ_{j∈N_i} R̂_i P_{b_ij^i} R̂_i^T (p̂_i − p̂_j)

(the thesis' σ_i in (3.14) is ``k_R Σ …`` for this observer).

Discretisation (Lie–Trotter splitting of (3.3), first order like Lie–Euler):
predict with the gyro, ``R̂⁻ = R̂ exp(dt [ω]^x)``, then correct in the inertial
frame, ``R̂⁺ = exp(−dt [σ(R̂⁻)]^x) R̂⁻`` (since ``R̂ [R̂^T σ]^x = [σ]^x R̂``), and
``p̂⁺ = p̂ + dt ṗ̂(R̂⁻, σ)``.  Evaluating σ at the predicted attitude pairs R̂_i
with bearings measured at the *end* of the step, the instant the runtime
aligns them to; with σ frozen at the start of a 10 ms step instead, the
10 ms mismatch × |ω| ≈ 2.4 rad/s biases σ and leaves a ≈1e-2 error floor.

Symbols -> names: R̂_i ``R_hat``, p̂_i ``p_hat``, ω_i ``omega`` (body frame,
measured), k_R ``k_R``, k_p ``k_p``, k_ij ``NeighborData.k``.
Leaders (agents 1, 2) do not run the observer: (R̂_l, p̂_l) = (R_l, p_l).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from agent.algorithms.bearing_terms import EDGE_FIELDS, NeighborData, bearing_correction, edge_messages, neighbor_data, position_rate
from zswarm.math.so3 import Mat3, Vec3, exp, mul
from zswarm.scenario.algorithm import AlgorithmSpec, Initial, Part, Publish, StalePolicy, View


@dataclass(frozen=True, slots=True)
class Gains:
    k_R: float
    k_p: float


@dataclass(frozen=True, slots=True)
class State:
    R_hat: Mat3
    p_hat: Vec3


@dataclass(frozen=True, slots=True)
class Inputs:
    omega: Vec3  # body-frame angular velocity measurement, rad/s
    neighbors: tuple[NeighborData, ...]


@dataclass(frozen=True, slots=True)
class Outputs:
    sigma: Vec3  # k_R Σ k_ij (…), the innovation of (3.3), inertial frame


def step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    """Advance (3.3)+(3.14) by ``dt`` seconds (agent's own measured step)."""
    R_pred = mul(state.R_hat, exp(dt * inputs.omega))
    sigma = gains.k_R * bearing_correction(R_pred, inputs.neighbors)
    p_dot = position_rate(R_pred, state.p_hat, sigma, gains.k_p, inputs.neighbors)
    R_next = mul(exp(-dt * sigma), R_pred)
    return State(R_next, state.p_hat + dt * p_dot), Outputs(sigma)


def initial_state(init: Initial, gains: Gains) -> State:
    return State(init.R_hat, init.p_hat)


def inputs(view: View, gains: Gains) -> Inputs:
    """ω_i: the gyro's mean over the step; the neighbours' data at the tick."""
    return Inputs(view.body_rate(view.t - view.dt, view.t), neighbor_data(view))


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    est: dict[str, Any] = {"R_hat": state.R_hat, "p_hat": state.p_hat}
    if outputs is not None:
        est["sigma"] = outputs.sigma
    return Publish(edge_messages(view, state.R_hat, state.p_hat), est)


SPEC = AlgorithmSpec(
    description="thesis §3.2: attitude observer (3.3) + position observer (3.14)",
    gains={"k_R": None, "k_p": None},
    sensors=frozenset({"gyro", "bearings"}),
    edge_in=EDGE_FIELDS,
    edge_out=EDGE_FIELDS,
    parts=(Part("observer", inputs, step),),
    graph="leader_follower",
    # Hold: with fixed positions what a neighbour sends (R̂_j b_ji^j and p̂_j)
    # estimates constants, so an old value is as good as the neighbour's estimate was.
    stale=StalePolicy(0.2, "hold"),
    leader="leader_pose",
    batched=True,  # its functions broadcast over a leading draw axis (agent/batched.py)
    draw_gains=frozenset({"k_R", "k_p"}),  # k_R Σ…, k_p Σ… only
)
