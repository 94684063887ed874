"""The §4 observers against the thesis' error dynamics (Boughellaba 2024, §4.3–4.4).

A centralised harness steps every agent's pure ``step`` synchronously on the
§4.5 tree (path 1-2-3-4-5, edges oriented 1->2->3->4->5) with exact relative
attitudes and ω = 0, so the discrete system is a first-order approximation of
the closed loops (4.9), (4.22), (4.37).  Along flows U_R = Σ_k U(R̄_k, ξ_k)
decreases (U̇_R = −k_R|HΨ|² − k_ξ Σ|∇_ξ U|² ≤ 0, proof of Theorem 4.2); the
O(dt²) discretisation term is a fraction dt·L of the O(dt) decrease,
so a strict decrease at every flow step is a fair test.  At a jump
U_R drops by at least δ (4.14).
"""

import math

import numpy as np
import pytest

from agent.algorithms import relative_attitude_continuous as cont
from agent.algorithms import relative_attitude_hybrid as hyb
from agent.algorithms import relative_pose_hybrid as pose
from agent.algorithms.relative_attitude_terms import EdgeData, relative_error
from zswarm.families import synergistic as hybrid
from zswarm.math import so3

EDGES = ((1, 2), (2, 3), (3, 4), (4, 5))
IDS = (1, 2, 3, 4, 5)
A = np.diag([5.0, 8.57, 12.0])
U = np.array([0.0, 0.6455, 0.7638]) / np.linalg.norm([0.0, 0.6455, 0.7638])
G = hyb.Gains(k_R=1.1, k_xi=3.5, A=A, u=U, gamma=1.9251, delta=0.0030, Xi=(0.08 * math.pi,))
# §4.5 initial estimates: alternating Ra(∓π/2, e3); true attitudes I.
R_HAT0 = {i: so3.Ra((-1) ** i * math.pi / 2 * -1, np.array([0.0, 0, 1])) for i in IDS}
P = {1: np.array([-2.0, -2, -2]), 2: np.array([2.0, -2, -2]), 3: np.array([-2.0, 2, -2]), 4: np.array([2.0, 2, -2]), 5: np.zeros(3)}


def edges_of(i, R, R_hat, xi, p_hat=None):
    out = []
    for k, (h, t) in enumerate(EDGES, start=1):
        if i not in (h, t):
            continue
        j = t if h == i else h
        b_own = R[i].T @ ((P[j] - P[i]) / np.linalg.norm(P[j] - P[i]))
        b_nbr = R[j].T @ ((P[i] - P[j]) / np.linalg.norm(P[i] - P[j]))
        out.append(EdgeData(k, h == i, R[i].T @ R[j], R_hat[j], xi.get(k, 0.0), b_own, b_nbr, None if p_hat is None else p_hat[j]))
    return tuple(out)


def R_bars(R, R_hat):
    Rt = {i: R[i] @ R_hat[i].T for i in IDS}
    return {k: Rt[t].T @ Rt[h] for k, (h, t) in enumerate(EDGES, start=1)}


def U_R(R, R_hat, xi):
    return sum(hybrid.potential(A, U, G.gamma, Rb, xi[k]) for k, Rb in R_bars(R, R_hat).items())


def run_hybrid(R, R_hat, xi, steps, dt):
    """Synchronous network steps; returns states and per-step (U before, U after, jumps)."""
    log = []
    for _ in range(steps):
        before = U_R(R, R_hat, xi)
        new_R, new_xi, jumps = {}, dict(xi), []
        for i in IDS:
            own = {k: x for k, x in xi.items() if EDGES[k - 1][0] == i}
            st, out = hyb.step(hyb.State(R_hat[i], own), hyb.Inputs(np.zeros(3), edges_of(i, R, R_hat, xi)), dt, G)
            new_R[i] = st.R_hat
            new_xi.update(st.xi)
            jumps += out.jumps
        R_hat, xi = new_R, new_xi
        log.append((before, U_R(R, R_hat, xi), jumps))
    return R_hat, xi, log


def test_section_4_5_start_is_on_the_undesired_critical_set():
    R = {i: np.eye(3) for i in IDS}
    for Rb in R_bars(R, R_HAT0).values():
        assert so3.attitude_norm(Rb) == pytest.approx(1.0, abs=1e-12)
        assert np.allclose(so3.psi(A @ Rb), 0, atol=1e-12)  # Pa(A R̄) = 0: a critical point


def test_hybrid_jumps_once_per_edge_then_U_decreases_and_converges():
    R = {i: np.eye(3) for i in IDS}
    xi0 = {k: 0.0 for k in range(1, 5)}
    R_hat, xi, log = run_hybrid(R, dict(R_HAT0), xi0, steps=3000, dt=0.01)
    first_before, first_after, first_jumps = log[0]
    assert sorted(k for k, _, _ in first_jumps) == [1, 2, 3, 4]
    assert all(after == pytest.approx(0.08 * math.pi) for _, _, after in first_jumps)
    assert sum(len(j) for _, _, j in log) == 4  # finitely many: one per edge
    # A jump step: each jump lowers U by its gap ≥ δ; the flow part of the step lowers it further.
    assert first_before - first_after >= 4 * G.delta
    for before, after, jumps in log[1:]:
        if before > 1e-10:
            assert after < before
    assert max(so3.attitude_norm(Rb) for Rb in R_bars(R, R_hat).values()) < 1e-3
    assert max(abs(x) for x in xi.values()) < 1e-3


def test_jump_map_lands_in_the_flow_set_so_jumps_cannot_chain():
    rng = np.random.default_rng(7)
    for _ in range(200):
        R_bar, xi = so3.exp(rng.normal(size=3) * 2), rng.normal() * 3
        new = hyb.jump_map(R_bar, xi, G)
        assert hyb.flow_set(R_bar, new, G) and not hyb.jump_set(R_bar, new, G)
        if hyb.jump_set(R_bar, xi, G):
            drop = hybrid.potential(A, U, G.gamma, R_bar, xi) - hybrid.potential(A, U, G.gamma, R_bar, new)
            assert drop >= G.delta


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_hybrid_converges_from_random_states_with_finitely_many_jumps(seed):
    rng = np.random.default_rng(seed)
    R = {i: so3.exp(rng.normal(size=3) * 2) for i in IDS}
    R_hat = {i: so3.exp(rng.normal(size=3) * 2) for i in IDS}
    xi0 = {k: float(rng.uniform(-1, 1)) for k in range(1, 5)}
    R_hat, xi, log = run_hybrid(R, R_hat, xi0, steps=3000, dt=0.01)
    assert sum(len(j) for _, _, j in log) <= 8
    assert max(so3.attitude_norm(Rb) for Rb in R_bars(R, R_hat).values()) < 1e-3


def test_continuous_undesired_equilibrium_is_an_equilibrium_and_unstable():
    """Theorem 4.1: Υ \\ A is made of equilibria, unstable ones.

    σ_i vanishes at the §4.5 start (to round-off); a 1e-6 rad kick of one
    estimate leaves the undesired set and reaches |R̄_k|_I < 1e-3 in 10 s.
    (Round-off alone escapes too, within ≈ 2 s: the instability rate is
    ≈ 15 /s, so the exact equilibrium cannot be held numerically.)
    """
    R = {i: np.eye(3) for i in IDS}
    g = cont.Gains(1.1, A)

    def run(R_hat, steps):
        for _ in range(steps):
            R_hat = {i: cont.step(cont.State(R_hat[i]), cont.Inputs(np.zeros(3), edges_of(i, R, R_hat, {})), 0.005, g)[0].R_hat for i in IDS}
        return max(so3.attitude_norm(Rb) for Rb in R_bars(R, R_hat).values())

    for i in IDS:
        sigma = cont.step(cont.State(R_HAT0[i]), cont.Inputs(np.zeros(3), edges_of(i, R, R_HAT0, {})), 0.005, g)[1].sigma
        assert np.linalg.norm(sigma) < 1e-12
    kicked = dict(R_HAT0)
    kicked[3] = kicked[3] @ so3.exp(np.array([1e-6, 2e-6, 0.0]))
    assert run(kicked, 2000) < 1e-3


def test_correction_vanishes_at_the_desired_equilibrium():
    """σ_i = 0 when every R̄_k = I and ξ_k = 0, for any true attitudes and a common offset."""
    rng = np.random.default_rng(0)
    R = {i: so3.exp(rng.normal(size=3)) for i in IDS}
    Q = so3.exp(rng.normal(size=3))  # R̂_i = Q^T R_i: R̃_i = Q for all i
    R_hat = {i: Q.T @ R[i] for i in IDS}
    for i in IDS:
        e = edges_of(i, R, R_hat, {})
        for ed in e:
            assert np.allclose(relative_error(R_hat[i], ed), np.eye(3), atol=1e-12)
        st, out = hyb.step(hyb.State(R_hat[i], {k: 0.0 for k, (h, _) in enumerate(EDGES, 1) if h == i}), hyb.Inputs(np.zeros(3), e), 0.01, G)
        assert np.allclose(out.sigma, 0, atol=1e-12) and not out.jumps


def test_pose_error_dynamics_do_not_depend_on_the_attitude_estimates():
    """(4.33): p̃_i = R̃_i p̂_i − p_i evolves by k_p Σ P_b(p̃_j − p̃_i), whatever R̂ does.

    Stepping (4.30) with the attitudes far from converged and comparing the
    new p̃ with one Euler step of (4.33): they agree to O(dt²) (dt = 1e-4).
    The sum Σ p̃_i is conserved (symmetric bearing Laplacian).
    """
    rng = np.random.default_rng(5)
    R = {i: so3.exp(rng.normal(size=3)) for i in IDS}
    R_hat = {i: so3.exp(rng.normal(size=3)) for i in IDS}
    p_hat = {i: rng.normal(size=3) * 2 for i in IDS}
    gp = pose.Gains(1.1, 3.5, 1.0, A, U, G.gamma, G.delta, G.Xi)
    dt = 1e-4
    xi = {k: 0.1 * k for k in range(1, 5)}
    p_t = {i: R[i] @ R_hat[i].T @ p_hat[i] - P[i] for i in IDS}
    new = {}
    for i in IDS:
        own = {k: x for k, x in xi.items() if EDGES[k - 1][0] == i}
        st, _ = pose.step(pose.State(R_hat[i], p_hat[i], own), pose.Inputs(np.zeros(3), np.zeros(3), edges_of(i, R, R_hat, xi, p_hat)), dt, gp)
        new[i] = R[i] @ st.R_hat.T @ st.p_hat - P[i]
    for i in IDS:
        rate = np.zeros(3)
        for h, t in EDGES:
            if i in (h, t):
                j = t if h == i else h
                b = (P[j] - P[i]) / np.linalg.norm(P[j] - P[i])
                rate += (np.eye(3) - np.outer(b, b)) @ (p_t[j] - p_t[i])
        assert np.allclose(new[i], p_t[i] + dt * rate, atol=1e-6)
    assert np.allclose(sum(new.values()), sum(p_t.values()), atol=1e-6)
