"""zswarm/math/kernels.py's compiled loops give the numbers of the numpy/Python code they replace,
bit for bit (so a run is the same with or without them: golden sim passes either way), on any
CPU and BLAS: neither side calls the BLAS (the numpy code's 3x3 products are so3.mul's
elementwise sums, the compiled ones the same sums, no fused multiply-add), so the promise holds
by construction; make test runs this file again with OpenBLAS's Prescott kernel and numpy's
AVX-512 paths off (tests/layers.sh).

The inputs cover both branches of Rodrigues' formula (|hω̄|² below and above 1e-8), torques
of either sign, and the ξ filter from a single sub-step to many, for one draw (sim's path)
and a stack of draws (the batched engine's).  A machine without a C compiler installs
zswarm without the kernels; these tests then fail, saying so, rather than pass vacuously.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from agent.algorithms import attitude_sync_terms as terms
from agent.algorithms import attitude_sync_velocity_free as vf
from world.dynamics import RigidBodies
from zswarm.math import kernels
from zswarm.math.so3 import exp_batch, log

NEEDED = "zswarm.math._kernels was not built (no C compiler at install?): pip install -e . with gcc"


def _bodies(rng: np.random.Generator, n: int, scale: np.ndarray) -> RigidBodies:
    R0 = exp_batch(rng.normal(size=(n, 3)) * 2.0)
    return RigidBodies(R0, rng.normal(size=(n, 3)) * scale[:, None], np.tile(np.eye(3) * 1.7, (n, 1, 1)))


def test_rigid_step_is_the_numpy_step(monkeypatch):
    assert kernels.rigid_step is not None, NEEDED
    rng = np.random.default_rng(7)
    n = 600
    scale = np.concatenate([np.full(200, 1e-7), np.full(200, 1.0), np.full(200, 40.0)])  # small-angle branch, ordinary, fast
    fast, slow = _bodies(np.random.default_rng(1), n, scale), _bodies(np.random.default_rng(1), n, scale)
    for _ in range(60):
        tau = rng.normal(size=(n, 3)) * 3.0
        fast.step(tau, 1e-3)
        monkeypatch.setattr(kernels, "rigid_step", None)
        slow.step(tau, 1e-3)
        monkeypatch.undo()
        assert np.array_equal(fast.R, slow.R) and np.array_equal(fast.w, slow.w)
    assert not np.array_equal(fast.R, _bodies(np.random.default_rng(1), n, scale).R)  # they did move


def test_exp_batch_is_numpys(monkeypatch):
    assert kernels.exp_batch is not None, NEEDED
    rng = np.random.default_rng(5)
    W = np.concatenate([rng.normal(size=(300, 3)) * s for s in (1e-6, 1e-4, 0.05, 1.0, 3.0)])  # both branches, |W| up to ~10
    fast = exp_batch(W)
    monkeypatch.setattr(kernels, "exp_batch", None)
    assert np.array_equal(fast, exp_batch(W))


@pytest.mark.parametrize("dt", [2e-4, 5e-3, 1e-2, 0.2])
def test_flow_xi_is_the_python_loop(monkeypatch, dt):
    assert kernels.flow_xi is not None, NEEDED
    rng = np.random.default_rng(3)
    M = 257
    xi = rng.uniform(-3.0, 3.0, M)
    c0 = tuple(rng.normal(size=M) for _ in range(3))
    c1 = tuple(c + 0.1 * rng.normal(size=M) for c in c0)
    fast = terms.flow_xi(c0, c1, xi, dt, 20.0, 1.9251)
    one = [terms.flow_xi(tuple(float(c[m]) for c in c0), tuple(float(c[m]) for c in c1), float(xi[m]), dt, 20.0, 1.9251) for m in range(M)]
    monkeypatch.setattr(kernels, "flow_xi", None)
    slow = terms.flow_xi(c0, c1, xi, dt, 20.0, 1.9251)
    slow_one = [terms.flow_xi(tuple(float(c[m]) for c in c0), tuple(float(c[m]) for c in c1), float(xi[m]), dt, 20.0, 1.9251) for m in range(M)]
    assert np.array_equal(fast, slow) and one == slow_one and np.array_equal(slow, np.array(slow_one))
    assert not np.array_equal(fast, xi)


@pytest.mark.parametrize("dt", [3e-4, 1e-2, 0.05])
def test_flow_aux_is_the_numpy_loop(monkeypatch, dt):
    """The velocity-free law's (Q_i, ζ_i) filter: compiled or numpy, a stack of draws or each
    draw alone (sim's path), over attitude samples before, inside and after the step (so
    sub-steps read every row of the rate table, the zero row included), Q_i near Q̃ = I and
    far from it, ζ on both sides of 0."""
    assert kernels.flow_aux is not None, NEEDED
    rng = np.random.default_rng(11)
    M = 97
    g = vf.Gains(0.4, 20.0, 30.0, 3.0, 20.0, np.diag([5.0, 8.57, 12.0]), np.array([0.0, 0.6455, 0.7638]) / np.linalg.norm([0.0, 0.6455, 0.7638]), 1.9251, 0.3848, (2.83,), 0.3848, (2.83,))
    R0 = exp_batch(rng.normal(size=(M, 3)))
    Q = np.concatenate([R0[: M // 2] @ exp_batch(rng.normal(size=(M // 2, 3)) * 1e-3), exp_batch(rng.normal(size=(M - M // 2, 3)) * 2.0)])
    zeta = rng.uniform(-3.0, 3.0, M)
    times = (-1.3 * dt, -0.6 * dt, -0.1 * dt)  # the newest sample 0.1 dt before the step's end: the zero row
    samples = tuple((t, R0 @ exp_batch(rng.normal(size=(M, 3)) * 0.05 * k)) for k, t in enumerate(times))
    fast = vf.flow_aux(Q, zeta, samples, dt, g)
    one = [vf.flow_aux(Q[m], float(zeta[m]), tuple((t, R[m]) for t, R in samples), dt, g) for m in range(M)]
    monkeypatch.setattr(kernels, "flow_aux", None)
    slow = vf.flow_aux(Q, zeta, samples, dt, g)
    slow_one = [vf.flow_aux(Q[m], float(zeta[m]), tuple((t, R[m]) for t, R in samples), dt, g) for m in range(M)]
    assert np.array_equal(fast[0], slow[0]) and np.array_equal(fast[1], slow[1])
    for m in range(M):
        assert np.array_equal(one[m][0], fast[0][m]) and one[m][1] == fast[1][m]
        assert np.array_equal(slow_one[m][0], fast[0][m]) and slow_one[m][1] == fast[1][m]
    assert not np.array_equal(fast[1], zeta)


def test_the_module_refuses_arrays_it_cannot_read():
    """zswarm.math._kernels reads arrays through the buffer protocol: one of the wrong kind, layout
    or size, a row outside the rate table, or a wrong number of arguments is an exception
    (TypeError, ValueError, IndexError), never a read or write out of bounds."""
    assert kernels.flow_aux is not None, NEEDED
    from zswarm.math import _kernels as k

    R, w, J, tau = np.tile(np.eye(3), (2, 1, 1)), np.zeros((2, 3)), np.tile(np.eye(3), (2, 1, 1)), np.zeros((2, 3))
    Ro, wo = np.empty_like(R), np.empty_like(w)
    k.rigid_step(R, w, J, tau, 1e-3, Ro, wo)  # the right arguments go through
    assert np.array_equal(Ro, R) and np.array_equal(wo, w)
    bad = [
        (TypeError, lambda: k.rigid_step(R.astype(np.float32), w, J, tau, 1e-3, Ro, wo)),  # float32
        (ValueError, lambda: k.rigid_step(R[:1], w, J, tau, 1e-3, Ro, wo)),  # one body short
        (ValueError, lambda: k.rigid_step(R, w, J, tau, 1e-3, Ro, np.empty((1, 3)))),  # output too small
        (ValueError, lambda: k.rigid_step(R, w, J, tau, 1e-3, Ro, np.empty((3, 2)).T)),  # not C-contiguous (numpy says so)
        (TypeError, lambda: k.rigid_step(R, w, J, tau, 1e-3, Ro)),  # an argument missing
        (TypeError, lambda: k.rigid_step(R, w, J, tau, "h", Ro, wo)),
        (ValueError, lambda: k.exp_batch(np.zeros(4), np.empty((2, 3, 3)))),  # not a stack of 3-vectors
        (ValueError, lambda: k.flow_xi(*([np.zeros(3)] * 5), np.zeros(2), np.zeros(3), 1e-2, 20.0, 1.9, 4)),  # a coefficient of 2 draws for 3
        (ValueError, lambda: k.flow_xi_one(*([0.0] * 10), -1)),  # a negative sub-step count
        (ValueError, lambda: k.predict(np.zeros((2, 3, 3)), np.zeros((3, 3, 3)), 0.5, np.empty((3, 3, 3)))),  # 2 draws for 3
        (ValueError, lambda: k.predict(np.zeros(8), np.zeros(8), 0.5, np.empty(8))),  # not 3x3 matrices
        (ValueError, lambda: k.terms(np.eye(3), np.eye(3), np.zeros(3), np.zeros((2, 3, 3)), np.empty((2, 14)))),  # rows of 14
        (TypeError, lambda: k.terms(np.eye(3), np.eye(3), np.zeros(3, dtype=np.float32), np.zeros((2, 3, 3)), np.empty((2, 15)))),
        (IndexError, lambda: k.flow_aux(np.tile(np.eye(3), (2, 1, 1)), np.zeros(2), np.zeros((2, 2, 3)), np.array([0, 2]), 1e-3, *([np.eye(3)] * 3), np.zeros(3), 1.0, 1.0, 1.0)),
        (TypeError, lambda: k.flow_aux(np.tile(np.eye(3), (2, 1, 1)), np.zeros(2), np.zeros((2, 2, 3)), np.array([0.0, 1.0]), 1e-3, *([np.eye(3)] * 3), np.zeros(3), 1.0, 1.0, 1.0)),  # float rows
    ]
    for exc, call in bad:
        with pytest.raises(exc):
            call()
    with pytest.raises(ValueError, match="read-only"):  # a read-only output (numpy refuses it)
        ro = np.empty_like(w)
        ro.flags.writeable = False
        k.rigid_step(R, w, J, tau, 1e-3, Ro, ro)


def _pairs(rng: np.random.Generator, M: int) -> tuple[np.ndarray, np.ndarray]:
    """R̄ at two steps: changes of every size (the small-angle branch of log, ordinary ones,
    near and at π, where numpy takes over)."""
    scale = np.concatenate([np.full(M // 4, 1e-8), np.full(M // 4, 1e-3), np.full(M // 4, 0.5), np.full(M - 3 * (M // 4), 2.0)])
    R_prev = exp_batch(rng.normal(size=(M, 3)) * 2.0)
    R_now = R_prev @ exp_batch(rng.normal(size=(M, 3)) * scale[:, None])
    axis = rng.normal(size=(3, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    R_now[-3:] = R_prev[-3:] @ exp_batch(axis * np.array([np.pi, np.pi - 2e-5, np.pi - 1e-3])[:, None])
    return R_prev, R_now


def test_predict_is_the_numpy_predict(monkeypatch):
    """R̄ predicted half a step ahead (attitude_sync_terms.predict): compiled or numpy, a stack
    or each draw alone (sim's path), the same bits; near π numpy's branch for those draws."""
    assert kernels.predict is not None, NEEDED
    R_prev, R_now = _pairs(np.random.default_rng(13), 400)
    raw = kernels.predict(R_prev, R_now, 0.5)
    assert np.isnan(raw[-3:-1, 0, 0]).all() and np.isfinite(raw[:-3]).all() and np.isfinite(raw[-1]).all()  # π and π − 2e-5 are numpy's
    fast = terms.predict(R_prev, R_now, 0.01, 0.005)
    one = [terms.predict(R_prev[m], R_now[m], 0.01, 0.005) for m in range(len(R_now))]
    monkeypatch.setattr(kernels, "predict", None)
    slow = terms.predict(R_prev, R_now, 0.01, 0.005)
    assert np.array_equal(fast, slow) and np.array_equal(np.array(one), fast)
    assert np.all(np.isfinite(fast)) and not np.array_equal(fast, R_now)


def test_terms_are_the_numpy_terms(monkeypatch):
    assert kernels.terms is not None, NEEDED
    _, R = _pairs(np.random.default_rng(17), 300)
    A, u = np.diag([5.0, 8.57, 12.0]), np.array([0.0, 0.6455, 0.7638]) / np.linalg.norm([0.0, 0.6455, 0.7638])
    fields = ("p0", "p1", "p2", "t0", "t1", "t2")

    def every(t: terms.Terms) -> list[np.ndarray]:
        return [np.asarray(getattr(t, f)) for f in fields] + [np.asarray(x) for x in t.abc]

    fast = every(terms.Terms(A, u, R))
    one = [every(terms.Terms(A, u, R[m])) for m in range(len(R))]
    monkeypatch.setattr(kernels, "terms", None)
    slow = every(terms.Terms(A, u, R))
    slow_one = [every(terms.Terms(A, u, R[m])) for m in range(len(R))]
    for n in range(len(fast)):
        assert np.array_equal(fast[n], slow[n])
        assert np.array_equal(np.array([o[n] for o in one]), fast[n]) and np.array_equal(np.array([o[n] for o in slow_one]), fast[n])
    assert isinstance(terms.Terms(A, u, R[0]).t0, float) and isinstance(terms.Terms(A, u, R[0]).abc[0], float)


def test_log_is_the_numpy_log(monkeypatch):
    """so3.log of a stack or of one matrix (sim's path): compiled or numpy, the same bits, the
    branches near 0, in between and near π (numpy's, for those matrices) all taken."""
    assert kernels.log_stack is not None, NEEDED
    R_prev, R_now = _pairs(np.random.default_rng(19), 400)
    R = np.swapaxes(R_prev, -1, -2) @ R_now
    raw = kernels.log_stack(R)
    assert np.isnan(raw[-3:-1, 0]).all() and np.isfinite(raw[:-3]).all()
    fast = log(R)
    one = [log(R[m]) for m in range(len(R))]
    monkeypatch.setattr(kernels, "log_stack", None)
    slow = log(R)
    assert np.array_equal(fast, slow) and np.array_equal(np.array(one), fast)
    # exp undoes log: to round-off, but near π, where the axis comes from the symmetric part,
    # (R_s + I)/2 = cos²(θ/2) I + sin²(θ/2) v v^T: the first term tilts it by up to
    # cot²(θ/2) ≈ (π − θ)²/4 <= 2.5e-9 for π − θ <= 1e-4 (so3.log's branch).
    assert np.allclose(exp_batch(fast[:-3]), R[:-3], atol=1e-12) and np.allclose(exp_batch(fast[-3:]), R[-3:], atol=3e-9)


def _gyro_histories(rng: np.random.Generator) -> list[list[tuple[float, np.ndarray]]]:
    """Sample histories as an agent's inbox holds them: 5 ms apart with jitter, a repeated time
    (a gap of 0, so no extrapolation slope), a late last sample, two samples only, a long one."""
    out = []
    for n in (2, 3, 8, 64):
        ts = np.cumsum(rng.uniform(0.002, 0.008, n)) + 1.0
        out.append([(float(t), rng.normal(size=3) * 3.0) for t in ts])
    h = out[2]
    out.append(h[:-1] + [(h[-2][0], h[-1][1])])  # the newest two at one time
    out.append(h[:4] + [(h[3][0] + 0.03, h[4][1])])  # the newest 30 ms after the one before
    return out


def test_rate_integral_is_the_python_loop(monkeypatch):
    """The gyro's pre-integration (timing._integrate) in C against the Python, bit for bit, for
    intervals before, across, at and past the samples (the linear extrapolation and its cap)."""
    from zswarm.math import timing

    assert kernels.rate_integral is not None, NEEDED
    rng = np.random.default_rng(11)
    cases = 0
    for h in _gyro_histories(rng):
        ts = [t for t, _ in h]
        gap = ts[-1] - ts[-2]
        points = [ts[0] - 0.01, ts[0], *ts[1:-1:3], ts[-2], ts[-1], ts[-1] + 0.5 * gap, ts[-1] + gap, ts[-1] + 3 * max(gap, 0.001)]
        points += [float(x) for x in rng.uniform(ts[0] - 0.005, ts[-1] + 0.02, 6)]
        for t0 in points:
            for t1 in points:
                if not t0 < t1:
                    continue
                for magnus in (False, True):
                    fast = np.empty(3)
                    assert kernels.rate_integral(h, t0, t1, magnus, fast)  # taken in C, not left to the Python
                    assert timing._integrate(h, t0, t1, magnus).tobytes() == fast.tobytes()
                    monkeypatch.setattr(timing, "rate_integral", None)
                    slow = timing._integrate(h, t0, t1, magnus)
                    monkeypatch.undo()
                    assert fast.tobytes() == slow.tobytes(), (len(h), t0, t1, magnus, fast, slow)
                    cases += 1
    assert cases > 1000
    # What it does not take goes to the Python: a stack of draws, a tuple of samples, a bad out.
    stack = [(1.0, np.zeros((4, 3))), (1.005, np.ones((4, 3)))]
    assert not kernels.rate_integral(stack, 1.0, 1.005, True, np.empty(3))
    assert not kernels.rate_integral(tuple(_gyro_histories(rng)[1]), 1.0, 1.1, True, np.empty(3))
    assert not kernels.rate_integral([(1, np.zeros(3)), (2, np.zeros(3))], 1.0, 1.5, True, np.empty(3))  # int times
    with pytest.raises(ValueError):
        kernels.rate_integral(_gyro_histories(rng)[1], 0.0, 2.0, True, np.empty(4))
    assert timing._integrate(stack, 1.0, 1.005, True).shape == (4, 3)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def test_one_draw_so3_products_are_the_python_ones(monkeypatch):
    """so3.exp, mul and apply of one vector or matrix in C against their Python float code, bit
    for bit: rotation vectors on both sides of the Taylor branch (|w|² = 1e-8) and past the trig
    kernels' range, transposed (strided) views, and what goes to the Python (lists, stacks)."""
    from zswarm.math import so3

    assert kernels.exp1 is not None and kernels.mul1 is not None and kernels.apply1 is not None, NEEDED
    rng = np.random.default_rng(3)
    ws = [rng.normal(size=3) * s for s in (1e-9, 1e-5, 9.9e-5, 1e-4, 0.01, 1.0, 3.0, 40.0) for _ in range(40)]
    Rs = [so3.exp(w) for w in ws[200:]]
    pairs = [(A, B) for A in Rs[:30] for B in (Rs[30], so3.T(Rs[31]), rng.normal(size=(3, 3)))]
    fast = ([so3.exp(w) for w in ws], [so3.mul(A, B) for A, B in pairs], [so3.apply(A, w) for A in Rs[:30] for w in ws[:40]], so3.apply(so3.T(Rs[0]), ws[5]))
    for name in ("exp1", "mul1", "apply1"):
        monkeypatch.setattr(kernels, name, None)
    slow = ([so3.exp(w) for w in ws], [so3.mul(A, B) for A, B in pairs], [so3.apply(A, w) for A in Rs[:30] for w in ws[:40]], so3.apply(so3.T(Rs[0]), ws[5]))
    monkeypatch.undo()
    for f, sl in zip(fast[:3], slow[:3], strict=True):
        assert all(_same(a, b) for a, b in zip(f, sl, strict=True))
    assert _same(fast[3], slow[3])
    out = np.empty(3)
    assert kernels.apply1(Rs[0], ws[0], out) and not kernels.apply1(Rs[0].tolist(), ws[0], out) and not kernels.apply1(Rs[0], np.zeros((2, 3)), out)
    assert not kernels.exp1(np.zeros(3, dtype=np.float32), np.empty((3, 3))) and not kernels.mul1(Rs[0], np.stack([Rs[0]] * 2), np.empty((3, 3)))
    with pytest.raises(ValueError):
        kernels.exp1(ws[0], np.empty(3))  # the output's size is checked
    assert _same(so3.mul(Rs[0].tolist(), Rs[1]), so3.mul(Rs[0], Rs[1]))  # a list still works, in Python


def test_bearing_sums_are_the_numpy_ones(monkeypatch):
    """bearing_terms.bearing_correction and position_rate of one draw in C against their numpy
    code, bit for bit, with and without b_pos (moving agents), an int k, no neighbour; and a
    stack of draws (the batched engine) left to numpy."""
    from agent.algorithms import bearing_terms as bt
    from zswarm.math import so3

    assert kernels.bearing_correction1 is not None and kernels.position_rate1 is not None, NEEDED
    rng = np.random.default_rng(9)

    def unit(v: np.ndarray) -> np.ndarray:
        return v / np.linalg.norm(v)

    for case in range(60):
        n = case % 4
        nbrs = tuple(
            bt.NeighborData(
                float(rng.uniform(0.5, 2.0)) if q % 2 == 0 else 1,
                so3.exp(rng.normal(size=3)),
                rng.normal(size=3) * 5.0,
                unit(rng.normal(size=3)),
                unit(rng.normal(size=3)),
                unit(rng.normal(size=3)) if case % 3 == 0 else None,
            )
            for q in range(n)
        )
        R, p, sigma, k_p = so3.exp(rng.normal(size=3)), rng.normal(size=3) * 5.0, rng.normal(size=3), float(rng.uniform(0.1, 3.0))
        fast = (bt.bearing_correction(R, nbrs), bt.position_rate(R, p, sigma, k_p, nbrs))
        monkeypatch.setattr(kernels, "bearing_correction1", None)
        monkeypatch.setattr(kernels, "position_rate1", None)
        slow = (bt.bearing_correction(R, nbrs), bt.position_rate(R, p, sigma, k_p, nbrs))
        monkeypatch.undo()
        assert _same(fast[0], slow[0]) and _same(fast[1], slow[1]), (case, fast, slow)
        assert kernels.bearing_correction1(R, nbrs, np.empty(3)) and kernels.position_rate1(R, p, sigma, k_p, nbrs, np.empty(3))
    stack = (bt.NeighborData(1.0, np.stack([so3.exp(rng.normal(size=3))] * 2), np.zeros((2, 3)), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])),)
    assert not kernels.bearing_correction1(R, stack, np.empty(3)) and not kernels.position_rate1(R, p, sigma, k_p, stack, np.empty(3))
    assert not kernels.position_rate1(R, p, sigma, np.array([1.0, 2.0]), nbrs, np.empty(3))  # per-draw gains
    assert bt.bearing_correction(R, stack).shape == (2, 3)


def test_rotation_and_finite_verdicts_are_the_pythons(monkeypatch):
    """so3.rotations_ok of one received (read-only) matrix in C gives the Python's verdict at every
    distance from SO(3) around the tolerance, NaN and a writable matrix included; finite_f8 is
    np.isfinite(a).all() for float64 arrays and None for what it does not read."""
    from zswarm.math import so3
    from zswarm.math.limits import ROT_TOL

    assert kernels.finite_f8 is not None, NEEDED
    rng = np.random.default_rng(4)
    mats = []
    for eps in (0.0, 0.2 * ROT_TOL, 0.45 * ROT_TOL, 0.5 * ROT_TOL, 0.55 * ROT_TOL, ROT_TOL, 2 * ROT_TOL, 0.1):
        for _ in range(40):
            M = so3.exp(rng.normal(size=3)) + eps * rng.normal(size=(3, 3))
            M.flags.writeable = False
            mats.append(M)
    bad = np.eye(3)
    bad[1, 1] = np.nan
    bad.flags.writeable = False
    mats += [bad, -np.eye(3), np.eye(3)]  # NaN, det -1, writable
    fast = [so3.rotations_ok(M, ROT_TOL) for M in mats]
    monkeypatch.setattr(kernels, "f8_ok", None)
    slow = [so3.rotations_ok(M, ROT_TOL) for M in mats]
    monkeypatch.undo()
    assert fast == slow and 0 < sum(fast) < len(fast), (sum(fast), len(fast))
    for a in (np.zeros(3), np.array([1.0, np.inf, 0]), np.array([[np.nan]]), np.arange(9.0).reshape(3, 3).T, np.zeros(3, dtype=np.float32), [1.0]):
        want = bool(np.isfinite(a).all()) if isinstance(a, np.ndarray) and a.dtype == np.float64 and a.flags.c_contiguous else None
        assert kernels.finite_f8(a) is want, a


def _same(a, b) -> bool:
    """The same value as the wire holds it: arrays of one type, dtype, shape, flags and bytes."""
    if isinstance(a, np.ndarray):
        return type(b) is np.ndarray and a.dtype == b.dtype and a.shape == b.shape and a.flags.writeable == b.flags.writeable and a.tobytes() == b.tobytes()
    if isinstance(a, list):
        return type(b) is list and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def test_wire_hooks_are_the_python_hooks():
    """The compiled msgspec hooks (messages.ENC_HOOK, DEC_HOOK) answer what the Python enc_hook and
    dec_hook answer: the usual arrays in C, everything else handed to them (their errors too), so
    every payload encodes to the same bytes and decodes to the same arrays."""
    import msgspec

    from zswarm.transport import messages, wire
    from zswarm.transport.message_checks import MessageError

    assert messages.ENC_HOOK is not messages.enc_hook and messages.DEC_HOOK is not messages.dec_hook, NEEDED
    rng = np.random.default_rng(5)
    big = np.arange(6.0).reshape(3, 2).astype(">f8")
    outs = [rng.normal(size=3), rng.normal(size=(3, 3)), np.zeros(0), np.array(2.5), rng.normal(size=(2, 4, 5)), rng.normal(size=(3, 3)).T,
            rng.normal(size=6)[::2], np.ones(3, dtype=np.float32), big, np.arange(3), np.float64(1.25), np.int32(7)]  # fmt: skip
    ro = rng.normal(size=3)
    ro.flags.writeable = False
    outs.append(ro)
    for x in outs:
        assert _same(messages.enc_hook(x), messages.ENC_HOOK(x)), x
    for x in (object(), "text", 1 + 2j):
        with pytest.raises(NotImplementedError) as slow:
            messages.enc_hook(x)
        with pytest.raises(NotImplementedError) as fast:
            messages.ENC_HOOK(x)
        assert str(fast.value) == str(slow.value)
    ins = [[[3], rng.normal(size=3).tobytes()], [[3, 3], rng.normal(size=9).tobytes()], [[3.0], bytes(24)], [[2], bytes(16)], [[3], bytes(23)],
           [[3, 3], bytes(24)], [[9], bytes(72)], [[1, 3], bytes(24)], [[True, 3], bytes(24)], [[3], bytearray(24)], [[3], bytes(24), 0], ([3], bytes(24)),
           [[2 ** 70], bytes(24)], [[-3], bytes(24)], [[3], "x" * 24], [[], bytes(8)], [[2, 3, 4], bytes(192)]]  # fmt: skip
    for x in ins:
        try:
            want = messages.dec_hook(np.ndarray, x)
        except (MessageError, NotImplementedError) as exc:
            with pytest.raises(type(exc)) as got:
                messages.DEC_HOOK(np.ndarray, x)
            assert str(got.value) == str(exc), x
            continue
        assert _same(want, messages.DEC_HOOK(np.ndarray, x)), x
    with pytest.raises(NotImplementedError):
        messages.DEC_HOOK(list, [[3], bytes(24)])
    # Whole messages: the same payload bytes, decoded to the same arrays.
    m = wire.build("sense", 0, 3, 0.5, gyro=rng.normal(size=3), bearings={2: np.array([0.0, 0.6, 0.8]), 5: np.array([1.0, 0.0, 0.0])}, attitude=np.eye(3))
    slow_enc = msgspec.msgpack.Encoder(enc_hook=messages.enc_hook)
    slow_dec = msgspec.msgpack.Decoder(messages.Sense, dec_hook=messages.dec_hook)
    payload = wire.encode_message(m)
    assert payload == slow_enc.encode(m)
    a, b = wire.decode(payload, "sense"), slow_dec.decode(payload)
    for f in ("gyro", "attitude"):
        assert _same(getattr(a, f), getattr(b, f)), f
    assert all(_same(a.bearings[j], b.bearings[j]) for j in (2, 5))


def test_decoded_named_values_are_checked_as_the_python_does(monkeypatch):
    """message_checks._named of a decoded map through kernels.named_decoded gives the Python's map
    (the same names in the same order, the same floats and arrays) or the Python's error, around
    every bound it checks: the value bound and NaN, the name's length, the envelope's names, the
    number of values, the shapes, and what it leaves to the Python (ints, bools, other shapes)."""
    from zswarm.transport import message_checks as mc

    assert kernels.named_decoded is not None, NEEDED
    rng = np.random.default_rng(9)
    M = mc.MAX_ABS

    def arr(*shape, fill=None):
        a = rng.normal(size=shape) if fill is None else np.full(shape, fill)
        return [list(shape), a.tobytes()]

    values = [0.5, -M, M, np.nextafter(M, np.inf), -np.nextafter(M, np.inf), np.nan, np.inf, 3, True, np.float64(2.0), "x", None,
              arr(3), arr(3, 3), arr(3, fill=M), arr(3, 3, fill=-M), arr(3, fill=np.nan), arr(3, 3, fill=np.inf), arr(3, fill=2 * M),
              arr(4), arr(1, 3), arr(2, 2), [[3], bytes(16)], [[3.0], bytes(24)], [[3], bytes(24), 1]]  # fmt: skip
    names = ["a", "sigma", "x" * mc.MAX_NAME, "x" * (mc.MAX_NAME + 1), "", "t", "src", "values_", 5]
    maps = [{n: v} for n in names for v in values[:3] + values[12:14]]
    maps += [{"a": v} for v in values]
    maps += [{f"v{k}": values[(k * 7) % len(values)] for k in range(m)} for m in (2, 5, 12)]
    maps += [{f"v{k}": (0.25 if k % 2 else arr(3)) for k in range(n)} for n in (0, mc.MAX_OPEN, mc.MAX_OPEN + 1)]
    maps += [[("a", 1.0)], "text"]

    def run(m):
        try:
            return mc._named(m, "values")
        except mc.MessageError as exc:
            return exc

    fast = [run(m) for m in maps]
    monkeypatch.setattr(mc, "named_decoded", None)
    slow = [run(m) for m in maps]
    for m, f, w in zip(maps, fast, slow, strict=True):
        if isinstance(w, Exception):
            assert type(f) is type(w) and str(f) == str(w), m
        else:
            assert list(f) == list(w) and all(_same(f[n], w[n]) or (f[n] != f[n] and w[n] != w[n]) for n in w), m
    assert sum(isinstance(w, Exception) for w in slow) > 10 and sum(not isinstance(w, Exception) for w in slow) > 10


def test_the_default_build_gives_the_same_numbers(tmp_path):
    """A CPU without AVX2 and FMA runs the default clones (SSE2, fma() the C library's): built
    alone here (-DZSWARM_DEFAULT_ONLY) and loaded in another interpreter (ZSWARM_KERNELS_FILE),
    it passes these bit-for-bit tests against numpy and gives the golden sim runs' numbers."""
    import shutil
    import subprocess
    import sys
    import sysconfig

    from tests.conftest import ROOT

    gcc = shutil.which("gcc")
    assert gcc is not None, "gcc is needed to build zswarm.math._kernels (pyproject.toml ext-modules)"
    so = tmp_path / "_kernels_default.so"
    flags = ["-O2", "-ffp-contract=off", "-fno-math-errno", "-Wno-psabi", "-DZSWARM_DEFAULT_ONLY", "-shared", "-fPIC"]
    subprocess.run([gcc, *flags, "-I", sysconfig.get_paths()["include"], str(ROOT / "zswarm" / "math" / "_kernels.c"), "-o", str(so), "-lm"], check=True, timeout=120)
    assert b"vfmadd" not in subprocess.run(["objdump", "-d", str(so)], capture_output=True, check=True, timeout=60).stdout  # no FMA instruction in it
    env = {**os.environ, "ZSWARM_KERNELS_FILE": str(so)}
    check = f"import zswarm.math.kernels as k; assert k._lib.__file__ == {str(so)!r}, k._lib.__file__"
    subprocess.run([sys.executable, "-c", check], env=env, check=True, timeout=60, cwd=ROOT)
    # The golden runs of the scenarios whose numbers these loops make most of (noise, the filters).
    golden = ("thesis-5.6-hybrid7-noisy", "thesis-5.6-velocity-free7", "thesis-4.5-continuous5-noisy", "thesis-5.6-velocity-free7-noisy")
    files = ["tests/unit/test_kernels.py", "tests/unit/test_trig.py", "tests/component/test_golden_sim.py"]
    pick = "not default_build and (not test_golden_sim or (test_sim_numbers_are_the_references and (" + " or ".join(golden) + ")))"
    args = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *files, "-k", pick]
    listed = subprocess.run([*args, "--collect-only"], env=env, cwd=ROOT, capture_output=True, text=True, timeout=300, check=True).stdout
    want = {line for line in listed.splitlines() if "::" in line}
    r = subprocess.run([*args, "-rA"], env=env, cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    passed = {line.split(" ", 1)[1] for line in r.stdout.splitlines() if line.startswith("PASSED ")}
    # every test selected passed (none skipped), the kernel and trig tests and the four golden runs among them
    assert passed == want, (sorted(want - passed), sorted(passed - want))
    assert sum("test_sim_numbers_are_the_references" in t for t in passed) == len(golden), sorted(passed)
    assert sum("test_trig.py" in t for t in passed) >= 3 and sum("test_kernels.py" in t for t in passed) >= 10, sorted(passed)
