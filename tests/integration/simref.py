"""A run's ``sim`` reference in a process of its own (tests/integration/conftest.py,
SimReference): ``python -m tests.integration.simref '{"topo": ..., "sets": [...], "duration":
null, "out": ..., "lean": false, "record": false}'`` simulates the scenario, makes its report
in ``out`` and writes the report's summary to ``out/reference.json`` (json's NaN kept, as
``make_report`` returns it)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from zswarm.engines.sim import simulate
from zswarm.results import make_report
from zswarm.scenario import load, parse_override


def main(spec: str) -> None:
    a = json.loads(spec)
    sc = load(Path(a["topo"]), [parse_override(x) for x in a["sets"]])
    duration = sc.duration if a["duration"] is None else float(a["duration"])
    out = Path(a["out"])
    out.mkdir(parents=True, exist_ok=True)
    msgs = simulate(sc, out, duration, sc.seed, lean=a["lean"], record=a["record"])
    kw = {} if a["record"] else {"messages": msgs}  # in memory: the report needs no file
    summary = make_report(out, sc, "sim", duration, 0.0, sc.seed, plots=False, **kw)
    (out / "reference.json").write_text(json.dumps(summary))


if __name__ == "__main__":
    main(sys.argv[1])
