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
) -> None:
    """Check Assumption 3.2 of the thesis (leader–follower cascade).

    a) agents 1 and 2 are the leaders, with no in-neighbours;
    c) every follower ``i`` has ``|N_i| >= 2`` with ``N_i ⊆ {1..i-1}``, no two
       agents are collocated, and each follower's bearings to its neighbours
       are not all collinear (the matrix ``M_i = Σ b_ij b_ij^T`` has rank ≥ 2).

    ``field_of[i]`` is the scenario field of agent ``i`` (``agents[2]``), used
    in error messages.  Bearings are taken from ``positions`` at ``t = 0``.
    """
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
    for a, i in enumerate(ids):
        for j in ids[a + 1 :]:
            if np.linalg.norm(np.subtract(positions[i], positions[j])) < 1e-9:
                raise GraphError(f"{field_of[j]}.p", f"agent {j} is collocated with agent {i} (Assumption 3.2c) (got {list(positions[j])})")
    for i in ids:
        if roles[i] != "follower":
            continue
        B = []
        for j in neighbors[i]:
            d = np.subtract(positions[j], positions[i], dtype=float)
            B.append(d / np.linalg.norm(d))
        sv = np.linalg.svd(np.array(B), compute_uv=False)
        if len(sv) < 2 or sv[1] < collinear_tol:
            raise GraphError(
                f"{field_of[i]}.neighbors",
                f"bearings to in-neighbours are collinear; at least two must not be (Assumption 3.2c) (got N_{i} = {list(neighbors[i])})",
            )
