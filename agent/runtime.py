"""The agent runtime: own clock, inbox of the newest data, step, publish.

:class:`AgentNode` is engine-agnostic: ``zswarm sim`` calls :meth:`tick` at
virtual times, ``python -m agent`` from a real-time loop (:func:`run_realtime`).
Bus callbacks only decode, validate, count and store the newest message per
source; all the math happens in :meth:`tick`.

The runtime knows no algorithm: it reads the algorithm's declaration
(:class:`zswarm.scenario.algorithm.AlgorithmSpec`), serves each part's ``inputs`` a
:class:`TickView` (newest data, their ages, the timing library on this
agent's histories), steps the parts that are due, and publishes what the
algorithm's ``publish`` returns.
"""

from __future__ import annotations

import logging
import math
import statistics
import time
from collections import deque
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

import numpy as np

from agent.inbox import MAX_NEIGHBOR_EVENTS, Inbox, step_ends

# An in-neighbour whose token is up but whose newest message is stamped more than this long
# ago (world time; or SILENT_PERIODS of this agent's own period, if longer) is lost
# (AgentNode.check_silent): 200 ticks at 100 Hz, far beyond a dropout of 0.5 or a delay of
# a few hundred ms, short beside a run.  Only told (log, stats events); the stale policy
# deals with old data as before.
SILENT_S = 2.0
SILENT_PERIODS = 20
from agent.tick_view import TickView
from zswarm.math.kernels import finite_f8
from zswarm.scenario.algorithm import AlgorithmSpec, Part, Publish, jumps
from zswarm.scenario.clock import AgentClock
from zswarm.scenario.links import LinkModel
from zswarm.scenario.programs import AgentProgram
from zswarm.transport import keys, wire
from zswarm.transport.bus import Bus

log = logging.getLogger("zswarm.agent")


_EYE3 = np.eye(3)
_EYE3.flags.writeable = False


def _edge_link(key: str) -> str | None:
    """``"j->i"`` of an edge key (keys.parse), else None."""
    k = keys.parse(key)
    return f"{k.src}->{k.dst}" if k is not None and k.kind == "edge" else None


def _edge_links(agent_id: int, neighbors: tuple[int, ...]) -> Callable[[str], str | None]:
    """The link of an edge key into ``agent_id``, or None unless it comes from one of its
    in-neighbours: any ``edge/<anything>/<i>`` used to be a link of its own (20 000 junk
    keys made 20 000 link counters and stored messages)."""
    links = {f"{j}->{agent_id}" for j in neighbors}
    known: dict[str, str] = {}  # key -> its link, for the in-neighbours' keys only (at most one each)

    def link_of(key: str) -> str | None:
        # Per message: the parse (keys.parse, ~2.6 µs) once per in-neighbour's key, then a lookup.
        link = known.get(key)
        if link is None:
            link = _edge_link(key)
            if link not in links:
                return None
            known[key] = link
        return link

    return link_of


def _finite_estimate(e: Mapping[str, Any]) -> bool:
    """Every number of an estimate (R_hat, p_hat, and the arrays and numbers it reports) finite."""
    for v in e.values():
        if isinstance(v, np.ndarray):
            ok = finite_f8(v) if finite_f8 is not None else None  # a float64 array in C (3.5 -> 0.3 µs)
            if ok is False or (ok is None and not np.isfinite(v).all()):
                return False
        elif isinstance(v, float):
            if not math.isfinite(v):
                return False
        elif isinstance(v, Mapping) and not _finite_estimate(v):
            return False
    return True


def _edge_sender(link: str) -> int:
    """The src an edge message on ``link`` ("j->i") must carry: j's own id."""
    return int(link.split("->", 1)[0])




class _PartState:
    """A part's schedule: when it last stepped (own clock) and how long it waits between steps."""

    __slots__ = ("part", "rate", "last", "min_gap", "steps", "t_first")

    def __init__(self, part: Part, clock_rate: float, scale: float = 1.0) -> None:
        self.part = part
        self.rate = part.rate * scale if part.rate is not None else None  # Hz (AgentProgram.part_rate_scale)
        self.last = 0.0
        self.steps = 0  # steps taken after the first tick (the achieved rate, in the stats)
        self.t_first: float | None = None
        # A part with its own rate steps when a step ends at least this long after
        # its last one: its period less half a clock period, so that step ends
        # jittered by the sensor grid do not make it skip a whole tick.  0: every step.
        self.min_gap = 1.0 / self.rate - 0.5 / clock_rate if self.rate is not None else 0.0


class AgentNode:
    """One agent: subscribes to its sensor key and in-edges, steps its algorithm on its own clock."""

    def __init__(self, program: AgentProgram, bus: Bus, run: str, now: Callable[[], float], inc: int = 0) -> None:
        """``program``: everything this agent runs on (zswarm.scenario.programs.agent_program)."""
        self.program = program
        agent_id = program.id
        self.inc = inc  # this process's incarnation, in every message it sends (wire.py)
        self.stale = program.stale
        self.stale_terms: dict[int, int] = {}  # per in-neighbour: terms evaluated on a message older than max_age
        self.id = agent_id
        self.run = run
        self.algo, self.gains, self.tree_edges = program.algorithm, program.gains, program.tree_edges
        self.aspec: AlgorithmSpec = program.spec
        self.state = self.algo.initial_state(program.initial, self.gains)
        self.parts = [_PartState(p, program.clock.rate, program.part_rate_scale) for p in self.aspec.parts]
        # Jumps of the hybrid variables SPEC.jumps declares, not yet published: (variable, "edge" |
        # "agent", its owner: edge k or this agent, t, before, after); counted per edge and own.
        self.jumps: list[tuple[str, str, int, float, float, float]] = []
        self.jump_count: dict[int, int] = {}
        self.agent_jump_count = 0
        self.estimate_edges = frozenset(k for k, o in program.spec.estimate.items() if o.kind == "edges")
        self.clock = AgentClock(program.clock, seed=program.clock_seed)
        self.out = program.out_neighbors
        links, seed = program.links, program.seed
        self.inbox = Inbox(
            f"zswarm.agent.{agent_id}",
            lambda: self.clock.local(now()),
            (lambda name: LinkModel(links[name], name, seed)) if links is not None else None,
        )
        sense_link = f"world->{agent_id}"
        bus.subscribe(keys.sense(run, agent_id), self.inbox.handler("sense", lambda k: sense_link, decode=wire.decoder("sense"), sender=lambda link: 0), direct=False)
        if program.neighbors:
            check_edge = self.aspec.check_edge
            handler = self.inbox.handler("edge", _edge_links(agent_id, program.neighbors), lambda m: check_edge(m.values), wire.decoder("edge"), sender=_edge_sender)
            bus.subscribe(keys.edges_into(run, agent_id), handler, direct=False)
        self.pub_edge = {i: bus.publisher(keys.edge(run, agent_id, i)) for i in self.out}
        # Detection: an in-neighbour whose liveliness token goes (its process died, or hung past
        # the 1 s lease) is marked lost at once; its terms are stale from then until its token
        # is back (the stale policy decides: "drop" leaves them out, "hold" keeps the last
        # message), and a restarted neighbour's first message is used at once (LinkCounter).
        self.lost: dict[int, float] = {}  # in-neighbour -> world time its token went (or it fell silent)
        self.silent: set[int] = set()  # in-neighbours lost to silence while their token was up (check_silent)
        self.neighbor_events: list[tuple[int, float, bool]] = []  # (j, world time, token up), the first MAX_NEIGHBOR_EVENTS
        self.pub_est = bus.publisher(keys.est(run, agent_id))
        self.pub_cmd = bus.publisher(keys.cmd(run, agent_id)) if self.aspec.command else None
        self.cmd_seq = 0
        self.sent = dict.fromkeys(self.out, 0)  # messages actually sent per out-edge (an algorithm may skip one)
        self.pub_stats = bus.publisher(keys.stats(run, "agent", agent_id))
        # The final counters are what the report's counts rest on (alive at the end, what
        # the recording lacks): sent once, on a publisher that waits rather than drops.
        self.pub_final = bus.publisher(keys.stats(run, "agent", agent_id), block=True)
        self.sense_link = sense_link
        self.view = TickView(self)
        self.seq = 0
        self.stats_seq = 0
        self.steps = 0
        self.missed = 0
        self.t_first: float | None = None
        self.t_last: float | None = None
        self.started = False
        self.catch_up_steps = 0  # steps beyond one per tick, taken to catch up after a late tick
        self.t_step = -math.inf  # own-clock time the state refers to (the last step's end)
        self.hybrid = jumps(self.aspec)  # a hybrid scheme: jump sets tested on the initial state (_advance)
        self.idle_ticks = 0  # ticks with no sensor packet newer than the last step
        self.step_failures = 0  # ticks whose step raised or gave a non-finite estimate (_step_failed)
        self.compute_s = 0.0
        self.compute_max = 0.0
        self._now = now
        # Own clock from a tick to its command's put, last 16 (0 in sim, whose ticks take no
        # time): the part of the command's way to the world that the sensors' transit lacks.
        self.send_delays: deque[float] = deque(maxlen=16)
        # Whether the run is over (set by ``python -m agent``): a neighbour's token going then is
        # its normal end, not a loss to warn of.
        self.run_over: Callable[[], bool] = lambda: False
        for j in program.neighbors:  # last: a MemoryBus calls back at once for tokens already up
            bus.watch_alive(keys.alive(run, "agent", j), partial(self._on_neighbor, j))

    def _on_neighbor(self, j: int, key: str, up: bool) -> None:
        """Liveliness of in-neighbour ``j`` (any thread): mark it lost or back."""
        t = self._now()
        if up:
            if self.lost.pop(j, None) is None:
                return  # its first appearance, not a return
            log.info("agent %d: in-neighbour %d is back at t = %.3f s", self.id, j, t)
        elif self.run_over():
            log.info("agent %d: in-neighbour %d left at the run's end (t = %.3f s)", self.id, j, t)
            return
        else:
            self.lost[j] = t
            log.warning("agent %d: in-neighbour %d lost (liveliness) at t = %.3f s", self.id, j, t)
        if len(self.neighbor_events) < MAX_NEIGHBOR_EVENTS:
            self.neighbor_events.append((j, t, up))

    # ------------------------------------------------------------------ the step

    def tick(self, t_world: float) -> None:
        """One tick at world time ``t_world`` (the agent reads its own clock from it).

        Steps end at measurements, not at the tick.  The state is brought to
        the newest sensor packet at or before the tick, and what is published
        is stamped with that packet's time, so the gyro, the bearings and the
        relative attitudes are measured up to the end of every step, never
        extrapolated.  Stepping to the tick instead meant integrating the gyro
        past its newest sample, which over Zenoh is 0–5 ms old (20–40 ms
        after a stall): each step added ½ω̇τ² of attitude error, about 1e-3 on
        the §3.2 run where ``sim`` (whose ticks and samples coincide) reaches
        1e-4, and the same ×10 in ``sim`` with a 10 ms sensor delay.

        A late tick (a stalled process, a missed deadline) catches up in steps
        of at most one period (:meth:`_step_ends`), each ending at a packet of
        the sensor history and seeing the data of its own time.  One long
        step would overshoot (gains × dt of order 1) and split into equal
        sub-steps on the newest data it paired a 12 ms old attitude with
        12 ms newer bearings: on the §3.3 run a 35 ms stall at t = 1 s left
        agent 4 (collinear neighbours, a weakly observable direction) a 4e-5
        attitude error for the rest of the run.  A tick with no packet newer
        than the last step neither steps nor publishes (counted as idle).
        """
        t_tick = self.clock.local(t_world)
        self.inbox.release_due()
        sense = self.inbox.get(self.sense_link)
        if sense is None:
            return  # nothing measured yet: no step, nothing to publish
        t_m = self.clock.local(sense.t)
        t_end = min(t_m, t_tick)
        if self.started and t_end <= self.t_step:
            self.idle_ticks += 1
            return
        c0 = time.perf_counter()
        good = self.state
        try:
            pub = self._advance(t_end, t_tick, sense)
            if pub is not None and not _finite_estimate(pub.estimate):
                raise FloatingPointError("a non-finite estimate")
        except Exception as exc:  # noqa: BLE001 - any failure of the algorithm's step: see _step_failed
            self._step_failed(good, exc, t_end)
            return
        if pub is None:
            return
        view = self.view
        self._send(pub, view.t_world, t_tick)
        c = time.perf_counter() - c0
        self.compute_s += c
        self.compute_max = max(self.compute_max, c)
        self.steps += 1
        if self.t_first is None:
            self.t_first = view.t_world
        self.t_last = view.t_world

    def _advance(self, t_end: float, t_tick: float, sense: dict[str, Any]) -> Publish | None:
        """Step the parts from the last step to ``t_end`` (the body of :meth:`tick`); what to publish."""
        view = self.view
        outputs: Any = None
        if not self.started:
            # The first step brings the initial estimate, which is at world time 0,
            # to the first measurement: over Zenoh that comes 1–20 ms after t = 0,
            # and taking the estimate as if it were at the tick shifts R̂_i by ω_i·τ
            # (0.07 rad for §4.5's agent 5 at 6.6 rad/s), enough to move the §4.5
            # start out of the hybrid jump set.  Prediction only: no neighbours.  A
            # process that joins more than 0.5 s late starts from its initial
            # estimate there instead.
            #
            # A hybrid scheme first tests its jump sets on the initial state, before any
            # flow (a step of length 0: no flow, then the jumps): a start inside the jump
            # sets jumps at t = 0, as the hybrid system does.  Testing them only at the end
            # of the first step let 10 ms of flow move a §5 start with ζ gaps of 1.7-12.4
            # (δ_Q̃ = 0.76) out of them first: 5 jumps fewer than an exact integration and
            # settle times 26-29 % early.  In sim the first tick is at t = 0 with the sample
            # of t = 0; over Zenoh at the first measurement, 1-20 ms later, with no flow yet.
            self.started = True
            lag = t_end - self.clock.local(0.0)
            transit = self._command_transit() if self.aspec.command else 0.0
            self._begin(t_end, sense, first=True, t_send=t_tick + transit)
            for ps in self.parts:
                ps.last = t_end
                if self.hybrid:
                    self._step_part(ps, 0.0)  # the jumps at the start (its outputs are not published)
                if 0.0 < lag <= 0.5:
                    self._step_part(ps, lag)  # its outputs (no neighbours) are not published
            self.t_step = t_end
        else:
            ends = self._step_ends(t_end)
            self.catch_up_steps += len(ends) - 1
            transit = self._command_transit() if self.aspec.command else 0.0
            for n, (t_e, packet) in enumerate(ends, 1):
                # Only the last step's command is sent: a catch-up step's torque is never held,
                # so it is evaluated at its own end (no lead, and no ξ flowed on ahead of it).
                self._begin(t_e, packet, first=False, t_send=t_tick + transit if n == len(ends) else None)
                for ps in self.parts:
                    if t_e - ps.last < ps.min_gap:
                        continue
                    dt, ps.last = t_e - ps.last, t_e
                    outputs = self._step_part(ps, dt) or outputs
                    ps.steps += 1
                    if ps.t_first is None:
                        ps.t_first = t_e
                self.t_step = t_e
        return self.algo.publish(self.state, outputs, view)

    def _step_failed(self, good: Any, exc: Exception, t_end: float) -> None:
        """A step raised or gave a non-finite estimate (a hostile but wire-valid measurement,
        e.g. a gyro of 1e200, used to kill the agent in ``so3.exp``): keep the last good
        state over the interval up to ``t_end`` (not stepped again: it would fail again),
        count it, log the first few, and go on with the next tick."""
        self.state = good
        self.t_step = max(self.t_step, t_end)
        for ps in self.parts:
            ps.last = max(ps.last, t_end)
        self.step_failures += 1
        if self.step_failures <= 3:
            log.warning("agent %d: a step failed (%s: %s); kept the last good state (%d so far)", self.id, type(exc).__name__, exc, self.step_failures)

    def _command_transit(self) -> float:
        """How long after its tick a command reaches the world (own clock): this agent's own
        delay from tick to put (measured) plus the sensor packets' transit (the same way back).
        §5.6 at time scale 0.5 with a core kept busy settled below 0.01 at 96 s (sim: 99 s);
        with the transit from the world's send instead (its lateness left out) 113 s, and
        without the agent's own delay as well 134 s."""
        own = statistics.median(self.send_delays) if self.send_delays else 0.0
        return own + self.inbox.sensor_transit(self.clock.local)

    def _begin(self, t_local: float, packet: dict[str, Any], first: bool, t_send: float | None = None) -> None:
        """Point the view at a step ending at ``t_local`` (own clock), with ``packet`` the
        newest sensor packet at or before it; ``t_send``: when what it sends should reach the
        world (own clock: the tick plus the network's transit)."""
        t_w = packet.t if self.clock.local(packet.t) == t_local else self.clock.world(t_local)
        self._count_stale()
        self.view.begin(t_local, t_w, packet, first)
        # A command is held from its arrival for one period: the middle of that hold, after
        # the step's end.  In sim (ticks at samples, no transit) exactly half a period; over
        # Zenoh the measurement is 0-5 ms old at the tick and the command 1-3 ms in transit,
        # which a controller that aimed at half a period would act that much late.
        self.view.command_lead = 0.0 if t_send is None else max(0.0, t_send - t_local) + 0.5 * self.view.period

    def _count_stale(self) -> None:
        """Count the in-neighbours the last step's view read stale (stats ``stale_terms``)."""
        for j in self.view.stale_read:
            self.stale_terms[j] = self.stale_terms.get(j, 0) + 1
        self.view.stale_read.clear()

    def _step_part(self, ps: _PartState, dt: float) -> Any:
        """Step one part by ``dt`` on the view as it stands; its outputs (None: it had no inputs)."""
        view = self.view
        view.dt = dt
        inputs = ps.part.inputs(view, self.gains)
        if inputs is None:
            return None
        self.state, outputs = ps.part.step(self.state, inputs, dt, self.gains)
        for attr, decl in self.aspec.jumps.items():
            for jump in getattr(outputs, attr, ()):
                if decl.owner == "edge":
                    k, before, after = jump
                    self.jump_count[k] = self.jump_count.get(k, 0) + 1
                else:
                    (before, after), k = jump, self.id
                    self.agent_jump_count += 1
                self.jumps.append((decl.variable, decl.owner, k, view.t_world, before, after))
        return outputs

    def _step_ends(self, t_end: float) -> list[tuple[float, dict[str, Any]]]:
        """Where the steps from the last one to ``t_end`` end (own clock), each with the
        newest sensor packet at or before it (:func:`step_ends`)."""
        local = self.clock.local
        packets = [(local(p.t), p) for p in self.inbox.recent_packets(self.clock.world(self.t_step))]
        newest_before = packets[0][1] if packets else self.inbox.get(self.sense_link)
        return step_ends(packets, self.t_step, t_end, 1.0 / self.program.clock.rate, newest_before)

    def _send(self, pub: Publish, t_world: float, t_local: float) -> None:
        """Publish at the tick ``t_local`` (the links' send stamp) what refers to ``t_world``."""
        seq = self.seq
        self.seq += 1
        t_stamp = t_world if pub.t is None else pub.t
        for i, fields in pub.edges.items():
            p = self.pub_edge.get(i)
            if p is not None:
                p.publish("edge", self.id, seq, t_stamp, inc=self.inc, t_local=t_local, **fields)
                self.sent[i] += 1
        # The estimate as SPEC.estimate declares it: R̂, p̂, per-edge maps, named values.
        est: dict[str, Any] = {"t_local": t_local}
        values: dict[str, Any] = {}
        edges: dict[str, Any] = {}
        for k, v in pub.estimate.items():
            if k == "R_hat" or k == "p_hat":
                est[k] = v
            elif k in self.estimate_edges:
                if v:
                    edges[k] = v
            else:
                values[k] = v
        if values:
            est["values"] = values
        if edges:
            est["edges"] = edges
        if self.jumps:
            est["jumps"], self.jumps = self.jumps, []
        if pub.command is not None and self.pub_cmd is not None:
            # To the world's plant (zero-order hold there), stamped with the time of the
            # measurements it was computed from.
            self.send_delays.append(max(0.0, self.clock.local(self._now()) - t_local))
            self.pub_cmd.publish("cmd", self.id, self.cmd_seq, t_stamp, inc=self.inc, t_local=t_local, **pub.command)
            self.cmd_seq += 1
        self.pub_est.publish("est", self.id, seq, t_stamp, inc=self.inc, **est)

    # ------------------------------------------------------------------ reporting

    def counters(self) -> dict[str, Any]:
        self._count_stale()
        span = (self.t_last - self.t_first) if (self.t_first is not None and self.t_last is not None) else 0.0
        c = self.inbox.counters()
        c.update(
            {
                "role": self.program.role,
                "steps": self.steps,
                "step_rate_hz": (self.steps - 1) / span if span > 0 else 0.0,
                "missed_deadlines": self.missed,
                "catch_up_steps": self.catch_up_steps,
                "idle_ticks": self.idle_ticks,
                "step_failures": self.step_failures,
                "compute_mean_us": 1e6 * self.compute_s / self.steps if self.steps else 0.0,
                "compute_max_us": 1e6 * self.compute_max,
                "sent": {f"{self.id}->{i}": n for i, n in self.sent.items()} | ({f"{self.id}->world": self.cmd_seq} if self.pub_cmd is not None else {}),
                "stale_policy": f"{self.stale.policy} after {self.stale.max_age:g} s",
                "stale_terms": {f"{j}->{self.id}": n for j, n in sorted(self.stale_terms.items())},
            }
        )
        if self.neighbor_events:
            c["neighbor_events"] = [[j, round(t, 6), up] for j, t, up in list(self.neighbor_events)]
        if len(self.parts) > 1:  # what each part achieved on this agent's clock (De Carli: 200/100/50 Hz)
            c["parts"] = {
                ps.part.name: {
                    "steps": ps.steps,
                    "rate_hz": (ps.steps - 1) / (ps.last - ps.t_first) if ps.t_first is not None and ps.last > ps.t_first else 0.0,
                    "configured_hz": ps.rate if ps.rate is not None else self.program.clock.rate,
                }
                for ps in self.parts
            }
        if self.jump_count:
            c["jumps"] = {str(k): n for k, n in sorted(self.jump_count.items())}
        if self.agent_jump_count:
            c["agent_jumps"] = self.agent_jump_count
        return c

    def check_silent(self, t_world: float) -> None:
        """Mark lost an in-neighbour whose token is up but whose messages stopped SILENT_S ago
        (world time, by their stamps), and back when they come again.  A token is a key any
        peer can declare: one that copied a neighbour's (its tag included) hid the
        neighbour's death from its token alone; messages stamped with the run's time keep
        coming only from a process that runs (issue 50).  Called once a second (run_realtime)."""
        limit = max(SILENT_S, SILENT_PERIODS / self.program.clock.rate)
        for j in self.program.neighbors:
            m = self.inbox.get(f"{j}->{self.id}")
            if m is None:
                continue  # nothing yet: its first message decides
            quiet = t_world - m.t
            if j in self.silent and quiet <= limit:
                self.silent.discard(j)
                self.lost.pop(j, None)
                log.info("agent %d: in-neighbour %d is sending again at t = %.3f s", self.id, j, t_world)
                self._neighbor_event(j, t_world, True)
            elif j not in self.lost and quiet > limit and not self.run_over():
                self.silent.add(j)
                self.lost[j] = t_world
                log.warning("agent %d: in-neighbour %d lost: silent for %.1f s while its liveliness token is up (a copied token, or a hung process) at t = %.3f s", self.id, j, quiet, t_world)
                self._neighbor_event(j, t_world, False)

    def _neighbor_event(self, j: int, t: float, up: bool) -> None:
        if len(self.neighbor_events) < MAX_NEIGHBOR_EVENTS:
            self.neighbor_events.append((j, t, up))

    def publish_stats(self, t_world: float, final: bool = False) -> None:
        counters = self.counters()
        counters["final"] = final
        (self.pub_final if final else self.pub_stats).publish("stats", self.id, self.stats_seq, t_world, inc=self.inc, role="agent", counters=counters)
        self.stats_seq += 1


def run_realtime(node: AgentNode, now: Callable[[], float], sleep_until: Callable[[float], bool], duration: float, stats_every: float = 1.0) -> None:
    """Tick ``node`` on its own schedule until ``duration`` (world time) or a stop.

    ``sleep_until(t)`` returns False when the run is being stopped.
    """
    t = node.clock.first_tick(max(0.0, now()))
    next_stats = stats_every
    while t <= duration and sleep_until(t):
        node.tick(now())
        t, missed = node.clock.next_tick(now())
        node.missed += missed
        if t >= next_stats:
            node.check_silent(now())
            node.publish_stats(t)
            next_stats += stats_every
