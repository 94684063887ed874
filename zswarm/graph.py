"""Interaction graphs and the papers' assumptions on them.

Edges are directed ``(j, i)``: agent ``j`` sends to agent ``i`` and ``j`` is an
*in-neighbour* of ``i`` (``j ∈ N_i`` in the thesis' notation).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np


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
