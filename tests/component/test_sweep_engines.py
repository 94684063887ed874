"""zswarm sweep's rows from the batched engine against sim's, run by run (issue 31).

Each sweep runs as a subprocess on both engines (34 s for the file, quietly).
"""

from __future__ import annotations

import pytest

from tests.component.test_sweep import _sweep_of, rows


@pytest.mark.parametrize(
    ("topology", "vary"),
    [
        ("thesis-5.6-hybrid7-noisy.toml", "noise.rel_att_var=0.005,0.02"),  # noise levels and repeats (seeds) in one batch
        ("thesis-5.6-velocity-free7-noisy.toml", "algorithm.gains.k_R=0.2,0.4"),  # a gain of SPEC.draw_gains: one batch
        ("thesis-5.6-continuous7.toml", "algorithm.gains.k_omega=0.1,0.2"),  # no jumps, no noise
        ("thesis-3.3-moving5.toml", "agents[3].estimate.R.angle=0.1,2.5"),  # §3 (leader–follower family), starts and repeats in one batch
        ("thesis-3.2-fixed8-noisy.toml", "algorithm.gains.k_p=1,2"),  # a shared noisy truth, each run's own noise and k_p: one batch
        ("thesis-4.5-hybrid5-noisy.toml", "noise.rel_att_var=0.005,0.02"),  # the tree family: §4.5's finals up to a common frame
    ],
)
def test_batched_rows_are_sims(tmp_path, topology, vary):
    """The same sweep on the batched engine and on sim, run by run: every column as written
    (six significant digits: the two engines differ by round-off, ~1e-15 relative, see
    tests/component/test_batched.py), but the wall time.  A threshold of 0.7 makes the
    convergence times of the hybrid laws' 3 s runs numbers, not blanks."""
    args = ["--vary", vary, "--repeats", "2", "--duration", "3", "--thresholds", "0.7,0.1", "--jobs", "2"]
    got = {}
    for engine in ("batched", "sim"):
        p = _sweep_of(topology, *args, "--no-plots", "--engine", engine, "--out", str(tmp_path / engine))  # rows only: no figures
        assert p.returncode == 0, p.stderr
        got[engine] = {r["run_id"]: r for r in rows(tmp_path / engine)}
    assert sorted(got["batched"]) == sorted(got["sim"]) and len(got["sim"]) == 4
    for rid, sim_row in got["sim"].items():
        b = got["batched"][rid]
        assert {k: v for k, v in b.items() if k != "wall_s"} == {k: v for k, v in sim_row.items() if k != "wall_s"}, rid
    if "continuous" not in topology:  # the continuous law stays near its undesired start for these 3 s
        assert any(r["conv_attitude_s"] for r in got["sim"].values())
    assert not (tmp_path / "batched" / "runs").exists()  # no run folders: the rows come from the engine's arrays


LOSSY = ["--set", "links.commands.drop=0.1", "--set", "links.commands.ge_p_gb=0.05", "--set", "links.commands.ge_p_bg=0.3"]


def _same_rows(tmp_path, topology, args, batches=None):
    """The sweep ``args`` on both engines: the same rows, every column as written but the wall
    time (``batches``: the batched run's stderr says it ran in that many); sim's rows."""
    got = {}
    for engine in ("batched", "sim"):
        p = _sweep_of(topology, *args, "--no-plots", "--engine", engine, "--out", str(tmp_path / engine))  # rows only: no figures
        assert p.returncode == 0, p.stderr
        got[engine] = {r["run_id"]: {k: v for k, v in r.items() if k != "wall_s"} for r in rows(tmp_path / engine)}
        if engine == "batched" and batches is not None:
            assert f"batched in {batches} batches" in p.stderr, p.stderr
    assert got["batched"] == got["sim"] and len(got["sim"]) == 4  # --engine batched ran them all (or exit 2)
    return list(got["sim"].values())


@pytest.mark.parametrize(
    ("topology", "vary", "sets"),
    [
        # delay, exponential jitter, Bernoulli and Gilbert–Elliott loss; FIFO and reordering
        ("thesis-5.6-hybrid7.toml", "links.commands.reorder=false,true", ["--set", "links.commands.delay_ms=3", "--set", "links.commands.jitter_ms=4", "--set", 'links.commands.jitter="exponential"', *LOSSY]),
        # normal jitter on noisy draws; a max_age shorter than the delay: commands expire, zeroed
        ("thesis-5.6-velocity-free7-noisy.toml", "links.commands.jitter_ms=0,3", ["--set", "links.commands.delay_ms=5", "--set", "world.commands.max_age=0.007"]),
        # one link's own model over the defaults; stale commands held
        ("thesis-5.6-continuous7.toml", "links.commands.delay_ms=2,8", ["--set", 'links.per_link."3->world".drop=0.5', "--set", "world.commands.max_age=0.006", "--set", 'world.commands.policy="hold"']),
    ],
)
def test_batched_rows_are_sims_with_command_links(tmp_path, topology, vary, sets):
    """Emulated command links (agent/batched_links.py): each draw loses and delays the commands
    its sim run does, so the rows are sim's column by column, the link counters included (sent,
    lost, latency p50, expired).  Each case is checked to have lost, delayed or expired
    something, or it would compare nothing."""
    args = ["--vary", vary, *sets, "--repeats", "2", "--duration", "2", "--thresholds", "0.7,0.1", "--jobs", "2"]
    sim_rows = _same_rows(tmp_path, topology, args)
    # Every case delays its commands by ≥ 2 ms; jitter (exponential ≥ 0, or normal about the
    # delay, clipped at 0) leaves the median at or above the delay.
    assert all(float(r["cmd_latency_p50_ms"]) >= 2 for r in sim_rows)
    if "drop" in " ".join(sets):
        assert all(int(r["cmd_dropped"]) > 0 for r in sim_rows)
    if "max_age" in " ".join(sets):
        assert all(int(r["cmd_expired"]) > 0 for r in sim_rows)
    if "repeats" in args and "drop" in " ".join(sets):
        assert len({r["cmd_dropped"] for r in sim_rows}) > 1  # each run (seed) its own losses


@pytest.mark.parametrize(
    ("topology", "vary", "sets"),
    [
        # the sweep of issue 46: delay, jitter, bursts and loss in one batch; stale neighbours held
        ("thesis-3.2-fixed8.toml", "links.delay_ms=0,200", ["--set", "links.jitter_ms=10", "--set", "links.drop=0.25", "--set", "links.ge_p_gb=0.05", "--set", "links.ge_p_bg=0.3"]),
        # stale neighbours dropped, one link slower than the rest, reordering
        ("thesis-3.2-fixed8.toml", "links.delay_ms=100,200", ["--set", "links.jitter_ms=10", "--set", "links.reorder=true", "--set", 'algorithm.stale.policy="drop"', "--set", 'links.per_link."2->3".delay_ms=300']),
        # moving agents read their neighbours' stamps and ages: draws split by stamp (batched_links.Split)
        ("thesis-3.3-moving5.toml", "links.delay_ms=0,20", ["--set", "links.jitter_ms=8", "--set", "links.drop=0.2", "--set", 'links.jitter="exponential"']),
        # §4.5: heard_all and the hybrid ξ messages over lossy links
        ("thesis-4.5-hybrid5.toml", "links.delay_ms=5,30", ["--set", "links.jitter_ms=10", "--set", "links.drop=0.2"]),
        # §5.6: lossy ξ/ω messages and lossy commands together, noisy draws
        ("thesis-5.6-velocity-free7-noisy.toml", "links.delay_ms=0,100", ["--set", "links.jitter_ms=30", "--set", "links.ge_p_gb=0.1", "--set", "links.ge_p_bg=0.2", "--set", "links.commands.delay_ms=3", "--set", "links.commands.drop=0.1"]),
    ],
)
def test_batched_rows_are_sims_with_agent_links(tmp_path, topology, vary, sets):
    """Emulated agent→agent links (agent/batched_links.py Edges): each draw loses, delays and
    reorders the messages its sim run does, reads the newest one delivered by its tick, held or
    dropped when stale as sim's agent does, so the rows are sim's column by column: the link
    counters (sent, delivered, lost, latency p50), the stale reads, the errors and jumps.  The
    points of a sweep over link parameters share one batch (their draws have links of their own)."""
    args = ["--vary", vary, *sets, "--repeats", "2", "--duration", "2", "--thresholds", "0.7,0.1", "--jobs", "1"]
    sim_rows = _same_rows(tmp_path, topology, args, batches=1)
    assert all(int(r["edge_dropped"]) > 0 or "drop" not in " ".join(sets) for r in sim_rows)
    assert max(float(r["edge_latency_p50_ms"]) for r in sim_rows) >= 5  # every case has a point of ≥ 20 ms delay: the delays reached the counters
    if "200" in vary or "policy" in " ".join(sets):
        assert any(int(r["stale_terms"]) > 0 for r in sim_rows)  # stale reads counted


def test_batched_rows_are_sims_with_link_cuts(tmp_path):
    """[[faults]] kind "cut" on an agent→agent and a command link (everything lost over an
    interval, after the model's own draws) runs batched: the same rows as sim, the cuts counted
    as lost (0.4 s of agent 3's commands at 100 Hz: 40)."""
    from tests.conftest import TOPO

    topo = tmp_path / "hybrid-cut.toml"
    cuts = '\n[[faults]]\nkind = "cut"\nlink = "3->world"\nat = 0.5\nduration = 0.4\n\n[[faults]]\nkind = "cut"\nlink = "2->3"\nat = 1.0\nduration = 0.5\n'
    topo.write_text((TOPO / "thesis-5.6-hybrid7.toml").read_text() + cuts)
    args = ["--vary", "links.delay_ms=0,10", "--set", "links.drop=0.1", "--repeats", "2", "--duration", "2", "--thresholds", "0.7,0.1", "--jobs", "1"]
    assert all(r["cmd_dropped"] == "40" for r in _same_rows(tmp_path, str(topo), args))


def test_batched_rows_are_sims_with_sensor_link_cuts(tmp_path):
    """[[faults]] kind "cut" on sensor links: agent 3 hears nothing for 0.6 s mid-run (120
    samples: its steps across the gap read the history of what came before), agent 5 nothing
    for its first 0.4 s (its first step 80 samples in), on sensor links with jitter and loss or
    without: the same rows as sim, the cut packets counted lost by the receivers."""
    from tests.conftest import TOPO

    topo = tmp_path / "hybrid-sensor-cut.toml"
    cuts = '\n[[faults]]\nkind = "cut"\nlink = "world->3"\nat = 0.5\nduration = 0.6\n\n[[faults]]\nkind = "cut"\nlink = "world->5"\nat = 0.0\nduration = 0.4\n'
    topo.write_text((TOPO / "thesis-5.6-hybrid7.toml").read_text() + cuts)
    # 1.5 s (2 s before): the last cut ends at 1.1 s, and 0.4 s of steps after it (40 ticks)
    # read the history across the gap; nothing after that is new to the engines.
    args = ["--vary", "links.sensors.drop=0,0.1", "--set", "links.sensors.jitter_ms=1", "--repeats", "2", "--duration", "1.5", "--thresholds", "0.7,0.1", "--jobs", "1"]
    sim_rows = _same_rows(tmp_path, str(topo), args)
    # Agent 3 loses the 120 samples of its cut at least, beside what the link loses
    # (agent 5's first 80 are before its first packet: nothing is counted lost before it).
    assert all(int(r["sensor_dropped"]) >= 120 for r in sim_rows)
    assert len({r["sensor_dropped"] for r in sim_rows if r["links.sensors.drop"] == "0.1"}) == 2


def test_batched_rows_are_sims_with_sensor_cuts_on_a_prescribed_truth(tmp_path):
    """§4.5's five agents hear nothing from 1.3 s to the end of a 2 s run (every sensor link
    cut): each draw's 100 Hz grid ends at its agents' last estimate (1.3 s), the 0.1 s points
    after it hold its last point as edges_on_grid clips them, and the finals are its last
    second's (part before the cut, part after, as with a cut at 2.3 s of a 3 s run before:
    the same paths, a second less of the prescribed truth's per-draw grid): the same rows as
    sim, with loss beside or not."""
    from tests.conftest import TOPO

    topo = tmp_path / "tree-sensor-cut.toml"
    cuts = "".join(f'\n[[faults]]\nkind = "cut"\nlink = "world->{i}"\nat = 1.3\nduration = 1.0\n' for i in range(1, 6))
    topo.write_text((TOPO / "thesis-4.5-hybrid5.toml").read_text() + cuts)
    args = ["--vary", "links.sensors.drop=0,0.1", "--set", "links.sensors.jitter_ms=1", "--repeats", "2", "--duration", "2", "--thresholds", "0.7,0.1", "--jobs", "1"]
    sim_rows = _same_rows(tmp_path, str(topo), args)
    assert all(int(r["sensor_dropped"]) == 0 or r["links.sensors.drop"] == "0.1" for r in sim_rows)  # a cut to the end is not a gap: nothing after it to count it
    assert len({r["final_attitude_error"] for r in sim_rows}) == 4


@pytest.mark.parametrize(
    ("topology", "vary", "sets"),
    [
        # 5 ms: releases t + 5e-3 meet the ticks in round-off both ways, so idle ticks and catch-up
        # steps (AgentNode.tick, step_ends) come every few seconds; 12.5 ms: never
        ("thesis-5.6-hybrid7.toml", "links.sensors.delay_ms=5,12.5", []),
        # the attitude history the velocity-free law integrates, noisy draws, lossy commands as well
        ("thesis-5.6-velocity-free7-noisy.toml", "links.sensors.delay_ms=3,15", ["--set", "links.commands.delay_ms=2", "--set", "links.commands.drop=0.1"]),
        # the first packet 2 ms after t = 0: the first step's prediction to it (AgentNode._advance's lag)
        ("thesis-5.6-continuous7.toml", "links.sensors.delay_ms=2,20", []),
        # a shared truth: the bearings and relative attitudes read from the delivered packets, the
        # estimates measured on the truth at their stamps (the report's estimates_with_truth)
        ("thesis-3.2-fixed8-noisy.toml", "links.sensors.delay_ms=5,12.5", []),
        ("thesis-3.3-moving5.toml", "links.sensors.delay_ms=5,12.5", []),
        ("thesis-4.5-hybrid5.toml", "links.sensors.delay_ms=5,12.5", []),
    ],
)
def test_batched_rows_are_sims_with_a_sensor_delay(tmp_path, topology, vary, sets):
    """A fixed delay on every sensor link (agent/batched.py _SensorLinks), for each family the
    batched engine runs (§5.6, §3, §4.5): every agent of every draw steps at the packets its sim run steps at (the newest delivered by the tick, idle when
    none is newer, catch-up steps after a late one) with the command lead sim gives it, so the
    rows are sim's column by column.  The delays change the runs (the rows of two delays
    differ), or this would compare nothing new."""
    args = ["--vary", vary, *sets, "--repeats", "2", "--duration", "2", "--thresholds", "0.7,0.1", "--jobs", "1"]
    sim_rows = _same_rows(tmp_path, topology, args, batches=2)  # a batch per delay: the draws of one share their steps
    # The first packet comes a tick later at the longer delay of each pair: a message fewer per
    # edge, a command fewer per agent (the continuous §5.6 law sends no messages, §3 and §4.5 no commands).
    assert len({(r["edge_sent"], r["cmd_sent"]) for r in sim_rows}) == 2
    if "continuous" not in topology:  # the continuous law sits on its undesired start for these 2 s
        assert len({r["final_attitude_error"] for r in sim_rows}) > 1
    assert all(r["sensor_dropped"] == "0" for r in sim_rows)


def _lossy_duration(topology, vary):
    """The horizon of a lossy-sensor-link case: 2 s (3 s before), as the other link cases of
    this file.  Every branch these cases test fires in each draw's first second (a 0.1-0.3
    loss at 200 Hz loses tens of packets per agent a second, bursts and jitter likewise; the
    asserts below on each draw's own counts held at 2 s), so the last second repeated them.
    One case keeps a horizon past 2.56 s: 512 sensor packets, the block of numbers each
    draw's sensor link reads ahead (agent/batched_links.py AHEAD), so each draw reads its
    next block mid-run on the engine as it did at 3 s."""
    return "2.7" if (topology, vary) == ("thesis-5.6-hybrid7.toml", "links.sensors.drop=0.1,0.3") else "2"


@pytest.mark.parametrize(
    ("topology", "vary", "sets"),
    [
        # Bernoulli loss and normal jitter: each draw's agents idle, catch up and stamp at packets of their own
        ("thesis-5.6-hybrid7.toml", "links.sensors.drop=0.1,0.3", ["--set", "links.sensors.delay_ms=3", "--set", "links.sensors.jitter_ms=2"]),
        # bursts (two or more packets lost: steps between packets read the history), noisy draws,
        # the attitude history the velocity-free law integrates, with and without jitter
        ("thesis-5.6-velocity-free7-noisy.toml", "links.sensors.jitter_ms=0,4", ["--set", "links.sensors.delay_ms=2", "--set", "links.sensors.ge_p_gb=0.1", "--set", "links.sensors.ge_p_bg=0.3"]),
        # one agent's sensors later than the others' (a neighbour's message newer than a step), exponential jitter
        ("thesis-5.6-hybrid7-noisy.toml", "links.sensors.drop=0,0.2", ["--set", 'links.per_link."world->3".delay_ms=7', "--set", 'links.sensors.jitter="exponential"', "--set", "links.sensors.jitter_ms=3"]),
        # reordering sensor links: a packet behind a newer one stays out of the inbox (LinkCounter), lost
        # counts less the late ones; exponential jitter larger than the sample period
        ("thesis-5.6-hybrid7.toml", "links.sensors.reorder=false,true", ["--set", "links.sensors.delay_ms=2", "--set", "links.sensors.jitter_ms=6", "--set", 'links.sensors.jitter="exponential"', "--set", "links.sensors.drop=0.05"]),
        # lossy, late ξ messages beside: each draw's agents send their own messages at their own ticks,
        # each its own n-th message's loss and delay, read at or before each step among those received
        ("thesis-5.6-hybrid7.toml", "links.drop=0,0.3", ["--set", "links.sensors.drop=0.1", "--set", "links.sensors.jitter_ms=2", "--set", "links.delay_ms=12", "--set", "links.jitter_ms=5", "--set", "links.ge_p_gb=0.05", "--set", "links.ge_p_bg=0.3"]),
        # a fixed sensor delay beside lossy messages and commands: the same plan, each draw its own messages
        ("thesis-5.6-velocity-free7-noisy.toml", "links.drop=0,0.2", ["--set", "links.sensors.delay_ms=5", "--set", "links.delay_ms=3", "--set", "links.jitter_ms=2", "--set", "links.commands.delay_ms=2", "--set", "links.commands.drop=0.1"]),
        # reordering ξ messages beside (exponential jitter of two periods): a message released after a
        # newer one of its draw stays out of the receiver's inbox, its counters replayed in release order
        ("thesis-5.6-hybrid7.toml", "links.reorder=false,true", ["--set", "links.sensors.drop=0.1", "--set", "links.sensors.jitter_ms=2", "--set", "links.delay_ms=3", "--set", "links.jitter_ms=20", "--set", 'links.jitter="exponential"']),
        # lossy, late commands beside: each draw's agents send their own commands at their own ticks
        ("thesis-5.6-hybrid7.toml", "links.commands.drop=0,0.2", ["--set", "links.sensors.drop=0.15", "--set", "links.sensors.delay_ms=2", "--set", "links.sensors.jitter_ms=2", "--set", "links.commands.delay_ms=3", "--set", "links.commands.jitter_ms=1"]),
        # a prescribed truth (§3, §4.5): each draw's estimates measured on the truth at their own
        # stamps, its laws reading its own sensor history around their neighbours' stamps (_Deep)
        ("thesis-3.2-fixed8-noisy.toml", "links.sensors.drop=0.1,0.3", ["--set", "links.sensors.jitter_ms=2"]),
        ("thesis-3.3-moving5.toml", "links.sensors.jitter_ms=0,3", ["--set", "links.sensors.delay_ms=2", "--set", "links.sensors.ge_p_gb=0.1", "--set", "links.sensors.ge_p_bg=0.3"]),
        ("thesis-4.5-hybrid5.toml", "links.sensors.drop=0.1,0.3", ["--set", "links.sensors.jitter_ms=2"]),
    ],
)
def test_batched_rows_are_sims_with_lossy_sensor_links(tmp_path, topology, vary, sets):
    """Sensor links with jitter, loss and bursts (agent/batched.py _DrawSensorLinks): each draw
    loses and delays the packets its sim run does, so its agents idle, catch up and step between
    packets at its own ticks, read their neighbours' messages stamped at or before each step
    (batched_inbox.DrawInbox) and send at their own ticks: the rows are sim's column by column,
    lost sensor packets and messages sent included.  Each draw loses packets of its own (the two
    repeats of a lossy point differ)."""
    args = ["--vary", vary, *sets, "--repeats", "2", "--duration", _lossy_duration(topology, vary), "--thresholds", "0.7,0.1", "--jobs", "1"]
    sim_rows = _same_rows(tmp_path, topology, args)
    fixed = "links.sensors.delay_ms=5" in sets  # a fixed sensor delay: no packet lost, every draw steps at the same ticks
    lossy = [r for r in sim_rows if int(r["sensor_dropped"]) > 0]
    assert len(lossy) >= 2 and len({r["sensor_dropped"] for r in lossy}) >= 2 or fixed
    if vary.startswith("links.drop"):  # each draw lost messages of its own (the receivers' counters)
        assert len({r["edge_dropped"] for r in sim_rows}) >= 3 and len({r["edge_latency_p50_ms"] for r in sim_rows}) >= 3
    if vary.startswith("links.reorder"):  # the late messages kept out changed what the agents read
        assert len({r["final_attitude_error"] for r in sim_rows}) == 4
    # idle ticks: each draw sent its own count (a point's repeats have seeds of their own; the
    # points of one repeat share the sensor links' numbers, so only a varied sensor link gives more)
    assert len({r["edge_sent"] for r in sim_rows}) >= (3 if "sensors" in vary else 1 if fixed else 2)
    if "commands.drop" in vary:  # each draw lost commands of its own, of its own count sent
        assert len({r["cmd_dropped"] for r in sim_rows}) >= 3 and len({r["cmd_sent"] for r in sim_rows}) >= 2
