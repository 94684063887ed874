"""What an algorithm sees at a tick: :class:`TickView`, the runtime's implementation of
:class:`zswarm.scenario.algorithm.View` (the newest data and their ages, and the timing
library's reads on this agent's sensor history)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from zswarm.math import timing

if TYPE_CHECKING:
    from agent.runtime import AgentNode

_EYE3 = np.eye(3)
_EYE3.flags.writeable = False


class _Neighbor:
    """An in-neighbour's newest message as a :class:`zswarm.scenario.algorithm.NeighborMsg`."""

    __slots__ = ("fields", "t", "t_world", "age")

    def __init__(self, fields: Mapping[str, Any], t: float, t_world: float, age: float) -> None:
        self.fields = fields
        self.t = t
        self.t_world = t_world
        self.age = age


class TickView(timing.HistoryReads):
    """What the algorithm sees at a tick (implements :class:`zswarm.scenario.algorithm.View`; the reads
    of the sensor history come from timing.HistoryReads on :meth:`_samples`).

    Built once per agent; :meth:`begin` points it at a tick.  Histories and
    per-neighbour lookups are computed at most once per tick.
    """

    def __init__(self, node: AgentNode) -> None:
        self._node = node
        a = node.program
        self.id = node.id
        self.role = a.role
        self.neighbors = a.neighbors
        self.senses = a.senses
        self.k_neighbors = a.k_neighbors
        self.out_neighbors = node.out
        self.tree_edges = node.tree_edges
        self.moving = a.moving
        self._links = {j: f"{j}->{node.id}" for j in a.neighbors}
        self.t = self.t_world = self.dt = 0.0
        self.period = 1.0 / a.clock.rate
        self.command_lead = 0.5 * self.period
        self.first = False
        self.sense: Mapping[str, Any] = {}
        self.sense_t = self.sense_t_world = 0.0
        self._cache: dict[Any, Any] = {}
        self.stale_read: set[int] = set()  # in-neighbours whose message this step read stale (the node counts them)

    def begin(self, t: float, t_world: float, sense: Mapping[str, Any], first: bool) -> None:
        self.t, self.t_world, self.sense, self.first = t, t_world, sense, first
        self.sense_t_world = sense["t"]  # a Mapping (the agent's Sense message, the batched engine's dict)
        self.sense_t = self._node.clock.local(sense["t"])
        self.dt = 0.0
        self._cache = {}
        self.stale_read.clear()

    @property
    def align(self) -> np.ndarray:
        """Body frame at the packet's acquisition time -> at this step's end: the gyro
        history's rotation (identity when the step ends at the packet, as it does
        unless the world skipped samples there)."""
        if "align" not in self._cache:
            if self.t == self.sense_t or "gyro" not in self.sense:
                self._cache["align"] = _EYE3
            else:
                self._cache["align"] = self.rotation(self.sense_t, self.t).T
        return self._cache["align"]  # type: ignore[no-any-return]

    def neighbor(self, j: int) -> _Neighbor | None:
        key = ("n", j)
        if key in self._cache:
            return self._cache[key]  # type: ignore[no-any-return]
        n = None
        # Not the newest message but the newest one stamped at or before this step:
        # the step's own measurements end at t, and pairing them with a neighbour's
        # data from after t meant extrapolating our own bearings and rotation into the
        # future (over Zenoh a neighbour's step is often 5–10 ms newer than ours).  On
        # §3.3 in sim with agent 4's sensors 6 ms late, its final attitude error was
        # 9e-5 that way against 2e-6 with none late; reading at or before: 2e-6.
        m = None if self.first else self._node.inbox.at_or_before(self._links.get(j, ""), self.t_world)
        if m is not None:
            node = self._node
            t_j = node.clock.local(m.t)
            age = self.t - t_j
            stale = age > node.stale.max_age or j in node.lost  # a lost neighbour's data are stale whatever their age
            if stale:
                self.stale_read.add(j)  # a read changes nothing outside the view: the node counts it (_count_stale)
            if not (stale and node.stale.policy == "drop"):
                n = _Neighbor(m.values, t_j, m.t, age)
        self._cache[key] = n
        return n

    def heard_all(self) -> bool:
        inbox = self._node.inbox
        return all(inbox.get(link) is not None for link in self._links.values())

    def _samples(self, name: str) -> list[tuple[float, np.ndarray]]:
        """Recent samples of a rate ("gyro", "velocity") on this agent's clock; once per tick."""
        key = ("s", name)
        if key not in self._cache:
            samples = self._node.inbox.samples(name)
            clock = self._node.clock
            if not clock.is_identity:
                samples = [(clock.local(t), w) for t, w in samples]
            self._cache[key] = samples
        return self._cache[key]  # type: ignore[no-any-return]

    def relative_attitude(self, j: int, t_world: float) -> np.ndarray | None:
        ck = ("R", j, t_world)
        if ck not in self._cache:
            inbox = self._node.inbox
            gk = ("g", "world")  # the gyro on world time, once per tick for every neighbour
            if gk not in self._cache:
                self._cache[gk] = inbox.samples("gyro")
            self._cache[ck] = timing.relative_attitude_at(inbox.samples("rel_att", j), self._cache[gk], t_world)
        return self._cache[ck]  # type: ignore[no-any-return]

    def body_vector(self, key: int | str, t_world: float, unit: bool = True) -> np.ndarray | None:
        ck = ("b", key, t_world, unit)
        if ck not in self._cache:
            hk = ("h", key)
            if hk not in self._cache:
                self._cache[hk] = self._node.inbox.vectors(key)
            self._cache[ck] = timing.body_vector_at(self._cache[hk], t_world, unit=unit)
        return self._cache[ck]  # type: ignore[no-any-return]
