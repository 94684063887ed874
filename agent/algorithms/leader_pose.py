"""A leader of the §3 observers: it knows its pose (thesis Assumptions 3.2a, 3.4a).

Leaders run no observer: (R̂_l, p̂_l) = (R_l, p_l), measured.  Each tick it
sends what the followers' §3 observers read from a neighbour (R̂_l, p̂_l, its
bearing toward the follower b_li^l and, when it moves, v_l), all from the
newest sensor packet and stamped with that packet's acquisition time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from agent.algorithms.bearing_terms import EDGE_FIELDS
from zswarm.scenario.algorithm import AlgorithmSpec, Initial, Publish, StalePolicy, View


@dataclass(frozen=True, slots=True)
class Gains:
    pass


@dataclass(frozen=True, slots=True)
class State:
    pass


def initial_state(init: Initial, gains: Gains) -> State:
    return State()


def publish(state: State, outputs: Any, view: View) -> Publish | None:
    s = view.sense
    R, p = s.get("attitude"), s.get("position")
    if R is None or p is None:
        return None
    bearings = s.get("bearings", {})
    edges: dict[int, dict[str, Any]] = {}
    for i in view.out_neighbors:
        b = bearings.get(i)
        if b is None:
            continue
        edges[i] = {"R_hat": R, "p_hat": p, "b": b}
        if "velocity" in s:
            edges[i]["vel"] = s["velocity"]
    return Publish(edges, {"R_hat": R, "p_hat": p}, t=view.sense_t_world)


SPEC = AlgorithmSpec(
    description="a leader: publishes its measured pose (thesis Assumption 3.2a / 3.4a)",
    gains={},
    sensors=frozenset({"gyro", "bearings", "attitude", "position"}),
    edge_in={},
    edge_out=EDGE_FIELDS,
    parts=(),
    stale=StalePolicy(0.2, "hold"),
    batched=True,  # its functions broadcast over a leading draw axis (agent/batched.py)
)
