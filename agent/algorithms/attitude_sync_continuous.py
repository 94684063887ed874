"""Continuous distributed attitude synchronization (thesis (5.24), §5.6's comparison law).

Boughellaba (2024), on the rigid bodies (5.1) of an undirected tree:

    τ_i = −k_ω ω_i − k_R Σ_{j∈N_i} ψ(A R_j^T R_i)                         (5.24)

(5.19) with every ξ_k = 0.  Almost global only: the states where every R̄_k
is a rotation by π about an eigenvector of A, ω = 0, are equilibria (the §5.6
start is one); they are unstable, so round-off, noise or asynchrony takes the
state off them, after a time that depends on how small that push is.

The law is static: a step computes τ_i from the step's measurements (ω_i
and each R_ij, both at the step's end) and sends it to the world, which
holds it until the next one (zero-order hold); R̄_k is carried half a period
ahead to the middle of that hold (attitude_sync_terms, "Sampled data").  It needs nothing from its
neighbours: R_j^T R_i = R_ij^T is measured (5.2), so it sends no edge messages.

Symbols -> names: ω_i ``omega``, τ_i ``tau``, k_ω ``k_omega``, k_R ``k_R``, A ``A``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from agent.algorithms.attitude_sync_terms import COMMAND, EDGE_FIELDS, Edge, continuous_coupling, measured_edges, predict
from zswarm.families import synergistic
from zswarm.math.so3 import Mat3, Vec3
from zswarm.scenario.algorithm import AlgorithmSpec, Initial, Part, Publish, StalePolicy, View


@dataclass(frozen=True, slots=True)
class Gains:
    k_R: float
    k_omega: float
    A: Mat3


@dataclass(frozen=True, slots=True)
class State:
    R_prev: Mapping[int, Mat3] = field(default_factory=dict)  # R̄_k of every edge at the last step


@dataclass(frozen=True, slots=True)
class Inputs:
    omega: Vec3  # ω_i measured at the step's end
    edges: tuple[Edge, ...]
    lead: float = 0.0  # s: the torque is evaluated this far ahead (half the hold interval)


@dataclass(frozen=True, slots=True)
class Outputs:
    tau: Vec3
    sigma: Vec3  # −Σ_j ψ(A R_j^T R_i)


def control(inputs: Inputs, gains: Gains, R_prev: Mapping[int, Mat3] | None = None, dt: float = 0.0) -> tuple[Vec3, Vec3]:
    """``(τ_i, σ_i)`` of (5.24), R̄_k predicted ``inputs.lead`` ahead from ``R_prev`` (``dt`` before)."""
    edges = inputs.edges
    if R_prev and inputs.lead > 0:
        edges = tuple(Edge(e.k, e.head, predict(R_prev.get(e.k), e.R_bar, dt, inputs.lead)) for e in edges)
    sigma = continuous_coupling(edges, gains.A)
    return -gains.k_omega * inputs.omega + gains.k_R * sigma, sigma


def step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    tau, sigma = control(inputs, gains, state.R_prev, dt)
    return State({e.k: e.R_bar for e in inputs.edges}), Outputs(tau, sigma)


def initial_state(init: Initial, gains: Gains) -> State:
    return State()


def inputs(view: View, gains: Gains) -> Inputs:
    return Inputs(np.asarray(view.sense["gyro"]), measured_edges(view, need_xi=False), view.command_lead)


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    est: dict[str, object] = {}
    if outputs is not None:
        est = {"tau": outputs.tau, "sigma": outputs.sigma}
    return Publish({}, est, {"tau": outputs.tau} if outputs is not None else None)


SPEC = AlgorithmSpec(
    description="thesis (5.24): continuous attitude synchronization, τ_i = −k_ω ω_i − k_R Σ_j ψ(A R_j^T R_i)",
    gains={"k_R": None, "k_omega": None},
    sensors=frozenset({"gyro", "rel_att"}),
    edge_in=EDGE_FIELDS,
    edge_out=EDGE_FIELDS,
    parts=(Part("control", inputs, step),),
    command=COMMAND,
    graph="tree",
    report="sync",
    params=synergistic.ContinuousParams,
    stale=StalePolicy(0.2, "hold"),
    batched=True,
    draw_gains=frozenset({"k_R", "k_omega"}),  # τ = −k_ω ω + k_R σ only
    sensor_use={"gyro": "ω_i, the damping −k_ω ω_i", "rel_att": "R_ij, the coupling"},
)
