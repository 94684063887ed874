"""The Chapter 5 laws against Appendix C: Lyapunov functions along flows and at jumps.

A centralised harness closes the loop of each law's pure ``step`` with the
rigid-body plant (world.dynamics, J not isotropic so the gyroscopic term is
exercised): every agent steps at the plant's step ``dt`` from the true
state, its torque is held over the next step, as the world does.  Then

* at a jump, V drops by at least k_R δ (C.7) (V̂ by min(k_R δ_R̄, k_Q̃ δ_Q̃), (C.12));
* along flows, ``(V(t+dt) − V(t))/dt`` equals V̇ of (C.6)/(C.11), which is ≤ 0,
  up to the sampled-data error of the hold, which is O(dt): halving dt halves
  the largest mismatch (a sign error in the law would leave an O(1) mismatch);
* V falls by at least the jumps' k_R δ from its start, as the proof's bound
  j ≤ ⌈V(0)/(k_R δ)⌉ says.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.algorithms import attitude_sync_continuous as cont
from agent.algorithms import attitude_sync_hybrid as hyb
from agent.algorithms import attitude_sync_velocity_free as vf
from agent.algorithms.attitude_sync_terms import Edge, coupling, xi_coefficients
from world.dynamics import RigidBodies
from zswarm.families import synergistic as hybrid
from zswarm.math.so3 import Ra, exp, psi

A = np.diag([5.0, 8.57, 12.0])
U_VEC = np.array([0.0, 0.6455, 0.7638]) / np.linalg.norm([0.0, 0.6455, 0.7638])
GAMMA, DELTA, XI = 1.9251, 0.3848, (0.9 * math.pi,)
EDGES = ((1, 2), (2, 3))  # a path 1 -> 2 -> 3, head first
J = np.stack([np.diag([1.0, 1.5, 2.0]), np.diag([2.0, 1.0, 1.2]), np.diag([1.3, 1.3, 0.8])])
E3 = np.array([0.0, 0.0, 1.0])


def hyb_gains(k_R=0.4, k_omega=0.1, k_xi=20.0):
    return hyb.Gains(k_R, k_omega, k_xi, A, U_VEC, GAMMA, DELTA, XI)


def vf_gains():
    return vf.Gains(0.4, 20.0, 30.0, 3.0, 20.0, A, U_VEC, GAMMA, DELTA, XI, DELTA, XI)


def rel(R):
    """R̄_k = R_tail^T R_head per edge k (1-based)."""
    return {k: R[t - 1].T @ R[h - 1] for k, (h, t) in enumerate(EDGES, start=1)}


def edges_of(i, R_bars, xi):
    out = []
    for k, (h, t) in enumerate(EDGES, start=1):
        if i in (h, t):
            out.append(Edge(k, i == h, R_bars[k], None if i == h else xi[k]))
    return tuple(out)


def U_sum(R_bars, xi):
    return sum(hybrid.potential(A, U_VEC, GAMMA, R_bars[k], xi[k]) for k in R_bars)


def run_hybrid(dt, T, R0, w0, g):
    """Closed loop of (5.19)+(5.21)+(5.7); per step: V after the step's jumps, its (C.6) rate, jumps."""
    b = RigidBodies(R0, w0, J)
    states = {i: hyb.State({k: 0.0 for k, (h, _t) in enumerate(EDGES, start=1) if h == i}, {}) for i in (1, 2, 3)}
    rows, jumps = [], []
    for n in range(int(round(T / dt)) + 1):
        R_bars = rel(b.R)
        heads = {k: states[h].xi[k] for k, (h, _t) in enumerate(EDGES, start=1)}
        taus = np.zeros((3, 3))
        for i in (1, 2, 3):
            before = dict(states[i].xi)
            states[i], out = hyb.step(states[i], hyb.Inputs(b.w[i - 1].copy(), edges_of(i, R_bars, heads)), dt if n else 0.0, g)
            taus[i - 1] = out.tau
            for k, x_before, x_after in out.jumps:
                jumps.append((n, k, x_before, x_after, R_bars[k]))
            del before
        xi = {k: states[h].xi[k] for k, (h, _t) in enumerate(EDGES, start=1)}
        V = g.k_R * U_sum(R_bars, xi) + float(np.einsum("ni,nij,nj->", b.w, J, b.w))
        grad_xi = [hybrid.grad_xi(A, U_VEC, GAMMA, R_bars[k], xi[k]) for k in R_bars]
        Vdot = -g.k_R * g.k_xi * sum(x * x for x in grad_xi) - 2.0 * g.k_omega * float(np.sum(b.w * b.w))
        rows.append((n * dt, V, Vdot))
        b.step(taus, dt)
    return np.array(rows), jumps


def flow_mismatch(rows, jump_steps, dt):
    """Largest |ΔV/dt − V̇| over steps with no jump at either end (V̇ as the trapezoid of its ends)."""
    worst = 0.0
    for n in range(len(rows) - 1):
        if n + 1 in jump_steps or n in jump_steps:
            continue
        fd = (rows[n + 1, 1] - rows[n, 1]) / dt
        worst = max(worst, abs(fd - 0.5 * (rows[n, 2] + rows[n + 1, 2])))
    return worst


@pytest.fixture(scope="module")
def undesired_start():
    # §5.6's start on this path: R_i alternating Ra(∓π/2, e3), so every R̄_k = Ra(π, e3), ω = 0.
    return np.stack([Ra(-math.pi / 2, E3), Ra(math.pi / 2, E3), Ra(-math.pi / 2, E3)]), np.zeros((3, 3))


def test_hybrid_jumps_lower_V_by_delta_and_flows_follow_C6(undesired_start):
    g = hyb_gains()
    R0, w0 = undesired_start
    res = {}
    for dt in (2e-3, 1e-3):
        rows, jumps = run_hybrid(dt, 4.0, R0, w0, g)
        res[dt] = (rows, jumps)
        # Both heads jump 0 -> 0.9π at the start (the state is on the undesired critical set).
        assert [(n, k) for n, k, *_ in jumps[:2]] == [(0, 1), (0, 2)]
        for _n, _k, before, after, R_bar in jumps:
            drop = g.k_R * (hybrid.potential(A, U_VEC, GAMMA, R_bar, before) - hybrid.potential(A, U_VEC, GAMMA, R_bar, after))
            assert drop >= g.k_R * DELTA  # (C.7)
        assert np.all(rows[:, 2] <= 0.0)  # (C.6) is ≤ 0 by construction; the test is the match below
        # V(t) ≤ V(0) − j k_R δ (the proof's bound), here at the end of the run.
        V0 = g.k_R * U_sum(rel(R0), {1: 0.0, 2: 0.0})
        assert rows[-1, 1] <= V0 - len(jumps) * g.k_R * DELTA
    m2 = flow_mismatch(res[2e-3][0], {j[0] for j in res[2e-3][1]}, 2e-3)
    m1 = flow_mismatch(res[1e-3][0], {j[0] for j in res[1e-3][1]}, 1e-3)
    # The held torque lags the law by up to dt: the mismatch is O(dt), ratio 2 on halving dt as
    # dt -> 0; the fast ξ mode (338 /s, h·λ = 0.34-0.68 here) adds higher-order terms, hence up to 3
    # (measured 2.40).  Its size: 0.45 % of max|V̇| at 1 ms (max|V̇| ≈ 243, right after the
    # jumps); a sign error in the coupling (τ = −k_ω ω − k_R σ) gives 19 %.
    assert 1.6 < m2 / m1 < 3.0, (m2, m1)
    assert m1 < 0.02 * float(np.max(np.abs(res[1e-3][0][:, 2])))


def test_hybrid_from_random_starts_V_decreases():
    rng = np.random.default_rng(7)
    g = hyb_gains()
    for _ in range(3):
        R0 = np.stack([exp(rng.normal(0, 2.0, 3)) for _ in range(3)])
        w0 = rng.normal(0, 0.5, (3, 3))
        rows, jumps = run_hybrid(1e-3, 2.0, R0, w0, g)
        V = rows[:, 1]
        # Between jumps V may rise by the hold's O(dt²) per step only: at most 1e-4 of V(0) over a step here.
        jump_steps = {j[0] for j in jumps}
        rises = [V[n + 1] - V[n] for n in range(len(V) - 1) if n + 1 not in jump_steps]
        assert max(rises) < 1e-4 * V[0]
        assert V[-1] < V[0]


def test_continuous_law_is_the_hybrid_one_at_xi_zero_and_V_follows_C6():
    rng = np.random.default_rng(3)
    R = [exp(rng.normal(0, 1.5, 3)) for _ in range(3)]
    R_bars = rel(np.stack(R))
    w = rng.normal(0, 1, 3)
    g = cont.Gains(0.4, 0.1, A)
    for i in (1, 2, 3):
        edges = edges_of(i, R_bars, {1: 0.0, 2: 0.0})
        tau, sigma = cont.control(cont.Inputs(w, edges), g)
        # (5.24) is (5.19) with every ξ = 0 (READING-NOTES: M ψ(A M) = −ψ(A M^T)).
        assert np.allclose(sigma, coupling(edges, {1: 0.0, 2: 0.0}, A, U_VEC), atol=1e-12)
        # ... and reads −Σ_j ψ(A R_j^T R_i) over the neighbours.
        direct = -sum(psi(A @ R[j - 1].T @ R[i - 1]) for j in {1: (2,), 2: (1, 3), 3: (2,)}[i])
        assert np.allclose(sigma, direct, atol=1e-12)
        assert np.allclose(tau, -0.1 * w + 0.4 * sigma)


def test_xi_rate_coefficients_are_exact():
    """u^T ψ(A R̄ Ra(ξ,u)) = a + b sin ξ + c(1 − cos ξ) for any R̄ and ξ (what the ξ sub-steps use)."""
    rng = np.random.default_rng(1)
    for _ in range(5):
        R_bar = exp(rng.normal(0, 2, 3))
        a, b, c = xi_coefficients(A, U_VEC, R_bar)
        for x in rng.uniform(-4, 4, 5):
            assert abs(float(U_VEC @ psi(A @ R_bar @ Ra(x, U_VEC))) - (a + b * math.sin(x) + c * (1 - math.cos(x)))) < 1e-12


def run_vf(dt, T, R0, Q0, g):
    """Closed loop of (5.20)-(5.23), (5.7), (5.12); V̂ of (C.10) and its rate (C.11)."""
    b = RigidBodies(R0, np.zeros((3, 3)), J)
    states = {i: vf.State(Q0[i - 1], 0.0, {k: 0.0 for k, (h, _t) in enumerate(EDGES, start=1) if h == i}, {}) for i in (1, 2, 3)}
    R_last = {i: b.R[i - 1].copy() for i in (1, 2, 3)}
    rows, jumps = [], []
    for n in range(int(round(T / dt)) + 1):
        R_bars = rel(b.R)
        heads = {k: states[h].xi[k] for k, (h, _t) in enumerate(EDGES, start=1)}
        taus = np.zeros((3, 3))
        for i in (1, 2, 3):
            samples = ((-dt, R_last[i]), (0.0, b.R[i - 1].copy())) if n else ((0.0, b.R[i - 1].copy()),)
            states[i], out = vf.step(states[i], vf.Inputs(samples, edges_of(i, R_bars, heads)), dt if n else 0.0, g)
            taus[i - 1] = out.tau
            for k, x0, x1 in out.jumps:
                jumps.append((n, "xi", g.k_R * (hybrid.potential(A, U_VEC, GAMMA, R_bars[k], x0) - hybrid.potential(A, U_VEC, GAMMA, R_bars[k], x1))))
            for z0, z1 in out.agent_jumps:
                jumps.append((n, "zeta", g.k_Qt * (hybrid.potential(A, U_VEC, GAMMA, out.Q_tilde, z0) - hybrid.potential(A, U_VEC, GAMMA, out.Q_tilde, z1))))
            R_last[i] = b.R[i - 1].copy()
        xi = {k: states[h].xi[k] for k, (h, _t) in enumerate(EDGES, start=1)}
        Qt = {i: states[i].Q.T @ b.R[i - 1] for i in (1, 2, 3)}
        V = g.k_R * U_sum(R_bars, xi) + g.k_Qt * sum(hybrid.potential(A, U_VEC, GAMMA, Qt[i], states[i].zeta) for i in Qt) + float(np.einsum("ni,nij,nj->", b.w, J, b.w))
        hs = [vf.damping(Qt[i], states[i].zeta, g)[0] for i in Qt]
        gz = [hybrid.grad_xi(A, U_VEC, GAMMA, Qt[i], states[i].zeta) for i in Qt]
        gx = [hybrid.grad_xi(A, U_VEC, GAMMA, R_bars[k], xi[k]) for k in R_bars]
        Vdot = -g.k_R * g.k_xi * sum(x * x for x in gx) - 2 * g.k_Qt * g.k_Q * sum(float(h @ h) for h in hs) - g.k_Qt * g.k_zeta * sum(x * x for x in gz)
        rows.append((n * dt, V, Vdot))
        b.step(taus, dt)
    return np.array(rows), jumps


def test_velocity_free_jumps_and_flows_follow_C11(undesired_start):
    g = vf_gains()
    R0, _ = undesired_start
    Q0 = np.stack([Ra(math.pi / 2, E3), Ra(-math.pi / 2, E3), Ra(math.pi / 2, E3)])  # Q̃_i(0) = Ra(π, e3)
    res = {}
    for dt in (2e-3, 1e-3):
        rows, jumps = run_vf(dt, 3.0, R0, Q0, g)
        res[dt] = (rows, jumps)
        kinds = sorted(k for n, k, _ in jumps if n == 0)
        assert kinds == ["xi", "xi", "zeta", "zeta", "zeta"]  # every ξ_k and ζ_i jumps at the start
        for _n, _kind, drop in jumps:
            assert drop >= min(g.k_R, g.k_Qt) * DELTA  # (C.12)
        assert rows[-1, 1] < rows[0, 1]
    m2 = flow_mismatch(res[2e-3][0], {j[0] for j in res[2e-3][1]}, 2e-3)
    m1 = flow_mismatch(res[1e-3][0], {j[0] for j in res[1e-3][1]}, 1e-3)
    # O(dt) again (the hold; Q's sub-steps see R_i on the chord between samples); bounds as above.
    assert 1.6 < m2 / m1 < 3.0, (m2, m1)
    assert m1 < 0.02 * float(np.max(np.abs(res[1e-3][0][:, 2])))
