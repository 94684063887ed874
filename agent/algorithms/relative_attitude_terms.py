"""Terms shared by the §4 observers of Boughellaba (2024) (relative attitudes, tree graph).

Orientation: edge k has a head h and a tail t (scenario ``[graph] edges``).
Its relative attitude error is ``R̄_k = R̃_t^T R̃_h = R̂_t R_ht^T R̂_h^T``
(Remark 4.3; ``R̃_i = R_i R̂_i^T``, ``R_ht = R_h^T R_t`` measured by h).  Agent
i computes it from its own measurement ``R_ij = R_i^T R_j`` of neighbour j:

* i heads edge k (j its tail):  ``R̄_k = R̂_j R_ij^T R̂_i^T``
* i is the tail (j the head):   ``R̄_k = R̂_i R_ij R̂_j^T``

With ``g_k = Ra(ξ_k, u) ψ(A R̄_k Ra(ξ_k, u))`` (Prop. 4.1), the correction of
(4.19)/(4.25) reads (READING-NOTES)

    σ_i = Σ_{k: i is tail} R̄_k g_k − Σ_{k: i is head} g_k,

and with every ξ_k = 0 it is (4.8), ``σ_i = −Σ_j ψ(A R̂_j R_ij^T R̂_i^T)``
(for a tail edge ``R̄ ψ(A R̄) = −ψ(A R̄^T)``).

Symbols -> names: R_ij ``R_ij``, R̂_j ``R_hat_j``, ξ_k ``xi``, b_ij^i ``b_own``,
b_ji^j ``b_nbr``, p̂_j ``p_hat_j``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from zswarm import hybrid
from zswarm.so3 import Mat3, Vec3, psi


@dataclass(frozen=True, slots=True)
class EdgeData:
    """What agent i has about tree neighbour j at a step (all aligned to the step's end).

    ``xi`` is ξ_k as received from the head j (unused when i heads the edge:
    then ξ_k is i's own state).  The bearing and position fields are used by
    the §4.4 position observer only.
    """

    k: int
    head: bool  # i heads edge k (owns ξ_k)
    R_ij: Mat3
    R_hat_j: Mat3
    xi: float = 0.0
    b_own: Vec3 | None = None
    b_nbr: Vec3 | None = None
    p_hat_j: Vec3 | None = None


def relative_error(R_hat_i: Mat3, e: EdgeData) -> Mat3:
    """``R̄_k`` of the edge between i and j, in the edge's orientation (Remark 4.3)."""
    if e.head:
        return e.R_hat_j @ e.R_ij.T @ R_hat_i.T
    return R_hat_i @ e.R_ij @ e.R_hat_j.T


def continuous_correction(R_hat: Mat3, edges: tuple[EdgeData, ...], A: Mat3) -> Vec3:
    """``σ_i = −Σ_j ψ(A R̂_j R_ij^T R̂_i^T)`` of (4.8), inertial frame."""
    s = np.zeros(3)
    for e in edges:
        s = s - psi(A @ e.R_hat_j @ e.R_ij.T @ R_hat.T)
    return s


def hybrid_correction(R_bars: Mapping[int, Mat3], edges: tuple[EdgeData, ...], xi: Mapping[int, float], A: Mat3, u: Vec3) -> Vec3:
    """``σ_i`` of (4.25) (READING-NOTES form); ``R_bars[k]`` (:func:`relative_error`) and ``xi[k]`` for every edge of i."""
    s = np.zeros(3)
    for e in edges:
        R_bar = R_bars[e.k]
        g = hybrid.grad_R(A, u, R_bar, xi[e.k])
        s = s - g if e.head else s + R_bar @ g
    return s


def relative_position_rate(R_hat: Mat3, p_hat: Vec3, edges: tuple[EdgeData, ...]) -> Vec3:
    """``Σ_j R̂_i (P_{b_ij^i} R̂_i^T p̂_i − R_ij P_{b_ji^j} R̂_j^T p̂_j)`` of (4.30).

    Computed as ``Σ_j (P_{R̂_i b_ij^i} p̂_i − M_ij P_{R̂_j b_ji^j} p̂_j)`` with
    ``M_ij = R̂_i R_ij R̂_j^T`` (since ``R̂ P_b R̂^T = P_{R̂ b}``).
    """
    acc = np.zeros(3)
    for e in edges:
        if e.b_own is None or e.b_nbr is None or e.p_hat_j is None:
            continue
        gi = R_hat @ e.b_own
        gi = gi / np.sqrt(gi @ gi)
        gj = e.R_hat_j @ e.b_nbr
        gj = gj / np.sqrt(gj @ gj)
        Pj = e.p_hat_j - gj * (gj @ e.p_hat_j)
        acc = acc + (p_hat - gi * (gi @ p_hat)) - R_hat @ e.R_ij @ e.R_hat_j.T @ Pj
    return acc

