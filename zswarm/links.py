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

Each link draws from its own generator seeded by ``(seed, crc32(link name))``,
so a seed gives the same losses and delays on every engine and every run.
With everything zero a model releases each message at its arrival time and
draws no random numbers.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

JITTER_KINDS = ("normal", "exponential")


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

    @property
    def active(self) -> bool:
        return self.delay_ms > 0 or self.jitter_ms > 0 or self.drop > 0 or self.ge_p_gb > 0

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
            out.append(("jitter", f"must be one of {', '.join(JITTER_KINDS)} (got {self.jitter!r})"))
        return out


def link_seed(seed: int, name: str) -> list[int]:
    """The generator seed of link ``name`` ("world->3", "1->3", ...)."""
    return [seed % (1 << 63), zlib.crc32(name.encode())]


class LinkModel:
    """Decides, message by message, loss and release time on one link."""

    __slots__ = ("spec", "name", "rng", "bad", "last_release", "offered", "dropped", "delays")

    def __init__(self, spec: LinkSpec, name: str, seed: int) -> None:
        self.spec = spec
        self.name = name
        self.rng = np.random.default_rng(link_seed(seed, name))
        self.bad = False  # Gilbert–Elliott state
        self.last_release = -math.inf
        self.offered = 0
        self.dropped = 0
        self.delays: list[float] = []  # applied delays, s (release − arrival)

    def admit(self, t_arrival: float) -> float | None:
        """Release time (s, receiver's clock) of a message arriving at ``t_arrival``, or None if lost."""
        self.offered += 1
        s = self.spec
        if not s.active:
            return t_arrival
        lost = False
        if s.drop > 0 and self.rng.random() < s.drop:
            lost = True
        if s.ge_p_gb > 0:
            flip = self.rng.random()
            self.bad = (flip >= s.ge_p_bg) if self.bad else (flip < s.ge_p_gb)
            if self.rng.random() < (s.ge_loss_bad if self.bad else s.ge_loss_good):
                lost = True
        if lost:
            self.dropped += 1
            return None
        d = s.delay_ms
        if s.jitter_ms > 0:
            if s.jitter == "normal":
                d = max(0.0, d + self.rng.normal(0.0, s.jitter_ms))
            else:
                d = d + self.rng.exponential(s.jitter_ms)
        release = t_arrival + d * 1e-3
        if not s.reorder:
            release = max(release, self.last_release)
        self.last_release = max(self.last_release, release)
        self.delays.append(release - t_arrival)
        return release

    def counters(self) -> dict[str, float | int]:
        d: dict[str, float | int] = {"offered": self.offered, "link_dropped": self.dropped}
        if self.delays:
            q = np.percentile(np.array(self.delays), [50, 99])
            d["applied_delay_p50_ms"], d["applied_delay_p99_ms"] = 1e3 * float(q[0]), 1e3 * float(q[1])
        return d
