"""A report that cannot be forged or poisoned (issue 29): each message is filed under its
key's process, messages stamped outside the run are counted and ignored, no error is
computed across a truth gap, a recording cut short is said to be, and summary.json is
strict JSON.  In-memory recordings of ``zswarm sim`` with messages added or taken out,
as a hostile peer or a dying recorder would leave them.  The same over Zenoh under
``--secure``: tests/integration/test_secure.py; a SIGKILLed recorder:
tests/integration/test_processes.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import TOPO
from zswarm.engines.sim import simulate
from zswarm.math import so3
from zswarm.report import OUTSIDE_RUN_MARGIN_S, TRUTH_GAP_PERIODS, TRUTH_GAP_S, errors, load_recording
from zswarm.results import make_report
from zswarm.scenario import load, parse_override
from zswarm.transport import wire

DURATION = 3.0


@pytest.fixture(scope="module")
def fixed8():
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    return sc, simulate(sc, Path("."), DURATION, sc.seed, record=False)


def _report(tmp_path: Path, sc, msgs, name: str) -> dict:
    out = tmp_path / name
    out.mkdir()
    make_report(out, sc, "sim", DURATION, 0.0, sc.seed, plots=False, messages=msgs)
    text = (out / "summary.json").read_text()

    def no_constant(c: str) -> None:
        raise AssertionError(f"summary.json holds {c}, which is not JSON")

    return json.loads(text, parse_constant=no_constant)  # strict: NaN/Infinity would raise


def _forged(t: float) -> list[tuple[str, bytes, int]]:
    """What a peer holding agent 4's rights can put on agent 4's own keys, claiming to be
    agent 3 and the world inside the messages (audit of 2026-12-03)."""
    R = so3.exp(np.array([2.0, 0.0, 0.0]))
    ns = int(t * 1e9)
    return [
        ("est/4", wire.encode("est", 3, 10**6, t, inc=9, t_local=t, R_hat=R, p_hat=np.full(3, 50.0)), ns),
        ("stats/agent/4", wire.encode("stats", 3, 10**6, t, inc=9, role="agent", counters={"steps": 424242, "final": True, "links": {"1->3": {"delivered": 0, "dropped": 10**6, "reordered": 0}}}), ns),
        ("stats/agent/4", wire.encode("stats", 0, 10**6, t, inc=9, role="world", counters={"late": 999999, "final": True}), ns),
    ]


def test_a_message_is_filed_under_its_key_not_its_src(tmp_path, fixed8):
    sc, msgs = fixed8
    clean = _report(tmp_path, sc, msgs, "clean")
    forged = [*msgs[: len(msgs) // 2], *_forged(1.5), *msgs[len(msgs) // 2 :], *_forged(DURATION - 0.1)]
    s = _report(tmp_path, sc, forged, "forged")
    # Filed under agent 3 and the world they made agent 3's error 0.28 -> 33.6 m, its steps
    # 424242, link 1->3 "all dropped", the world "late 999999" (overloaded).
    for k in ("agents", "links", "world", "overload", "convergence", "mean_attitude_error_final", "mean_position_error_final"):
        assert s[k] == clean[k], k
    assert s["malformed_in_recording"] == 6 and clean["malformed_in_recording"] == 0
    assert s["recording"]["missing_total"] == 0 and not s["recording"]["surplus"]  # not counted as recorded on est/4


def test_a_message_stamped_outside_the_run_is_counted_and_ignored(tmp_path, fixed8):
    """One wire-valid estimate stamped t = 1e12: it took the final window (position error
    1.37 -> 9902), and on the §4 observers the report built a 10 ms grid up to it."""
    sc, msgs = fixed8
    clean = _report(tmp_path, sc, msgs, "clean")
    far = wire.encode("est", 5, 10**6, 1e12, t_local=1e12, R_hat=np.eye(3), p_hat=np.full(3, 9e3))
    late = wire.encode("est", 5, 10**6 + 1, DURATION + 0.5 * OUTSIDE_RUN_MARGIN_S, t_local=0.0, R_hat=np.eye(3), p_hat=np.full(3, 9e3))
    s = _report(tmp_path, sc, [*msgs, ("est/5", far, 0), ("est/5", late, 0)], "far")
    # The one within the margin is the run's (an agent's last step after the stop): it counts.
    assert s["agents"]["5"]["last_estimate_t"] == DURATION + 0.5 * OUTSIDE_RUN_MARGIN_S
    assert s["recording"]["outside_run"] == {"est": 1}
    assert s["agents"]["3"] == clean["agents"]["3"]


def test_the_tree_report_survives_an_estimate_from_the_far_future(tmp_path):
    """§4.5 (per-edge metrics on a 10 ms grid from the first to the last estimate): a t = 1e12
    estimate made it allocate 728 TiB (MemoryError) and summary.json held only the error."""
    sc = load(TOPO / "thesis-4.5-continuous5.toml")
    msgs = simulate(sc, Path("."), 1.0, sc.seed, record=False)
    far = ("est/2", wire.encode("est", 2, 10**6, 1e12, t_local=1e12, R_hat=np.eye(3), p_hat=np.zeros(3)), 0)
    out = tmp_path / "out"
    out.mkdir()
    a = make_report(out, sc, "sim", 1.0, 0.0, sc.seed, plots=False, messages=msgs)
    b = make_report(out, sc, "sim", 1.0, 0.0, sc.seed, plots=False, messages=[*msgs, far])
    assert b["edges"] == a["edges"] and b["recording"]["outside_run"] == {"est": 1}


def test_no_error_is_computed_across_a_truth_gap(tmp_path, fixed8):
    """The recorder stopped for a while: the truth has a gap.  Interpolated across it, the
    error read 0.91 where the real one was 0.01.  Now NaN there, and the gap is reported."""
    sc, msgs = fixed8
    gap = (1.0, 1.6)
    cut = [m for m in msgs if not (m[0] == "truth" and gap[0] < wire.decode(m[1])["t"] < gap[1])]
    rec_full, rec_cut = load_recording(msgs), load_recording(cut)
    e_full, e_cut = errors(rec_full), errors(rec_cut)
    period = float(np.median(np.diff(rec_full.truth_t)))
    for i in sc.ids:
        t = e_cut[i][:, 0]
        inside = (t > gap[0] + 1e-9) & (t < gap[1] - 1e-9)
        assert inside.any() and np.isnan(e_cut[i][inside, 1:]).all()
        # Elsewhere the same figures (with a truth sample at most one period away).
        np.testing.assert_array_equal(e_cut[i][~inside], e_full[i][~inside])
    s = _report(tmp_path, sc, cut, "gap")
    g = s["recording"]["truth_gaps"]
    assert g["count"] == 1 and g["bound_s"] == pytest.approx(max(TRUTH_GAP_S, TRUTH_GAP_PERIODS * period))
    (a, b), = g["spans"]
    assert a == pytest.approx(gap[0], abs=period) and b == pytest.approx(gap[1], abs=period)
    assert not s["recording"]["cut_short"]  # a gap is not an end ...
    # ... but data was lost there as at a cut end (issue 50): a problem naming the span.
    assert not s["completed"] and any(p.startswith("the recording has 1 hole (no truth for longer than") and f"{a:.2f}-{b:.2f} s" in p for p in s["problems"]), s["problems"]


def test_a_recording_cut_short_is_not_a_completed_run(tmp_path, fixed8):
    """The recorder died at t = 1.95 s of 3: the recording has neither the rest nor the stop.
    The summary says where it ends, and the final errors (over the run's last second) are
    NaN (null), not the last values before the cut."""
    sc, msgs = fixed8
    stop = 1.95
    cut = [m for m in msgs if m[2] <= stop * 1e9 and m[0] != "ctl/stop"]
    s = _report(tmp_path, sc, cut, "cut")
    assert not s["completed"] and any("ends at t = 1.95 s of 3" in p for p in s["problems"]), s["problems"]
    r = s["recording"]
    assert r["cut_short"] and not r["exact"] and r["ends_at_s"] == pytest.approx(stop, abs=0.01)
    assert r["truth_gaps"]["spans"][-1][1] == DURATION
    assert s["agents"]["3"]["attitude_error_final"] is None  # no estimate with a truth in the last second


# Gains of 1e12 overflow the law's products on purpose: numpy's overflow warnings are the point.
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning", "ignore:invalid value encountered:RuntimeWarning")
def test_most_steps_failed_is_not_a_completed_run(tmp_path):
    """Gains of 1e12: 271 of 301 steps failed, NaN errors, and the run read completed."""
    sc = load(TOPO / "thesis-3.2-fixed8.toml", overrides=[parse_override("algorithm.gains.k_R=1e12")])
    msgs = simulate(sc, Path("."), 1.0, sc.seed, record=False)
    out = tmp_path / "out"
    out.mkdir()
    s = make_report(out, sc, "sim", 1.0, 0.0, sc.seed, plots=False, messages=msgs)
    failed = {i: a["step_failures"] for i, a in s["agents"].items() if a["step_failures"]}
    assert failed and not s["completed"], failed
    assert any(f"agent {i} failed" in p for p in s["problems"] for i in failed)
    json.loads((out / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    # 101 ticks in 1 s at 100 Hz: those that failed and those that stepped make them up.
    assert all(a["step_failures"] + a["steps"] == 101 for a in s["agents"].values())


def test_junk_payloads_do_not_reach_the_disk(tmp_path, fixed8):
    """300 payloads of 1 MB on est/3 grew the run recorder's raw file by 300 MB in a second.
    The recorder writes a payload as it came only up to what a message of the run can be
    (wire.max_payload, by kind: 16 KiB for an estimate); a bigger one is described
    (stream, size) and counted malformed, in the viewer recording and in summary.json.  Half
    the junk is 200 KB, which the single 256 KiB limit before 2026-12-07 let through."""
    from zswarm.recording.capture import Recorder
    from zswarm.recording.mcap_io import read, transcode
    from zswarm.transport import keys
    from zswarm.transport.bus import MemoryBus
    from zswarm.transport.wire import max_payload

    sc, msgs = fixed8
    bus = MemoryBus()
    path = tmp_path / "recording.raw.mcap"
    rec = Recorder(bus, "r", path, now_ns=lambda: 0, scenario=sc, raw=True)
    big, small = np.random.default_rng(1).bytes(1 << 20), np.random.default_rng(2).bytes(200_000)
    for k in range(300):
        bus.put(keys.est("r", 3), big if k % 2 else small)
    edge = wire.encode("edge", 1, 0, 0.5, t_local=0.5, R_hat=np.eye(3), p_hat=np.zeros(3), b=np.array([0.0, 0.0, 1.0]))
    bus.put(keys.edge("r", 1, 3), edge)  # a real message beside them is written
    rec.close()
    assert path.stat().st_size < 100_000 and rec.malformed == 300
    assert max_payload(8, "est/3") < len(small) < 256 << 10 < len(big)  # the single limit before 2026-12-07: 256 KiB
    assert transcode(path, tmp_path / "recording.mcap", sc) == 300
    got = list(read(tmp_path / "recording.mcap"))
    bad = [m for s, m, _ in got if s == "events/malformed"]
    # The first ten described, the rest counted on their key in one entry (issue 50: a flood
    # left an entry a message); the sizes add up either way.
    assert len(bad) == 11 and all(m["stream"] == "est/3" for m in bad) and bad[-1]["count"] == 290
    assert sum(m.get("count", 1) for m in bad) == 300 and sum(m["size"] for m in bad) == 150 * ((1 << 20) + 200_000)
    assert [s for s, _, _ in got if not s.startswith("events/")] == ["edge/1/3"]
    # The report counts what the recorder described (summary.json said 0: the count was dropped).
    assert load_recording([*msgs, *got]).malformed == 300
