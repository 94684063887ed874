"""The synergistic potential of the thesis' hybrid schemes and its parameter design.

Boughellaba (2024) §4.3.2.3 (also §5.5), after Wang & Tayebi (2022):

    U(R̄, ξ) = tr(A (I − R̄ Ra(ξ, u))) + (γ/2) ξ²                        (4.23)
    ψ(R̄^T ∇_R̄ U) = Ra(ξ, u) ψ(A R̄ Ra(ξ, u))                          Prop. 4.1
    ∇_ξ U = γ ξ + 2 u^T ψ(A R̄ Ra(ξ, u))                                Prop. 4.1

Condition 4.1 asks for δ > 0 and a finite Ξ such that at every undesired
critical point (ξ = 0, Pa(A R̄) = 0, R̄ ≠ I, i.e. R̄ = Ra(π, q_β) for an
eigenvector q_β of A) ``U(R̄, 0) − min_{ξ∈Ξ} U(R̄, ξ) > δ``.  Proposition 4.2
gives (u, Δ*) and the bounds on γ and δ that guarantee it; :func:`design`
computes them and :func:`condition_gaps` evaluates the condition itself.

Symbols -> names: A ``A`` (3×3, symmetric), u ``u``, γ ``gamma``, δ ``delta``,
Ξ ``Xi``, ξ ``xi``, Δ* ``Delta_star``, λ_i/q_i eigenpairs of A (ascending).
"""

from __future__ import annotations

import argparse
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from zswarm.math.so3 import Mat3, Ra, Vec3, psi, trace
from zswarm.scenario.algorithm import InitialField, Jumps, Output

# The thesis' parameters of the §4.5 and §5.6 hybrid schemes (zswarm generate's recipes).
HYBRID_PARAMS_4 = {"A": [5, 8.57, 12], "u": [0, 0.6455, 0.7638], "gamma": 1.9251, "delta": 0.0030, "Xi": ["0.08*pi"]}
HYBRID_PARAMS_5 = {"A": [5, 8.57, 12], "u": [0, 0.6455, 0.7638], "gamma": 1.9251, "delta": 0.3848, "Xi": ["0.9*pi"]}

# The published designs take γ and δ at 95 % of their Prop. 4.2 bounds:
# 0.95·4·5/π² = 1.9251 (§4.5, §5.6); 0.95·(4Δ*/π² − γ)ξ_L²/2 = 0.0030 (Ξ = {0.08π})
# and 0.3848 (Ξ = {0.9π}).
DEFAULT_MARGIN = 0.95
# λ2 within this relative distance of λ1λ3/(λ3 − λ1) counts as the second case of
# Prop. 4.2.  The cases meet continuously there; the thesis' A = diag(5, 8.57, 12)
# has λ2 = 8.57 ≈ 60/7 = 8.5714 and uses the second case (u_1 = 0, Δ* = 5).
CASE_BOUNDARY_RTOL = 1e-3


class DesignError(ValueError):
    """Parameters that break Prop. 4.2 or Condition 4.1; ``field`` names the culprit."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}")
        self.field = field
        self.problem = problem


def potential(A: Mat3, u: Vec3, gamma: float, R_bar: Mat3, xi: float) -> float:
    """``U(R̄, ξ)`` of (4.23).  Broadcasts: R̄ a stack (M, 3, 3) of M draws (ξ a number or
    (M,)) gives (M,)."""
    if R_bar.ndim > 2:
        return trace(A @ (np.eye(3) - R_bar @ Ra(xi, u))) + 0.5 * gamma * xi * xi  # type: ignore[no-any-return]
    return float(np.trace(A @ (np.eye(3) - R_bar @ Ra(xi, u)))) + 0.5 * gamma * xi * xi


def grad_R(A: Mat3, u: Vec3, R_bar: Mat3, xi: float) -> Vec3:
    """``ψ(R̄^T ∇_R̄ U) = Ra(ξ,u) ψ(A R̄ Ra(ξ,u))`` (Prop. 4.1): the body-frame gradient, g_k.
    Broadcasts as :func:`potential` ((M, 3))."""
    Q = Ra(xi, u)
    if R_bar.ndim > 2:
        return (Q @ psi(A @ R_bar @ Q)[..., None])[..., 0]
    return Q @ psi(A @ R_bar @ Q)


def grad_xi(A: Mat3, u: Vec3, gamma: float, R_bar: Mat3, xi: float) -> float:
    """``∇_ξ U = γ ξ + 2 u^T ψ(A R̄ Ra(ξ,u))`` (Prop. 4.1).  Broadcasts as :func:`potential`."""
    if R_bar.ndim > 2:
        return gamma * xi + 2.0 * (psi(A @ R_bar @ Ra(xi, u)) @ u)  # type: ignore[no-any-return]
    return gamma * xi + 2.0 * float(u @ psi(A @ R_bar @ Ra(xi, u)))


def best_xi(A: Mat3, u: Vec3, gamma: float, R_bar: Mat3, Xi: Sequence[float]) -> tuple[float, float]:
    """``(ξ*, U(R̄, ξ*))`` with ``ξ* = argmin_{ξ∈Ξ} U(R̄, ξ)`` (first of equal minima).
    With R̄ a stack of M draws: both (M,)."""
    best, u_best = Xi[0], potential(A, u, gamma, R_bar, Xi[0])
    if R_bar.ndim > 2:
        best = np.full(R_bar.shape[:-2], float(Xi[0]))
        for x in Xi[1:]:
            v = potential(A, u, gamma, R_bar, x)
            better = v < u_best
            best, u_best = np.where(better, x, best), np.where(better, v, u_best)
        return best, u_best  # type: ignore[return-value]
    for x in Xi[1:]:
        v = potential(A, u, gamma, R_bar, x)
        if v < u_best:
            best, u_best = x, v
    return best, u_best


@dataclass(frozen=True, slots=True)
class Design:
    """The outcome of Prop. 4.2 for given A and Ξ (and optional γ, δ)."""

    case: int  # 1: λ1 = λ2; 2: λ2 ≥ λ1λ3/(λ3−λ1); 3: otherwise
    eigenvalues: tuple[float, float, float]  # λ1 ≤ λ2 ≤ λ3
    eigenvectors: NDArray[np.float64]  # columns q_1, q_2, q_3
    alpha: tuple[float, float, float]  # u = Σ α_i q_i, α_i ≥ 0
    u: NDArray[np.float64]
    Delta_star: float
    gamma_max: float  # γ < 4Δ*/π²
    gamma: float
    delta_max: float  # δ < (4Δ*/π² − γ) ξ_L²/2
    delta: float
    Xi: tuple[float, ...]
    gaps: tuple[float, float, float]  # Condition 4.1 gap at R̄ = Ra(π, q_β), β = 1, 2, 3

    @property
    def condition_holds(self) -> bool:
        return all(g > self.delta for g in self.gaps)

    def as_dict(self) -> dict[str, object]:
        return {
            "case": self.case,
            "eigenvalues": list(self.eigenvalues),
            "alpha": list(self.alpha),
            "u": self.u.tolist(),
            "Delta_star": self.Delta_star,
            "gamma_max": self.gamma_max,
            "gamma": self.gamma,
            "delta_max": self.delta_max,
            "delta": self.delta,
            "Xi": list(self.Xi),
            "condition_4_1_gaps": list(self.gaps),
            "condition_4_1_holds": self.condition_holds,
        }


def eig_sorted(A: Mat3) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Eigenvalues ascending and eigenvectors (columns) of a symmetric A."""
    lam, Q = np.linalg.eigh(0.5 * (A + A.T))
    return lam, Q


def check_A(A: Mat3, fld: str = "A", distinct: bool = True) -> None:
    """Assumption 4.4: A symmetric positive definite with three distinct eigenvalues."""
    if A.shape != (3, 3) or not np.all(np.isfinite(A)):
        raise DesignError(fld, f"must be a finite 3x3 matrix (got {A.tolist()})")
    if not np.allclose(A, A.T, atol=1e-12, rtol=1e-9):
        raise DesignError(fld, f"must be symmetric (Assumption 4.4) (got {A.tolist()})")
    lam, _ = eig_sorted(A)
    if lam[0] <= 0:
        raise DesignError(fld, f"must be positive definite (Assumption 4.4) (got eigenvalues {lam.tolist()})")
    if distinct and (lam[1] - lam[0] < 1e-9 * lam[2] or lam[2] - lam[1] < 1e-9 * lam[2]):
        raise DesignError(fld, f"needs three distinct eigenvalues (Assumption 4.4) (got {lam.tolist()})")


def condition_gaps(A: Mat3, u: Vec3, gamma: float, Xi: Sequence[float]) -> tuple[float, float, float]:
    """``U(R̄, 0) − min_{ξ∈Ξ} U(R̄, ξ)`` at the three undesired critical attitudes ``R̄ = Ra(π, q_β)``.

    Condition 4.1 holds for δ iff every gap exceeds δ (Prop. 4.1 puts every
    undesired critical point at ξ = 0 with R̄ a rotation by π about an
    eigenvector of A).
    """
    _, Q = eig_sorted(A)
    gaps = []
    for b in range(3):
        R_bar = Ra(math.pi, Q[:, b])
        gaps.append(potential(A, u, gamma, R_bar, 0.0) - best_xi(A, u, gamma, R_bar, list(Xi))[1])
    return (gaps[0], gaps[1], gaps[2])


def design(
    A: Mat3,
    Xi: Sequence[float],
    gamma: float | None = None,
    delta: float | None = None,
    margin: float = DEFAULT_MARGIN,
) -> Design:
    """Prop. 4.2: u, Δ*, and the bounds on γ and δ for ``A`` and ``Ξ``.

    ``gamma``/``delta`` default to ``margin`` times their bounds.  Raises
    :class:`DesignError` naming ``A``, ``Xi``, ``gamma`` or ``delta`` if a
    bound of (4.24) fails.
    """
    A = np.asarray(A, dtype=float)
    check_A(A, "A", distinct=False)
    lam, Q = eig_sorted(A)
    l1, l2, l3 = (float(x) for x in lam)
    if not l2 < l3 * (1 - 1e-12):
        raise DesignError("A", f"Prop. 4.2 needs λ1 ≤ λ2 < λ3 (got {lam.tolist()})")
    if not Xi:
        raise DesignError("Xi", "must hold at least one value")
    for x in Xi:
        if not (0 < abs(x) <= math.pi + 1e-12):
            raise DesignError("Xi", f"every |ξ| must lie in (0, π] (Prop. 4.2) (got {x})")
    boundary = l1 * l3 / (l3 - l1)
    if abs(l2 - l1) <= 1e-12 * l3:
        case = 1
        a2 = (0.0, 0.0, 1.0 - l2 / l3)
        a2 = (1.0 - a2[2], 0.0, a2[2])  # α_1² + α_3² = 1 (q_1, q_2 span one eigenspace)
        Dstar = l1 * (1.0 - l2 / l3)
    elif l2 >= boundary * (1 - CASE_BOUNDARY_RTOL):
        case = 2
        a2 = (0.0, l2 / (l2 + l3), l3 / (l2 + l3))
        Dstar = l1
    else:
        case = 3
        s = 2.0 * (l1 * l2 + l1 * l3 + l2 * l3)  # Σ_l Σ_{k≠l} λ_l λ_k
        prods = (l2 * l3, l1 * l3, l1 * l2)  # Π_{l≠i} λ_l
        a2 = tuple(1.0 - 4.0 * pr / s for pr in prods)  # type: ignore[assignment]
        Dstar = 4.0 * l1 * l2 * l3 / s
    alpha = tuple(math.sqrt(max(0.0, x)) for x in a2)
    u = Q @ np.array(alpha)
    u = u / np.linalg.norm(u)
    gamma_max = 4.0 * Dstar / math.pi**2
    g = margin * gamma_max if gamma is None else float(gamma)
    if not 0 < g < gamma_max:
        raise DesignError("gamma", f"Prop. 4.2 needs 0 < γ < 4Δ*/π² = {gamma_max:.6g} (got {g:g})")
    xi_L = max(abs(x) for x in Xi)
    delta_max = (gamma_max - g) * xi_L**2 / 2.0
    d = margin * delta_max if delta is None else float(delta)
    if not 0 < d < delta_max:
        raise DesignError("delta", f"Prop. 4.2 needs 0 < δ < (4Δ*/π² − γ) ξ_L²/2 = {delta_max:.6g} (got {d:g})")
    gaps = condition_gaps(A, u, g, Xi)
    return Design(case, (l1, l2, l3), Q, (alpha[0], alpha[1], alpha[2]), u, Dstar, gamma_max, g, delta_max, d, tuple(float(x) for x in Xi), gaps)


def check_parameters(A: Mat3, u: Vec3, gamma: float, delta: float, Xi: Sequence[float], u_tol: float = 1e-2, condition: str = "4.1") -> Design:
    """Check user-given (A, u, γ, δ, Ξ) against Prop. 4.2 and Condition 4.1.

    Condition 5.1 (the velocity-free law's (Q̃_i, ζ_i) with δ_Q̃ and Π) is the same
    statement for the same potential (4.23) on SO(3) × R (Remark 5.2): pass
    (δ_Q̃, Π) as (delta, Xi) and ``condition="5.1"`` for the messages.

    ``u`` must be a unit vector equal, up to the sign of each eigen-component,
    to Prop. 4.2's ``u`` within ``u_tol`` per component (the thesis prints u to
    4 decimals).  Raises :class:`DesignError` naming the parameter whose bound
    fails.
    """
    A = np.asarray(A, dtype=float)
    u = np.asarray(u, dtype=float)
    check_A(A, "A", distinct=True)
    d = design(A, Xi, gamma, delta)
    if abs(float(np.linalg.norm(u)) - 1.0) > 1e-3:
        raise DesignError("u", f"must be a unit vector (got norm {np.linalg.norm(u):.6g})")
    got = np.abs(d.eigenvectors.T @ u)
    if np.max(np.abs(got - np.array(d.alpha))) > u_tol:
        raise DesignError(
            "u",
            f"is not Prop. 4.2's u for this A: eigen-components |α| = {np.round(got, 4).tolist()}, "
            f"Prop. 4.2 (case {d.case}) gives {np.round(d.alpha, 4).tolist()}, i.e. u = {np.round(d.u, 4).tolist()}",
        )
    gaps = condition_gaps(A, u, d.gamma, Xi)
    if not all(g > d.delta for g in gaps):
        raise DesignError("delta", f"Condition {condition} fails: gaps U(R̄,0) − min_Ξ U(R̄,ξ) at the undesired critical points are {[round(g, 6) for g in gaps]}, not all > δ = {d.delta:g}")
    return Design(d.case, d.eigenvalues, d.eigenvectors, d.alpha, u, d.Delta_star, d.gamma_max, d.gamma, d.delta_max, d.delta, d.Xi, gaps)


# --------------------------------------------------------------------------- scenario parameters
# The [algorithm.params] of the §4 observers and Chapter 5 laws (SPEC.params, the
# zswarm.scenario.algorithm.Params protocol): read and checked against Assumption 4.4, Prop. 4.2 and
# Condition 5.1 here, beside the math; their fields go to the algorithms' Gains by name.

_PARAMS_FIELD = "algorithm.params"


def _read_A(r: Any, d: dict[str, Any], f: str) -> NDArray[np.float64]:
    a = d["A"]
    if isinstance(a, list) and len(a) == 3 and all(not isinstance(x, list) for x in a):
        A = np.diag(r.vec3(a, f"{f}.A"))
    elif isinstance(a, list) and len(a) == 3 and all(isinstance(row, list) and len(row) == 3 for row in a):
        A = np.array([[r.num(e, f"{f}.A[{x}][{y}]") for y, e in enumerate(row)] for x, row in enumerate(a)])
    else:
        raise r.err(f"{f}.A", "must be 3 eigenvalues (a diagonal A) or a 3x3 list of rows", a)
    try:
        _checked_A(tuple(A.ravel().tolist()))
    except DesignError as exc:
        raise r.err(f"{f}.{exc.field}", exc.problem) from None
    return A


@functools.lru_cache(maxsize=64)
def _checked_A(A: tuple[float, ...]) -> None:
    """:func:`check_A` of a scenario's A, remembered as :func:`_checked` is."""
    check_A(np.array(A).reshape(3, 3), "A")


def angle_set(r: Any, v: Any, fld: str, example: str) -> tuple[float, ...]:
    """A hybrid set (Ξ, Π): a non-empty list of numbers or expressions like ``"0.9*pi"``."""
    if not isinstance(v, list) or not v:
        raise r.err(fld, f'must be a non-empty list of numbers or expressions like "{example}"', v)
    return tuple(float(r.expr(x, f"{fld}[{n}]")(0.0)) if isinstance(x, str) else r.num(x, f"{fld}[{n}]") for n, x in enumerate(v))


@functools.lru_cache(maxsize=64)
def _checked(A: tuple[float, ...], u: tuple[float, float, float], gamma: float, delta: float, Xi: tuple[float, ...], condition: str) -> None:
    """:func:`check_parameters` of a scenario's params, remembered: a basin's draws load the same
    [algorithm.params] once a draw (0.5 ms of eigen-decompositions and gap conditions each);
    a DesignError is raised again on every call (exceptions are not cached)."""
    check_parameters(np.array(A).reshape(3, 3), np.array(u), gamma, delta, Xi, condition=condition)


def _set_P(p: HybridParams | VelocityFreeParams) -> dict[str, Any]:
    """The Gains values of Prop. 4.2's set P (A as a 3x3 matrix)."""
    return {"A": np.array(p.A, dtype=float).reshape(3, 3), "u": np.array(p.u), "gamma": p.gamma, "delta": p.delta, "Xi": p.Xi}


@dataclass(frozen=True, slots=True)
class ContinuousParams:
    """A of the continuous observer (4.8) and law (5.13) (Assumption 4.4: symmetric, three
    distinct positive eigenvalues), row-major."""

    A: tuple[float, ...]
    jumps = False

    @classmethod
    def load(cls, r: Any, d: Any, fld: str = _PARAMS_FIELD) -> ContinuousParams:
        d = r.table(d if d is not None else {}, fld, {"A"}, {"A"})
        return cls(tuple(_read_A(r, d, fld).ravel().tolist()))

    def gains(self, ids: tuple[int, ...]) -> dict[str, Any]:
        return {"A": np.array(self.A, dtype=float).reshape(3, 3)}


@dataclass(frozen=True, slots=True)
class HybridParams:
    """The set P = (A, u, γ, δ, Ξ) of Prop. 4.2 (hybrid observers (4.25)-(4.26), hybrid law
    (5.14)-(5.16)); u is made unit (the thesis prints it to 4 decimals; Prop. 4.1 needs |u| = 1)."""

    A: tuple[float, ...]
    u: tuple[float, float, float]
    gamma: float
    delta: float
    Xi: tuple[float, ...]
    jumps = True
    FIELDS: ClassVar[frozenset[str]] = frozenset({"A", "u", "gamma", "delta", "Xi"})

    @classmethod
    def _read(cls, r: Any, d: Any, fld: str, allowed: set[str]) -> tuple[dict[str, Any], NDArray[np.float64], tuple[float, float, float], tuple[Any, ...]]:
        d = r.table(d if d is not None else {}, fld, allowed, allowed)
        A = _read_A(r, d, fld)
        u = r.vec3(d["u"], f"{fld}.u")
        gamma = r.num(d["gamma"], f"{fld}.gamma", positive=True)
        delta = r.num(d["delta"], f"{fld}.delta", positive=True)
        Xi = angle_set(r, d["Xi"], f"{fld}.Xi", "0.08*pi")
        try:
            _checked(tuple(A.ravel().tolist()), u, gamma, delta, Xi, "4.1")
        except DesignError as exc:
            raise r.err(f"{fld}.{exc.field}", exc.problem) from None
        un = np.array(u) / np.linalg.norm(u)
        return d, A, u, (tuple(A.ravel().tolist()), (float(un[0]), float(un[1]), float(un[2])), gamma, delta, Xi)

    @classmethod
    def load(cls, r: Any, d: Any, fld: str = _PARAMS_FIELD) -> HybridParams:
        return cls(*cls._read(r, d, fld, set(cls.FIELDS))[3])

    def gains(self, ids: tuple[int, ...]) -> dict[str, Any]:
        return _set_P(self)


@dataclass(frozen=True, slots=True)
class VelocityFreeParams:
    """P of Prop. 4.2 and the velocity-free law's (δ_Q̃, Π) of Condition 5.1 (§5.4)."""

    A: tuple[float, ...]
    u: tuple[float, float, float]
    gamma: float
    delta: float
    Xi: tuple[float, ...]
    delta_Q: float
    Pi: tuple[float, ...]
    jumps = True

    @classmethod
    def load(cls, r: Any, d: Any, fld: str = _PARAMS_FIELD) -> VelocityFreeParams:
        d, A, u, base = HybridParams._read(r, d, fld, set(HybridParams.FIELDS) | {"delta_Q", "Pi"})
        # Condition 5.1 for (A, u, γ, δ_Q̃, Π): the same potential (4.23) on SO(3) × R, so
        # Prop. 4.2 (Remark 5.2, Wang & Tayebi 2022 Prop. 2) bounds δ_Q̃ with Π as δ with Ξ.
        delta_Q = r.num(d["delta_Q"], f"{fld}.delta_Q", positive=True)
        Pi = angle_set(r, d["Pi"], f"{fld}.Pi", "0.9*pi")
        try:
            _checked(base[0], u, base[2], delta_Q, Pi, "5.1")
        except DesignError as exc:
            name = {"delta": "delta_Q", "Xi": "Pi"}.get(exc.field, exc.field)
            raise r.err(f"{fld}.{name}", exc.problem.replace("δ", "δ_Q̃").replace("Ξ", "Π")) from None
        return cls(*base, delta_Q, Pi)

    def gains(self, ids: tuple[int, ...]) -> dict[str, Any]:
        return _set_P(self) | {"delta_Q": self.delta_Q, "Pi": self.Pi}


# ξ_k(0) of the tree edges an agent heads ([agents.estimate] xi = {k = ξ_k(0)}; 0 unless stated):
# every hybrid scheme's initial state besides its estimates (SPEC.initial).
XI_INITIAL = InitialField("edges", MappingProxyType({}), "ξ_k(0) of the edges k this agent heads (Remark 4.4)", symbol="ξ")
# What every hybrid scheme's estimate reports of ξ (SPEC.estimate) and how its steps list the
# jumps of ξ_k, (4.26) / (5.7), and of the agent's own ζ_i, (5.12) (SPEC.jumps).
XI_ESTIMATE: Mapping[str, Output] = MappingProxyType({"xi": Output("edges", doc="ξ_k of the edges k this agent heads")})
XI_JUMPS: Mapping[str, Jumps] = MappingProxyType({"jumps": Jumps("xi", "edge", "ξ_k of a headed edge k, (4.26) / (5.7)")})
ZETA_JUMPS: Mapping[str, Jumps] = MappingProxyType({"agent_jumps": Jumps("zeta", "agent", "ζ_i, (5.12)")})


# --------------------------------------------------------------------------- zswarm design-hybrid (a command of the tree family: zswarm.families.tree)


def design_command(args: Any) -> int:
    """``zswarm design-hybrid``: print (or check) a design of Prop. 4.2 for A and Ξ."""
    import json

    import numpy as np

    from zswarm.transport import procutil

    vals = [procutil.number_arg(x, "--A") for x in args.A.split(",")]
    if len(vals) == 3:
        A = np.diag(vals)
    elif len(vals) == 9:
        A = np.array(vals).reshape(3, 3)
    else:
        procutil.fail_usage(f"--A: give 3 eigenvalues or 9 entries (got {len(vals)} numbers)")
    Xi = [procutil.number_arg(x, "--xi") for x in args.xi.split(",")]
    gamma = None if args.gamma is None else procutil.number_arg(args.gamma, "--gamma")
    delta = None if args.delta is None else procutil.number_arg(args.delta, "--delta")
    try:
        if args.u is not None:
            u = [procutil.number_arg(x, "--u") for x in args.u.split(",")]
            if len(u) != 3:
                procutil.fail_usage(f"--u: give 3 numbers (got {len(u)})")
            base = design(A, Xi, gamma, delta)
            d = check_parameters(A, np.array(u), base.gamma, base.delta, Xi)
        else:
            d = design(A, Xi, gamma, delta)
    except DesignError as exc:
        procutil.fail_usage(f"--{exc.field.lower()}: {exc.problem}")
    if args.json:
        print(json.dumps(d.as_dict(), indent=2))
        return 0
    lam = d.eigenvalues
    case_text = {1: "λ1 = λ2", 2: "λ2 ≥ λ1λ3/(λ3−λ1)", 3: "λ1 < λ2 < λ1λ3/(λ3−λ1)"}[d.case]
    print(
        f"A: eigenvalues λ = {lam[0]:g}, {lam[1]:g}, {lam[2]:g}; Prop. 4.2 case {d.case} ({case_text}; λ1λ3/(λ3−λ1) = {lam[0] * lam[2] / (lam[2] - lam[0]):.6g})"
    )
    print(f"u       = [{', '.join(f'{x:.4f}' for x in d.u)}]   (α = [{', '.join(f'{a:.4f}' for a in d.alpha)}] on the eigenvectors of A)")
    print(f"Δ*      = {d.Delta_star:.6g}")
    print(f"γ       = {d.gamma:.6g}   (bound: γ < 4Δ*/π² = {d.gamma_max:.6g})")
    print(f"δ       = {d.delta:.6g}   (bound: 0 < δ < (4Δ*/π² − γ) ξ_L²/2 = {d.delta_max:.6g}, ξ_L = {max(abs(x) for x in Xi):.6g})")
    print(f"Ξ       = {{{', '.join(f'{x:.6g}' for x in Xi)}}}")
    gaps = ", ".join(f"{g:.4g}" for g in d.gaps)
    print(f"Condition 4.1: U(R̄,0) − min_Ξ U(R̄,ξ) at R̄ = Ra(π, q_β), β = 1,2,3: {gaps}  (> δ: {'holds' if d.condition_holds else 'FAILS'})")
    print(
        "Condition 5.1 (the velocity-free law's (Q̃_i, ζ_i), §5.4) is the same condition on the same potential (4.23): "
        f"with δ_Q̃ = {d.delta:.6g} and Π = Ξ it {'holds' if d.condition_holds else 'FAILS'} (Remark 5.2); "
        "[algorithm.params] delta_Q, Pi are checked against these bounds too"
    )
    return 0 if d.condition_holds else 1


def design_arguments(d: argparse.ArgumentParser) -> None:
    d.add_argument("--A", required=True, help="eigenvalues of a diagonal A, e.g. 5,8.57,12 (or 9 numbers, row-major)")
    d.add_argument("--xi", required=True, help="the set Ξ, e.g. 0.08pi or 0.5,0.9pi")
    d.add_argument("--gamma", default=None, help="γ to check (default: 0.95 of its bound)")
    d.add_argument("--delta", default=None, help="δ to check (default: 0.95 of its bound)")
    d.add_argument("--u", default=None, help="u to check against Prop. 4.2's (3 numbers)")
    d.add_argument("--json", action="store_true", help="print the design as JSON")
