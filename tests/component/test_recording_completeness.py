"""What a recording lacks is counted exactly: against what each process says it published
(final stats), per channel; and the run recorder's raw file transcodes to the same recording."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader

from zswarm.engines.sim import LEAN_SKIP, simulate
from zswarm.recording.mcap_io import RawOut, read, transcode
from zswarm.report import load_recording
from zswarm.results import completeness, make_report
from zswarm.scenario import load

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
    from zswarm.transport import wire

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
    token is gone but which sent stats within RECENT_STATS_S of world time before the stop
    (its final stats, sent before the token went, can be seen after); one killed earlier
    is not waited for."""
    from zswarm.recording.capture import Recorder
    from zswarm.recording.mcap_io import RECENT_STATS_S
    from zswarm.transport import keys, wire
    from zswarm.transport.bus import MemoryBus

    bus = MemoryBus()

    def stats(role, i, seq, t, final):
        bus.publisher(keys.stats("r", role, i)).put(wire.encode("stats", i, seq, t, role=role, counters={"final": final}))

    rec = Recorder(bus, "r", None, now_ns=lambda: 0)
    procs = [("world", 0), ("agent", 1), ("agent", 2), ("agent", 3), ("agent", 4), ("agent", 5)]
    for role, i in procs[:3] + procs[4:]:  # agent 3 never came up
        bus.declare_token(keys.alive("r", role, i))
    assert rec.awaiting_finals(procs) == procs[:3] + procs[4:]
    for role, i in procs:
        if i != 3:
            stats(role, i, 0, 1.0, False)
    for i in (4, 5):  # killed mid-run (no final stats); 5 sent stats RECENT_STATS_S before the end
        stats("agent", i, 1, 10.0 - (2 * RECENT_STATS_S if i == 4 else RECENT_STATS_S), False)
        bus.undeclare_token(keys.alive("r", "agent", i))
    assert rec.awaiting_finals(procs) == procs[:3]  # before the stop: the tokens alone
    stats("world", 0, 1, 10.0, True)
    bus.publisher(keys.ctl("r", "stop")).put(wire.encode("stop", 0, 0, 10.0, reason="duration"))
    assert rec.stopped.is_set() and rec.stop_t == 10.0
    bus.publisher(keys.stats("r", "agent", 2)).put(wire.encode("stats", 2, 1, 2.0, role="agent", counters=5))  # malformed: not a final
    assert rec.awaiting_finals(procs) == [("agent", 1), ("agent", 2), ("agent", 5)]
    stats("agent", 1, 1, 9.5, False)
    bus.undeclare_token(keys.alive("r", "agent", 1))  # its token seen going before its final stats
    assert rec.awaiting_finals(procs) == [("agent", 1), ("agent", 2), ("agent", 5)]
    stats("agent", 1, 2, 10.0, True)
    stats("agent", 2, 2, 10.0, True)
    assert rec.awaiting_finals(procs) == [("agent", 5)]
    assert rec.missing_finals(procs) == [("agent", 4), ("agent", 5)]  # agent 3, never seen, is not counted
    bus.declare_token(keys.alive("r", "agent", 4))  # back (a restart): awaited as up
    assert rec.awaiting_finals(procs, recent_s=0.0) == [("agent", 4)]


def _raw_file(path: Path, msgs, every: int) -> list[int]:
    """Write ``msgs`` as the run recorder does, a chunk ended every ``every`` messages;
    return the file's size after each flush (what a SIGKILL at that moment leaves)."""
    raw = RawOut(path, {"engine": "test"})
    sizes = []
    for k, (stream, payload, t) in enumerate(msgs, start=1):
        raw.message(stream, payload, t)
        if k % every == 0:
            raw.flush()
            sizes.append(path.stat().st_size)
    raw.close()
    return sizes


def test_a_raw_file_cut_short_reads_back_to_its_last_complete_chunk(tmp_path, fixed8):
    """A SIGKILLed recorder leaves a raw file without its summary and with a chunk cut
    anywhere: everything up to the last complete chunk reads back, in file order (the
    reader's log-time order sorted the whole file first and yielded nothing at all)."""
    sc, msgs = fixed8
    path = tmp_path / "recording.raw.mcap"
    every = 700
    sizes = _raw_file(path, msgs, every)
    data = path.read_bytes()
    for k in (2, len(sizes) // 2, len(sizes) - 1):
        for extra in (0, 1, 37, 5000):  # cut at a chunk's end, in the next record's header, inside the next chunk
            cut = tmp_path / "cut.raw.mcap"
            cut.write_bytes(data[: sizes[k - 1] + extra])
            got = list(read(cut))
            # Every message of the k complete chunks, and nothing made up (the cut chunk is incomplete).
            assert len(got) == k * every, (k, extra, len(got))
            assert [t for _, _, t in got] == [t for _, _, t in msgs[: k * every]]


def test_transcoding_a_cut_raw_file_keeps_what_it_holds(tmp_path, fixed8):
    """The launcher's report of a run whose recorder was SIGKILLed: the cut raw file becomes
    a viewer recording with every message it held and a report; a raw file with no complete
    message is kept, not replaced by an empty recording."""
    from zswarm.recording.mcap_io import LOST_CHANNEL, EmptyRecording

    sc, msgs = fixed8
    path = tmp_path / "recording.raw.mcap"
    sizes = _raw_file(path, msgs, 500)
    whole = path.read_bytes()
    path.write_bytes(whole[: sizes[5] + 100])  # 6 chunks on disk, the 7th cut
    assert transcode(path, tmp_path / "recording.mcap", sc) == 0
    assert not path.exists()
    got = [(s, m) for s, m, _t in read(tmp_path / "recording.mcap")]
    assert sum(1 for s, _m in got if s != LOST_CHANNEL) == 3000
    # The cut is named where it is (issue 50): one loss, in the 7th chunk, on events/lost.
    (lost,) = [m["text"] for s, m in got if s == LOST_CHANNEL]
    assert lost == f"{path}: byte {sizes[5]}: the file ends inside a record (cut short: a killed writer or a full disk); what followed was never written"
    rec = load_recording(tmp_path / "recording.mcap")
    assert rec.lost == [lost]
    assert {k: v for k, v in rec.streams.items() if k != LOST_CHANNEL} == load_recording(msgs[:3000]).streams
    # Nothing complete: the raw file is kept as it is and no recording is written.
    (tmp_path / "recording.mcap").unlink()
    path.write_bytes(whole[:200])
    with pytest.raises(EmptyRecording, match="no complete message"):
        transcode(path, tmp_path / "recording.mcap", sc)
    assert path.read_bytes() == whole[:200] and not (tmp_path / "recording.mcap").exists()
    assert not list(tmp_path.glob("*.part"))


def _same(a, b) -> bool:
    """Two decoded values alike: arrays by their bits, containers item by item."""
    import numpy as np

    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def test_the_report_read_in_the_transcodes_pass_is_the_one_read_back(tmp_path, fixed8):
    """``zswarm run``'s report takes the run from the transcode as it writes it
    (mcap_io.transcoded), not from reading recording.mcap back: the recording it decodes is the
    one read back, field by field and bit for bit (the messages, the liveliness events, the
    junk described one by one and counted in bulk, a message of another agent's key, the
    envelopes a fault summary uses), the summary the same, and the file written the same bytes."""
    import dataclasses
    import shutil

    from zswarm.recording.mcap_io import transcoded

    sc, msgs = fixed8
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
    raw = RawOut(tmp_path / "a" / "recording.raw.mcap", {"engine": "test"})
    for k, (stream, payload, t) in enumerate(msgs):
        raw.message(stream, payload, t)
        if k % 400 == 0:
            raw.alive({"key": f"zswarm/r/alive/agent/{k % 8 + 1}", "alive": k % 800 == 0, "t_wall": float(k)}, t)
        if k % 97 == 0:
            raw.message("est/3", b"\x93garbage", t)  # 10 described, the rest counted
        if k == 1000:
            raw.message("est/4", msgs[next(j for j, m in enumerate(msgs) if m[0] == "est/5")][1], t)  # agent 5's estimate on agent 4's key
    raw.close()
    shutil.copy(tmp_path / "a" / "recording.raw.mcap", tmp_path / "b" / "recording.raw.mcap")

    junk = len(range(0, len(msgs), 97)) + 1  # and the estimate on another agent's key
    assert junk > 12  # more than are described one by one (DESCRIBE_PER_KEY)
    assert transcode(tmp_path / "a" / "recording.raw.mcap", tmp_path / "a" / "recording.mcap", sc) == junk
    back = load_recording(tmp_path / "a" / "recording.mcap", envelopes=True)
    entries = transcoded(tmp_path / "b" / "recording.raw.mcap", tmp_path / "b" / "recording.mcap", sc)
    one_pass = load_recording(entries, envelopes=True)
    assert not (tmp_path / "b" / "recording.raw.mcap").exists()  # the last entry taken: in place
    for f in dataclasses.fields(back):
        assert _same(getattr(back, f.name), getattr(one_pass, f.name)), f.name
    assert back.malformed == junk and len(back.alive_events) == sum(s == "events/alive" for s, _, _ in msgs) + len(range(0, len(msgs), 400))
    assert all(back.envelopes[s] for s in ("truth", "est/3", "sense/5", "stats/agent/5")) and back.stats  # JSON leaves out inc = 0: each was empty
    assert (tmp_path / "a" / "recording.mcap").read_bytes() == (tmp_path / "b" / "recording.mcap").read_bytes()
    # make_report on a folder the recorder left its raw file in reads it in the transcode's pass;
    # made again (the raw file gone, recording.mcap read back) it is the same summary.
    c = tmp_path / "c"
    c.mkdir()
    raw = RawOut(c / "recording.raw.mcap", {"engine": "test"})
    for stream, payload, t in msgs:
        raw.message(stream, payload, t)
    raw.close()
    one_pass = make_report(c, sc, "run", 2.0, 1.0, sc.seed, plots=False)
    assert not (c / "recording.raw.mcap").exists() and (c / "recording.mcap").exists()
    assert _same(one_pass, make_report(c, sc, "run", 2.0, 1.0, sc.seed, plots=False))


def test_a_report_that_fails_while_reading_the_run_leaves_the_recording_in_place(tmp_path, fixed8, monkeypatch):
    """The report reads the run in the transcode's pass: if the report fails part way, the
    transcode is finished all the same (recording.mcap in place, the raw file gone, no partial
    copy), and its error is the one raised; an iteration closed before its end (Ctrl-C) leaves
    the raw file as it was and no recording.mcap."""
    from zswarm.recording.mcap_io import transcoded
    from zswarm.results import pipeline

    sc, msgs = fixed8
    raw = RawOut(tmp_path / "recording.raw.mcap", {"engine": "test"})
    for stream, payload, t in msgs:
        raw.message(stream, payload, t)
    raw.close()
    size = (tmp_path / "recording.raw.mcap").stat().st_size

    def fails_half_way(entries, **_kw):
        for k, _ in enumerate(entries):
            if k == len(msgs) // 2:
                raise RuntimeError("a report that failed")

    monkeypatch.setattr(pipeline, "load_recording", fails_half_way)
    with pytest.raises(RuntimeError, match="a report that failed"):
        make_report(tmp_path, sc, "run", 2.0, 1.0, sc.seed, plots=False)
    assert not (tmp_path / "recording.raw.mcap").exists() and not (tmp_path / "recording.mcap.part").exists()
    assert sum(1 for _ in read(tmp_path / "recording.mcap")) == len(msgs)
    # Closed half way: nothing moved.
    (tmp_path / "d").mkdir()
    raw = RawOut(tmp_path / "d" / "recording.raw.mcap", {"engine": "test"})
    for stream, payload, t in msgs:
        raw.message(stream, payload, t)
    raw.close()
    it = transcoded(tmp_path / "d" / "recording.raw.mcap", tmp_path / "d" / "recording.mcap", sc)
    for _ in zip(range(len(msgs) // 2), it, strict=False):
        pass
    it.close()
    assert (tmp_path / "d" / "recording.raw.mcap").stat().st_size == size
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["recording.raw.mcap"]
