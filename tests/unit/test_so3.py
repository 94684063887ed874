"""SO(3) identities at tight tolerances, cross-checked against scipy's Rotation.

Tolerances: 1e-12 for identities that hold exactly in exact arithmetic on
well-conditioned inputs (a few ulps of float64 times the 3×3 products), 1e-9
near θ = π where log is conditioned by 1/sin θ.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from tests.conftest import examples
from zswarm.math import so3

vec = st.lists(st.floats(-10, 10, allow_nan=False), min_size=3, max_size=3).map(np.array)
angle = st.floats(0.0, math.pi)
axis = vec.filter(lambda v: np.linalg.norm(v) > 1e-3)


@given(vec, vec)
def test_hat_is_cross_product(a, b):
    assert np.allclose(so3.hat(a) @ b, np.cross(a, b), atol=1e-12)
    assert np.allclose(so3.cross(a, b), np.cross(a, b), atol=1e-12)
    assert np.allclose(so3.vee(so3.hat(a)), a, atol=0)


@given(vec)
def test_exp_is_a_rotation_and_matches_scipy(w):
    R = so3.exp(w)
    assert so3.is_rotation(R, 1e-12)
    assert np.allclose(R, Rotation.from_rotvec(w).as_matrix(), atol=1e-12)


@given(angle, axis)
def test_log_inverts_exp(theta, v):
    w = theta * v / np.linalg.norm(v)
    R = so3.exp(w)
    w2 = so3.log(R)
    assert np.allclose(so3.exp(w2), R, atol=1e-9)
    assert np.linalg.norm(w2) <= math.pi + 1e-12


@pytest.mark.parametrize("theta", [0.0, 1e-10, 1e-7, 1e-4, 0.5, math.pi - 1e-3, math.pi - 1e-6, math.pi])
def test_log_near_zero_and_pi(theta):
    v = np.array([0.3, -0.5, 0.8])
    v /= np.linalg.norm(v)
    R = so3.Ra(theta, v)
    w = so3.log(R)
    assert np.allclose(so3.exp(w), R, atol=1e-9)
    assert abs(np.linalg.norm(w) - theta) < 1e-9
    if 0 < theta < math.pi - 1e-5:
        assert np.allclose(w / np.linalg.norm(w), v, atol=1e-6)


@given(angle, axis)
def test_Ra_matches_exp_and_attitude_norm_is_sin_half_angle(theta, v):
    R = so3.Ra(theta, v)
    assert np.allclose(R, so3.exp(theta * v / np.linalg.norm(v)), atol=1e-12)
    assert abs(so3.attitude_norm(R) - math.sin(theta / 2)) < 1e-7
    assert 0.0 <= so3.attitude_norm(R) <= 1.0


@given(vec)
def test_psi_of_rotation_is_sin_theta_axis(w):
    R = so3.exp(w)
    th = np.linalg.norm(w)
    if th > 1e-6:
        assert np.allclose(so3.psi(R), math.sin(th) * w / th, atol=1e-12)


@settings(max_examples=examples(50))
@given(vec, vec)
def test_exp_batch_matches_exp(a, b):
    W = np.stack([a, b, np.zeros(3), 1e-6 * a])
    Rs = so3.exp_batch(W)
    for k in range(4):
        assert np.allclose(Rs[k], so3.exp(W[k]), atol=1e-13)


@given(axis, vec)
def test_projector(x, y):
    P = so3.projector(x)
    assert np.allclose(P @ x, 0, atol=1e-9)
    assert np.allclose(P @ P, P, atol=1e-12)
    assert np.allclose(P, P.T, atol=0)


def test_geodesic_interp_endpoints_and_midpoint():
    R0 = so3.Ra(0.3, np.array([1.0, 0, 0]))
    R1 = so3.Ra(1.1, np.array([1.0, 0, 0]))
    assert np.allclose(so3.geodesic_interp(R0, R1, 0.0), R0, atol=1e-12)
    assert np.allclose(so3.geodesic_interp(R0, R1, 1.0), R1, atol=1e-12)
    assert np.allclose(so3.geodesic_interp(R0, R1, 0.5), so3.Ra(0.7, np.array([1.0, 0, 0])), atol=1e-12)


@given(angle, axis)
@settings(max_examples=examples(300))
def test_quaternion_matches_scipy_and_rebuilds_R(theta, v):
    """The (x, y, z, w), w ≥ 0 quaternion of Ra(θ, v) is scipy's up to sign and gives
    back R; near θ = π too (1e-12: Shepperd's method divides by the largest of
    4w², 4x², 4y², 4z², which is ≥ 1, so nothing is ill-conditioned)."""
    R = so3.Ra(theta, v / np.linalg.norm(v))
    q = np.array(so3.quaternion(R))
    ref = Rotation.from_matrix(R).as_quat()  # (x, y, z, w)
    ref = ref if ref[3] > 0 or (ref[3] == 0 and q @ ref > 0) else -ref
    assert q[3] >= 0.0
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    assert min(np.max(np.abs(q - ref)), np.max(np.abs(q + ref))) < 1e-12
    assert np.max(np.abs(Rotation.from_quat(q).as_matrix() - R)) < 1e-12


def test_mul_and_apply_are_the_same_sums_for_one_matrix_and_a_stack():
    """so3.mul and so3.apply: (a_i0 b_0j + a_i1 b_1j) + a_i2 b_2j, each operation rounded, so one
    matrix (Python floats) and each matrix of a stack (numpy's elementwise ufuncs) give the same
    bits, and both agree with the exact product to round-off."""
    from zswarm.math.so3 import apply, exp_batch, mul

    rng = np.random.default_rng(23)
    A, B = exp_batch(rng.normal(size=(200, 3)) * 2.0), exp_batch(rng.normal(size=(200, 3)) * 2.0)
    v = rng.normal(size=(200, 3)) * 10.0
    AB, Av = mul(A, B), apply(A, v)
    for m in range(len(A)):
        assert np.array_equal(mul(A[m], B[m]), AB[m]) and np.array_equal(apply(A[m], v[m]), Av[m])
        by_hand = [[(A[m, i, 0] * B[m, 0, j] + A[m, i, 1] * B[m, 1, j]) + A[m, i, 2] * B[m, 2, j] for j in range(3)] for i in range(3)]
        assert np.array_equal(AB[m], np.array(by_hand))
    # broadcasting one matrix over a stack, either side
    assert np.array_equal(mul(A[0], B), np.array([mul(A[0], b) for b in B])) and np.array_equal(mul(A, B[0]), np.array([mul(a, B[0]) for a in A]))
    assert np.array_equal(apply(A[0], v), np.array([apply(A[0], x) for x in v]))
    # three products of entries <= 1 summed: within 3 ulps of 1 of the exact (long double) product
    exact = np.einsum("nik,nkj->nij", A.astype(np.longdouble), B.astype(np.longdouble))
    assert np.max(np.abs(AB - exact)) <= 3 * 2.0**-52
