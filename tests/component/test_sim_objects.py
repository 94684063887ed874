"""``zswarm sim`` hands its processes validated message objects (``wire.Message``) instead
of bytes each receiver decodes (issue 28): the results are the byte path's, bit for bit,
on every shipped scenario — the same recorded messages and the same ``errors.csv``.

Bit for bit is the tolerance because nothing numerical changes: a Message is what
``wire.decode`` makes of ``wire.encode``'s bytes for the same arguments (float64 values
copied, never recomputed), so any difference is a bug (a receiver that changed a shared
message, a message validated differently, a different delivery order)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.conftest import TOPO
from zswarm import results
from zswarm.engines.sim import simulate
from zswarm.recording.mcap_io import decode
from zswarm.scenario import load
from zswarm.transport import wire
from zswarm.transport.bus import MemoryBus

SCENARIOS = sorted(p.name for p in TOPO.glob("*.toml"))
# World seconds per scenario: long enough for every process's 1 s stats, the §4/§5
# hybrid laws' first jumps (§4.5: 0.3-0.6 s; §5.6: within 2 s) and De Carli's slowest
# part (50 Hz) to have stepped many times.
DURATION = 2.5


# Wall-clock measurements of the step (perf_counter), not results: they differ between any two runs.
WALL = ("compute_mean_us", "compute_max_us")


def _results(x):
    """``x`` without the WALL counters, at any depth."""
    if isinstance(x, dict):
        return {k: _results(v) for k, v in x.items() if k not in WALL}
    if isinstance(x, list):
        return [_results(v) for v in x]
    return x


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("name", SCENARIOS)
def test_objects_and_bytes_give_the_same_run(tmp_path, name):
    sc = load(TOPO / name)
    runs = {}
    for objects in (True, False):
        out = tmp_path / str(objects)
        out.mkdir()
        msgs = simulate(sc, out, DURATION, sc.seed, record=False, objects=objects)
        summary = results.make_report(out, sc, "sim", DURATION, 0.0, sc.seed, plots=False, messages=msgs)
        runs[objects] = (msgs, (out / "errors.csv").read_bytes(), json.dumps(_results(summary), sort_keys=True, default=str))
    (m_obj, csv_obj, sum_obj), (m_bytes, csv_bytes, sum_bytes) = runs[True], runs[False]
    assert any(isinstance(p, wire.Message) for _, p, _ in m_obj) and not any(isinstance(p, wire.Message) for _, p, _ in m_bytes)
    assert len(m_obj) == len(m_bytes)
    for (s1, p1, t1), (s2, p2, t2) in zip(m_obj, m_bytes, strict=True):
        assert (s1, t1) == (s2, t2)
        if s1.startswith("events/"):
            continue
        assert _same(_results(dict(decode(p1))), _results(dict(decode(p2)))), (s1, t1)
    assert csv_obj == csv_bytes
    assert sum_obj == sum_bytes


def test_a_receiver_cannot_change_what_another_receives():
    """One Message goes to every subscriber: it arrives equal to what was sent whatever an
    earlier subscriber did with its own copy (the agent's inbox adds arrival stamps)."""
    bus = MemoryBus()
    got = []
    bus.subscribe("k", lambda k, m: got.append(m))
    bus.subscribe("k", lambda k, m: got.append(m))
    bus.publisher("k").publish("sense", 0, 1, 0.5, gyro=np.array([1.0, 2.0, 3.0]))
    a, b = got
    assert a is b and type(a) is wire.Sense
    with pytest.raises(ValueError):
        a["gyro"][0] = 5.0  # read-only, as decode's arrays are
    again = wire.decode(wire.encode_message(a))
    assert _same(dict(again), dict(a))


def test_a_message_decode_would_refuse_travels_as_bytes():
    """An invalid message is not validated into an object: its bytes go, and each receiver
    counts and drops it as it would over Zenoh."""
    got = []
    bus = MemoryBus()
    bus.subscribe("k", lambda k, m: got.append(m))
    bus.publisher("k").publish("sense", 0, 1, 0.5, gyro=np.array([np.nan, 0.0, 0.0]))
    assert isinstance(got[0], bytes)
    with pytest.raises(wire.MessageError, match="gyro: non-finite"):
        wire.decode(got[0])


def _truth_times(path):
    from zswarm.recording.mcap_io import read

    return [t for s, _, t in read(path) if s == "truth"]


def test_a_long_run_writes_as_it_goes_and_the_file_is_the_same(tmp_path, monkeypatch):
    """Past DEFER_MESSAGES the recorder writes what it held and then each message as it
    comes: the recording holds the same messages as one written after the run, and the
    CLI's report reads that file (``keep`` stays empty: the memory no longer holds them all)."""
    import zswarm.engines.sim as sim_mod
    from zswarm.recording.mcap_io import read

    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    for d in ("all", "spill"):
        (tmp_path / d).mkdir()
    kept: list = []
    simulate(sc, tmp_path / "all", 1.5, sc.seed, keep=kept)
    assert kept  # 1.5 s of §3.2: ≈ 7 000 messages, held
    cap = 1000
    monkeypatch.setattr(sim_mod, "DEFER_MESSAGES", cap)
    spilled: list = []
    simulate(sc, tmp_path / "spill", 1.5, sc.seed, keep=spilled)
    assert not spilled
    a = [(s, t) for s, _, t in read(tmp_path / "all" / "recording.mcap") if not s.startswith(("stats/", "events/"))]
    b = [(s, t) for s, _, t in read(tmp_path / "spill" / "recording.mcap") if not s.startswith(("stats/", "events/"))]
    assert len(a) > cap  # more than the recorder may hold: the spilled run wrote as it went
    assert sorted(a) == sorted(b)


def test_ctrl_c_keeps_what_was_simulated(tmp_path):
    """A KeyboardInterrupt during the run (Ctrl-C) still writes the messages held so far:
    the recording is readable up to the interruption."""
    sc = load(TOPO / "thesis-3.2-fixed8.toml")

    def interrupt(t: float) -> None:
        if t >= 2.0:
            raise KeyboardInterrupt

    (tmp_path / "o").mkdir()
    with pytest.raises(KeyboardInterrupt):
        simulate(sc, tmp_path / "o", 10.0, sc.seed, progress=interrupt)
    ts = _truth_times(tmp_path / "o" / "recording.mcap")
    # Log times are world time in ns.  progress runs at the first event at or after 2 s,
    # once it is processed, and the world's sample at 2 s is that event (samples go
    # before agent ticks at equal times): the last truth is the one of 2 s exactly.
    assert ts and max(ts) == 2_000_000_000
