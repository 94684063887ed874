"""The Foxglove layout a report writes beside each recording (zswarm/recording/layout.py): every
series it plots is a field of a channel of that recording, by the channel's own JSON schema."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest
from mcap.reader import make_reader

from tests.conftest import ROOT, TOPO
from zswarm.scenario import load


def _panels(node):
    if node.get("type") == "panel":
        yield node
    for item in node.get("items", []):
        yield from _panels(item["content"])


@pytest.mark.parametrize("name", ["thesis-3.2-fixed8", "thesis-4.5-hybrid5", "thesis-5.6-hybrid7"])
def test_the_layout_plots_fields_the_recording_has(tmp_path, name):
    out = tmp_path / name
    p = subprocess.run([sys.executable, "-m", "zswarm", "sim", str(TOPO / f"{name}.toml"), "--duration", "1", "--out", str(out), "--quiet", "--no-plots"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    layout = json.loads((out / "foxglove-layout.json").read_text())
    with open(out / "recording.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    fields = {c.topic: set(json.loads(summary.schemas[c.schema_id].data).get("properties", {})) for c in summary.channels.values() if c.message_encoding == "json"}
    panels = list(_panels(layout["content"]))
    plots = [q for q in panels if q["panelType"] == "Plot"]
    assert plots, panels
    for q in plots:
        for series in q["config"]["paths"]:
            topic, _, field = series["value"].partition(".")
            assert topic in fields and field in fields[topic], (series, sorted(fields.get(topic, ())))
    # The 3-D panel renders on the frame /tf is rooted at, from far enough back to take in every body:
    # at twice the bodies' extent from the origin they lie within ±atan(1/2) = ±27° of the view's
    # axis, inside a 3-D panel's usual 60° field of view (the layout puts the camera at 2.5).
    (three_d,) = [q for q in panels if q["panelType"] == "ThreeDee"]
    assert three_d["config"]["followTf"] == "world"
    extent = max(math.hypot(*a.p) for a in load(TOPO / f"{name}.toml").agents)
    assert three_d["config"]["cameraState"]["distance"] >= 2 * extent
