"""``zswarm run --rerun URL`` (issue 32): the recorder process streams the run to a listening
Rerun program while it goes on (here ``rerun --save``, which writes what it receives): every
agent's frames, the per-edge |R̄_k|_I and the jumps arrive; the run itself is not slowed into
an overload by it."""

from __future__ import annotations

import json

import pytest

from tests import browser
from tests.component.test_rerun_view import entities
from tests.conftest import TOPO
from tests.integration.conftest import zswarm
from zswarm.scenario import load

pytestmark = pytest.mark.integration


def test_run_streams_live_to_a_rerun_viewer(procs, tmp_path):
    sc = load(TOPO / "thesis-5.6-hybrid7.toml")
    out = tmp_path / "run"
    with browser.rerun_receiver(tmp_path / "live.rrd") as url:
        p = procs.start(
            zswarm("run", str(TOPO / "thesis-5.6-hybrid7.toml"), "--duration", "5", "--out", str(out), "--quiet", "--no-plots", "--rerun", url), log=tmp_path / "launcher.log"
        )
        code = p.wait(5 * 3 + 90)
        procs.adopt(out)
        assert code == 0, (tmp_path / "launcher.log").read_text()[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["completed"]
    got = entities(tmp_path / "live.rrd")
    want = (
        {f"/world/agent_{i}" for i in sc.ids} | {f"/sync/edge/attitude/{h}_{t}" for h, t in sc.oriented} | {"/hybrid/jumps", f"/commands/tau_norm/{sc.ids[0]}"}
    )
    assert not want - got, sorted(want - got)
