"""Scenario files: TOML -> frozen dataclasses, validated.

Every error reads ``file: field: problem (got X)``.  See ``topologies/`` for
examples and the README for the full format.

Format (units: seconds, Hz, metres, radians)::

    [scenario]  name, description, duration, seed
    [algorithm] name (built-in, entry point or module path: zswarm.algorithm.resolve);
                [algorithm.gains] as the algorithm's SPEC.gains declares;
                [algorithm.params] read by the algorithm's params type (SPEC.params: the §4/§5
                schemes' A, u, gamma, delta, Xi, delta_Q, Pi in zswarm.hybrid; De Carli's p_star)
    [world]     step (s, <= 0.001), sensor_rate (Hz), plant ("prescribed" motions, or
                "rigid_body": (5.1) driven by the agents' torques; the default when the
                algorithm sends a torque), sensors (the sensors fitted; default: what the
                algorithm declares);
                [world.formation] axis, rate: p_i(t) = R(t)^T p_i(0), R(t) = Ra(rate·t, axis);
                [world.commands] max_age (s), policy ("zero" | "hold"): stale commands (world/plant.py)
    [noise]     gyro_var, bearing_var, velocity_var, rel_att_var, attitude_var, rel_pos_var
                (variances, as the papers state them; attitude: R_i exp([n_R]^x), §5.6;
                rel_pos: ⁱp_ij + n per axis, m², De Carli et al. (2))
    [clock]     rate (Hz), jitter (s, std of tick times), drift_ppm, offset (s): defaults for agents
    [graph]     edges = [[head, tail], ...]: the oriented tree of §4, edge k is the k-th
    [[agents]]  id, role, p (at t = 0), R, omega = [3 expressions in t], v = [3 expressions
                in t] (inertial velocity), gyro_bias, neighbors (N_i), k_neighbors (k_ij),
                gains (per-agent overrides, e.g. k_R = k_i^R of §3.3), J (rigid_body: the
                inertia, 3 principal moments or a 3x3 list of rows; omega is then ω_i(0)),
                [agents.estimate] what the algorithm declares (SPEC.initial: p, R, Omega by
                default; xi = {k = ξ_k(0)}, Q, zeta, yaw as its scheme has them);
                [agents.clock] overrides
    [links]     delay_ms, jitter_ms, jitter, reorder, drop, ge_*: agent→agent edges;
                [links.sensors] the same for world→agent links; [links.commands] for the
                agent→world command links; [links.per_link."j->i"] (or "world->i", "i->world") one link

Any field can be overridden from the command line, ``--set links.delay_ms=50``
(:func:`parse_override`, :func:`loads` ``overrides``); an error in an
overridden field names the flag instead of the file.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zswarm import so3
from zswarm.wire import MAX_ABS
from zswarm.algorithm import STALE_POLICIES, AlgorithmError, AlgorithmSpec, InitialField, StalePolicy, resolve
from zswarm.expr import Expr, ExprError, parse
from zswarm.graph import GraphError, check_leader_follower, check_tree
from zswarm.links import JITTER_KINDS, LinkSpec
from zswarm.text import shown, toml_key

# The world's plants and command policy (world/plant.py); imported lazily there to keep
# the loader free of the world package's numerics.
PLANTS = ("prescribed", "rigid_body", "kinematic")
PLANT_INPUTS: Mapping[str, Mapping[str, tuple[int, ...]]] = MappingProxyType(
    {"prescribed": {}, "rigid_body": {"tau": (3,)}, "kinematic": {"vel": (3,), "yaw_rate": ()}}
)
COMMAND_POLICIES = ("zero", "hold")


@dataclass(frozen=True, slots=True)
class CommandPolicy:
    """``[world.commands]``: how old a command may be, and what happens past that age (world/plant.py)."""

    max_age: float = 0.5  # s
    policy: str = "zero"


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names file, field and problem."""


@dataclass(frozen=True, slots=True)
class Formation:
    """A rigidly rotating formation: p_i(t) = R(t)^T p_i(0), R(t) = Ra(rate·t, axis) (§3.3.4, §4.5)."""

    axis: tuple[float, float, float]  # unit vector
    rate: float  # rad/s


@dataclass(frozen=True, slots=True)
class ClockSpec:
    """An agent's clock: tick rate on its own clock, tick jitter, drift and offset."""

    rate: float = 100.0  # Hz
    jitter: float = 0.0  # s, standard deviation of each tick's wake-up time
    drift_ppm: float = 0.0  # own clock runs (1 + drift_ppm·1e-6) times world time
    offset: float = 0.0  # s, own clock reading at world time 0


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


@dataclass(frozen=True, slots=True)
class AgentSpec:
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

    @property
    def R_matrix(self) -> np.ndarray:
        return np.array(self.R, dtype=float).reshape(3, 3)

    @property
    def omega0(self) -> np.ndarray:
        """ω_i(0): the rigid body's initial rate (its ``omega`` expressions at t = 0)."""
        return np.array([float(e(0.0)) for e in self.omega])


@dataclass(frozen=True, slots=True)
class Fault:
    """One ``[[faults]]`` entry (or ``--fault``): something that goes wrong at world time ``at``.

    ``kill``: SIGKILL agent ``agent``; with ``restart_at``, start it again then (a new
    incarnation, from the scenario's initial estimate).  ``stop``: SIGSTOP agent ``agent``
    (a hung process), SIGCONT ``duration`` s later.  ``router``: the router goes down for
    ``duration`` s (``zswarm run`` only: ``sim`` has none).  ``cut``: link ``link``
    ("j->i", "world->i", "i->world") loses every message for ``duration`` s (link
    emulation, both engines).
    """

    kind: str
    at: float
    agent: int | None = None
    restart_at: float | None = None
    duration: float = 0.0
    link: str | None = None

    @property
    def end(self) -> float:
        """When it is over (the restart, the SIGCONT, the router or link back); inf: never."""
        if self.kind == "kill":
            return math.inf if self.restart_at is None else self.restart_at
        return self.at + self.duration

    def describe(self) -> str:
        if self.kind == "kill":
            return f"agent {self.agent} killed at {self.at:g} s" + ("" if self.restart_at is None else f", restarted at {self.restart_at:g} s")
        if self.kind == "stop":
            return f"agent {self.agent} stopped (SIGSTOP) at {self.at:g} s for {self.duration:g} s"
        if self.kind == "router":
            return f"router down at {self.at:g} s for {self.duration:g} s"
        return f"link {self.link} cut at {self.at:g} s for {self.duration:g} s"


def fault_actions(faults: Sequence[Fault]) -> list[tuple[float, int, str, Fault]]:
    """What carrying out ``faults`` takes, in time order: ``(world time, the fault's index,
    action, fault)``, actions ``kill``, ``restart``, ``stop``, ``cont``, ``router_down``,
    ``router_up`` (a cut is the link emulation's: no action).  Both engines read this."""
    acts: list[tuple[float, int, str, Fault]] = []
    for n, f in enumerate(faults):
        if f.kind == "kill":
            acts.append((f.at, n, "kill", f))
            if f.restart_at is not None:
                acts.append((f.restart_at, n, "restart", f))
        elif f.kind == "stop":
            acts += [(f.at, n, "stop", f), (f.end, n, "cont", f)]
        elif f.kind == "router":
            acts += [(f.at, n, "router_down", f), (f.end, n, "router_up", f)]
    return sorted(acts, key=lambda a: (a[0], a[1]))


FAULT_KINDS = ("kill", "stop", "router", "cut")
_FAULT_FIELDS = {"kill": {"agent", "restart_at"}, "stop": {"agent", "duration"}, "router": {"duration"}, "cut": {"link", "duration"}}


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
    velocity_var: float = 0.0
    rel_att_var: float = 0.0
    formation: Formation | None = None
    params: Any = None  # the [algorithm.params], of the algorithm's SPEC.params type (None: it takes none)
    oriented: tuple[tuple[int, int], ...] = ()  # §4: edge k = oriented[k-1] = (head, tail)
    oriented_from: str = ""  # "graph.edges" or how the orientation was derived
    warnings: tuple[str, ...] = ()  # accepted, but worth telling the user (printed by the CLI)
    links: LinkSpec = LinkSpec()  # [links]: the agent→agent edges' model
    sensor_links: LinkSpec = LinkSpec()  # [links.sensors]: the world→agent sensor links' model
    link_overrides: Mapping[str, LinkSpec] = field(default_factory=dict)  # [links.per_link."j->i"]
    stale: StalePolicy = StalePolicy()  # [algorithm.stale]
    plant: str = "prescribed"  # [world] plant
    commands: CommandPolicy = CommandPolicy()  # [world.commands]
    command_links: LinkSpec = LinkSpec()  # [links.commands]: the agent→world command links' model
    attitude_var: float = 0.0
    rel_pos_var: float = 0.0  # [noise] rel_pos_var: body-frame relative positions (m² per axis)
    part_rate_scale: float = 1.0  # every part's declared rate times this (zswarm.study.refine: the dt → 0 reference)
    sensors_fitted: frozenset[str] | None = None  # [world] sensors (None: what the algorithms declare)
    module: ModuleType | None = field(default=None, repr=False)  # the algorithm (zswarm.algorithm interface)
    leader_module: ModuleType | None = field(default=None, repr=False)  # what agents with role "leader" run
    module_dir: str | None = None  # a directory the algorithm's module was found in (beside the scenario file)
    faults: tuple[Fault, ...] = ()  # [[faults]] and --fault, in time order

    def module_for(self, role: str) -> ModuleType:
        """The algorithm module an agent of ``role`` runs."""
        m = self.leader_module if role == "leader" else self.module
        assert m is not None
        return m

    def sensors_of(self, i: int) -> frozenset[str]:
        """The sensor fields the world measures for agent ``i``: its own algorithm's,
        and the scenario algorithm's (a leader measures what its followers do)."""
        own: frozenset[str] = self.module_for(self.agent(i).role).SPEC.sensors
        return own | self.info.sensors

    @property
    def part_rates(self) -> tuple[float, ...]:
        """The declared rates (Hz) of the algorithm's parts that have their own."""
        return tuple(p.rate * self.part_rate_scale for p in self.info.parts if p.rate is not None)

    def link_spec(self, name: str) -> LinkSpec:
        """The model of link ``name`` ("world->3", "1->3", "3->world")."""
        if name in self.link_overrides:
            spec = self.link_overrides[name]
        elif name.endswith("->world"):
            spec = self.command_links
        else:
            spec = self.sensor_links if name.startswith("world->") else self.links
        cuts = tuple((f.at, f.end) for f in self.faults if f.kind == "cut" and f.link == name)
        return replace(spec, cuts=cuts) if cuts else spec

    @property
    def links_active(self) -> bool:
        """Some agent-side link (sensors, edges) is emulated (the command links are the world's)."""
        return (
            self.links.active
            or self.sensor_links.active
            or any(s.active for n, s in self.link_overrides.items() if not n.endswith("->world"))
            or any(f.kind == "cut" and not str(f.link).endswith("->world") for f in self.faults)
        )

    @property
    def info(self) -> AlgorithmSpec:
        """The algorithm's declaration (``SPEC``)."""
        assert self.module is not None
        spec: AlgorithmSpec = self.module.SPEC
        return spec

    @property
    def moving(self) -> bool:
        return self.plant == "kinematic" or self.formation is not None or any(a.velocity is not None for a in self.agents)

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

    def sensed(self, i: int) -> tuple[int, ...]:
        """The robots agent ``i`` measures relative positions of: its sensing out-edges for a
        "sensing" graph (De Carli et al.), else its neighbours."""
        a = self.agent(i)
        return a.senses if self.info.graph == "sensing" else a.neighbors

    def graph_neighbors(self, i: int) -> tuple[int, ...]:
        """In- and out-neighbours of ``i``: the agents it measures bearings to."""
        return tuple(sorted(set(self.agent(i).neighbors) | set(self.out_neighbors(i))))


# --------------------------------------------------------------------------- helpers


class _Ctx:
    """Carries the file name so every error names file and field."""

    def __init__(self, path: str, overridden: Mapping[str, str] | None = None) -> None:
        self.path = shown(path)
        self.overridden = overridden or {}  # field path -> the flag that set it (Override.label)

    def where(self, fld: str) -> str:
        """The file, or the flag when ``fld`` (or a table holding it) was set on the command line."""
        for f, flag in self.overridden.items():
            # The field itself, inside it, or a table the override reached into (an unknown key).
            if fld == f or fld.startswith((f + ".", f + "[")) or f.startswith((fld + ".", fld + "[")):
                return flag
        return self.path

    def err(self, fld: str, problem: str, got: Any = ...) -> ScenarioError:
        tail = "" if got is ... else f" (got {got!r})"
        return ScenarioError(f"{self.where(fld)}: {fld}: {problem}{tail}")

    def table(self, d: Any, fld: str, allowed: set[str], required: set[str] = frozenset()) -> dict[str, Any]:  # type: ignore[assignment]
        if not isinstance(d, dict):
            raise self.err(fld, "must be a table", d)
        for k in d:
            if k not in allowed:
                key = toml_key(k)
                raise self.err(f"{fld}.{key}" if fld else key, f"unknown key (allowed: {', '.join(sorted(allowed))})")
        for k in sorted(required):
            if k not in d:
                raise self.err(f"{fld}.{k}" if fld else k, "missing")
        return d

    def num(self, v: Any, fld: str, *, positive: bool = False, nonneg: bool = False, maxv: float | None = None, minv: float | None = None) -> float:
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
            raise self.err(fld, f"must be <= {maxv:g}", v)
        if minv is not None and x < minv:
            raise self.err(fld, f"must be >= {minv:g}", v)
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

    def axis(self, v: Any, fld: str) -> NDArray[np.float64]:
        """A direction: the unit vector along a non-zero 3-vector.  Scaled by its largest
        entry first, so that neither [1e300, 1e300, 0] (whose norm overflows to inf, which
        made the axis 0 with a RuntimeWarning) nor [1e-200, 1e-200, 0] (whose squares
        underflow, which read as a zero axis) is mistaken."""
        x = np.array(self.vec3(v, fld))
        m = float(np.max(np.abs(x)))
        if m == 0.0:
            raise self.err(fld, "must be non-zero", v)
        x = x / m
        return x / np.linalg.norm(x)

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
            return tuple(so3.Ra(theta, self.axis(v["axis"], f"{fld}.axis")).ravel().tolist())
        if isinstance(v, list) and len(v) == 3 and all(isinstance(r, list) and len(r) == 3 for r in v):
            R = np.array([[self.num(e, f"{fld}[{a}][{b}]") for b, e in enumerate(r)] for a, r in enumerate(v)])
            if not so3.is_rotation(R, 1e-6):
                raise self.err(fld, "is not a rotation matrix (R^T R = I, det R = 1 within 1e-6)", v)
            return tuple(R.ravel().tolist())
        raise self.err(fld, "must be {angle, axis} or a 3x3 list of rows", v)


# --------------------------------------------------------------------------- loading


def load(path: str | Path, overrides: Sequence[Override] = ()) -> Scenario:
    """Load and validate a scenario file, with command-line ``overrides`` applied.

    Raises
    ------
    ScenarioError
        With ``file: field: problem (got X)`` for anything wrong (``--set …:
        field: problem`` when an override is at fault).
    """
    p = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"{shown(p)}: cannot read file ({exc.strerror})") from None
    return loads(text, p, overrides)


@dataclass(frozen=True, slots=True)
class Override:
    """One ``--set FIELD=VALUE``: ``keys`` is the path into the TOML document
    (table keys and array indices), ``field`` its canonical spelling."""

    flag: str  # as given, e.g. "--set links.delay_ms=50"
    field: str  # e.g. 'links.per_link."1->3".drop', "agents[2].clock.rate"
    keys: tuple[str | int, ...]
    value: Any

    @property
    def label(self) -> str:
        """``flag`` for a one-line message: the user's text escaped when it holds a newline, a tab, …"""
        name, _, text = self.flag.partition(" ")
        return f"{name} {shown(text)}"


_SEGMENT = re.compile(r'"(?P<q>[^"]*)"|(?P<k>[A-Za-z0-9_>-]+)|\[(?P<i>\d+)\]')


def _field_name(keys: Sequence[str | int]) -> str:
    out = ""
    for k in keys:
        if isinstance(k, int):
            out += f"[{k}]"
        else:
            part = toml_key(k)
            out += f".{part}" if out else part
    return out


def parse_field(text: str, flag: str = "--set") -> tuple[str | int, ...]:
    """``links.per_link."1->3".drop`` or ``agents[2].clock.rate`` -> the key path."""
    keys: list[str | int] = []
    pos = 0
    while pos < len(text):
        if keys and not text.startswith("[", pos):
            if not text.startswith(".", pos):
                raise ScenarioError(f"{flag}: {shown(text)}: cannot parse the field name at {text[pos:]!r}")
            pos += 1
        m = _SEGMENT.match(text, pos)
        if m is None or m.end() == pos:
            raise ScenarioError(f"{flag}: {shown(text)}: cannot parse the field name at {text[pos:]!r}")
        keys.append(int(m["i"]) if m["i"] is not None else (m["q"] if m["q"] is not None else m["k"]))
        pos = m.end()
    if not keys or isinstance(keys[0], int):
        raise ScenarioError(f"{flag}: {text!r}: expected FIELD=VALUE, e.g. links.delay_ms=50")
    return tuple(keys)


def parse_value(raw: str) -> Any:
    """A TOML value (``50``, ``0.3``, ``true``, ``[1, 0, 0]``, ``"0.1*pi"``); anything
    that is not valid TOML is taken as a string (``exponential``)."""
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw


def parse_override(text: str, flag: str = "--set") -> Override:
    """``FIELD=VALUE`` as given to ``--set`` (or one value of ``--vary``)."""
    name, eq, raw = text.partition("=")
    if not eq or not name.strip():
        raise ScenarioError(f"{flag}: {text!r}: expected FIELD=VALUE, e.g. links.delay_ms=50")
    keys = parse_field(name.strip(), flag)
    return Override(f"{flag} {text}", _field_name(keys), keys, parse_value(raw.strip()))


def _apply(doc: dict[str, Any], o: Override) -> None:
    node: Any = doc
    for n, k in enumerate(o.keys[:-1]):
        here = _field_name(o.keys[: n + 1])
        nxt = o.keys[n + 1]
        if isinstance(k, int):
            if not isinstance(node, list):
                raise ScenarioError(f"{o.label}: {here}: not an array")
            if not 0 <= k < len(node):
                raise ScenarioError(f"{o.label}: {here}: no such element (the array has {len(node)})")
            node = node[k]
        else:
            if not isinstance(node, dict):
                raise ScenarioError(f"{o.label}: {here}: not a table")
            if k not in node:
                node[k] = [] if isinstance(nxt, int) else {}
            node = node[k]
    last = o.keys[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or not 0 <= last < len(node):
            raise ScenarioError(f"{o.label}: {o.field}: no such element")
        node[last] = o.value
    elif not isinstance(node, dict):
        raise ScenarioError(f"{o.label}: {_field_name(o.keys[:-1])}: not a table")
    else:
        node[last] = o.value


def render(doc: dict[str, Any], source: str, overrides: Sequence[Override]) -> str:
    """The TOML text of a scenario with overrides applied (comments are not kept)."""
    import tomli_w

    head = f"# {shown(source)}, with " + ", ".join(o.label for o in overrides) + "\n" if overrides else ""
    return head + tomli_w.dumps(doc)


# Bounds that keep a run finite: 1e6 s is 11.6 days of world time (an hour's soak is 3600 s),
# and a truth step under 1 µs is a million steps per simulated second (1e-300 never ended).
MAX_DURATION_S = 1e6
MIN_WORLD_STEP_S = 1e-6


def loads(text: str, path: str = "<string>", overrides: Sequence[Override] = ()) -> Scenario:
    """Parse and validate scenario TOML ``text``; ``path`` is used in errors.

    With ``overrides``, the scenario's ``text`` is the TOML of the result (what
    a results folder stores as ``scenario.toml``).
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{shown(path)}: TOML syntax: {exc}") from None
    if overrides:
        placed = []
        for o in overrides:
            if o.keys == APPEND_FAULT:  # --fault: one more [[faults]] entry, named by its index
                faults = doc.setdefault("faults", [])
                if not isinstance(faults, list):
                    raise ScenarioError(f"{shown(path)}: faults: must be an array of tables ([[faults]])")
                o = replace(o, field=f"faults[{len(faults)}]", keys=("faults", len(faults)))
                faults.append(o.value)
            else:
                _apply(doc, o)
            placed.append(o)
        overrides = placed
        text = render(doc, path, overrides)
    c = _Ctx(path, {o.field: o.label for o in overrides})

    c.table(doc, "", {"scenario", "algorithm", "world", "noise", "clock", "graph", "links", "agents", "faults"}, {"scenario", "algorithm", "agents"})
    sc = c.table(doc["scenario"], "scenario", {"name", "description", "duration", "seed"}, {"name", "duration"})
    name = c.string(sc["name"], "scenario.name")
    # The results folder is runs/<name>-<stamp>: "тест ☃/../../x" wrote outside runs/ and a NUL
    # was a traceback.  A file name of letters (any script), digits, '.', '_', '-'.
    if not SAFE_NAME.fullmatch(name) or name.startswith("."):
        raise c.err("scenario.name", f"must be a file name of at most {MAX_NAME} letters, digits, '.', '_' or '-', not starting with '.' (it names the results folder)", name)
    description = c.string(sc.get("description", ""), "scenario.description")
    # At most MAX_DURATION_S: 1e300 was accepted and the world ran until killed.
    duration = c.num(sc["duration"], "scenario.duration", positive=True, maxv=MAX_DURATION_S)
    seed = c.integer(sc.get("seed", 0), "scenario.seed")

    al = c.table(doc["algorithm"], "algorithm", {"name", "gains", "params", "stale"}, {"name"})
    algo = c.string(al["name"], "algorithm.name")
    near = path if Path(path).is_file() else None
    try:
        module, module_dir = resolve(algo, near)
        leader_module = resolve(module.SPEC.leader)[0] if module.SPEC.leader else None
    except AlgorithmError as exc:
        raise c.err("algorithm.name", str(exc), algo) from None
    info: AlgorithmSpec = module.SPEC
    if leader_module is not None:
        for fname, fspec in info.edge_in.items():
            out = leader_module.SPEC.edge_out.get(fname)
            if not fspec.optional and (out is None or out.shape != fspec.shape):
                raise c.err("algorithm.name", f"its leader algorithm {info.leader!r} does not write the edge field {fname!r} {fspec.shape} it reads", algo)
    g = c.table(al.get("gains", {}), "algorithm.gains", set(info.gains))
    gains: dict[str, float] = {}
    for k, default in info.gains.items():
        if k not in g:
            if default is None:
                raise c.err(f"algorithm.gains.{k}", "missing")
            gains[k] = default
        else:
            gains[k] = c.num(g[k], f"algorithm.gains.{k}", positive=True)
    params = _params(c, al.get("params"), info)
    st = c.table(al.get("stale", {}), "algorithm.stale", {"max_age", "policy"})
    stale = StalePolicy(
        c.num(st.get("max_age", info.stale.max_age), "algorithm.stale.max_age", positive=True),
        c.string(st.get("policy", info.stale.policy), "algorithm.stale.policy"),
    )
    if stale.policy not in STALE_POLICIES:
        raise c.err("algorithm.stale.policy", f"must be one of {', '.join(STALE_POLICIES)}", stale.policy)

    w = c.table(doc.get("world", {}), "world", {"step", "sensor_rate", "formation", "plant", "sensors", "commands"})
    step = c.num(w.get("step", 0.001), "world.step", positive=True, maxv=0.001, minv=MIN_WORLD_STEP_S)
    sensor_rate = c.num(w.get("sensor_rate", 200.0), "world.sensor_rate", positive=True, maxv=1.0 / step)
    formation = None
    if "formation" in w:
        fm = c.table(w["formation"], "world.formation", {"axis", "rate"}, {"axis", "rate"})
        ax = c.axis(fm["axis"], "world.formation.axis")
        rate = float(c.expr(fm["rate"], "world.formation.rate")(0.0))
        formation = Formation((float(ax[0]), float(ax[1]), float(ax[2])), rate)
    plant, commands, fitted = _plant(c, w, info, algo, formation is not None)

    nz = c.table(doc.get("noise", {}), "noise", {"gyro_var", "bearing_var", "velocity_var", "rel_att_var", "attitude_var", "rel_pos_var"})
    gyro_var = c.num(nz.get("gyro_var", 0.0), "noise.gyro_var", nonneg=True)
    bearing_var = c.num(nz.get("bearing_var", 0.0), "noise.bearing_var", nonneg=True)
    velocity_var = c.num(nz.get("velocity_var", 0.0), "noise.velocity_var", nonneg=True)
    rel_att_var = c.num(nz.get("rel_att_var", 0.0), "noise.rel_att_var", nonneg=True)
    attitude_var = c.num(nz.get("attitude_var", 0.0), "noise.attitude_var", nonneg=True)
    rel_pos_var = c.num(nz.get("rel_pos_var", 0.0), "noise.rel_pos_var", nonneg=True)
    # Noise added to a measured value: 10 σ within the wire's ±MAX_ABS (a sample beyond it is
    # dropped as malformed: gyro_var = 1e30 gave 0 steps and a run that read completed).
    for fld_, v_ in (("gyro_var", gyro_var), ("velocity_var", velocity_var), ("rel_pos_var", rel_pos_var)):
        if v_ > MAX_NOISE_VAR:
            raise c.err(f"noise.{fld_}", f"must be <= {MAX_NOISE_VAR:g} (10 standard deviations within the wire's ±{MAX_ABS:g})", v_)

    default_clock = _clock(c, doc.get("clock", {}), "clock", ClockSpec())

    raw_agents = doc["agents"]
    if not isinstance(raw_agents, list) or not raw_agents:
        raise c.err("agents", "must be a non-empty array of tables ([[agents]])", raw_agents)
    agents: list[AgentSpec] = []
    seen: dict[int, str] = {}
    for n, ra in enumerate(raw_agents):
        f = f"agents[{n}]"
        agents.append(_agent(c, ra, f, default_clock, info, gains, leaders=leader_module is not None, plant=plant))
        if agents[-1].id in seen:
            raise c.err(f"{f}.id", f"duplicate id (also {seen[agents[-1].id]})", agents[-1].id)
        seen[agents[-1].id] = f
    if params is not None:
        _user_code(c, "algorithm.params", lambda: params.check_agents(c, "algorithm.params", tuple(a.id for a in agents)))
    ids = sorted(seen)
    if ids != list(range(1, len(ids) + 1)):
        raise c.err("agents", "ids must be 1..n, each once", ids)
    agents.sort(key=lambda a: a.id)
    fastest = max((p.rate for p in info.parts if p.rate is not None), default=0.0)
    for a in agents:
        if a.clock.rate < fastest:
            raise c.err(f"{seen[a.id]}.clock.rate", f"must be >= {fastest:g} Hz, the rate of the algorithm's fastest part", a.clock.rate)
    if formation is not None:
        for a in agents:
            if a.velocity is not None:
                raise c.err(f"{seen[a.id]}.v", "an agent of a rotating [world.formation] has its velocity set by the formation")
    for a in agents:
        _check_finite_over_run(c, a, seen[a.id], duration, step)

    oriented: tuple[tuple[int, int], ...] = ()
    oriented_from = ""
    warnings: list[str] = []
    if info.graph == "leader_follower":
        if "graph" in doc:
            raise c.err("graph", f"{algo} uses each follower's in-neighbours (agents[].neighbors), not [graph]")
        try:
            warnings = check_leader_follower(
                {a.id: a.neighbors for a in agents},
                {a.id: a.role for a in agents},
                {a.id: a.p for a in agents},
                seen,
                later=_snapshots(agents, formation, duration),
            )
        except GraphError as exc:
            raise ScenarioError(f"{shown(path)}: {exc}") from None
    elif info.graph == "sensing":
        agents = _sensing(c, doc, algo, agents, seen)
    else:
        oriented, oriented_from = _tree(c, doc.get("graph"), agents, seen)
        nbrs = {a.id: tuple(sorted({t for h, t in oriented if h == a.id} | {h for h, t in oriented if t == a.id})) for a in agents}
        out = []
        for a in agents:
            # Every tree neighbour is an in-neighbour: the edges carry messages both ways.
            if a.neighbors and tuple(sorted(a.neighbors)) != nbrs[a.id]:
                raise c.err(f"{seen[a.id]}.neighbors", f"disagrees with the tree's neighbours {list(nbrs[a.id])} of agent {a.id}", list(a.neighbors))
            for key, fi in info.initial.items():
                if fi.kind != "edges":
                    continue
                for ek in a.estimate.get(key) or {}:
                    if not 1 <= ek <= len(oriented):
                        raise c.err(f"{seen[a.id]}.estimate.{key}.{ek}", f"no edge {ek} (edges are 1..{len(oriented)})")
                    head, tail = oriented[ek - 1]
                    if head != a.id:
                        raise c.err(
                            f"{seen[a.id]}.estimate.{key}.{ek}",
                            f"{fi.symbol}_{ek} lives at the head of edge {ek} ({head} -> {tail}), agent {head} (Remark 4.4), not agent {a.id}",
                        )
            out.append(replace(a, neighbors=nbrs[a.id], k_neighbors=(1.0,) * len(nbrs[a.id])))
        agents = out

    link_names = {f"world->{a.id}" for a in agents} | {f"{j}->{a.id}" for a in agents for j in a.neighbors} | ({f"{a.id}->world" for a in agents} if info.command else set())
    links, sensor_links, command_links, link_overrides = _links(c, doc.get("links", {}), link_names)
    faults = _faults(c, doc.get("faults", []), duration, {a.id for a in agents}, link_names)

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
        velocity_var=velocity_var,
        rel_att_var=rel_att_var,
        formation=formation,
        params=params,
        oriented=oriented,
        oriented_from=oriented_from,
        warnings=tuple(warnings),
        links=links,
        sensor_links=sensor_links,
        link_overrides=MappingProxyType(link_overrides),
        stale=stale,
        plant=plant,
        commands=commands,
        command_links=command_links,
        attitude_var=attitude_var,
        rel_pos_var=rel_pos_var,
        sensors_fitted=fitted,
        module=module,
        leader_module=leader_module,
        module_dir=module_dir,
        faults=faults,
    )


def _faults(c: _Ctx, d: Any, duration: float, ids: set[int], link_names: set[str]) -> tuple[Fault, ...]:
    """``[[faults]]``: each checked alone (its kind's fields, inside the run, of an agent or
    a link of the scenario), then against the others (one fault at a time per agent, link,
    and for the router)."""
    if not isinstance(d, list):
        raise c.err("faults", "must be an array of tables ([[faults]])", d)
    out: list[tuple[Fault, str]] = []
    for n, raw in enumerate(d):
        f = f"faults[{n}]"
        if not isinstance(raw, dict):
            raise c.err(f, "must be a table", raw)
        kind = c.string(raw.get("kind"), f"{f}.kind") if "kind" in raw else None
        if kind not in FAULT_KINDS:
            raise c.err(f"{f}.kind", f"must be one of {', '.join(FAULT_KINDS)}", kind) if kind is not None else c.err(f"{f}.kind", "missing")
        extra = _FAULT_FIELDS[kind]
        t = c.table(raw, f, {"kind", "at"} | extra, {"kind", "at"} | (extra - {"restart_at"}))
        at = c.num(t["at"], f"{f}.at", nonneg=True)
        if at >= duration:
            raise c.err(f"{f}.at", f"must be within the run (< scenario.duration = {duration:g} s)", t["at"])
        agent = restart_at = link = None
        dur = 0.0
        if "agent" in t:
            agent = c.integer(t["agent"], f"{f}.agent")
            if agent not in ids:
                raise c.err(f"{f}.agent", f"no such agent (ids: {sorted(ids)})", agent)
        if "restart_at" in t:
            restart_at = c.num(t["restart_at"], f"{f}.restart_at")
            if not at < restart_at < duration:
                raise c.err(f"{f}.restart_at", f"must be after at = {at:g} s and before the end ({duration:g} s)", t["restart_at"])
        if "duration" in t:
            dur = c.num(t["duration"], f"{f}.duration", nonneg=kind == "router", positive=kind != "router")
        if "link" in t:
            link = c.string(t["link"], f"{f}.link")
            if link not in link_names:
                raise c.err(f"{f}.link", f"not a link of this scenario (e.g. {', '.join(sorted(link_names)[:4])})", link)
        fault = Fault(kind, at, agent, restart_at, dur, link)
        # An agent dead to the end may not be stopped or killed again, and so on: one at a time.
        who = ("agent", agent) if agent is not None else ("link", link) if link is not None else ("router", 0)
        for other, g in out:
            same = ("agent", other.agent) if other.agent is not None else ("link", other.link) if other.link is not None else ("router", 0)
            if same == who and fault.at <= other.end and other.at <= fault.end:
                raise c.err(f, f"overlaps {g} ({other.describe()}): one fault at a time per {who[0]}")
        out.append((fault, f))
    return tuple(sorted((f for f, _ in out), key=lambda f: f.at))


APPEND_FAULT: tuple[str | int, ...] = ("faults", -1)  # an Override's keys: append to [[faults]]


def fault_override(text: str, flag: str = "--fault") -> Override:
    """``--fault KIND,FIELD=VALUE,...`` as an override that appends a ``[[faults]]`` entry."""
    return Override(f"{flag} {text}", "faults[+]", APPEND_FAULT, parse_fault(text, flag))


def parse_fault(text: str, flag: str = "--fault") -> dict[str, Any]:
    """``--fault KIND,FIELD=VALUE,...`` (e.g. ``kill,agent=5,at=10,restart_at=15``) as the
    table of a ``[[faults]]`` entry (checked with the rest of the scenario)."""
    kind, *rest = [p.strip() for p in text.split(",")]
    if not kind or "=" in kind:
        raise ScenarioError(f"{flag} {shown(text)}: expected KIND,FIELD=VALUE,... (e.g. kill,agent=5,at=10,restart_at=15; kinds: {', '.join(FAULT_KINDS)})")
    table: dict[str, Any] = {"kind": kind}
    for p in rest:
        k, eq, v = p.partition("=")
        if not eq or not k.strip():
            raise ScenarioError(f"{flag} {shown(text)}: {p!r}: expected FIELD=VALUE")
        table[k.strip()] = parse_value(v.strip())
    return table


_LINK_FIELDS = ("delay_ms", "jitter_ms", "jitter", "reorder", "drop", "ge_p_gb", "ge_p_bg", "ge_loss_good", "ge_loss_bad")


def _link_spec(c: _Ctx, d: Any, f: str, base: LinkSpec, extra: set[str] = frozenset()) -> LinkSpec:  # type: ignore[assignment]
    d = c.table(d, f, set(_LINK_FIELDS) | extra)
    kw: dict[str, Any] = {}
    for k in _LINK_FIELDS:
        if k not in d:
            kw[k] = getattr(base, k)
        elif k == "jitter":
            kw[k] = c.string(d[k], f"{f}.jitter")
            if kw[k] not in JITTER_KINDS:
                raise c.err(f"{f}.jitter", f"must be one of {', '.join(JITTER_KINDS)}", d[k])
        elif k == "reorder":
            if not isinstance(d[k], bool):
                raise c.err(f"{f}.reorder", "must be true or false", d[k])
            kw[k] = d[k]
        else:
            kw[k] = c.num(d[k], f"{f}.{k}")
    spec = LinkSpec(**kw)
    for fld, problem in spec.check():
        raise c.err(f"{f}.{fld}", problem)
    return spec


def _links(c: _Ctx, d: Any, names: set[str]) -> tuple[LinkSpec, LinkSpec, LinkSpec, dict[str, LinkSpec]]:
    """``[links]``: defaults of the agent→agent edges; ``[links.sensors]``: defaults of the
    world→agent sensor links (zero unless set: on-board sensors); ``[links.commands]``:
    defaults of the agent→world command links (zero unless set); ``[links.per_link."j->i"]``,
    ``"world->i"`` and ``"i->world"``: one link each, on top of its kind's defaults."""
    edges = _link_spec(c, d, "links", LinkSpec(), {"per_link", "sensors", "commands"})
    sensors = _link_spec(c, d.get("sensors", {}), "links.sensors", LinkSpec())
    commands = _link_spec(c, d.get("commands", {}), "links.commands", LinkSpec())
    over: dict[str, LinkSpec] = {}
    per = c.table(d.get("per_link", {}), "links.per_link", names)
    for name, sub in per.items():
        base = sensors if name.startswith("world->") else commands if name.endswith("->world") else edges
        over[name] = _link_spec(c, sub, f'links.per_link."{name}"', base)
    return edges, sensors, commands, over


def _plant(c: _Ctx, w: dict[str, Any], info: AlgorithmSpec, algo: str, formation: bool) -> tuple[str, CommandPolicy, frozenset[str] | None]:
    """``[world] plant``, ``[world.commands]`` and ``[world] sensors``, checked against what the
    algorithm sends (SPEC.command) and measures (SPEC.sensors)."""
    from zswarm.algorithm import SENSORS

    sends = {k: f.shape for k, f in info.command.items()}
    default = next((p for p in PLANTS if sends and dict(PLANT_INPUTS[p]) == sends), "prescribed")
    plant = c.string(w.get("plant", default), "world.plant")
    if plant not in PLANTS:
        raise c.err("world.plant", f"must be one of {', '.join(PLANTS)}", plant)
    reads = dict(PLANT_INPUTS[plant])
    if sends and sends != reads:
        raise c.err("world.plant", f"{algo} sends {sends or 'nothing'} on cmd/<i>, but the {plant!r} plant reads {reads or 'nothing'}", plant)
    if plant != "prescribed" and formation:
        raise c.err("world.formation", f"a formation is a prescribed motion; the {plant!r} plant moves by its own dynamics")
    cm = c.table(w.get("commands", {}), "world.commands", {"max_age", "policy"})
    if cm and plant == "prescribed":
        raise c.err("world.commands", "the prescribed plant takes no commands")
    base = CommandPolicy()
    policy = CommandPolicy(
        c.num(cm.get("max_age", base.max_age), "world.commands.max_age", positive=True),
        c.string(cm.get("policy", base.policy), "world.commands.policy"),
    )
    if policy.policy not in COMMAND_POLICIES:
        raise c.err("world.commands.policy", f"must be one of {', '.join(COMMAND_POLICIES)}", policy.policy)
    fitted = None
    if "sensors" in w:
        raw = w["sensors"]
        if not isinstance(raw, list) or not all(isinstance(x, str) for x in raw):
            raise c.err("world.sensors", f"must be a list of sensor names ({', '.join(SENSORS)})", raw)
        for x in raw:
            if x not in SENSORS:
                raise c.err("world.sensors", f"unknown sensor {x!r} (known: {', '.join(SENSORS)})", raw)
        fitted = frozenset(raw)
        missing = sorted(set(info.sensors) - fitted)
        if missing:
            why = "; ".join(f"{m}: {info.sensor_use.get(m, 'declared in its SPEC.sensors')}" for m in missing)
            raise c.err("world.sensors", f"{algo} needs the sensor(s) {', '.join(repr(m) for m in missing)}, not fitted ({why})", raw)
    return plant, policy, fitted


# Motions are checked on this grid over the whole run (at most this many points): an
# expression finite at t = 0 may not be later, and 1/(1-t) used to turn the truth into NaN
# at t = 1, after which the agents dropped every sensor packet as malformed.
FINITE_CHECK_STEP = 1e-3
# An agent's own clock reads (1 + drift)·t + offset and stamps its messages (t_local): past
# ±1e10 s a double resolves it to no better than 2 µs, and 2e12 put every message beyond the
# wire's ±MAX_ABS (all dropped, exit 0); 1e300 froze the clock (t + dt == t: sim hung).
MAX_CLOCK_OFFSET_S = 1e10
MAX_NOISE_VAR = (0.1 * MAX_ABS) ** 2
SAFE_NAME = re.compile(r"[\w.\-]{1,100}")
MAX_NAME = 100
FINITE_CHECK_POINTS = 1_000_000


def _check_finite_over_run(c: Any, a: AgentSpec, fld: str, duration: float, step: float = 1e-3) -> None:
    """Every motion finite and within what the truth and the wire can carry over the run.

    ω: |ω_k|·world.step ≤ π/2, a quarter turn per integration step at most (past it the
    world's exp(ω dt) steps alias; ω = 1e13 was a traceback, ω = exp(3t) turned the truth
    wire-invalid at 9.2 s and it was dropped while the run read completed).  v: the position
    stays within the wire's ±MAX_ABS over the run, |v_k|·duration ≤ MAX_ABS/10."""
    exprs = [("omega", k, e) for k, e in enumerate(a.omega)] + [("v", k, e) for k, e in enumerate(a.velocity or ())]
    for name, k, e in exprs:
        limit, why = (0.5 * math.pi / step, f"a quarter turn per world.step of {step:g} s") if name == "omega" else (0.1 * MAX_ABS / duration, f"the positions within ±{MAX_ABS:g} over the run's {duration:g} s")
        if e.constant:
            v0 = float(e(0.0))
            if abs(v0) > limit:
                raise c.err(f"{fld}.{name}[{k}]", f"must be within ±{limit:.4g} ({why})", e.source)
            continue
        n = max(1, min(FINITE_CHECK_POINTS, math.ceil(duration / FINITE_CHECK_STEP - 1e-9)))
        ts = np.arange(n + 1) * (duration / n)  # k·1 ms exactly, when the run has at most 1e6 steps of it
        with np.errstate(all="ignore"):
            v = np.broadcast_to(np.asarray(e(ts), dtype=float), ts.shape)
        bad = ~np.isfinite(v)
        if bad.any():
            raise c.err(f"{fld}.{name}[{k}]", f"is not finite at t = {ts[int(np.argmax(bad))]:g} s (checked every {duration / n:.3g} s over the run's {duration:g} s)", e.source)
        over = np.abs(v) > limit
        if over.any():
            at = int(np.argmax(over))
            raise c.err(f"{fld}.{name}[{k}]", f"reaches {v[at]:.4g} at t = {ts[at]:g} s, beyond ±{limit:.4g} ({why})", e.source)


def _snapshots(agents: list[AgentSpec], formation: Formation | None, duration: float, n: int = 200) -> list[dict[int, tuple[float, ...]]]:
    """Positions at ``n`` times over the run, for the checks of moving agents (empty if all fixed)."""
    if formation is None and all(a.velocity is None for a in agents):
        return []
    ts = np.linspace(0.0, duration, n + 1)[1:]
    p0 = np.array([a.p for a in agents])
    if formation is not None:
        out = [p0 @ so3.Ra(formation.rate * t, np.array(formation.axis)) for t in ts]
    else:
        # Midpoint rule on a grid of at most 10 ms, sampled at ts.
        h = min(0.01, duration / n)
        grid = np.arange(0.0, duration + h, h)
        P = p0.copy()
        out, k = [], 0
        for t0 in grid[:-1]:
            tm = np.array([t0 + h / 2])
            V = np.array([[float(e(tm)[0]) for e in a.velocity] if a.velocity is not None else [0.0, 0.0, 0.0] for a in agents])
            P = P + h * V
            while k < len(ts) and ts[k] <= t0 + h + 1e-12:
                out.append(P.copy())
                k += 1
        while len(out) < len(ts):
            out.append(P.copy())
    return [{a.id: tuple(row[n_]) for n_, a in enumerate(agents)} for row in out]


def _params(c: _Ctx, d: Any, info: AlgorithmSpec) -> Any:
    """``[algorithm.params]``, read by the algorithm's params type (SPEC.params, e.g. the set P of
    Prop. 4.2 in zswarm.hybrid); None for an algorithm that takes none."""
    f = "algorithm.params"
    if info.params is None:
        if d is not None:
            raise c.err(f, "this algorithm takes no params")
        return None
    return _user_code(c, f, lambda: info.params.load(c, d, f))


def _user_code(c: _Ctx, fld: str, call: Any) -> Any:
    """Run a params type's or an initial field's own reading code (an algorithm's, maybe a
    user's): a ScenarioError it raises stands; anything else it raises is one ``file: field:``
    line naming the exception, not a traceback."""
    try:
        return call()
    except ScenarioError:
        raise
    except Exception as exc:  # noqa: BLE001 - a user's code may raise anything
        raise c.err(fld, f"the algorithm's own check failed: {type(exc).__name__}: {exc}") from None


def _tree(c: _Ctx, d: Any, agents: list[AgentSpec], seen: dict[int, str]) -> tuple[tuple[tuple[int, int], ...], str]:
    """The oriented tree of §4: ``[graph] edges = [[head, tail], ...]`` or derived from neighbours.

    Derived orientation (when ``[graph]`` is absent): each undirected edge
    ``{a, b}`` listed in ``agents[].neighbors`` gets head ``min(a, b)``; edges
    are indexed in ascending ``(head, tail)`` order.  Either way the result
    goes to ``summary.json``.
    """
    ids = {a.id for a in agents}
    if d is not None:
        g = c.table(d, "graph", {"edges"}, {"edges"})
        raw = g["edges"]
        if not isinstance(raw, list) or not raw:
            raise c.err("graph.edges", "must be a list of [head, tail] pairs", raw)
        pairs = []
        for n, e in enumerate(raw):
            if not isinstance(e, list) or len(e) != 2:
                raise c.err(f"graph.edges[{n}]", "must be a [head, tail] pair", e)
            h, t = (c.integer(x, f"graph.edges[{n}]") for x in e)
            for x in (h, t):
                if x not in ids:
                    raise c.err(f"graph.edges[{n}]", f"unknown agent {x}", e)
            pairs.append((h, t))
        fld, how = "graph.edges", "graph.edges"
    else:
        und = set()
        for a in agents:
            for j in a.neighbors:
                if j not in ids:
                    raise c.err(f"{seen[a.id]}.neighbors", f"unknown agent {j}", list(a.neighbors))
                und.add((min(a.id, j), max(a.id, j)))
        pairs = sorted(und)
        fld, how = "agents[].neighbors", "derived: head = smaller id, edges in ascending (head, tail) order"
    try:
        check_tree(sorted(ids), pairs, fld)
    except GraphError as exc:
        raise ScenarioError(f"{c.path}: {exc}") from None
    return tuple(pairs), how


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
    if abs(offset) > MAX_CLOCK_OFFSET_S:
        raise c.err(f"{f}.offset", f"must be within ±{MAX_CLOCK_OFFSET_S:g} s (the own clock's resolution stays under 2 µs)", offset)
    return ClockSpec(rate, jitter, drift, offset)


def _sensing(c: _Ctx, doc: Mapping[str, Any], algo: str, agents: list[AgentSpec], seen: Mapping[int, str]) -> list[AgentSpec]:
    """A directed sensing graph (De Carli et al. §II): ``agents[].neighbors`` lists the robots
    each one senses; communication is its undirected counterpart, so every agent's
    neighbours become the robots it senses and those that sense it (``senses`` keeps the
    first).  Every robot needs a sensing edge, and the undirected graph must be connected."""
    if "graph" in doc:
        raise c.err("graph", f"{algo} takes its directed sensing graph from agents[].neighbors (the robots each one senses), not [graph]")
    ids = {a.id for a in agents}
    sensed_by: dict[int, set[int]] = {a.id: set() for a in agents}
    for a in agents:
        for j in a.neighbors:
            if j not in ids:
                raise c.err(f"{seen[a.id]}.neighbors", f"unknown agent {j}", list(a.neighbors))
            if j == a.id:
                raise c.err(f"{seen[a.id]}.neighbors", f"agent {a.id} cannot sense itself", list(a.neighbors))
            sensed_by[j].add(a.id)
    for a in agents:
        if not a.neighbors and not sensed_by[a.id]:
            raise c.err(f"{seen[a.id]}.neighbors", f"robot {a.id} has no sensing edge: it senses no robot and no robot senses it", [])
    comm = {a.id: set(a.neighbors) | sensed_by[a.id] for a in agents}
    start = agents[0].id
    reached, todo = {start}, [start]
    while todo:
        for j in comm[todo.pop()] - reached:
            reached.add(j)
            todo.append(j)
    if reached != ids:
        raise c.err("agents[].neighbors", f"the sensing graph's undirected version is disconnected: {sorted(reached)} do not reach {sorted(ids - reached)}")
    return [replace(a, senses=a.neighbors, neighbors=tuple(sorted(comm[a.id])), k_neighbors=(1.0,) * len(comm[a.id])) for a in agents]


def _agent(c: _Ctx, d: Any, f: str, default_clock: ClockSpec, info: AlgorithmSpec, gains: Mapping[str, float], leaders: bool, plant: str = "prescribed") -> AgentSpec:
    rigid, kin = plant == "rigid_body", plant == "kinematic"
    d = c.table(
        d,
        f,
        {"id", "role", "p", "R", "omega", "v", "gyro_bias", "neighbors", "k_neighbors", "gains", "estimate", "clock"} | ({"J"} if rigid else set()) | {n for n, fi in info.initial.items() if fi.table == "agent"},
        ({"id", "omega"} if rigid else {"id", "p"} if kin else {"id", "p", "omega"}) | ({"role"} if info.graph == "leader_follower" else set()),
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
    if info.graph == "tree" and role != "follower":
        raise c.err(f"{f}.role", "the §4 observers have no leaders: every agent estimates its attitude (up to a common rotation)", role)
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
    assert fi.parse is not None  # "custom" (zswarm.algorithm.check_module)
    return _user_code(c, fld, lambda: fi.parse(c, v, fld))  # type: ignore[misc]


def _inertia(c: _Ctx, v: Any, fld: str) -> tuple[float, ...]:
    """An inertia matrix: 3 principal moments (diagonal) or a 3x3 list of rows, symmetric positive definite."""
    if isinstance(v, list) and len(v) == 3 and all(not isinstance(x, list) for x in v):
        J = np.diag(c.vec3(v, fld))
    elif isinstance(v, list) and len(v) == 3 and all(isinstance(r, list) and len(r) == 3 for r in v):
        J = np.array([[c.num(e, f"{fld}[{a}][{b}]") for b, e in enumerate(r)] for a, r in enumerate(v)])
    else:
        raise c.err(fld, "must be 3 principal moments or a 3x3 list of rows (kg m^2)", v)
    if not np.allclose(J, J.T, rtol=1e-9, atol=1e-12):
        raise c.err(fld, "must be symmetric", v)
    lam = np.linalg.eigvalsh(0.5 * (J + J.T))
    if lam[0] <= 0:
        raise c.err(fld, f"must be positive definite (eigenvalues {np.round(lam, 6).tolist()})", v)
    return tuple(J.ravel().tolist())
