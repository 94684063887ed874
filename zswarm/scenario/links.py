"""Link emulation at the receiving end of a link: delay, jitter, dropout, bursts (seeded).

Every message that reaches a receiver first goes through its link's
:class:`LinkModel`, which decides whether it is lost and, if not, when it is
released to the receiver's inbox:

* delay: ``delay_ms`` plus a random part of scale ``jitter_ms``, either
  ``"normal"`` (N(0, jitter²), the total clipped at 0: a delay is never
  negative) or ``"exponential"`` (mean ``jitter_ms``, always ≥ 0); with
  ``reorder = false`` a message is never released before one that arrived
  earlier (FIFO: its release is pushed back), with ``reorder = true`` it may be;
* dropout: Bernoulli with probability ``drop``, and/or a Gilbert–Elliott
  two-state channel (per message: move good→bad with ``ge_p_gb``, bad→good
  with ``ge_p_bg``, then lose the message with ``ge_loss_good`` or
  ``ge_loss_bad``); the stationary loss is
  ``(p_bg·loss_good + p_gb·loss_bad)/(p_gb + p_bg)``, the mean burst
  (stay in bad) ``1/p_bg`` messages.

Each link draws from its own generators, one per purpose (:data:`PURPOSES`: the
Bernoulli loss, the Gilbert–Elliott move, the Gilbert–Elliott loss, the
jitter), seeded by ``(seed, crc32(link name), purpose)``.  Message n of a link
takes the n-th number of every stream its spec uses, whether or not the message
is lost on the way: what became of one message never shifts the numbers of the
next.  So the numbers of a link can be read ahead in blocks (:class:`LinkDraws`),
the same ones for one message at a time in ``sim`` and for a whole batch of draws
on the batched engine (agent/batched.py), and a seed gives the same losses and
delays on every engine and every run.  With everything zero a model releases
each message at its arrival time and draws no random numbers.
"""

from __future__ import annotations

import math
import zlib
from collections import deque
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import msgspec
import numpy as np

from zswarm.scenario.reading import _Ctx
from zswarm.scenario.schema import Table, bounds
from zswarm.util.quoting import did_you_mean

JITTER_KINDS = ("normal", "exponential")
_PROBABILITY = bounds(minv=0.0, maxv=1.0, problem_text="must be a probability in [0, 1]", got_float=True)


@dataclass(frozen=True, slots=True)
class LinkSpec:
    """One link's model (units: ms, probabilities in [0, 1])."""

    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    jitter: str = "normal"
    reorder: bool = False
    drop: float = 0.0
    ge_p_gb: float = 0.0
    ge_p_bg: float = 1.0
    ge_loss_good: float = 0.0
    ge_loss_bad: float = 1.0
    cuts: tuple[tuple[float, float], ...] = ()  # [start, end) intervals (s, receiver's clock) that lose everything: [[faults]] kind "cut"

    @property
    def active(self) -> bool:
        return self.delay_ms > 0 or self.jitter_ms > 0 or self.drop > 0 or self.ge_p_gb > 0 or bool(self.cuts)

    @property
    def stationary_loss(self) -> float:
        """Long-run loss probability of the Bernoulli and Gilbert–Elliott parts together."""
        ge = 0.0
        if self.ge_p_gb > 0:
            pi_bad = self.ge_p_gb / (self.ge_p_gb + self.ge_p_bg)
            ge = (1 - pi_bad) * self.ge_loss_good + pi_bad * self.ge_loss_bad
        return 1 - (1 - self.drop) * (1 - ge)

    def check(self) -> list[tuple[str, str]]:
        """Problems as ``(field, problem)`` pairs; empty when the spec is valid."""
        out = []
        for f in ("delay_ms", "jitter_ms"):
            v = getattr(self, f)
            if not (math.isfinite(v) and v >= 0):
                out.append((f, f"must be >= 0 (got {v!r})"))
        for f in ("drop", "ge_p_gb", "ge_p_bg", "ge_loss_good", "ge_loss_bad"):
            v = getattr(self, f)
            if not (math.isfinite(v) and 0 <= v <= 1):
                out.append((f, f"must be a probability in [0, 1] (got {v!r})"))
        if self.ge_p_gb > 0 and self.ge_p_bg == 0:
            out.append(("ge_p_bg", "must be > 0 when ge_p_gb > 0, or the channel never leaves the bad state (got 0)"))
        if self.jitter not in JITTER_KINDS:
            out.append(("jitter", f"must be one of {', '.join(JITTER_KINDS)}{did_you_mean(self.jitter, JITTER_KINDS)} (got {self.jitter!r})"))
        return out


# The random numbers a link may take per message, one stream each (a spec uses those of its parts).
PURPOSES = ("drop", "ge_move", "ge_loss", "jitter")
BLOCK = 256  # numbers read ahead per stream in sim (any block size gives the same numbers)


def link_seed(seed: int, name: str, purpose: str) -> list[int]:
    """The seed of link ``name``'s ("world->3", "1->3", "3->world") stream of ``purpose``."""
    return [seed % (1 << 63), zlib.crc32(name.encode()), PURPOSES.index(purpose)]


def purposes(spec: LinkSpec) -> tuple[str, ...]:
    """The streams a spec draws from, a number each per message."""
    out = []
    if spec.drop > 0:
        out.append("drop")
    if spec.ge_p_gb > 0:
        out += ["ge_move", "ge_loss"]
    if spec.jitter_ms > 0:
        out.append("jitter")
    return tuple(out)


def block(rng: np.random.Generator, purpose: str, jitter: str, n: int) -> np.ndarray:
    """The next ``n`` numbers of a stream: uniforms in [0, 1), or the jitter's standard normal
    or standard exponential variates (scaled by ``jitter_ms`` where they are used).  Numpy's
    Generator fills a block one number after the other, so blocks of any size give the numbers
    of one draw at a time (tests/unit/test_links.py)."""
    if purpose != "jitter":
        return rng.random(n)
    return rng.standard_normal(n) if jitter == "normal" else rng.standard_exponential(n)


class LinkDraws:
    """One link's streams for one seed, read ahead ``size`` numbers at a time."""

    __slots__ = ("buf", "pos", "rngs", "size", "spec")

    def __init__(self, spec: LinkSpec, name: str, seed: int, size: int = BLOCK) -> None:
        self.spec = spec
        self.rngs = {p: np.random.default_rng(link_seed(seed, name, p)) for p in purposes(spec)}
        self.buf: dict[str, list[float]] = {}
        self.pos = size
        self.size = size

    def next(self) -> dict[str, float]:
        """The numbers of the next message, by purpose."""
        if self.pos == self.size:
            self.buf = {p: block(r, p, self.spec.jitter, self.size).tolist() for p, r in self.rngs.items()}
            self.pos = 0
        k = self.pos
        self.pos += 1
        return {p: b[k] for p, b in self.buf.items()}


class LinkModel:
    """Decides, message by message, loss and release time on one link."""

    __slots__ = ("spec", "name", "draws", "bad", "last_release", "offered", "dropped", "delays", "cut")

    def __init__(self, spec: LinkSpec, name: str, seed: int) -> None:
        self.spec = spec
        self.name = name
        self.draws = LinkDraws(spec, name, seed)
        self.bad = False  # Gilbert–Elliott state
        self.last_release = -math.inf
        self.offered = 0
        self.dropped = 0
        self.cut = 0  # lost to a cut (a fault), not to the model
        self.delays: list[float] = []  # applied delays, s (release − arrival)

    def admit(self, t_arrival: float) -> float | None:
        """Release time (s, receiver's clock) of a message arriving at ``t_arrival``, or None if lost.

        The batched engine decides the same way for a stack of draws (agent/batched.py
        ``_Links.admit``): a change here is a change there."""
        self.offered += 1
        s = self.spec
        if not s.active:
            return t_arrival
        x = self.draws.next()
        lost = s.drop > 0 and x["drop"] < s.drop
        if s.ge_p_gb > 0:
            self.bad = (x["ge_move"] >= s.ge_p_bg) if self.bad else (x["ge_move"] < s.ge_p_gb)
            lost = lost or x["ge_loss"] < (s.ge_loss_bad if self.bad else s.ge_loss_good)
        if lost:
            self.dropped += 1
            return None
        # A cut after the model's draws: outside its interval the link decides exactly as without it.
        if s.cuts and any(a <= t_arrival < b for a, b in s.cuts):
            self.cut += 1
            return None
        d = s.delay_ms
        if s.jitter_ms > 0:
            d = max(0.0, d + s.jitter_ms * x["jitter"]) if s.jitter == "normal" else d + s.jitter_ms * x["jitter"]
        release = t_arrival + d * 1e-3
        if not s.reorder:
            release = max(release, self.last_release)
        self.last_release = max(self.last_release, release)
        self.delays.append(release - t_arrival)
        return release

    def counters(self) -> dict[str, float | int]:
        d: dict[str, float | int] = {"offered": self.offered, "link_dropped": self.dropped}
        if self.spec.cuts:
            d["link_cut"] = self.cut
        if self.delays:
            q = np.percentile(np.array(self.delays), [50, 99])
            d["applied_delay_p50_ms"], d["applied_delay_p99_ms"] = 1e3 * float(q[0]), 1e3 * float(q[1])
        return d


# Messages in a row behind the newest one of an incarnation after which the newest is taken
# for a stray (links are FIFO, so the sender's own stream never goes back): its sequence
# resumes from them.  One message with seq 2**53 − 1 used to pin a link for the rest of the run.
RESYNC = 8
# ...and only when they are this far behind it: emulated reordering (links.reorder, jitter
# of a few periods) puts a message behind a handful of others, never a thousand.
RESYNC_GAP = 1024


class LinkCounter:
    """Counts what arrives on one link and decides which message is the newest.

    Loss is inferred from sequence-number gaps within each incarnation of the
    sender (``inc``: a restarted process numbers from 0 again under a new one,
    and is followed at once, counted in ``restarts``).  Incarnations are start
    times (procutil.incarnation), so a message of an older incarnation than the
    one followed is a dead process's straggler or a second sender on the key:
    counted in ``old_incarnation`` and never stored, so two senders on one key
    cannot make the link flap between them (a forger alternating two
    incarnations made a link read 302 restarts and 1,587,820 dropped).  Also keeps the last 2000
    latencies (receiver's clock at arrival minus the sender's send stamp):
    meaningful when the clocks share a base, as they do for processes on one
    host with no configured offset or drift.
    """

    __slots__ = ("delivered", "dropped", "max_seq", "reordered", "latency", "inc", "restarts", "resyncs", "old_incarnation", "_behind", "_before")

    def __init__(self) -> None:
        self.delivered = 0
        self.dropped = 0  # sequence numbers skipped within an incarnation, less those that came late
        self.max_seq = -1
        self.reordered = 0
        self.latency: deque[float] = deque(maxlen=2000)
        self.inc: int | None = None
        self.restarts = 0
        self.resyncs = 0
        self.old_incarnation = 0  # messages of an incarnation older than the one followed
        self._behind = 0  # messages in a row behind max_seq
        self._before = (-1, 0)  # (max_seq, dropped) before the newest message

    def see(self, seq: int, inc: int, latency: float) -> bool:
        """Count one message; True when it is the newest of its link (store it)."""
        if self.inc is not None and inc < self.inc:
            self.old_incarnation += 1
            return False
        self.delivered += 1
        self.latency.append(latency)
        if inc != self.inc:
            # The sender restarted: messages 0..seq-1 of its new incarnation were lost.  The
            # first message a receiver sees starts its count (a receiver that started, or
            # restarted, late did not lose what was sent before it listened).
            # A new incarnation whose first message is RESYNC_GAP or more into its count is
            # counted from there too: a restarted process's first messages are not a
            # thousand lost ones, but a second sender on the key may be (1e6 "dropped").
            self.restarts += self.inc is not None
            self.max_seq = -1 if self.inc is not None and seq < RESYNC_GAP else seq - 1
            self.inc = inc
        elif seq <= self.max_seq:
            self._behind += 1
            if self._behind < RESYNC or self.max_seq - seq < RESYNC_GAP:
                self.reordered += 1
                if seq < self.max_seq:
                    self.dropped = max(0, self.dropped - 1)  # counted lost when the gap opened
                return False
            # RESYNC in a row behind: the newest was a stray.  Count as if it had never come:
            # the gap from the message before it to these (RESYNC of them) is what was lost.
            self.resyncs += 1
            self.reordered -= RESYNC - 1
            before, dropped = self._before
            self.dropped = dropped + max(0, seq - before - RESYNC)
            self.max_seq = seq
            self._behind = 0
            return True
        self._before = (self.max_seq, self.dropped)
        self.dropped += seq - self.max_seq - 1
        self.max_seq = seq
        self._behind = 0
        return True

    def as_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"delivered": self.delivered, "dropped": self.dropped, "reordered": self.reordered}
        if self.restarts:
            d["restarts"] = self.restarts
        if self.resyncs:
            d["resyncs"] = self.resyncs
        if self.old_incarnation:
            d["old_incarnation"] = self.old_incarnation
        if self.latency:
            q = np.percentile(np.array(self.latency), [50, 99])
            d["latency_p50_ms"], d["latency_p99_ms"] = 1e3 * float(q[0]), 1e3 * float(q[1])
        return d


# --------------------------------------------------------------------------- the scenario's [links]
# (read here, beside LinkSpec: the loader asks this module for its part of the file)


class LinkTable(Table, frozen=True, kw_only=True):
    """A link's model as the scenario file states it (``[links]``, ``[links.sensors]``,
    ``[links.commands]``, ``[links.per_link."j->i"]``): :class:`LinkSpec` less its cuts,
    which come from ``[[faults]]``."""

    delay_ms: Annotated[float, bounds(nonneg=True, got_float=True)] = 0.0
    jitter_ms: Annotated[float, bounds(nonneg=True, got_float=True)] = 0.0
    jitter: Literal["normal", "exponential"] = "normal"
    reorder: bool = False
    drop: Annotated[float, _PROBABILITY] = 0.0
    ge_p_gb: Annotated[float, _PROBABILITY] = 0.0
    ge_p_bg: Annotated[float, _PROBABILITY] = 1.0
    ge_loss_good: Annotated[float, _PROBABILITY] = 0.0
    ge_loss_bad: Annotated[float, _PROBABILITY] = 1.0


class LinksTable(LinkTable, frozen=True, kw_only=True):
    """``[links]``: the agent→agent edges' model, and the tables of the other kinds and of single links."""

    sensors: LinkTable = LinkTable()
    commands: LinkTable = LinkTable()
    per_link: dict[str, Any] = msgspec.field(default_factory=dict)  # link name -> a LinkTable over its kind's; names checked against the scenario's links


def _spec(c: _Ctx, t: LinkTable, f: str) -> LinkSpec:
    spec = LinkSpec(**{k: getattr(t, k) for k in LinkTable.__struct_fields__})
    for fld, problem in spec.check():  # what a type cannot say: ge_p_bg > 0 when ge_p_gb > 0
        raise c.err(f"{f}.{fld}", problem)
    return spec


def _links(c: _Ctx, t: LinksTable, names: set[str]) -> tuple[LinkSpec, LinkSpec, LinkSpec, dict[str, LinkSpec]]:
    """``[links]``: defaults of the agent→agent edges; ``[links.sensors]``: defaults of the
    world→agent sensor links (zero unless set: on-board sensors); ``[links.commands]``:
    defaults of the agent→world command links (zero unless set); ``[links.per_link."j->i"]``,
    ``"world->i"`` and ``"i->world"``: one link each, on top of its kind's defaults."""
    edges, sensors, commands = _spec(c, t, "links"), _spec(c, t.sensors, "links.sensors"), _spec(c, t.commands, "links.commands")
    over: dict[str, LinkSpec] = {}
    per = c.table(t.per_link, "links.per_link", names)
    for name, sub in per.items():
        base = sensors if name.startswith("world->") else commands if name.endswith("->world") else edges
        f = f'links.per_link."{name}"'
        over[name] = _spec(c, c.typed(sub, f, LinkTable, {k: getattr(base, k) for k in LinkTable.__struct_fields__}), f)
    return edges, sensors, commands, over
