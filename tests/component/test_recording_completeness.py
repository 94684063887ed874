"""What a recording lacks is counted exactly: against what each process says it published
(final stats), per channel; and the run recorder's raw file transcodes to the same recording."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader

from zswarm.record import RawOut, read, transcode
from zswarm.report import completeness, load_recording, make_report
from zswarm.scenario import load
from zswarm.sim import LEAN_SKIP, simulate

TOPO = Path(__file__).resolve().parents[2] / "topologies"


@pytest.fixture(scope="module")
def fixed8():
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    msgs = simulate(sc, Path("."), 2.0, sc.seed, record=False)
    return sc, msgs


def test_a_full_recording_lacks_nothing(fixed8):
    sc, msgs = fixed8
    c = completeness(sc, load_recording(msgs))
    # 2 s: 401 samples (truth + 8 sense each), 201 steps per agent (est + one message per out-edge)
    assert c["exact"] and c["missing_total"] == 0 and not c["surplus"]
    n_edges = sum(len(a.neighbors) for a in sc.agents)
    stats = sum(1 for t, _, _ in msgs if t.startswith("stats/"))
    assert c["published"] == 401 * 9 + 201 * (8 + n_edges) + stats


def test_dropped_messages_are_counted_per_channel(fixed8):
    sc, msgs = fixed8
    gone = {"est/3": 7, "truth": 2, "edge/1/3": 5, "sense/8": 1}
    left, drop = [], dict(gone)
    for m in msgs:
        if drop.get(m[0], 0) > 0:
            drop[m[0]] -= 1
            continue
        left.append(m)
    c = completeness(sc, load_recording(left))
    assert c["missing"] == gone and c["missing_total"] == sum(gone.values()) and c["exact"]


def test_without_final_stats_the_count_is_a_lower_bound(fixed8):
    """Agent 5's final stats lost (a killed process sends none): its counts are a lower bound."""
    from zswarm import wire

    sc, msgs = fixed8
    final5 = [m for m in msgs if m[0] == "stats/agent/5" and wire.decode(m[1])["counters"].get("final")]
    assert len(final5) == 1
    assert completeness(sc, load_recording(msgs))["exact"]
    assert not completeness(sc, load_recording([m for m in msgs if m is not final5[0]]))["exact"]


def test_lean_channels_are_left_out_on_purpose(tmp_path):
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    msgs = simulate(sc, tmp_path, 1.0, sc.seed, lean=True, record=False)
    s = make_report(tmp_path, sc, "sim", 1.0, 0.0, sc.seed, plots=False, messages=msgs, not_recorded=LEAN_SKIP)
    assert s["recording"]["missing_total"] == 0 and s["recording"]["not_recorded"] == list(LEAN_SKIP)
    # Without saying so, the same lean recording lacks every sensor and edge message.
    s2 = make_report(tmp_path, sc, "sim", 1.0, 0.0, sc.seed, plots=False, messages=msgs)
    assert s2["recording"]["missing_total"] == 201 * 8 + 101 * sum(len(a.neighbors) for a in sc.agents)


def test_the_raw_recording_transcodes_to_the_same_recording(tmp_path, fixed8):
    """The run recorder's path (payloads as they came, transcoded after the run) gives the
    report exactly what the JSON path gives."""
    sc, msgs = fixed8
    raw = RawOut(tmp_path / "recording.raw.mcap", {"engine": "test"})
    for k, (stream, payload, t) in enumerate(msgs):
        raw.message(stream, payload, t)
        if k % 500 == 0:
            raw.flush()  # many chunks, as the recorder's flush every 0.5 s makes them
    raw.close()
    with open(tmp_path / "recording.raw.mcap", "rb") as f:  # written without chunk indexes (RawOut)
        assert make_reader(f).get_summary().chunk_indexes == []
    assert transcode(tmp_path / "recording.raw.mcap", tmp_path / "recording.mcap", sc) == 0
    assert not (tmp_path / "recording.raw.mcap").exists()
    with open(tmp_path / "recording.mcap", "rb") as f:  # the raw file's metadata carried over
        meta = {k: v for m in make_reader(f).iter_metadata() if m.name == "zswarm" for k, v in m.metadata.items()}
    assert meta["engine"] == "test" and meta["transcoded_from"] == "recording.raw.mcap", meta
    a, b = load_recording(msgs), load_recording(tmp_path / "recording.mcap")
    assert a.streams == b.streams
    assert (a.truth_R == b.truth_R).all() and all((x[1] == y[1]).all() for x, y in zip(a.est[5], b.est[5], strict=True))
    assert [t for t, _, _ in read(tmp_path / "recording.mcap")] == [t for t, _, _ in msgs]  # same order


def test_the_recorder_waits_for_the_final_stats_of_the_processes_still_up():
    """After the run's stop the recorder waits for each process still up to send its final
    stats (a fixed second was not always enough on a loaded machine), and for one whose
    token went less than GONE_GRACE_S before the stop arrived (its final stats, sent
    before, can be seen after); one whose token went before that is not waited for."""
    from zswarm import keys, wire
    from zswarm.bus import MemoryBus
    from zswarm.record import GONE_GRACE_S, Recorder

    bus = MemoryBus()
    clock = [0]  # the recorder's now_ns
    rec = Recorder(bus, "r", None, now_ns=lambda: clock[0])
    procs = [("world", 0), ("agent", 1), ("agent", 2), ("agent", 3), ("agent", 4)]
    for role, i in procs[:3] + procs[4:]:  # agent 3 never came up
        bus.declare_token(keys.alive("r", role, i))
    assert rec.awaiting_finals(procs) == procs[:3] + procs[4:]
    bus.undeclare_token(keys.alive("r", "agent", 4))  # killed mid-run, 10 s before the stop
    clock[0] = 10_000_000_000
    bus.publisher(keys.ctl("r", "stop")).put(wire.encode("stop", 0, 0, 10.0, reason="duration"))
    assert rec.stopped.is_set() and rec.stop_t == clock[0]
    clock[0] += int(5 * GONE_GRACE_S * 1e9)  # whenever the recorder looks, the stop's time is what counts
    bus.publisher(keys.stats("r", "agent", 1)).put(wire.encode("stats", 1, 0, 1.0, role="agent", counters={"final": False}))
    bus.publisher(keys.stats("r", "world", 0)).put(wire.encode("stats", 0, 1, 2.0, role="world", counters={"final": True}))
    bus.publisher(keys.stats("r", "agent", 2)).put(wire.encode("stats", 2, 0, 1.0, role="agent", counters=5))  # malformed: still awaited
    assert rec.awaiting_finals(procs) == [("agent", 1), ("agent", 2)]
    bus.publisher(keys.stats("r", "agent", 1)).put(wire.encode("stats", 1, 1, 2.0, role="agent", counters={"final": True}))
    bus.undeclare_token(keys.alive("r", "agent", 2))  # gone after the stop: its final stats may still come
    assert rec.awaiting_finals(procs) == [("agent", 2)]
    assert rec.missing_finals(procs) == [("agent", 2), ("agent", 4)]  # agent 3, never seen, is not counted
    bus.publisher(keys.stats("r", "agent", 2)).put(wire.encode("stats", 2, 1, 3.0, role="agent", counters={"final": True}))
    assert rec.awaiting_finals(procs) == [] and rec.missing_finals(procs) == [("agent", 4)]


def test_a_token_gone_within_the_grace_before_the_stop_is_waited_for():
    """The recorder may be behind: a process that stopped cleanly just before the world's
    stop was seen (GONE_GRACE_S) is waited for; without a stop, now is the reference."""
    from zswarm import keys, wire
    from zswarm.bus import MemoryBus
    from zswarm.record import GONE_GRACE_S, Recorder

    bus = MemoryBus()
    clock = [0]
    rec = Recorder(bus, "r", None, now_ns=lambda: clock[0])
    procs = [("agent", 1)]
    bus.declare_token(keys.alive("r", "agent", 1))
    clock[0] = 1_000_000_000
    bus.undeclare_token(keys.alive("r", "agent", 1))
    clock[0] += int(0.5 * GONE_GRACE_S * 1e9)
    assert rec.awaiting_finals(procs) == procs  # no stop yet: gone half the grace ago
    clock[0] += int(GONE_GRACE_S * 1e9)
    assert rec.awaiting_finals(procs) == []  # 1.5 x the grace ago
    bus.publisher(keys.ctl("r", "stop")).put(wire.encode("stop", 0, 0, 10.0, reason="duration"))
    assert rec.awaiting_finals(procs) == []  # the stop came 1.5 x the grace after it went
    bus.declare_token(keys.alive("r", "agent", 1))  # back (a restart): awaited as up
    assert rec.awaiting_finals(procs) == procs