"""Summaries that say what they cannot know (issue 61, item 7), over real processes: a killed
sender's "sent" and a killed receiver's "delivered" are lower bounds and say so, an agent killed
by a ``kill`` fault has its fate, and a summary made again says what the folder ran with.  (A
world that died is not put down to late sensor packets: test_processes.py, where it dies.)

The run is the five agents of §3.3 (edges 1->3, 2->3, 2->4, 3->4, 3->5, 4->5) for 7 s at time
scale 1."""

from __future__ import annotations

import json
import subprocess

import pytest

from tests.conftest import TOPO
from tests.integration.conftest import assert_run_exit_ok, stop_tail, wait_for, zswarm

pytestmark = pytest.mark.integration
T33 = str(TOPO / "thesis-3.3-moving5.toml")


def test_a_killed_sender_counts_sent_as_a_lower_bound_and_a_killed_agent_has_its_fate(procs, tmp_path):
    """Agent 3 SIGKILLed at 2 s and restarted at 3 s; agent 4 SIGKILLed at 2.5 s for good.

    A process sends its counts once a second of world time (and a last time on a clean exit):
    what a SIGKILLed incarnation sent after its last stats never reaches the recorder, so its
    "sent" is a lower bound (a restarted §3.2 agent's link read 3444 delivered of 3349 sent).
    The killed process's exit code is filed under ``agent-4~killed1``; its fate was looked up
    under ``agent-4`` and the summary had none."""
    out = tmp_path / "out"
    p = procs.start(
        zswarm("run", T33, "--duration", "7", "--out", str(out), "--no-plots", "--fault", "kill,agent=3,at=2,restart_at=3", "--fault", "kill,agent=4,at=2.5"),
        log=tmp_path / "launcher.log",
    )
    wait_for(lambda: procs.adopt(out), 60, "processes.json")
    code = p.wait(180)
    procs.adopt(out)  # the restarted agent too
    log = (tmp_path / "launcher.log").read_text()
    s = assert_run_exit_ok(code, out, tmp_path / "launcher.log")
    assert s["exit_codes"]["agent-4~killed1"] == -9 and "agent-4" not in s["exit_codes"], s["exit_codes"]
    # The fate of agent 4 is its killed process's exit status; agent 3's is its restarted
    # process's (exit 0, its final stats recorded: the count of every other agent is exact).
    assert s["agents"]["4"].get("fate") == "killed by signal 9", s["agents"]["4"]
    assert s["agents"]["3"].get("fate") == "finished", s["agents"]["3"]
    assert "agent 4: killed by signal 9" in log, log[-3000:]
    links = s["links"]
    # Agent 3's first incarnation and agent 4 were SIGKILLed: what they sent is a lower bound.
    for name in ("3->4", "3->5", "4->5"):
        assert links[name].get("sent_is_lower_bound") is True, (name, links[name])
    # Every other sender exited cleanly with its final stats: its count is exact.
    for name in ("1->3", "2->3", "2->4", "world->1", "world->5"):
        assert "sent_is_lower_bound" not in links[name], (name, links[name])
    # The table says which counts are lower bounds.
    said = [x for x in log.splitlines() if x.startswith("sent counts are lower bounds")]
    assert len(said) == 1 and all(n in said[0] for n in ("3->4", "3->5", "4->5")) and "1->3" not in said[0], said
    # The receiving side.  Agent 3 ran as two processes, each counting from 0: link 1->3's
    # delivered is their sum (the newest alone read 339 of 698 sent), what the first received in
    # its last second is not in it, and 1->3 says both.  Agent 4, killed for good, likewise.
    into3 = links["1->3"]
    assert len(into3["delivered_by_incarnation"]) == 2 and into3["delivered"] == sum(into3["delivered_by_incarnation"].values()), into3
    # Sent at 100 Hz for 7 s; lost: agent 3's second of death and its restart (the token came
    # back fault["token"]["back_at"] - 3 s after it), plus a second of counts at each kill.
    back = next(f for f in s["faults"] if f.get("agent") == 3)["token"]["back_at"]
    assert into3["sent"] - into3["delivered"] <= 100 * ((back - 2.0) + 1.0) + stop_tail(100.0), (into3, back)
    for name in ("1->3", "2->3", "2->4", "3->4"):
        assert links[name].get("delivered_is_lower_bound") is True, (name, links[name])
    assert "delivered_is_lower_bound" not in links["world->5"] and "delivered_is_lower_bound" not in links["4->5"], (links["world->5"], links["4->5"])
    said = [x for x in log.splitlines() if x.startswith("delivered counts are lower bounds")]
    assert len(said) == 1 and all(n in said[0] for n in ("1->3", "3->4")) and "4->5" not in said[0], said
    # Its summary lost, the report made again says what the folder ran with: the recorder's
    # metadata (copied from its raw file into recording.mcap) and the start message.
    (out / "summary.json").unlink()
    r = subprocess.run(zswarm("report", str(out)), capture_output=True, text=True, timeout=300)
    s2 = json.loads((out / "summary.json").read_text())
    assert (s2["engine"], s2["duration_s"], s2["time_scale"]) == ("run", 7.0, 1.0), r.stderr[-2000:]
    assert s2["remade"] == {"engine": "recording metadata", "duration_s": "recording ctl/start", "time_scale": "recording ctl/start", "seed": "recording ctl/start"}, s2["remade"]
