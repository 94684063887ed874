"""The golden sim runs (tests/data/golden_sim.json): what a reference holds, where its bits can be
promised, and the tolerance that applies elsewhere.

``zswarm sim`` of every shipped scenario for DURATION s of world time gives the numbers of its
``summary.json`` and the digests of ``errors.csv`` and ``edges.csv``.  A refactor of the
algorithm interface, the scenario loader or the report must not move them.

**Where the same bits hold.**  The arithmetic of a run is fixed by the code except where a
library picks its own path at run time: numpy's matmul and ``np.linalg`` go to the BLAS/LAPACK
(OpenBLAS picks its kernel by CPU, or by ``OPENBLAS_CORETYPE``: Prescott's rounds 3x3 products
otherwise than SkylakeX's, Haswell's and Zen's, and every kernel its own SVD, inverse and
determinant, measured 2026-12-05), numpy dispatches some ufuncs (``arctan2``, ``exp``) to
AVX-512 code when the CPU has it and ``NPY_DISABLE_CPU_FEATURES`` does not turn it off, and
Python's math module calls the C library.  :func:`fingerprint` records those choices with the
reference.  On the same fingerprint the run must give the same bits (every number equal, the
CSV digests equal); on another, each number is compared with :func:`tolerance`, derived below.

**The tolerance on another machine.**  A different rounding changes each operation by at most
half an ulp, u = 2^-53 relative.  A step of a run (the world's, at ``step`` <= 1 ms, and the
agents' between) does a few hundred operations on numbers of the state's scale S (positions up
to max(1, |p_i(0)|, |p̂_i(0)|) m; rotation entries <= 1), and the observers and the closed
loops are contracting, so round-off does not grow faster than it is made: after N world steps
a state differs by at most N·K·u·S, K = 256 ulps a step.  Then a number w of the summary:

- plain (an error norm, a rate, ξ, a time): |g − w| <= N·K·u·(S + |w|) (the state's floor and
  the number's own relative rounding);
- an attitude measure |X|_I = sqrt((3 − tr X)/4) of one agent or edge (``attitude_error``,
  ``Q_tilde``): the round-off lands on its square, which is a sum of rotation entries, so
  |g² − w²| <= E = N·K·u, that is |g − w| <= E/(g + w) (exact), at most sqrt(E).  Measured: the
  §3.3 follower at |R̃|_I = 1.7e-7 moves by 4.3e-10 (0.25 %) between the SkylakeX and Haswell
  kernels, a change of 1.5e-16 on its square: one rounding of the trace;
- a mean or a maximum of such measures (``mean_…``, ``max_…``, ``synchronization.…``): each
  term moves by at most sqrt(E), and so does their mean or maximum.

With N = 2000 (2 s at 1 kHz) E = 5.7e-11: a converged attitude (|R̃|_I ~ 1e-7, the floor of
the arithmetic) may move by up to 7.5e-6 on another machine, while an O(1) number may move by
5.7e-11·(S + |w|).  A gain changed by 1e-6 relative moves the §3.2 position errors by ~1e-6 and
its attitude errors by ~5e-7 (measured), four orders above these bounds on the numbers it
moves: test_golden_sim checks that such a change fails the comparison on every machine.  The
numbers that are not floats (counts, strings, flags) are compared for equality everywhere.
"""

from __future__ import annotations

import hashlib
import json
import math
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from tests.conftest import ROOT, TOPO

GOLDEN = ROOT / "tests" / "data" / "golden_sim.json"
DURATION = 2.0  # s of world time: the hybrid schemes' jumps at t = 0 and first flow, the De Carli estimators' first updates
SCENARIOS = sorted(p.stem for p in TOPO.glob("*.toml"))
# Measured wall times and the wall-time-derived figures are not results.
NOT_RESULTS = ("wall_time", "compute_mean_us", "compute_max_us", "compute_s")
# Keys summary.json gained after the reference was written (not numbers of the run): left out
# of the comparison of key sets; every number of the reference is still compared.
ADDED = ("report_family",)
U = 2.0**-53  # the unit round-off of a double
K_ULPS = 256  # ulps of the state's scale a step may change by under another rounding (module docstring)
SQRT_MEASURES = ("attitude_error", "Q_tilde")  # |X|_I = sqrt((3 − tr X)/4): the report's attitude measures
AGGREGATES = ("mean_", "max_")
SYNC_MEASURES = ("synchronization.initial", "synchronization.final")  # the maximum over edges of |R̄_k|_I


def numbers(x: Any, path: str = "") -> dict[str, Any]:
    """The summary's result leaves: path -> number, string, bool or None (timings left out)."""
    if isinstance(x, dict):
        out: dict[str, Any] = {}
        for k, v in x.items():
            if any(n in k for n in NOT_RESULTS):
                continue
            out.update(numbers(v, f"{path}.{k}" if path else str(k)))
        return out
    if isinstance(x, list):
        out = {}
        for n, v in enumerate(x):
            out.update(numbers(v, f"{path}[{n}]"))
        return out
    return {path: x}


def run(name: str, out: Path, overrides: tuple[str, ...] = ()) -> dict[str, Any]:
    """``zswarm sim`` of a shipped scenario (with ``--set`` overrides) for DURATION s, its report's
    numbers and its CSVs' digests."""
    from zswarm.engines.sim import simulate
    from zswarm.results import make_report
    from zswarm.scenario import load
    from zswarm.scenario.overrides import parse_override

    sc = load(TOPO / f"{name}.toml", [parse_override(o) for o in overrides])
    simulate(sc, out, DURATION, sc.seed)
    summary = make_report(out, sc, "sim", DURATION, 0.0, sc.seed, plots=False)
    digests = {f: hashlib.sha256((out / f).read_bytes()).hexdigest() for f in ("errors.csv", "edges.csv") if (out / f).exists()}
    return {"csv_sha256": digests, "summary": numbers(json.loads(json.dumps(summary))), "scale": {"S": scale(sc), "N": DURATION / sc.step}}


def scale(sc: Any) -> float:
    """S of the module docstring: the largest initial position or position estimate, at least 1 m."""
    s = 1.0
    for a in sc.agents:
        s = max(s, *(abs(float(x)) for x in a.p))
        for v in a.estimate.values.values():  # the 3-vectors among them: positions (rotations are 9 entries <= 1)
            if isinstance(v, tuple | list) and len(v) == 3 and all(isinstance(x, int | float) for x in v):
                s = max(s, *(abs(float(x)) for x in v))
    return s


def fingerprint() -> dict[str, Any]:
    """What decides the rounding of a run on this machine: numpy's version and build, the BLAS
    library numpy calls and the kernel it picked (threadpoolctl: OpenBLAS's core name), the SIMD
    targets numpy dispatches to here, whether zswarm's compiled loops are loaded, the C library."""
    try:
        from numpy._core._multiarray_umath import __cpu_baseline__, __cpu_dispatch__, __cpu_features__
    except ImportError:  # numpy 1.x
        from numpy.core._multiarray_umath import __cpu_baseline__, __cpu_dispatch__, __cpu_features__

    from zswarm.math import kernels

    return {
        "machine": platform.machine(),
        "python": sys.version.split()[0],
        "libc": " ".join(platform.libc_ver()),
        "numpy": np.__version__,
        "blas": _numpys_blas(),
        "simd": {"baseline": list(__cpu_baseline__), "dispatched": [t for t in __cpu_dispatch__ if __cpu_features__.get(t)]},
        "fma": bool(__cpu_features__.get("FMA3")),  # the C library's sin, exp, ... take FMA code paths where the CPU has it
        "kernels": kernels._lib is not None,
    }


_BLAS: list[dict[str, Any]] = []


def _numpys_blas() -> list[dict[str, Any]]:
    """numpy's BLAS as threadpoolctl reports it, asked of an interpreter that has loaded numpy
    alone (this one may have loaded scipy's own OpenBLAS too), in this environment (which holds
    OPENBLAS_CORETYPE); remembered for the process."""
    if not _BLAS:
        code = (
            "import json, numpy, threadpoolctl; print(json.dumps(sorted(({k: i.get(k) for k in ('internal_api', 'version', 'architecture')}"
            " for i in threadpoolctl.threadpool_info() if i.get('user_api') == 'blas'), key=json.dumps)))"
        )
        _BLAS.extend(json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120).stdout))
    return _BLAS


def reference() -> dict[str, Any]:
    return json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}


def tolerance(key: str, w: float, g: float, S: float, N: float) -> float:
    """The most |g − w| may be on another machine (module docstring)."""
    E = N * K_ULPS * U
    leaf = key.rsplit(".", 1)[-1]
    if key in SYNC_MEASURES or (any(m in leaf for m in SQRT_MEASURES) and leaf.startswith(AGGREGATES)):
        return math.sqrt(E)  # a mean or maximum of measures: each moves by at most sqrt(E)
    if any(m in leaf for m in SQRT_MEASURES):
        return min(math.sqrt(E), E / max(abs(g) + abs(w), 1e-300))  # |g − w| = |g² − w²|/(g + w)
    return E * (S + abs(w))


def compare(got: dict[str, Any], want: dict[str, Any], same_machine: bool) -> list[str]:
    """The differences of a run's numbers ``got`` from the reference's ``want`` (one line each):
    bit for bit on the reference's machine, within :func:`tolerance` elsewhere."""
    problems = []
    gs, ws = got["summary"], want["summary"]
    missing = (set(gs) ^ set(ws)) - set(ADDED)
    if missing:
        problems.append(f"keys differ: {sorted(missing)}")
    S, N = want["scale"]["S"], want["scale"]["N"]
    for k, w in ws.items():
        if k not in gs:
            continue
        g = gs[k]
        if isinstance(w, float) and isinstance(g, float) and math.isnan(w) and math.isnan(g):
            continue
        if same_machine or not isinstance(w, float) or isinstance(w, bool) or not isinstance(g, float):
            if g != w:
                problems.append(f"{k}: {g!r}, the reference {w!r} (same machine: bit for bit)")
            continue
        tol = tolerance(k, w, g, S, N)
        if not abs(g - w) <= tol:
            problems.append(f"{k}: {g!r}, the reference {w!r}: |Δ| = {abs(g - w):.3g} > {tol:.3g}")
    if same_machine and got["csv_sha256"] != want["csv_sha256"]:
        problems.append(f"CSV digests differ: {got['csv_sha256']} against {want['csv_sha256']}")
    return problems
