"""The algorithm interface: what an algorithm declares, and how one is found by name.

An algorithm is a Python module (zswarm's own in ``agent/algorithms/``, or a
user's anywhere on the import path) that exposes

* ``SPEC`` — an :class:`AlgorithmSpec`: gains, the sensor fields it needs,
  what it reads from each in-neighbour and writes on each out-edge, what it
  sends to the world, its parts and their rates, the graph it assumes;
* ``Gains`` and ``State`` — frozen dataclasses;
* ``initial_state(init: Initial, gains) -> State``;
* for each part of ``SPEC.parts``: ``inputs(view, gains) -> Inputs`` (built
  from what the runtime serves through a :class:`View`, with the timing
  library :mod:`zswarm.math.timing`) and the pure ``step(state, inputs, dt, gains)
  -> (state, outputs)``; an attribute of ``outputs`` that ``SPEC.jumps`` names lists the
  jumps of a hybrid variable at that step (``(edge k, before, after)`` or ``(before, after)``);
* ``publish(state, view) -> Publish`` — the messages of this tick: one per
  out-neighbour, the estimate for the recorder, and the command to the world.

The runtime (``agent/runtime.py``) reads the declaration and does the rest:
subscriptions, validation of what arrives against ``edge_in``, link
emulation, clocks, stale data, steps that end at measurements, catching up
after late ticks, publishing, counters.
It never asks which algorithm runs.

``algorithm.name`` in a scenario is a built-in name (``bearing_pose_fixed``),
an entry point of the group ``zswarm.algorithms``, or an importable module
(``mylab.observers.my_observer``; a module file beside the scenario file is
found too).
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import importlib.util
import sys
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Annotated, Any, ClassVar, Literal, Protocol

import numpy as np

from zswarm.math.limits import ROT_TOL
from zswarm.math.so3 import rotations_ok
from zswarm.scenario.schema import Table, bounds
from zswarm.util import plugins

ENTRY_POINT_GROUP = "zswarm.algorithms"
BUILTIN_PACKAGE = "agent.algorithms."  # where zswarm's own algorithms live (registered in pyproject.toml)

# The sensors the world can fit, each with what it measures: an algorithm declares them by
# name (SPEC.sensors) and reads each under the same name in its sensor packet (View.sense).
SENSORS: Mapping[str, str] = MappingProxyType(
    {
        "gyro": "body-frame ω_i + bias + noise",
        "bearings": "{j: b_ij^i} toward every graph neighbour",
        "rel_att": "{j: R_ij = R_i^T R_j} for every graph neighbour",
        "velocity": "inertial v_i",
        "velocity_body": "body-frame v_i^i",
        "attitude": "own attitude R_i",
        "position": "own position p_i",
        "rel_pos": "{j: ⁱp_ij = R_i^T (p_j − p_i)} toward the robots i senses, agents[].neighbors (De Carli et al. (2))",
    }
)
GRAPHS = ("any", "leader_follower", "tree", "sensing")
RESERVED = frozenset({"v", "type", "src", "seq", "inc", "t", "t_local", "rx"})  # message envelope and runtime keys


class AlgorithmError(ValueError):
    """An algorithm module that does not satisfy the interface (the message says what is wrong)."""


@dataclass(frozen=True, slots=True)
class Field:
    """One field of an edge message or command: a float64 array of ``shape`` (``()``: a number);
    ``rotation``: a 3x3 rotation matrix, checked on arrival like the wire's own rotations."""

    shape: tuple[int, ...] = (3,)
    optional: bool = False
    doc: str = ""
    rotation: bool = False

    def __post_init__(self) -> None:
        if self.rotation and self.shape != (3, 3):
            raise AlgorithmError(f"a rotation field has shape (3, 3), not {self.shape}")


@dataclass(frozen=True, slots=True)
class Output:
    """A named value the estimate reports besides R̂ and p̂ (``SPEC.estimate``): ``kind="value"``,
    a number or a float64 array of ``shape`` (``()``: a number); ``kind="edges"``, a number per
    tree edge the agent heads ({k: value}, e.g. ξ_k).  The est message carries each in its own
    place (zswarm.transport.messages.Est: ``values`` or ``edges``)."""

    kind: Literal["value", "edges"] = "value"
    shape: tuple[int, ...] = ()
    doc: str = ""


@dataclass(frozen=True, slots=True)
class Jumps:
    """The jumps of a hybrid variable, as a step's outputs list them (``SPEC.jumps``, by the
    outputs' attribute): ``variable`` names it in the est message and the report (``"xi"``),
    ``owner`` says whose it is — ``"edge"``: one per tree edge, each jump ``(k, before, after)``;
    ``"agent"``: the agent's own, each jump ``(before, after)``."""

    variable: str
    owner: Literal["edge", "agent"] = "edge"
    doc: str = ""


Stale = Literal["hold", "drop"]
STALE_POLICIES: tuple[str, ...] = typing.get_args(Stale)


class StalePolicy(Table, frozen=True, kw_only=False):
    """What an agent does with a neighbour's message older than ``max_age`` seconds
    (its stamp against the agent's clock): ``"hold"`` uses it as if fresh,
    ``"drop"`` leaves that neighbour's terms out of the step until a fresher one
    arrives.  Either way such terms are counted (``stale_terms`` in the stats).
    The algorithm's SPEC states its default; a scenario's ``[algorithm.stale]`` overrides it."""

    max_age: Annotated[float, bounds(positive=True)] = 0.2  # s
    policy: Stale = "hold"


@dataclass(frozen=True, slots=True)
class Part:
    """One part of an algorithm, stepped at its own rate.

    ``rate`` is in Hz on the agent's own clock; ``None`` steps the part at
    every step of the agent (its ``[clock] rate``); a part with a rate steps
    when a step ends at least its period, less half a clock period, after its
    last one.  Parts share the algorithm's one ``State``; they are stepped in
    declaration order when due at the same step (a cascade reads what the
    previous part wrote).
    """

    name: str
    inputs: Callable[[View, Any], Any]
    step: Callable[[Any, Any, float, Any], tuple[Any, Any]]
    rate: float | None = None


class Reader(Protocol):
    """How a params type or an initial-state field reads its part of a scenario file (the
    loader's reader, ``zswarm.scenario.reading._Ctx``): each method checks and converts one value,
    and ``err`` makes the ``file: field: problem (got X)`` error to raise."""

    def err(self, fld: str, problem: str, got: Any = ...) -> Exception: ...

    def table(self, d: Any, fld: str, allowed: set[str], required: set[str] = ...) -> dict[str, Any]: ...

    def num(self, v: Any, fld: str, *, positive: bool = False, nonneg: bool = False, maxv: float | None = None, minv: float | None = None) -> float: ...

    def vec3(self, v: Any, fld: str) -> tuple[float, float, float]: ...

    def rotation(self, v: Any, fld: str) -> tuple[float, ...]: ...

    def expr(self, v: Any, fld: str) -> Callable[[float], Any]: ...


class Params(Protocol):
    """What ``SPEC.params`` is: a frozen dataclass type of the algorithm's scenario-wide
    parameters (``[algorithm.params]``), which lives beside the math that uses them
    (:mod:`zswarm.hybrid`'s for the §4/§5 hybrid schemes).  Its field names are the names
    of the ``Gains`` fields its values go to."""

    jumps: ClassVar[bool]  # a hybrid scheme: the runtime tests its jump sets on the initial state

    @classmethod
    def load(cls, r: Reader, d: Any, fld: str) -> Params:
        """The parameters from the ``[algorithm.params]`` table ``d`` (None: absent)."""
        ...

    def check_agents(self, r: Reader, fld: str, ids: tuple[int, ...]) -> None:
        """Optional: checks against the scenario's agents (ids in the agents' order); raise ``r.err``."""
        ...

    def gains(self, ids: tuple[int, ...]) -> Mapping[str, Any]:
        """The values of the ``Gains`` fields they provide, by name."""
        ...


INITIAL_KINDS = ("vector", "rotation", "number", "angle", "edges", "custom")


@dataclass(frozen=True, slots=True)
class InitialField:
    """One initial-state value an agent can be given in the scenario: ``[agents.estimate] name``
    (``table="agent"``: ``[[agents]] name``).

    ``kind``: "vector" (3 numbers), "rotation" ({angle, axis} or 3x3 rows), "number",
    "angle" (a number or an expression like "0.3*pi"), "edges" (a table {edge index k =
    number}, the value of each tree edge k, held by its head: ``symbol`` names it in
    messages), "custom" (``parse(reader, value, field)``).  ``default``: the value when not
    stated (None: not stated is None)."""

    kind: str
    default: Any = None
    doc: str = ""
    symbol: str = ""
    table: str = "estimate"
    parse: Callable[[Reader, Any, str], Any] | None = None


IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
# What an algorithm's agents start from unless its SPEC says otherwise: p̂_i(0), R̂_i(0), Ω̂_i(0).
POSE_ESTIMATE: Mapping[str, InitialField] = MappingProxyType(
    {
        "p": InitialField("vector", (0.0, 0.0, 0.0), "p̂_i(0)"),
        "R": InitialField("rotation", IDENTITY, "R̂_i(0)"),
        "Omega": InitialField("vector", (0.0, 0.0, 0.0), "Ω̂_i(0) (filtered observer)"),
    }
)


@dataclass(frozen=True, slots=True)
class AlgorithmSpec:
    """The declaration of an algorithm (see the module docstring)."""

    description: str
    gains: Mapping[str, float | None]  # name -> default (None: required); every gain must be > 0
    sensors: frozenset[str]  # keys of SENSORS the world measures for this agent
    edge_in: Mapping[str, Field]  # fields read from each in-neighbour's message
    edge_out: Mapping[str, Field]  # fields written on each out-edge
    parts: tuple[Part, ...]  # empty: the agent only publishes what it measures (a leader)
    command: Mapping[str, Field] = field(default_factory=dict)  # sent to the world on cmd/<i> (observers: none)
    graph: str = "any"  # "leader_follower" (Assumptions 3.2/3.4) | "tree" (Assumption 4.2) | "sensing" (De Carli et al.: directed sensing, undirected communication) | "any"
    params: type | None = None  # the [algorithm.params] type (see Params), e.g. zswarm.hybrid.HybridParams; None: takes none
    initial: Mapping[str, InitialField] = field(default_factory=lambda: POSE_ESTIMATE)  # the initial-state values an agent may be given, by name
    stale: StalePolicy = StalePolicy(0.2, "drop")
    leader: str | None = None  # the algorithm agents with role "leader" run (None: no leaders)
    # Its inputs, step and publish broadcast over a leading draw axis (every measurement, message
    # and state value a stack of M draws), so the batched engine (agent/batched.py) may run it.
    batched: bool = False
    # The gains the batched engine may give each draw a value of (a sweep over them steps as one
    # batch): each one only ever multiplies a per-draw vector (M, 3) in the laws, so its stack of
    # M values as (M, 1) broadcasts as the number does.  The others take one value per batch.
    draw_gains: frozenset[str] = frozenset()
    sensor_use: Mapping[str, str] = field(default_factory=dict)  # sensor -> what it is for (named when one is not fitted)
    # What its publish's estimate reports besides R_hat and p_hat (see Output); a number or array
    # it does not declare is reported as a value, a per-edge map must be declared.
    estimate: Mapping[str, Output] = field(default_factory=dict)
    # Its hybrid variables' jumps, by the attribute of the step's outputs that lists them (see Jumps).
    jumps: Mapping[str, Jumps] = field(default_factory=dict)
    # The experiment family of this algorithm (zswarm.families.contract: its report, sweep, basin, batched measure):
    # a name registered in the entry-point group zswarm.families.contract.GROUP ("leader_follower", "tree",
    # "sync", "formation" are zswarm's) or a module path (mylab.my_family).
    report: str = "leader_follower"

    def check_edge(self, fields: Mapping[str, Any]) -> Mapping[str, Any]:
        """Validate a received edge message's fields against ``edge_in`` (raises ValueError)."""
        return _check_fields(fields, self.edge_in, "edge")


def number(x: Any) -> Any:
    """A value of a number field (ξ_k, a message's scalar): a float, or a stack of M draws'
    values on the batched engine (agent/batched.py), as it is."""
    return x if isinstance(x, np.ndarray) else float(x)


def _check_fields(fields: Mapping[str, Any], spec: Mapping[str, Field], what: str) -> Mapping[str, Any]:
    for name, f in spec.items():
        v = fields.get(name)
        if v is None:
            if not f.optional:
                raise ValueError(f"{what} field {name!r} missing")
            continue
        shape = v.shape if type(v) is np.ndarray else np.shape(v)  # np.shape costs 0.4 µs a call
        if shape != f.shape:
            raise ValueError(f"{what} field {name!r}: shape {shape}, expected {f.shape}")
        if f.rotation and not rotations_ok(v, ROT_TOL):
            raise ValueError(f"{what} field {name!r}: not a rotation (R^T R = I, det R = 1 within {ROT_TOL:g})")
    return fields


@dataclass(frozen=True, slots=True)
class Initial:
    """What a scenario gives an agent to start from: its ``SPEC.initial`` values (stated in the
    scenario or their defaults; vectors and rotations as arrays), and the graph around it."""

    id: int
    values: Mapping[str, Any]  # every declared initial value of this agent, by name
    stated: frozenset[str] = frozenset()  # the names stated in the scenario (the rest are defaults)
    tree_edges: Mapping[int, tuple[int, bool]] = field(default_factory=dict)  # tree neighbour j -> (edge k, this agent heads k)
    others: Mapping[int, Mapping[str, Any]] = field(default_factory=dict)  # every agent's stated values, by id
    seed: int = 0  # the run's seed: for initial estimates drawn as a paper draws them (De Carli et al. §IV)
    p0: np.ndarray = field(default_factory=lambda: np.zeros(3))  # true p_i(0), for estimates drawn around it

    @property
    def R_hat(self) -> np.ndarray:
        return np.asarray(self.values.get("R", np.eye(3)), dtype=float).reshape(3, 3)

    @property
    def p_hat(self) -> np.ndarray:
        return np.asarray(self.values.get("p", np.zeros(3)), dtype=float)

    @property
    def Omega(self) -> np.ndarray:
        return np.asarray(self.values.get("Omega", np.zeros(3)), dtype=float)

    def edges_headed(self, name: str) -> dict[int, float]:
        """An "edges" value of every tree edge k this agent heads (0 unless stated)."""
        own = self.values.get(name) or {}
        return {k: float(own.get(k, 0.0)) for k, head in self.tree_edges.values() if head}

    def edges_tailed(self, name: str) -> dict[int, float]:
        """An "edges" value of every tree edge k this agent is the tail of, as its head was given it."""
        return {k: float((self.others.get(j, {}).get(name) or {}).get(k, 0.0)) for j, (k, head) in self.tree_edges.items() if not head}


@dataclass(frozen=True, slots=True)
class Publish:
    """What an agent sends at a tick.

    ``edges[j]``: the fields of the message to out-neighbour j (an agent with
    nothing to say to j leaves it out).  ``estimate``: for the recorder —
    ``R_hat``, ``p_hat`` (what the errors are computed from) and what ``SPEC.estimate``
    declares: per-edge maps ({k: ξ_k}), numbers and arrays (plotted and recorded).  ``command``:
    the fields of ``cmd/<i>`` to the world (``None``: nothing).  ``t``: world
    time the content refers to (``None``: the step's end, ``view.t_world``).
    """

    edges: Mapping[int, Mapping[str, Any]]
    estimate: Mapping[str, Any]
    command: Mapping[str, Any] | None = None
    t: float | None = None


class NeighborMsg(Protocol):
    """An in-neighbour's newest message as the runtime serves it."""

    fields: Mapping[str, Any]  # the declared edge_in fields (arrays, numbers)
    t: float  # stamp of its content, on this agent's clock
    t_world: float  # the same stamp in world time (as sent)
    age: float  # the step's time minus t (≥ 0 unless every recent message is newer)


class View(Protocol):
    """What an algorithm's ``inputs``/``publish`` see at a tick (served by the runtime).

    Times are on the agent's own clock unless named ``*_world``.
    """

    id: int
    role: str
    neighbors: tuple[int, ...]  # in-neighbours N_i (a "sensing" graph: the robots i senses and those sensing i)
    senses: tuple[int, ...]  # the robots whose relative positions i measures (sensor rel_pos)
    k_neighbors: tuple[float, ...]  # k_ij, same order
    out_neighbors: tuple[int, ...]
    tree_edges: Mapping[int, tuple[int, bool]]  # tree neighbour j -> (edge k, this agent heads k)
    moving: bool  # positions change (the world's motion is not fixed)
    t: float  # the end of this step: the newest measurement's time (see AgentNode.tick), or a
    # clock period on from the last step where the world skipped samples
    t_world: float
    period: float  # this agent's clock period, s (1 / [clock] rate): how long what it sends is held
    command_lead: float  # s after t: the middle of the hold of the command this step sends (the measurement's age at
    # the tick, plus the command's way to the world: the agent's own tick-to-send delay and the sensor packets'
    # transit (both measured), plus half a period; period/2 in sim; 0 on a catch-up step, whose command is not sent)
    dt: float  # the step being taken (0 when the view is begun, before any part steps)
    first: bool  # the step from the initial estimate (t = 0) to the first measurement: prediction only, no neighbours
    sense: Mapping[str, Any]  # newest sensor packet at or before t (fields named as SENSORS)
    sense_t: float  # its acquisition time on this clock
    sense_t_world: float  # the same in world time (the packet's stamp)
    align: np.ndarray  # rotates a body-frame vector sampled at sense_t to the body frame at t (gyro; I when t == sense_t)

    def neighbor(self, j: int) -> NeighborMsg | None:
        """j's newest message stamped at or before t; None if none arrived yet, at the first
        step, or if it is older than the stale-data max_age under the "drop" policy.  A read
        changes nothing: the runtime counts the steps that read a neighbour stale (either
        policy) after the step, in ``stale_terms``."""
        ...

    def heard_all(self) -> bool:
        """Every in-neighbour has delivered at least one message."""
        ...

    def mean_rate(self, name: str, t0: float, t1: float) -> np.ndarray:
        """Mean over [t0, t1] of a sensed rate ("gyro", "velocity"): :func:`zswarm.math.timing.interval_mean_rate`."""
        ...

    def body_rate(self, t0: float, t1: float) -> np.ndarray:
        """The constant rate whose exponential over [t0, t1] is the body rotation the gyro
        measured (third order): :func:`zswarm.math.timing.rotation_rate`.  The ω to predict
        an attitude with, ``R̂ exp(dt[ω]^x)``."""
        ...

    def rotation(self, t0: float, t1: float) -> np.ndarray:
        """Body rotation from t0 to t1 from the gyro: :func:`zswarm.math.timing.rotation_over`."""
        ...

    def series(self, name: str, t0: float, t1: float) -> list[tuple[float, np.ndarray]]:
        """Samples ``(time on this clock, value)`` of the sensor field ``name`` ("attitude", "gyro", ...)
        acquired in ``(t0, t1]``, with the newest one at or before t0 first when there is one."""
        ...

    def relative_attitude(self, j: int, t_world: float) -> np.ndarray | None:
        """The measured R_ij at world time t_world from the sensor history:
        :func:`zswarm.math.timing.relative_attitude_at`."""
        ...

    def body_vector(self, key: int | str, t_world: float, unit: bool = True) -> np.ndarray | None:
        """A body-frame vector at world time t_world from the sensor history: the bearing
        toward agent ``key`` (int) or a sensed vector field ("velocity_body"):
        :func:`zswarm.math.timing.body_vector_at`."""
        ...


# --------------------------------------------------------------------------- finding and checking


def registered() -> Mapping[str, str]:
    """Algorithm names -> module paths: zswarm's own algorithms (pyproject.toml) and those of
    every installed package that declares some in ENTRY_POINT_GROUP."""
    return plugins.registered(ENTRY_POINT_GROUP, BUILTIN_PACKAGE)


def _find_spec(target: str) -> Any:
    """importlib's spec of module ``target``, or None (not found, or not a module name)."""
    try:
        return importlib.util.find_spec(target)
    except (ImportError, ValueError):
        return None


def builtin() -> Mapping[str, str]:
    """zswarm's own algorithms (the entry points its distribution declares) -> module paths."""
    return MappingProxyType({k: v for k, v in registered().items() if v.startswith(BUILTIN_PACKAGE)})


def resolve(name: str, near: str | Path | None = None) -> tuple[ModuleType, str | None]:
    """The module of ``algorithm.name``; also the directory added to ``sys.path`` to
    find it (a module file beside the scenario), else None.

    Raises
    ------
    AlgorithmError
        When nothing of that name can be imported, or the module fails the interface.
    """
    added: str | None = None
    target = registered().get(name, name)
    spec = _find_spec(target)
    if spec is None and near is not None:
        d = str(Path(near).resolve().parent)
        if d not in sys.path:
            sys.path.insert(0, d)
            added = d
        spec = _find_spec(target)
    if spec is None:
        known = ", ".join(builtin()) or f"none: zswarm is not installed (pip install -e .), its entry points of {ENTRY_POINT_GROUP!r} are missing"
        raise AlgorithmError(f"unknown algorithm: no built-in, entry point or importable module {name!r} (built-in: {known}; or a module path like mylab.my_observer)")
    try:
        module = importlib.import_module(target)
    except Exception as exc:  # a user's module may raise anything on import
        raise AlgorithmError(f"importing {target!r} failed: {type(exc).__name__}: {exc}") from None
    check(module)
    return module, added


def check(module: ModuleType) -> AlgorithmSpec:
    """Check that ``module`` satisfies the interface; return its SPEC (raises AlgorithmError)."""
    name = module.__name__
    spec = getattr(module, "SPEC", None)
    if not isinstance(spec, AlgorithmSpec):
        raise AlgorithmError(f"module {name!r} has no SPEC (a zswarm.scenario.algorithm.AlgorithmSpec)")
    for attr in ("Gains", "State"):
        obj = getattr(module, attr, None)
        if not (isinstance(obj, type) and dataclasses.is_dataclass(obj)):
            raise AlgorithmError(f"module {name!r}: {attr} must be a dataclass")
    for fn in ("initial_state", "publish"):
        if not callable(getattr(module, fn, None)):
            raise AlgorithmError(f"module {name!r}: no function {fn}()")
    for what, fields in (("edge_in", spec.edge_in), ("edge_out", spec.edge_out), ("command", spec.command)):
        for fname, f in fields.items():
            if fname in RESERVED or not isinstance(f, Field):
                raise AlgorithmError(f"module {name!r}: SPEC.{what}[{fname!r}]: " + ("a reserved name" if fname in RESERVED else "must be a zswarm.scenario.algorithm.Field"))
    for p in spec.parts:
        if not (callable(p.inputs) and callable(p.step)):
            raise AlgorithmError(f"module {name!r}: part {p.name!r} needs callable inputs and step")
        if p.rate is not None and not p.rate > 0:
            raise AlgorithmError(f"module {name!r}: part {p.name!r}: rate must be > 0 Hz (got {p.rate})")
    unknown = set(spec.sensors) - set(SENSORS)
    if unknown:
        raise AlgorithmError(f"module {name!r}: SPEC.sensors: unknown {sorted(unknown)} (known: {', '.join(SENSORS)})")
    if spec.graph not in GRAPHS:
        raise AlgorithmError(f"module {name!r}: SPEC.graph must be one of {GRAPHS} (got {spec.graph!r})")
    if spec.params is not None and not (isinstance(spec.params, type) and dataclasses.is_dataclass(spec.params) and callable(getattr(spec.params, "load", None)) and callable(getattr(spec.params, "gains", None))):
        raise AlgorithmError(f"module {name!r}: SPEC.params must be a dataclass type with load() and gains() (zswarm.scenario.algorithm.Params), or None")
    for key, f in spec.initial.items():
        if not isinstance(f, InitialField) or f.kind not in INITIAL_KINDS or (f.kind == "custom") != (f.parse is not None) or f.table not in ("estimate", "agent"):
            raise AlgorithmError(f"module {name!r}: SPEC.initial[{key!r}] must be a zswarm.scenario.algorithm.InitialField of a kind in {INITIAL_KINDS} (parse given for custom only), table 'estimate' or 'agent'")
    if not isinstance(spec.report, str) or plugins.family_module(spec.report) is None:
        known = ", ".join(plugins.registered(plugins.FAMILY_GROUP, plugins.OWN_FAMILIES))
        raise AlgorithmError(f"module {name!r}: SPEC.report: no experiment family {spec.report!r} (registered: {known}; or a module path like mylab.my_family)")
    for key, o in spec.estimate.items():
        if key in RESERVED or key in ("R_hat", "p_hat") or not isinstance(o, Output) or o.kind not in ("value", "edges"):
            raise AlgorithmError(f"module {name!r}: SPEC.estimate[{key!r}] must be a zswarm.scenario.algorithm.Output of kind 'value' or 'edges' (R_hat and p_hat are the estimate itself)")
    for key, j in spec.jumps.items():
        if not isinstance(j, Jumps) or j.owner not in ("edge", "agent") or not j.variable:
            raise AlgorithmError(f"module {name!r}: SPEC.jumps[{key!r}] must be a zswarm.scenario.algorithm.Jumps (a variable name, owner 'edge' or 'agent')")
    if spec.stale.policy not in STALE_POLICIES:
        raise AlgorithmError(f"module {name!r}: SPEC.stale.policy must be one of {STALE_POLICIES}")
    if not isinstance(spec.draw_gains, frozenset) or not spec.draw_gains <= set(spec.gains):
        raise AlgorithmError(f"module {name!r}: SPEC.draw_gains must be a frozenset of declared gains (SPEC.gains: {', '.join(spec.gains) or 'none'})")
    known = set(spec.gains) | param_names(spec)
    for f in dataclasses.fields(module.Gains):
        if f.name not in known:
            raise AlgorithmError(f"module {name!r}: Gains.{f.name} is neither a declared gain (SPEC.gains) nor a field of SPEC.params ({param_names(spec) or 'none'})")
    return spec


def initial_value(f: InitialField, v: Any) -> Any:
    """A scenario's initial value (tuples, as loaded) as an algorithm receives it in
    ``Initial.values``: vectors as arrays, rotations as 3x3 arrays, edge values as a dict."""
    if v is None:
        return None
    if f.kind == "vector":
        return np.array(v)
    if f.kind == "rotation":
        return np.array(v).reshape(3, 3)
    if f.kind in ("number", "angle"):
        return float(v)
    if f.kind == "edges":
        return dict(v)
    return v


def param_names(spec: AlgorithmSpec) -> set[str]:
    """The names SPEC.params gives values to (its dataclass fields)."""
    return {f.name for f in dataclasses.fields(spec.params)} if spec.params is not None else set()


def jumps(spec: AlgorithmSpec) -> bool:
    """A hybrid scheme (its params type says so): jump sets tested on the initial state."""
    return bool(getattr(spec.params, "jumps", False))


def make_gains(module: ModuleType, values: Mapping[str, Any]) -> Any:
    """The module's ``Gains`` from the agent's gains and the scenario's params (by field name)."""
    return module.Gains(**{f.name: values[f.name] for f in dataclasses.fields(module.Gains)})
