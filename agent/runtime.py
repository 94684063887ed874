"""The agent runtime: own clock, inbox of the newest data, step, publish.

:class:`AgentNode` is engine-agnostic: ``zswarm sim`` calls :meth:`tick` at
virtual times, ``python -m agent`` from a real-time loop (:func:`run_realtime`).
Bus callbacks only decode, count and store the newest message per source;
all the math happens in :meth:`tick`.
"""

from __future__ import annotations

import bisect
import dataclasses
import heapq
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from types import ModuleType
from typing import Any

import numpy as np

from agent.algorithms import REGISTRY
from agent.algorithms.bearing_terms import NeighborData
from agent.algorithms.relative_attitude_terms import EdgeData
from zswarm import keys, so3, wire
from zswarm.bus import Bus
from zswarm.clock import AgentClock
from zswarm.links import LinkModel
from zswarm.scenario import Scenario
from zswarm.so3 import exp

log = logging.getLogger("zswarm.agent")


class LinkCounter:
    """Counts what arrives on one link; loss is inferred from sequence-number gaps.

    Also keeps the last 2000 latencies (receiver's clock at arrival minus the
    sender's send stamp): meaningful when the clocks share a base, as they do
    for processes on one host with no configured offset or drift.
    """

    __slots__ = ("delivered", "max_seq", "reordered", "latency")

    def __init__(self) -> None:
        self.delivered = 0
        self.max_seq = -1
        self.reordered = 0
        self.latency: deque[float] = deque(maxlen=2000)

    def see(self, seq: int, latency: float) -> None:
        self.delivered += 1
        self.latency.append(latency)
        if seq < self.max_seq:
            self.reordered += 1
        else:
            self.max_seq = seq

    def as_dict(self) -> dict[str, Any]:
        # Messages numbered 0..max_seq were sent before the last one received;
        # those not delivered were lost on the way.
        d: dict[str, Any] = {"delivered": self.delivered, "dropped": max(0, self.max_seq + 1 - self.delivered), "reordered": self.reordered}
        if self.latency:
            q = np.percentile(np.array(self.latency), [50, 99])
            d["latency_p50_ms"], d["latency_p99_ms"] = 1e3 * float(q[0]), 1e3 * float(q[1])
        return d


_EYE3 = np.eye(3)
_EYE3.flags.writeable = False
VEL_BODY = -1  # key of the body-frame velocity among an Inbox's body vectors


class Inbox:
    """Newest decoded message per source key, with per-link counters and malformed counts."""

    def __init__(self, log_name: str, now: Callable[[], float], link_model: Callable[[str], LinkModel] | None = None) -> None:
        self._lock = threading.Lock()
        self.now = now  # the receiver's own clock, stamps every arrival as "rx"
        # Link emulation (zswarm/links.py): each arrival is lost or held until its release time.
        self._link_model = link_model
        self.models: dict[str, LinkModel] = {}
        self._held: list[tuple[float, int, str, str, dict[str, Any]]] = []
        self._held_n = 0
        self.latest: dict[str, dict[str, Any]] = {}
        # (acquisition world time, value) of recent sensor packets' gyro and inertial
        # velocity, for integrating them over a step
        self.rates: dict[str, deque[tuple[float, np.ndarray]]] = {"gyro": deque(maxlen=64), "vel": deque(maxlen=64)}
        # (acquisition world time, body-frame bearings {j: b_ij^i} and velocity
        # {VEL_BODY: v_i^i}, gyro) of recent sensor packets
        self.bearings: deque[tuple[float, dict[int, np.ndarray], np.ndarray]] = deque(maxlen=64)
        self.links: dict[str, LinkCounter] = {}
        self.malformed = 0
        self._logged: set[str] = set()
        self._log = logging.getLogger(log_name)

    def handler(self, expect: str, link_of: Callable[[str], str | None]) -> Callable[[str, bytes], None]:
        def on_message(key: str, payload: bytes) -> None:
            link = link_of(key)
            try:
                if link is None:
                    raise wire.MessageError("key is not one of this agent's links")
                msg = wire.decode(payload, expect)
            except wire.MessageError as exc:
                with self._lock:
                    self.malformed += 1
                    first = key not in self._logged
                    self._logged.add(key)
                if first:
                    self._log.warning("dropped malformed message on %s: %s (logged once per key)", key, exc)
                return
            rx = self.now()
            with self._lock:
                if self._link_model is not None:
                    model = self.models.get(link)
                    if model is None:
                        model = self.models[link] = self._link_model(link)
                    release = model.admit(rx)
                    if release is None:
                        return  # lost on the emulated link (counted by the model)
                    if release > rx:
                        heapq.heappush(self._held, (release, self._held_n, link, expect, msg))
                        self._held_n += 1
                        return
                self._deliver(link, expect, msg, rx)

        return on_message

    def _deliver(self, link: str, expect: str, msg: dict[str, Any], rx: float) -> None:
        """Store a message that has reached this agent (caller holds the lock)."""
        msg["rx"] = rx
        sent = msg["t_local"] if "t_local" in msg else msg["t"]
        counter = self.links.get(link)
        if counter is None:
            counter = self.links[link] = LinkCounter()
        counter.see(msg["seq"], rx - sent)
        prev = self.latest.get(link)
        if prev is None or msg["seq"] >= prev["seq"]:
            self.latest[link] = msg
            if expect == "sense":
                for name, q in self.rates.items():
                    if name in msg:
                        q.append((msg["t"], msg[name]))
                if "bearings" in msg or "vel_body" in msg:
                    vecs = dict(msg.get("bearings", {}))
                    if "vel_body" in msg:
                        vecs[VEL_BODY] = msg["vel_body"]
                    self.bearings.append((msg["t"], vecs, msg["gyro"]))

    def release_due(self) -> None:
        """Deliver every held message whose release time has come (the agent calls this each tick)."""
        if not self._held:
            return
        now = self.now()
        with self._lock:
            while self._held and self._held[0][0] <= now:
                release, _, link, expect, msg = heapq.heappop(self._held)
                self._deliver(link, expect, msg, release)

    def get(self, link: str) -> dict[str, Any] | None:
        return self.latest.get(link)

    def samples(self, name: str = "gyro") -> list[tuple[float, np.ndarray]]:
        """Recent ``(acquisition world time, value)`` of a rate in sensor packets: "gyro" or "vel"."""
        with self._lock:
            return list(self.rates[name])

    def bearing_at(self, j: int, t: float, max_ahead: float = 0.05, unit: bool = True) -> np.ndarray | None:
        """This agent's body-frame bearing toward j at world time ``t`` (or, for
        ``j = VEL_BODY`` and ``unit=False``, its body-frame velocity).

        From the two sensor samples around ``t`` (or the newest two, up to
        ``max_ahead`` s past the newest): the older one is turned into the
        newer one's body frame with the gyro, so what is left between them is
        the bearing's own (translational) change, slow next to the body's
        rotation; that is interpolated or extrapolated linearly and the result
        turned to the body frame at ``t``.  A plain linear extrapolation of
        body-frame vectors holds only for a sample gap (5 ms), and over Zenoh
        the newest sample is often older than that.  None outside the history.
        """
        with self._lock:
            hist = [(ts, b[j], w) for ts, b, w in self.bearings if j in b]
        if len(hist) < 2:
            return None
        pairs = list(zip(hist, hist[1:], strict=False))
        (t0, b0, _), (t1, b1, w1) = pairs[-1]
        if not t1 < t <= t1 + max_ahead:
            for (t0, b0, _), (t1, b1, w1) in pairs:
                if t0 <= t <= t1:
                    break
            else:
                return None
        if t1 <= t0:
            return None
        b0_in_1 = exp(-(t1 - t0) * w1) @ b0
        s_ = (t - t0) / (t1 - t0)
        v = exp(-(t - t1) * w1) @ ((1 - s_) * b0_in_1 + s_ * b1)
        return v / np.sqrt(v @ v) if unit else v

    def counters(self) -> dict[str, Any]:
        with self._lock:
            links = {k: v.as_dict() for k, v in self.links.items()}
            for k, m in self.models.items():
                if m.spec.active:
                    links.setdefault(k, {"delivered": 0, "dropped": 0, "reordered": 0}).update(m.counters())
            return {"links": links, "malformed": self.malformed}


def interval_mean_rate(samples: list[tuple[float, np.ndarray]], t0: float, t1: float) -> np.ndarray:
    """Mean of a sampled rate over ``[t0, t1]``.

    The rate is linearly interpolated between samples (``(time, vector)``,
    increasing times), held before the first, and past the newest sample
    extrapolated linearly from the last two for at most one sample gap (then
    held); the resulting piecewise-linear function is integrated exactly.

    This is the gyro pre-integration of an IMU-driven estimator.  Using only
    the newest sample over a 10 ms step lags by half a step (≈ ω̇·dt/2 rate
    error); holding the newest sample until the tick — which over Zenoh
    arrives 0–5 ms before it — leaves a ½ω̇τ² error per step of the same sign
    as ω̇, measured as a 1e-3 attitude floor on the §3.2 run.
    """
    # Plain Python on the few samples that matter (numpy's per-call overhead made
    # this a tenth of a §3.2 sim): those from the last one at or before t0 on.
    n = len(samples)
    if n == 1 or t1 <= t0:
        return np.array(samples[-1][1] if t1 <= t0 else samples[0][1], dtype=float)
    ts_all = [s[0] for s in samples]
    first = max(0, min(bisect.bisect_right(ts_all, t0) - 1, n - 2))
    ts = ts_all[first:]
    W = [tuple(s[1].tolist()) if type(s[1]) is np.ndarray else tuple(map(float, s[1])) for s in samples[first:]]
    gap = ts_all[-1] - ts_all[-2]
    Wl, Wp = samples[-1][1], samples[-2][1]
    slope = [(float(Wl[c]) - float(Wp[c])) / gap if gap > 0 else 0.0 for c in range(3)]
    t_last = ts_all[-1]
    t_cap = t_last + max(gap, 0.0)

    def value(t: float, k: int) -> tuple[float, float, float]:
        """The rate at t; k: index into ts of the last sample at or before t (-1: none)."""
        if k < 0:
            return W[0]  # type: ignore[return-value]
        if k >= len(ts) - 1:
            tau = min(max(t - t_last, 0.0), t_cap - t_last)
            w = W[-1]
            return (w[0] + tau * slope[0], w[1] + tau * slope[1], w[2] + tau * slope[2])
        ta, tb = ts[k], ts[k + 1]
        a, b = W[k], W[k + 1]
        u = (t - ta) / (tb - ta) if tb > ta else 1.0
        return (a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]))

    # Breakpoints of the piecewise-linear rate inside (t0, t1): sample times and t_cap.
    # The rate is continuous, so one value per breakpoint serves both segments.
    grid = sorted({t0, t1, *(t for t in (*ts, t_cap) if t0 < t < t1)})
    vals = [value(g, bisect.bisect_right(ts, g) - 1) for g in grid]
    acc = [0.0, 0.0, 0.0]
    for n_ in range(len(grid) - 1):
        h = grid[n_ + 1] - grid[n_]
        lo, hi = vals[n_], vals[n_ + 1]
        acc[0] += 0.5 * (lo[0] + hi[0]) * h
        acc[1] += 0.5 * (lo[1] + hi[1]) * h
        acc[2] += 0.5 * (lo[2] + hi[2]) * h
    return np.array(acc) / (t1 - t0)


def _edge_link(key: str) -> str | None:
    parts = key.split("/")
    if len(parts) == 5 and parts[2] == "edge":
        return f"{parts[3]}->{parts[4]}"
    return None


class AgentNode:
    """One agent: subscribes to its sensor key and in-edges, steps its algorithm on its own clock."""

    def __init__(self, scenario: Scenario, agent_id: int, bus: Bus, run: str, seed: int, now: Callable[[], float]) -> None:
        self.sc = scenario
        self.moving = scenario.moving  # a property of the scenario: computed once, read every tick
        self.stale = scenario.stale
        self.stale_terms: dict[int, int] = {}  # per in-neighbour: terms evaluated on a message older than max_age
        self.id = agent_id
        self.spec = scenario.agent(agent_id)
        self.run = run
        self.leader = self.spec.role == "leader"
        self.algo: ModuleType = REGISTRY[scenario.algorithm]
        self.tree = scenario.info.graph == "tree"
        self.hybrid = scenario.info.params == "hybrid"
        self.heard_all = False  # tree observers correct only once every neighbour has been heard
        kw: dict[str, Any] = dict(self.spec.gains)
        if scenario.params is not None:
            pr = scenario.params
            kw.update(A=pr.A_matrix, u=np.array(pr.u), gamma=pr.gamma, delta=pr.delta, Xi=pr.Xi)
        self.gains = self.algo.Gains(**{f.name: kw[f.name] for f in dataclasses.fields(self.algo.Gains)})
        # Tree edges (§4): neighbour j -> (edge index k, whether this agent heads k and owns ξ_k).
        self.edge_of: dict[int, tuple[int, bool]] = {}
        for k, (h, t) in enumerate(scenario.oriented, start=1):
            if agent_id in (h, t):
                self.edge_of[t if h == agent_id else h] = (k, h == agent_id)
        est = self.spec.estimate
        init = {
            "R_hat": np.array(est.R_hat).reshape(3, 3),
            "p_hat": np.array(est.p_hat),
            "Omega": np.array(est.Omega),
            "xi": {k: float(est.xi.get(k, 0.0)) for k, head in self.edge_of.values() if head},
        }
        self.state = self.algo.State(**{f.name: init[f.name] for f in dataclasses.fields(self.algo.State)})
        self.jumps: list[tuple[int, float, float, float]] = []  # (k, t, ξ before, ξ after) not yet published
        self.jump_count: dict[int, int] = {k: 0 for k, head in self.edge_of.values() if head}
        self.clock = AgentClock(self.spec.clock, seed=(seed * 1000003 + agent_id) % (1 << 63))
        self.out = scenario.out_neighbors(agent_id)
        self.inbox = Inbox(
            f"zswarm.agent.{agent_id}",
            lambda: self.clock.local(now()),
            (lambda name: LinkModel(scenario.link_spec(name), name, seed)) if scenario.links_active else None,
        )
        sense_link = f"world->{agent_id}"
        bus.subscribe(keys.sense(run, agent_id), self.inbox.handler("sense", lambda k: sense_link))
        if self.spec.neighbors:
            bus.subscribe(keys.edges_into(run, agent_id), self.inbox.handler("edge", _edge_link))
        self.pub_edge = {i: bus.publisher(keys.edge(run, agent_id, i)) for i in self.out}
        self.pub_est = bus.publisher(keys.est(run, agent_id))
        self.pub_stats = bus.publisher(keys.stats(run, "agent", agent_id))
        self.sense_link = sense_link
        self.seq = 0
        self.stats_seq = 0
        self.steps = 0
        self.missed = 0
        self.t_first: float | None = None
        self.t_last: float | None = None
        self.last_local: float | None = None
        self.substeps = 0  # extra sub-steps taken for late ticks
        self._t_world = 0.0  # world time of the tick being computed
        self._tick_cache: dict[Any, Any] = {}
        self.compute_s = 0.0
        self.compute_max = 0.0

    # ------------------------------------------------------------------ the step

    def tick(self, t_world: float) -> None:
        """One step at world time ``t_world`` (the agent reads its own clock from it)."""
        t_local = self.clock.local(t_world)
        self._t_world = t_world
        self._tick_cache = {}  # per-tick results used by several neighbours
        self.inbox.release_due()
        sense = self.inbox.get(self.sense_link)
        if sense is None:
            return  # nothing measured yet: no step, nothing to publish
        c0 = time.perf_counter()
        if self.last_local is None and not self.leader:
            self._catch_up_from_zero(t_local, sense)
        dt = 0.0 if self.last_local is None else t_local - self.last_local
        self.last_local = t_local
        extra: dict[str, np.ndarray] = {}
        bearings = sense.get("bearings", {})
        # Samples were measured at the packet's acquisition time t_s (an on-board
        # sensor stamps them on the agent's own clock, local(t_s)); body-frame
        # vectors are rotated to this tick with the gyro: b(t) = exp(-τ[ω]^x) b(t_s).
        # Arrival time would add the world's scheduling delay (ms on a busy host).
        # A leader sends the packet's own (R, b) pair, both taken at t_s.
        align = _EYE3
        if self.leader:
            R_hat, p_hat = sense.get("R"), sense.get("p")
            if R_hat is None or p_hat is None:
                return
        else:
            align = so3.exp(-(t_local - self.clock.local(sense["t"])) * sense["gyro"])
            if dt > 0:
                omega = interval_mean_rate(self._samples("gyro"), t_local - dt, t_local)
                inputs = self._tree_inputs(sense, omega, align, t_local, dt) if self.tree else self._bearing_inputs(sense, omega, align, t_local, dt)
                # A late tick (a stalled process, a missed deadline) would take one
                # long explicit step: k_R σ dt and k_ξ γ dt of order 1 overshoot and can
                # throw ξ into the jump set.  Sub-steps of at most two periods keep the
                # discretisation what it is at the nominal rate.
                n_sub = max(1, math.ceil(dt * self.spec.clock.rate / 2.0 - 1e-9))
                for _ in range(n_sub):
                    self.state, outputs = self.algo.step(self.state, inputs, dt / n_sub, self.gains)
                    for k, before, after in getattr(outputs, "jumps", ()):
                        self.jumps.append((k, t_world, before, after))
                        self.jump_count[k] += 1
                self.substeps += n_sub - 1
                extra["sigma"] = outputs.sigma
            R_hat = self.state.R_hat
            p_hat = getattr(self.state, "p_hat", np.zeros(3))
            if hasattr(self.state, "Omega"):
                extra["Omega"] = self.state.Omega
        seq = self.seq
        self.seq += 1
        # A follower's R̂ is at this tick, so the bearing it sends is aligned to it too.
        t_stamp = sense["t"] if self.leader else t_world
        xi = getattr(self.state, "xi", {})
        for i, pub in self.pub_edge.items():
            fields: dict[str, Any] = {"t_local": t_local, "R_hat": R_hat, "p_hat": p_hat}
            b = bearings.get(i)
            if b is not None:
                fields["b"] = align @ b
                if self.moving and not self.leader:
                    # Rotation alone misses how far the bearing itself turned since the
                    # sample (translation: 0.5 rad/s in §3.3.4); extrapolate it instead.
                    b_t = self._bearing_now(i)
                    if b_t is not None:
                        fields["b"] = b_t
            elif not self.tree:
                continue
            if "vel" in sense:
                fields["vel"] = sense["vel"]
            elif "vel_body" in sense:
                # ṗ̂_j ≈ R̂_j v_j^j during flows (4.30): lets i bring p̂_j to its tick.
                fields["vel"] = R_hat @ (align @ sense["vel_body"])
            if self.tree:
                fields["w"] = sense["gyro"]
                k, head = self.edge_of[i]
                if head and k in xi:
                    fields["xi"] = xi[k]
            pub.put(wire.encode("edge", self.id, seq, t_stamp, **fields))
        est: dict[str, Any] = {"t_local": t_local, "R_hat": R_hat, "p_hat": p_hat, "extra": _extra_map(extra)}
        if xi:
            est["xi"] = xi
        if self.jumps:
            est["jumps"], self.jumps = self.jumps, []
        self.pub_est.put(wire.encode("est", self.id, seq, t_stamp, **est))
        c = time.perf_counter() - c0
        self.compute_s += c
        self.compute_max = max(self.compute_max, c)
        self.steps += 1
        if self.t_first is None:
            self.t_first = t_world
        self.t_last = t_world

    def _catch_up_from_zero(self, t_local: float, sense: dict[str, Any]) -> None:
        """Bring the initial estimate, which is at world time 0, to this first tick.

        Over Zenoh the first tick with data comes 1–20 ms after t = 0; taking
        the initial estimate as if it were at that tick shifts R̂_i by ω_i·τ
        (0.07 rad for §4.5's agent 5 at 6.6 rad/s), which is enough to move the
        §4.5 start out of the hybrid jump set.  The catch-up is prediction only
        (gyro, velocities; no neighbour terms).  A process that joins more than
        0.5 s late starts from its initial estimate at its first tick instead.
        """
        t0 = self.clock.local(0.0)
        if not 0.0 < t_local - t0 <= 0.5 or not self._samples("gyro"):
            return
        omega = interval_mean_rate(self._samples("gyro"), t0, t_local)
        args: tuple[Any, ...] = (omega,)
        if "vel_body" in sense:
            args = (omega, sense["vel_body"])  # newest v_i^i; the gap is a few ms
        elif "vel" in sense:
            args = (omega, interval_mean_rate(self._samples("vel"), t0, t_local))
        empty = self.algo.Inputs(*args, ())
        self.state, _ = self.algo.step(self.state, empty, t_local - t0, self.gains)
        self.last_local = t_local

    def _stale_drop(self, j: int, m: dict[str, Any], t_local: float) -> bool:
        """Apply the stale-data policy to j's newest message: count it if older than
        ``max_age``, and say whether to leave j's terms out ("drop")."""
        if t_local - self.clock.local(m["t"]) <= self.stale.max_age:
            return False
        self.stale_terms[j] = self.stale_terms.get(j, 0) + 1
        return self.stale.policy == "drop"

    def _samples(self, name: str) -> list[tuple[float, np.ndarray]]:
        """Recent samples of a rate ("gyro", "vel") on this agent's clock; once per tick."""
        cache = self._tick_cache
        if name not in cache:
            samples = self.inbox.samples(name)
            if not self.clock.is_identity:
                samples = [(self.clock.local(t), w) for t, w in samples]
            cache[name] = samples
        return cache[name]  # type: ignore[no-any-return]

    def _bearing_now(self, j: int) -> np.ndarray | None:
        """Our bearing toward j at this tick (sensor history), for moving agents; once per tick."""
        key = ("b", j)
        if key not in self._tick_cache:
            self._tick_cache[key] = self.inbox.bearing_at(j, self._t_world)
        return self._tick_cache[key]  # type: ignore[no-any-return]

    def _bearing_inputs(self, sense: dict[str, Any], omega: np.ndarray, align: np.ndarray, t_local: float, dt: float) -> Any:
        """Inputs of the §3 observers: per in-neighbour j its (R̂_j, p̂_j, b_ji^j) and our b_ij^i."""
        nbrs = []
        bearings = sense.get("bearings", {})
        for j, k in zip(self.spec.neighbors, self.spec.k_neighbors, strict=True):
            m = self.inbox.get(f"{j}->{self.id}")
            b_own = bearings.get(j)
            if m is None or b_own is None or "b" not in m:
                continue  # no data from j yet: its term is left out of the sums
            if self._stale_drop(j, m, t_local):
                continue
            b_now = align @ b_own
            if not self.moving:
                nbrs.append(NeighborData(k, m["R_hat"], m["p_hat"], m["b"], b_now))
                continue
            # Moving agents: inertial bearings turn (0.5 rad/s in §3.3.4), so j's
            # R̂_j b_ij^j, sampled at j's stamp t_j, is paired with our own bearing
            # at t_j (from the sensor history), turned to this tick's body frame by
            # the gyro; p̂_j is brought to this tick with j's measured velocity.
            # Pairing with the newest bearing instead left a 4e-3 attitude floor
            # over Zenoh (5–10 ms ages × 0.5 rad/s).
            b_t = self._bearing_now(j)
            if b_t is not None:
                b_now = b_t
            t_j = self.clock.local(m["t"])
            tau = t_local - t_j
            b_then = self.inbox.bearing_at(j, m["t"])
            b_att = b_now
            if b_then is not None:
                w_bar = interval_mean_rate(self._samples("gyro"), t_j, t_local)
                b_att = so3.exp(-tau * w_bar) @ b_then
            p_hat_j = m["p_hat"] + tau * m["vel"] if "vel" in m else m["p_hat"]
            nbrs.append(NeighborData(k, m["R_hat"], p_hat_j, m["b"], b_att, b_now))
        if "vel" in sense:
            v = interval_mean_rate(self._samples("vel"), t_local - dt, t_local)
            return self.algo.Inputs(omega, v, tuple(nbrs))
        return self.algo.Inputs(omega, tuple(nbrs))

    def _tree_inputs(self, sense: dict[str, Any], omega: np.ndarray, align: np.ndarray, t_local: float, dt: float) -> Any:
        """Inputs of the §4 observers, every quantity brought to this tick.

        The measured ``R_ij = R_i^T R_j`` is from time t_s and j's estimate from
        its tick t_j; both are propagated with the gyros (ours, and j's rate
        sent with its estimate):
        ``R_ij(t) = exp(−τ_s[ω_i]) R_ij(t_s) exp(τ_s[ω_j])``,
        ``R̂_j(t) = R̂_j(t_j) exp((t − t_j)[ω_j])``.  Without this, pairing a
        10 ms old R̂_j with R_ij on an agent turning at 6.6 rad/s (§4.5, agent 5)
        biases R̄ by ≈ 0.07 rad.  Stamps are compared on this agent's clock,
        which assumes the agents' clocks are synchronised (as over one host).
        """
        edges = []
        tau_s = t_local - self.clock.local(sense["t"])
        rel = sense.get("rel_att", {})
        bearings = sense.get("bearings", {})
        for j, (k, head) in self.edge_of.items():
            m = self.inbox.get(f"{j}->{self.id}")
            R_m = rel.get(j)
            if m is None or R_m is None or "w" not in m or (self.hybrid and not head and "xi" not in m):
                continue  # nothing from j yet: the edge's terms are left out
            if self._stale_drop(j, m, t_local):
                continue
            w_j = m["w"]
            tau_j = t_local - self.clock.local(m["t"])
            b_own = bearings.get(j)
            if b_own is not None:
                b_t = self._bearing_now(j) if self.moving else None
                b_own = align @ b_own if b_t is None else b_t
            b_nbr = m.get("b")
            R_ij = align @ R_m @ so3.exp(tau_s * w_j)
            if b_nbr is not None:
                b_nbr = so3.exp(-tau_j * w_j) @ b_nbr
                b_then = self.inbox.bearing_at(j, m["t"]) if (self.moving and b_own is not None) else None
                if b_then is not None:
                    # j's bearing is from its tick t_j; the inertial bearing b_ji = −b_ij
                    # has turned since (0.5 rad/s in §4.5): our own bearing's change
                    # over [t_j, t], in j's frame, corrects it.
                    w_bar = interval_mean_rate(self._samples("gyro"), t_local - tau_j, t_local)
                    b_nbr = b_nbr - R_ij.T @ (b_own - so3.exp(-tau_j * w_bar) @ b_then)
            edges.append(
                EdgeData(
                    k,
                    head,
                    R_ij,
                    m["R_hat"] @ so3.exp(tau_j * w_j),
                    float(m.get("xi", 0.0)),
                    b_own,
                    b_nbr,
                    m["p_hat"] + tau_j * m["vel"] if "vel" in m else m["p_hat"],
                )
            )
        if not self.heard_all:
            # Until every neighbour has been heard once, only the gyro (and velocity)
            # prediction runs: a correction from part of the tree would move R̂_i
            # before its other edges are even evaluated (off the thesis' synchronous
            # start, e.g. out of the §4.5 jump set before the first jump check).
            if len(edges) < len(self.edge_of):
                edges = []
            else:
                self.heard_all = True
        if "vel_body" in sense:
            # (4.30) integrates R̂_i v_i^i ≈ R̃_i^T v_i over the step: take v_i^i at the
            # step's midpoint, turned to this tick's body frame (a midpoint rule).
            # The newest sample instead runs ahead of a rotating formation's
            # velocity by v̇·dt/2 ≈ 7 mm/s in §4.5, a ≈ 0.05–0.09 m bias on p̃.
            v = self.inbox.bearing_at(VEL_BODY, self._t_world - dt / 2, unit=False)
            v = align @ sense["vel_body"] if v is None else so3.exp(-(dt / 2) * omega) @ v
            return self.algo.Inputs(omega, v, tuple(edges))
        return self.algo.Inputs(omega, tuple(edges))

    # ------------------------------------------------------------------ reporting

    def counters(self) -> dict[str, Any]:
        span = (self.t_last - self.t_first) if (self.t_first is not None and self.t_last is not None) else 0.0
        c = self.inbox.counters()
        c.update(
            {
                "role": self.spec.role,
                "steps": self.steps,
                "step_rate_hz": (self.steps - 1) / span if span > 0 else 0.0,
                "missed_deadlines": self.missed,
                "late_substeps": self.substeps,
                "compute_mean_us": 1e6 * self.compute_s / self.steps if self.steps else 0.0,
                "compute_max_us": 1e6 * self.compute_max,
                "sent": {f"{self.id}->{i}": self.seq for i in self.out},
                "stale_policy": f"{self.stale.policy} after {self.stale.max_age:g} s",
                "stale_terms": {f"{j}->{self.id}": n for j, n in sorted(self.stale_terms.items())},
            }
        )
        if self.jump_count:
            c["jumps"] = {str(k): n for k, n in self.jump_count.items()}
        return c

    def publish_stats(self, t_world: float, final: bool = False) -> None:
        counters = self.counters()
        counters["final"] = final
        self.pub_stats.put(wire.encode("stats", self.id, self.stats_seq, t_world, role="agent", counters=counters))
        self.stats_seq += 1


EXTRA_KEYS = {"sigma": 0, "Omega": 1}


def _extra_map(extra: dict[str, np.ndarray]) -> dict[int, np.ndarray]:
    """Algorithm extras on the wire: ``vecmap`` keys are ints (see EXTRA_KEYS)."""
    return {EXTRA_KEYS[k]: v for k, v in extra.items()}


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
            node.publish_stats(t)
            next_stats += stats_every
