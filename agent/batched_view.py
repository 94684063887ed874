"""The batched engine's view (agent/batched.py): :class:`BatchedView`, the
zswarm.scenario.algorithm.View of one agent for M draws (every message and state value with a
leading draw axis), and the sensor history of each draw when the draws hold different ones
(:class:`_Deep`)."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from agent import batched_links
from agent.batched_arrays import _EYE3, HISTORY, HistorySplit, Unsupported, _take
from zswarm.math import timing
from zswarm.scenario import Scenario

if TYPE_CHECKING:
    from agent.batched_sensing import _DrawSensorLinks



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
        self.declared_jumps = sc.module_for(a.role).SPEC.jumps  # what its steps' outputs list as jumps (the engine counts them)
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
