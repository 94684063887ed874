"""zswarm's compiled loops (zswarm/math/_kernels.c), for the hot spots that the batched engine's
profile shows and numpy cannot make cheap: the rigid-body step of every body and world step,
Rodrigues' formula on stacks, the ξ_k filter's Heun sub-steps, the velocity-free law's
(Q_i, ζ_i) filter, and the Chapter 5 laws' R̄ prediction and potential Terms (agent/batched.py,
issue 31).

Each does the operations of the numpy or Python code it replaces in the same order, so the
numbers are the same with or without it (tests/unit/test_kernels.py checks it bit for bit,
and the golden sim runs of tests/component/test_golden_sim.py pass either way); only the
time differs.  The module is built at install as an optional extension (pyproject.toml
``ext-modules``; arrays reach it through the buffer protocol, checked for kind, layout and
size): where no C compiler is found, or with ``ZSWARM_KERNELS=0`` in the environment, every
function here is None and the callers use numpy.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from collections.abc import Callable
from types import ModuleType
from typing import Any

import numpy as np

_F8 = np.dtype(np.float64)


def _load() -> ModuleType | None:
    if os.environ.get("ZSWARM_KERNELS", "1") == "0":
        return None
    other = os.environ.get("ZSWARM_KERNELS_FILE")
    if other:  # another build of zswarm/math/_kernels.c (tests/unit/test_kernels.py: the default one alone)
        spec = importlib.util.spec_from_file_location("zswarm.math._kernels", other)
        if spec is None or spec.loader is None:
            raise ImportError(f"ZSWARM_KERNELS_FILE={other}: not a Python extension module")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    try:
        return importlib.import_module("zswarm.math._kernels")
    except ImportError:  # not built (no C compiler at install)
        return None


_lib = _load()


def _f64(a: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` as a C-contiguous float64 array of ``shape`` (broadcast); itself when it is one."""
    if type(a) is np.ndarray and a.dtype is _F8 and a.shape == shape and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(np.broadcast_to(np.asarray(a, dtype=np.float64), shape))


exp_batch: Callable[[np.ndarray], np.ndarray] | None = None
rigid_step: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float], tuple[np.ndarray, np.ndarray]] | None = None
flow_xi: Callable[..., Any] | None = None
flow_aux: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None
predict: Callable[[np.ndarray, np.ndarray, float], np.ndarray] | None = None
log_stack: Callable[[np.ndarray], np.ndarray] | None = None
terms: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None
# What f8_ok and idmap_ok check of an array besides its values (zswarm/transport/message_checks.py names them too).
CHECK_NONE, CHECK_UNIT, CHECK_ROTATION = 0, 1, 2
# The wire's checks of a decoded message's arrays (zswarm/transport/message_checks.py): True when
# they pass, False to have the Python check them and name the problem.
f8_ok: Callable[[Any, int, int, float, float], bool] | None = None
idmap_ok: Callable[[Any, int, int, float, float, int, int], bool] | None = None
# zswarm.math.timing's gyro pre-integration of one agent's samples (a rate vector each): True with
# the result in ``out``, False to have the Python do it (a stack of draws).
rate_integral: Callable[[Any, float, float, bool, np.ndarray], bool] | None = None
# One draw's SO(3) products and the §3 observers' sums (so3.exp, mul, apply; bearing_terms): True with
# the result in the last argument, False (a stack of draws, other types) to have the Python do it.
exp1: Callable[[Any, np.ndarray], bool] | None = None
mul1: Callable[[Any, Any, np.ndarray], bool] | None = None
apply1: Callable[[Any, Any, np.ndarray], bool] | None = None
bearing_correction1: Callable[[Any, Any, np.ndarray], bool] | None = None
position_rate1: Callable[[Any, Any, Any, Any, Any, np.ndarray], bool] | None = None
# Every value of a contiguous float64 array finite: True or False (None: not such an array).
finite_f8: Callable[[Any], bool | None] | None = None
# A decoded message's envelope and the fields its kind lists pass the wire's checks as they are
# (messages.Msg.__post_init__); the codes of the fields' kinds (_kernels.c, fields_ok).
fields_ok: Callable[..., bool] | None = None
F_VEC, F_VEC_UNIT, F_MAT_ROT, F_MAP_VEC, F_MAP_VEC_UNIT, F_MAP_MAT_ROT, F_FLOAT, F_EMPTY = range(1, 9)
# message_checks._named of a decoded map of floats, 3-vectors and 3x3 matrices (None: not such a map).
named_decoded: Callable[[Any, frozenset[str], int, int, float], dict[str, Any] | None] | None = None


def wire_hooks(enc_hook: Callable[[Any], Any], dec_hook: Callable[[type, Any], Any]) -> tuple[Callable[[Any], Any], Callable[[type, Any], Any]]:
    """The wire's msgspec hooks (zswarm/transport/messages.py) compiled: an array field of the
    usual kinds (a contiguous float64 array out, a 3-vector or 3x3 matrix in) without a Python
    frame, everything else handed to ``enc_hook`` and ``dec_hook``; the Python hooks themselves
    when the loops are not built."""
    if _lib is None:
        return enc_hook, dec_hook
    _lib.set_wire_hooks(np.frombuffer, _F8, dec_hook, enc_hook)
    return _lib.enc_hook, _lib.dec_hook


if _lib is not None:
    lib: Any = _lib

    def _exp_batch(W: np.ndarray) -> np.ndarray:
        """zswarm.math.so3.exp_batch of (n, 3) rotation vectors: (n, 3, 3)."""
        W = np.ascontiguousarray(W, dtype=np.float64)
        E = np.empty((W.shape[0], 3, 3))
        lib.exp_batch(W, E)
        return E

    def _rigid_step(R: np.ndarray, w: np.ndarray, J_inv: np.ndarray, tau: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """``(R⁺, ω⁺)`` of world.dynamics.RigidBodies.step for isotropic inertias (new arrays)."""
        R, w, J_inv, tau = (np.ascontiguousarray(x, dtype=np.float64) for x in (R, w, J_inv, tau))
        R_out, w_out = np.empty_like(R), np.empty_like(w)
        lib.rigid_step(R, w, J_inv, tau, h, R_out, w_out)
        return R_out, w_out

    def _flow_xi(c0: tuple[Any, Any, Any], c1: tuple[Any, Any, Any], xi: Any, dt: float, k_xi: float, gamma: float, n: int) -> Any:
        """attitude_sync_terms.flow_xi's sub-steps: ξ a float, or an array of M draws (then the
        coefficients are arrays of M or numbers)."""
        if not isinstance(xi, np.ndarray):
            return lib.flow_xi_one(*c0, *c1, xi, dt, k_xi, gamma, n)
        shape = xi.shape
        x = np.array(xi, dtype=np.float64, order="C")  # a copy: flowed in place
        cs = [_f64(c, shape) for c in (*c0, *c1)]
        lib.flow_xi(*cs, x, dt, k_xi, gamma, n)
        return x

    def _flow_aux(Qt: np.ndarray, z: np.ndarray, table: np.ndarray, rows: np.ndarray, h: float, A: np.ndarray, K: np.ndarray, K2: np.ndarray, u2: np.ndarray, k_Q: float, k_zeta: float, gamma: float) -> tuple[np.ndarray, np.ndarray]:
        """attitude_sync_velocity_free.flow_aux's sub-steps: (Q̃ (M, 3, 3), ζ (M,)) after len(rows)
        sub-steps of h, sub-step m at the body rate table[rows[m]] (table (rows, M, 3)); new arrays."""
        M = z.shape[0]
        Q_out = np.array(Qt, dtype=np.float64, order="C")  # copies: flowed in place
        z_out = np.array(z, dtype=np.float64, order="C")
        tab = _f64(table, (table.shape[0], M, 3))
        r = np.ascontiguousarray(rows, dtype=np.int64)  # the rows are checked against the table in C (IndexError)
        lib.flow_aux(Q_out, z_out, tab, r, h, _f64(A, (3, 3)), _f64(K, (3, 3)), _f64(K2, (3, 3)), _f64(u2, (3,)), k_Q, k_zeta, gamma)
        return Q_out, z_out

    def _predict(R_prev: np.ndarray, R_now: np.ndarray, ratio: float) -> np.ndarray:
        """attitude_sync_terms.predict of M draws (stacks (M, 3, 3)): a new array, NaN for a draw
        whose log(R_prev^T R_now) is near π (the caller's numpy does those)."""
        shape = R_now.shape
        out = np.empty(shape)
        lib.predict(_f64(R_prev, shape), _f64(R_now, shape), ratio, out)
        return out

    def _log_stack(R: np.ndarray) -> np.ndarray:
        """zswarm.math.so3.log_batch of a stack (M, 3, 3): (M, 3), NaN for a matrix near a half turn
        (the caller's numpy does those)."""
        out = np.empty((R.shape[0], 3))
        lib.log_stack(_f64(R, R.shape), out)
        return out

    def _terms(A: np.ndarray, K: np.ndarray, u: np.ndarray, R: np.ndarray) -> np.ndarray:
        """attitude_sync_terms.Terms of M draws of R̄ (M, 3, 3): the rows ψ(X) (3), ψ(XK) (3),
        ψ(XK²) (3), tr X, tr XK, tr XK², u·ψ(X), u·ψ(XK), u·ψ(XK²) of (15, M), X = A R̄."""
        out = np.empty((15, R.shape[0]))
        lib.terms(_f64(A, (3, 3)), _f64(K, (3, 3)), _f64(u, (3,)), _f64(R, R.shape), out)
        return out

    exp_batch, rigid_step, flow_xi, flow_aux, predict, terms, log_stack = _exp_batch, _rigid_step, _flow_xi, _flow_aux, _predict, _terms, _log_stack
    lib.set_ndarray(np.ndarray)
    f8_ok, idmap_ok, rate_integral = lib.f8_ok, lib.idmap_ok, lib.rate_integral
    exp1, mul1, apply1, bearing_correction1, position_rate1 = lib.exp1, lib.mul1, lib.apply1, lib.bearing_correction1, lib.position_rate1
    finite_f8, named_decoded, fields_ok = lib.finite_f8, lib.named_decoded, lib.fields_ok
