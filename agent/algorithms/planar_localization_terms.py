"""Terms of De Carli, Restrepo and Robuffo Giordano (IEEE L-CSS 2024): the adaptive
relative-yaw observer, the common-frame yaw and position observers and the
formation control law, for robots with the kinematics (1)
``ṗ_i = R_z(ψ_i) v_i, ψ̇_i = ω_i`` (v_i body frame) that measure the body-frame
relative positions (2) ``ⁱp_ij = R_iᵀ(p_j − p_i)`` along directed sensing edges.

Pure functions on float64 arrays (and Python complex numbers for the unit
complex numbers of §III-B); each returns a rate (the right-hand side of the
equation it names) or the exact solution of the agent's own linear part over
a step with its neighbours' terms held.

Symbols -> names: ⁱp_ij ``p_ij``; ⁱp̂_ij ``p_hat``; ẑ_ψij ``z_hat`` (a 2-vector,
not renormalised: Remark 3); v_i, ω_i ``v_i``, ``w_i``; V̄_j (5) ``V_bar(v_j)``;
Ω_ij (6) ``Omega(w_j − w_i)``; Z ``Z``; k_pe ``k_pe``; k_ψ ``k_psi``;
ẑ_i (13) ``zc`` (complex); z_ij = e^{ιψ_ij} ``z_ij``; k_z ``k_z``;
p̂_i (21) ``p_hat_i``; R̂_i = R_z(∠ẑ_i) ``R_hat``; k_p ``k_p``; p*_i
``p_star``; k_c, ν_max ``k_c``, ``nu_max``.

Orientation of the in/out sums.  Edge (i, j) means *i senses j*.  In (21) the
sum over ``N_i^out`` carries ⁱp_ij, so j ∈ N_i^out are the robots i senses.
In (30) the paper's sum over ``N_i^in`` carries ⁱp_ij too: the two equations
name the same set differently, and we read (30) with the sums of (21) (the
robots i senses, then the robots that sense i).  The second sum of (30),
``R̂_jᵀ(p*_i − p*_j) − ʲp_ji``, is in robot j's body frame while v_i is in
robot i's; as printed the law mixes frames whenever ψ_i ≠ ψ_j.  We rotate it
into i's frame with the estimated ``R̂_iᵀR̂_j`` (= ⁱR_j once (13) has converged,
whatever α), which is what makes μ_i the gradient of the formation error.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

Vec2 = NDArray[np.float64]
Vec3 = NDArray[np.float64]
Mat3 = NDArray[np.float64]

Z = np.array([[1.0, 0.0], [0.0, -1.0]])  # z_ψji = Z z_ψij (relative yaw of the reverse edge)


def V_bar(v: Vec3) -> NDArray[np.float64]:
    """(5): ``V̄ = [[v_x, −v_y], [v_y, v_x], [0, 0]]`` (3×2), so that ``R_z(ψ) v = V̄ z_ψ + v_z e3``.
    The same map of a relative position is P̄ (26)."""
    return np.array([[v[0], -v[1]], [v[1], v[0]], [0.0, 0.0]])


def Omega(w_ij: float) -> NDArray[np.float64]:
    """(6): the skew-symmetric ``Ω_ij`` with ``ż_ψij = Ω_ij z_ψij``, ``ω_ij = ω_j − ω_i``."""
    return np.array([[0.0, -w_ij], [w_ij, 0.0]])


def Rz(psi: float) -> Mat3:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _cross_e3(p: Vec3) -> Vec3:
    """``S_e3 p = e3 × p``."""
    return np.array([-p[1], p[0], 0.0])


def relative_state_rates(
    p_hat: Vec3,
    z_hat: Vec2,
    p_ij: Vec3,
    v_i: Vec3,
    w_i: float,
    v_j: Vec3,
    w_j: float,
    k_pe: float,
    k_psi: float,
    reverse: tuple[Vec3, Vec3] | None = None,
) -> tuple[Vec3, Vec2]:
    """The adaptive relative-state observer of edge (i, j): (7), or (8) with ``reverse``.

    ``ⁱp̂̇_ij = −v_i − S_e3 ω_i ⁱp_ij + v_jz e3 + V̄_j ẑ_ψij − k_pe ⁱe_pij``,
    ``ẑ̇_ψij = Ω_ij ẑ_ψij − k_ψ V̄_jᵀ ⁱe_pij`` with ``ⁱe_pij = ⁱp̂_ij − ⁱp_ij``.
    For a bidirectional edge, ``reverse = (ʲe_pji, v_i)`` adds ``− k_ψ Z V̄_iᵀ ʲe_pji``
    to ẑ̇_ψij (8) (robot j's error of its own estimate of the reverse edge).
    Velocities are body-frame (m/s), ω in rad/s.
    """
    e_p = p_hat - p_ij
    Vj = V_bar(v_j)
    dp = -v_i - w_i * _cross_e3(p_ij) + np.array([0.0, 0.0, v_j[2]]) + Vj @ z_hat - k_pe * e_p
    dz = Omega(w_j - w_i) @ z_hat - k_psi * (Vj.T @ e_p)
    if reverse is not None:
        e_ji, v_own = reverse
        dz = dz - k_psi * (Z @ (V_bar(v_own).T @ e_ji))
    return dp, dz


def relative_yaw(z_hat: Vec2) -> complex:
    """The unit complex number ``z_ij = e^{ιψ̂_ij}`` of an estimate ẑ_ψij, renormalised when read
    (Remark 3); 1 when the estimate is (numerically) zero."""
    n = math.hypot(float(z_hat[0]), float(z_hat[1]))
    return complex(1.0, 0.0) if n < 1e-12 else complex(z_hat[0] / n, z_hat[1] / n)


def common_yaw_rate(zc: complex, w_i: float, terms: Iterable[tuple[complex, complex]], k_z: float) -> complex:
    """(13): ``ẑ̇_i = ι ω_i ẑ_i + k_z Σ_j (z̄_ij ẑ_j − ẑ_i)``; ``terms`` are (z_ij, ẑ_j) per neighbour."""
    acc = 0j
    for z_ij, zc_j in terms:
        acc += z_ij.conjugate() * zc_j - zc
    return 1j * w_i * zc + k_z * acc


def common_yaw_step(zc: complex, w_i: float, terms: list[tuple[complex, complex]], k_z: float, dt: float) -> complex:
    """(13) from ``t − dt`` to ``t``, ``terms`` the neighbours' (z_ij, ẑ_j) at ``t`` (what an
    agent has when its part runs: it steps over the interval just elapsed).

    ``ẑ̇ = a ẑ + c(s)``, ``a = ι ω_i − k_z |N_i|``, ``c = k_z Σ z̄_ij ẑ_j``, with ``c``
    held in the frame that turns with robot i, ``c(t − dt + s) = c(t) e^{ι ω_i (s − dt)}``,
    solved exactly: ``ẑ(t) = e^{a dt} ẑ(t − dt) + c(t) (1 − e^{−k_z |N_i| dt}) / (k_z |N_i|)``.

    On the fixed points (Proposition 1: ẑ_j = α z_j, z_ij = z̄_i z_j) every term
    ``z̄_ij ẑ_j = α z_i`` turns with robot i at exactly ω_i, so the step is exact there for
    any ``dt``; held constant instead (a zero-order hold) the terms lag the robot's turn and
    leave an error ∝ ω_i dt (measured on decarli-8-formation at 100 Hz: 4e-3)."""
    n = len(terms)
    ead = cmath.exp(complex(-k_z * n, w_i) * dt)
    if n == 0:
        return ead * zc
    kn = k_z * n
    c = k_z * sum((z_ij.conjugate() * zc_j for z_ij, zc_j in terms), 0j)
    return ead * zc + c * (dt if kn * dt < 1e-12 else -math.expm1(-kn * dt) / kn)


def position_rate(
    p_hat_i: Vec3,
    R_hat_i: Mat3,
    v_i: Vec3,
    out_terms: Iterable[tuple[Vec3, Vec3]],
    in_terms: Iterable[tuple[Vec3, Mat3, Vec3]],
    k_p: float,
) -> Vec3:
    """(21): ``p̂̇_i = R̂_i v_i − k_p [Σ_{j∈N_i^out}(p̂_i − p̂_j + R̂_i ⁱp_ij) + Σ_{j∈N_i^in}(p̂_i − p̂_j − R̂_j ʲp_ji)]``.

    ``out_terms``: (p̂_j, ⁱp_ij) for each robot i senses; ``in_terms``: (p̂_j, R̂_j, ʲp_ji)
    for each robot that senses i (its estimate, yaw estimate and measurement, received).
    """
    corr = np.zeros(3)
    for p_hat_j, p_ij in out_terms:
        corr += p_hat_i - p_hat_j + R_hat_i @ p_ij
    for p_hat_j, R_hat_j, p_ji in in_terms:
        corr += p_hat_i - p_hat_j - R_hat_j @ p_ji
    return R_hat_i @ v_i - k_p * corr


def formation_velocity(
    R_hat_i: Mat3,
    p_star_i: Vec3,
    out_terms: Iterable[tuple[Vec3, Vec3]],
    in_terms: Iterable[tuple[Vec3, Mat3, Vec3]],
    k_c: float,
    nu_max: float,
) -> tuple[Vec3, Vec3]:
    """(30): ``v_i = k_c k_i μ_i`` (body frame), ``k_i = min(1, ν_max/‖μ_i‖)``; returns (v_i, μ_i).

    ``μ_i = Σ_{j sensed by i} (ⁱp_ij − R̂_iᵀ(p*_j − p*_i)) + Σ_{j sensing i} R̂_iᵀR̂_j (R̂_jᵀ(p*_i − p*_j) − ʲp_ji)``
    (the second sum rotated into i's frame; module docstring).  ``out_terms``: (p*_j, ⁱp_ij);
    ``in_terms``: (p*_j, R̂_j, ʲp_ji).
    """
    mu = np.zeros(3)
    for p_star_j, p_ij in out_terms:
        mu += p_ij - R_hat_i.T @ (p_star_j - p_star_i)
    for p_star_j, R_hat_j, p_ji in in_terms:
        mu += R_hat_i.T @ (p_star_i - p_star_j) - R_hat_i.T @ (R_hat_j @ p_ji)
    n = float(np.linalg.norm(mu))
    k = 1.0 if n <= nu_max else nu_max / n
    return k_c * k * mu, mu


def position_step(
    p_hat_i: Vec3,
    R_hat_i: Mat3,
    v_i: Vec3,
    out_terms: list[tuple[Vec3, Vec3]],
    in_terms: list[tuple[Vec3, Mat3, Vec3]],
    k_p: float,
    dt: float,
    w_i: float = 0.0,
) -> Vec3:
    """(21) from ``t − dt`` to ``t``, the arguments their values at ``t``.

    Each term ``q_ij = p̂_j − R̂_i ⁱp_ij`` (or ``p̂_j + R̂_j ʲp_ji``) estimates p_i, so over the
    step it moves with robot i: ``q(s) = q(t) − ∫_s^t R̂_i v_i``.  With that, and R̂_i turning
    at ``w_i`` (R̂_i(t − u) = R̂_i R_z(−ω_i u), as (13) turns it) under the held body velocity
    ``v_i``, (21) is solved exactly:
    ``p̂(t) = e^{−a dt} (p̂(t − dt) + Δ) + (1 − e^{−a dt})/a · b``, ``a = k_p d_i``,
    ``b = k_p Σ q``, ``Δ = R̂_i ∫₀^dt R_z(−ω_i u) du v_i`` the robot's own displacement.
    On the consensus set (every q = p_i(t)) the step is exact for any dt; holding the
    terms at their end values instead leads p_i by ≈ |v| dt/2 (5 mm at 50 Hz and 0.5 m/s,
    the floor measured before)."""
    d = len(out_terms) + len(in_terms)
    b = np.zeros(3)
    for p_hat_j, p_ij in out_terms:
        b = b + k_p * (p_hat_j - R_hat_i @ p_ij)
    for p_hat_j, R_hat_j, p_ji in in_terms:
        b = b + k_p * (p_hat_j + R_hat_j @ p_ji)
    s = complex(0.0, w_i) * dt  # ∫₀^dt e^{−ι ω u} du = dt (1 − e^{−ι ω dt})/(ι ω dt)
    phi_xy = dt if abs(s) < 1e-12 else dt * (1.0 - cmath.exp(-s)) / s
    vc = complex(float(v_i[0]), float(v_i[1])) * phi_xy
    disp = R_hat_i @ np.array([vc.real, vc.imag, float(v_i[2]) * dt])
    a = k_p * d
    if a * dt < 1e-12:
        return p_hat_i + disp + dt * b
    e = math.exp(-a * dt)
    return e * (p_hat_i + disp) + (-math.expm1(-a * dt) / a) * b
