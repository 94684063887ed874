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
  library :mod:`zswarm.timing`) and the pure ``step(state, inputs, dt, gains)
  -> (state, outputs)``; ``outputs.jumps`` (optional) lists hybrid jumps
  ``(edge k, ξ before, ξ after)``;
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
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Any, Protocol

import numpy as np

from zswarm import plugins
from zswarm.so3 import rotations_ok
from zswarm.wire import ROT_TOL

ENTRY_POINT_GROUP = "zswarm.algorithms"
BUILTIN_PACKAGE = "agent.algorithms."  # where zswarm's own algorithms live (registered in pyproject.toml)
REPORT_FAMILY_GROUP = "zswarm.report_families"
BUILTIN_FAMILIES = "zswarm.report.families."  # zswarm's own report families (registered in pyproject.toml)

# The sensor fields the world can measure, and the sensor-packet key each one fills.
SENSORS: Mapping[str, str] = MappingProxyType(
    {
        "gyro": "gyro",  # body-frame ω_i + bias + noise
        "bearings": "bearings",  # {j: b_ij^i} toward every graph neighbour
        "rel_att": "rel_att",  # {j: R_ij = R_i^T R_j} for every graph neighbour
        "velocity": "vel",  # inertial v_i
        "velocity_body": "vel_body",  # body-frame v_i^i
        "attitude": "R",  # own attitude R_i
        "position": "p",  # own position p_i
        "rel_pos": "rel_pos",  # {j: ⁱp_ij = R_i^T (p_j − p_i)} toward the robots i senses, agents[].neighbors (De Carli et al. (2))
    }
)
GRAPHS = ("any", "leader_follower", "tree", "sensing")
RESERVED = frozenset({"v", "type", "src", "seq", "inc", "t", "t_local", "rx"})  # message envelope and runtime keys
PARAMS = ("", "A", "hybrid", "hybrid_vf", "formation")


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
class StalePolicy:
    """What an agent does with a neighbour's message older than ``max_age`` seconds
    (its stamp against the agent's clock): ``"hold"`` uses it as if fresh,
    ``"drop"`` leaves that neighbour's terms out of the step until a fresher one
    arrives.  Either way such terms are counted (``stale_terms`` in the stats)."""

    max_age: float = 0.2  # s
    policy: str = "hold"


STALE_POLICIES = ("hold", "drop")


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
    params: str = ""  # "" | "A" (continuous, Assumption 4.4) | "hybrid" (Prop. 4.2 set P) | "hybrid_vf" (and δ_Q̃, Π of Condition 5.1) | "formation" (p*_i)
    stale: StalePolicy = StalePolicy(0.2, "drop")
    leader: str | None = None  # the algorithm agents with role "leader" run (None: no leaders)
    sensor_use: Mapping[str, str] = field(default_factory=dict)  # sensor -> what it is for (named when one is not fitted)
    # The report family that turns a run of this algorithm into figures (zswarm.report.family):
    # a name registered in the entry-point group REPORT_FAMILY_GROUP ("leader_follower", "tree",
    # "sync", "formation" are zswarm's) or a module path (mylab.my_family).
    report: str = "leader_follower"

    def check_edge(self, fields: Mapping[str, Any]) -> Mapping[str, Any]:
        """Validate a received edge message's fields against ``edge_in`` (raises ValueError)."""
        return _check_fields(fields, self.edge_in, "edge")


def _check_fields(fields: Mapping[str, Any], spec: Mapping[str, Field], what: str) -> Mapping[str, Any]:
    for name, f in spec.items():
        v = fields.get(name)
        if v is None:
            if not f.optional:
                raise ValueError(f"{what} field {name!r} missing")
            continue
        shape = np.shape(v)
        if shape != f.shape:
            raise ValueError(f"{what} field {name!r}: shape {shape}, expected {f.shape}")
        if f.rotation and not rotations_ok(v, ROT_TOL):
            raise ValueError(f"{what} field {name!r}: not a rotation (R^T R = I, det R = 1 within {ROT_TOL:g})")
    return fields


@dataclass(frozen=True, slots=True)
class Initial:
    """What a scenario gives an agent to start from (``[agents.estimate]``, the graph)."""

    id: int
    R_hat: np.ndarray
    p_hat: np.ndarray
    Omega: np.ndarray
    xi: Mapping[int, float]  # ξ_k(0) of every edge k this agent heads (0 unless given)
    xi_in: Mapping[int, float] = field(default_factory=dict)  # ξ_k(0) of every edge k this agent is the tail of
    Q: np.ndarray = field(default_factory=lambda: np.eye(3))  # Q_i(0) (velocity-free law, §5.4)
    zeta: float = 0.0  # ζ_i(0)
    seed: int = 0  # the run's seed: for initial estimates drawn as a paper draws them (De Carli et al. §IV)
    p0: np.ndarray = field(default_factory=lambda: np.zeros(3))  # true p_i(0), for estimates drawn around it
    p_stated: bool = False  # p_hat is the scenario's (else the algorithm may draw it, as a paper does)
    yaw0: Mapping[int, float] = field(default_factory=dict)  # ψ̂_j(0) stated in the scenario, of every agent j that has one
    yaw_knots: tuple[float, ...] | None = None  # this robot's yaw-rate spline knots, when stated


@dataclass(frozen=True, slots=True)
class Publish:
    """What an agent sends at a tick.

    ``edges[j]``: the fields of the message to out-neighbour j (an agent with
    nothing to say to j leaves it out).  ``estimate``: for the recorder —
    ``R_hat``, ``p_hat`` (what the errors are computed from), ``xi`` ({k: ξ_k}),
    and any other named arrays (plotted and recorded as extras).  ``command``:
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
    sense: Mapping[str, Any]  # newest sensor packet at or before t (fields by SENSORS' keys)
    sense_t: float  # its acquisition time on this clock
    sense_t_world: float  # the same in world time (the packet's stamp)
    align: np.ndarray  # rotates a body-frame vector sampled at sense_t to the body frame at t (gyro; I when t == sense_t)

    def neighbor(self, j: int) -> NeighborMsg | None:
        """j's newest message stamped at or before t; None if none arrived yet, at the first
        step, or if it is older than the stale-data max_age under the "drop" policy
        (counted either way)."""
        ...

    def heard_all(self) -> bool:
        """Every in-neighbour has delivered at least one message."""
        ...

    def mean_rate(self, name: str, t0: float, t1: float) -> np.ndarray:
        """Mean over [t0, t1] of a sensed rate ("gyro", "vel"): :func:`zswarm.timing.interval_mean_rate`."""
        ...

    def body_rate(self, t0: float, t1: float) -> np.ndarray:
        """The constant rate whose exponential over [t0, t1] is the body rotation the gyro
        measured (third order): :func:`zswarm.timing.rotation_rate`.  The ω to predict
        an attitude with, ``R̂ exp(dt[ω]^x)``."""
        ...

    def rotation(self, t0: float, t1: float) -> np.ndarray:
        """Body rotation from t0 to t1 from the gyro: :func:`zswarm.timing.rotation_over`."""
        ...

    def series(self, name: str, t0: float, t1: float) -> list[tuple[float, np.ndarray]]:
        """Samples ``(time on this clock, value)`` of the sensor field ``name`` ("R", "gyro", ...)
        acquired in ``(t0, t1]``, with the newest one at or before t0 first when there is one."""
        ...

    def relative_attitude(self, j: int, t_world: float) -> np.ndarray | None:
        """The measured R_ij at world time t_world from the sensor history:
        :func:`zswarm.timing.relative_attitude_at`."""
        ...

    def body_vector(self, key: int | str, t_world: float, unit: bool = True) -> np.ndarray | None:
        """A body-frame vector at world time t_world from the sensor history: the bearing
        toward agent ``key`` (int) or a sensed vector field ("vel_body"):
        :func:`zswarm.timing.body_vector_at`."""
        ...


# --------------------------------------------------------------------------- finding and checking


def registered() -> Mapping[str, str]:
    """Algorithm names -> module paths: zswarm's own algorithms (pyproject.toml) and those of
    every installed package that declares some in ENTRY_POINT_GROUP."""
    return plugins.registered(ENTRY_POINT_GROUP, BUILTIN_PACKAGE)


def family_module(name: str) -> str | None:
    """The module path of the report family ``name`` (registered, or a module path that can be
    imported), without importing it; None when there is none."""
    target = plugins.registered(REPORT_FAMILY_GROUP, BUILTIN_FAMILIES).get(name, name)
    try:
        return target if importlib.util.find_spec(target) is not None else None
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
    try:
        spec = importlib.util.find_spec(target)
    except (ImportError, ValueError):
        spec = None
    if spec is None and near is not None:
        d = str(Path(near).resolve().parent)
        if d not in sys.path:
            sys.path.insert(0, d)
            added = d
        try:
            spec = importlib.util.find_spec(target)
        except (ImportError, ValueError):
            spec = None
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
        raise AlgorithmError(f"module {name!r} has no SPEC (a zswarm.algorithm.AlgorithmSpec)")
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
                raise AlgorithmError(f"module {name!r}: SPEC.{what}[{fname!r}]: " + ("a reserved name" if fname in RESERVED else "must be a zswarm.algorithm.Field"))
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
    if spec.params not in PARAMS:
        raise AlgorithmError(f"module {name!r}: SPEC.params must be one of {PARAMS} (got {spec.params!r})")
    if not isinstance(spec.report, str) or family_module(spec.report) is None:
        known = ", ".join(plugins.registered(REPORT_FAMILY_GROUP, BUILTIN_FAMILIES))
        raise AlgorithmError(f"module {name!r}: SPEC.report: no report family {spec.report!r} (registered: {known}; or a module path like mylab.my_family)")
    if spec.stale.policy not in STALE_POLICIES:
        raise AlgorithmError(f"module {name!r}: SPEC.stale.policy must be one of {STALE_POLICIES}")
    known = set(spec.gains) | (PARAM_NAMES[spec.params])
    for f in dataclasses.fields(module.Gains):
        if f.name not in known:
            raise AlgorithmError(f"module {name!r}: Gains.{f.name} is neither a declared gain (SPEC.gains) nor a param of SPEC.params={spec.params!r}")
    return spec


PARAM_NAMES: Mapping[str, frozenset[str]] = MappingProxyType(
    {
        "": frozenset(),
        "A": frozenset({"A"}),
        "hybrid": frozenset({"A", "u", "gamma", "delta", "Xi"}),
        "hybrid_vf": frozenset({"A", "u", "gamma", "delta", "Xi", "delta_Q", "Pi"}),
        "formation": frozenset({"p_star"}),  # {agent id: p*_i} (De Carli et al. (30))
    }
)


def make_gains(module: ModuleType, values: Mapping[str, Any]) -> Any:
    """The module's ``Gains`` from the agent's gains and the scenario's params (by field name)."""
    return module.Gains(**{f.name: values[f.name] for f in dataclasses.fields(module.Gains)})
