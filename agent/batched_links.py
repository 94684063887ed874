"""Emulated links on the batched engine (agent/batched.py): each draw of a batch its own losses
and delays, the very numbers its ``sim`` run takes.

A link's randomness is one stream per purpose (zswarm/scenario/links.py ``PURPOSES``), message n taking
the n-th number of each whatever became of the others, so the numbers of M draws are read ahead
in blocks, ``(M, AHEAD)`` per stream, and a message is admitted for all the draws at once
(:meth:`LinkStack.admit`: the operations of ``LinkModel.admit``, element by element).  Messages
in flight are arrays (a release time per draw), not objects.

:class:`Commands` is the world's end of the agent→world command links (world/plant.py
``CommandInbox``): admission when sent, the commands in flight, the zero-order hold of the
newest one released by each world step, and the stale-command policy; its counters are those
the world reports (``links``, ``commands``), per draw.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from zswarm.scenario import Scenario
from zswarm.scenario.links import PURPOSES, LinkCounter, LinkSpec, block, link_seed, purposes

AHEAD = 512  # numbers read ahead per stream and draw
LATENCIES = 2000  # the last latencies a LinkCounter keeps (zswarm/scenario/links.py)


def per_draw_sensors(sc: Scenario) -> bool:
    """The sensor links draw random numbers (jitter, loss, bursts), lose packets in cuts or differ
    between agents: each draw's agents then step at packets of their own (not one fixed delay
    for all: agent/batched.py ``_DrawSensorLinks``; reordering or not, a packet behind a newer
    one stays out of the inbox, as the runtime's LinkCounter keeps it out), with any command
    links and agent→agent links, FIFO or reordering, beside them (``DrawInbox``).  One fixed
    delay on every sensor link is one plan for all draws (agent/batched.py ``_SensorLinks``)
    unless emulated agent→agent links run beside it.  Every link model runs batched, on every
    family the engine runs."""
    sensor = [sc.link_spec(f"world->{i}") for i in sc.ids]
    return any(s.active for s in sensor) and (any(purposes(s) or s.cuts for s in sensor) or len(set(sensor)) > 1)


class LinkStack:
    """One link's model for M draws, each with its own seed and its own spec (a sweep's link
    parameters vary between draws of one batch): ``LinkModel`` draw by draw.  A draw reads only
    its own streams, so numbers it draws for a purpose its spec does not use change nothing."""

    def __init__(self, specs: Sequence[LinkSpec], name: str, seeds: Sequence[int]) -> None:
        self.specs = list(specs)
        self.M = len(seeds)

        def col(f: str) -> np.ndarray:
            return np.array([getattr(s, f) for s in specs], dtype=float)

        self.delay, self.jit, self.drop = col("delay_ms"), col("jitter_ms"), col("drop")
        self.p_gb, self.p_bg, self.loss_good, self.loss_bad = col("ge_p_gb"), col("ge_p_bg"), col("ge_loss_good"), col("ge_loss_bad")
        self.normal = np.array([s.jitter == "normal" for s in specs])
        self.reorder = np.array([s.reorder for s in specs])
        self.any_active = any(s.active for s in specs)
        self.cuts = [s.cuts for s in specs] if any(s.cuts for s in specs) else None  # [[faults]] kind "cut": [start, end) per draw
        self.cut = np.zeros(self.M, dtype=np.int64)
        used = set().union(*(purposes(s) for s in specs))
        self.streams = {p: [(np.random.default_rng(link_seed(seed, name, p)), sp.jitter) for seed, sp in zip(seeds, specs, strict=True)] for p in PURPOSES if p in used}
        self.buf: dict[str, np.ndarray] = {}
        self.pos = AHEAD  # the next number of every draw (admit) ...
        self.at: np.ndarray | None = None  # ... or of each draw (admit with rows: draws that send at ticks of their own)
        self.bad = np.zeros(self.M, dtype=bool)
        self.last_release = np.full(self.M, -math.inf)
        self.offered = np.zeros(self.M, dtype=np.int64)
        self.dropped = np.zeros(self.M, dtype=np.int64)

    def _next(self) -> dict[str, np.ndarray]:
        if self.pos == AHEAD:
            self.buf = {p: np.stack([block(r, p, kind, AHEAD) for r, kind in rngs]) for p, rngs in self.streams.items()}
            self.pos = 0
        k = self.pos
        self.pos += 1
        return {p: b[:, k] for p, b in self.buf.items()}

    def _next_of(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """The next numbers of the draws ``rows``, each draw at its own message count."""
        if self.at is None:  # from now on a position per draw
            if self.pos == AHEAD:
                self.buf = {p: np.stack([block(r, p, kind, AHEAD) for r, kind in rngs]) for p, rngs in self.streams.items()}
                self.pos = 0
            self.at = np.full(self.M, self.pos, dtype=np.int64)
        for m in rows[self.at[rows] == AHEAD]:  # a draw at the end of its block reads its next one
            for p, rngs in self.streams.items():
                r, kind = rngs[m]
                self.buf[p][m] = block(r, p, kind, AHEAD)
            self.at[m] = 0
        k = self.at[rows]
        self.at[rows] += 1
        return {p: b[rows, k] for p, b in self.buf.items()}

    def admit(self, t_arrival: float, rows: np.ndarray | None = None) -> np.ndarray:
        """Release times (M,) of a message arriving at ``t_arrival`` in every draw, NaN where lost
        (LinkModel.admit's operations, element by element; a draw whose spec is all zero gets its
        arrival time, as LinkModel returns it).  ``rows``: only these draws send it, each its
        own next numbers (its own n-th message); the release times (len(rows),) of theirs."""
        if rows is not None and len(rows) == self.M and self.at is None:
            rows = None  # every draw: all at the same count
        r = slice(None) if rows is None else rows
        self.offered[r] += 1
        n = self.M if rows is None else len(rows)
        if not self.any_active:
            return np.full(n, t_arrival)
        if rows is None and self.at is not None:
            rows = np.arange(self.M)
            r = rows
        x = self._next() if rows is None else self._next_of(rows)
        drop, p_gb, p_bg, loss_good, loss_bad = self.drop[r], self.p_gb[r], self.p_bg[r], self.loss_good[r], self.loss_bad[r]
        lost = x["drop"] < drop if "drop" in x else np.zeros(n, dtype=bool)  # drop = 0: never
        if "ge_move" in x:
            on = p_gb > 0
            bad = self.bad[r]
            bad = np.where(on, np.where(bad, x["ge_move"] >= p_bg, x["ge_move"] < p_gb), bad)
            self.bad[r] = bad
            lost |= on & (x["ge_loss"] < np.where(bad, loss_bad, loss_good))
        self.dropped[r] += lost
        if self.cuts is not None:  # after the model's draws, as LinkModel: outside a cut the link decides as without it
            cut = ~lost & np.array([any(a <= t_arrival < b for a, b in self.cuts[m]) for m in range(self.M)])[r]
            self.cut[r] += cut
            lost = lost | cut
        delay = self.delay[r]
        d = delay
        if "jitter" in x:
            jit = self.jit[r]
            z = delay + jit * x["jitter"]
            d = np.where(jit > 0, np.where(self.normal[r], np.maximum(0.0, z), z), delay)
        last = self.last_release[r]
        release = t_arrival + d * 1e-3
        release = np.where(self.reorder[r], release, np.maximum(release, last))
        release = np.where(lost, np.nan, release)
        self.last_release[r] = np.where(lost, last, np.maximum(last, release))
        return release


class Commands:
    """The command links i->world of M draws and the world's hold of their commands: the
    torque source of the batched rigid-body plant (``inputs_at``, as CommandInbox's)."""

    def __init__(self, draws: Sequence[Scenario], seeds: Sequence[int], counters: bool) -> None:
        sc = draws[0]
        self.ids = list(sc.ids)
        self.M, self.n = len(seeds), len(self.ids)
        M, n = self.M, self.n
        self.links = [LinkStack([d.link_spec(f"{i}->world") for d in draws], f"{i}->world", seeds) for i in self.ids]
        self.policy = sc.commands
        self.counters = counters
        self.pending: list[list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = [[] for _ in self.ids]  # per agent: (release (M,), seq (M,), stamp (M,), u (M, 3))
        self.soonest = np.full(n, math.inf)  # per agent: the earliest release in flight
        self.u = np.zeros((M, n, 3))
        self.stamp = np.full((M, n), -math.inf)
        self.seq = np.full((M, n), -1, dtype=np.int64)
        self.applied = np.zeros((M, n), dtype=np.int64)
        self.superseded = np.zeros((M, n), dtype=np.int64)
        self.expired = np.zeros((M, n), dtype=np.int64)
        self.stale_s = np.zeros((M, n))
        self._flag = np.zeros((M, n), dtype=bool)
        # LinkCounter at admission (commands arrive in order, so only gaps count as lost).
        self.sent = np.zeros((M, n), dtype=np.int64)  # per draw: its agents may send at ticks of their own
        self.delivered = np.zeros((M, n), dtype=np.int64)
        self.first_seq = np.full((M, n), -1, dtype=np.int64)
        self.max_seq = np.full((M, n), -1, dtype=np.int64)
        self.latency: list[list[np.ndarray]] = [[] for _ in self.ids]  # per agent, per command: (M,) release − send stamp, NaN where lost

    def send(self, a: int, t: float, stamp: float, u: np.ndarray, rows: np.ndarray | None = None) -> None:
        """Agent (column) ``a`` sends the command ``u`` (M, 3) at its tick ``t``, stamped ``stamp``
        (the world time of the measurements it was computed from).  ``rows``: only in these
        draws (``u`` then theirs, (len(rows), 3)), each its own next command of the agent."""
        seq = self.sent[:, a].copy()
        if rows is None:
            self.sent[:, a] += 1
            release = self.links[a].admit(t)
        else:
            self.sent[rows, a] += 1
            release = np.full(self.M, np.nan)
            release[rows] = self.links[a].admit(t, rows)
            full = np.zeros((self.M, 3))
            full[rows] = u
            u = full
        ok = ~np.isnan(release)
        self.delivered[:, a] += ok
        self.first_seq[:, a] = np.where(ok & (self.first_seq[:, a] < 0), seq, self.first_seq[:, a])
        self.max_seq[:, a] = np.where(ok, seq, self.max_seq[:, a])
        if self.counters:
            self.latency[a].append(release - t)  # NaN where lost or not sent
        if ok.any():
            self.pending[a].append((release, seq, np.full(self.M, stamp), np.broadcast_to(np.asarray(u, dtype=float), (self.M, 3)).copy()))
            self.soonest[a] = min(self.soonest[a], float(np.nanmin(release)))

    def inputs_at(self, s: float, h: float) -> np.ndarray:
        """The torques (M·n, 3) held over the world step ``[s, s + h]``: in each draw every
        command released at or before ``s`` taken in release order (the newest by sequence
        wins), then the stale policy (CommandInbox.inputs_at)."""
        for a in np.flatnonzero(self.soonest <= s + 1e-12):
            self._release(int(a), s)
        out = self.u
        old = ((s - self.stamp) > self.policy.max_age) & np.isfinite(self.stamp)
        if old.any():
            self.stale_s[old] += h
            self.expired += old & ~self._flag
            self._flag |= old
            if self.policy.policy == "zero":
                out = np.where(old[..., None], 0.0, self.u)
        return out.reshape(self.M * self.n, 3)

    def _release(self, a: int, s: float) -> None:
        pending = self.pending[a]
        rel = np.array([p[0] for p in pending])  # (K, M), in sequence (= arrival) order
        due = rel <= s + 1e-12
        if not due.any():
            return
        key = np.where(due, rel, np.inf)
        order = np.argsort(key, axis=0, kind="stable")  # release order, ties in arrival order (the world's heap)
        cols = np.arange(self.M)
        U = np.stack([p[3] for p in pending])  # (K, M, 3)
        S = np.array([p[1] for p in pending])  # (K, M)
        T = np.array([p[2] for p in pending])
        for k in range(int(due.sum(axis=0).max())):
            e = order[k]  # per draw, its k-th release of this step
            take = due[e, cols]
            newer = take & (S[e, cols] > self.seq[:, a])
            self.superseded[:, a] += take & ~newer
            if newer.any():
                self.u[newer, a] = U[e, cols][newer]
                self.stamp[newer, a] = T[e, cols][newer]
                self.seq[newer, a] = S[e, cols][newer]
                self.applied[newer, a] += 1
                self._flag[newer, a] = False
        rel = np.where(due, np.nan, rel)
        keep = [q for q in range(len(pending)) if not np.all(np.isnan(rel[q]))]
        self.pending[a] = [(rel[q], *pending[q][1:]) for q in keep]
        self.soonest[a] = float(np.nanmin(rel[keep])) if keep else math.inf

    def link_counters(self, m: int) -> dict[str, dict[str, Any]]:
        """Draw ``m``'s summary ``links`` entries of the command links, as the world counts them."""
        out = {}
        for a, i in enumerate(self.ids):
            d: dict[str, Any] = {"sent": int(self.sent[m, a]), "delivered": int(self.delivered[m, a])}
            span = self.max_seq[m, a] - self.first_seq[m, a] + 1 if self.first_seq[m, a] >= 0 else 0
            d["dropped"] = int(span - self.delivered[m, a])
            lat = np.array([x[m] for x in self.latency[a]]) if self.latency[a] else np.zeros(0)
            lat = lat[~np.isnan(lat)][-LATENCIES:]
            if lat.size:
                d["latency_p50_ms"] = 1e3 * float(np.percentile(lat, 50))
            if self.links[a].specs[m].active:
                d["offered"], d["link_dropped"] = int(self.links[a].offered[m]), int(self.links[a].dropped[m])
            out[f"{i}->world"] = d
        return out


class Split(Exception):  # a signal, not an error
    """A step read a neighbour's stamp (``t``, ``t_world``, ``age``) that differs between the draws
    of its group: the engine steps those draws again in groups of one stamp (``j``: whose)."""

    def __init__(self, j: int) -> None:
        super().__init__(j)
        self.j = j


class _Sent:
    __slots__ = ("release", "seq", "stamp", "t_send")

    def __init__(self, seq: int, stamp: float, t_send: float, release: np.ndarray) -> None:
        self.seq, self.stamp, self.t_send, self.release = seq, stamp, t_send, release


class _Ring:
    """One link's messages that some draw may still read: their fields, per draw (M, ...), and
    stamps, at slot ``index % cap`` (``index``: the link's message count), grown when the
    messages between the oldest readable one and the newest outgrow it."""

    def __init__(self, M: int) -> None:
        self.M, self.cap, self.lo = M, 16, 0
        self.fields: dict[str, np.ndarray] = {}
        self.stamp = np.zeros(self.cap)
        self.release = np.zeros((self.cap, M))

    def put(self, a: int, stamp: float, release: np.ndarray, fields: dict[str, Any], ndim: dict[str, int]) -> None:
        if a - self.lo >= self.cap:
            cap = self.cap
            while a - self.lo >= cap:
                cap *= 2
            live = np.arange(self.lo, a)
            self.stamp = self._regrow(self.stamp, cap, live)
            self.release = self._regrow(self.release, cap, live)
            self.fields = {n: self._regrow(v, cap, live) for n, v in self.fields.items()}
            self.cap = cap
        k = a % self.cap
        self.stamp[k] = stamp
        self.release[k] = release
        for name, v in fields.items():
            v = np.asarray(v, dtype=float)
            if v.ndim <= ndim.get(name, v.ndim):  # one value for every draw
                v = np.broadcast_to(v, (self.M, *v.shape))
            ring = self.fields.get(name)
            if ring is None:
                ring = self.fields[name] = np.zeros((self.cap, *v.shape))
            ring[k] = v

    def _regrow(self, old: np.ndarray, cap: int, live: np.ndarray) -> np.ndarray:
        new = np.zeros((cap, *old.shape[1:]))
        new[live % cap] = old[live % self.cap]
        return new


class Read:
    """What in-neighbour j's link holds for receiver i at a tick, per draw: the newest message
    delivered (``sel``, the link's message index; −1: none yet), its stamp, and whether it is stale."""

    __slots__ = ("cols", "has", "present", "ring", "sel", "stale", "stamp")

    def __init__(self, ring: _Ring, sel: np.ndarray, t: float, max_age: float, drop: bool, cols: np.ndarray | None = None) -> None:
        self.has = sel >= 0
        self.ring, self.sel = ring, sel
        self.cols = np.arange(len(sel)) if cols is None else cols  # each entry's draw (a sub-stack's: DrawInbox.read)
        st = ring.stamp[sel % ring.cap] if ring.stamp.ndim == 1 else ring.stamp[sel % ring.cap, self.cols]  # 2-D: a stamp per draw (DrawInbox)
        self.stamp = np.where(self.has, st, np.nan)
        self.stale = self.has & ((t - np.where(self.has, self.stamp, t)) > max_age)
        self.present = self.has & ~(self.stale & drop)


class GroupMsg:
    """An in-neighbour's message for the draws of a group (zswarm.scenario.algorithm.NeighborMsg): its fields
    gathered per draw (M, ...) from each draw's own newest message (draws outside the group get the
    group's first draw's: valid numbers, thrown away); its stamp where the group shares one,
    else reading it raises :class:`Split`."""

    __slots__ = ("_j", "_stamp", "_t", "fields")

    def __init__(self, j: int, read: Read, group: np.ndarray, t: float) -> None:
        first = int(np.flatnonzero(group)[0])
        sel = np.where(group & read.has, read.sel, read.sel[first]) % read.ring.cap
        self.fields = {name: ring[sel, read.cols] for name, ring in read.ring.fields.items()}
        st = read.stamp[group]
        self._j, self._t = j, t
        self._stamp = float(st[0]) if np.all(st == st[0]) else None

    def _uniform(self) -> float:
        if self._stamp is None:
            raise Split(self._j)
        return self._stamp

    @property
    def t(self) -> float:
        return self._uniform()

    @property
    def t_world(self) -> float:
        return self._uniform()

    @property
    def age(self) -> float:
        return self._t - self._uniform()


class Edges:
    """The agent→agent links of M draws (the receivers' Inbox with LinkModel and LinkCounter):
    each message admitted for every draw when sent (:class:`LinkStack`), held as one entry with
    a release time per draw, and at a receiver's tick the newest message delivered by then in
    each draw (sim's ``at_or_before``: the highest sequence delivered, stamps never being ahead
    of the tick).  ``ndim``: per receiver, the number of dimensions of each field it reads (more
    is a draw axis).  ``counters``: keep every message, for the receivers' counters per draw."""

    def __init__(self, draws: Sequence[Scenario], seeds: Sequence[int], counters: bool, ndim: dict[int, dict[str, int]]) -> None:
        sc = draws[0]
        self.M = M = len(seeds)
        self.into = {i: tuple(sc.agent(i).neighbors) for i in sc.ids}
        names = [(j, i) for i in sc.ids for j in sc.agent(i).neighbors]
        self.links = {k: LinkStack([d.link_spec(f"{k[0]}->{k[1]}") for d in draws], f"{k[0]}->{k[1]}", seeds) for k in names}
        self.msgs: dict[tuple[int, int], list[_Sent]] = {k: [] for k in names}
        self.rings = {k: _Ring(M) for k in names}
        self.ndim = ndim
        self.sel = {k: np.full(M, -1, dtype=np.int64) for k in names}  # the newest delivered, per draw
        self.todo = dict.fromkeys(names, 0)  # the first message not yet delivered or lost in every draw
        self.sent = dict.fromkeys(names, 0)
        self.max_age, self.drop = sc.stale.max_age, sc.stale.policy == "drop"
        self.counters = counters
        self.stale_terms = {i: np.zeros(M, dtype=np.int64) for i in sc.ids}
        self._arrays: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None  # link_counters', built once

    def send(self, j: int, i: int, seq: int, stamp: float, t_send: float, fields: dict[str, Any]) -> None:
        k = (j, i)
        if k not in self.links:
            return  # i does not listen to j (sim's receiver drops it: not one of its links)
        a = self.sent[k]
        self.sent[k] += 1
        release = self.links[k].admit(t_send)
        self.rings[k].put(a, stamp, release, fields, self.ndim[i])
        if self.counters:
            self.msgs[k].append(_Sent(seq, stamp, t_send, release))

    def read(self, i: int, t: float) -> dict[int, Read]:
        """What each in-neighbour's link of ``i`` delivers by ``i``'s tick at ``t``, per draw."""
        out = {}
        for j in self.into[i]:
            k = (j, i)
            ring, sel, start, n = self.rings[k], self.sel[k], self.todo[k], self.sent[k]
            if start < n:
                idx = np.arange(start, n)
                due = ring.release[idx % ring.cap] <= t  # (K, M); NaN (lost) compares False
                newest = np.where(due, idx[:, None], -1).max(axis=0)
                sel = np.maximum(sel, newest)
                settled = (due | np.isnan(ring.release[idx % ring.cap])).all(axis=1)
                self.todo[k] = start + (int(np.argmin(settled)) if not settled.all() else len(idx))  # the first some draw still waits for
                self.sel[k] = sel
            live = sel[sel >= 0]
            ring.lo = min(self.todo[k], int(live.min())) if live.size else 0
            out[j] = Read(ring, sel, t, self.max_age, self.drop)
        return out

    def link_counters(self, m: int, t_end: float) -> dict[str, dict[str, Any]]:
        """Draw ``m``'s summary ``links`` entries of the agent→agent links, as the receivers count
        them (LinkCounter) over the messages released by ``t_end``: on a FIFO link in sequence
        order, so delivered, lost (the sequence's gaps) and the latencies of the last LATENCIES
        come from arrays; with reordering they are replayed, in release order, through a LinkCounter."""
        if self._arrays is None:
            self._arrays = {k: (np.array([x.release for x in msgs]).reshape(len(msgs), self.M), np.array([x.seq for x in msgs]), np.array([x.t_send for x in msgs])) for k, msgs in self.msgs.items()}
        out = {}
        for j, i in self.msgs:
            R, seq, t_send = self._arrays[(j, i)]
            d: dict[str, Any]
            if self.links[(j, i)].specs[m].reorder:
                d = replayed(R[:, m], seq, t_send, t_end)
            else:
                idx = np.flatnonzero(R[:, m] <= t_end)  # NaN (lost) compares False
                if not idx.size:
                    d = {"delivered": 0, "dropped": 0, "reordered": 0}
                else:
                    d = {"delivered": int(idx.size), "dropped": int(seq[idx[-1]] - seq[idx[0]] + 1 - idx.size), "reordered": 0}
                    q = np.percentile(R[idx[-LATENCIES:], m] - t_send[idx[-LATENCIES:]], [50, 99])
                    d["latency_p50_ms"], d["latency_p99_ms"] = 1e3 * float(q[0]), 1e3 * float(q[1])
            d["sent"] = self.sent[(j, i)]
            out[f"{j}->{i}"] = d
        return out


def replayed(release: np.ndarray, seq: np.ndarray, t_send: np.ndarray, t_end: float) -> dict[str, Any]:
    """A reordering link's counters as its receiver's LinkCounter counts them: the messages
    released by ``t_end`` (NaN: lost or not sent) taken in release order, ties in send order
    (the Inbox's heap), each with its sequence number and latency."""
    got = np.flatnonzero(release <= t_end)  # NaN compares False
    if not got.size:
        return {"delivered": 0, "dropped": 0, "reordered": 0}
    counter = LinkCounter()
    for e in got[np.argsort(release[got], kind="stable")]:
        counter.see(int(seq[e]), 0, float(release[e] - t_send[e]))
    return counter.as_dict()
