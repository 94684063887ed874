"""Emulated links on the batched engine (agent/batched.py): each draw of a batch its own losses
and delays, the very numbers its ``sim`` run takes.

A link's randomness is one stream per purpose (zswarm/links.py ``PURPOSES``), message n taking
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

from zswarm.links import LinkSpec, block, link_seed, purposes
from zswarm.scenario import Scenario

AHEAD = 512  # numbers read ahead per stream and draw
LATENCIES = 2000  # the last latencies a LinkCounter keeps (zswarm/links.py)


def problem(sc: Scenario) -> str | None:
    """Which emulated links the batched engine does not run yet (None: it runs them all)."""
    if sc.links_active:
        return "emulated links between agents or from the sensors (delay, jitter, loss): the batched engine runs the agent→world command links only"
    if any(f.kind == "cut" for f in sc.faults):
        return "link cuts"
    return None


class LinkStack:
    """One link's model for M draws, each with its own seed: ``LinkModel`` draw by draw."""

    def __init__(self, spec: LinkSpec, name: str, seeds: Sequence[int]) -> None:
        self.spec = spec
        self.M = len(seeds)
        self.streams = {p: [np.random.default_rng(link_seed(s, name, p)) for s in seeds] for p in purposes(spec)}
        self.buf: dict[str, np.ndarray] = {}
        self.pos = AHEAD
        self.bad = np.zeros(self.M, dtype=bool)
        self.last_release = np.full(self.M, -math.inf)
        self.offered = 0
        self.dropped = np.zeros(self.M, dtype=np.int64)

    def _next(self) -> dict[str, np.ndarray]:
        if self.pos == AHEAD:
            self.buf = {p: np.stack([block(r, p, self.spec.jitter, AHEAD) for r in rngs]) for p, rngs in self.streams.items()}
            self.pos = 0
        k = self.pos
        self.pos += 1
        return {p: b[:, k] for p, b in self.buf.items()}

    def admit(self, t_arrival: float) -> np.ndarray:
        """Release times (M,) of a message arriving at ``t_arrival`` in every draw, NaN where lost."""
        self.offered += 1
        s = self.spec
        if not s.active:
            return np.full(self.M, t_arrival)
        x = self._next()
        lost = x["drop"] < s.drop if s.drop > 0 else np.zeros(self.M, dtype=bool)
        if s.ge_p_gb > 0:
            self.bad = np.where(self.bad, x["ge_move"] >= s.ge_p_bg, x["ge_move"] < s.ge_p_gb)
            lost |= x["ge_loss"] < np.where(self.bad, s.ge_loss_bad, s.ge_loss_good)
        self.dropped += lost
        d: Any = s.delay_ms
        if s.jitter_ms > 0:
            d = np.maximum(0.0, d + s.jitter_ms * x["jitter"]) if s.jitter == "normal" else d + s.jitter_ms * x["jitter"]
        release = t_arrival + np.multiply(d, 1e-3) * np.ones(self.M)
        if not s.reorder:
            release = np.where(lost, release, np.maximum(release, self.last_release))
        self.last_release = np.where(lost, self.last_release, np.maximum(self.last_release, release))
        release[lost] = np.nan
        return release


class Commands:
    """The command links i->world of M draws and the world's hold of their commands: the
    torque source of the batched rigid-body plant (``inputs_at``, as CommandInbox's)."""

    def __init__(self, sc: Scenario, seeds: Sequence[int], counters: bool) -> None:
        self.ids = list(sc.ids)
        self.M, self.n = len(seeds), len(self.ids)
        M, n = self.M, self.n
        self.links = [LinkStack(sc.link_spec(f"{i}->world"), f"{i}->world", seeds) for i in self.ids]
        self.policy = sc.commands
        self.counters = counters
        self.pending: list[list[tuple[np.ndarray, int, float, np.ndarray]]] = [[] for _ in self.ids]  # per agent: (release (M,), seq, stamp, u (M, 3))
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
        self.sent = np.zeros(n, dtype=np.int64)
        self.delivered = np.zeros((M, n), dtype=np.int64)
        self.first_seq = np.full((M, n), -1, dtype=np.int64)
        self.max_seq = np.full((M, n), -1, dtype=np.int64)
        self.latency: list[list[np.ndarray]] = [[] for _ in self.ids]  # per agent, per command: (M,) release − send stamp, NaN where lost

    def send(self, a: int, t: float, stamp: float, u: np.ndarray) -> None:
        """Agent (column) ``a`` sends the command ``u`` (M, 3) at its tick ``t``, stamped ``stamp``
        (the world time of the measurements it was computed from)."""
        seq = int(self.sent[a])
        self.sent[a] += 1
        release = self.links[a].admit(t)
        ok = ~np.isnan(release)
        self.delivered[:, a] += ok
        self.first_seq[:, a] = np.where(ok & (self.first_seq[:, a] < 0), seq, self.first_seq[:, a])
        self.max_seq[:, a] = np.where(ok, seq, self.max_seq[:, a])
        if self.counters:
            self.latency[a].append(release - t)
        if ok.any():
            self.pending[a].append((release, seq, stamp, np.broadcast_to(np.asarray(u, dtype=float), (self.M, 3)).copy()))
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
        S = np.array([p[1] for p in pending])
        T = np.array([p[2] for p in pending])
        for k in range(int(due.sum(axis=0).max())):
            e = order[k]  # per draw, its k-th release of this step
            take = due[e, cols]
            newer = take & (S[e] > self.seq[:, a])
            self.superseded[:, a] += take & ~newer
            if newer.any():
                self.u[newer, a] = U[e, cols][newer]
                self.stamp[newer, a] = T[e][newer]
                self.seq[newer, a] = S[e][newer]
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
            d: dict[str, Any] = {"sent": int(self.sent[a]), "delivered": int(self.delivered[m, a])}
            span = self.max_seq[m, a] - self.first_seq[m, a] + 1 if self.first_seq[m, a] >= 0 else 0
            d["dropped"] = int(span - self.delivered[m, a])
            lat = np.array([x[m] for x in self.latency[a]]) if self.latency[a] else np.zeros(0)
            lat = lat[~np.isnan(lat)][-LATENCIES:]
            if lat.size:
                d["latency_p50_ms"] = 1e3 * float(np.percentile(lat, 50))
            if self.links[a].spec.active:
                d["offered"], d["link_dropped"] = self.links[a].offered, int(self.links[a].dropped[m])
            out[f"{i}->world"] = d
        return out
