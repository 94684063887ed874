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
"""

from __future__ import annotations

import json
from collections import defaultdict

import pytest

from tests.integration.conftest import pid_alive, zswarm
from zswarm.generate import generate
from zswarm.record import read

pytestmark = pytest.mark.integration
N, DURATION = 16, 20.0


def test_sixteen_agents_no_false_failure_and_a_counted_recording(procs, tmp_path):
    text, sc = generate("bearing-fixed", N, 1, duration=DURATION)
    topo = tmp_path / "gen16.toml"
    topo.write_text(text)
    out = tmp_path / "out"
    p = procs.start(zswarm("run", str(topo), "--out", str(out), "--time-scale", "0.5", "--quiet"), log=tmp_path / "launcher.log")
    code = p.wait(DURATION * 2 * 4 + 120)  # time scale 0.5: twice DURATION of wall time, ×4 as before, + start-up
    procs.adopt(out)
    assert code == 0, (tmp_path / "launcher.log").read_text()[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["completed"]
    assert all(a["alive_at_end"] for a in s["agents"].values()), {i: a["alive_at_end"] for i, a in s["agents"].items()}
    assert all(v == 0 for v in s["exit_codes"].values()), s["exit_codes"]
    # No agent gave up on the world while the run was on (the world's token goes at the end,
    # after the agents' last tick: an agent may log that, never a stop before its last step).
    for i in sc.ids:
        log = (out / "logs" / f"agent-{i}.log").read_text()
        assert "did not come back" not in log, (i, log[-2000:])
        before_end = log.split("stopped after")[0]
        assert "lost the world's token" not in before_end, (i, log[-2000:])
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
    assert set(changes) == expected, set(changes) ^ expected
    for key, seq in changes.items():
        assert seq in ([True], [True, False]), (key, seq)
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
