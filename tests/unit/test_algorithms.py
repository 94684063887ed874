"""The §3.2 observers against properties of the math (thesis §3.2.2–3.2.4).

With leader neighbours (R̂_j = R_j, p̂_j = p_j) the attitude error
R̃ = R R̂^T of (3.3) obeys dR̃/dt = R̃[σ]^x with σ = k_R Σ k (b × R̃^T b), so
V(R̃) = Σ_j k_ij (1 − b_ij^T R̃ b_ij) has dV/dt = −|σ|²/k_R ≤ 0.  The tests
step the discrete observer with dt = 1 ms and check V decreases at every
step (an O(dt²) discretisation term is far below the O(dt) decrease away
from equilibria), and that the true pose is an equilibrium.
"""

import numpy as np
import pytest

from agent.algorithms import bearing_pose_fixed as fixed
from agent.algorithms import bearing_pose_fixed_filtered as filt
from agent.algorithms.bearing_terms import NeighborData
from zswarm.math import so3
from zswarm.math.timing import interval_mean_rate

P = {1: np.array([0.0, 0, 0]), 2: np.array([2.0, 0, 1]), 3: np.array([2.0, 2, 2])}


def unit(v):
    return v / np.linalg.norm(v)


def neighbours(R_true, R_hat, p_hat_i, leaders_R):
    """Leader neighbour data for agent 3, from true attitudes."""
    out = []
    for j in (1, 2):
        b_ij = unit(P[j] - P[3])
        b_own = R_true.T @ b_ij  # b_3j^3
        b_nbr = leaders_R[j].T @ (-b_ij)  # b_j3^j
        out.append(NeighborData(1.0, leaders_R[j], P[j], b_nbr, b_own))
    return tuple(out)


def V(Rt):
    return sum(1 - unit(P[j] - P[3]) @ Rt @ unit(P[j] - P[3]) for j in (1, 2))


@pytest.mark.parametrize("theta", [0.3, 1.5, 2.8])
def test_attitude_lyapunov_decreases_along_steps(theta):
    rng = np.random.default_rng(0)
    R = so3.exp(rng.normal(size=3))
    R_hat = so3.Ra(theta, np.array([0.2, 1, -0.4])).T @ R  # R̃ = R R̂^T = Ra(θ)... rotated
    leaders = {1: so3.exp(rng.normal(size=3)), 2: so3.exp(rng.normal(size=3))}
    st = fixed.State(R_hat, np.zeros(3))
    g = fixed.Gains(k_R=1.0, k_p=1.0)
    dt = 1e-3
    w = np.array([0.5, -1.0, 0.8])
    v_prev = V(R @ st.R_hat.T)
    for _ in range(2000):
        nb = neighbours(R, st.R_hat, st.p_hat, leaders)
        # Truth and estimate move with the same ω over the step; the observer
        # sees the bearing at the end of the step (as the runtime aligns it).
        R = R @ so3.exp(dt * w)
        nb = neighbours(R, st.R_hat, st.p_hat, leaders)
        st, _ = fixed.step(st, fixed.Inputs(w, nb), dt, g)
        v = V(R @ st.R_hat.T)
        assert v <= v_prev + 1e-12
        v_prev = v
    assert v_prev < V(so3.Ra(theta, np.array([0.2, 1, -0.4])))


def test_true_pose_is_an_equilibrium_of_both_observers():
    R = so3.exp(np.array([0.4, -0.2, 1.0]))
    leaders = {1: so3.exp(np.array([1.0, 0, 0])), 2: np.eye(3)}
    nb = neighbours(R, R, P[3], leaders)
    s1, out = fixed.step(fixed.State(R, P[3].copy()), fixed.Inputs(np.zeros(3), nb), 0.01, fixed.Gains(1.0, 1.0))
    assert np.allclose(out.sigma, 0, atol=1e-15)
    assert np.allclose(s1.R_hat, R, atol=1e-15) and np.allclose(s1.p_hat, P[3], atol=1e-14)
    s2, _ = filt.step(filt.State(R, P[3].copy(), np.zeros(3)), filt.Inputs(np.zeros(3), nb), 0.01, filt.Gains(1.0, 1.0))
    assert np.allclose(s2.R_hat, R, atol=1e-15) and np.allclose(s2.Omega, 0, atol=1e-15)


def test_position_error_decreases_with_exact_attitude():
    """With R̂ = R, (3.14) is ṗ̂ = −k_p Σ P_b (p̂ − p_j): |p̂ − p|² is non-increasing."""
    R = np.eye(3)
    leaders = {1: np.eye(3), 2: np.eye(3)}
    st = fixed.State(R, np.array([-2.0, 0.0, -1.0]))
    prev = e0 = np.linalg.norm(st.p_hat - P[3])
    lam = np.linalg.eigvalsh(sum(so3.projector(unit(P[j] - P[3])) for j in (1, 2)))[0]
    dt, n = 1e-2, 3000
    for _ in range(n):
        nb = neighbours(R, st.R_hat, st.p_hat, leaders)
        st, _ = fixed.step(st, fixed.Inputs(np.zeros(3), nb), dt, fixed.Gains(1.0, 1.0))
        e = np.linalg.norm(st.p_hat - P[3])
        assert e <= prev + 1e-12
        prev = e
    # GES (Prop. 3.1): the Euler map I − dt k_p Σ P_b contracts by (1 − dt λ_min) per step.
    assert lam > 0
    assert prev <= e0 * (1 - dt * lam) ** n * (1 + 1e-9)


def test_filtered_observer_converges_from_large_error():
    rng = np.random.default_rng(3)
    R = np.eye(3)
    leaders = {1: so3.exp(rng.normal(size=3)), 2: so3.exp(rng.normal(size=3))}
    st = filt.State(so3.Ra(0.9 * np.pi, np.array([1.0, 0, 0])), np.zeros(3), np.zeros(3))
    for _ in range(4000):
        nb = neighbours(R, st.R_hat, st.p_hat, leaders)
        st, _ = filt.step(st, filt.Inputs(np.zeros(3), nb), 1e-2, filt.Gains(1.0, 1.0))
    assert so3.attitude_norm(R @ st.R_hat.T) < 1e-4


def test_interval_mean_rate_is_exact_for_piecewise_linear_rates():
    samples = [(t, np.array([t, 2 * t, -t])) for t in (0.0, 0.005, 0.010, 0.015)]
    m = interval_mean_rate(samples, 0.002, 0.012)
    assert np.allclose(m, [0.007, 0.014, -0.007], atol=1e-15)
    # Extrapolated linearly for one sample gap past the newest sample (exact here)...
    assert np.allclose(interval_mean_rate(samples, 0.012, 0.018), [0.015, 0.03, -0.015], atol=1e-15)
    # ...then held: over [0.015, 0.025] the rate is 0.015→0.020 (linear) then 0.020.
    assert np.allclose(interval_mean_rate(samples, 0.015, 0.025), [0.01875, 0.0375, -0.01875], atol=1e-15)
    assert np.allclose(interval_mean_rate(samples[:1], 0.0, 0.01), [0, 0, 0])
