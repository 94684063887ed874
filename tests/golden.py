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

**The bound on another machine: its form from the math, its constants from a measurement.**
A run on another machine rounds some operations otherwise (another BLAS kernel, another SIMD
width, FMA or not, another libm); each such difference is an ulp or a few of the numbers it is
made on.  ``python -m tests.measure_golden_spread`` (``make golden-spread``) forces here every
kernel and SIMD setting this machine can fake (14 settings: OpenBLAS's Prescott, Nehalem,
Sandybridge, Haswell and SkylakeX kernels, numpy's dispatch from AVX512_SPR down to its X86_V2
baseline, glibc's libm with and without its FMA builds, zswarm's compiled loops off and their
default clone, and combinations) and keeps every number that moved in
tests/data/golden_spread.json.  The bound has two parts.

- **The state's part, K ulps of the quantity's scale.**  A perturbation δ made at one step
  reaches the end of the run through the linearised dynamics; where they contract it is no
  larger there, so after N steps the state differs by at most the sum of what each step
  rounded, N·k·u of its scale (u = 2^-53), and a number w read from it by K·u·(S + |w|),
  K = N·k: S the positions' scale (tests/golden.py ``scale``: at least 1 m; rotation entries
  and angles are <= 1), |w| the number's own rounding.  For an attitude measure the scale is
  1: K·u·(1 + |w|).  It is relative (K·u·|w|) where a number is above its state's scale, and
  absolute where it is below: a converged error w ≪ S is the difference of two numbers of size
  S (p̂_i − p_i, a yaw of a rotation), so it cannot be known better than u·S, and it is not
  (measured: the §3.2 leaders' position errors, 9.7e-15 m, move by 8.7e-15, 90 % of their
  value, 11 ulps of S; a De Carli relative yaw error, 9.7e-6 rad, by 1.8e-14, 1.9e-9 of its
  value).  Measured over the 14 settings (golden_spread.json "derived"), K is at most 27 ulps
  on the numbers that are not attitude measures (a De Carli relative yaw error, libm without
  FMA) and 50 on the measures beyond their floor below (§4.5 hybrid, agent 1 at 0.19, the
  oldest setting), all of N = 2000 steps: 0.03 ulps a step on average, against the 256 a step
  the old estimate took (but not a rate to scale by: see below).  K_ULPS is SAFETY = 16 times
  the worst measured (another machine may combine other roundings than this one can fake),
  rounded up to a power of two.  Where a run's dynamics grow a perturbation, K is that run's
  own measured worst times 16, rounded up (AMPLIFIED, with the growth measured).
- **The measure's floor.**  |X|_I = sqrt((3 − tr X)/4) is computed from the trace of a product
  of rotations, a sum of O(1) numbers: its square is known to an absolute c·u whatever its size
  (one rounding of each of three 3-term dot products and of their sum, 6.5 ulps between two
  machines; the states' departures from orthogonality add to it), so |g² − w²| <= C·u, that
  is |g − w| <= C·u/(g + w), at most sqrt(C·u) (1.7e-7 for C = 256).  Below ~1e-7 a measure is
  this round-off, not a value: no relative bound can hold there.  The summary's "final"
  numbers are means over the last second of such samples; where the samples are smaller than
  their mean (a converging error) the floor of the mean is set by the smallest; measured, C is
  at most 15.9 ulps on the square of a measure below 1e-3 (§3.3's follower 5 at |R̃|_I = 2.6e-4,
  moved by 3.3e-12 by the Prescott and Sandybridge kernels; follower 3 at 1.7e-7 by 3.8e-9,
  11.4 ulps).  C_TRACE is 16 times that, rounded up.  A mean or maximum over agents or edges
  (``mean_…``, ``max_…``, ``synchronization.…``) moves by at most the most any of its terms
  may: the largest bound of the measures it is made of (:func:`_terms`).

**The constants hold for the runs measured, DURATION s (N_MEASURED steps), and are not scaled to
another length.**  The sum above bounds what contracting dynamics make of the round-off, but
these runs do not contract at every instant, and the measurement shows it
(tests/data/golden_growth.json, ``python -m tests.measure_golden_spread --growth``: five runs at
1, 2, 4 and 8 s, the default against Prescott's kernel and libm without FMA): §3.3 at 1 s has
moved its follower 3's |R̃_3|_I = 7.8e-3 by 1.9e-10, 100 times this bound, and is back at its
floor by 2 s; from 2 to 4 s, K of the numbers that are not measures grows x12 in §5.6 hybrid
(2.9 -> 34 ulps, far from synchronised), x5 in the §4.5 hybrid pose run (24 -> 123) and x1.2 in
§3.2 (11 -> 13).  So :func:`bounds` refuses a run of another length: a golden run of another
length or step needs ``make golden-spread`` anew.  What a gain changed by 1e-6
moves, and by how many times its bound, under each setting, is in the same file; test_golden_sim
checks the file against these constants and a gain change live on the four thesis schemes.
The numbers that are not floats (counts, strings, flags) are compared for equality everywhere;
so are the times read on a grid (settle times, jump times): a round-off flips one only where the
value at a grid point is within ~1e-13 of its threshold.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
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
# The bound's constants (module docstring), from tests/data/golden_spread.json, measured 2026-12-07 over 14
# settings of this machine's OpenBLAS, numpy dispatch, libm and compiled loops:
SAFETY = 16  # the bound over the worst spread measured here: other machines combine other roundings
N_MEASURED = 2000  # world steps of the measured runs (DURATION / 1 ms)
K_ULPS = 1024  # ulps of a number's scale a run may move by: 16 x 50.5 (the worst measured, §4.5 hybrid agent 1) -> 2^10
C_TRACE = 256  # ulps the square of an attitude measure may move by at its floor: 16 x 15.9 (§3.3 follower 5) -> 2^8
# Runs whose dynamics grow a perturbation: their own worst measured K times SAFETY, rounded up to a
# power of two (ulps of the number's scale, as K_ULPS).  The growth is measured by turning one
# initial estimate by 1e-12 rad (tests/data/golden_growth.json).
AMPLIFIED = {
    # The continuous §4.5 observer grows what it is given (the hybrid one was made against it):
    # agent 1's initial estimate turned by 1e-12 rad moves its final |R̃|_I by 8.3e-10 (x835; the
    # hybrid run x0.41 at most, the noisy continuous one x0.04).  Measured K 4.9e5 ulps (edge 4 at 8.2e-4,
    # the Prescott and Sandybridge kernels).  Its noisy twin needs none: 31 ulps.
    "thesis-4.5-continuous5": 2**23,
    # The velocity-free law's auxiliary filter (Q_i, ζ_i): Q_3(0) turned by 1e-12 rad moves Q̃_3 by
    # 4.6e-12 at the end (x4.6).  Measured K 3.3e3 ulps (Q̃_3 at 0.018, Sandybridge) and 1.8e3 (noisy,
    # Q̃_6 at 0.044, the oldest setting); every other number of these runs by <= 36.
    "thesis-5.6-velocity-free7": 2**16,
    "thesis-5.6-velocity-free7-noisy": 2**15,
}
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

    fp: dict[str, Any] = {
        "machine": platform.machine(),
        "python": sys.version.split()[0],
        "libc": " ".join(platform.libc_ver()),
        "numpy": np.__version__,
        "blas": _numpys_blas(),
        "simd": {"baseline": list(__cpu_baseline__), "dispatched": [t for t in __cpu_dispatch__ if __cpu_features__.get(t)]},
        "fma": bool(__cpu_features__.get("FMA3")),  # the C library's sin, exp, ... take FMA code paths where the CPU has it
        "kernels": kernels._lib is not None,
    }
    if os.environ.get("GLIBC_TUNABLES"):  # can turn off the C library's FMA builds of sin, exp, ... (other bits, measured)
        fp["glibc_tunables"] = os.environ["GLIBC_TUNABLES"]
    return fp


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


def k_ulps(name: str, N: float) -> float:
    """K of the module docstring for scenario ``name``, measured for N_MEASURED world steps only."""
    if N != N_MEASURED:
        raise ValueError(f"{name}: a run of {N:g} world steps; the bound was measured on {N_MEASURED} (make golden-spread anew)")
    return AMPLIFIED.get(name, K_ULPS)


def is_measure(key: str) -> bool:
    """An attitude measure |X|_I (of one agent or edge, or a mean or maximum of such)."""
    return key in SYNC_MEASURES or any(m in key.rsplit(".", 1)[-1] for m in SQRT_MEASURES)


def is_aggregate(key: str) -> bool:
    return key in SYNC_MEASURES or key.rsplit(".", 1)[-1].startswith(AGGREGATES)


def tolerance(key: str, w: float, g: float, S: float, K: float, terms: float = 0.0) -> float:
    """The most |g − w| may be on another machine (module docstring): K ulps of the number's
    scale, and for an attitude measure its floor; ``terms``, for a mean or maximum of measures,
    the largest bound of the measures it is made of."""
    if not is_measure(key):
        return K * U * (S + abs(w))
    floor = min(math.sqrt(C_TRACE * U), C_TRACE * U / max(abs(g) + abs(w), 1e-300))  # |g − w| = |g² − w²|/(g + w)
    own = K * U * (1.0 + abs(w)) + floor
    return max(own, terms) if is_aggregate(key) else own


def bounds(name: str, got: dict[str, Any], want: dict[str, Any], K: float | None = None) -> dict[str, float]:
    """The bound of every float of the reference ``want`` that ``got`` has (a float too); ``K``
    other than the run's own only to see what it would be elsewhere (tests/measure_golden_spread.py)."""
    gs, ws = got["summary"], want["summary"]
    S, N = want["scale"]["S"], want["scale"]["N"]
    K = k_ulps(name, N) if K is None else K

    def pair(k: str) -> tuple[float, float] | None:
        w, g = ws.get(k), gs.get(k)
        if isinstance(w, float) and isinstance(g, float) and not (math.isnan(w) or math.isnan(g)):
            return w, g
        return None

    floats = {k: p for k in ws if (p := pair(k)) is not None}
    own = {k: tolerance(k, w, g, S, K) for k, (w, g) in floats.items() if is_measure(k) and not is_aggregate(k)}
    return {k: tolerance(k, w, g, S, K, _terms(k, own, ws)) if is_aggregate(k) else tolerance(k, w, g, S, K) for k, (w, g) in floats.items()}


def _terms(key: str, own: dict[str, float], summary: dict[str, Any]) -> float:
    """The largest bound of the measures an aggregate is made of: ``mean_X``/``max_X`` of the
    agents' or edges' ``X`` (a leader's left out: the report's means are over followers,
    report/base.py headline), or of every per-agent and per-edge measure where none is named so
    (``synchronization.…``, or a family's mean of another series)."""
    base = key.rsplit(".", 1)[-1].removeprefix("mean_").removeprefix("max_")
    named = [t for k, t in own.items() if k.rsplit(".", 1)[-1] == base and summary.get(k.rsplit(".", 1)[0] + ".role") != "leader"]
    return max(named or own.values(), default=0.0)


def compare(got: dict[str, Any], want: dict[str, Any], same_machine: bool, name: str) -> list[str]:
    """The differences of a run's numbers ``got`` from the reference's ``want`` (one line each):
    bit for bit on the reference's machine, within :func:`tolerance` elsewhere."""
    problems = []
    gs, ws = got["summary"], want["summary"]
    missing = (set(gs) ^ set(ws)) - set(ADDED)
    if missing:
        problems.append(f"keys differ: {sorted(missing)}")
    tol = {} if same_machine else bounds(name, got, want)
    for k, w in ws.items():
        if k not in gs:
            continue
        g = gs[k]
        if isinstance(w, float) and isinstance(g, float) and math.isnan(w) and math.isnan(g):
            continue
        if k not in tol:
            if g != w:
                problems.append(f"{k}: {g!r}, the reference {w!r} ({'same machine: bit for bit' if same_machine else 'not a float: equal'})")
            continue
        if not abs(g - w) <= tol[k]:
            problems.append(f"{k}: {g!r}, the reference {w!r}: |Δ| = {abs(g - w):.3g} > {tol[k]:.3g}")
    if same_machine and got["csv_sha256"] != want["csv_sha256"]:
        problems.append(f"CSV digests differ: {got['csv_sha256']} against {want['csv_sha256']}")
    return problems
