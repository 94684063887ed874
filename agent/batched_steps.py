"""The batched engine's agent ticks when each draw steps at packets of its own (agent/batched.py:
sensor links with jitter, loss or cuts): the draws' steps grouped where they share what the law
takes as one value (:func:`_tick_draws`), stepped on sub-stacks of those draws (:func:`_take`,
:func:`_put`), apart where their histories differ, and what they publish sent per draw."""

from __future__ import annotations

import dataclasses
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from agent import batched_inbox, batched_links
from agent.batched_arrays import HistorySplit, Unsupported, _put, _spread, _sub_rows, _take, _where
from agent.batched_sensing import _DrawSensorLinks
from agent.batched_view import BatchedView, _Deep
from zswarm.families.measure import Published


def _tick_draws(
    i: int,
    a: int,
    t_tick: float,
    n_tick: int,
    links: _DrawSensorLinks,
    store: Mapping[int, dict[str, Any]],
    v: BatchedView,
    mod: ModuleType,
    g: Any,
    part: Any,
    states: dict[int, Any],
    hybrid: bool,
    jumps: np.ndarray,
    agent_jumps: np.ndarray,
    inbox: batched_inbox.DrawInbox,
    u: np.ndarray | batched_links.Commands,
    sent_edges: np.ndarray,
    sent_commands: np.ndarray,
    published: Published | None = None,
) -> None:
    """Agent i's tick at ``t_tick`` in M draws whose sensor links lose and delay packets each its
    own way (_DrawSensorLinks): each draw takes its steps (AgentNode.tick and _advance) on its
    own packets and history, reads its neighbours' messages stamped at or before each step
    (DrawInbox), and after its last step sends what it publishes, stamped with that step's
    time; idle draws send nothing.  ``u``: the torques the plant holds, (M, n, 3), or the
    command links (each draw's agent sends its own commands: Commands.send with rows).

    The draws' n-th steps are stepped together where they share what the law takes as one
    value (the step's start and end, its packet, whether it is the tick's last: dt, t and the
    command lead), on a sub-stack of those draws only (:func:`_take`, :func:`_put`); a step
    whose law reads the sensor history is stepped apart for each history the draws hold."""
    links.deliver(t_tick)
    plans = links.plan(t_tick)
    merged: dict[tuple[Any, ...], list[int]] = {}
    for n_p, (mode, _G, t_step, ends, held) in enumerate(plans):
        prev = t_step
        for r, (t_e, k_e) in enumerate(ends):
            # A step between packets reads the history (View.relative_attitude): by history at once
            apart = tuple(held) if t_e != k_e * links.sample_dt else ()
            merged.setdefault((mode, prev, t_e, k_e, r == len(ends) - 1, apart), []).append(n_p)
            prev = t_e
    # In the order of their ends: a draw's steps end later and later, so each step comes after
    # the draw's step before it, whichever of its tick's steps it is.
    c = _AgentTick(i, a, t_tick, n_tick, store, v, mod, g, part, states, hybrid, jumps, agent_jumps, inbox, u, sent_edges, sent_commands, published, links=links)
    for (mode, prev, t_e, k_e, last, _), members in sorted(merged.items(), key=lambda kv: (kv[0][2], kv[0][1])):
        _round_apart(c, [plans[n_p] for n_p in members], mode, prev, t_e, k_e, last)


def _round_apart(c: _AgentTick, plans: Sequence[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]], mode: str, prev: float, t_e: float, k_e: int, last: bool) -> None:
    """_round_step on the draws of ``plans``; where a read of the sensor history needs them
    apart (HistorySplit, raised before the step changes anything), per history, and where
    the draws of one plan still differ (a shared truth's deeper histories, _Deep), draw by draw."""
    histories = {tuple(p[4]) for p in plans}
    try:
        _round_step(c, plans, mode, prev, t_e, k_e, last, len(histories) > 1)
    except HistorySplit:
        if len(histories) > 1:
            for h in histories:
                _round_apart(c, [p for p in plans if tuple(p[4]) == h], mode, prev, t_e, k_e, last)
        else:
            for d in np.flatnonzero(np.logical_or.reduce([p[1] for p in plans])):
                one = np.zeros_like(plans[0][1])
                one[d] = True
                src = next(p for p in plans if p[1][d])
                _round_step(c, [(src[0], one, src[2], src[3], src[4])], mode, prev, t_e, k_e, last, False)


@dataclass(slots=True)
class _AgentTick:
    """What agent i's steps of one tick read and write (_tick_draws' arguments), and ``done``:
    this tick's outputs so far, (draws, their sub-stack's outputs, its rows)."""

    i: int
    a: int
    t_tick: float
    n_tick: int
    store: Mapping[int, dict[str, Any]]
    v: BatchedView
    mod: ModuleType
    g: Any
    part: Any
    states: dict[int, Any]
    hybrid: bool
    jumps: np.ndarray
    agent_jumps: np.ndarray
    inbox: batched_inbox.DrawInbox
    u: np.ndarray | batched_links.Commands
    sent_edges: np.ndarray
    sent_commands: np.ndarray
    published: Published | None  # on a shared truth: the estimates the draws publish, for its measure
    links: _DrawSensorLinks | None = None  # the agent's sensor link (its draws' inboxes: _Deep)
    done: list[tuple[np.ndarray, Any, int]] = dataclasses.field(default_factory=list)


def _round_step(c: _AgentTick, plans: Sequence[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]], mode: str, prev: float, t_e: float, k_e: int, last: bool, mixed: bool) -> None:
    """One step, from ``prev`` to the packet ``k_e`` at ``t_e``, of the draws of ``plans``
    (_tick_draws); ``last``: their tick's last, after which they publish.  ``mixed``: the draws
    hold different histories (reading it raises HistorySplit)."""
    i, v, states, inbox, part = c.i, c.v, c.states, c.inbox, c.part
    M = len(c.jumps)
    idx = np.flatnonzero(np.logical_or.reduce([p[1] for p in plans]))
    whole = len(idx) == M
    rows = idx if whole else _sub_rows(idx)
    m, n = len(rows), len(idx)
    sub = {i: states[i] if whole else _take(states[i], rows, M)}
    g_sub = c.g if whole else _take_gains(c.g, rows, M)
    sub_jumps, sub_agent, stale = np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.int64)
    _point_view(c, [tuple(p[4]) for p in plans], t_e, k_e, mode == "first", None if whole else rows, mixed)
    out = None
    try:
        if mode == "first":
            v.command_lead = max(0.0, c.t_tick - t_e) + 0.5 * v.period  # AgentNode._begin
            if part is not None:
                reads = inbox.read(i, t_e, rows)  # heard_all: what has come (neighbor() reads nothing at the first step)
                if c.hybrid:  # the jump sets on the initial state; the outputs are not sent (AgentNode._advance)
                    v.dt = 0.0
                    _step_groups(part, sub, i, v, g_sub, 0.0, sub_jumps, sub_agent, reads, stale)
                if 0.0 < t_e <= 0.5:
                    v.dt = t_e  # the initial estimate (at t = 0) brought to the first packet: prediction only
                    _step_groups(part, sub, i, v, g_sub, t_e, sub_jumps, sub_agent, reads, stale)
        else:
            # only the last step's command is sent (AgentNode._advance): a catch-up step's has no lead
            v.command_lead = max(0.0, c.t_tick - t_e) + 0.5 * v.period if last else 0.0
            v.dt = t_e - prev
            if part is not None:
                out = _step_groups(part, sub, i, v, g_sub, t_e - prev, sub_jumps, sub_agent, inbox.read(i, t_e, rows), stale)
        c.jumps[idx] += sub_jumps[:n]
        c.agent_jumps[idx] += sub_agent[:n]
        inbox.stale_terms[i][idx] += stale[:n]
        states[i] = sub[i] if whole else _put(states[i], sub[i], idx, M, m)
        if out is not None:
            c.done.append((idx, out, m))
        if not last:
            return
        if out is None and mode != "first":
            # No outputs at this step: the newest of an earlier step this tick, per draw (else None)
            had = np.zeros(M, dtype=bool)
            for d, _, _ in c.done:
                had[d] = True
            if had[idx].any():
                for part_idx in (idx[had[idx]], idx[~had[idx]]):
                    if part_idx.size:
                        _publish_apart(c, part_idx, c.done if had[part_idx[0]] else [], plans, t_e, k_e)
                return
        try:
            pub = c.mod.publish(sub[i], out, v)  # publish reads the view too (a bearing at a stamp)
        except HistorySplit:  # ... in a history the draws do not share: published apart, per history
            _publish_apart(c, idx, c.done if out is not None else [], plans, t_e, k_e)
            return
        _send(c, idx, m, pub)
    finally:
        v._packets = v.history = v.mixed = v.deep = None


def _point_view(c: _AgentTick, held: list[tuple[int, ...]], t_e: float, k_e: int, first: bool, rows: np.ndarray | None, mixed: bool) -> None:
    """Point the view at a step ending at ``t_e`` on the packet ``k_e`` for the draws ``rows``
    (a sub-stack's; None: all), their sensor history the samples ``held`` (each plan's; more
    than one: ``mixed``, read as one where they agree)."""
    store, M = c.store, len(c.jumps)

    def take(k: int) -> dict[str, Any]:
        return store[k] if rows is None else _take(store[k], rows, M)

    def history() -> deque[dict[str, Any]]:
        # The draws' inbox history (the packets from the one at or before their tick's first step on)
        if mixed:
            raise HistorySplit
        return deque(take(k) for k in held[0])

    c.v.begin(t_e, take(k_e), first=first)
    c.v._packets, c.v.history = None, history
    if c.links is not None and c.links.deep:  # each draw its own last HISTORY packets (_Deep)
        deep = _Deep(c.links, np.arange(M) if rows is None else rows, store, M)
        c.v.deep = deep
        c.v.history = deep.history
    elif mixed:
        c.v.mixed = (held, store.__getitem__, lambda ks: [take(k) for k in ks])


def _publish_apart(c: _AgentTick, idx: np.ndarray, done: list[tuple[np.ndarray, Any, int]], plans: Sequence[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]], t_e: float, k_e: int) -> None:
    """_publish_rows for the draws ``idx``: together, else (HistorySplit: publish read a history
    they do not share, before sending anything) per history, else draw by draw."""
    mine = [p for p in plans if p[1][idx].any()]
    histories = {tuple(p[4]) for p in mine}
    try:
        _publish_rows(c, idx, done, mine, t_e, k_e, len(histories) > 1)
    except HistorySplit:
        if len(histories) > 1:
            for h in histories:
                group = [p for p in mine if tuple(p[4]) == h]
                sub = idx[np.logical_or.reduce([p[1] for p in group])[idx]]
                _publish_apart(c, sub, done, group, t_e, k_e)
        else:
            for d in idx:
                _publish_rows(c, np.array([d]), done, mine, t_e, k_e, False)


def _publish_rows(c: _AgentTick, idx: np.ndarray, done: list[tuple[np.ndarray, Any, int]], plans: Sequence[tuple[str, np.ndarray, float, list[tuple[float, int]], list[int]]], t_e: float, k_e: int, mixed: bool) -> None:
    """Publish for the draws ``idx`` (of the step of ``plans`` ending at ``t_e``) from their
    state, with their newest outputs of this tick (``done``, oldest first; none: None), the
    view pointed at their rows."""
    M = len(c.jumps)
    rows = _sub_rows(idx)
    outputs = None
    for d, out, m in done:
        outputs = _spread(out, d, M, m) if outputs is None else _put(outputs, out, d, M, m)
    sub_out = None if outputs is None else _take(outputs, rows, M)
    mine = [p for p in plans if p[1][idx].any()]
    _point_view(c, [tuple(p[4]) for p in mine], t_e, k_e, False, rows, mixed and len({tuple(p[4]) for p in mine}) > 1)
    _send(c, idx, len(rows), c.mod.publish(_take(c.states[c.i], rows, M), sub_out, c.v))


def _send(c: _AgentTick, idx: np.ndarray, m: int, pub: Any) -> None:
    """What the draws ``idx`` publish (a sub-stack of ``m`` rows): their messages into the
    inbox stamped with the step's time, their torques into the plant's (``u``, (M, n, 3)) or
    onto their command links (each draw its own next command: Commands.send)."""
    if pub is None:
        return
    t_stamp = c.v.t_world if pub.t is None else pub.t
    c.sent_edges[idx] += len(pub.edges)
    if pub.command is not None:
        c.sent_commands[idx] += 1
        if "tau" in pub.command:
            tau = np.broadcast_to(np.asarray(pub.command["tau"], dtype=float), (m, 3))[: len(idx)]
            if isinstance(c.u, batched_links.Commands):
                c.u.send(c.a, c.t_tick, t_stamp, tau, idx)  # arrives at the tick, as the world stamps it
            else:
                c.u[idx, c.a] = tau
    for j, fields in pub.edges.items():
        c.inbox.send(c.i, j, idx, t_stamp, fields, c.n_tick, m, c.t_tick)
    if c.published is not None and pub.estimate is not None:
        c.published.put(idx, t_stamp, pub.estimate, m)


def _take_gains(g: Any, rows: np.ndarray, M: int) -> Any:
    """The Gains of a sub-stack: the gains stacked per draw (draw_gains: (M, 1)) gathered."""
    per = {f.name: getattr(g, f.name)[rows] for f in dataclasses.fields(g) if isinstance(getattr(g, f.name), np.ndarray) and getattr(g, f.name).shape == (M, 1)}
    return dataclasses.replace(g, **per) if per else g


def _step(part: Any, states: dict[int, Any], i: int, view: BatchedView, gains: Any, dt: float, jumps: np.ndarray, agent_jumps: np.ndarray) -> Any:
    inputs = part.inputs(view, gains)
    if inputs is None:
        return None
    states[i], outputs = part.step(states[i], inputs, dt, gains)
    _count_jumps(outputs, view.declared_jumps, jumps, agent_jumps, np.ones(len(jumps), dtype=bool))
    return outputs


def _count_jumps(outputs: Any, declared: Mapping[str, Any], jumps: np.ndarray, agent_jumps: np.ndarray, G: np.ndarray) -> None:
    """Count a step's jumps in the draws of ``G``, as its algorithm's SPEC.jumps declares them
    (``declared``: the outputs' attribute -> Jumps; of an edge's variable in ``jumps``, of the
    agent's own in ``agent_jumps``): a jump's value after is finite in the draws that jumped
    (NaN elsewhere)."""
    for attr, decl in declared.items():
        count = jumps if decl.owner == "edge" else agent_jumps
        for jump in getattr(outputs, attr, ()):
            after = jump[-1]
            count += (np.isfinite(np.asarray(after, dtype=float)).reshape(count.shape) if np.ndim(after) else True) & G


def _step_groups(part: Any, states: dict[int, Any], i: int, view: BatchedView, gains: Any, dt: float, jumps: np.ndarray, agent_jumps: np.ndarray, reads: Mapping[int, batched_links.Read], stale_terms: np.ndarray, base: np.ndarray | None = None) -> Any:
    """One step of agent i's draws over emulated links: the draws differ in which neighbours'
    messages they hold (lost, late, stale) and in those messages' stamps, so they are stepped in
    groups that share what the law reads: which in-neighbours are present (and heard from at
    all), and, where a law reads a neighbour's stamp or age (batched_links.Split), that stamp.
    Each group is stepped on the whole stack (every draw's own message, the others' filled in)
    and its draws' results kept; one group when every draw holds the same, as on perfect links.
    ``base``: only these draws step (the others keep their state: _DrawSensorLinks' plans)."""
    M = len(jumps)
    base = np.ones(M, dtype=bool) if base is None else base
    key = np.stack([np.stack([r.present, r.has]) for r in reads.values()]).reshape(-1, M).T if reads else None
    if key is not None and not (key[base] == key[base][0]).all():
        _, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        queue = [G for G in (base & (inv == u) for u in range(int(inv.max()) + 1)) if G.any()]
    else:
        queue = [base]
    s0 = states[i]
    state, outputs, nones = s0, None, np.zeros(M, dtype=bool)
    try:
        while queue:
            G = queue.pop()
            view.group, view.read_js = (reads, G), set()
            view._cache.clear()
            try:
                inputs = part.inputs(view, gains)
                st, out = (s0, None) if inputs is None else part.step(s0, inputs, dt, gains)
            except batched_links.Split as sp:
                stamp = reads[sp.j].stamp
                queue += [G & (stamp == u) for u in np.unique(stamp[G])]
                continue
            for j in view.read_js:
                r = reads[j]
                stale_terms += G & r.has & r.stale
            every = G is base and bool(base.all())  # one group of every draw: its results whole
            state = st if every else _where(G, st, state, M)
            if out is None:
                nones |= G
                continue
            outputs = out if outputs is None or every else _where(G, out, outputs, M)
            _count_jumps(out, view.declared_jumps, jumps, agent_jumps, G)
    finally:
        view.group = None
        view._cache.clear()
    if outputs is not None and (nones & base).any():
        raise Unsupported(f"agent {i}: its law had inputs in some draws and none in others at one tick (the batched engine cannot publish both)")
    states[i] = state
    return outputs


# A sub-stack has at least this many rows (a group's draws, then copies of its first): its draw
# axis is then never one of a law's own small axes (3-vectors, quaternions) when it is read back.