"""Interaction graphs and the papers' assumptions on them.

Edges are directed ``(j, i)``: agent ``j`` sends to agent ``i`` and ``j`` is an
*in-neighbour* of ``i`` (``j ∈ N_i`` in the thesis' notation).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from zswarm.scenario.reading import ScenarioError, _Ctx

if TYPE_CHECKING:
    from zswarm.scenario.agent_config import AgentSpec


@dataclass(frozen=True, slots=True)
class Shape:
    """What an algorithm's graph (``SPEC.graph``) asks of a scenario's agents."""

    roles: bool = False  # every agent states its role, leader or follower (Assumptions 3.2/3.4)
    leaderless: str = ""  # why no agent may be a leader; "": one may, when the algorithm has a leader role
    oriented: bool = False  # the edges are the oriented tree of [graph] (Assumption 4.2), edge k the k-th


SHAPES: Mapping[str, Shape] = MappingProxyType(
    {
        "any": Shape(),
        "leader_follower": Shape(roles=True),
        "tree": Shape(leaderless="the §4 observers have no leaders: every agent estimates its attitude (up to a common rotation)", oriented=True),
        "sensing": Shape(),  # De Carli et al.: directed sensing (agents[].neighbors), undirected communication
    }
)


class GraphError(ValueError):
    """A graph that violates an assumption; ``field`` names what is wrong."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}")
        self.field = field
        self.problem = problem


def in_edges(neighbors: Mapping[int, Sequence[int]]) -> list[tuple[int, int]]:
    """All directed edges ``(j, i)`` with ``j ∈ N_i``, sorted."""
    return sorted((j, i) for i, nb in neighbors.items() for j in nb)


def out_neighbors(neighbors: Mapping[int, Sequence[int]]) -> dict[int, tuple[int, ...]]:
    """``{j: (i, ...)}``: the agents that have ``j`` as an in-neighbour."""
    out: dict[int, list[int]] = {j: [] for j in neighbors}
    for j, i in in_edges(neighbors):
        out.setdefault(j, []).append(i)
    return {j: tuple(sorted(v)) for j, v in out.items()}


def check_leader_follower(
    neighbors: Mapping[int, Sequence[int]],
    roles: Mapping[int, str],
    positions: Mapping[int, Sequence[float]],
    field_of: Mapping[int, str],
    collinear_tol: float = 1e-6,
    later: Sequence[Mapping[int, Sequence[float]]] = (),
) -> list[str]:
    """Check Assumption 3.2 (fixed agents) or 3.4 (moving agents) of the thesis.

    a) agents 1 and 2 are the leaders, with no in-neighbours;
    c) every follower ``i`` has ``|N_i| >= 2`` with ``N_i ⊆ {1..i-1}``, no two
       agents are collocated, and each follower's bearings to its neighbours
       are not all collinear (the matrix ``M_i = Σ b_ij b_ij^T`` has rank ≥ 2).

    ``positions`` are those at t = 0; ``later`` are snapshots over the run
    (moving agents).  Collocation at any snapshot is an error (Assumption
    3.5).  Bearings collinear at t = 0 are an error unless the motion excites
    them: the run-average of ``Σ_j P_{b_ij(t)}`` is positive definite (the
    persistent-excitation argument that makes the thesis' own §3.3.4
    scenario converge, where agent 4 and its two neighbours stay on one
    rotating line).  Such a follower is returned as a warning.

    ``field_of[i]`` is the scenario field of agent ``i`` (``agents[2]``), used
    in error messages.
    """
    warnings: list[str] = []
    ids = sorted(neighbors)
    for i in ids:
        f = field_of[i]
        nb = list(neighbors[i])
        if i in (1, 2):
            if roles[i] != "leader":
                raise GraphError(f"{f}.role", f"agent {i} must be a leader (Assumption 3.2a) (got {roles[i]!r})")
            if nb:
                raise GraphError(f"{f}.neighbors", f"a leader has no in-neighbours (Assumption 3.2a) (got {nb})")
            continue
        if roles[i] != "follower":
            raise GraphError(f"{f}.role", f"only agents 1 and 2 are leaders (Assumption 3.2a) (got {roles[i]!r})")
        if len(nb) < 2:
            raise GraphError(f"{f}.neighbors", f"a follower needs at least 2 in-neighbours (Assumption 3.2c) (got {nb})")
        if len(set(nb)) != len(nb):
            raise GraphError(f"{f}.neighbors", f"duplicate in-neighbour (got {nb})")
        for j in nb:
            if j not in neighbors:
                raise GraphError(f"{f}.neighbors", f"unknown agent {j} (got {nb})")
            if j >= i:
                raise GraphError(
                    f"{f}.neighbors",
                    f"in-neighbours must be numbered below the agent, N_i ⊆ {{1..{i - 1}}} (Assumption 3.2c) (got {j})",
                )
    for snap_no, snap in enumerate([positions, *later]):
        for a, i in enumerate(ids):
            for j in ids[a + 1 :]:
                if np.linalg.norm(np.subtract(snap[i], snap[j])) < 1e-9:
                    when = "" if snap_no == 0 else f" during the run (snapshot {snap_no})"
                    raise GraphError(f"{field_of[j]}.p", f"agent {j} is collocated with agent {i}{when} (Assumptions 3.2c/3.5) (got {list(snap[j])})")
    for i in ids:
        if roles[i] != "follower":
            continue
        sv = np.linalg.svd(np.array([_unit(positions[i], positions[j]) for j in neighbors[i]]), compute_uv=False)
        if len(sv) >= 2 and sv[1] >= collinear_tol:
            continue
        M = np.zeros((3, 3))
        for snap in later:
            for j in neighbors[i]:
                b = _unit(snap[i], snap[j])
                M += np.eye(3) - np.outer(b, b)
        lam = float(np.linalg.eigvalsh(M / len(later))[0]) if later else 0.0
        if lam < 1e-3:
            raise GraphError(
                f"{field_of[i]}.neighbors",
                f"bearings to in-neighbours are collinear at t = 0 and the motion does not excite them (run-average of Σ_j P_b_ij has "
                f"smallest eigenvalue {lam:.2g}); at least two must not be collinear (Assumption 3.2c/3.4c) (got N_{i} = {list(neighbors[i])})",
            )
        warnings.append(
            f"{field_of[i]}: agent {i}'s bearings to {list(neighbors[i])} are collinear at t = 0 (against Assumption 3.4c); "
            f"the motion excites them (run-average of Σ_j P_b_ij ≥ {lam:.2f}·I), so convergence rests on persistent excitation"
        )
    return warnings


def _unit(p_i: Sequence[float], p_j: Sequence[float]) -> np.ndarray:
    d = np.subtract(p_j, p_i, dtype=float)
    return d / np.linalg.norm(d)


def check_tree(ids: Sequence[int], edges: Sequence[tuple[int, int]], fld: str) -> None:
    """Assumption 4.2: the undirected graph of ``edges`` is a tree spanning ``ids``.

    No self-loops, no edge listed twice (in either orientation), connected and
    acyclic (so ``m = n - 1``).  ``fld`` names the scenario field in errors.
    """
    seen: dict[frozenset[int], int] = {}
    for k, (a, b) in enumerate(edges):
        if a == b:
            raise GraphError(f"{fld}[{k}]", f"self-loop on agent {a}")
        key = frozenset((a, b))
        if key in seen:
            raise GraphError(f"{fld}[{k}]", f"edge {a}-{b} listed twice (also {fld}[{seen[key]}])")
        seen[key] = k
    parent = {i: i for i in ids}

    def root(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    adj: dict[int, list[int]] = {i: [] for i in ids}
    for k, (a, b) in enumerate(edges):
        ra, rb = root(a), root(b)
        if ra == rb:
            cycle = _path(adj, a, b) + [a]
            raise GraphError(
                f"{fld}[{k}]",
                f"edge {a}-{b} closes the cycle {'-'.join(map(str, cycle))}; the graph must be an undirected tree (Assumption 4.2)",
            )
        parent[ra] = rb
        adj[a].append(b)
        adj[b].append(a)
    comps = sorted({root(i) for i in ids})
    if len(comps) > 1:
        parts = [sorted(i for i in ids if root(i) == r) for r in comps]
        raise GraphError(fld, f"the graph is not connected (components {parts}); it must be an undirected tree (Assumption 4.2)")


def _path(adj: Mapping[int, Sequence[int]], a: int, b: int) -> list[int]:
    """The path a ... b in a forest (breadth-first)."""
    prev: dict[int, int | None] = {a: None}
    queue = [a]
    while queue:
        x = queue.pop(0)
        if x == b:
            break
        for y in adj[x]:
            if y not in prev:
                prev[y] = x
                queue.append(y)
    out: list[int] = []
    node: int | None = b
    while node is not None:
        out.append(node)
        node = prev[node]
    return out[::-1]


# --------------------------------------------------------------------------- the scenario's graph
# §4's oriented tree ([graph] or derived) and De Carli's sensing graph, read for the loader.


def _tree(c: _Ctx, d: Any, agents: list[AgentSpec], seen: dict[int, str]) -> tuple[tuple[tuple[int, int], ...], str]:
    """The oriented tree of §4: ``[graph] edges = [[head, tail], ...]`` or derived from neighbours.

    Derived orientation (when ``[graph]`` is absent): each undirected edge
    ``{a, b}`` listed in ``agents[].neighbors`` gets head ``min(a, b)``; edges
    are indexed in ascending ``(head, tail)`` order.  Either way the result
    goes to ``summary.json``.
    """
    ids = {a.id for a in agents}
    if d is not None:
        g = c.table(d, "graph", {"edges"}, {"edges"})
        raw = g["edges"]
        if not isinstance(raw, list) or not raw:
            raise c.err("graph.edges", "must be a list of [head, tail] pairs", raw)
        pairs = []
        for n, e in enumerate(raw):
            if not isinstance(e, list) or len(e) != 2:
                raise c.err(f"graph.edges[{n}]", "must be a [head, tail] pair", e)
            h, t = (c.integer(x, f"graph.edges[{n}]") for x in e)
            for x in (h, t):
                if x not in ids:
                    raise c.err(f"graph.edges[{n}]", f"unknown agent {x}", e)
            pairs.append((h, t))
        fld, how = "graph.edges", "graph.edges"
    else:
        und = set()
        for a in agents:
            for j in a.neighbors:
                if j not in ids:
                    raise c.err(f"{seen[a.id]}.neighbors", f"unknown agent {j}", list(a.neighbors))
                und.add((min(a.id, j), max(a.id, j)))
        pairs = sorted(und)
        fld, how = "agents[].neighbors", "derived: head = smaller id, edges in ascending (head, tail) order"
    try:
        check_tree(sorted(ids), pairs, fld)
    except GraphError as exc:
        raise ScenarioError(f"{c.path}: {exc}") from None
    return tuple(pairs), how


def _sensing(c: _Ctx, doc: Mapping[str, Any], algo: str, agents: list[AgentSpec], seen: Mapping[int, str]) -> list[AgentSpec]:
    """A directed sensing graph (De Carli et al. §II): ``agents[].neighbors`` lists the robots
    each one senses; communication is its undirected counterpart, so every agent's
    neighbours become the robots it senses and those that sense it (``senses`` keeps the
    first).  Every robot needs a sensing edge, and the undirected graph must be connected."""
    if "graph" in doc:
        raise c.err("graph", f"{algo} takes its directed sensing graph from agents[].neighbors (the robots each one senses), not [graph]")
    ids = {a.id for a in agents}
    sensed_by: dict[int, set[int]] = {a.id: set() for a in agents}
    for a in agents:
        for j in a.neighbors:
            if j not in ids:
                raise c.err(f"{seen[a.id]}.neighbors", f"unknown agent {j}", list(a.neighbors))
            if j == a.id:
                raise c.err(f"{seen[a.id]}.neighbors", f"agent {a.id} cannot sense itself", list(a.neighbors))
            sensed_by[j].add(a.id)
    for a in agents:
        if not a.neighbors and not sensed_by[a.id]:
            raise c.err(f"{seen[a.id]}.neighbors", f"robot {a.id} has no sensing edge: it senses no robot and no robot senses it", [])
    comm = {a.id: set(a.neighbors) | sensed_by[a.id] for a in agents}
    start = agents[0].id
    reached, todo = {start}, [start]
    while todo:
        for j in comm[todo.pop()] - reached:
            reached.add(j)
            todo.append(j)
    if reached != ids:
        raise c.err("agents[].neighbors", f"the sensing graph's undirected version is disconnected: {sorted(reached)} do not reach {sorted(ids - reached)}")
    return [replace(a, senses=a.neighbors, neighbors=tuple(sorted(comm[a.id])), k_neighbors=(1.0,) * len(comm[a.id])) for a in agents]
