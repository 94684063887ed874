"""Measurement models of the thesis, with its noise and bias models.

* Gyro: ``ω_i^m = ω_i + b_ω_i + n``, ``n ~ N(0, gyro_var)`` per sample (thesis §3.2.5).
* Bearing: ``b_ij^i = R_i^T (p_j - p_i)/||p_j - p_i||`` (3.2); with noise, the
  projective model (3.18)–(3.19): perturb ``(b1/b3, b2/b3)`` by
  ``n ~ N(0, bearing_var)`` each, rebuild ``sign(b3)·(x, y, 1)/||(x, y, 1)||``.
* Relative attitude (4.2): ``R_ij = R_i^T R_j``; with noise (§4.5)
  ``R_ij exp([n_R]^x)``, ``n_R ~ N(0, rel_att_var)`` per axis.
* Own attitude (§5.6): ``R_i exp([n_R]^x)``, ``n_R ~ N(0, attitude_var)`` per axis.
* Velocity (inertial (3.21) or body frame (4.30)): ``v + n``, ``n ~ N(0, velocity_var)``
  per axis (§3.3.4: "linear and angular velocity measurements ... variance of 0.1").
* Relative position (De Carli et al. (2)): ``ⁱp_ij = R_i^T (p_j − p_i)`` plus
  ``n ~ N(0, rel_pos_var)`` per axis (the paper states no noise model; this is the
  simplest one for a range-and-bearing sensor such as an RGB-D camera).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zswarm.math.so3 import apply, exp, mul

Vec3 = NDArray[np.float64]


def bearings(R: NDArray[np.float64], p: NDArray[np.float64], i: NDArray[np.intp], j: NDArray[np.intp]) -> NDArray[np.float64]:
    """Body-frame bearings ``b_ij^i = R_i^T (p_j − p_i)/‖p_j − p_i‖`` (3.2) of the
    pairs ``(i[q], j[q])`` (indices into the stacks R (n, 3, 3), p (n, 3)), shape (P, 3)."""
    D = p[j] - p[i]
    D = D / np.sqrt(np.einsum("pk,pk->p", D, D))[:, None]
    return np.einsum("pki,pk->pi", R[i], D)


def noisy_bearing(b: Vec3, std: float, rng: np.random.Generator) -> Vec3:
    """Bearing noise model (3.18)–(3.19) with per-coordinate noise std ``std``.

    Near ``b3 = 0`` the projective coordinates blow up; there the model is
    undefined and the clean bearing is returned (|b3| < 1e-9 has probability
    zero for the papers' scenarios).
    """
    if std == 0.0:
        return b
    n1, n2 = rng.normal(0.0, std, 2)
    return projective_bearing(b, n1, n2)


def projective_bearing(b: Vec3, n1: Any, n2: Any) -> Any:
    """(3.18)–(3.19) with the noise ``n1, n2`` given: floats, or arrays (M,) of M draws' noise on
    one bearing (the batched engine), then (M, 3).  ``|v|²`` summed as ``(x² + y²) + 1``, the same
    operations either way (``v @ v`` may round otherwise)."""
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    if abs(b2) < 1e-9:
        return b if np.ndim(n1) == 0 else np.broadcast_to(b, (len(n1), 3))
    x = b0 / b2 + n1
    y = b1 / b2 + n2
    sign = math.copysign(1.0, b2)
    if np.ndim(x) == 0:
        return sign * np.array((x, y, 1.0)) / math.sqrt(x * x + y * y + 1.0)
    v = np.stack((x, y, np.ones_like(x)), axis=-1)
    return sign * v / np.sqrt(x * x + y * y + 1.0)[:, None]


def gyro(omega: Vec3, bias: Vec3, std: float, rng: np.random.Generator) -> Vec3:
    """Gyro measurement ``ω + b_ω + n`` with ``n ~ N(0, std²)`` per axis."""
    return omega + bias + rng.normal(0.0, std, 3) if std > 0 else omega + bias


def relative_attitude(R_i: NDArray[np.float64], R_j: NDArray[np.float64], std: float, rng: np.random.Generator) -> NDArray[np.float64]:
    """``R_ij = R_i^T R_j`` (4.2), times ``exp([n_R]^x)`` with ``n_R ~ N(0, std²)`` per axis."""
    R_ij = mul(R_i.T, R_j)
    return mul(R_ij, exp(rng.normal(0.0, std, 3))) if std > 0 else R_ij


def attitude(R: NDArray[np.float64], std: float, rng: np.random.Generator) -> NDArray[np.float64]:
    """Own attitude ``R_i exp([n_R]^x)``, ``n_R ~ N(0, std²)`` per axis (§5.6)."""
    return mul(R, exp(rng.normal(0.0, std, 3))) if std > 0 else R


def velocity(v: Vec3, std: float, rng: np.random.Generator) -> Vec3:
    """Velocity measurement ``v + n`` with ``n ~ N(0, std²)`` per axis."""
    return v + rng.normal(0.0, std, 3) if std > 0 else np.array(v, dtype=float)


def relative_position(R_i: NDArray[np.float64], p_i: Vec3, p_j: Vec3, std: float, rng: np.random.Generator) -> Vec3:
    """``ⁱp_ij = R_i^T (p_j − p_i)`` (De Carli et al. (2)) plus ``n ~ N(0, std²)`` per axis."""
    d = apply(R_i.T, p_j - p_i)
    return d + rng.normal(0.0, std, 3) if std > 0 else d
