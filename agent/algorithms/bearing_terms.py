"""Terms shared by the §3.2 bearing-based observers of Boughellaba (2024).

Symbols -> names:

* ``b_ij^i`` (bearing from i to j measured in i's body frame) -> ``b_own``
* ``b_ji^j`` (bearing from j to i measured by j, received from j) -> ``b_nbr``;
  the thesis' ``b_ij^j = R_j^T b_ij = -b_ji^j`` (READING-NOTES).
* ``R̂_j, p̂_j`` (neighbour's estimates, received) -> ``R_hat_j``, ``p_hat_j``
* ``k_ij`` -> ``k``
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from zswarm.math import kernels
from zswarm.math.so3 import Mat3, T, Vec3, apply, cross, dot
from zswarm.scenario.algorithm import Field, View


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
    """``Σ_j k_ij (R̂_j b_ij^j × R̂_i b_ij^i)`` of (3.3)/(3.9), inertial frame.  Estimates may be
    stacks of M draws (the batched engine): R̂ (M, 3, 3), the result then (M, 3); so may the
    measurements (bearings (M, 3) with noise per draw).

    With ``b_ij^j = -b_ji^j``: each term is ``-(R̂_j b_ji^j) × (R̂_i b_ij^i)``.
    """
    if kernels.bearing_correction1 is not None:  # one draw in C, the same operations (zswarm/math/_kernels.c)
        out = np.empty(3)
        if kernels.bearing_correction1(R_hat, nbrs, out):
            return out
    s = np.zeros(3)
    for n in nbrs:
        s = s + n.k * cross(-apply(n.R_hat_j, n.b_nbr), apply(R_hat, n.b_own))
    return s


def _per_vector(x: Any) -> Any:
    """A value per vector as a factor of its vectors: a number as it is, a stack (...,) as (..., 1)."""
    return x[..., None] if isinstance(x, np.ndarray) and x.ndim else x


def position_rate(R_hat: Mat3, p_hat: Vec3, sigma: Vec3, k_p: float, nbrs: tuple[NeighborData, ...]) -> Vec3:
    """Right-hand side of (3.14), with the measured ``P_{b_ij^i}`` (READING-NOTES).

    ``ṗ̂_i = -[σ_i]^x p̂_i - k_p Σ_j R̂_i P_{b_ij^i} R̂_i^T (p̂_i - p̂_j)``.
    Since ``R̂ P_b R̂^T = P_{R̂ b}`` it is computed as ``P_{R̂_i b_ij^i}``.
    """
    if kernels.position_rate1 is not None:  # one draw in C, the same operations (zswarm/math/_kernels.c)
        out = np.empty(3)
        if kernels.position_rate1(R_hat, p_hat, sigma, k_p, nbrs, out):
            return out
    acc = np.zeros(3)
    for n in nbrs:
        g = apply(R_hat, n.b_own if n.b_pos is None else n.b_pos)
        g = g / _per_vector(np.sqrt(dot(g, g)))
        d = p_hat - n.p_hat_j
        acc = acc + (d - g * _per_vector(dot(g, d)))
    return -cross(sigma, p_hat) - k_p * acc


# --------------------------------------------------------------------------- inputs and messages (§3)

# What a §3 agent sends each out-neighbour i: its estimates and its bearing toward i.
EDGE_FIELDS: Mapping[str, Field] = MappingProxyType(
    {
        "R_hat": Field((3, 3), rotation=True, doc="R̂_j, the sender's attitude estimate"),
        "p_hat": Field((3,), doc="p̂_j, the sender's position estimate"),
        "b": Field((3,), doc="b_ji^j, the sender's body-frame bearing toward the receiver"),
        "vel": Field((3,), optional=True, doc="v_j, the sender's inertial velocity (moving agents)"),
    }
)


def neighbor_data(view: View) -> tuple[NeighborData, ...]:
    """Per in-neighbour j its (R̂_j, p̂_j, b_ji^j) and our own bearing b_ij^i, at this tick.

    Our bearing, sampled at the sensor packet's acquisition time, is turned to
    the tick's body frame with the gyro (``view.align``).  Moving agents: the
    inertial bearings turn (0.5 rad/s in §3.3.4), so j's R̂_j b_ij^j, sampled at
    j's stamp t_j, is paired with our own bearing at t_j (from the sensor
    history), turned to this tick's body frame by the gyro; p̂_j is brought to
    this tick with j's measured velocity.  Pairing with the newest bearing
    instead left a 4e-3 attitude floor over Zenoh (5–10 ms ages × 0.5 rad/s).
    """
    nbrs = []
    bearings = view.sense.get("bearings", {})
    for j, k in zip(view.neighbors, view.k_neighbors, strict=True):
        b_own = bearings.get(j)
        if b_own is None:
            continue
        m = view.neighbor(j)
        if m is None:
            continue  # no (fresh enough) data from j: its term is left out of the sums
        f = m.fields
        b_now = apply(view.align, b_own)
        if not view.moving:
            nbrs.append(NeighborData(k, f["R_hat"], f["p_hat"], f["b"], b_now))
            continue
        b_t = view.body_vector(j, view.t_world)
        if b_t is not None:
            b_now = b_t
        tau = m.age
        b_then = view.body_vector(j, m.t_world)
        b_att = b_now
        if b_then is not None:
            b_att = apply(T(view.rotation(m.t, view.t)), b_then)
        p_hat_j = f["p_hat"] + tau * f["vel"] if "vel" in f else f["p_hat"]
        nbrs.append(NeighborData(k, f["R_hat"], p_hat_j, f["b"], b_att, b_now))
    return tuple(nbrs)


def edge_messages(view: View, R_hat: Mat3, p_hat: Vec3) -> dict[int, dict[str, Any]]:
    """Our estimates and our bearing toward each out-neighbour, all at this tick.

    For moving agents the bearing rotation alone misses how far the bearing
    itself turned since the sample (translation: 0.5 rad/s in §3.3.4), so it is
    taken from the sensor history at the tick instead.
    """
    out: dict[int, dict[str, Any]] = {}
    bearings = view.sense.get("bearings", {})
    vel = view.sense.get("velocity")
    for i in view.out_neighbors:
        b = bearings.get(i)
        if b is None:
            continue
        b_tick = view.body_vector(i, view.t_world) if view.moving else None
        fields: dict[str, Any] = {"R_hat": R_hat, "p_hat": p_hat, "b": apply(view.align, b) if b_tick is None else b_tick}
        if vel is not None:
            fields["vel"] = vel
        out[i] = fields
    return out
