"""The batched lockstep engine: M draws of one scenario stepped together (issue 31).

``zswarm sim`` runs one draw as processes exchanging messages; a Monte-Carlo basin or sweep
runs thousands of draws that share one schedule (the same clocks, sensor grid and graph;
only the agents' starts differ).  Here those draws are stepped *together*: every state and
measurement carries a leading draw axis, the world's plant integrates all M·n bodies at
once (world/plant.py's RigidBodyPlant, the same scheme and step), and each agent's law is
the **same algorithm module** as on ``sim``: its ``inputs``, ``step`` and ``publish`` are
called once per agent and tick on arrays of M draws (the laws broadcast over a leading
axis: agent/algorithms/attitude_sync_terms.py, zswarm/math/so3.py).

What ``sim`` does at a tick is reproduced, in its order: at a time where the world samples
and agents tick, the world first (it integrates up to t under the torques held since the
last ticks, then measures), then the agents by id, each seeing the edge messages of the
agents before it at this tick and of those after it at the last; a command acts from its
tick on (zero-order hold); an agent's first tick (t = 0) tests a hybrid scheme's jump sets
and sends no command; a step's command is evaluated half a period ahead (View.command_lead).
So a draw here and the same draw on ``sim`` differ by round-off only (the batched linear
algebra sums in another order), which the dynamics then carries: tests/component/test_batched.py.

Lockstep needs what it says: every agent on the same clock with no jitter, drift or offset,
its ticks on the sensor grid, no faults but link cuts (the
agent→agent and command links are emulated draw by draw: agent/batched_links.py, _step_groups;
a sensor delay, the same on every sensor link, is stepped as the runtime steps it: _SensorLinks;
sensor jitter, loss and cuts, each draw at its own packets: _DrawSensorLinks, _tick_draws; on a
prescribed truth each draw's estimates are measured at their own stamps by its family's measure,
and its laws read its own sensor history, _Deep, which ``--engine auto`` leaves to sim: prefer_sim),
leaders (if any) that only publish,
sensors of the kinds implemented here (SENSORS; on a truth per draw PER_DRAW_SENSORS), and
the plant its experiment family measures it on here (zswarm.families.contract.Batched: rigid bodies, a
truth per draw; or the prescribed motion, the same in every draw, so it is simulated and
measured once, by the world's own Sensing, and its measurements
are shared), and an algorithm whose SPEC says its functions broadcast (``batched=True``).
The noise is drawn from the world's generators in the world's order, each draw's from its own
seed and with its own variances (on a shared truth the noisy measurements then get a draw
axis; draws of one seed and variances share one draw of it).
:func:`problem` says which of these a scenario lacks; the commands then run it on ``sim`` per
draw.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType, ModuleType, SimpleNamespace
from typing import Any, cast

import numpy as np

from agent import batched_inbox, batched_links
from agent.batched_arrays import HISTORY, Unsupported, _same, stack
from agent.batched_sensing import NOISES, _DrawSensorLinks, _measure_draws, _Noise, _SensorLinks, _Torques, _with_draws
from agent.batched_steps import _step, _step_groups, _tick_draws
from agent.batched_view import BatchedView
from agent.inbox import RECENT_EDGE_MESSAGES
from world.motion import prescribed, prescribed_key
from world.node import PLAN_SAMPLES, Sensing
from world.plant import RigidBodyPlant
from zswarm.families import contract as zswarm_family
from zswarm.families.measure import Context, Published, Result, Truth
from zswarm.math.so3 import exp, mul
from zswarm.scenario import Scenario, ScenarioText
from zswarm.scenario.agent_config import Estimate
from zswarm.scenario.algorithm import jumps as has_jumps
from zswarm.scenario.links import LinkSpec
from zswarm.scenario.programs import agent_program, world_program

SENSORS = frozenset({"gyro", "rel_att", "attitude", "bearings", "position", "velocity"})  # what the batched world measures
PER_DRAW_SENSORS = frozenset({"gyro", "rel_att", "attitude"})  # ... on a truth per draw (rigid bodies)
# The plants the draws run on here (a family's Batched.plant): rigid bodies (5.1), a truth per
# draw; the prescribed motion, the same truth for every draw (simulated once, its measurements
# shared by the draws).
PLANTS = ("rigid_body", "prescribed")
def problem(sc: Scenario) -> str | None:
    """Why ``sc`` cannot run on the batched engine (None: it can)."""
    spec = sc.info
    if not getattr(spec, "batched", False):
        return f"{sc.algorithm}'s functions are not declared to broadcast over draws (SPEC.batched)"
    if sc.leader_module is not None:
        lead = sc.module_for("leader").SPEC
        if not getattr(lead, "batched", False):
            return f"the leaders' {sc.leader_module}: its functions are not declared to broadcast over draws (SPEC.batched)"
        if lead.parts:
            return f"the leaders' {sc.leader_module} steps (the batched engine runs leaders that only publish)"
    declared = zswarm_family.of(sc).batched
    if declared is None:
        return f"its experiment family {spec.report!r} declares no measure on the batched engine (zswarm.families.contract.Batched)"
    measure = declared.plant
    if measure not in PLANTS:
        return f"the {spec.report!r} family's {measure!r} plant (the batched engine runs {', '.join(PLANTS)})"
    if sc.plant != measure:
        return f"the {sc.plant!r} plant with the {spec.report!r} family (the batched engine runs it on the {measure!r} plant)"
    if (declared.truth if measure == "rigid_body" else declared.stamps if _per_draw(sc) else declared.ticks) is None:
        return f"the {spec.report!r} family measures no such draws on the batched engine (zswarm.families.contract.Batched: no {'truth' if measure == 'rigid_body' else 'stamps' if _per_draw(sc) else 'ticks'} measure)"
    need = frozenset().union(*(sc.sensors_of(i) for i in sc.ids))
    have = SENSORS if measure == "prescribed" else PER_DRAW_SENSORS
    if need - have:
        return f"the sensor(s) {', '.join(sorted(need - have))} (the batched world measures {', '.join(sorted(have))} on the {measure!r} plant)"
    if len(spec.parts) != 1 or spec.parts[0].rate is not None:
        return "an algorithm of several parts or with a part rate of its own"
    clocks = {a.clock for a in sc.agents}
    if len(clocks) != 1:
        return "agents on different clocks"
    (c,) = clocks
    if c.jitter or c.drift_ppm or c.offset:
        return "clock jitter, drift or offset"
    ratio = sc.sensor_rate / c.rate
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        return f"agent ticks off the sensor grid ({c.rate:g} Hz against {sc.sensor_rate:g} Hz)"
    if any(f.kind != "cut" for f in sc.faults):
        return "faults (other than link cuts)"
    if sc.part_rate_scale != 1.0:
        return "scaled part rates"
    if sc.stale.max_age < 1.0 / c.rate:
        return "a stale-data max_age shorter than a clock period (lockstep serves every message as fresh)"
    return None


def prefer_sim(sc: Scenario) -> str | None:
    """Why ``--engine auto`` runs ``sc`` on sim though this engine runs it (None: it does not).

    Sensor links with jitter, loss or cuts on a prescribed truth (the §3 and §4.5 observers):
    each draw steps at packets of its own and its laws read its own sensor history around their
    neighbours' stamps, so the draws are stepped in many small groups and read in parts
    (_Deep).  The rows are sim's, but measured at 0.72 s of CPU a draw for 2 s of §4.5 hybrid
    (20 % loss, 3 ms jitter, M = 400) against 0.75 s on sim (its processes' start included): no faster."""
    if sc.plant == "prescribed" and _per_draw(sc):
        return "sensor links with jitter, loss or cuts on a prescribed truth: the batched engine runs them (--engine batched, the same rows) but no faster than sim"
    return None


def _per_draw(sc: Scenario) -> bool:
    """Each draw's agents step at packets of their own (run's ``per_draw``)."""
    return batched_links.per_draw_sensors(sc) or (sc.link_spec(f"world->{sc.ids[0]}").active and any(sc.link_spec(f"{j}->{a.id}").active for a in sc.agents for j in a.neighbors))


_NO_TEXT = ScenarioText("")
_NO_LINKS: Mapping[str, LinkSpec] = MappingProxyType({})


def schedule(sc: Scenario) -> Scenario:
    """What the draws of one batch must share: the scenario without what may differ per draw (its
    agents' starts R_i(0), ω_i(0), J_i and initial estimates, the noise variances, the seed, the
    gains its algorithm lets each draw have (SPEC.draw_gains), its TOML, and the models of its
    agent→agent and command links: batched_links takes each draw's own)."""
    draw = sc.info.draw_gains  # gains each draw may have its own value of (SPEC.draw_gains)
    agents = tuple(dataclasses.replace(a, R=(), omega=cast(Any, ()), J=None, estimate=Estimate(), gains=_without(a.gains, draw)) for a in sc.agents)
    # The sensor links stay: every draw of a batch steps at the same packets (_SensorLinks).
    sensor = MappingProxyType({k: v for k, v in sc.link_overrides.items() if k.startswith("world->")}) if sc.link_overrides else _NO_LINKS
    sc = dataclasses.replace(sc, links=LinkSpec(), command_links=LinkSpec(), link_overrides=sensor)
    return dataclasses.replace(sc, agents=agents, source=_NO_TEXT, seed=0, gains=_without(sc.gains, draw), **{f"{f}_var": 0.0 for f in NOISES})


def _without(gains: Mapping[str, float], names: frozenset[str]) -> Mapping[str, float]:
    return MappingProxyType({k: v for k, v in gains.items() if k not in names}) if names else gains


def draw_gains(module: ModuleType, values: Sequence[Any]) -> Any:
    """One agent's Gains for M draws: the first draw's, where a gain differs between draws its M
    values as a stack (M, 1) (it multiplies (M, 3) vectors only: SPEC.draw_gains)."""
    g0 = values[0]
    stacked: dict[str, Any] = {}
    for f in dataclasses.fields(g0):
        col = [getattr(v, f.name) for v in values]
        if all(_same(col[0], x) for x in col[1:]):
            continue
        if f.name not in module.SPEC.draw_gains:
            raise Unsupported(f"draws whose gain {f.name} differs ({module.__name__.rsplit('.', 1)[-1]} takes one value of it for all the draws of a batch)")
        stacked[f.name] = np.array(col, dtype=float)[:, None]
    return dataclasses.replace(g0, **stacked) if stacked else g0


def group(sc: Scenario) -> tuple[Any, ...]:
    """What runs must share to be stepped in one batch (a sweep's grouping): the schedule, and
    which sensors are noisy (the world draws no numbers for a variance of 0)."""
    return (schedule(sc), tuple(getattr(sc, f"{f}_var") > 0 for f in NOISES))


# world/node.py Sensing.measure's draw order: per field, the numbers it draws per item (a
# neighbour, a bearing pair), each field only where its variance is > 0.
def run(
    draws: Sequence[Scenario],
    duration: float,
    seed: int,
    grid_s: float,
    progress: Callable[[float], None] | None = None,
    seeds: Sequence[int] | None = None,
    rows: bool = False,
) -> Result:
    """Step the draws (scenarios that differ only in their agents' starts, or for a prescribed
    truth in their initial estimates, and on rigid bodies in their noise variances) together for
    ``duration`` s of world time; the report family's measure on a grid of ``grid_s`` (the
    family's, zswarm.report.family.Family.basin_grid_s).  ``seeds``: each draw's seed (its noise,
    as sim's World draws it with that seed); by default every draw has ``seed``.  ``rows``: also
    what a sweep's row reads (Result.final_att, att_coarse, ...).  Message and command counts
    are counted either way."""
    sc = draws[0]
    why = problem(sc)
    if why is not None:
        raise Unsupported(f"{sc.name}: the batched engine cannot run it: {why}")
    M, ids = len(draws), sc.ids
    n = len(ids)
    seeds = [seed] * M if seeds is None else list(seeds)
    if len(seeds) != M:
        raise ValueError(f"{len(seeds)} seeds for {M} draws")
    common = schedule(sc)
    if any(schedule(d) != common for d in draws[1:]):
        raise Unsupported("draws that differ in more than their agents' starts, noise variances, seeds and per-draw gains (SPEC.draw_gains)")
    declared = zswarm_family.of(sc).batched
    assert declared is not None  # problem() refused a family without one
    shared = sc.plant == "prescribed"
    col = {i: a for a, i in enumerate(ids)}
    torques = _Torques(M * n)
    # The world's command inbox per draw (batched_links.Commands) for emulated command links, and
    # wherever each draw's agents step at packets of their own and so may skip ticks (sensor links
    # with loss, jitter or cuts, or a sensor delay beside emulated agent→agent links: an agent that
    # hears nothing sends nothing, and the world's stale-command policy acts on what it holds)
    per_draw = any(_per_draw(d) for d in draws)  # (a sweep's draws differ in their agent→agent links)
    cmd_links = None if shared or not (per_draw or any(d.link_spec(f"{i}->world").active for d in draws for i in ids)) else batched_links.Commands(draws, seeds, counters=rows)
    edge_links = batched_links.Edges(draws, seeds, rows, {i: {f: len(x.shape) for f, x in sc.module_for(sc.agent(i).role).SPEC.edge_in.items()} for i in ids}) if any(d.link_spec(f"{j}->{i}").active for d in draws for i in ids for j in sc.agent(i).neighbors) else None
    published = dict.fromkeys(ids, 0)  # messages each agent sent (its sequence number, as AgentNode.seq)
    period = 1.0 / sc.agent(ids[0]).clock.rate  # AgentClock: tick k at k · period
    std = {f: np.sqrt([getattr(d, f"{f}_var") for d in draws]) for f in NOISES}
    if any(np.any((v > 0) != (v[0] > 0)) for v in std.values()):
        raise Unsupported("draws of which some have a sensor's noise and others not (the world draws no numbers for a variance of 0)")
    one_noise = len(set(seeds)) == 1 and all(np.all(v == v[0]) for v in std.values())  # every draw the same noise
    plant: Any
    sensing: Sensing | None = None
    if shared:
        world = world_program(sc, seeds[0])
        key = prescribed_key(world)
        if any(prescribed_key(world_program(d, seeds[0])) != key for d in draws[1:]):
            raise Unsupported("draws whose prescribed truths differ (the batched engine simulates it once for all)")
        plant = prescribed(world)
        sensing = Sensing(world)  # the world's sensors, its generators (one noise) and draw order
    else:
        R0 = np.array([[a.R_matrix for a in d.agents] for d in draws])  # (M, n, 3, 3)
        w0 = np.array([[a.omega0 for a in d.agents] for d in draws])
        J = np.array([[np.array(a.J).reshape(3, 3) for a in d.agents] for d in draws])
        plant = RigidBodyPlant(R0.reshape(-1, 3, 3), np.zeros((M * n, 3)), w0.reshape(-1, 3), J.reshape(-1, 3, 3), sc.step, torques if cmd_links is None else cmd_links)  # type: ignore[arg-type]
    bias = np.array([a.gyro_bias for a in sc.agents])

    modules: dict[int, ModuleType] = {}
    parts: dict[int, Any] = {}
    gains: dict[int, Any] = {}
    views: dict[int, BatchedView] = {}
    states: dict[int, Any] = {}
    inboxes: dict[int, dict[int, deque[tuple[dict[str, Any], float]]]] = {i: {} for i in ids}
    want = {i: sc.sensors_of(i) for i in ids}
    nbrs = {i: sc.graph_neighbors(i) for i in ids}
    # Kept sensor history: on a shared truth, every packet (as an agent's inbox keeps them); on a
    # truth per draw, the attitudes only.
    packets: dict[int, deque[dict[str, Any]]] = {i: deque(maxlen=HISTORY) for i in ids}
    histories: dict[int, dict[str, deque[tuple[float, np.ndarray]]]] = {i: {} if shared else {f: deque(maxlen=HISTORY) for f in ("attitude",) if f in want[i]} for i in ids}
    # The world's generators, when not Sensing's own (one noise for every draw on a shared truth).
    per_draw_noise = not (shared and one_noise)
    noise: dict[int, _Noise] = {}
    if per_draw_noise:
        for i in ids:
            items = {"gyro": "gyro" in want[i], "rel_att": len(nbrs[i]) * ("rel_att" in want[i]), "attitude": "attitude" in want[i]}
            if shared:
                assert sensing is not None
                items |= {"bearing": len(sensing.pairs_of[i]) * ("bearings" in want[i]), "velocity": sc.moving and "velocity" in want[i]}
            noise[i] = _Noise(seeds, i, std, {f: int(c) for f, c in items.items()}, one_noise)
    for i in ids:
        per = [agent_program(d, i, s) for d, s in zip(draws, seeds, strict=True)]
        modules[i], tree_edges = per[0].algorithm, per[0].tree_edges
        gains[i] = draw_gains(modules[i], [p.gains for p in per])
        spec_parts = modules[i].SPEC.parts
        parts[i] = spec_parts[0] if spec_parts else None  # None: a leader that only publishes
        states[i] = stack([modules[i].initial_state(p.initial, gains[i]) for p in per])
        views[i] = BatchedView(sc, i, tree_edges, inboxes[i], histories[i], packets[i] if shared else None)
    hybrid = has_jumps(sc.info)
    # A sensor delay (the same on every sensor link: batched_links.per_draw_sensors): the packets' releases
    # and the steps the agents take on them, one plan for every agent and draw.
    sensor_spec = sc.link_spec(f"world->{ids[0]}")
    sensor_links = _SensorLinks(sensor_spec, period) if sensor_spec.active and not per_draw else None
    store: dict[int, dict[int, dict[str, Any]]] = {i: {} for i in ids}  # sample -> packet, while some tick may read it
    draw_links: dict[int, _DrawSensorLinks] = {}
    draw_inbox: batched_inbox.DrawInbox | None = None
    if per_draw:
        draw_links = {i: _DrawSensorLinks([d.link_spec(f"world->{i}") for d in draws], f"world->{i}", seeds, period, 1.0 / sc.sensor_rate) for i in ids}
        for dl in draw_links.values():
            dl.deep = shared  # a shared truth's laws read the sensor history around their neighbours' stamps too
        ndim = {i: {f: len(x.shape) for f, x in sc.module_for(sc.agent(i).role).SPEC.edge_in.items()} for i in ids}
        draw_inbox = batched_inbox.DrawInbox(sc, M, ndim, *((draws, seeds) if edge_links is not None else (None, None)), counters=rows)
        edge_links = None  # the draw inbox emulates them
    draw_edges = np.zeros(M, dtype=np.int64)  # per draw (per_draw): messages and commands sent
    draw_commands = np.zeros(M, dtype=np.int64)
    n_tick = 0

    sample_dt = 1.0 / sc.sensor_rate
    tick_every = round(sc.sensor_rate / sc.agent(ids[0]).clock.rate)
    n_samples = math.floor(duration * sc.sensor_rate + 1e-9) + 1
    stamps = None if sensor_links is None else _SensorLinks(sensor_spec, period).stamps(n_samples, tick_every, sample_dt)
    # The family's measure (zswarm.families.measure): of each draw's truth at every sample, or of the estimates on a
    # shared truth at the agents' common ticks or at each draw's own stamps.
    make = declared.truth if not shared else declared.stamps if per_draw else declared.ticks
    assert make is not None  # problem() refused a family without it
    measure: Any = make(Context(sc, M, duration, sample_dt, n_samples, tick_every, grid_s, rows, stamps))
    # The packet fields with a draw axis (each draw's own noise: _measure_draws), on a shared truth
    drawn = frozenset(f for f, nz in (("gyro", "gyro"), ("bearings", "bearing"), ("rel_att", "rel_att"), ("velocity", "velocity"), ("attitude", "attitude")) if per_draw_noise and not one_noise and std[nz][0] > 0)
    truths: dict[int, Any] = {}  # with a sensor delay on a shared truth: sample -> the truth there (what an estimate stamped then is measured on)
    edge_messages = commands = 0
    jumps = np.zeros(M, dtype=np.int64)
    agent_jumps = np.zeros(M, dtype=np.int64)
    started = False
    last = 0.0
    steps = 0
    for k in range(n_samples):
        t = k * sample_dt  # as World.next_time computes it
        tick = k % tick_every == 0
        sensed: dict[int, dict[str, Any]] = {}
        if sensing is not None:
            # World.sample: the motion planned ahead, advanced, measured by the world's sensors.
            if t > plant.planned_through():
                plant.plan(np.arange(k, k + PLAN_SAMPLES) * sample_dt)
            plant.advance_to(t)
            R = plant.R
            V = plant.velocity() if sc.moving else None
            if per_draw_noise:  # each draw's own noise: the noisy fields get a draw axis
                B = sensing.bearings(R, plant.p)
                W = plant.omega_now()
                measured = {i: _measure_draws(sensing, i, noise[i].next(), R, plant.p, W, V, B) for i in ids}
            else:
                measured = sensing.measure(R, plant.p, plant.omega_now(), V)
            for i, m in measured.items():
                m["t"] = t
                if per_draw:
                    store[i][k] = _with_draws(m, M, drawn)
                elif sensor_links is None:
                    packets[i].append(m)
                else:
                    store[i][k] = m
                sensed[i] = m
            if sensor_links is not None:
                sensor_links.offer(k, t)
                truths[k] = SimpleNamespace(R=plant.R.copy(), p=plant.p.copy())
            if per_draw:
                truths[k] = (plant.R.copy(), plant.p.copy())
                for dl in draw_links.values():
                    dl.offer(k, t)
        else:
            plant.advance_to(t)
            R = plant.R.reshape(M, n, 3, 3)
            W = plant.omega_now().reshape(M, n, 3)
            measure.sample(k, t, Truth(R, W))
            RT = np.swapaxes(R, -1, -2)
            # Measured as World.sample does.  Every sample goes into the histories, as an agent's inbox
            # keeps them; the rest is measured at the agents' ticks only (a relative attitude is M
            # products, at 200 Hz for 100 Hz agents).  With a sensor delay every sample is measured
            # in full and kept (store) until the ticks that deliver and read it.
            for i in ids:
                a = col[i]
                need = want[i] if tick or sensor_links is not None or per_draw else histories[i].keys()
                # The world's noise, drawn at every sample in its order (gyro, then rel_att per neighbour,
                # then attitude) from its generator per agent and seed (_Noise).
                nz = noise[i].next()
                n_gyro, n_att = nz.get("gyro", [None])[0], nz.get("attitude", [None])[0]
                n_rel = dict(zip(nbrs[i], nz["rel_att"], strict=True)) if "rel_att" in nz else None
                sense: dict[str, Any] = {"t": t}
                if "gyro" in need:
                    sense["gyro"] = W[:, a] + bias[a] if n_gyro is None else W[:, a] + bias[a] + n_gyro
                if "rel_att" in need:
                    sense["rel_att"] = {j: mul(RT[:, a], R[:, col[j]]) for j in nbrs[i]}
                    if n_rel is not None:
                        sense["rel_att"] = {j: mul(R_ij, exp(n_rel[j])) for j, R_ij in sense["rel_att"].items()}
                if "attitude" in need:
                    sense["attitude"] = R[:, a] if n_att is None else mul(R[:, a], exp(n_att))
                if sensor_links is None and not per_draw:
                    for f, hist in histories[i].items():
                        hist.append((t, sense[f].copy()))
                else:
                    if "attitude" in sense:
                        sense["attitude"] = sense["attitude"].copy()
                    store[i][k] = sense
                sensed[i] = sense
            if sensor_links is not None:
                sensor_links.offer(k, t)
            for dl in draw_links.values():
                dl.offer(k, t)
        if not tick:
            continue
        estimates: dict[int, Mapping[str, Any]] = {}
        t_tick = (k // tick_every) * period  # the agents' clock at this tick (AgentClock): the links' send and release times
        if per_draw:
            assert draw_inbox is not None
            draw_inbox.now = t_tick
            estimated: dict[int, Published] = {}
            for i in ids:
                if shared:
                    estimated[i] = Published(M, measure.fields)
                _tick_draws(i, col[i], t_tick, n_tick, draw_links[i], store[i], views[i], modules[i], gains[i], parts[i], states, hybrid, jumps, agent_jumps, draw_inbox, torques.u.reshape(M, n, 3) if cmd_links is None else cmd_links, draw_edges, draw_commands, estimated.get(i))
            n_tick += 1
            if shared:
                measure.tick(truths, estimated)  # each draw's estimates on the truth at their stamps
            lo_all = k
            for i in ids:  # the samples no later tick reads
                lo = draw_links[i].oldest_needed()
                draw_links[i].trim(lo)
                _drop_before(store[i], lo)
                lo_all = min(lo_all, lo)
            _drop_before(truths, lo_all)  # a later estimate is stamped at a packet a later step reads
            if progress is not None and k % int(sc.sensor_rate) == 0:
                progress(t)
            continue
        if sensor_links is None:
            mode, ends = ("steps" if started else "first"), [(t, k)]
        else:
            for t_p, k_p in sensor_links.deliver(t_tick):  # what the agents' inboxes hold from now on
                for i in ids:
                    if shared:
                        packets[i].append(store[i][k_p])
                    for f, hist in histories[i].items():
                        hist.append((t_p, store[i][k_p][f]))
            if sensor_links.packets:  # the oldest packet a step may still read: the older ones go
                lo = sensor_links.packets[0][1]
                for i in ids:
                    _drop_before(store[i], lo)
                _drop_before(truths, lo)
            mode, ends = sensor_links.plan(t_tick)
            if mode in ("none", "idle"):  # nothing measured yet, or nothing newer: no step, nothing sent (AgentNode.tick)
                continue
        for i in ids:
            a = col[i]
            v, mod, g, part = views[i], modules[i], gains[i], parts[i]
            outputs = None
            if mode == "first":
                t_e, k_e = ends[0]
                v.begin(t_e, sensed[i] if sensor_links is None else store[i][k_e], first=True)
                if sensor_links is not None:
                    v.command_lead = max(0.0, t_tick - t_e) + 0.5 * v.period  # AgentNode._begin
                if hybrid and part is not None:  # the jump sets on the initial state; the outputs are not sent (AgentNode._advance)
                    v.dt = 0.0
                    _step(part, states, i, v, g, 0.0, jumps, agent_jumps)
                if sensor_links is not None and part is not None and 0.0 < t_e <= 0.5:
                    v.dt = t_e  # the initial estimate (at t = 0) brought to the first packet: prediction only (no neighbours)
                    _step(part, states, i, v, g, t_e, jumps, agent_jumps)
            else:
                prev = last
                for n_e, (t_e, k_e) in enumerate(ends, 1):
                    v.begin(t_e, sensed[i] if sensor_links is None else store[i][k_e], first=False)
                    if sensor_links is None:
                        v.command_lead = 0.5 * v.period
                    else:  # only the last step's command is sent (AgentNode._advance): a catch-up step's has no lead
                        v.command_lead = max(0.0, t_tick - t_e) + 0.5 * v.period if n_e == len(ends) else 0.0
                    v.dt = t_e - prev
                    if part is not None:
                        if edge_links is None:
                            outputs = _step(part, states, i, v, g, t_e - prev, jumps, agent_jumps) or outputs
                        else:
                            reads = edge_links.read(i, t_tick)
                            outputs = _step_groups(part, states, i, v, g, t_e - prev, jumps, agent_jumps, reads, edge_links.stale_terms[i])
                    prev = t_e
            pub = mod.publish(states[i], outputs, v)
            if pub is None:
                continue
            seq = published[i]
            published[i] += 1
            edge_messages += len(pub.edges)
            commands += pub.command is not None
            t_stamp = v.t_world if pub.t is None else pub.t
            if pub.command is not None and "tau" in pub.command:
                if cmd_links is None:
                    torques.u.reshape(M, n, 3)[:, a] = pub.command["tau"]
                else:
                    cmd_links.send(a, t_tick, t_stamp, pub.command["tau"])  # arrives at the tick, as the world stamps it
            for j, fields in pub.edges.items():
                if edge_links is None:
                    box = inboxes[j].get(i)
                    if box is None:
                        box = inboxes[j][i] = deque(maxlen=RECENT_EDGE_MESSAGES)
                    box.append((dict(fields), t_stamp))
                else:
                    edge_links.send(i, j, seq, t_stamp, t_tick, dict(fields))
            estimates[i] = pub.estimate
        if shared:
            measure.tick(plant if sensor_links is None else truths[ends[-1][1]], estimates)  # the truth at the estimates' stamp
        if started:
            steps += 1
        started, last = True, ends[-1][0]
        if progress is not None and k % int(sc.sensor_rate) == 0:
            progress(t)
    res: Result = measure.result(Result(np.zeros(0), np.zeros((M, 0)), jumps, agent_jumps, steps, edge_messages=edge_messages, commands=commands, command_links=cmd_links, edge_links=edge_links, t_end=(n_samples - 1) * sample_dt))
    if per_draw:
        assert draw_inbox is not None
        res.draw_edge_messages, res.draw_commands = draw_edges, draw_commands
        res.edge_messages, res.commands = int(draw_edges.max()), int(draw_commands.max())
        res.sensor_dropped = np.sum([dl.dropped() for dl in draw_links.values()], axis=0)
        res.stale_terms = np.sum(list(draw_inbox.stale_terms.values()), axis=0)
        if draw_inbox.links:
            res.edge_links = draw_inbox  # the receivers' counters per draw (link_counters)
    return res


def _drop_before(by_sample: dict[int, Any], lo: int) -> None:
    """Forget the samples before ``lo`` (keys inserted in sample order)."""
    while by_sample and next(iter(by_sample)) < lo:
        del by_sample[next(iter(by_sample))]
