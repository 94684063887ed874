"""``make golden``: write tests/data/golden_sim.json anew on this machine, on a commit whose
numbers are known good (every shipped scenario, tests/golden.py's run), with this machine's
rounding fingerprint.  It writes; it tests nothing and reports no test result: commit the
file with the reason its numbers changed.

    python -m tests.write_golden [SCENARIO ...]   (default: every shipped scenario)
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from tests import golden


def main(argv: list[str]) -> int:
    names = argv or golden.SCENARIOS
    unknown = sorted(set(names) - set(golden.SCENARIOS))
    if unknown:
        print(f"write_golden: no such shipped scenario: {', '.join(unknown)} (topologies/*.toml)", file=sys.stderr)
        return 2
    ref = golden.reference()
    fp = golden.fingerprint()
    if argv and ref.get("fingerprint") not in (None, fp):
        print("write_golden: the reference was written on another machine; write every scenario here (no arguments)", file=sys.stderr)
        return 2
    scenarios = ref.get("scenarios", {}) if argv else {}
    for name in names:
        with tempfile.TemporaryDirectory() as d:
            scenarios[name] = golden.run(name, Path(d))
        print(f"  {name}", flush=True)
    golden.GOLDEN.write_text(json.dumps({"fingerprint": fp, "scenarios": scenarios}, indent=1, sort_keys=True) + "\n")
    print(f"wrote {golden.GOLDEN.relative_to(golden.ROOT)}: {len(names)} scenario(s) on {fp}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
