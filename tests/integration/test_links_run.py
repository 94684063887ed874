"""Link emulation on ``zswarm run`` (issue 4): real processes over Zenoh.

Drop ratio: each link's losses are Bernoulli(0.3) draws from its own seeded
generator, so the measured ratio (1 − delivered/sent, counted by the sender
and the receiver) must lie within 3σ = 3·sqrt(0.3·0.7/sent) of 0.3, plus the
messages still in flight when the agents stop (not losses, but not
delivered either: the 50 ms delay queue and the stop's tail).

Delay: the delay applied to each message is exactly the configured 50 ms; the
observed latency (release to the agent minus the sender's stamp) adds the
real transport to it: the sender's step after its stamp, the network, the
receiver's callback thread.  Its median must lie between 50 ms and 50 ms plus
one agent period (10 ms): a message later than that at the median would miss
the receiver's next tick more often than not, which is what the runtime must
not do.  (Measured: 0.1–3 ms over the delay on a quiet machine, 5 ms with 8
agents on 2 slower cores.)

Convergence: at delay 50 ms and drop 0.2, ``run`` and ``sim`` must agree on
the time after which the followers' mean errors stay below the report's
thresholds within 25 %.
"""

from __future__ import annotations

import math

import pytest

from tests.conftest import TOPO
from tests.integration.conftest import assert_run_exit_ok, not_alive, stop_tail, zswarm

pytestmark = pytest.mark.integration

FIXED8 = TOPO / "thesis-3.2-fixed8.toml"


def run(procs, tmp_path, sets, duration, scale=1.0):
    out = tmp_path / "run"
    args = [a for s in sets for a in ("--set", s)]
    p = procs.start(zswarm("run", str(FIXED8), *args, "--duration", str(duration), "--time-scale", str(scale), "--out", str(out), "--quiet", "--no-plots"), log=tmp_path / "launcher.log")
    code = p.wait(duration / scale * 3 + 90)
    procs.adopt(out)
    s = assert_run_exit_ok(code, out, tmp_path / "launcher.log")
    assert s["completed"]
    assert not (why := not_alive(out, s)), why
    return out, s


def test_drop_ratio_and_delay_on_every_link(procs, tmp_path):
    sets = ["links.drop=0.3", "links.delay_ms=50", "links.sensors.drop=0.3", "links.sensors.delay_ms=50"]
    _, s = run(procs, tmp_path, sets, 10.0)
    links = s["links"]
    assert len(links) == 22  # 14 edges and 8 sensor links
    for name, c in links.items():
        # In flight at the stop: the 50 ms delay queue, then the stop's tail (conftest.STOP_SKEW_S).
        rate = 200.0 if name.startswith("world->") else 100.0  # sensors / edges
        in_flight = round(0.05 * rate) + stop_tail(rate)
        sent = c["sent"]
        lost = sent - c["delivered"]
        sigma = math.sqrt(0.3 * 0.7 / sent)
        assert abs(lost / sent - 0.3) <= 3 * sigma + in_flight / sent, (name, c)
        assert 50.0 <= c["latency_p50_ms"] <= 50.0 + 1e3 / 100.0, (name, c)  # plus at most one agent period (docstring)
        assert c["applied_delay_p50_ms"] == pytest.approx(50.0, abs=1e-6)


def test_sim_and_run_agree_on_convergence_time_with_lossy_delayed_links(procs, sim_reference, tmp_path):
    sets = ["links.delay_ms=50", "links.drop=0.2"]
    # At time scale 1 (the links' 50 ms are in world time at any scale).  Beside
    # `stress-ng --cpu 1` the world skipped 1.5-1.6 % of its samples here (2026-12-03) while
    # it skipped every sample it woke a period late; it now takes them late, up to 0.1 s
    # (test_run.py).  Before issue 28 a busy machine made the agents miss up to 23 % of their
    # ticks at 1 (attitude 24.9 s against sim's 11.2 s).
    ref = sim_reference(FIXED8, tmp_path / "sim", sets=tuple(sets), lean=True)  # computed while the run runs
    _, s = run(procs, tmp_path, sets, 40.0)
    ss = ref.summary()
    for key in ("attitude_s", "position_s"):
        tr, ts = s["convergence"][key], ss["convergence"][key]
        assert tr is not None and ts is not None, (s["convergence"], ss["convergence"])
        assert abs(tr - ts) <= 0.25 * ts, (key, tr, ts)
