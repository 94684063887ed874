"""Terms shared by the §3.2 bearing-based observers of Boughellaba (2024).

Symbols -> names:

* ``b_ij^i`` (bearing from i to j measured in i's body frame) -> ``b_own``
* ``b_ji^j`` (bearing from j to i measured by j, received from j) -> ``b_nbr``;
  the thesis' ``b_ij^j = R_j^T b_ij = -b_ji^j`` (READING-NOTES).
* ``R̂_j, p̂_j`` (neighbour's estimates, received) -> ``R_hat_j``, ``p_hat_j``
* ``k_ij`` -> ``k``
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zswarm.so3 import Mat3, Vec3, cross


@dataclass(frozen=True, slots=True)
class NeighborData:
    """What agent i has about in-neighbour j at a step.

    ``b_own`` is i's body-frame bearing toward j (``b_ij^i``); ``b_nbr`` is
    j's body-frame bearing toward i (``b_ji^j``) as sent by j with
    ``R_hat_j`` and ``p_hat_j`` (Assumption 3.2b).
    """

    k: float
    R_hat_j: Mat3
    p_hat_j: Vec3
    b_nbr: Vec3
    b_own: Vec3
    # i's bearing at the step's end for the projection of (3.14)/(3.25), when it
    # differs from b_own (moving agents: b_own is then paired with j's sample time)
    b_pos: Vec3 | None = None


def bearing_correction(R_hat: Mat3, nbrs: tuple[NeighborData, ...]) -> Vec3:
    """``Σ_j k_ij (R̂_j b_ij^j × R̂_i b_ij^i)`` of (3.3)/(3.9), inertial frame.

    With ``b_ij^j = -b_ji^j``: each term is ``-(R̂_j b_ji^j) × (R̂_i b_ij^i)``.
    """
    s = np.zeros(3)
    for n in nbrs:
        s = s + n.k * cross(-(n.R_hat_j @ n.b_nbr), R_hat @ n.b_own)
    return s


def position_rate(R_hat: Mat3, p_hat: Vec3, sigma: Vec3, k_p: float, nbrs: tuple[NeighborData, ...]) -> Vec3:
    """Right-hand side of (3.14), with the measured ``P_{b_ij^i}`` (READING-NOTES).

    ``ṗ̂_i = -[σ_i]^x p̂_i - k_p Σ_j R̂_i P_{b_ij^i} R̂_i^T (p̂_i - p̂_j)``.
    Since ``R̂ P_b R̂^T = P_{R̂ b}`` it is computed as ``P_{R̂_i b_ij^i}``.
    """
    acc = np.zeros(3)
    for n in nbrs:
        g = R_hat @ (n.b_own if n.b_pos is None else n.b_pos)
        g = g / np.sqrt(g @ g)
        d = p_hat - n.p_hat_j
        acc = acc + (d - g * (g @ d))
    return -cross(sigma, p_hat) - k_p * acc
