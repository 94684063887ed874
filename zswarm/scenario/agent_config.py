"""An agent's entry of a scenario (``[[agents]]``): its config type and how it is read —
pose and motion, neighbours, gains, clock, and the initial state its algorithm declares
(``SPEC.initial``, read by kind)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from zswarm.scenario.algorithm import AlgorithmSpec, InitialField
from zswarm.scenario.clock import ClockSpec, _clock
from zswarm.scenario.expr import Expr
from zswarm.scenario.graph import SHAPES
from zswarm.scenario.reading import _Ctx, _user_code
from zswarm.scenario.world_config import _inertia
from zswarm.util.quoting import toml_key


@dataclass(frozen=True, slots=True)
class Estimate:
    """What an agent starts from: every initial value its algorithm declares (``SPEC.initial``),
    stated in ``[agents.estimate]`` / ``[[agents]]`` or its default (vectors and rotations as
    tuples, rotations row-major), and which of them were stated."""

    values: Mapping[str, Any] = field(default_factory=dict)
    stated: frozenset[str] = frozenset()

    def __getitem__(self, name: str) -> Any:
        return self.values[name]

    def get(self, name: str, default: Any = None) -> Any:
        return self.values.get(name, default)


class StartPose:
    """``R_matrix`` and ``omega0`` of what has a start attitude ``R`` (row-major 3×3) and rate
    expressions ``omega``: an agent's entry (:class:`AgentSpec`) and the world's body of it
    (zswarm.scenario.programs.Body)."""

    __slots__ = ()
    R: tuple[float, ...]
    omega: tuple[Expr, Expr, Expr]

    @property
    def R_matrix(self) -> np.ndarray:
        return np.array(self.R, dtype=float).reshape(3, 3)

    @property
    def omega0(self) -> np.ndarray:
        """ω_i(0): the rigid body's initial rate (its ``omega`` expressions at t = 0)."""
        return np.array([float(e(0.0)) for e in self.omega])


@dataclass(frozen=True, slots=True)
class AgentSpec(StartPose):
    id: int
    role: str  # "leader" | "follower"
    p: tuple[float, float, float]  # inertial position at t = 0 (fixed in §3.2)
    R: tuple[float, ...]  # initial attitude, row-major 3×3 (body -> inertial)
    omega: tuple[Expr, Expr, Expr]  # body-frame angular velocity ω_i(t), rad/s
    gyro_bias: tuple[float, float, float]
    neighbors: tuple[int, ...]  # N_i: in-neighbours
    k_neighbors: tuple[float, ...]  # k_ij, same order as neighbors
    estimate: Estimate
    clock: ClockSpec
    velocity: tuple[Expr, Expr, Expr] | None = None  # inertial velocity v_i(t), m/s (None: fixed or formation)
    gains: Mapping[str, float] = field(default_factory=dict)  # the algorithm's gains for this agent
    J: tuple[float, ...] | None = None  # inertia, row-major 3×3 (rigid_body plant)
    senses: tuple[int, ...] = ()  # a "sensing" graph's robots this agent senses (then neighbors: both ways)


def _agent(c: _Ctx, d: Any, f: str, default_clock: ClockSpec, info: AlgorithmSpec, gains: Mapping[str, float], leaders: bool, plant: str = "prescribed") -> AgentSpec:
    rigid, kin = plant == "rigid_body", plant == "kinematic"
    d = c.table(
        d,
        f,
        {"id", "role", "p", "R", "omega", "v", "gyro_bias", "neighbors", "k_neighbors", "gains", "estimate", "clock"} | ({"J"} if rigid else set()) | {n for n, fi in info.initial.items() if fi.table == "agent"},
        ({"id", "omega"} if rigid else {"id", "p"} if kin else {"id", "p", "omega"}) | ({"role"} if SHAPES[info.graph].roles else set()),
    )
    if kin:
        for key in ("omega", "v"):
            if key in d:
                raise c.err(f"{f}.{key}", "the kinematic plant moves each vehicle by its commands (De Carli et al. (1)): no prescribed motion", d[key])
        d = dict(d, omega=["0", "0", "0"])
    aid = c.integer(d["id"], f"{f}.id")
    if aid < 1:
        raise c.err(f"{f}.id", "must be >= 1", aid)
    role = c.string(d.get("role", "follower"), f"{f}.role")
    if role not in ("leader", "follower"):
        raise c.err(f"{f}.role", "must be 'leader' or 'follower'", role)
    if SHAPES[info.graph].leaderless and role != "follower":
        raise c.err(f"{f}.role", SHAPES[info.graph].leaderless, role)
    if role == "leader" and not leaders:
        raise c.err(f"{f}.role", "this algorithm has no leader role (its SPEC.leader is None)", role)
    p = c.vec3(d.get("p", [0, 0, 0]), f"{f}.p")
    J = None
    if rigid:
        if "J" not in d:
            raise c.err(f"{f}.J", "missing: the rigid_body plant needs each agent's inertia (3 principal moments, or a 3x3 list of rows)")
        J = _inertia(c, d["J"], f"{f}.J")
    R = c.rotation(d.get("R", [[1, 0, 0], [0, 1, 0], [0, 0, 1]]), f"{f}.R")
    if kin and abs(R[8] - 1.0) > 1e-9:
        raise c.err(f"{f}.R", "a vehicle of the kinematic plant has a yaw only: R must be a rotation about e3", d.get("R"))
    om = d["omega"]
    if not isinstance(om, list) or len(om) != 3:
        raise c.err(f"{f}.omega", "must be a list of 3 expressions in t", om)
    omega = tuple(c.expr(e, f"{f}.omega[{k}]") for k, e in enumerate(om))
    if rigid:
        for k, e in enumerate(omega):
            if not e.constant:
                raise c.err(f"{f}.omega[{k}]", "is ω_i(0) of a rigid body (the dynamics (5.1) set ω_i(t)): a number, not an expression in t", om[k])
        if "v" in d:
            raise c.err(f"{f}.v", "the rigid_body plant models attitudes only (positions stay at p)")
    velocity = None
    if "v" in d:
        if not isinstance(d["v"], list) or len(d["v"]) != 3:
            raise c.err(f"{f}.v", "must be a list of 3 expressions in t (inertial velocity, m/s)", d["v"])
        velocity = tuple(c.expr(e, f"{f}.v[{k}]") for k, e in enumerate(d["v"]))
    bias = c.vec3(d.get("gyro_bias", [0, 0, 0]), f"{f}.gyro_bias")
    nb = d.get("neighbors", [])
    if not isinstance(nb, list):
        raise c.err(f"{f}.neighbors", "must be a list of agent ids", nb)
    neighbors = tuple(c.integer(j, f"{f}.neighbors[{k}]") for k, j in enumerate(nb))
    kn = d.get("k_neighbors", [1.0] * len(neighbors))
    if not isinstance(kn, list) or len(kn) != len(neighbors):
        raise c.err(f"{f}.k_neighbors", f"must list one gain k_ij per neighbour ({len(neighbors)})", kn)
    k_neighbors = tuple(c.num(k, f"{f}.k_neighbors[{n}]", positive=True) for n, k in enumerate(kn))
    own = c.table(d.get("gains", {}), f"{f}.gains", set(info.gains))
    agent_gains = dict(gains)
    for k, v in own.items():
        agent_gains[k] = c.num(v, f"{f}.gains.{k}", positive=True)
    est = c.table(d.get("estimate", {}), f"{f}.estimate", {n for n, fi in info.initial.items() if fi.table == "estimate"})
    if role == "leader" and est:
        raise c.err(f"{f}.estimate", "a leader knows its pose and has no estimate")
    values: dict[str, Any] = {}
    stated: set[str] = set()
    for name, fi in info.initial.items():
        src, fld = (est, f"{f}.estimate.{name}") if fi.table == "estimate" else (d, f"{f}.{name}")
        if name in src:
            values[name] = _initial_value(c, fi, src[name], fld)
            stated.add(name)
        else:
            values[name] = fi.default
    estimate = Estimate(MappingProxyType(values), frozenset(stated))
    clock = _clock(c, d.get("clock", {}), f"{f}.clock", default_clock)
    return AgentSpec(aid, role, p, R, omega, bias, neighbors, k_neighbors, estimate, clock, velocity, MappingProxyType(agent_gains), J)  # type: ignore[arg-type]


def _initial_value(c: _Ctx, fi: InitialField, v: Any, fld: str) -> Any:
    """One stated initial value (SPEC.initial) read by its kind."""
    if fi.kind == "vector":
        return c.vec3(v, fld)
    if fi.kind == "rotation":
        return c.rotation(v, fld)
    if fi.kind == "number":
        return c.num(v, fld)
    if fi.kind == "angle":  # a number or an expression like "0.3*pi" (rad)
        return float(c.expr(v, fld)(0.0)) if isinstance(v, str) else c.num(v, fld)
    if fi.kind == "edges":  # {edge index k = value}, held by the head of k (checked with the tree)
        if not isinstance(v, dict):
            raise c.err(fld, f"must be a table {{edge index k = {fi.symbol}_k(0)}}", v)
        out: dict[int, float] = {}
        for k, x in v.items():
            if not k.isdigit() or int(k) < 1:
                raise c.err(f"{fld}.{toml_key(k)}", "keys are edge indices k = 1..m")
            out[int(k)] = c.num(x, f"{fld}.{k}")
        return MappingProxyType(out)
    assert fi.parse is not None  # "custom" (zswarm.scenario.algorithm.check_module)
    return _user_code(c, fld, lambda: fi.parse(c, v, fld))  # type: ignore[misc]
