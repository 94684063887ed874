"""Scenario files: TOML -> the typed schema (:class:`ScenarioFile`, each table of the type
its subsystem declares: zswarm.scenario.schema) -> a frozen :class:`Scenario`, validated.

Every error reads ``file: field: problem (got X)``.  See ``topologies/`` for
examples and the README for the full format.

Format (units: seconds, Hz, metres, radians)::

    [scenario]  name, description, duration, seed
    [algorithm] name (built-in, entry point or module path: zswarm.scenario.algorithm.resolve);
                [algorithm.gains] as the algorithm's SPEC.gains declares;
                [algorithm.params] read by the algorithm's params type (SPEC.params: the §4/§5
                schemes' A, u, gamma, delta, Xi, delta_Q, Pi in zswarm.families.synergistic; De Carli's p_star)
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

import functools
import pickle
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Annotated, Any

import msgspec

from zswarm.scenario.agent_config import AgentSpec, Estimate, _agent
from zswarm.scenario.algorithm import AlgorithmError, AlgorithmSpec, StalePolicy, resolve
from zswarm.scenario.clock import ClockSpec, _clock
from zswarm.scenario.faults import APPEND_FAULT, FAULT_KINDS, Fault, _faults, fault_actions, fault_override, parse_fault
from zswarm.scenario.graph import GraphError, _sensing, _tree, check_leader_follower
from zswarm.scenario.links import LinkSpec, LinksTable, _links, purposes
from zswarm.scenario.motion_checks import _check_finite_over_run, _snapshots
from zswarm.scenario.overrides import Override, _apply, parse_field, parse_override, parse_value, render
from zswarm.scenario.reading import ScenarioError, _Ctx, _user_code
from zswarm.scenario.schema import Table, bounds
from zswarm.scenario.world_config import COMMAND_POLICIES, PLANT_INPUTS, PLANTS, CommandPolicy, NoiseTable, WorldTable, _plant
from zswarm.util.quoting import shown

# Re-exported: the scenario's parts live with their subsystems; importers may keep asking here.
__all__ = [
    "APPEND_FAULT",
    "COMMAND_POLICIES",
    "FAULT_KINDS",
    "PLANTS",
    "PLANT_INPUTS",
    "AgentSpec",
    "ClockSpec",
    "CommandPolicy",
    "Estimate",
    "Fault",
    "Formation",
    "Override",
    "Scenario",
    "ScenarioError",
    "fault_actions",
    "fault_override",
    "load",
    "loads",
    "parse_fault",
    "parse_field",
    "parse_override",
    "parse_value",
]


@dataclass(frozen=True, slots=True)
class Formation:
    """A rigidly rotating formation: p_i(t) = R(t)^T p_i(0), R(t) = Ra(rate·t, axis) (§3.3.4, §4.5)."""

    axis: tuple[float, float, float]  # unit vector
    rate: float  # rad/s


class ScenarioText:
    """A scenario's TOML: the file's text, or with overrides the TOML of the result (the file's
    document with the overrides applied), written when first read (a basin's draws are loaded by
    the thousand and never written out)."""

    __slots__ = ("_overrides", "_path", "_rendered", "_text")

    def __init__(self, text: str, path: str = "", overrides: Sequence[Override] = ()) -> None:
        self._text, self._path, self._overrides = text, path, tuple(overrides)
        self._rendered: str | None = None if overrides else text

    @property
    def text(self) -> str:
        if self._rendered is None:
            doc = pickle.loads(_toml(self._text))
            self._rendered = render(doc, self._path, _apply_overrides(doc, self._path, self._overrides))
        return self._rendered

    def with_more(self, overrides: Sequence[Override]) -> ScenarioText:
        """The TOML of this scenario with ``overrides`` applied after its own."""
        return ScenarioText(self._text, self._path, self._overrides + tuple(overrides))

    @property
    def plain(self) -> bool:
        """True when this is a file's text as it is (no overrides)."""
        return not self._overrides

    @property
    def file_text(self) -> str:
        return self._text

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ScenarioText) and self.text == other.text

    def __hash__(self) -> int:
        return hash(self.text)


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
    source: ScenarioText = field(repr=False)  # its TOML: ``text``
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
    part_rate_scale: float = 1.0  # every part's declared rate times this (zswarm.studies.step_size.refine: the dt → 0 reference)
    sensors_fitted: frozenset[str] | None = None  # [world] sensors (None: what the algorithms declare)
    module: ModuleType | None = field(default=None, repr=False)  # the algorithm (zswarm.scenario.algorithm interface)
    leader_module: ModuleType | None = field(default=None, repr=False)  # what agents with role "leader" run
    module_dir: str | None = None  # a directory the algorithm's module was found in (beside the scenario file)
    faults: tuple[Fault, ...] = ()  # [[faults]] and --fault, in time order

    @property
    def text(self) -> str:
        """The scenario's TOML (with overrides: the TOML of the result, what a results folder
        stores as ``scenario.toml``)."""
        return self.source.text

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
    def random_links(self) -> bool:
        """Some link (sensors, edges, commands) draws random numbers: loss, bursts or jitter."""
        names = [f"{i}->world" for i in self.ids] + [f"world->{i}" for i in self.ids] + [f"{j}->{a.id}" for a in self.agents for j in a.neighbors]
        return any(purposes(self.link_spec(n)) for n in names)

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


def with_rotations(sc: Scenario, overrides: Sequence[Override]) -> Scenario:
    """``sc`` with ``overrides`` that each set a rotation of an agent's start, ``agents[n].R``
    or an ``agents[n].estimate.NAME`` that its algorithm declares a rotation: the Scenario that
    :func:`loads` gives for the file's text and those overrides (the same errors too), without
    reading the rest of the file again: a basin loads a draw a few milliseconds at a time.
    Anything else (another field, a scenario that was itself loaded with overrides, a plant or
    graph whose checks read the attitudes) is loaded in full."""
    if not overrides:
        return sc
    fast = sc.source.plain and sc.info.graph == "tree" and sc.plant in ("rigid_body", "prescribed")
    order = _agent_order(sc.source.file_text) if fast else ()
    c = _Ctx(sc.path, {o.field: o.label for o in overrides})
    by_id = {a.id: a for a in sc.agents}
    for o in overrides if fast else ():
        k = o.keys
        n = k[1] if len(k) >= 3 and k[0] == "agents" and isinstance(k[1], int) else -1
        aid = order[n] if 0 <= n < len(order) else None
        if aid is None or aid not in by_id:
            fast = False
            break
        a = by_id[aid]
        fi = sc.info.initial.get(str(k[3])) if len(k) == 4 and k[2] == "estimate" else None
        if len(k) == 3 and k[2] == "R":
            by_id[a.id] = replace(a, R=c.rotation(o.value, o.field))
        elif fi is not None and fi.kind == "rotation" and fi.table == "estimate" and a.role != "leader":
            name = str(k[3])
            values = dict(a.estimate.values)
            values[name] = c.rotation(o.value, o.field)
            by_id[a.id] = replace(a, estimate=Estimate(MappingProxyType(values), a.estimate.stated | {name}))
        else:
            fast = False
            break
    if not fast:
        return loads(sc.source.file_text if sc.source.plain else sc.text, sc.path, overrides)
    return replace(sc, agents=tuple(by_id[a.id] for a in sc.agents), source=sc.source.with_more(overrides))


@functools.lru_cache(maxsize=16)
def _agent_order(text: str) -> tuple[int | None, ...]:
    """The ids of a scenario file's [[agents]] in the file's order (what agents[n] names)."""
    agents = pickle.loads(_toml(text)).get("agents")
    if not isinstance(agents, list):
        return ()
    return tuple(a.get("id") if isinstance(a, dict) and isinstance(a.get("id"), int) else None for a in agents)


# A bound that keeps a run finite: 1e6 s is 11.6 days of world time (an hour's soak is 3600 s).
MAX_DURATION_S = 1e6
SAFE_NAME = re.compile(r"[\w.\-]{1,100}")
MAX_NAME = 100


class Header(Table, frozen=True, kw_only=True):
    """``[scenario]``."""

    name: str
    description: str = ""
    duration: Annotated[float, bounds(positive=True, maxv=MAX_DURATION_S)]  # s (1e300 was accepted and the world ran until killed)
    seed: int = 0


class AlgorithmTable(Table, frozen=True, kw_only=True):
    """``[algorithm]``: its gains, params and stale policy are read once the algorithm is known
    (their fields and defaults are its SPEC's)."""

    name: str
    gains: dict[str, Any] = msgspec.field(default_factory=dict)  # as _gains_type(SPEC.gains)
    params: Any = None  # read by SPEC.params
    stale: dict[str, Any] = msgspec.field(default_factory=dict)  # a StalePolicy over SPEC.stale


class ScenarioFile(Table, frozen=True, kw_only=True):
    """A scenario file: each table of the type its subsystem declares.  The agents, faults and
    graph are read by hand (rotations, expressions, the papers' graph assumptions)."""

    agents: Any
    algorithm: AlgorithmTable
    scenario: Header
    world: WorldTable = WorldTable()
    noise: NoiseTable = NoiseTable()
    clock: dict[str, Any] = msgspec.field(default_factory=dict)  # a ClockSpec, read with the check a type cannot make (zswarm.scenario.clock._clock)
    graph: Any = None
    links: LinksTable = LinksTable()
    faults: Any = msgspec.field(default_factory=list)


@functools.cache
def _gains_type(declared: tuple[tuple[str, float | None], ...]) -> type[Table]:
    """``[algorithm.gains]`` of an algorithm whose SPEC.gains are ``declared``: each a number
    > 0, required when its default is None."""
    fields = [(k, Annotated[float, bounds(positive=True)]) if d is None else (k, Annotated[float, bounds(positive=True)], d) for k, d in declared]
    gains: type[Table] = msgspec.defstruct("Gains", fields, bases=(Table,), frozen=True, kw_only=True)  # type: ignore[assignment]  # a Table: its base
    return gains


@functools.lru_cache(maxsize=16)
def _toml(text: str) -> bytes:
    """The TOML document of ``text``, parsed once and kept pickled (a basin loads the same file
    once a draw; unpickling is 0.02 ms where parsing is 0.5): each caller gets its own copy to
    apply overrides to.  A syntax error is raised again on every call."""
    return pickle.dumps(tomllib.loads(text), protocol=pickle.HIGHEST_PROTOCOL)


def _apply_overrides(doc: dict[str, Any], path: str, overrides: Sequence[Override]) -> list[Override]:
    """``overrides`` applied to ``doc`` in place; returned as placed (a --fault named by its index)."""
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
    return placed


def loads(text: str, path: str = "<string>", overrides: Sequence[Override] = ()) -> Scenario:
    """Parse and validate scenario TOML ``text``; ``path`` is used in errors.

    With ``overrides``, the scenario's ``text`` is the TOML of the result (what
    a results folder stores as ``scenario.toml``).
    """
    try:
        doc = pickle.loads(_toml(text))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{shown(path)}: TOML syntax: {exc}") from None
    source = ScenarioText(text, path, overrides)
    overrides = _apply_overrides(doc, path, overrides)
    c = _Ctx(path, {o.field: o.label for o in overrides})

    sf = c.typed(doc, "", ScenarioFile)
    name = sf.scenario.name
    # The results folder is runs/<name>-<stamp>: "тест ☃/../../x" wrote outside runs/ and a NUL
    # was a traceback.  A file name of letters (any script), digits, '.', '_', '-'.
    if not SAFE_NAME.fullmatch(name) or name.startswith("."):
        raise c.err("scenario.name", f"must be a file name of at most {MAX_NAME} letters, digits, '.', '_' or '-', not starting with '.' (it names the results folder)", name)
    description, duration, seed = sf.scenario.description, sf.scenario.duration, sf.scenario.seed

    algo = sf.algorithm.name
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
    gains = msgspec.structs.asdict(c.typed(sf.algorithm.gains, "algorithm.gains", _gains_type(tuple(info.gains.items()))))
    params = _params(c, sf.algorithm.params, info)
    stale = c.typed(sf.algorithm.stale, "algorithm.stale", StalePolicy, msgspec.structs.asdict(info.stale))

    w = sf.world
    step = w.step
    # A bound that depends on another field: at most one sample per truth step.
    sensor_rate = c.num(w.sensor_rate, "world.sensor_rate", maxv=1.0 / step)
    formation = None
    if w.formation is not None:
        ax = c.axis(w.formation.axis, "world.formation.axis")
        rate = float(c.expr(w.formation.rate, "world.formation.rate")(0.0))
        formation = Formation((float(ax[0]), float(ax[1]), float(ax[2])), rate)
    plant, commands, fitted = _plant(c, w, info, algo)
    nz = sf.noise

    default_clock = _clock(c, sf.clock, "clock", ClockSpec())

    raw_agents = sf.agents
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
    if params is not None and hasattr(params, "check_agents"):
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
        oriented, oriented_from = _tree(c, sf.graph, agents, seen)
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
    links, sensor_links, command_links, link_overrides = _links(c, sf.links, link_names)
    faults = _faults(c, sf.faults, duration, {a.id for a in agents}, link_names)

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
        gyro_var=nz.gyro_var,
        bearing_var=nz.bearing_var,
        agents=tuple(agents),
        source=source,
        velocity_var=nz.velocity_var,
        rel_att_var=nz.rel_att_var,
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
        attitude_var=nz.attitude_var,
        rel_pos_var=nz.rel_pos_var,
        sensors_fitted=fitted,
        module=module,
        leader_module=leader_module,
        module_dir=module_dir,
        faults=faults,
    )


def _params(c: _Ctx, d: Any, info: AlgorithmSpec) -> Any:
    """``[algorithm.params]``, read by the algorithm's params type (SPEC.params, e.g. the set P of
    Prop. 4.2 in zswarm.families.synergistic); None for an algorithm that takes none."""
    f = "algorithm.params"
    if info.params is None:
        if d is not None:
            raise c.err(f, "this algorithm takes no params")
        return None
    return _user_code(c, f, lambda: info.params.load(c, d, f))


