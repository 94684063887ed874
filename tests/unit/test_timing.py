"""The timing library (zswarm/math/timing.py) against fine integrations of the same motion.

The reference integrates Ṙ = R[ω(t)]^x with 20 000 exponential steps over the
interval, ω the same piecewise-linear interpolation of the samples the
library sees; its own error (O(h²) per step, h = 0.5 µs) is below 1e-14.
"""

import math

import numpy as np
import pytest

from zswarm.math import so3
from zswarm.math.timing import body_vector_at, interval_mean_rate, relative_attitude_at, rotation_over, rotation_rate


def w(t):
    return np.array([1 - np.cos(2 * t), 1 + 0.5 * np.sin(3 * t), 2 + np.sin(9 * t)])


TS = np.arange(0.0, 0.05, 0.005)
GYRO = [(float(t), w(t)) for t in TS]


def reference(t0, t1, n=20000):
    R = np.eye(3)
    h = (t1 - t0) / n
    for k in range(n):
        t = t0 + (k + 0.5) * h
        R = R @ so3.exp(h * np.array([np.interp(t, TS, [s[1][c] for s in GYRO]) for c in range(3)]))
    return R


@pytest.mark.parametrize("t0, t1", [(0.0123, 0.0223), (0.0, 0.005), (0.007, 0.031)])
def test_rotation_rate_is_third_order_where_the_mean_rate_is_not(t0, t1):
    R = reference(t0, t1)
    err_mean = np.linalg.norm(so3.log(so3.exp((t1 - t0) * interval_mean_rate(GYRO, t0, t1)).T @ R))
    err_magnus = np.linalg.norm(so3.log(rotation_over(GYRO, t0, t1).T @ R))
    # The mean rate misses the (h³/12) ω×ω̇ Magnus term, O(h³): 6e-8, 5e-7, 7e-6 rad
    # over these 5, 10, 24 ms.  The second-order Magnus/BCH leaves the next orders,
    # smaller by about (h|ω|)² ≤ (0.024 s · 3 rad/s)² = 5e-3.
    assert err_mean > 5e-8
    assert err_magnus < 1e-2 * err_mean


def test_rotation_over_backwards_is_the_inverse():
    R = rotation_over(GYRO, 0.004, 0.017)
    assert np.allclose(rotation_over(GYRO, 0.017, 0.004), R.T, atol=1e-15)
    assert np.array_equal(rotation_over(GYRO, 0.01, 0.01), np.eye(3))
    assert np.allclose(rotation_rate(GYRO, 0.0, 0.005) * 0.005, so3.log(rotation_over(GYRO, 0.0, 0.005)), atol=1e-15)


def test_relative_attitude_is_exact_at_samples_and_follows_both_bodies_between():
    """R_ij = R_i^T R_j for two bodies; i's gyro is known, j's rotation is interpolated."""
    wj = lambda t: np.array([0.3, -1.0 + t, 0.5])  # noqa: E731  (j's rate: slowly varying)
    Ri, Rj = so3.Ra(0.3, np.array([1.0, 0, 0])), so3.Ra(-0.7, np.array([0, 1.0, 1]))
    hist, truth = [], {}
    h = 1e-5
    for k in range(int(round(0.05 / h)) + 1):
        t = k * h
        if k % 500 == 0:
            hist.append((round(t, 9), Ri.T @ Rj))
        if k % 50 == 0:
            truth[round(t, 9)] = Ri.T @ Rj
        Ri = Ri @ so3.exp(h * np.array([np.interp(t + h / 2, TS, [s[1][c] for s in GYRO]) for c in range(3)]))
        Rj = Rj @ so3.exp(h * wj(t + h / 2))
    for t, R in hist:
        assert np.array_equal(relative_attitude_at(hist, GYRO, t), R)
    for t in (0.0125, 0.0305, 0.0445):
        got = relative_attitude_at(hist, GYRO, t)
        # j's rate changes by ω̇_j h = 5e-3 rad/s over a 5 ms gap; interpolating its
        # rotation at a constant rate errs by ≈ ω̇_j h²/8 = 3e-6 rad at most.
        assert np.linalg.norm(so3.log(got.T @ truth[round(t, 9)])) < 5e-6
    assert relative_attitude_at(hist, GYRO, 1.0) is None


def test_body_vector_across_a_gap_follows_the_gyro_history():
    """A fixed inertial direction seen from the body, sampled with three samples missing
    (a 20 ms gap, as when the world skips samples), looked up inside the gap."""
    kept = [s_ for s_ in GYRO if not 0.008 < s_[0] < 0.022]  # 0, 0.005, then 0.025, 0.03, ...
    ts = [t for t, _ in kept]

    def R_at(t, n=4000):  # Ṙ = R[ω]^x on the piecewise-linear gyro of the kept samples, from R(0) = I
        R, h = np.eye(3), t / n
        for k in range(n):
            tm = (k + 0.5) * h
            R = R @ so3.exp(h * np.array([np.interp(tm, ts, [w_[c] for _, w_ in kept]) for c in range(3)]))
        return R

    g = np.array([0.6, -0.8, 0.0])  # inertial unit vector
    hist = [(t, R_at(t).T @ g, w_) for t, w_ in kept]
    for t, b, _ in hist:
        # At a sample, the sample over its length: the same bits as a plain sum in the same
        # order ((x² + y²) + z², as so3.dot), not as np.linalg.norm, whose BLAS dot rounds by
        # the CPU's kernel.
        assert np.array_equal(body_vector_at(hist, t), b / math.sqrt((b[0] * b[0] + b[1] * b[1]) + b[2] * b[2]))
    for t in (0.0075, 0.0125, 0.02):
        truth = R_at(t).T @ g
        got = body_vector_at(hist, t)
        # The newer sample's rate held over the gap (the former method) errs by
        # ≈ ½|ω̇|h², 2–4e-4 rad here; the gyro history's rotation is third order on this
        # piecewise-linear rate (1e-10 here), and a fixed direction interpolates exactly.
        (t0, b0, _), (t1, b1, w1) = hist[1], hist[2]
        s_ = (t - t0) / (t1 - t0)
        old = so3.exp(-(t - t1) * w1) @ ((1 - s_) * so3.exp(-(t1 - t0) * w1) @ b0 + s_ * b1)
        old /= np.linalg.norm(old)
        assert np.linalg.norm(got - truth) < 1e-2 * np.linalg.norm(old - truth), (t, np.linalg.norm(got - truth), np.linalg.norm(old - truth))


def test_relative_attitude_without_gyro_follows_the_geodesic():
    """A velocity-free agent has no gyro: R_ij between (and just past) samples is on their geodesic."""
    import numpy as np

    from zswarm.math import so3, timing

    R0 = so3.Ra(0.3, np.array([1.0, 2.0, 0.5]))
    w = np.array([0.2, -0.1, 0.4])
    hist = [(0.0, R0), (0.005, R0 @ so3.exp(0.005 * w))]
    for t in (0.0025, 0.005, 0.008):
        got = timing.relative_attitude_at(hist, [], t)
        assert np.allclose(got, R0 @ so3.exp(t * w), atol=1e-12)
