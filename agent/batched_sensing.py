"""The batched engine's world side (agent/batched.py): the sensor links (a delay shared by every
draw: :class:`_SensorLinks`; jitter, loss and cuts per draw: :class:`_DrawSensorLinks`), the
world's noise drawn per draw in its order (:class:`_Noise`, :func:`_measure_draws`), and the
torques the plant holds."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from agent import batched_links
from agent.batched_arrays import HISTORY, Unsupported
from agent.inbox import since, step_ends
from world.node import Sensing
from world.sensors import projective_bearing
from zswarm.math.so3 import exp, mul
from zswarm.scenario.links import LinkModel, LinkSpec


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


class _Torques:
    """The plant's command source: the torques the agents' last ticks sent, held (ZOH)."""

    def __init__(self, n_bodies: int) -> None:
        self.u = np.zeros((n_bodies, 3))

    def inputs_at(self, s: float, h: float) -> np.ndarray:
        return self.u


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
