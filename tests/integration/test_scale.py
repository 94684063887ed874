"""16 agents of a generated scenario on `zswarm run`: a loaded machine is not a dead process.

On 2 cores 16 agents at 100 Hz, the world at 200 Hz, the recorder and the router
are close to the machine's capacity (missed deadlines are expected and reported),
and with another process keeping a core busy they exceed it.  None of that may
read as a failure: no agent stops because the world "went away", no liveliness
token flaps, every agent is alive at the end, and the recording holds everything
the processes published or summary.json says exactly what it lacks.

At time scale 0.5 (the agents' 100 Hz in world time are 50 Hz of wall time): on
the slower days of this machine (a raw Zenoh agent at 8–9 % of a core instead of
5 %) time scale 1 put it at twice its capacity, agents at 32–44 Hz, and one of 16
agents' sessions still dropped and re-joined once in 20 s (a 28 ms reconnect).
That is recorded as open in issue 13; this test holds the runtime to "loaded, not
dead" near capacity.

Overload alone does not make a token flap (measured 2026-12-02 with every process
of the test in a CPU-quota cgroup: at 0.7 of a core agents ran at 52 Hz with 245
missed deadlines, at 0.45 of a core at 31 Hz with 746; beside 11 busy-looping
processes at 100 Hz; no flap in any).  CI's machine once flapped one agent's
session (2026-12-02: lost every token, back 0.6 s later; agents there at 61 Hz):
a link silent for the 1 s lease, which overload does not do, and a machine that
stops (a virtual CPU descheduled by its host) does.  So a flap is accepted only
when the test process itself measured such a stop (``StallMeter``) and the token
came back; without one it fails the test as before.  (At 0.45 of a core the
quota itself made the meter late by up to 0.28 s: well below the 0.75 s taken as
a stop.)
"""

from __future__ import annotations

import json
import re
from collections import defaultdict

import pytest

from tests.integration.conftest import assert_run_exit_ok, not_alive, pid_alive, zswarm
from zswarm.recording.mcap_io import read
from zswarm.studies.generate import generate
from zswarm.transport.bus import LEASE_MS

pytestmark = pytest.mark.integration
N, DURATION = 16, 20.0
LEASE_S = LEASE_MS / 1000


def test_sixteen_agents_no_false_failure_and_a_counted_recording(procs, tmp_path, stall_meter):
    text, sc = generate("bearing-fixed", N, 1, duration=DURATION)
    topo = tmp_path / "gen16.toml"
    topo.write_text(text)
    out = tmp_path / "out"
    p = procs.start(zswarm("run", str(topo), "--out", str(out), "--time-scale", "0.5", "--quiet", "--no-plots"), log=tmp_path / "launcher.log")
    code = p.wait(DURATION * 2 * 4 + 120)  # time scale 0.5: twice DURATION of wall time, ×4 as before, + start-up
    procs.adopt(out)
    s = assert_run_exit_ok(code, out, tmp_path / "launcher.log")
    assert s["completed"]
    assert not (why := not_alive(out, s)), why
    assert all(v == 0 for v in s["exit_codes"].values()), s["exit_codes"]
    stall_meter.stop()
    # A flap (a token gone and back while its process ran) is a false failure unless the
    # machine itself stopped: every link carries a message at least every 20 ms of wall
    # time here and a keep-alive every lease/4 when idle, so a link is silent for the
    # lease only if its ends were stopped for at least lease - lease/4.  The stall meter
    # (conftest.StallMeter) sees such a stop of the machine; a flap without one is the
    # runtime's fault (as when Zenoh's receiving thread waited for the GIL: 5 of 16
    # agents flapped in a 20 s run at time scale 1, over this machine's capacity).
    machine_stopped = stall_meter.max_late >= 0.75 * LEASE_S
    longest = sorted(stall_meter.stalls, key=lambda st: -st[1])[:5]
    why = f"the machine's longest stop: {stall_meter.max_late:.3f} s ({len(stall_meter.stalls)} over 0.1 s; longest at: {longest})"
    # No agent gave up on the world (the world's token goes at the end, after the agents'
    # last tick: an agent may log that, never a stop before its last step).
    for i in sc.ids:
        log = (out / "logs" / f"agent-{i}.log").read_text()
        assert "did not come back" not in log, (i, log[-2000:])
        before_end = log.split("stopped after")[0]
        assert machine_stopped or "lost the world's token" not in before_end, (i, why, log[-2000:])
    # Liveliness: every token appeared once and went at most once (at the end), and only
    # the keys of processes the run started appeared.
    changes: dict[str, list[bool]] = defaultdict(list)
    topics = set()
    for topic, m, _t in read(out / "recording.mcap"):
        topics.add(topic.split("/")[0])
        if topic == "events/alive":
            changes[m["key"]].append(m["alive"])
    run_id = json.loads((out / "processes.json").read_text())["run_id"]
    expected = {f"zswarm/{run_id}/alive/agent/{i}" for i in sc.ids} | {f"zswarm/{run_id}/alive/world/0", f"zswarm/{run_id}/alive/recorder/0"}
    # Each key carries the tag of the run's secret (keys.alive_tag): 24 hex digits.
    untagged = {k.rsplit("/", 1)[0] for k in changes if re.fullmatch(r"[0-9a-f]{24}", k.rsplit("/", 1)[1])}
    assert untagged == expected and len(changes) == len(expected), set(changes)
    for key, seq in changes.items():
        # after a stop of the machine, a token may go and come back, alternating, and
        # must be back before the end (every agent alive at the end: asserted above)
        flapped = seq[:1] == [True] and all(a != b for a, b in zip(seq, seq[1:]))
        assert seq in ([True], [True, False]) or (machine_stopped and flapped), (key, seq, why)
    assert topics <= {"truth", "sense", "edge", "est", "stats", "ctl", "events"}, topics
    # The recording: what each process says it published (final stats), per channel,
    # against what was recorded.  Either nothing is missing or the count says how much.
    rec = s["recording"]
    assert rec["exact"], rec
    assert rec["recorded"] + rec["missing_total"] == rec["published"]
    assert rec["missing_total"] == sum(rec["missing"].values())
    steps = sum(a["steps"] for a in s["agents"].values())
    # published: a truth and N sense messages per world sample, an est per step, edges, stats
    assert rec["published"] > s["world"]["samples"] * (N + 1) + steps
    assert not [c for c in procs.adopt(out) if pid_alive(c["pid"])]
    print(why)
