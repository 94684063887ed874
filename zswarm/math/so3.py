"""Pure SO(3) helpers shared by every algorithm and by the world.

Notation follows the thesis (Boughellaba 2024, §2.1):

* ``hat(x)`` is ``[x]^x``, the skew-symmetric matrix with ``hat(x) @ y = x × y``;
  ``vee`` is its inverse.
* ``psi(C) = vee(Pa(C))`` with ``Pa(C) = (C - C^T)/2`` (eq. (2.5) of the thesis).
* ``Ra(theta, v) = I + sin(theta)[v]^x + (1 - cos(theta))[v]^x^2`` (angle-axis).
* ``attitude_norm(R) = |R|_I = sqrt(tr(I - R)/4)`` in [0, 1]; it equals
  ``sin(theta/2)`` for a rotation by ``theta``.
* ``projector(x) = P_x = I - x x^T/||x||^2``.

Only numpy, the standard library and zswarm.math.kernels (the compiled Rodrigues formula of
exp_batch: the same numbers) are imported here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zswarm.math import kernels
from zswarm.math.trig import sincos

Vec3 = NDArray[np.float64]
Mat3 = NDArray[np.float64]

_EYE = np.eye(3)


def cross(a: Vec3, b: Vec3) -> Vec3:
    """Cross product ``a × b`` of two 3-vectors, or of each pair of stacks (..., 3) (one side
    may be a single vector): the same operations element by element, so a stack's rows are
    the single vectors' bits (the batched engine against sim).

    Hand-written: ``np.cross`` costs ~10 µs of call overhead per 3-vector,
    which dominates an observer step (see DESIGN.md, "Per-agent math").
    """
    if a.ndim > 1 or b.ndim > 1:
        out = np.empty(np.broadcast_shapes(a.shape, b.shape))
        a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
        b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
        np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
        np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
        np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
        return out
    return np.array(
        (
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        )
    )


def dot(a: Vec3, b: Vec3) -> Any:
    """``a · b`` of two 3-vectors (a float), or of each pair of stacks (..., 3) -> (...,):
    ``(a0 b0 + a1 b1) + a2 b2`` in that order either way, so a stack's values are the single
    vectors' bits (``a @ b`` goes to BLAS, whose sum of three may be fused or reordered)."""
    if a.ndim > 1 or b.ndim > 1:
        return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    x0, x1, x2 = a.tolist()
    y0, y1, y2 = b.tolist()
    return x0 * y0 + x1 * y1 + x2 * y2


def mul(A: Mat3, B: Mat3) -> Mat3:
    """``A B`` of two 3x3 matrices, or of each pair of stacks (..., 3, 3) (either may be a single
    matrix, broadcast): ``(a_i0 b_0j + a_i1 b_1j) + a_i2 b_2j``, each product and sum rounded on
    its own (numpy's elementwise ufuncs), so the bits are the same on every CPU, for one matrix
    or a stack, and the same as zswarm/math/_kernels.c's products.

    ``A @ B`` goes to the BLAS, whose kernel is picked at run time (by the CPU and
    ``OPENBLAS_CORETYPE``) and may fuse the multiply-adds or sum in another order, and differs
    between one matrix and a stack: measured, Prescott's kernel against SkylakeX/Haswell/Zen's.
    """
    if kernels.mul1 is not None:  # one product in C, the same operations (False: not two 3x3 float64 arrays)
        out = np.empty((3, 3))
        if kernels.mul1(A, B, out):
            return out
    A = np.asarray(A, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    if A.shape == (3, 3) and B.shape == (3, 3):  # one product: the same operations on Python floats, a third of the time
        (a, b, c), (d, e, f), (g, h, i) = A.tolist()
        (p, q, r), (s, t, u), (w, x, y) = B.tolist()
        return np.array(
            (
                ((a * p + b * s) + c * w, (a * q + b * t) + c * x, (a * r + b * u) + c * y),
                ((d * p + e * s) + f * w, (d * q + e * t) + f * x, (d * r + e * u) + f * y),
                ((g * p + h * s) + i * w, (g * q + h * t) + i * x, (g * r + h * u) + i * y),
            )
        )
    return (A[..., :, 0:1] * B[..., 0:1, :] + A[..., :, 1:2] * B[..., 1:2, :]) + A[..., :, 2:3] * B[..., 2:3, :]


def apply(R: Mat3, v: Vec3) -> Vec3:
    """``R v``: a matrix times a vector, or each of stacks (..., 3, 3) and (..., 3) (either may
    be a single one, broadcast), summed ``(r_i0 v_0 + r_i1 v_1) + r_i2 v_2`` as :func:`mul`
    does: no BLAS, so one draw and a stack of draws give the same bits on every CPU."""
    if kernels.apply1 is not None:  # one product in C, the same operations (False: not a 3x3 and a 3-vector float64 array)
        out = np.empty(3)
        if kernels.apply1(R, v, out):
            return out
    R = np.asarray(R, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if R.shape == (3, 3) and v.shape == (3,):  # one product: the same operations on Python floats (R @ v took 1.4 µs, this 0.9)
        (a, b, c), (d, e, f), (g, h, i) = R.tolist()
        x, y, z = v.tolist()
        return np.array(((a * x + b * y) + c * z, (d * x + e * y) + f * z, (g * x + h * y) + i * z))
    return (R[..., :, 0] * v[..., 0, None] + R[..., :, 1] * v[..., 1, None]) + R[..., :, 2] * v[..., 2, None]


def hat(x: Vec3) -> Mat3:
    """Skew-symmetric matrix ``[x]^x`` such that ``hat(x) @ y == x × y``."""
    return np.array(
        (
            (0.0, -x[2], x[1]),
            (x[2], 0.0, -x[0]),
            (-x[1], x[0], 0.0),
        )
    )


def vee(S: Mat3) -> Vec3:
    """Inverse of :func:`hat` (reads the skew part of ``S`` only)."""
    return np.array((S[2, 1], S[0, 2], S[1, 0]))


def Pa(C: Mat3) -> Mat3:
    """Anti-symmetric part ``(C - C^T)/2``."""
    return 0.5 * (C - C.T)


def psi(C: Mat3) -> Vec3:
    """``psi(C) = vee(Pa(C))`` (thesis eq. (2.5)); a stack (..., 3, 3) gives (..., 3)."""
    if C.ndim > 2:
        out = np.empty(C.shape[:-1])  # the same operations as below, written in place (np.stack cost twice as much)
        np.subtract(C[..., 2, 1], C[..., 1, 2], out=out[..., 0])
        np.subtract(C[..., 0, 2], C[..., 2, 0], out=out[..., 1])
        np.subtract(C[..., 1, 0], C[..., 0, 1], out=out[..., 2])
        out *= 0.5
        return out
    return 0.5 * np.array((C[2, 1] - C[1, 2], C[0, 2] - C[2, 0], C[1, 0] - C[0, 1]))


def trace(X: NDArray[np.float64]) -> NDArray[np.float64]:
    """The trace of each matrix of a stack (..., 3, 3): ``(X00 + X11) + X22``, np.trace's own
    sum of three, at a sixth of its cost on a stack of a thousand."""
    return X[..., 0, 0] + X[..., 1, 1] + X[..., 2, 2]  # type: ignore[no-any-return]


def T(R: Mat3) -> Mat3:
    """The transpose of a matrix or of each of a stack (..., 3, 3)."""
    return np.swapaxes(R, -1, -2)


def exp(w: Vec3) -> Mat3:
    """Exponential map ``exp([w]^x)`` by Rodrigues' formula.

    Uses the Taylor expansions of ``sin(t)/t`` and ``(1-cos t)/t^2`` below
    ``t = 1e-4`` rad, where the closed forms lose digits to cancellation.  A stack
    (..., 3) gives (..., 3, 3) (:func:`exp_batch`, the same formula).
    """
    if type(w) is np.ndarray and w.ndim > 1:
        return exp_batch(w.reshape(-1, 3)).reshape(w.shape[:-1] + (3, 3))
    if kernels.exp1 is not None:  # the lines below in C, the same operations (False: not a float64 (3,) array)
        out = np.empty((3, 3))
        if kernels.exp1(w, out):
            return out
    x, y, z = w.tolist() if type(w) is np.ndarray else (float(w[0]), float(w[1]), float(w[2]))
    t2 = x * x + y * y + z * z
    if t2 < 1e-8:
        a = 1.0 - t2 / 6.0
        b = 0.5 - t2 / 24.0
    else:
        t = math.sqrt(t2)
        sn, cs = sincos(t)  # zswarm/math/trig.py: exp_batch's sin and cos
        a = sn / t
        b = (1.0 - cs) / t2
    # I + a[w]^x + b[w]^x², with [w]^x² = w wᵀ − |w|² I, written out (a third of
    # the cost of the matrix expression for one 3-vector).
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    return np.array(
        (
            (1.0 - b * (y * y + z * z), bxy - a * z, bxz + a * y),
            (bxy + a * z, 1.0 - b * (x * x + z * z), byz - a * x),
            (bxz - a * y, byz + a * x, 1.0 - b * (x * x + y * y)),
        )
    )


def exp_batch(W: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rodrigues' formula for a stack of rotation vectors, shape (n, 3) -> (n, 3, 3); sin and cos
    by zswarm/math/trig.py (four vectors to an instruction when compiled)."""
    W = np.asarray(W, dtype=np.float64)
    if kernels.exp_batch is not None:  # the lines below, compiled (zswarm/math/_kernels.c): the same numbers
        return kernels.exp_batch(W)
    t2 = (W[:, 0] * W[:, 0] + W[:, 2] * W[:, 2]) + W[:, 1] * W[:, 1]  # the compiled loop's order
    small = t2 < 1e-8
    t = np.sqrt(np.where(small, 1.0, t2))
    sn, cs = sincos(t)  # zswarm/math/trig.py, as the compiled loop's
    a = np.where(small, 1.0 - t2 / 6.0, sn / t)
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - cs) / np.where(small, 1.0, t2))
    K = np.zeros((W.shape[0], 3, 3))
    K[:, 0, 1] = -W[:, 2]
    K[:, 0, 2] = W[:, 1]
    K[:, 1, 0] = W[:, 2]
    K[:, 1, 2] = -W[:, 0]
    K[:, 2, 0] = -W[:, 1]
    K[:, 2, 1] = W[:, 0]
    return _EYE + a[:, None, None] * K + b[:, None, None] * mul(K, K)


def log(R: Mat3) -> Vec3:
    """Logarithm map: the rotation vector ``w`` with ``exp(w) = R``, ``|w| <= pi``.

    Near ``theta = pi`` the antisymmetric part vanishes, so the axis is taken
    from the symmetric part ``(R + I)/2 = v v^T`` instead.  A stack (..., 3, 3) gives
    (..., 3); one matrix goes the way of a stack of one (:func:`log_batch`), so that sim's
    one draw and the batched engine's stack do the same arithmetic.
    """
    if R.ndim > 2:
        return log_batch(R.reshape(-1, 3, 3)).reshape(R.shape[:-2] + (3,))
    return log_batch(np.asarray(R, dtype=np.float64)[None])[0]


def _log_near_pi(R: Mat3) -> Vec3:
    """:func:`log` of one matrix, with its branch near π."""
    c = (float(np.trace(R)) - 1.0) * 0.5
    s = psi(R)  # = sin(theta) * v
    # atan2, not acos: near theta = pi, acos(c) loses half the digits (an error
    # of 1e-8 rad from c = -1 + 1e-16), while |s| = sin(theta) is accurate there.
    theta = math.atan2(math.sqrt(dot(s, s)), c)
    if theta < 1e-6:
        return s * (1.0 + theta * theta / 6.0)
    if theta < math.pi - 1e-4:
        return s * (theta / math.sin(theta))
    # The symmetric part: (R_s + I)/2 = cos²(θ/2) I + sin²(θ/2) v v^T.  R's skew part, sin θ [v]^x,
    # is not zero this near π (up to 1e-4): left in, it turned the axis by up to ~1e-5 rad.
    B = 0.5 * (0.5 * (R + R.T) + _EYE)
    k = int(np.argmax(np.diag(B)))
    v = B[:, k] / math.sqrt(max(B[k, k], 1e-300))
    v = v / np.linalg.norm(v)
    if dot(v, s) < 0.0:  # pick the sign consistent with the small skew part
        v = -v
    return theta * v


def log_batch(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`log` of each of a stack (n, 3, 3) -> (n, 3): its branches, element by element,
    θ by the C library's atan2 (math.atan2, as the compiled loop calls it; numpy's own differs
    in the last bit for ~3 % of arguments)."""
    if kernels.log_stack is not None:  # the lines below, compiled (zswarm/math/_kernels.c): the same numbers
        out = kernels.log_stack(R)
        near_pi = np.isnan(out[:, 0])
    else:
        c = (trace(R) - 1.0) * 0.5
        s = psi(R)
        r = np.sqrt((s[:, 0] * s[:, 0] + s[:, 2] * s[:, 2]) + s[:, 1] * s[:, 1])  # the compiled loop's order
        theta = np.fromiter(map(math.atan2, r.tolist(), c.tolist()), float, len(r))
        small = theta < 1e-6
        mid = ~small & (theta < math.pi - 1e-4)
        out = np.empty_like(s)
        out[small] = s[small] * (1.0 + theta[small, None] ** 2 / 6.0)
        th = theta[mid]
        out[mid] = s[mid] * (th / np.fromiter(map(math.sin, th.tolist()), float, len(th)))[:, None]  # the C library's sin, as compiled
        near_pi = ~small & ~mid
    for n in np.flatnonzero(near_pi):  # near π: rare, each on its own
        out[n] = _log_near_pi(R[n])
    return out


def Ra(theta: float, v: Vec3) -> Mat3:
    """Angle-axis rotation ``Ra(theta, v)``; ``v`` need not be unit (it is normalised).
    ``theta`` an array (M,) gives a stack (M, 3, 3), each by the same operations."""
    v = np.asarray(v, dtype=np.float64)
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise ValueError("Ra: rotation axis must be non-zero")
    K = hat(v / n)
    if isinstance(theta, np.ndarray):
        return _EYE + np.sin(theta)[..., None, None] * K + (1.0 - np.cos(theta))[..., None, None] * mul(K, K)
    return _EYE + math.sin(theta) * K + (1.0 - math.cos(theta)) * mul(K, K)


def attitude_norm(R: Mat3) -> float:
    """``|R|_I = sqrt(tr(I - R)/4)`` in [0, 1] (thesis §2.1): tr R ∈ [−1, 3] for a rotation,
    so the bounds only take off round-off (tr R = −1 − 4e-16 at a half turn gave 1 + 2e-16)."""
    return math.sqrt(min(1.0, max(0.0, (3.0 - float(np.trace(R))) * 0.25)))


def projector(x: Vec3) -> Mat3:
    """Orthogonal projector ``P_x = I - x x^T/||x||^2`` onto the plane normal to ``x``."""
    n2 = float(x @ x)
    return _EYE - np.outer(x, x) / n2


def is_rotation(R: Mat3, tol: float = 1e-9) -> bool:
    """True when ``R^T R = I`` and ``det R = 1`` within ``tol``."""
    R = np.asarray(R)
    return (
        R.shape == (3, 3)
        and bool(np.all(np.isfinite(R)))
        and float(np.max(np.abs(R.T @ R - _EYE))) <= tol
        and abs(float(np.linalg.det(R)) - 1.0) <= tol
    )


def rotations_ok(M: NDArray[np.float64], tol: float) -> bool:
    """True when every 3x3 matrix of the stack ``M`` (..., 3, 3) is a rotation within ``tol``:
    each entry of ``R^T R − I`` and ``det R − 1`` at most ``tol`` in magnitude (entries finite).

    One matrix (what most messages carry) in plain Python: 2 µs against 70 µs of numpy's
    per-call overhead for the stacked form, which was a third of a ``sim`` run's time."""
    M = np.asarray(M)
    if M.shape == (3, 3):
        # A read-only (received) matrix in C, the same sums and verdicts (zswarm/math/_kernels.c f8_check);
        # False there (writable, NaN, not float64) is decided here.
        if kernels.f8_ok is not None and kernels.f8_ok(M, 9, kernels.CHECK_ROTATION, math.inf, tol):
            return True
        return _rotation_ok(M.ravel().tolist(), tol)
    M = M.reshape(-1, 3, 3)
    if not M.shape[0]:
        return True
    if M.shape[0] <= 8:
        return all(_rotation_ok(R.ravel().tolist(), tol) for R in M)
    E = np.matmul(M.transpose(0, 2, 1), M) - _EYE
    a, b, c = M[:, 0, 0], M[:, 0, 1], M[:, 0, 2]
    d, e, f = M[:, 1, 0], M[:, 1, 1], M[:, 1, 2]
    g, h, i = M[:, 2, 0], M[:, 2, 1], M[:, 2, 2]
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return bool(np.abs(E).max() <= tol) and bool(np.abs(det - 1.0).max() <= tol)


def _rotation_ok(m: list[float], tol: float) -> bool:
    """:func:`rotations_ok` of one matrix given row-major as 9 floats (False for NaN)."""
    a, b, c, d, e, f, g, h, i = m
    return (
        abs(a * a + d * d + g * g - 1.0) <= tol
        and abs(b * b + e * e + h * h - 1.0) <= tol
        and abs(c * c + f * f + i * i - 1.0) <= tol
        and abs(a * b + d * e + g * h) <= tol
        and abs(a * c + d * f + g * i) <= tol
        and abs(b * c + e * f + h * i) <= tol
        and abs(a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) - 1.0) <= tol
    )


def geodesic_interp(R0: Mat3, R1: Mat3, s: float) -> Mat3:
    """Point at fraction ``s`` of the geodesic from ``R0`` to ``R1`` (``R0 exp(s log(R0^T R1))``)."""
    return mul(R0, exp(s * log(mul(R0.T, R1))))


def quaternion(R: Mat3) -> tuple[float, float, float, float]:
    """The unit quaternion ``(x, y, z, w)`` of a rotation, with ``w >= 0`` (Shepperd's method).

    Picks the largest of ``w², x², y², z²`` to divide by, so it is accurate for
    every rotation (the naive ``w = sqrt(1 + tr R)/2`` loses all digits near π).
    """
    m = R
    tr = float(m[0, 0] + m[1, 1] + m[2, 2])
    d = (tr, float(m[0, 0]), float(m[1, 1]), float(m[2, 2]))
    k = max(range(4), key=d.__getitem__)
    if k == 0:
        s = 2.0 * math.sqrt(max(1.0 + tr, 0.0))
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif k == 1:
        s = 2.0 * math.sqrt(max(1.0 + m[0, 0] - m[1, 1] - m[2, 2], 0.0))
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif k == 2:
        s = 2.0 * math.sqrt(max(1.0 - m[0, 0] + m[1, 1] - m[2, 2], 0.0))
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 - m[0, 0] - m[1, 1] + m[2, 2], 0.0))
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    sign = 1.0 if w >= 0 else -1.0
    return (sign * float(x) / n, sign * float(y) / n, sign * float(z) / n, sign * float(w) / n)


def nearest_rotations(A: np.ndarray) -> np.ndarray:
    """The rotation nearest to each matrix of a stack (T, 3, 3): U diag(1, 1, ±1) V^T of its SVD
    (the chordal mean of rotations: the nearest rotation to their average)."""
    U, _, Vt = np.linalg.svd(A)
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    D = np.zeros_like(A)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    return U @ D @ Vt  # type: ignore[no-any-return]
