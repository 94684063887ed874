"""Each draw's inbox on the batched engine when its agents step at packets of their own
(agent/batched.py: sensor links with jitter, loss or cuts): the edge messages each draw's
agents sent, released per draw by its own link model, read at the stamps of each draw's
steps, with the receivers' counters per draw (:class:`DrawInbox`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from agent.batched_links import LATENCIES, LinkStack, Read, replayed
from agent.inbox import RECENT_EDGE_MESSAGES as RECENT  # edge messages an agent keeps per link
from zswarm.scenario import Scenario


class _DrawRing:
    """One agent→agent link whose sender's draws publish at ticks and stamps of their own: the
    messages of its last ``cap`` ticks, each with a stamp per draw (NaN: that draw sent nothing
    at that tick), a release time per draw (NaN: not sent, or lost on an emulated link) and its
    fields per draw; the layout :class:`Read` and :class:`GroupMsg` read (``stamp`` (cap, M),
    ``fields`` (cap, M, ...), ``cap``)."""

    def __init__(self, M: int, cap: int) -> None:
        self.M, self.cap = M, cap
        self.n = 0  # messages (ticks with a send in some draw) so far
        self.tick = -1  # the tick of message n − 1
        self.stamp = np.full((cap, M), np.nan)
        self.release = np.full((cap, M), np.nan)
        self.fields: dict[str, np.ndarray] = {}
        self.sent = np.zeros(M, dtype=np.int64)
        self.gone = np.zeros(M, dtype=np.int64)  # messages no longer kept that each draw received

    def grow(self) -> None:
        """Twice the ticks kept (a message still in flight on the slot the next one takes)."""
        cap = 2 * self.cap
        live = np.arange(max(0, self.n - self.cap), self.n)

        def moved(old: np.ndarray, fill: float) -> np.ndarray:
            new = np.full((cap, *old.shape[1:]), fill)
            new[live % cap] = old[live % self.cap]
            return new

        self.stamp, self.release = moved(self.stamp, np.nan), moved(self.release, np.nan)
        self.fields = {k: moved(v, 0.0) for k, v in self.fields.items()}
        self.cap = cap


class DrawInbox:
    """The agent→agent links of M draws whose agents step at packets of their own (sensor links
    with jitter, loss or a delay: agent/batched.py ``_DrawSensorLinks``): a draw's agent may skip
    a tick (idle) or stamp its message with an older packet's time, so every message carries a
    stamp per draw, and a step at ``t`` reads in each draw the newest message stamped at or
    before ``t`` (Inbox.at_or_before) among the RECENT newest it has received, held or dropped
    when stale as the runtime does.  With emulated agent→agent links (``draws``), each draw's
    message is admitted to its link when sent (:meth:`LinkStack.admit` with rows: the draw's own
    n-th message takes its own numbers) and received at its release; on a reordering link a
    message released after a newer one of its draw stays out, as the receiver's LinkCounter
    keeps it out."""

    CAP = 2 * RECENT  # ticks kept per link (more while messages are in flight): a draw's RECENT newest messages are among them unless it idled half of them

    def __init__(self, sc: Scenario, M: int, ndim: dict[int, dict[str, int]], draws: Sequence[Scenario] | None = None, seeds: Sequence[int] | None = None, counters: bool = False) -> None:
        self.M = M
        self.into = {i: tuple(sc.agent(i).neighbors) for i in sc.ids}
        self.rings = {(j, i): _DrawRing(M, self.CAP) for i in sc.ids for j in sc.agent(i).neighbors}
        self.ndim = ndim
        self.max_age, self.drop = sc.stale.max_age, sc.stale.policy == "drop"
        self.stale_terms = {i: np.zeros(M, dtype=np.int64) for i in sc.ids}
        self.now = 0.0  # the tick being stepped: what has been released by then is received
        self.links: dict[tuple[int, int], LinkStack] = {}
        if draws is not None and seeds is not None:
            self.links = {k: LinkStack([d.link_spec(f"{k[0]}->{k[1]}") for d in draws], f"{k[0]}->{k[1]}", seeds) for k in self.rings}
        self.reorders = {k for k, link in self.links.items() if link.reorder.any()}  # links on which some draw reorders
        # With counters: per link, each message's release per draw (NaN: not sent or lost), the
        # draw's sequence number (-1: not sent) and its send time (the receivers' LinkCounter).
        self.counters = counters
        self.log: dict[tuple[int, int], list[tuple[np.ndarray, np.ndarray, float]]] = {k: [] for k in self.rings}
        self._counts: dict[tuple[int, int], dict[str, np.ndarray]] | None = None

    def send(self, j: int, i: int, idx: np.ndarray, stamp: float, fields: Mapping[str, Any], tick: int, m: int, t_send: float) -> None:
        """Agent j's draws ``idx`` send ``fields`` to i at tick number ``tick`` (time ``t_send``),
        stamped ``stamp``; ``fields`` per draw are a sub-stack of ``m`` rows, its first
        ``len(idx)`` those draws'."""
        ring = self.rings.get((j, i))
        if ring is None:
            return  # i does not listen to j
        if ring.tick != tick:  # the tick's first send on this link: a new message
            ring.tick = tick
            slot = ring.n % ring.cap
            if ring.n >= ring.cap and np.any(ring.release[slot] > t_send):  # still in flight in some draw (NaN compares False)
                ring.grow()
                slot = ring.n % ring.cap
            elif ring.n >= ring.cap:
                ring.gone += ~np.isnan(ring.release[slot])
            ring.stamp[slot] = np.nan
            ring.release[slot] = np.nan
            ring.n += 1
        slot = (ring.n - 1) % ring.cap
        ring.stamp[slot, idx] = stamp
        link = self.links.get((j, i))
        release = link.admit(t_send, idx) if link is not None else np.full(len(idx), t_send)
        ring.release[slot, idx] = release
        if self.counters:
            rel, seq = np.full(self.M, np.nan), np.full(self.M, -1, dtype=np.int64)
            rel[idx], seq[idx] = release, ring.sent[idx]
            self.log[(j, i)].append((rel, seq, t_send))
        ring.sent[idx] += 1
        for name, v in fields.items():
            v = np.asarray(v, dtype=float)
            if v.ndim <= self.ndim[i].get(name, v.ndim):  # one value for every draw
                v = np.broadcast_to(v, (m, *v.shape))
            buf = ring.fields.get(name)
            if buf is None:
                buf = ring.fields[name] = np.zeros((ring.cap, self.M, *v.shape[1:]))
            buf[slot, idx] = v[: len(idx)]

    def read(self, i: int, t: float, cols: np.ndarray) -> dict[int, Read]:
        """What each in-neighbour's link of ``i`` holds for a step at ``t`` in the draws ``cols``
        (a sub-stack's rows), per draw: the newest message stamped at or before ``t`` among
        those received by the tick (:attr:`now`)."""
        out = {}
        for j in self.into[i]:
            ring = self.rings[(j, i)]
            if not ring.n:
                out[j] = Read(ring, np.full(len(cols), -1), t, self.max_age, self.drop, cols)  # type: ignore[arg-type]
                continue
            live = np.arange(max(0, ring.n - ring.cap), ring.n)[:, None]
            S = ring.stamp[live[:, 0] % ring.cap][:, cols]  # (L, len(cols)), NaN: not sent
            R = ring.release[live[:, 0] % ring.cap][:, cols]
            sent = R <= self.now  # received (NaN: not sent or lost)
            if (j, i) in self.reorders:
                # A message released after a newer one of its draw is late: the receiver's
                # LinkCounter keeps it out (Inbox._deliver; ties in send order, as the heap's).
                # On a FIFO link releases never go back, so this keeps every one.
                after = np.minimum.accumulate(np.where(np.isnan(R), np.inf, R)[::-1], axis=0)[::-1]
                sent &= R <= np.vstack([after[1:], np.full((1, len(cols)), np.inf)])
            held = sent.sum(axis=0)
            c = np.cumsum(sent[::-1], axis=0)[::-1]  # per entry: the draw's messages from it on
            recent = sent & (c <= RECENT)  # the draw's RECENT newest (Inbox.recent's deque; FIFO: in release order)
            sel = np.where(recent & (S <= t), live, -1).max(axis=0)
            # Every recent one newer than t: the oldest of them (Inbox.at_or_before)
            oldest = np.where(sent & (c == np.minimum(RECENT, held)), live, -1).max(axis=0)
            fall = (sel < 0) & (held > 0)
            if np.any(fall & (held < RECENT) & (ring.gone[cols] > 0)):
                raise ValueError(f"agent {i}'s step at {t:g} s is behind every message of agent {j} the batched engine keeps ({ring.cap} ticks)")
            sel = np.where(fall, oldest, sel)
            out[j] = Read(ring, sel, t, self.max_age, self.drop, cols)  # type: ignore[arg-type]
        return out

    def link_counters(self, m: int, t_end: float) -> dict[str, dict[str, Any]]:
        """Draw ``m``'s summary ``links`` entries of the agent→agent links, as the receivers
        count them (LinkCounter) over the messages released by ``t_end``: on a FIFO link in
        sequence order, from arrays; on a reordering one replayed in release order."""
        if self._counts is None:
            self._counts = {}
            for k, log in self.log.items():
                R = np.array([x[0] for x in log]).reshape(len(log), self.M)
                Q = np.array([x[1] for x in log]).reshape(len(log), self.M)
                T = np.array([x[2] for x in log])
                D = R <= t_end  # NaN (not sent, lost) compares False
                n = D.sum(axis=0)
                first = np.where(D, Q, np.iinfo(np.int64).max).min(axis=0, initial=np.iinfo(np.int64).max)
                last = np.where(D, Q, -1).max(axis=0, initial=-1)
                self._counts[k] = {"n": n, "dropped": np.where(n > 0, last - first + 1 - n, 0), "R": R, "T": T, "D": D}
        out = {}
        for (j, i), c in self._counts.items():
            d: dict[str, Any] = {"delivered": int(c["n"][m]), "dropped": int(c["dropped"][m]), "reordered": 0}
            if self.links[(j, i)].specs[m].reorder:
                d = replayed(c["R"][:, m], np.array([x[1][m] for x in self.log[(j, i)]]), c["T"], t_end)
            elif c["n"][m]:
                got = np.flatnonzero(c["D"][:, m])[-LATENCIES:]
                q = np.percentile(c["R"][got, m] - c["T"][got], [50, 99])
                d["latency_p50_ms"], d["latency_p99_ms"] = 1e3 * float(q[0]), 1e3 * float(q[1])
            d["sent"] = int(self.rings[(j, i)].sent[m])
            out[f"{j}->{i}"] = d
        return out
