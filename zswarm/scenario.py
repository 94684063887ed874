"""Scenario files: TOML -> frozen dataclasses, validated.

Every error reads ``file: field: problem (got X)``.  See ``topologies/`` for
examples and the README for the full format.

Format (units: seconds, Hz, metres, radians)::

    [scenario]  name, description, duration, seed
    [algorithm] name; [algorithm.gains] per algorithm (see ALGORITHMS)
    [world]     step (s, <= 0.001), sensor_rate (Hz)
    [noise]     gyro_var, bearing_var (variances, as the papers state them)
    [clock]     rate (Hz), jitter (s, std of tick times), drift_ppm, offset (s): defaults for agents
    [[agents]]  id, role, p, R, omega = [3 expressions in t], gyro_bias,
                neighbors (N_i), k_neighbors (k_ij, one per neighbour),
                [agents.estimate] p, R, Omega; [agents.clock] overrides
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from zswarm import so3
from zswarm.expr import Expr, ExprError, parse
from zswarm.graph import GraphError, check_leader_follower


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names file, field and problem."""


@dataclass(frozen=True, slots=True)
class AlgorithmInfo:
    """What the loader knows about an algorithm: its gains and graph assumption."""

    gains: Mapping[str, float | None]  # name -> default (None: required)
    graph: str
    description: str


# The gains of each algorithm, with defaults; every gain must be > 0.
ALGORITHMS: Mapping[str, AlgorithmInfo] = MappingProxyType(
    {
        "bearing_pose_fixed": AlgorithmInfo(
            MappingProxyType({"k_R": None, "k_p": None}),
            "leader_follower",
            "thesis §3.2: attitude observer (3.3) + position observer (3.14)",
        ),
        "bearing_pose_fixed_filtered": AlgorithmInfo(
            MappingProxyType({"k_Omega": None, "k_p": None}),
            "leader_follower",
            "thesis §3.2: filtered attitude observer (3.8)-(3.9) + position observer (3.14)",
        ),
    }
)


@dataclass(frozen=True, slots=True)
class ClockSpec:
    """An agent's clock: tick rate on its own clock, tick jitter, drift and offset."""

    rate: float = 100.0  # Hz
    jitter: float = 0.0  # s, standard deviation of each tick's wake-up time
    drift_ppm: float = 0.0  # own clock runs (1 + drift_ppm·1e-6) times world time
    offset: float = 0.0  # s, own clock reading at world time 0


@dataclass(frozen=True, slots=True)
class Estimate:
    """Initial estimates of a follower (body/inertial frames as in the thesis)."""

    p_hat: tuple[float, float, float] = (0.0, 0.0, 0.0)
    R_hat: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)  # row-major
    Omega: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class AgentSpec:
    id: int
    role: str  # "leader" | "follower"
    p: tuple[float, float, float]  # inertial position (fixed in §3.2)
    R: tuple[float, ...]  # initial attitude, row-major 3×3 (body -> inertial)
    omega: tuple[Expr, Expr, Expr]  # body-frame angular velocity ω_i(t), rad/s
    gyro_bias: tuple[float, float, float]
    neighbors: tuple[int, ...]  # N_i: in-neighbours
    k_neighbors: tuple[float, ...]  # k_ij, same order as neighbors
    estimate: Estimate
    clock: ClockSpec

    @property
    def R_matrix(self) -> np.ndarray:
        return np.array(self.R, dtype=float).reshape(3, 3)


@dataclass(frozen=True, slots=True)
class Scenario:
    path: str
    name: str
    description: str
    duration: float
    seed: int
    algorithm: str
    gains: Mapping[str, float]
    step: float
    sensor_rate: float
    gyro_var: float
    bearing_var: float
    agents: tuple[AgentSpec, ...]
    text: str = field(repr=False)

    def agent(self, i: int) -> AgentSpec:
        for a in self.agents:
            if a.id == i:
                return a
        raise KeyError(i)

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(a.id for a in self.agents)

    @property
    def edges(self) -> tuple[tuple[int, int], ...]:
        """Directed edges ``(j, i)``: j sends to i (j ∈ N_i), sorted."""
        return tuple(sorted((j, a.id) for a in self.agents for j in a.neighbors))

    def out_neighbors(self, j: int) -> tuple[int, ...]:
        return tuple(i for (s, i) in self.edges if s == j)

    def graph_neighbors(self, i: int) -> tuple[int, ...]:
        """In- and out-neighbours of ``i``: the agents it measures bearings to."""
        return tuple(sorted(set(self.agent(i).neighbors) | set(self.out_neighbors(i))))


# --------------------------------------------------------------------------- helpers


class _Ctx:
    """Carries the file name so every error names file and field."""

    def __init__(self, path: str) -> None:
        self.path = path

    def err(self, fld: str, problem: str, got: Any = ...) -> ScenarioError:
        tail = "" if got is ... else f" (got {got!r})"
        return ScenarioError(f"{self.path}: {fld}: {problem}{tail}")

    def table(self, d: Any, fld: str, allowed: set[str], required: set[str] = frozenset()) -> dict[str, Any]:  # type: ignore[assignment]
        if not isinstance(d, dict):
            raise self.err(fld, "must be a table", d)
        for k in d:
            if k not in allowed:
                raise self.err(f"{fld}.{k}" if fld else k, f"unknown key (allowed: {', '.join(sorted(allowed))})")
        for k in sorted(required):
            if k not in d:
                raise self.err(f"{fld}.{k}" if fld else k, "missing")
        return d

    def num(self, v: Any, fld: str, *, positive: bool = False, nonneg: bool = False, maxv: float | None = None) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.err(fld, "must be a number", v)
        x = float(v)
        if not math.isfinite(x):
            raise self.err(fld, "must be finite", v)
        if positive and x <= 0:
            raise self.err(fld, "must be > 0", v)
        if nonneg and x < 0:
            raise self.err(fld, "must be >= 0", v)
        if maxv is not None and x > maxv:
            raise self.err(fld, f"must be <= {maxv}", v)
        return x

    def integer(self, v: Any, fld: str) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.err(fld, "must be an integer", v)
        return v

    def string(self, v: Any, fld: str) -> str:
        if not isinstance(v, str):
            raise self.err(fld, "must be a string", v)
        return v

    def vec3(self, v: Any, fld: str) -> tuple[float, float, float]:
        if not isinstance(v, list) or len(v) != 3:
            raise self.err(fld, "must be a list of 3 numbers", v)
        x, y, z = (self.num(e, f"{fld}[{k}]") for k, e in enumerate(v))
        return (x, y, z)

    def expr(self, v: Any, fld: str) -> Expr:
        try:
            return parse(v)
        except ExprError as exc:
            raise self.err(fld, str(exc), v) from None

    def rotation(self, v: Any, fld: str) -> tuple[float, ...]:
        """A rotation: ``{angle = "0.1*pi", axis = [1,0,0]}`` or a 3×3 list of rows."""
        if isinstance(v, dict):
            self.table(v, fld, {"angle", "axis"}, {"angle", "axis"})
            theta = float(self.expr(v["angle"], f"{fld}.angle")(0.0))
            axis = np.array(self.vec3(v["axis"], f"{fld}.axis"))
            if np.linalg.norm(axis) == 0:
                raise self.err(f"{fld}.axis", "must be non-zero", v["axis"])
            return tuple(so3.Ra(theta, axis).ravel().tolist())
        if isinstance(v, list) and len(v) == 3 and all(isinstance(r, list) and len(r) == 3 for r in v):
            R = np.array([[self.num(e, f"{fld}[{a}][{b}]") for b, e in enumerate(r)] for a, r in enumerate(v)])
            if not so3.is_rotation(R, 1e-6):
                raise self.err(fld, "is not a rotation matrix (R^T R = I, det R = 1 within 1e-6)", v)
            return tuple(R.ravel().tolist())
        raise self.err(fld, "must be {angle, axis} or a 3x3 list of rows", v)


# --------------------------------------------------------------------------- loading


def load(path: str | Path) -> Scenario:
    """Load and validate a scenario file.

    Raises
    ------
    ScenarioError
        With ``file: field: problem (got X)`` for anything wrong.
    """
    p = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"{p}: cannot read file ({exc.strerror})") from None
    return loads(text, p)


def loads(text: str, path: str = "<string>") -> Scenario:
    """Parse and validate scenario TOML ``text``; ``path`` is used in errors."""
    c = _Ctx(path)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: TOML syntax: {exc}") from None

    c.table(doc, "", {"scenario", "algorithm", "world", "noise", "clock", "agents"}, {"scenario", "algorithm", "agents"})
    sc = c.table(doc["scenario"], "scenario", {"name", "description", "duration", "seed"}, {"name", "duration"})
    name = c.string(sc["name"], "scenario.name")
    description = c.string(sc.get("description", ""), "scenario.description")
    duration = c.num(sc["duration"], "scenario.duration", positive=True)
    seed = c.integer(sc.get("seed", 0), "scenario.seed")

    al = c.table(doc["algorithm"], "algorithm", {"name", "gains"}, {"name"})
    algo = c.string(al["name"], "algorithm.name")
    if algo not in ALGORITHMS:
        raise c.err("algorithm.name", f"unknown algorithm (known: {', '.join(ALGORITHMS)})", algo)
    info = ALGORITHMS[algo]
    g = c.table(al.get("gains", {}), "algorithm.gains", set(info.gains))
    gains: dict[str, float] = {}
    for k, default in info.gains.items():
        if k not in g:
            if default is None:
                raise c.err(f"algorithm.gains.{k}", "missing")
            gains[k] = default
        else:
            gains[k] = c.num(g[k], f"algorithm.gains.{k}", positive=True)

    w = c.table(doc.get("world", {}), "world", {"step", "sensor_rate"})
    step = c.num(w.get("step", 0.001), "world.step", positive=True, maxv=0.001)
    sensor_rate = c.num(w.get("sensor_rate", 200.0), "world.sensor_rate", positive=True, maxv=1.0 / step)

    nz = c.table(doc.get("noise", {}), "noise", {"gyro_var", "bearing_var"})
    gyro_var = c.num(nz.get("gyro_var", 0.0), "noise.gyro_var", nonneg=True)
    bearing_var = c.num(nz.get("bearing_var", 0.0), "noise.bearing_var", nonneg=True)

    default_clock = _clock(c, doc.get("clock", {}), "clock", ClockSpec())

    raw_agents = doc["agents"]
    if not isinstance(raw_agents, list) or not raw_agents:
        raise c.err("agents", "must be a non-empty array of tables ([[agents]])", raw_agents)
    agents: list[AgentSpec] = []
    seen: dict[int, str] = {}
    for n, ra in enumerate(raw_agents):
        f = f"agents[{n}]"
        agents.append(_agent(c, ra, f, default_clock))
        if agents[-1].id in seen:
            raise c.err(f"{f}.id", f"duplicate id (also {seen[agents[-1].id]})", agents[-1].id)
        seen[agents[-1].id] = f
    ids = sorted(seen)
    if ids != list(range(1, len(ids) + 1)):
        raise c.err("agents", "ids must be 1..n, each once", ids)
    agents.sort(key=lambda a: a.id)

    if info.graph == "leader_follower":
        try:
            check_leader_follower(
                {a.id: a.neighbors for a in agents},
                {a.id: a.role for a in agents},
                {a.id: a.p for a in agents},
                seen,
            )
        except GraphError as exc:
            raise ScenarioError(f"{path}: {exc}") from None

    return Scenario(
        path=path,
        name=name,
        description=description,
        duration=duration,
        seed=seed,
        algorithm=algo,
        gains=MappingProxyType(gains),
        step=step,
        sensor_rate=sensor_rate,
        gyro_var=gyro_var,
        bearing_var=bearing_var,
        agents=tuple(agents),
        text=text,
    )


def _clock(c: _Ctx, d: Any, f: str, base: ClockSpec) -> ClockSpec:
    d = c.table(d, f, {"rate", "jitter", "drift_ppm", "offset"})
    rate = c.num(d.get("rate", base.rate), f"{f}.rate", positive=True, maxv=10000.0)
    jitter = c.num(d.get("jitter", base.jitter), f"{f}.jitter", nonneg=True)
    if jitter >= 0.5 / rate:
        raise c.err(f"{f}.jitter", f"must be < half the period ({0.5 / rate:g} s)", jitter)
    drift = c.num(d.get("drift_ppm", base.drift_ppm), f"{f}.drift_ppm")
    if abs(drift) >= 1e5:
        raise c.err(f"{f}.drift_ppm", "must be within ±100000 ppm", drift)
    offset = c.num(d.get("offset", base.offset), f"{f}.offset")
    return ClockSpec(rate, jitter, drift, offset)


def _agent(c: _Ctx, d: Any, f: str, default_clock: ClockSpec) -> AgentSpec:
    d = c.table(
        d,
        f,
        {"id", "role", "p", "R", "omega", "gyro_bias", "neighbors", "k_neighbors", "estimate", "clock"},
        {"id", "role", "p", "omega"},
    )
    aid = c.integer(d["id"], f"{f}.id")
    if aid < 1:
        raise c.err(f"{f}.id", "must be >= 1", aid)
    role = c.string(d["role"], f"{f}.role")
    if role not in ("leader", "follower"):
        raise c.err(f"{f}.role", "must be 'leader' or 'follower'", role)
    p = c.vec3(d["p"], f"{f}.p")
    R = c.rotation(d.get("R", [[1, 0, 0], [0, 1, 0], [0, 0, 1]]), f"{f}.R")
    om = d["omega"]
    if not isinstance(om, list) or len(om) != 3:
        raise c.err(f"{f}.omega", "must be a list of 3 expressions in t", om)
    omega = tuple(c.expr(e, f"{f}.omega[{k}]") for k, e in enumerate(om))
    bias = c.vec3(d.get("gyro_bias", [0, 0, 0]), f"{f}.gyro_bias")
    nb = d.get("neighbors", [])
    if not isinstance(nb, list):
        raise c.err(f"{f}.neighbors", "must be a list of agent ids", nb)
    neighbors = tuple(c.integer(j, f"{f}.neighbors[{k}]") for k, j in enumerate(nb))
    kn = d.get("k_neighbors", [1.0] * len(neighbors))
    if not isinstance(kn, list) or len(kn) != len(neighbors):
        raise c.err(f"{f}.k_neighbors", f"must list one gain k_ij per neighbour ({len(neighbors)})", kn)
    k_neighbors = tuple(c.num(k, f"{f}.k_neighbors[{n}]", positive=True) for n, k in enumerate(kn))
    est = c.table(d.get("estimate", {}), f"{f}.estimate", {"p", "R", "Omega"})
    if role == "leader" and est:
        raise c.err(f"{f}.estimate", "a leader knows its pose and has no estimate")
    estimate = Estimate(
        c.vec3(est.get("p", [0, 0, 0]), f"{f}.estimate.p"),
        c.rotation(est.get("R", [[1, 0, 0], [0, 1, 0], [0, 0, 1]]), f"{f}.estimate.R"),
        c.vec3(est.get("Omega", [0, 0, 0]), f"{f}.estimate.Omega"),
    )
    clock = _clock(c, d.get("clock", {}), f"{f}.clock", default_clock)
    return AgentSpec(aid, role, p, R, omega, bias, neighbors, k_neighbors, estimate, clock)  # type: ignore[arg-type]
