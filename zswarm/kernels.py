"""zswarm's compiled loops (zswarm/_kernels.c), for the hot spots that the batched engine's
profile shows and numpy cannot make cheap: the rigid-body step of every body and world step,
Rodrigues' formula on stacks, the ξ_k filter's Heun sub-steps and the velocity-free law's
(Q_i, ζ_i) filter (agent/batched.py, issue 31).

Each does the operations of the numpy or Python code it replaces in the same order, so the
numbers are the same with or without it (tests/unit/test_kernels.py checks it bit for bit,
and the golden sim runs of tests/component/test_golden_sim.py pass either way); only the
time differs.  The library is built at install as an optional extension (pyproject.toml
``ext-modules``): where no C compiler is found, or with ``ZSWARM_KERNELS=0`` in the
environment, every function here is None and the callers use numpy.
"""

from __future__ import annotations

import ctypes
import importlib.util
import os
from collections.abc import Callable
from typing import Any

import numpy as np

_c_double_p = ctypes.POINTER(ctypes.c_double)


def _load() -> ctypes.CDLL | None:
    if os.environ.get("ZSWARM_KERNELS", "1") == "0":
        return None
    spec = importlib.util.find_spec("zswarm._kernels")
    if spec is None or spec.origin is None:
        return None
    try:
        return ctypes.CDLL(spec.origin)
    except OSError:
        return None


_lib = _load()


def _ptr(a: np.ndarray) -> Any:
    return a.ctypes.data_as(_c_double_p)


def _f64(a: Any, shape: tuple[int, ...]) -> np.ndarray:
    return np.ascontiguousarray(np.broadcast_to(np.asarray(a, dtype=np.float64), shape))


exp_batch: Callable[[np.ndarray], np.ndarray] | None = None
rigid_step: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float], tuple[np.ndarray, np.ndarray]] | None = None
flow_xi: Callable[..., Any] | None = None
flow_aux: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None

if _lib is not None:
    lib = _lib
    lib.rigid_step.restype = None
    lib.rigid_step.argtypes = [ctypes.c_size_t, _c_double_p, _c_double_p, _c_double_p, _c_double_p, ctypes.c_double, _c_double_p, _c_double_p]
    lib.exp_batch.restype = None
    lib.exp_batch.argtypes = [ctypes.c_size_t, _c_double_p, _c_double_p]
    lib.flow_xi.restype = None
    lib.flow_xi.argtypes = [ctypes.c_size_t] + [_c_double_p] * 7 + [ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_long]
    lib.flow_xi_one.restype = ctypes.c_double
    lib.flow_xi_one.argtypes = [ctypes.c_double] * 10 + [ctypes.c_long]
    lib.flow_aux.restype = None
    lib.flow_aux.argtypes = [ctypes.c_size_t, ctypes.c_long] + [_c_double_p] * 3 + [ctypes.POINTER(ctypes.c_int64), ctypes.c_double] + [_c_double_p] * 4 + [ctypes.c_double] * 3

    def _exp_batch(W: np.ndarray) -> np.ndarray:
        """zswarm.so3.exp_batch of (n, 3) rotation vectors: (n, 3, 3)."""
        W = np.ascontiguousarray(W, dtype=np.float64)
        E = np.empty((W.shape[0], 3, 3))
        lib.exp_batch(W.shape[0], _ptr(W), _ptr(E))
        return E

    def _rigid_step(R: np.ndarray, w: np.ndarray, J_inv: np.ndarray, tau: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """``(R⁺, ω⁺)`` of world.dynamics.RigidBodies.step for isotropic inertias (new arrays)."""
        n = w.shape[0]
        R, w, J_inv, tau = (np.ascontiguousarray(x, dtype=np.float64) for x in (R, w, J_inv, tau))
        R_out, w_out = np.empty_like(R), np.empty_like(w)
        lib.rigid_step(n, _ptr(R), _ptr(w), _ptr(J_inv), _ptr(tau), h, _ptr(R_out), _ptr(w_out))
        return R_out, w_out

    def _flow_xi(c0: tuple[Any, Any, Any], c1: tuple[Any, Any, Any], xi: Any, dt: float, k_xi: float, gamma: float, n: int) -> Any:
        """attitude_sync_terms.flow_xi's sub-steps: ξ a float, or an array of M draws (then the
        coefficients are arrays of M or numbers)."""
        if not isinstance(xi, np.ndarray):
            return lib.flow_xi_one(*c0, *c1, xi, dt, k_xi, gamma, n)
        shape = xi.shape
        x = np.array(xi, dtype=np.float64, order="C")  # a copy: flowed in place
        cs = [_f64(c, shape) for c in (*c0, *c1)]
        lib.flow_xi(x.size, *(_ptr(c) for c in cs), _ptr(x), dt, k_xi, gamma, n)
        return x

    def _flow_aux(Qt: np.ndarray, z: np.ndarray, table: np.ndarray, rows: np.ndarray, h: float, A: np.ndarray, K: np.ndarray, K2: np.ndarray, u2: np.ndarray, k_Q: float, k_zeta: float, gamma: float) -> tuple[np.ndarray, np.ndarray]:
        """attitude_sync_velocity_free.flow_aux's sub-steps: (Q̃ (M, 3, 3), ζ (M,)) after len(rows)
        sub-steps of h, sub-step m at the body rate table[rows[m]] (table (rows, M, 3)); new arrays."""
        M = z.shape[0]
        Q_out = np.array(Qt, dtype=np.float64, order="C")  # copies: flowed in place
        z_out = np.array(z, dtype=np.float64, order="C")
        tab = _f64(table, (table.shape[0], M, 3))
        r = np.ascontiguousarray(rows, dtype=np.int64)
        if r.size and (r.min() < 0 or r.max() >= tab.shape[0]):
            raise IndexError("flow_aux: a sub-step's row is outside the rate table")
        mats = [_f64(x, (3, 3)) for x in (A, K, K2)]
        u = _f64(u2, (3,))
        lib.flow_aux(M, r.size, _ptr(Q_out), _ptr(z_out), _ptr(tab), r.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), h, *(_ptr(x) for x in mats), _ptr(u), k_Q, k_zeta, gamma)
        return Q_out, z_out

    exp_batch, rigid_step, flow_xi, flow_aux = _exp_batch, _rigid_step, _flow_xi, _flow_aux
