"""A published number run again: the same bits on the machine that wrote its file, the same
printed figure on any other.

The data files behind the docs' tables (docs/data/, the sweeps and basins of docs/figures/) were
written on one machine, whose rounding (tests/golden.py's fingerprint: numpy's SIMD targets, the
BLAS kernel, the C library's FMA builds, zswarm's compiled loops) is kept in
docs/data/machine.json (``python -m tests.reproduce`` writes it).  There a re-run takes the same
code path, so it gives the file's cells exactly as rows.cell writes them (six significant
digits).  Elsewhere round-off differs, and over a long run it may grow: tests/golden.py measured
up to ~50 ulps of a number's scale over 2 s and, near a converged measure's floor, moves of
3.8e-9 on 1.7e-7; over 150 s of §4.5's continuous observer a perturbation grows x835, and a
quickstart re-run of it moved its final measure by 1.1e-3 of itself under tests/layers.sh's
other-machine settings.  What a re-run must give there is what the page prints: each number
within one unit of its third significant digit (the tables print two to four), or within the
attitude measure's round-off floor sqrt(C_TRACE·u) = 1.7e-7 (tests/golden.py) where that is
larger; counts, jump numbers and verdicts exactly.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

from tests.conftest import ROOT
from tests.golden import C_TRACE, U, fingerprint
from zswarm.util import rows as rows_io

MACHINE = ROOT / "docs" / "data" / "machine.json"
FLOOR = math.sqrt(C_TRACE * U)


def same_machine() -> bool:
    """Whether this machine rounds as the one that wrote the docs' data files."""
    return fingerprint() == json.loads(MACHINE.read_text())["fingerprint"]


def _number(s: str) -> float | None:
    try:
        return float(s)
    except ValueError:
        return None


def _exact(s: str) -> bool:
    """A count, a verdict or a label: compared exactly everywhere."""
    return _number(s) is None or s.lstrip("-").isdigit()


def near(a: float, b: float) -> bool:
    """Within one unit of the third significant digit of the larger, or the round-off floor."""
    if a == b:
        return True
    if not (math.isfinite(a) and math.isfinite(b)):
        return False
    unit = 10.0 ** (math.floor(math.log10(max(abs(a), abs(b)))) - 2)
    return abs(a - b) <= max(unit, FLOOR)


def differ(got: Mapping[str, object], want: Mapping[str, str], skip: Iterable[str] = ("wall_s",), same_path: bool = True) -> dict[str, tuple[str, str]]:
    """The cells of a re-run ``got`` (values) that its file's row ``want`` (strings) does not
    give: exactly on the file's machine, to the printed figure elsewhere (module docstring).
    ``same_path=False``: the re-run took another code path than the file's (``sim`` for a row
    the batched engine wrote: the same equations, another order of the same sums), which rounds
    otherwise on any machine, so it is held to the printed figure everywhere."""
    exact = same_path and same_machine()
    out: dict[str, tuple[str, str]] = {}
    for k, v in got.items():
        if k in skip:
            continue
        a, b = str(rows_io.cell(v)), want[k]
        if a == b:
            continue
        if exact or _exact(a) or _exact(b):
            out[k] = (a, b)
            continue
        x, y = _number(a), _number(b)
        if x is None or y is None or not near(x, y):
            out[k] = (a, b)
    return out


def write_main(description: str, default: Path, write: Callable[[Path], None]) -> None:
    """The ``--write [FILE]`` command of a test module that keeps a reference file (``make
    fine-references``): ``write(FILE)``, ``default`` without FILE, and the path printed."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--write", type=Path, nargs="?", const=default, required=True, metavar="FILE", help=f"the file to write (without FILE: {default.relative_to(ROOT)})")
    out = ap.parse_args().write
    write(out)
    print(out)


if __name__ == "__main__":
    MACHINE.write_text(json.dumps({"written_by": "python -m tests.reproduce", "fingerprint": fingerprint()}, indent=1) + "\n")
    print(MACHINE)
