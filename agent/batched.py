"""The batched lockstep engine: M draws of one scenario stepped together (issue 31).

``zswarm sim`` runs one draw as processes exchanging messages; a Monte-Carlo basin or sweep
runs thousands of draws that share one schedule (the same clocks, sensor grid and graph;
only the agents' starts differ).  Here those draws are stepped *together*: every state and
measurement carries a leading draw axis, the world's plant integrates all M·n bodies at
once (world/plant.py's RigidBodyPlant, the same scheme and step), and each agent's law is
the **same algorithm module** as on ``sim``: its ``inputs``, ``step`` and ``publish`` are
called once per agent and tick on arrays of M draws (the laws broadcast over a leading
axis: agent/algorithms/attitude_sync_terms.py, zswarm/math/so3.py).

What ``sim`` does at a tick is reproduced, in its order: at a time where the world samples
and agents tick, the world first (it integrates up to t under the torques held since the
last ticks, then measures), then the agents by id, each seeing the edge messages of the
agents before it at this tick and of those after it at the last; a command acts from its
tick on (zero-order hold); an agent's first tick (t = 0) tests a hybrid scheme's jump sets
and sends no command; a step's command is evaluated half a period ahead (View.command_lead).
So a draw here and the same draw on ``sim`` differ by round-off only (the batched linear
algebra sums in another order), which the dynamics then carries: tests/component/test_batched.py.

Lockstep needs what it says: every agent on the same clock with no jitter, drift or offset,
its ticks on the sensor grid, no faults but link cuts (the
agent→agent and command links are emulated draw by draw: agent/batched_links.py, _step_groups;
a sensor delay, the same on every sensor link, is stepped as the runtime steps it: _SensorLinks;
sensor jitter, loss and cuts, each draw at its own packets: _DrawSensorLinks, _tick_draws; on a
prescribed truth each draw's estimates are measured at their own stamps by its family's measure,
and its laws read its own sensor history, _Deep, which ``--engine auto`` leaves to sim: prefer_sim),
leaders (if any) that only publish,
sensors of the kinds implemented here (SENSORS; on a truth per draw PER_DRAW_SENSORS), and
the plant its experiment family measures it on here (zswarm.families.contract.Batched: rigid bodies, a
truth per draw; or the prescribed motion, the same in every draw, so it is simulated and
measured once, by the world's own Sensing, and its measurements
are shared), and an algorithm whose SPEC says its functions broadcast (``batched=True``).
The noise is drawn from the world's generators in the world's order, each draw's from its own
seed and with its own variances (on a shared truth the noisy measurements then get a draw
axis; draws of one seed and variances share one draw of it).
:func:`problem` says which of these a scenario lacks; the commands then run it on ``sim`` per
draw.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType, ModuleType, SimpleNamespace
from typing import Any, cast

import numpy as np

from agent import batched_links
from agent.runtime import RECENT_EDGE_MESSAGES, setup, since, step_ends
from world.motion import prescribed, prescribed_key
from world.node import PLAN_SAMPLES, Sensing
from world.plant import RigidBodyPlant
from world.sensors import projective_bearing
from zswarm.math import timing
from zswarm.scenario.agent_config import Estimate
from zswarm.scenario.algorithm import jumps as has_jumps
from zswarm.scenario.links import LinkModel, LinkSpec
from zswarm.families import contract as zswarm_family
from zswarm.families.measure import Context, Published, Result, Truth
from zswarm.scenario import Scenario, ScenarioText
from zswarm.math.so3 import exp, mul

SENSORS = frozenset({"gyro", "rel_att", "attitude", "bearings", "position", "velocity"})  # what the batched world measures
PER_DRAW_SENSORS = frozenset({"gyro", "rel_att", "attitude"})  # ... on a truth per draw (rigid bodies)
# The plants the draws run on here (a family's Batched.plant): rigid bodies (5.1), a truth per
# draw; the prescribed motion, the same truth for every draw (simulated once, its measurements
# shared by the draws).
PLANTS = ("rigid_body", "prescribed")
_EYE3 = np.eye(3)
_EYE3.flags.writeable = False
HISTORY = 64  # sensor samples kept per agent for View.series (the runtime's inbox keeps as many)


class HistorySplit(Exception):
    """A law read the sensor history in a step whose draws hold different histories
    (_tick_draws then steps them apart)."""


class Unsupported(ValueError):
    """A scenario (or a request of its algorithm) that lockstep cannot reproduce."""


def problem(sc: Scenario) -> str | None:
    """Why ``sc`` cannot run on the batched engine (None: it can)."""
    spec = sc.info
    if not getattr(spec, "batched", False):
        return f"{sc.algorithm}'s functions are not declared to broadcast over draws (SPEC.batched)"
    if sc.leader_module is not None:
        lead = sc.module_for("leader").SPEC
        if not getattr(lead, "batched", False):
            return f"the leaders' {sc.leader_module}: its functions are not declared to broadcast over draws (SPEC.batched)"
        if lead.parts:
            return f"the leaders' {sc.leader_module} steps (the batched engine runs leaders that only publish)"
    declared = zswarm_family.of(sc).batched
    if declared is None:
        return f"its experiment family {spec.report!r} declares no measure on the batched engine (zswarm.families.contract.Batched)"
    measure = declared.plant
    if measure not in PLANTS:
        return f"the {spec.report!r} family's {measure!r} plant (the batched engine runs {', '.join(PLANTS)})"
    if sc.plant != measure:
        return f"the {sc.plant!r} plant with the {spec.report!r} family (the batched engine runs it on the {measure!r} plant)"
    if (declared.truth if measure == "rigid_body" else declared.stamps if _per_draw(sc) else declared.ticks) is None:
        return f"the {spec.report!r} family measures no such draws on the batched engine (zswarm.families.contract.Batched: no {'truth' if measure == 'rigid_body' else 'stamps' if _per_draw(sc) else 'ticks'} measure)"
    need = frozenset().union(*(sc.sensors_of(i) for i in sc.ids))
    have = SENSORS if measure == "prescribed" else PER_DRAW_SENSORS
    if need - have:
        return f"the sensor(s) {', '.join(sorted(need - have))} (the batched world measures {', '.join(sorted(have))} on the {measure!r} plant)"
    if len(spec.parts) != 1 or spec.parts[0].rate is not None:
        return "an algorithm of several parts or with a part rate of its own"
    clocks = {a.clock for a in sc.agents}
    if len(clocks) != 1:
        return "agents on different clocks"
    (c,) = clocks
    if c.jitter or c.drift_ppm or c.offset:
        return "clock jitter, drift or offset"
    ratio = sc.sensor_rate / c.rate
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        return f"agent ticks off the sensor grid ({c.rate:g} Hz against {sc.sensor_rate:g} Hz)"
    if any(f.kind != "cut" for f in sc.faults):
        return "faults (other than link cuts)"
    if sc.part_rate_scale != 1.0:
        return "scaled part rates"
    if sc.stale.max_age < 1.0 / c.rate:
        return "a stale-data max_age shorter than a clock period (lockstep serves every message as fresh)"
    return None


def prefer_sim(sc: Scenario) -> str | None:
    """Why ``--engine auto`` runs ``sc`` on sim though this engine runs it (None: it does not).

    Sensor links with jitter, loss or cuts on a prescribed truth (the §3 and §4.5 observers):
    each draw steps at packets of its own and its laws read its own sensor history around their
    neighbours' stamps, so the draws are stepped in many small groups and read in parts
    (_Deep).  The rows are sim's, but measured at 0.72 s of CPU a draw for 2 s of §4.5 hybrid
    (20 % loss, 3 ms jitter, M = 400) against 0.75 s on sim (its processes' start included): no faster."""
    if sc.plant == "prescribed" and _per_draw(sc):
        return "sensor links with jitter, loss or cuts on a prescribed truth: the batched engine runs them (--engine batched, the same rows) but no faster than sim"
    return None


def _per_draw(sc: Scenario) -> bool:
    """Each draw's agents step at packets of their own (run's ``per_draw``)."""
    return batched_links.per_draw_sensors(sc) or (sc.link_spec(f"world->{sc.ids[0]}").active and any(sc.link_spec(f"{j}->{a.id}").active for a in sc.agents for j in a.neighbors))


@dataclass(frozen=True, slots=True)
class _Msg:
    """An in-neighbour's newest message (zswarm.scenario.algorithm.NeighborMsg), fields batched."""

    fields: Mapping[str, Any]
    t: float
    t_world: float
    age: float


class BatchedView(timing.HistoryReads):
    """zswarm.scenario.algorithm.View for M draws of one agent: every message and state value has a
    leading draw axis; the measurements too on a truth per draw (rigid bodies), not on a
    shared one (prescribed motion: the same for every draw, so no draw axis).  Steps end at
    sensor packets (lockstep).  On a shared truth the sensor packets are kept as the runtime's
    inbox keeps them (``HISTORY`` of them) and read as the runtime reads them (timing.HistoryReads,
    timing.relative_attitude_at, timing.body_vector_at), so body_rate, rotation,
    relative_attitude and body_vector give the runtime's numbers; on a truth per draw only the
    history of the fields in ``history`` is kept, and the rest say they are not available."""

    def __init__(self, sc: Scenario, i: int, tree_edges: Mapping[int, tuple[int, bool]], inbox: dict[int, deque[tuple[dict[str, Any], float]]], history: Mapping[str, deque[tuple[float, np.ndarray]]], packets: deque[dict[str, Any]] | None = None) -> None:
        a = sc.agent(i)
        self.id = i
        self.role = a.role
        self.neighbors = a.neighbors
        self.senses = sc.sensed(i)
        self.k_neighbors = a.k_neighbors
        self.out_neighbors = sc.out_neighbors(i)
        self.tree_edges = tree_edges
        self.moving = sc.moving
        self.period = 1.0 / a.clock.rate
        self.max_age = sc.stale.max_age
        self.t = self.t_world = self.dt = 0.0
        self.command_lead = 0.5 * self.period
        self.first = False
        self.sense: Mapping[str, Any] = {}
        self.sense_t = self.sense_t_world = 0.0
        self.stale_read: set[int] = set()
        self._inbox = inbox
        self._history = history
        self._packets = packets
        # The per-draw sensor links' history of a step, built when a law reads it (_tick_draws):
        # None, or a function that returns it (or raises HistorySplit).
        self.history: Callable[[], deque[dict[str, Any]]] | None = None
        # A step of draws that hold different histories: each one's samples (as sample numbers),
        # the packet of a sample, and the group's packets of some samples (:meth:`series`)
        self.mixed: tuple[list[tuple[int, ...]], Callable[[int], dict[str, Any]], Callable[[Sequence[int]], list[dict[str, Any]]]] | None = None
        # On a shared truth with per-draw sensor links: each draw's inbox history (_Deep), read by parts
        self.deep: _Deep | None = None
        self._cache: dict[Any, Any] = {}
        # Emulated agent→agent links: what each in-neighbour's link holds per draw, and the draws
        # of the group being stepped (_step_groups); None: lockstep's perfect links (the inbox).
        self.group: tuple[Mapping[int, batched_links.Read], np.ndarray] | None = None
        self.read_js: set[int] = set()  # in-neighbours this step read (their stale reads are counted)

    @property
    def align(self) -> np.ndarray:
        """Body frame at the packet's time -> at the step's end (TickView.align): the identity
        where the step ends at its packet, else the gyro history's rotation between (a step
        between packets: sensor links that lost the packets there)."""
        if "align" not in self._cache:
            if self.t == self.sense_t or "gyro" not in self.sense:
                self._cache["align"] = _EYE3
            else:
                self._cache["align"] = np.swapaxes(self.rotation(self.sense_t, self.t), -1, -2)
        return self._cache["align"]  # type: ignore[no-any-return]

    def begin(self, t: float, sense: Mapping[str, Any], first: bool) -> None:
        self.t = self.t_world = t
        # The packet's own time: the step's end but where packets were lost before it
        # (_DrawSensorLinks; relative_attitude and body_rate then read the history there).
        self.sense_t = self.sense_t_world = sense.get("t", t)
        self.sense, self.first = sense, first
        self._cache.clear()

    def neighbor(self, j: int) -> Any:
        if self.group is not None:  # emulated links: the group's draws, each its own newest message
            if self.first:
                return None
            reads, G = self.group
            r = reads.get(j)
            if r is None or not r.has[G][0]:  # a group shares what it holds (_step_groups)
                return None
            self.read_js.add(j)  # a stale read counts, dropped or held (TickView.neighbor)
            if not r.present[G][0]:
                return None
            return batched_links.GroupMsg(j, r, G, self.t)
        recent = None if self.first else self._inbox.get(j)
        if not recent:
            return None
        # The newest stamped at or before this step, else the oldest (Inbox.at_or_before): a step
        # behind its tick (a sensor delay) reads what was sent by then.
        m = next((x for x in reversed(recent) if x[1] <= self.t_world), recent[0])
        age = self.t - m[1]
        if age > self.max_age:
            raise Unsupported(f"agent {self.id} read agent {j}'s message {age:g} s old on perfect links (stale after {self.max_age:g} s)")
        return _Msg(m[0], m[1], m[1], age)

    def heard_all(self) -> bool:
        if self.group is not None:
            reads, G = self.group
            return all(j in reads and bool(reads[j].has[G][0]) for j in self.neighbors)
        return all(j in self._inbox for j in self.neighbors)

    def _samples(self, name: str) -> list[tuple[float, np.ndarray]]:
        key = ("s", name)
        if key not in self._cache:
            packets = self._packets_now()
            if packets is not None:  # as the runtime's inbox.series
                self._cache[key] = [(p["t"], p[name]) for p in packets if name in p]
            elif name in self._history:
                self._cache[key] = list(self._history[name])
            else:
                raise Unsupported(f"the batched engine keeps no history of {name!r} here")
        return self._cache[key]  # type: ignore[no-any-return]

    def _shared(self, what: str) -> deque[dict[str, Any]]:
        packets = self._packets_now()
        if packets is None:
            raise Unsupported(f"{what} need the shared truth (prescribed motion)")
        return packets

    def series(self, name: str, t0: float, t1: float) -> list[tuple[float, np.ndarray]]:
        """View.series; in a step of draws that hold different histories, the same for all
        when their samples in the window are the same (the velocity-free law reads its
        attitudes over each step), else HistorySplit."""
        if self.deep is not None:
            parts = self.deep.parts(t0, t1)
            if parts is not None:
                wins = {tuple(round(t / self.deep.dt) for t, _ in timing.window([(p["t"], p) for p in packets], t0, t1)) for _, packets in parts}  # type: ignore[misc]
                if len(wins) > 1:
                    raise Unsupported(f"draws whose sensor histories differ in View.series({name!r}) over ({t0:g}, {t1:g}] (a shared truth's laws read them by parts)")
                return [(p["t"], p[name]) for p in self.deep.take(sorted(wins.pop()))]
            return super().series(name, t0, t1)
        if self.mixed is None:
            return super().series(name, t0, t1)
        sets, packet, build = self.mixed
        wins = {tuple(int(k) for _, k in timing.window([(packet(k)["t"], k) for k in h if name in packet(k)], t0, t1)) for h in sets}  # type: ignore[misc]
        if len(wins) > 1:
            raise HistorySplit
        return [(p["t"], p[name]) for p in build(wins.pop())]

    def _by_parts(self, key: Any, t0: float, t1: float, read: Callable[[], Any], newest: bool = False) -> Any:
        """A history read over ``[t0, t1]`` in draws that hold histories of their own (_Deep):
        once per set of draws that hold the same samples around it, each on those samples
        (the reads are local: _Deep.parts), the draws' values put together."""
        if key in self._cache:
            return self._cache[key]
        parts = None if self.deep is None else self.deep.parts(t0, t1, newest)
        if parts is None:
            value = read()
        else:
            outer, saved = self._cache, (self._packets, self.history)
            got = []
            try:
                for rows, packets in parts:
                    self._cache, self._packets, self.history = {}, deque(packets), None
                    got.append((rows, read()))
            finally:
                self._cache, (self._packets, self.history) = outer, saved
            if all(v is None for _, v in got):
                value = None
            elif any(v is None for _, v in got):
                raise HistorySplit  # some draws have samples there and others not: stepped apart
            else:
                vals = [(rows, np.asarray(v)) for rows, v in got]
                nd = max(v.ndim for _, v in vals)  # a part's value without its draw axis (e.g. the identity) has one less
                inner = next(v.shape[1:] for _, v in vals if v.ndim == nd)
                value = np.empty((self.deep.m, *inner))  # type: ignore[union-attr]
                for rows, v in vals:
                    value[rows] = v if v.ndim == nd else v[None]
        self._cache[key] = value
        return value

    def mean_rate(self, name: str, t0: float, t1: float) -> np.ndarray:
        return self._by_parts(("mr", name, t0, t1), t0, t1, lambda: super(BatchedView, self).mean_rate(name, t0, t1), t1 <= t0)  # type: ignore[no-any-return]

    def body_rate(self, t0: float, t1: float) -> np.ndarray:
        return self._by_parts(("br", t0, t1), t0, t1, lambda: super(BatchedView, self).body_rate(t0, t1), t1 <= t0)  # type: ignore[no-any-return]

    def rotation(self, t0: float, t1: float) -> np.ndarray:
        if t0 == t1:
            return _EYE3  # rotation_over's identity, in every draw
        lo, hi = min(t0, t1), max(t0, t1)
        return self._by_parts(("rt", t0, t1), lo, hi, lambda: super(BatchedView, self).rotation(t0, t1))  # type: ignore[no-any-return]

    def _packets_now(self) -> deque[dict[str, Any]] | None:
        if self.history is not None:
            self._packets, self.history = self.history(), None
        return self._packets

    def relative_attitude(self, j: int, t_world: float) -> np.ndarray | None:
        def read() -> np.ndarray | None:
            hist = [(p["t"], p["rel_att"][j]) for p in self._shared("relative attitudes between samples") if j in p.get("rel_att", ())]
            return timing.relative_attitude_at(hist, self._rates("gyro"), t_world)

        return self._by_parts(("R", j, t_world), t_world, t_world, read)  # type: ignore[no-any-return]

    def _rates(self, name: str) -> list[tuple[float, np.ndarray]]:
        """The samples that body_rate, rotation and mean_rate integrate: only a shared truth's."""
        self._shared(f"integrals of {name!r} between samples")
        return self._samples(name)

    def body_vector(self, key: int | str, t_world: float, unit: bool = True) -> np.ndarray | None:
        def read() -> np.ndarray | None:
            packets = self._shared("body-frame vectors between samples")
            if isinstance(key, int):  # as the runtime's inbox.vectors
                hist = [(p["t"], p["bearings"][key], p["gyro"]) for p in packets if key in p.get("bearings", ())]
            else:
                hist = [(p["t"], p[key], p["gyro"]) for p in packets if key in p]
            return timing.body_vector_at(hist, t_world, unit=unit)

        return self._by_parts(("b", key, t_world, unit), t_world, t_world, read)  # type: ignore[no-any-return]


def stack(values: Sequence[Any]) -> Any:
    """Per-draw values (states, initial values) as one value with a leading draw axis:
    dataclasses field by field, mappings key by key, numbers and arrays stacked."""
    v0 = values[0]
    if dataclasses.is_dataclass(v0) and not isinstance(v0, type):
        return type(v0)(**{f.name: stack([getattr(v, f.name) for v in values]) for f in dataclasses.fields(v0)})
    if isinstance(v0, Mapping):
        keys = list(v0)
        if any(list(v) != keys for v in values):
            raise Unsupported("draws whose states hold different keys")
        return {k: stack([v[k] for v in values]) for k in keys}
    if v0 is None:
        if any(v is not None for v in values):
            raise Unsupported("draws whose states differ in what is set")
        return None
    if isinstance(v0, tuple):
        if any(len(v) != len(v0) for v in values):
            raise Unsupported("draws whose states differ in length")
        return tuple(stack(list(col)) for col in zip(*values, strict=True))
    return np.stack([np.asarray(v, dtype=float) for v in values])


class _SensorLinks:
    """The world→agent sensor links of a batch with a sensor delay: one fixed delay on every
    link (batched_links.per_draw_sensors), so every agent of every draw receives the same packets at the
    same ticks, and the steps the runtime takes on them (AgentNode.tick: an idle tick when no
    packet is newer than the last step, catch-up steps after a late one) are one plan for all.
    Replays a LinkModel (the release times) and the Inbox's delivery at the ticks (held packets
    whose release is at or before the tick, in release order), once."""

    def __init__(self, spec: LinkSpec, period: float) -> None:
        self.model = LinkModel(spec, "world->", 0)  # no random numbers: the seed is never read
        self.period = period
        self.held: deque[tuple[float, int, float]] = deque()  # (release, sample, t): FIFO, releases ascending
        self.packets: deque[tuple[float, int]] = deque(maxlen=HISTORY)  # delivered (t, sample), as Inbox.packets
        self.started = False
        self.t_step = 0.0

    def offer(self, k: int, t: float) -> None:
        """Sample ``k``, sent at ``t``: held until its release (it arrives at ``t``: sim's bus)."""
        release = self.model.admit(t)
        assert release is not None  # no loss (batched_links.per_draw_sensors)
        self.held.append((release, k, t))

    def deliver(self, t_tick: float) -> list[tuple[float, int]]:
        """The packets released by the tick ``t_tick`` (Inbox.release_due), oldest first."""
        out = []
        while self.held and self.held[0][0] <= t_tick:
            _, k, t = self.held.popleft()
            out.append((t, k))
        self.packets.extend(out)
        return out

    def stamps(self, n_samples: int, tick_every: int, sample_dt: float) -> np.ndarray:
        """The stamps of what the ticks of a run publish (the time of each publishing tick's last
        step), planned ahead on a fresh instance: a shared truth's measures keep what the report
        reads at those times (_Ticks)."""
        out = []
        for k in range(n_samples):
            self.offer(k, k * sample_dt)
            if k % tick_every == 0:
                self.deliver((k // tick_every) * self.period)
                mode, ends = self.plan((k // tick_every) * self.period)
                if mode in ("first", "steps"):
                    out.append(ends[-1][0])
        return np.array(out)

    def plan(self, t_tick: float) -> tuple[str, list[tuple[float, int]]]:
        """This tick's steps (AgentNode.tick): ("none", []) before the first packet, ("idle", [])
        when none is newer than the last step, ("first", [(t, k)]) the first step at the newest
        packet, else ("steps", [(t_end, sample), ...]) (step_ends)."""
        if not self.packets:
            return "none", []
        t_m, k_m = self.packets[-1]
        t_end = min(t_m, t_tick)
        if not self.started:
            self.started, self.t_step = True, t_end
            return "first", [(t_end, k_m)]
        if t_end <= self.t_step:
            return "idle", []
        recent = since(self.packets, self.t_step, lambda p: p[0])  # Inbox.recent_packets(t_step)
        ends = step_ends(recent, self.t_step, t_end, self.period, recent[0][1])
        at = {k: t for t, k in recent}
        for t_e, k in ends:
            if at[k] != t_e:  # no loss and ≥ 1 sample a period: never (an end is a packet's time)
                raise Unsupported(f"a step at {t_e:g} s between sensor packets (the batched engine keeps no history to read there)")
        self.t_step = ends[-1][0]
        return "steps", ends


class _DrawSensorLinks:
    """One agent's sensor link in M draws, each with its own delays and losses (jitter, Bernoulli
    and Gilbert–Elliott loss, cuts, FIFO or reordering; batched_links.per_draw_sensors): the packets each draw's inbox holds
    at a tick (the link's LinkStack admits every sample for all draws when it is sent) and the
    steps that draw's AgentNode takes on them (AgentNode.tick, step_ends).  Draws that take the
    same steps form a group (:meth:`plan`); a step between packets (two or more lost) reads the
    group's history there, as the runtime reads its inbox's."""

    def __init__(self, specs: Sequence[LinkSpec], name: str, seeds: Sequence[int], period: float, sample_dt: float) -> None:
        self.stack = batched_links.LinkStack(specs, name, seeds)
        self.M = M = len(seeds)
        self.period, self.sample_dt = period, sample_dt
        self.k0 = 0  # the sample of rel[0]
        self.rel: list[np.ndarray] = []  # per sample from k0: its release (M,), NaN where lost
        self.kept: list[np.ndarray] = []  # per sample from k0: in the draw's inbox (M,) (released, and not behind a newer one)
        self.R = np.zeros((0, M))  # rel as one array (K, M), as of the last deliver
        self.got = np.zeros((0, M), dtype=bool)  # kept as one array
        self.t_last = -math.inf  # the last deliver's tick
        self.kmax = np.full(M, -1, dtype=np.int64)  # the newest packet in the inbox (LinkCounter.max_seq)
        self.n_dropped = np.zeros(M, dtype=np.int64)  # LinkCounter.dropped: the gaps, less the packets that came late into one
        self.started = np.zeros(M, dtype=bool)
        self.t_step = np.zeros(M)  # the last step's end
        self.kstep = np.full(M, -1, dtype=np.int64)  # the newest packet at or before it
        self.deep = False  # keep each draw's last HISTORY packets (a shared truth's laws read them: _Deep)

    def offer(self, k: int, t: float) -> None:
        """Sample ``k``, sent at ``t`` (sim's bus delivers it at once: it arrives at ``t``)."""
        self.rel.append(self.stack.admit(t))
        self.kept.append(np.zeros(self.M, dtype=bool))

    def deliver(self, t_tick: float) -> None:
        """Each draw's inbox at the tick: the packets released since the last tick, taken in
        release order (Inbox._release's heap: ties in arrival order) through the receiver's
        LinkCounter: a packet newer than the newest kept goes in (the gap before it counted
        lost), an older one is late (reordering links) and stays out (a lost one it filled less)."""
        R = self.R = np.array(self.rel)
        new = (R <= t_tick) & ~(R <= self.t_last)  # NaN (lost) compares False
        self.t_last = t_tick
        got = self.got = np.array(self.kept)
        if new.any():
            order = np.argsort(np.where(new, R, np.inf), axis=0, kind="stable")  # per draw, in release order, ties by sample
            cols = np.arange(self.M)
            for r in range(int(new.sum(axis=0).max())):
                e = order[r]
                come = new[e, cols]
                k = self.k0 + e
                first = come & (self.kmax < 0)
                newer = come & (k > self.kmax)
                self.n_dropped += np.where(newer & ~first, k - self.kmax - 1, 0)
                late = come & (k < self.kmax)
                self.n_dropped = np.where(late, np.maximum(0, self.n_dropped - 1), self.n_dropped)
                self.kmax = np.where(newer, k, self.kmax)
                got[e[newer], cols[newer]] = True
            for q in np.flatnonzero(new.any(axis=1)):
                self.kept[q] = got[q]

    def dropped(self) -> np.ndarray:
        """LinkCounter's lost count per draw."""
        return self.n_dropped

    def oldest_needed(self) -> int:
        """The oldest sample a later tick may read (a step's packet at or before its start) or
        count (a reordered packet still in flight: it comes late, and the counter sees it)."""
        waiting = int(self.kmax.min()) + 1
        flying = np.flatnonzero((self.R > self.t_last).any(axis=1))  # NaN (lost) compares False
        if flying.size:
            waiting = min(waiting, self.k0 + int(flying[0]))
        if self.deep and self.got.size:  # each draw's last HISTORY packets, as its inbox keeps them
            got = self.got
            left = np.cumsum(got[::-1], axis=0)[::-1]  # the draw's kept packets from each sample on
            keep = (got & (left <= HISTORY)).any(axis=1)
            if keep.any():
                waiting = min(waiting, self.k0 + int(np.argmax(keep)))
        return min(waiting, int(self.kstep[self.started].min())) if self.started.any() else waiting

    def trim(self, lo: int) -> None:
        if lo > self.k0:
            del self.rel[: lo - self.k0]
            del self.kept[: lo - self.k0]
            self.k0 = lo

    def plan(self, t_tick: float) -> list[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]]:
        """This tick's steps per group of draws (AgentNode.tick): ``(mode, draws, t_step, ends,
        packets)``: "first" (the first step, at the newest packet) or "steps" (step_ends' ends
        from ``t_step``); ``packets``: the samples the group's inbox holds from the one at or
        before ``t_step`` on (its history).  Draws with no packet yet, or none newer than their
        last step (idle), are in no group: they neither step nor send.  After :meth:`deliver`."""
        dt = self.sample_dt
        out = []
        t_m = self.kmax * dt  # a packet's stamp: k · sample_dt (World.next_time)
        first = ~self.started & (self.kmax >= 0)
        if first.any():
            # The first step: at the newest packet, its history every packet delivered so far (all
            # at this tick: the draw had none before, so nothing was trimmed, k0 = 0).
            idx = np.flatnonzero(first)
            top = int(self.kmax[idx].max())
            got = self.got[: top + 1, idx]  # (k0 = 0: nothing trimmed before a first step)
            groups, inv = np.unique(np.concatenate([self.kmax[idx, None], got.T], axis=1), axis=0, return_inverse=True)
            inv = inv.reshape(-1)
            for u, (km, *held) in enumerate(groups):
                G = np.zeros(self.M, dtype=bool)
                G[idx[inv == u]] = True
                out.append(("first", G, 0.0, [(float(km * dt), int(km))], [k for k in range(int(km) + 1) if held[k]]))
        steps = self.started & (t_m > self.t_step)
        idx = np.flatnonzero(steps)
        if idx.size:
            W = self.kmax[idx] - self.kstep[idx]
            # Which of the samples after its last step each draw's inbox holds (w = 1 .. W): with
            # the step and the newest packet, the group key (as many columns as the widest gap)
            w = np.arange(1, int(W.max()) + 1)[:, None]
            row = np.clip(self.kstep[idx] + w - self.k0, 0, len(self.rel) - 1)
            held_w = (w <= W) & self.got[row, idx]  # (W, len(idx))
            key = np.concatenate([np.stack([self.kstep[idx], self.kmax[idx], self.t_step[idx].view(np.int64)], axis=1), held_w.T], axis=1)
            groups, inv = np.unique(key, axis=0, return_inverse=True)
            inv = inv.reshape(-1)
            for u, (ks, km, _, *bits) in enumerate(groups):
                members = idx[inv == u]
                G = np.zeros(self.M, dtype=bool)
                G[members] = True
                t_step = float(self.t_step[members[0]])
                held = [int(ks)] + [int(ks) + w for w in range(1, int(km - ks) + 1) if bits[w - 1]]
                ends = step_ends([(k * dt, k) for k in held], t_step, float(km * dt), self.period, int(ks))
                out.append(("steps", G, t_step, ends, held))
                self.t_step[G] = ends[-1][0]
                self.kstep[G] = ends[-1][1]
        self.t_step = np.where(first, t_m, self.t_step)
        self.kstep = np.where(first, self.kmax, self.kstep)
        self.started |= first
        return out


class _Deep:
    """The sensor histories of a step's draws on a shared truth (rows: each sub-stack row's draw):
    each draw's inbox holds its own last HISTORY packets (the runtime's Inbox.packets), which
    differ between draws that lost different packets long before.  A history read is local (the
    timing functions read the samples around their interval and the newest two), so the draws
    are read in parts (:meth:`parts`), each the draws that hold the same samples there."""

    def __init__(self, links: _DrawSensorLinks, rows: np.ndarray, store: Mapping[int, dict[str, Any]], M: int) -> None:
        self.rows, self.store, self.M, self.m = rows, store, M, len(rows)
        self.k0, self.dt = links.k0, links.sample_dt
        got = links.got[:, rows] & ((links.k0 + np.arange(len(links.got)))[:, None] <= links.kmax[rows][None, :])
        got &= np.cumsum(got[::-1], axis=0)[::-1] <= HISTORY  # the last HISTORY (a deque's maxlen)
        self.got = got
        self.cum = np.cumsum(got, axis=0)  # (K, m): each row's packets up to each sample
        self.ts = (links.k0 + np.arange(len(got))) * links.sample_dt  # k · sample_dt, as World.next_time
        self.uniform = bool(np.all(got == got[:, :1]))

    def take(self, samples: Sequence[int], rows: np.ndarray | None = None) -> list[dict[str, Any]]:
        draws = self.rows if rows is None else self.rows[rows]
        return [_take(self.store[k], draws, self.M) for k in samples]

    def history(self) -> deque[dict[str, Any]]:
        """The whole history, for draws that all hold the same (else HistorySplit)."""
        if not self.uniform:
            raise HistorySplit
        return deque(self.take((self.k0 + np.flatnonzero(self.got[:, 0])).tolist()))

    def parts(self, t0: float, t1: float, newest: bool = False) -> list[tuple[np.ndarray, list[dict[str, Any]]]] | None:
        """``(rows, packets)`` per set of rows that hold the same samples a read over ``[t0, t1]``
        reads (None: every row holds the same history).  The timing functions read the newest
        sample at or before t0, those up to the first after t1, and when none is after t1 the
        history's newest two (body_vector_at, relative_attitude_at, _integrate); ``newest``: the
        newest sample only (a rate over an empty interval is the newest sample's)."""
        if self.uniform:
            return None
        cum, K, N = self.cum, len(self.ts), self.cum[-1]
        if newest:
            lo, hi = np.maximum(N - 1, 0), N
        else:
            s0, s1 = (int(np.searchsorted(self.ts, t + 1e-12, side="right")) - 1 for t in (t0, t1))
            c0 = cum[s0] if s0 >= 0 else np.zeros(self.m, dtype=np.int64)  # packets at or before t0: the newest is c0 − 1
            c1 = cum[min(s1, K - 1)] if s1 >= 0 else np.zeros(self.m, dtype=np.int64)  # ... t1: the first after is c1
            hi = np.minimum(c1 + 1, N)
            lo = np.maximum(np.where(hi >= N, np.minimum(c0 - 1, N - 2), c0 - 1), 0)
        width = int(np.max(hi - lo, initial=0))
        key = np.full((self.m, width), -1, dtype=np.int64)
        for o in range(width):
            pos = lo + o
            key[:, o] = np.where(pos < hi, np.argmax(cum >= (pos + 1)[None, :], axis=0), -1)
        uniq, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        out = []
        for u, row in enumerate(uniq):
            rows = np.flatnonzero(inv == u)
            out.append((rows, self.take((self.k0 + row[row >= 0]).tolist(), rows)))
        return out


class _Torques:
    """The plant's command source: the torques the agents' last ticks sent, held (ZOH)."""

    def __init__(self, n_bodies: int) -> None:
        self.u = np.zeros((n_bodies, 3))

    def inputs_at(self, s: float, h: float) -> np.ndarray:
        return self.u


_NO_TEXT = ScenarioText("")
_NO_LINKS: Mapping[str, LinkSpec] = MappingProxyType({})


def schedule(sc: Scenario) -> Scenario:
    """What the draws of one batch must share: the scenario without what may differ per draw (its
    agents' starts R_i(0), ω_i(0), J_i and initial estimates, the noise variances, the seed, the
    gains its algorithm lets each draw have (SPEC.draw_gains), its TOML, and the models of its
    agent→agent and command links: batched_links takes each draw's own)."""
    draw = sc.info.draw_gains  # gains each draw may have its own value of (SPEC.draw_gains)
    agents = tuple(dataclasses.replace(a, R=(), omega=cast(Any, ()), J=None, estimate=Estimate(), gains=_without(a.gains, draw)) for a in sc.agents)
    # The sensor links stay: every draw of a batch steps at the same packets (_SensorLinks).
    sensor = MappingProxyType({k: v for k, v in sc.link_overrides.items() if k.startswith("world->")}) if sc.link_overrides else _NO_LINKS
    sc = dataclasses.replace(sc, links=LinkSpec(), command_links=LinkSpec(), link_overrides=sensor)
    return dataclasses.replace(sc, agents=agents, source=_NO_TEXT, seed=0, gains=_without(sc.gains, draw), **{f"{f}_var": 0.0 for f in NOISES})


def _without(gains: Mapping[str, float], names: frozenset[str]) -> Mapping[str, float]:
    return MappingProxyType({k: v for k, v in gains.items() if k not in names}) if names else gains


def _same(a: Any, b: Any) -> bool:
    return bool(np.array_equal(a, b)) if isinstance(a, np.ndarray) or isinstance(b, np.ndarray) else bool(a == b)


def draw_gains(module: ModuleType, values: Sequence[Any]) -> Any:
    """One agent's Gains for M draws: the first draw's, where a gain differs between draws its M
    values as a stack (M, 1) (it multiplies (M, 3) vectors only: SPEC.draw_gains)."""
    g0 = values[0]
    stacked: dict[str, Any] = {}
    for f in dataclasses.fields(g0):
        col = [getattr(v, f.name) for v in values]
        if all(_same(col[0], x) for x in col[1:]):
            continue
        if f.name not in module.SPEC.draw_gains:
            raise Unsupported(f"draws whose gain {f.name} differs ({module.__name__.rsplit('.', 1)[-1]} takes one value of it for all the draws of a batch)")
        stacked[f.name] = np.array(col, dtype=float)[:, None]
    return dataclasses.replace(g0, **stacked) if stacked else g0


def group(sc: Scenario) -> tuple[Any, ...]:
    """What runs must share to be stepped in one batch (a sweep's grouping): the schedule, and
    which sensors are noisy (the world draws no numbers for a variance of 0)."""
    return (schedule(sc), tuple(getattr(sc, f"{f}_var") > 0 for f in NOISES))


# world/node.py Sensing.measure's draw order: per field, the numbers it draws per item (a
# neighbour, a bearing pair), each field only where its variance is > 0.
NOISE_ORDER = (("gyro", 3), ("bearing", 2), ("rel_att", 3), ("velocity", 3), ("attitude", 3))


class _Noise:
    """The world's sensor noise of one agent for M draws, in the world's order at every sample
    (NOISE_ORDER) from the world's generator of that agent and seed: each draw gets the numbers
    its own sim run gets.  Draws of one seed and variances share one generator and its numbers;
    otherwise each draw has its own, read ahead ``AHEAD`` samples at a time (a block of standard
    normals is the sequence the sample-by-sample calls draw, and ``0 + σ z`` is numpy's normal)."""

    AHEAD = 128

    def __init__(self, seeds: Sequence[int], i: int, std: Mapping[str, np.ndarray], items: Mapping[str, int], shared: bool) -> None:
        self.on = [(f, size, items[f]) for f, size in NOISE_ORDER if items.get(f, 0) and std[f][0] > 0]
        self.shared = shared
        self.std: dict[str, Any]
        if self.shared:
            self.rng = np.random.default_rng([seeds[0] % (1 << 63), i])
            self.std = {f: float(v[0]) for f, v in std.items()}
        else:
            self.rngs = [np.random.default_rng([s % (1 << 63), i]) for s in seeds]
            self.std = {f: v[:, None] for f, v in std.items()}
            self.width = sum(size * count for _, size, count in self.on)
            self.buf = np.zeros((len(seeds), 0, self.width))
            self.k = 0

    def next(self) -> dict[str, list[Any]]:
        """Each noisy field's noise at this sample, per item: (size,) shared, (M, size) per draw."""
        if self.shared:
            rng, std = self.rng, self.std
            return {f: [rng.normal(0.0, std[f], size) for _ in range(count)] for f, size, count in self.on}
        if not self.on:
            return {}
        if self.k == self.buf.shape[1]:
            self.buf = np.stack([r.standard_normal((self.AHEAD, self.width)) for r in self.rngs])
            self.k = 0
        z = self.buf[:, self.k]
        self.k += 1
        out: dict[str, list[Any]] = {}
        c = 0
        for f, size, count in self.on:
            out[f] = [0.0 + self.std[f] * z[:, c + size * q : c + size * (q + 1)] for q in range(count)]
            c += size * count
        return out


def _measure_draws(sensing: Sensing, i: int, noise: Mapping[str, list[Any]], R: np.ndarray, p: np.ndarray, W: np.ndarray, V: np.ndarray | None, B: np.ndarray | None) -> dict[str, Any]:
    """Sensing.measure of agent i on a shared truth with each draw's own noise ``noise``
    (_Noise.next): a noisy field gets a draw axis, the others stay shared.  The same operations
    as world/sensors.py's, element by element."""
    a, want, index = sensing.index[i], sensing.sensors[i], sensing.index
    m: dict[str, Any] = {}
    if "gyro" in want:
        m["gyro"] = W[a] + sensing.bias[a] + noise["gyro"][0] if "gyro" in noise else W[a] + sensing.bias[a]
    if B is not None and "bearings" in want:
        nb = noise.get("bearing")
        m["bearings"] = {j: B[q] if nb is None else projective_bearing(B[q], nb[n][:, 0], nb[n][:, 1]) for n, (q, j) in enumerate(sensing.pairs_of[i])}
    if "rel_att" in want:
        nr = noise.get("rel_att")
        rel = {j: mul(R[a].T, R[index[j]]) for j in sensing.nbrs[i]}
        m["rel_att"] = rel if nr is None else {j: mul(R_ij, exp(nr[n])) for n, (j, R_ij) in enumerate(rel.items())}
    if V is not None and "velocity" in want:
        m["velocity"] = V[a] + noise["velocity"][0] if "velocity" in noise else np.array(V[a], dtype=float)
    if "attitude" in want:
        m["attitude"] = mul(R[a], exp(noise["attitude"][0])) if "attitude" in noise else R[a]
    if "position" in want:
        m["position"] = p[a]
    return m


NOISES = ("gyro", "bearing", "rel_att", "velocity", "attitude")  # the noise variances the batched world draws with


def _with_draws(m: dict[str, Any], M: int, drawn: frozenset[str]) -> dict[str, Any]:
    """A shared truth's packet for draws that step at packets of their own: the fields measured
    once for all (not in ``drawn``) as read-only views with a draw axis, so a sub-stack's rows
    are taken from every field alike (_take) whatever M is."""
    out: dict[str, Any] = {}
    for f, v in m.items():
        if f in drawn or f == "t":
            out[f] = v
        elif isinstance(v, dict):
            out[f] = {j: np.broadcast_to(x, (M, *np.shape(x))) for j, x in v.items()}
        else:
            out[f] = np.broadcast_to(v, (M, *np.shape(v)))
    return out


def run(
    draws: Sequence[Scenario],
    duration: float,
    seed: int,
    grid_s: float,
    progress: Callable[[float], None] | None = None,
    seeds: Sequence[int] | None = None,
    rows: bool = False,
) -> Result:
    """Step the draws (scenarios that differ only in their agents' starts, or for a prescribed
    truth in their initial estimates, and on rigid bodies in their noise variances) together for
    ``duration`` s of world time; the report family's measure on a grid of ``grid_s`` (the
    family's, zswarm.report.family.Family.basin_grid_s).  ``seeds``: each draw's seed (its noise,
    as sim's World draws it with that seed); by default every draw has ``seed``.  ``rows``: also
    what a sweep's row reads (Result.final_att, att_coarse, ...).  Message and command counts
    are counted either way."""
    sc = draws[0]
    why = problem(sc)
    if why is not None:
        raise Unsupported(f"{sc.name}: the batched engine cannot run it: {why}")
    M, ids = len(draws), sc.ids
    n = len(ids)
    seeds = [seed] * M if seeds is None else list(seeds)
    if len(seeds) != M:
        raise ValueError(f"{len(seeds)} seeds for {M} draws")
    common = schedule(sc)
    if any(schedule(d) != common for d in draws[1:]):
        raise Unsupported("draws that differ in more than their agents' starts, noise variances, seeds and per-draw gains (SPEC.draw_gains)")
    declared = zswarm_family.of(sc).batched
    assert declared is not None  # problem() refused a family without one
    shared = sc.plant == "prescribed"
    col = {i: a for a, i in enumerate(ids)}
    torques = _Torques(M * n)
    # The world's command inbox per draw (batched_links.Commands) for emulated command links, and
    # wherever each draw's agents step at packets of their own and so may skip ticks (sensor links
    # with loss, jitter or cuts, or a sensor delay beside emulated agent→agent links: an agent that
    # hears nothing sends nothing, and the world's stale-command policy acts on what it holds)
    per_draw = any(_per_draw(d) for d in draws)  # (a sweep's draws differ in their agent→agent links)
    cmd_links = None if shared or not (per_draw or any(d.link_spec(f"{i}->world").active for d in draws for i in ids)) else batched_links.Commands(draws, seeds, counters=rows)
    edge_links = batched_links.Edges(draws, seeds, rows, {i: {f: len(x.shape) for f, x in sc.module_for(sc.agent(i).role).SPEC.edge_in.items()} for i in ids}) if any(d.link_spec(f"{j}->{i}").active for d in draws for i in ids for j in sc.agent(i).neighbors) else None
    published = dict.fromkeys(ids, 0)  # messages each agent sent (its sequence number, as AgentNode.seq)
    period = 1.0 / sc.agent(ids[0]).clock.rate  # AgentClock: tick k at k · period
    std = {f: np.sqrt([getattr(d, f"{f}_var") for d in draws]) for f in NOISES}
    if any(np.any((v > 0) != (v[0] > 0)) for v in std.values()):
        raise Unsupported("draws of which some have a sensor's noise and others not (the world draws no numbers for a variance of 0)")
    one_noise = len(set(seeds)) == 1 and all(np.all(v == v[0]) for v in std.values())  # every draw the same noise
    plant: Any
    sensing: Sensing | None = None
    if shared:
        key = prescribed_key(sc)
        if any(prescribed_key(d) != key for d in draws[1:]):
            raise Unsupported("draws whose prescribed truths differ (the batched engine simulates it once for all)")
        plant = prescribed(sc)
        sensing = Sensing(sc, seeds[0])  # the world's sensors, its generators (one noise) and draw order
    else:
        R0 = np.array([[a.R_matrix for a in d.agents] for d in draws])  # (M, n, 3, 3)
        w0 = np.array([[a.omega0 for a in d.agents] for d in draws])
        J = np.array([[np.array(a.J).reshape(3, 3) for a in d.agents] for d in draws])
        plant = RigidBodyPlant(R0.reshape(-1, 3, 3), np.zeros((M * n, 3)), w0.reshape(-1, 3), J.reshape(-1, 3, 3), sc.step, torques if cmd_links is None else cmd_links)  # type: ignore[arg-type]
    bias = np.array([a.gyro_bias for a in sc.agents])

    modules: dict[int, ModuleType] = {}
    parts: dict[int, Any] = {}
    gains: dict[int, Any] = {}
    views: dict[int, BatchedView] = {}
    states: dict[int, Any] = {}
    inboxes: dict[int, dict[int, deque[tuple[dict[str, Any], float]]]] = {i: {} for i in ids}
    want = {i: sc.sensors_of(i) for i in ids}
    nbrs = {i: sc.graph_neighbors(i) for i in ids}
    # Kept sensor history: on a shared truth, every packet (as an agent's inbox keeps them); on a
    # truth per draw, the attitudes only.
    packets: dict[int, deque[dict[str, Any]]] = {i: deque(maxlen=HISTORY) for i in ids}
    histories: dict[int, dict[str, deque[tuple[float, np.ndarray]]]] = {i: {} if shared else {f: deque(maxlen=HISTORY) for f in ("attitude",) if f in want[i]} for i in ids}
    # The world's generators, when not Sensing's own (one noise for every draw on a shared truth).
    per_draw_noise = not (shared and one_noise)
    noise: dict[int, _Noise] = {}
    if per_draw_noise:
        for i in ids:
            items = {"gyro": "gyro" in want[i], "rel_att": len(nbrs[i]) * ("rel_att" in want[i]), "attitude": "attitude" in want[i]}
            if shared:
                assert sensing is not None
                items |= {"bearing": len(sensing.pairs_of[i]) * ("bearings" in want[i]), "velocity": sc.moving and "velocity" in want[i]}
            noise[i] = _Noise(seeds, i, std, {f: int(c) for f, c in items.items()}, one_noise)
    for i in ids:
        per = [setup(d, i, s) for d, s in zip(draws, seeds, strict=True)]
        modules[i], _, tree_edges, _ = per[0]
        gains[i] = draw_gains(modules[i], [p[1] for p in per])
        spec_parts = modules[i].SPEC.parts
        parts[i] = spec_parts[0] if spec_parts else None  # None: a leader that only publishes
        states[i] = stack([modules[i].initial_state(p[3], gains[i]) for p in per])
        views[i] = BatchedView(sc, i, tree_edges, inboxes[i], histories[i], packets[i] if shared else None)
    hybrid = has_jumps(sc.info)
    # A sensor delay (the same on every sensor link: batched_links.per_draw_sensors): the packets' releases
    # and the steps the agents take on them, one plan for every agent and draw.
    sensor_spec = sc.link_spec(f"world->{ids[0]}")
    sensor_links = _SensorLinks(sensor_spec, period) if sensor_spec.active and not per_draw else None
    store: dict[int, dict[int, dict[str, Any]]] = {i: {} for i in ids}  # sample -> packet, while some tick may read it
    draw_links: dict[int, _DrawSensorLinks] = {}
    draw_inbox: batched_links.DrawInbox | None = None
    if per_draw:
        draw_links = {i: _DrawSensorLinks([d.link_spec(f"world->{i}") for d in draws], f"world->{i}", seeds, period, 1.0 / sc.sensor_rate) for i in ids}
        for dl in draw_links.values():
            dl.deep = shared  # a shared truth's laws read the sensor history around their neighbours' stamps too
        ndim = {i: {f: len(x.shape) for f, x in sc.module_for(sc.agent(i).role).SPEC.edge_in.items()} for i in ids}
        draw_inbox = batched_links.DrawInbox(sc, M, ndim, *((draws, seeds) if edge_links is not None else (None, None)), counters=rows)
        edge_links = None  # the draw inbox emulates them
    draw_edges = np.zeros(M, dtype=np.int64)  # per draw (per_draw): messages and commands sent
    draw_commands = np.zeros(M, dtype=np.int64)
    n_tick = 0

    sample_dt = 1.0 / sc.sensor_rate
    tick_every = round(sc.sensor_rate / sc.agent(ids[0]).clock.rate)
    n_samples = math.floor(duration * sc.sensor_rate + 1e-9) + 1
    stamps = None if sensor_links is None else _SensorLinks(sensor_spec, period).stamps(n_samples, tick_every, sample_dt)
    # The family's measure (zswarm.families.measure): of each draw's truth at every sample, or of the estimates on a
    # shared truth at the agents' common ticks or at each draw's own stamps.
    make = declared.truth if not shared else declared.stamps if per_draw else declared.ticks
    assert make is not None  # problem() refused a family without it
    measure: Any = make(Context(sc, M, duration, sample_dt, n_samples, tick_every, grid_s, rows, stamps))
    # The packet fields with a draw axis (each draw's own noise: _measure_draws), on a shared truth
    drawn = frozenset(f for f, nz in (("gyro", "gyro"), ("bearings", "bearing"), ("rel_att", "rel_att"), ("velocity", "velocity"), ("attitude", "attitude")) if per_draw_noise and not one_noise and std[nz][0] > 0)
    truths: dict[int, Any] = {}  # with a sensor delay on a shared truth: sample -> the truth there (what an estimate stamped then is measured on)
    edge_messages = commands = 0
    jumps = np.zeros(M, dtype=np.int64)
    agent_jumps = np.zeros(M, dtype=np.int64)
    started = False
    last = 0.0
    steps = 0
    for k in range(n_samples):
        t = k * sample_dt  # as World.next_time computes it
        tick = k % tick_every == 0
        sensed: dict[int, dict[str, Any]] = {}
        if sensing is not None:
            # World.sample: the motion planned ahead, advanced, measured by the world's sensors.
            if t > plant.planned_through():
                plant.plan(np.arange(k, k + PLAN_SAMPLES) * sample_dt)
            plant.advance_to(t)
            R = plant.R
            V = plant.velocity() if sc.moving else None
            if per_draw_noise:  # each draw's own noise: the noisy fields get a draw axis
                B = sensing.bearings(R, plant.p)
                W = plant.omega_now()
                measured = {i: _measure_draws(sensing, i, noise[i].next(), R, plant.p, W, V, B) for i in ids}
            else:
                measured = sensing.measure(R, plant.p, plant.omega_now(), V)
            for i, m in measured.items():
                m["t"] = t
                if per_draw:
                    store[i][k] = _with_draws(m, M, drawn)
                elif sensor_links is None:
                    packets[i].append(m)
                else:
                    store[i][k] = m
                sensed[i] = m
            if sensor_links is not None:
                sensor_links.offer(k, t)
                truths[k] = SimpleNamespace(R=plant.R.copy(), p=plant.p.copy())
            if per_draw:
                truths[k] = (plant.R.copy(), plant.p.copy())
                for dl in draw_links.values():
                    dl.offer(k, t)
        else:
            plant.advance_to(t)
            R = plant.R.reshape(M, n, 3, 3)
            W = plant.omega_now().reshape(M, n, 3)
            measure.sample(k, t, Truth(R, W))
            RT = np.swapaxes(R, -1, -2)
            # Measured as World.sample does.  Every sample goes into the histories, as an agent's inbox
            # keeps them; the rest is measured at the agents' ticks only (a relative attitude is M
            # products, at 200 Hz for 100 Hz agents).  With a sensor delay every sample is measured
            # in full and kept (store) until the ticks that deliver and read it.
            for i in ids:
                a = col[i]
                need = want[i] if tick or sensor_links is not None or per_draw else histories[i].keys()
                # The world's noise, drawn at every sample in its order (gyro, then rel_att per neighbour,
                # then attitude) from its generator per agent and seed (_Noise).
                nz = noise[i].next()
                n_gyro, n_att = nz.get("gyro", [None])[0], nz.get("attitude", [None])[0]
                n_rel = dict(zip(nbrs[i], nz["rel_att"], strict=True)) if "rel_att" in nz else None
                sense: dict[str, Any] = {"t": t}
                if "gyro" in need:
                    sense["gyro"] = W[:, a] + bias[a] if n_gyro is None else W[:, a] + bias[a] + n_gyro
                if "rel_att" in need:
                    sense["rel_att"] = {j: mul(RT[:, a], R[:, col[j]]) for j in nbrs[i]}
                    if n_rel is not None:
                        sense["rel_att"] = {j: mul(R_ij, exp(n_rel[j])) for j, R_ij in sense["rel_att"].items()}
                if "attitude" in need:
                    sense["attitude"] = R[:, a] if n_att is None else mul(R[:, a], exp(n_att))
                if sensor_links is None and not per_draw:
                    for f, hist in histories[i].items():
                        hist.append((t, sense[f].copy()))
                else:
                    if "attitude" in sense:
                        sense["attitude"] = sense["attitude"].copy()
                    store[i][k] = sense
                sensed[i] = sense
            if sensor_links is not None:
                sensor_links.offer(k, t)
            for dl in draw_links.values():
                dl.offer(k, t)
        if not tick:
            continue
        estimates: dict[int, Mapping[str, Any]] = {}
        t_tick = (k // tick_every) * period  # the agents' clock at this tick (AgentClock): the links' send and release times
        if per_draw:
            assert draw_inbox is not None
            draw_inbox.now = t_tick
            estimated: dict[int, Published] = {}
            for i in ids:
                if shared:
                    estimated[i] = Published(M, measure.fields)
                _tick_draws(i, col[i], t_tick, n_tick, draw_links[i], store[i], views[i], modules[i], gains[i], parts[i], states, hybrid, jumps, agent_jumps, draw_inbox, torques.u.reshape(M, n, 3) if cmd_links is None else cmd_links, draw_edges, draw_commands, estimated.get(i))
            n_tick += 1
            if shared:
                measure.tick(truths, estimated)  # each draw's estimates on the truth at their stamps
            lo_all = k
            for i in ids:  # the samples no later tick reads
                lo = draw_links[i].oldest_needed()
                draw_links[i].trim(lo)
                _drop_before(store[i], lo)
                lo_all = min(lo_all, lo)
            _drop_before(truths, lo_all)  # a later estimate is stamped at a packet a later step reads
            if progress is not None and k % int(sc.sensor_rate) == 0:
                progress(t)
            continue
        if sensor_links is None:
            mode, ends = ("steps" if started else "first"), [(t, k)]
        else:
            for t_p, k_p in sensor_links.deliver(t_tick):  # what the agents' inboxes hold from now on
                for i in ids:
                    if shared:
                        packets[i].append(store[i][k_p])
                    for f, hist in histories[i].items():
                        hist.append((t_p, store[i][k_p][f]))
            if sensor_links.packets:  # the oldest packet a step may still read: the older ones go
                lo = sensor_links.packets[0][1]
                for i in ids:
                    _drop_before(store[i], lo)
                _drop_before(truths, lo)
            mode, ends = sensor_links.plan(t_tick)
            if mode in ("none", "idle"):  # nothing measured yet, or nothing newer: no step, nothing sent (AgentNode.tick)
                continue
        for i in ids:
            a = col[i]
            v, mod, g, part = views[i], modules[i], gains[i], parts[i]
            outputs = None
            if mode == "first":
                t_e, k_e = ends[0]
                v.begin(t_e, sensed[i] if sensor_links is None else store[i][k_e], first=True)
                if sensor_links is not None:
                    v.command_lead = max(0.0, t_tick - t_e) + 0.5 * v.period  # AgentNode._begin
                if hybrid and part is not None:  # the jump sets on the initial state; the outputs are not sent (AgentNode._advance)
                    v.dt = 0.0
                    _step(part, states, i, v, g, 0.0, jumps, agent_jumps)
                if sensor_links is not None and part is not None and 0.0 < t_e <= 0.5:
                    v.dt = t_e  # the initial estimate (at t = 0) brought to the first packet: prediction only (no neighbours)
                    _step(part, states, i, v, g, t_e, jumps, agent_jumps)
            else:
                prev = last
                for n_e, (t_e, k_e) in enumerate(ends, 1):
                    v.begin(t_e, sensed[i] if sensor_links is None else store[i][k_e], first=False)
                    if sensor_links is None:
                        v.command_lead = 0.5 * v.period
                    else:  # only the last step's command is sent (AgentNode._advance): a catch-up step's has no lead
                        v.command_lead = max(0.0, t_tick - t_e) + 0.5 * v.period if n_e == len(ends) else 0.0
                    v.dt = t_e - prev
                    if part is not None:
                        if edge_links is None:
                            outputs = _step(part, states, i, v, g, t_e - prev, jumps, agent_jumps) or outputs
                        else:
                            reads = edge_links.read(i, t_tick)
                            outputs = _step_groups(part, states, i, v, g, t_e - prev, jumps, agent_jumps, reads, edge_links.stale_terms[i])
                    prev = t_e
            pub = mod.publish(states[i], outputs, v)
            if pub is None:
                continue
            seq = published[i]
            published[i] += 1
            edge_messages += len(pub.edges)
            commands += pub.command is not None
            t_stamp = v.t_world if pub.t is None else pub.t
            if pub.command is not None and "tau" in pub.command:
                if cmd_links is None:
                    torques.u.reshape(M, n, 3)[:, a] = pub.command["tau"]
                else:
                    cmd_links.send(a, t_tick, t_stamp, pub.command["tau"])  # arrives at the tick, as the world stamps it
            for j, fields in pub.edges.items():
                if edge_links is None:
                    box = inboxes[j].get(i)
                    if box is None:
                        box = inboxes[j][i] = deque(maxlen=RECENT_EDGE_MESSAGES)
                    box.append((dict(fields), t_stamp))
                else:
                    edge_links.send(i, j, seq, t_stamp, t_tick, dict(fields))
            estimates[i] = pub.estimate
        if shared:
            measure.tick(plant if sensor_links is None else truths[ends[-1][1]], estimates)  # the truth at the estimates' stamp
        if started:
            steps += 1
        started, last = True, ends[-1][0]
        if progress is not None and k % int(sc.sensor_rate) == 0:
            progress(t)
    res: Result = measure.result(Result(np.zeros(0), np.zeros((M, 0)), jumps, agent_jumps, steps, edge_messages=edge_messages, commands=commands, command_links=cmd_links, edge_links=edge_links, t_end=(n_samples - 1) * sample_dt))
    if per_draw:
        assert draw_inbox is not None
        res.draw_edge_messages, res.draw_commands = draw_edges, draw_commands
        res.edge_messages, res.commands = int(draw_edges.max()), int(draw_commands.max())
        res.sensor_dropped = np.sum([dl.dropped() for dl in draw_links.values()], axis=0)
        res.stale_terms = np.sum(list(draw_inbox.stale_terms.values()), axis=0)
        if draw_inbox.links:
            res.edge_links = draw_inbox  # the receivers' counters per draw (link_counters)
    return res


def _drop_before(by_sample: dict[int, Any], lo: int) -> None:
    """Forget the samples before ``lo`` (keys inserted in sample order)."""
    while by_sample and next(iter(by_sample)) < lo:
        del by_sample[next(iter(by_sample))]


def _tick_draws(
    i: int,
    a: int,
    t_tick: float,
    n_tick: int,
    links: _DrawSensorLinks,
    store: Mapping[int, dict[str, Any]],
    v: BatchedView,
    mod: ModuleType,
    g: Any,
    part: Any,
    states: dict[int, Any],
    hybrid: bool,
    jumps: np.ndarray,
    agent_jumps: np.ndarray,
    inbox: batched_links.DrawInbox,
    u: np.ndarray | batched_links.Commands,
    sent_edges: np.ndarray,
    sent_commands: np.ndarray,
    published: Published | None = None,
) -> None:
    """Agent i's tick at ``t_tick`` in M draws whose sensor links lose and delay packets each its
    own way (_DrawSensorLinks): each draw takes its steps (AgentNode.tick and _advance) on its
    own packets and history, reads its neighbours' messages stamped at or before each step
    (DrawInbox), and after its last step sends what it publishes, stamped with that step's
    time; idle draws send nothing.  ``u``: the torques the plant holds, (M, n, 3), or the
    command links (each draw's agent sends its own commands: Commands.send with rows).

    The draws' n-th steps are stepped together where they share what the law takes as one
    value (the step's start and end, its packet, whether it is the tick's last: dt, t and the
    command lead), on a sub-stack of those draws only (:func:`_take`, :func:`_put`); a step
    whose law reads the sensor history is stepped apart for each history the draws hold."""
    links.deliver(t_tick)
    plans = links.plan(t_tick)
    merged: dict[tuple[Any, ...], list[int]] = {}
    for n_p, (mode, _G, t_step, ends, held) in enumerate(plans):
        prev = t_step
        for r, (t_e, k_e) in enumerate(ends):
            # A step between packets reads the history (View.relative_attitude): by history at once
            apart = tuple(held) if t_e != k_e * links.sample_dt else ()
            merged.setdefault((mode, prev, t_e, k_e, r == len(ends) - 1, apart), []).append(n_p)
            prev = t_e
    # In the order of their ends: a draw's steps end later and later, so each step comes after
    # the draw's step before it, whichever of its tick's steps it is.
    c = _AgentTick(i, a, t_tick, n_tick, store, v, mod, g, part, states, hybrid, jumps, agent_jumps, inbox, u, sent_edges, sent_commands, published, links=links)
    for (mode, prev, t_e, k_e, last, _), members in sorted(merged.items(), key=lambda kv: (kv[0][2], kv[0][1])):
        _round_apart(c, [plans[n_p] for n_p in members], mode, prev, t_e, k_e, last)


def _round_apart(c: _AgentTick, plans: Sequence[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]], mode: str, prev: float, t_e: float, k_e: int, last: bool) -> None:
    """_round_step on the draws of ``plans``; where a read of the sensor history needs them
    apart (HistorySplit, raised before the step changes anything), per history, and where
    the draws of one plan still differ (a shared truth's deeper histories, _Deep), draw by draw."""
    histories = {tuple(p[4]) for p in plans}
    try:
        _round_step(c, plans, mode, prev, t_e, k_e, last, len(histories) > 1)
    except HistorySplit:
        if len(histories) > 1:
            for h in histories:
                _round_apart(c, [p for p in plans if tuple(p[4]) == h], mode, prev, t_e, k_e, last)
        else:
            for d in np.flatnonzero(np.logical_or.reduce([p[1] for p in plans])):
                one = np.zeros_like(plans[0][1])
                one[d] = True
                src = next(p for p in plans if p[1][d])
                _round_step(c, [(src[0], one, src[2], src[3], src[4])], mode, prev, t_e, k_e, last, False)


@dataclass(slots=True)
class _AgentTick:
    """What agent i's steps of one tick read and write (_tick_draws' arguments), and ``done``:
    this tick's outputs so far, (draws, their sub-stack's outputs, its rows)."""

    i: int
    a: int
    t_tick: float
    n_tick: int
    store: Mapping[int, dict[str, Any]]
    v: BatchedView
    mod: ModuleType
    g: Any
    part: Any
    states: dict[int, Any]
    hybrid: bool
    jumps: np.ndarray
    agent_jumps: np.ndarray
    inbox: batched_links.DrawInbox
    u: np.ndarray | batched_links.Commands
    sent_edges: np.ndarray
    sent_commands: np.ndarray
    published: Published | None  # on a shared truth: the estimates the draws publish, for its measure
    links: _DrawSensorLinks | None = None  # the agent's sensor link (its draws' inboxes: _Deep)
    done: list[tuple[np.ndarray, Any, int]] = dataclasses.field(default_factory=list)


def _round_step(c: _AgentTick, plans: Sequence[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]], mode: str, prev: float, t_e: float, k_e: int, last: bool, mixed: bool) -> None:
    """One step, from ``prev`` to the packet ``k_e`` at ``t_e``, of the draws of ``plans``
    (_tick_draws); ``last``: their tick's last, after which they publish.  ``mixed``: the draws
    hold different histories (reading it raises HistorySplit)."""
    i, v, states, inbox, part = c.i, c.v, c.states, c.inbox, c.part
    M = len(c.jumps)
    idx = np.flatnonzero(np.logical_or.reduce([p[1] for p in plans]))
    whole = len(idx) == M
    rows = idx if whole else _sub_rows(idx)
    m, n = len(rows), len(idx)
    sub = {i: states[i] if whole else _take(states[i], rows, M)}
    g_sub = c.g if whole else _take_gains(c.g, rows, M)
    sub_jumps, sub_agent, stale = np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.int64)
    _point_view(c, [tuple(p[4]) for p in plans], t_e, k_e, mode == "first", None if whole else rows, mixed)
    out = None
    try:
        if mode == "first":
            v.command_lead = max(0.0, c.t_tick - t_e) + 0.5 * v.period  # AgentNode._begin
            if part is not None:
                reads = inbox.read(i, t_e, rows)  # heard_all: what has come (neighbor() reads nothing at the first step)
                if c.hybrid:  # the jump sets on the initial state; the outputs are not sent (AgentNode._advance)
                    v.dt = 0.0
                    _step_groups(part, sub, i, v, g_sub, 0.0, sub_jumps, sub_agent, reads, stale)
                if 0.0 < t_e <= 0.5:
                    v.dt = t_e  # the initial estimate (at t = 0) brought to the first packet: prediction only
                    _step_groups(part, sub, i, v, g_sub, t_e, sub_jumps, sub_agent, reads, stale)
        else:
            # only the last step's command is sent (AgentNode._advance): a catch-up step's has no lead
            v.command_lead = max(0.0, c.t_tick - t_e) + 0.5 * v.period if last else 0.0
            v.dt = t_e - prev
            if part is not None:
                out = _step_groups(part, sub, i, v, g_sub, t_e - prev, sub_jumps, sub_agent, inbox.read(i, t_e, rows), stale)
        c.jumps[idx] += sub_jumps[:n]
        c.agent_jumps[idx] += sub_agent[:n]
        inbox.stale_terms[i][idx] += stale[:n]
        states[i] = sub[i] if whole else _put(states[i], sub[i], idx, M, m)
        if out is not None:
            c.done.append((idx, out, m))
        if not last:
            return
        if out is None and mode != "first":
            # No outputs at this step: the newest of an earlier step this tick, per draw (else None)
            had = np.zeros(M, dtype=bool)
            for d, _, _ in c.done:
                had[d] = True
            if had[idx].any():
                for part_idx in (idx[had[idx]], idx[~had[idx]]):
                    if part_idx.size:
                        _publish_apart(c, part_idx, c.done if had[part_idx[0]] else [], plans, t_e, k_e)
                return
        try:
            pub = c.mod.publish(sub[i], out, v)  # publish reads the view too (a bearing at a stamp)
        except HistorySplit:  # ... in a history the draws do not share: published apart, per history
            _publish_apart(c, idx, c.done if out is not None else [], plans, t_e, k_e)
            return
        _send(c, idx, m, pub)
    finally:
        v._packets = v.history = v.mixed = v.deep = None


def _point_view(c: _AgentTick, held: list[tuple[int, ...]], t_e: float, k_e: int, first: bool, rows: np.ndarray | None, mixed: bool) -> None:
    """Point the view at a step ending at ``t_e`` on the packet ``k_e`` for the draws ``rows``
    (a sub-stack's; None: all), their sensor history the samples ``held`` (each plan's; more
    than one: ``mixed``, read as one where they agree)."""
    store, M = c.store, len(c.jumps)

    def take(k: int) -> dict[str, Any]:
        return store[k] if rows is None else _take(store[k], rows, M)

    def history() -> deque[dict[str, Any]]:
        # The draws' inbox history (the packets from the one at or before their tick's first step on)
        if mixed:
            raise HistorySplit
        return deque(take(k) for k in held[0])

    c.v.begin(t_e, take(k_e), first=first)
    c.v._packets, c.v.history = None, history
    if c.links is not None and c.links.deep:  # each draw its own last HISTORY packets (_Deep)
        deep = _Deep(c.links, np.arange(M) if rows is None else rows, store, M)
        c.v.deep = deep
        c.v.history = deep.history
    elif mixed:
        c.v.mixed = (held, store.__getitem__, lambda ks: [take(k) for k in ks])


def _publish_apart(c: _AgentTick, idx: np.ndarray, done: list[tuple[np.ndarray, Any, int]], plans: Sequence[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]], t_e: float, k_e: int) -> None:
    """_publish_rows for the draws ``idx``: together, else (HistorySplit: publish read a history
    they do not share, before sending anything) per history, else draw by draw."""
    mine = [p for p in plans if p[1][idx].any()]
    histories = {tuple(p[4]) for p in mine}
    try:
        _publish_rows(c, idx, done, mine, t_e, k_e, len(histories) > 1)
    except HistorySplit:
        if len(histories) > 1:
            for h in histories:
                group = [p for p in mine if tuple(p[4]) == h]
                sub = idx[np.logical_or.reduce([p[1] for p in group])[idx]]
                _publish_apart(c, sub, done, group, t_e, k_e)
        else:
            for d in idx:
                _publish_rows(c, np.array([d]), done, mine, t_e, k_e, False)


def _publish_rows(c: _AgentTick, idx: np.ndarray, done: list[tuple[np.ndarray, Any, int]], plans: Sequence[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]], t_e: float, k_e: int, mixed: bool) -> None:
    """Publish for the draws ``idx`` (of the step of ``plans`` ending at ``t_e``) from their
    state, with their newest outputs of this tick (``done``, oldest first; none: None), the
    view pointed at their rows."""
    M = len(c.jumps)
    rows = _sub_rows(idx)
    outputs = None
    for d, out, m in done:
        outputs = _spread(out, d, M, m) if outputs is None else _put(outputs, out, d, M, m)
    sub_out = None if outputs is None else _take(outputs, rows, M)
    mine = [p for p in plans if p[1][idx].any()]
    _point_view(c, [tuple(p[4]) for p in mine], t_e, k_e, False, rows, mixed and len({tuple(p[4]) for p in mine}) > 1)
    _send(c, idx, len(rows), c.mod.publish(_take(c.states[c.i], rows, M), sub_out, c.v))


def _send(c: _AgentTick, idx: np.ndarray, m: int, pub: Any) -> None:
    """What the draws ``idx`` publish (a sub-stack of ``m`` rows): their messages into the
    inbox stamped with the step's time, their torques into the plant's (``u``, (M, n, 3)) or
    onto their command links (each draw its own next command: Commands.send)."""
    if pub is None:
        return
    t_stamp = c.v.t_world if pub.t is None else pub.t
    c.sent_edges[idx] += len(pub.edges)
    if pub.command is not None:
        c.sent_commands[idx] += 1
        if "tau" in pub.command:
            tau = np.broadcast_to(np.asarray(pub.command["tau"], dtype=float), (m, 3))[: len(idx)]
            if isinstance(c.u, batched_links.Commands):
                c.u.send(c.a, c.t_tick, t_stamp, tau, idx)  # arrives at the tick, as the world stamps it
            else:
                c.u[idx, c.a] = tau
    for j, fields in pub.edges.items():
        c.inbox.send(c.i, j, idx, t_stamp, fields, c.n_tick, m, c.t_tick)
    if c.published is not None and pub.estimate is not None:
        c.published.put(idx, t_stamp, pub.estimate, m)


def _take_gains(g: Any, rows: np.ndarray, M: int) -> Any:
    """The Gains of a sub-stack: the gains stacked per draw (draw_gains: (M, 1)) gathered."""
    per = {f.name: getattr(g, f.name)[rows] for f in dataclasses.fields(g) if isinstance(getattr(g, f.name), np.ndarray) and getattr(g, f.name).shape == (M, 1)}
    return dataclasses.replace(g, **per) if per else g


def _step(part: Any, states: dict[int, Any], i: int, view: BatchedView, gains: Any, dt: float, jumps: np.ndarray, agent_jumps: np.ndarray) -> Any:
    inputs = part.inputs(view, gains)
    if inputs is None:
        return None
    states[i], outputs = part.step(states[i], inputs, dt, gains)
    _count_jumps(outputs, jumps, agent_jumps, np.ones(len(jumps), dtype=bool))
    return outputs


def _count_jumps(outputs: Any, jumps: np.ndarray, agent_jumps: np.ndarray, G: np.ndarray) -> None:
    """Count a step's jumps (``outputs.jumps``: ξ_k, ``outputs.agent_jumps``: the agents' own) in
    the draws of ``G``: a jump's value after is finite in the draws that jumped (NaN elsewhere)."""
    for _k, _before, after in getattr(outputs, "jumps", ()):
        jumps += (np.isfinite(np.asarray(after, dtype=float)).reshape(jumps.shape) if np.ndim(after) else True) & G
    for _before, after in getattr(outputs, "agent_jumps", ()):
        agent_jumps += (np.isfinite(np.asarray(after, dtype=float)).reshape(agent_jumps.shape) if np.ndim(after) else True) & G


def _step_groups(part: Any, states: dict[int, Any], i: int, view: BatchedView, gains: Any, dt: float, jumps: np.ndarray, agent_jumps: np.ndarray, reads: Mapping[int, batched_links.Read], stale_terms: np.ndarray, base: np.ndarray | None = None) -> Any:
    """One step of agent i's draws over emulated links: the draws differ in which neighbours'
    messages they hold (lost, late, stale) and in those messages' stamps, so they are stepped in
    groups that share what the law reads: which in-neighbours are present (and heard from at
    all), and, where a law reads a neighbour's stamp or age (batched_links.Split), that stamp.
    Each group is stepped on the whole stack (every draw's own message, the others' filled in)
    and its draws' results kept; one group when every draw holds the same, as on perfect links.
    ``base``: only these draws step (the others keep their state: _DrawSensorLinks' plans)."""
    M = len(jumps)
    base = np.ones(M, dtype=bool) if base is None else base
    key = np.stack([np.stack([r.present, r.has]) for r in reads.values()]).reshape(-1, M).T if reads else None
    if key is not None and not (key[base] == key[base][0]).all():
        _, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        queue = [G for G in (base & (inv == u) for u in range(int(inv.max()) + 1)) if G.any()]
    else:
        queue = [base]
    s0 = states[i]
    state, outputs, nones = s0, None, np.zeros(M, dtype=bool)
    try:
        while queue:
            G = queue.pop()
            view.group, view.read_js = (reads, G), set()
            view._cache.clear()
            try:
                inputs = part.inputs(view, gains)
                st, out = (s0, None) if inputs is None else part.step(s0, inputs, dt, gains)
            except batched_links.Split as sp:
                stamp = reads[sp.j].stamp
                queue += [G & (stamp == u) for u in np.unique(stamp[G])]
                continue
            for j in view.read_js:
                r = reads[j]
                stale_terms += G & r.has & r.stale
            every = G is base and bool(base.all())  # one group of every draw: its results whole
            state = st if every else _where(G, st, state, M)
            if out is None:
                nones |= G
                continue
            outputs = out if outputs is None or every else _where(G, out, outputs, M)
            _count_jumps(out, jumps, agent_jumps, G)
    finally:
        view.group = None
        view._cache.clear()
    if outputs is not None and (nones & base).any():
        raise Unsupported(f"agent {i}: its law had inputs in some draws and none in others at one tick (the batched engine cannot publish both)")
    states[i] = state
    return outputs


# A sub-stack has at least this many rows (a group's draws, then copies of its first): its draw
# axis is then never one of a law's own small axes (3-vectors, quaternions) when it is read back.
SUB_ROWS = 16


def _sub_rows(idx: np.ndarray) -> np.ndarray:
    """The rows of a group's sub-stack: its draws ``idx``, padded to SUB_ROWS with the first."""
    return idx if len(idx) >= SUB_ROWS else np.concatenate([idx, np.full(SUB_ROWS - len(idx), idx[0])])


def _take(x: Any, rows: np.ndarray, M: int) -> Any:
    """The draws ``rows`` of ``x`` (M draws), through dataclasses, mappings and tuples: every
    array with the leading draw axis (shape[0] == M, as :func:`_where` and :func:`stack`) gathered;
    what has no draw axis is the same in every draw and kept."""
    if type(x) is np.ndarray:
        return x[rows] if x.ndim and x.shape[0] == M else x
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return dataclasses.replace(x, **{f.name: _take(getattr(x, f.name), rows, M) for f in dataclasses.fields(x) if f.init})
    if isinstance(x, Mapping):
        return {k: _take(v, rows, M) for k, v in x.items()}
    if isinstance(x, tuple | list):
        return type(x)(_take(v, rows, M) for v in x)
    if isinstance(x, np.ndarray) and x.ndim >= 1 and x.shape[0] == M:
        return x[rows]
    return x


def _put(full: Any, sub: Any, idx: np.ndarray, M: int, m: int) -> Any:
    """``full`` (M draws) with its draws ``idx`` replaced by the first ``len(idx)`` rows of
    ``sub``, a sub-stack of ``m`` rows (:func:`_sub_rows`) stepped from ``_take(full, rows)``.
    What the step created (a mapping's new key, a value that was None) is spread to every draw
    from the group's rows (the others' values are valid numbers no later step of theirs reads
    before setting its own: as :func:`_where` keeps ``a`` where ``b`` lacks it); a value
    without a draw axis that now differs between draws gets one."""
    if full is sub:
        return full
    if type(sub) is np.ndarray and type(full) is np.ndarray and sub.ndim and full.ndim and sub.shape[0] == m and full.shape == (M, *sub.shape[1:]):
        out = full.astype(np.result_type(full, sub), copy=True)  # the common case: per draw, in both
        out[idx] = sub[: len(idx)]
        return out
    if _kind(full) != _kind(sub):  # e.g. None before the first step
        return _spread(sub, idx, M, m)
    if dataclasses.is_dataclass(sub) and not isinstance(sub, type):
        return dataclasses.replace(full, **{f.name: _put(getattr(full, f.name), getattr(sub, f.name), idx, M, m) for f in dataclasses.fields(sub) if f.init})
    if isinstance(sub, Mapping):
        return {k: (_put(full[k], v, idx, M, m) if k in full else _spread(v, idx, M, m)) for k, v in sub.items()}
    if isinstance(sub, tuple | list):
        if len(sub) != len(full):
            return full  # e.g. the jump events of one group's step: counted per group, not merged (_where)
        return type(sub)(_put(f, s, idx, M, m) for f, s in zip(full, sub, strict=True))
    n = len(idx)
    if isinstance(sub, np.ndarray) and sub.ndim >= 1 and sub.shape[0] == m:  # per draw
        inner, part = sub.shape[1:], sub[:n]
    else:  # the same in every draw of the group
        if isinstance(full, np.ndarray) and full.ndim >= 1 and full.shape[0] == M and full.shape[1:] == np.shape(sub):
            inner, part = np.shape(sub), sub
        elif _same(full, sub):
            return sub
        else:
            inner, part = np.shape(sub), sub
    if isinstance(full, np.ndarray) and full.shape == (M, *inner):
        out = full.astype(np.result_type(full, part), copy=True)
    elif np.shape(full) == inner:
        out = np.empty((M, *inner), dtype=np.result_type(full, part))
        out[...] = full
    else:
        return _spread(sub, idx, M, m)
    out[idx] = part
    return out


def _kind(x: Any) -> Any:
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return type(x)
    if isinstance(x, Mapping):
        return Mapping
    if isinstance(x, tuple | list):
        return tuple
    return "number" if isinstance(x, np.ndarray | float | int | np.number) else type(x)


def _spread(sub: Any, idx: np.ndarray, M: int, m: int) -> Any:
    """A sub-stack's value for all M draws: draw ``idx[r]`` gets row r, every other draw row 0."""
    where = np.zeros(M, dtype=np.int64)
    where[idx] = np.arange(len(idx))
    return _take(sub, where, m)


def _where(G: np.ndarray, a: Any, b: Any, M: int) -> Any:
    """``a`` in the draws of ``G``, ``b`` in the others, through dataclasses, mappings and tuples;
    an array without the draw axis is the same in every group (no draw's data went into it)."""
    if a is b:
        return a
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return dataclasses.replace(a, **{f.name: _where(G, getattr(a, f.name), getattr(b, f.name), M) for f in dataclasses.fields(a) if f.init})
    if isinstance(a, Mapping):
        return {k: _where(G, v, b[k], M) if k in b else v for k, v in a.items()}
    if isinstance(a, tuple | list):
        if len(a) != len(b):
            return b  # e.g. the jump events of one group's step: counted per group, not merged
        return type(a)(_where(G, x, y, M) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray) and a.ndim >= 1 and a.shape[0] == M:
        return np.where(G.reshape((M,) + (1,) * (a.ndim - 1)), a, b)
    return a
