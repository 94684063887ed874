"""Faults as scenario events (``[[faults]]``, ``--fault``): their config type, how they are
read, and the actions that carry them out (both engines read :func:`fault_actions`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from zswarm.scenario.overrides import Override, parse_value
from zswarm.scenario.reading import ScenarioError, _Ctx
from zswarm.util.quoting import did_you_mean, shown

APPEND_FAULT: tuple[str | int, ...] = ("faults", -1)  # an Override's keys: append to [[faults]]


@dataclass(frozen=True, slots=True)
class Fault:
    """One ``[[faults]]`` entry (or ``--fault``): something that goes wrong at world time ``at``.

    ``kill``: SIGKILL agent ``agent``; with ``restart_at``, start it again then (a new
    incarnation, from the scenario's initial estimate).  ``stop``: SIGSTOP agent ``agent``
    (a hung process), SIGCONT ``duration`` s later.  ``router``: the router goes down for
    ``duration`` s (``zswarm run`` only: ``sim`` has none).  ``cut``: link ``link``
    ("j->i", "world->i", "i->world") loses every message for ``duration`` s (link
    emulation, both engines).
    """

    kind: str
    at: float
    agent: int | None = None
    restart_at: float | None = None
    duration: float = 0.0
    link: str | None = None

    @property
    def end(self) -> float:
        """When it is over (the restart, the SIGCONT, the router or link back); inf: never."""
        if self.kind == "kill":
            return math.inf if self.restart_at is None else self.restart_at
        return self.at + self.duration

    def describe(self) -> str:
        if self.kind == "kill":
            return f"agent {self.agent} killed at {self.at:g} s" + ("" if self.restart_at is None else f", restarted at {self.restart_at:g} s")
        if self.kind == "stop":
            return f"agent {self.agent} stopped (SIGSTOP) at {self.at:g} s for {self.duration:g} s"
        if self.kind == "router":
            return f"router down at {self.at:g} s for {self.duration:g} s"
        return f"link {self.link} cut at {self.at:g} s for {self.duration:g} s"


def fault_actions(faults: Sequence[Fault]) -> list[tuple[float, int, str, Fault]]:
    """What carrying out ``faults`` takes, in time order: ``(world time, the fault's index,
    action, fault)``, actions ``kill``, ``restart``, ``stop``, ``cont``, ``router_down``,
    ``router_up`` (a cut is the link emulation's: no action).  Both engines read this."""
    acts: list[tuple[float, int, str, Fault]] = []
    for n, f in enumerate(faults):
        if f.kind == "kill":
            acts.append((f.at, n, "kill", f))
            if f.restart_at is not None:
                acts.append((f.restart_at, n, "restart", f))
        elif f.kind == "stop":
            acts += [(f.at, n, "stop", f), (f.end, n, "cont", f)]
        elif f.kind == "router":
            acts += [(f.at, n, "router_down", f), (f.end, n, "router_up", f)]
    return sorted(acts, key=lambda a: (a[0], a[1]))


FAULT_KINDS = ("kill", "stop", "router", "cut")


_FAULT_FIELDS = {"kill": {"agent", "restart_at"}, "stop": {"agent", "duration"}, "router": {"duration"}, "cut": {"link", "duration"}}


def _faults(c: _Ctx, d: Any, duration: float, ids: set[int], link_names: set[str]) -> tuple[Fault, ...]:
    """``[[faults]]``: each checked alone (its kind's fields, inside the run, of an agent or
    a link of the scenario), then against the others (one fault at a time per agent, link,
    and for the router)."""
    if not isinstance(d, list):
        raise c.err("faults", "must be an array of tables ([[faults]])", d)
    out: list[tuple[Fault, str]] = []
    for n, raw in enumerate(d):
        f = f"faults[{n}]"
        if not isinstance(raw, dict):
            raise c.err(f, "must be a table", raw)
        kind = c.string(raw.get("kind"), f"{f}.kind") if "kind" in raw else None
        if kind not in FAULT_KINDS:
            raise c.err(f"{f}.kind", f"must be one of {', '.join(FAULT_KINDS)}{did_you_mean(kind, FAULT_KINDS)}", kind) if kind is not None else c.err(f"{f}.kind", "missing")
        extra = _FAULT_FIELDS[kind]
        t = c.table(raw, f, {"kind", "at"} | extra, {"kind", "at"} | (extra - {"restart_at"}))
        at = c.num(t["at"], f"{f}.at", nonneg=True)
        if at >= duration:
            raise c.err(f"{f}.at", f"must be within the run (< scenario.duration = {duration:g} s)", t["at"])
        agent = restart_at = link = None
        dur = 0.0
        if "agent" in t:
            agent = c.integer(t["agent"], f"{f}.agent")
            if agent not in ids:
                raise c.err(f"{f}.agent", f"no such agent (ids: {sorted(ids)})", agent)
        if "restart_at" in t:
            restart_at = c.num(t["restart_at"], f"{f}.restart_at")
            if not at < restart_at < duration:
                raise c.err(f"{f}.restart_at", f"must be after at = {at:g} s and before the end ({duration:g} s)", t["restart_at"])
        if "duration" in t:
            dur = c.num(t["duration"], f"{f}.duration", nonneg=kind == "router", positive=kind != "router")
        if "link" in t:
            link = c.string(t["link"], f"{f}.link")
            if link not in link_names:
                raise c.err(f"{f}.link", f"not a link of this scenario (e.g. {', '.join(sorted(link_names)[:4])})", link)
        fault = Fault(kind, at, agent, restart_at, dur, link)
        # An agent dead to the end may not be stopped or killed again, and so on: one at a time.
        who = ("agent", agent) if agent is not None else ("link", link) if link is not None else ("router", 0)
        for other, g in out:
            same = ("agent", other.agent) if other.agent is not None else ("link", other.link) if other.link is not None else ("router", 0)
            if same == who and fault.at <= other.end and other.at <= fault.end:
                raise c.err(f, f"overlaps {g} ({other.describe()}): one fault at a time per {who[0]}")
        out.append((fault, f))
    return tuple(sorted((f for f, _ in out), key=lambda f: f.at))


def fault_override(text: str, flag: str = "--fault") -> Override:
    """``--fault KIND,FIELD=VALUE,...`` as an override that appends a ``[[faults]]`` entry."""
    return Override(f"{flag} {text}", "faults[+]", APPEND_FAULT, parse_fault(text, flag))


def parse_fault(text: str, flag: str = "--fault") -> dict[str, Any]:
    """``--fault KIND,FIELD=VALUE,...`` (e.g. ``kill,agent=5,at=10,restart_at=15``) as the
    table of a ``[[faults]]`` entry (checked with the rest of the scenario)."""
    kind, *rest = [p.strip() for p in text.split(",")]
    if not kind or "=" in kind:
        raise ScenarioError(f"{flag} {shown(text)}: expected KIND,FIELD=VALUE,... (e.g. kill,agent=5,at=10,restart_at=15; kinds: {', '.join(FAULT_KINDS)})")
    table: dict[str, Any] = {"kind": kind}
    for p in rest:
        k, eq, v = p.partition("=")
        if not eq or not k.strip():
            raise ScenarioError(f"{flag} {shown(text)}: {p!r}: expected FIELD=VALUE")
        table[k.strip()] = parse_value(v.strip())
    return table
