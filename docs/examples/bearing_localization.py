"""Bearing-only network localization with known attitudes: a zswarm algorithm in one file.

Zhao & Zelazo, "Localizability and distributed protocols for bearing-based
network localization in arbitrary dimensions", Automatica 69 (2016), eq. (6):
each follower knows its attitude R_i (an attitude sensor), measures the
body-frame bearings b_ij^i to its neighbours and estimates its position

    ṗ̂_i = −k_p Σ_{j∈N_i} P_{g_ij} (p̂_i − p̂_j),   g_ij = R_i b_ij^i,   P_g = I − g gᵀ

from its neighbours' estimates p̂_j.  Leaders (anchors) know their position.
With fixed positions and a bearing-rigid, leader-anchored graph the
estimates converge exponentially to the true positions.

Its own parameter, ``[algorithm.params] v_max`` (m/s), bounds the speed of the
estimate: ṗ̂_i = −k_p r_i · min(1, v_max / (k_p ‖r_i‖)), r_i the sum above.  The
scaling is positive and per agent, so each step keeps the gradient's direction
and the error still decreases along it; far from the solution the estimate moves
at v_max instead of k_p ‖r_i‖.

Its runs are reported by its own family, ``bearing_fit`` (``bearing_fit.py``
beside this file): the bearing residual of every edge.

zswarm does not ship this observer: this file is the tutorial's
(docs/tutorial-own-algorithm.md).  Run it with

    zswarm sim docs/examples/bearing-localization8.toml
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from zswarm.scenario.algorithm import AlgorithmSpec, Field, Initial, Part, Publish, Reader, StalePolicy, View


@dataclass(frozen=True, slots=True)
class Params:
    """``[algorithm.params]``: the estimate's speed bound (m/s); its field goes to ``Gains.v_max``."""

    v_max: float
    jumps: ClassVar[bool] = False  # not a hybrid scheme

    @classmethod
    def load(cls, r: Reader, d: Any, fld: str) -> Params:
        d = r.table(d if d is not None else {}, fld, {"v_max"}, {"v_max"})
        return cls(r.num(d["v_max"], f"{fld}.v_max", positive=True))

    def gains(self, ids: tuple[int, ...]) -> dict[str, Any]:
        return {"v_max": self.v_max}


@dataclass(frozen=True, slots=True)
class Gains:
    k_p: float
    v_max: float  # from [algorithm.params]


@dataclass(frozen=True, slots=True)
class State:
    p_hat: np.ndarray  # p̂_i, inertial frame, m


@dataclass(frozen=True, slots=True)
class Inputs:
    # per in-neighbour j: (inertial bearing g_ij, p̂_j)
    neighbors: tuple[tuple[np.ndarray, np.ndarray], ...]


@dataclass(frozen=True, slots=True)
class Outputs:
    residual: np.ndarray  # Σ P_g (p̂_i − p̂_j), m


def initial_state(init: Initial, gains: Gains) -> State:
    return State(init.p_hat)


def inputs(view: View, gains: Gains) -> Inputs:
    """g_ij = R_i b_ij^i from the newest sensor packet (attitude and bearing sampled
    together); p̂_j from j's newest message (None: not heard yet, left out)."""
    R = view.sense["attitude"]
    bearings = view.sense["bearings"]
    nbrs = []
    for j in view.neighbors:
        m = view.neighbor(j)
        if m is None or j not in bearings:
            continue
        nbrs.append((R @ bearings[j], m.fields["p_hat"]))
    return Inputs(tuple(nbrs))


def step(state: State, inputs: Inputs, dt: float, gains: Gains) -> tuple[State, Outputs]:
    """One explicit Euler step of ṗ̂_i = −k_p r_i, r_i = Σ_j P_{g_ij}(p̂_i − p̂_j), at most v_max fast."""
    r = np.zeros(3)
    for g, p_j in inputs.neighbors:
        d = state.p_hat - p_j
        r = r + d - g * (g @ d)
    speed = gains.k_p * float(np.linalg.norm(r))
    scale = 1.0 if speed <= gains.v_max else gains.v_max / speed
    return State(state.p_hat - dt * gains.k_p * scale * r), Outputs(r)


def publish(state: State, outputs: Outputs | None, view: View) -> Publish:
    estimate: dict[str, Any] = {"R_hat": view.sense["attitude"], "p_hat": state.p_hat}
    if outputs is not None:
        estimate["residual"] = outputs.residual
    return Publish({i: {"p_hat": state.p_hat} for i in view.out_neighbors}, estimate)


SPEC = AlgorithmSpec(
    description="bearing-only network localization with known attitudes (Zhao & Zelazo 2016, eq. 6)",
    gains={"k_p": None},
    sensors=frozenset({"gyro", "bearings", "attitude"}),
    edge_in={"p_hat": Field((3,), doc="p̂_j")},
    edge_out={"p_hat": Field((3,), doc="p̂_i")},
    parts=(Part("localization", inputs, step),),
    graph="leader_follower",
    params=Params,  # [algorithm.params] v_max
    report="bearing_fit",  # its report family: bearing_fit.py beside this file
    stale=StalePolicy(0.2, "hold"),  # p̂_j estimates a constant: an old one is still good
    leader="leader_pose",
)
