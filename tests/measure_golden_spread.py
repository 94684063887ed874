"""``make golden-spread``: measure how far the golden sim runs' numbers move on this machine
under every kernel and SIMD setting that can be forced here, and how far a gain changed by a
millionth moves them, and write it to tests/data/golden_spread.json (tests/golden.py derives
its bound from it; tests/component/test_golden_sim.py holds the bound to it).  It writes; it
tests nothing and reports no test result.

    python -m tests.measure_golden_spread            (every setting below; ~5 min of one core, `make golden-spread`)
    python -m tests.measure_golden_spread --margins  (the margins anew from the numbers kept, after the bound's constants changed)
    python -m tests.measure_golden_spread --growth   (tests/data/golden_growth.json: the runs at other lengths, and how
                                                     much a run grows an initial estimate turned by 1e-12 rad; ~3 min)
    python -m tests.measure_golden_spread --child OUT   (one setting: the one in the environment)

Each setting is a set of environment variables read at process start, so each runs in an
interpreter of its own (the ``--child``):

- OpenBLAS's kernel (``OPENBLAS_CORETYPE``): the build is DYNAMIC_ARCH, and of the names it
  accepts, these load a kernel of their own here (threadpoolctl's name in the file: Prescott
  reports "Katmai", its alias in a 64-bit build; Core2 is Prescott's too, Zen and Cooperlake
  Haswell's and SkylakeX's, Atom Nehalem's; an unknown name is the CPU's own);
- numpy's dispatch (``NPY_DISABLE_CPU_FEATURES``): the AVX512_SPR target alone (what the
  reference's machine had), the whole AVX-512 family (tests/layers.sh's OTHER), and every
  dispatch target down to the X86_V2 baseline (no AVX2, no FMA in numpy's loops);
- the C library's own paths (``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA``): glibc's sin, cos,
  exp, atan2, ... have FMA builds chosen at load time; this turns them off (measured: other bits);
- zswarm's compiled loops: off (``ZSWARM_KERNELS=0``, numpy's code) and the default clone
  alone (``-DZSWARM_DEFAULT_ONLY``, what a CPU without AVX2 runs; ``ZSWARM_KERNELS_FILE``);
- combinations: tests/layers.sh's OTHER exactly, OTHER with glibc without FMA, and the oldest
  machine this can fake (Prescott, numpy at its baseline, glibc without FMA, the default clone).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path
from typing import Any

from tests import golden

SPREAD = golden.ROOT / "tests" / "data" / "golden_spread.json"
_AVX512 = "AVX512F,AVX512CD,AVX512_SKX,AVX512_CLX,AVX512_CNL,AVX512_ICL,AVX512_SPR,X86_V4"  # tests/layers.sh's OTHER
_BASELINE = "X86_V3,X86_V4,AVX512_ICL,AVX512_SPR"  # every dispatch target of numpy 2.x above X86_V2
_NO_FMA_LIBM = "glibc.cpu.hwcaps=-AVX2,-FMA"
DEFAULT_BUILD = "@default-build"  # replaced by the path of the -DZSWARM_DEFAULT_ONLY build

SETTINGS: dict[str, dict[str, str]] = {
    "default": {},
    "openblas=Prescott": {"OPENBLAS_CORETYPE": "Prescott"},
    "openblas=Nehalem": {"OPENBLAS_CORETYPE": "Nehalem"},
    "openblas=Sandybridge": {"OPENBLAS_CORETYPE": "Sandybridge"},
    "openblas=Haswell": {"OPENBLAS_CORETYPE": "Haswell"},
    "numpy-AVX512_SPR": {"NPY_DISABLE_CPU_FEATURES": "AVX512_SPR"},
    "numpy-AVX512": {"NPY_DISABLE_CPU_FEATURES": _AVX512},
    "numpy-baseline": {"NPY_DISABLE_CPU_FEATURES": _BASELINE},
    "libm-FMA": {"GLIBC_TUNABLES": _NO_FMA_LIBM},
    "kernels-off": {"ZSWARM_KERNELS": "0"},
    "kernels-default-build": {"ZSWARM_KERNELS_FILE": DEFAULT_BUILD},
    "layers-OTHER": {"OPENBLAS_CORETYPE": "Prescott", "NPY_DISABLE_CPU_FEATURES": _AVX512},
    "layers-OTHER+libm-FMA": {"OPENBLAS_CORETYPE": "Prescott", "NPY_DISABLE_CPU_FEATURES": _AVX512, "GLIBC_TUNABLES": _NO_FMA_LIBM},
    "oldest": {"OPENBLAS_CORETYPE": "Prescott", "NPY_DISABLE_CPU_FEATURES": _BASELINE, "GLIBC_TUNABLES": _NO_FMA_LIBM, "ZSWARM_KERNELS_FILE": DEFAULT_BUILD},
}

# The gain changes the comparison must catch: every gain of one scenario of each chapter's
# schemes, times 1 + 1e-6.  A gain given per agent is changed where it is given (§3.3's k_R).
GAIN_CHANGE = 1e-6
GAINS: dict[str, dict[str, float]] = {
    "thesis-3.2-fixed8": {"algorithm.gains.k_R": 1.0, "algorithm.gains.k_p": 1.0},
    "thesis-3.3-moving5": {"algorithm.gains.k_p": 1.0, "agents[2].gains.k_R": 10.0, "agents[3].gains.k_R": 5.0, "agents[4].gains.k_R": 3.0},
    "thesis-4.5-hybrid-pose5": {"algorithm.gains.k_R": 1.1, "algorithm.gains.k_xi": 3.5, "algorithm.gains.k_p": 1.0},
    "thesis-5.6-hybrid7": {"algorithm.gains.k_R": 0.4, "algorithm.gains.k_omega": 0.1, "algorithm.gains.k_xi": 20.0},
}
# Measured too (not in the live test): the two runs whose bound is widened (tests/golden.py AMPLIFIED).
GAINS_ALSO: dict[str, dict[str, float]] = {
    "thesis-4.5-continuous5": {"algorithm.gains.k_R": 1.1},
    "thesis-5.6-velocity-free7": {"algorithm.gains.k_R": 0.4, "algorithm.gains.k_Q": 30.0},
}


def changed(field: str, value: float) -> str:
    """The ``--set`` of ``field`` at ``value`` times 1 + GAIN_CHANGE."""
    return f"{field}={value * (1 + GAIN_CHANGE)!r}"


def build_default_clone(where: Path) -> Path:
    """zswarm/math/_kernels.c built with its default clone alone (as tests/unit/test_kernels.py does)."""
    gcc = shutil.which("gcc")
    if gcc is None:
        raise SystemExit("measure_golden_spread: gcc is needed for the default build of zswarm/math/_kernels.c")
    so = where / "_kernels_default.so"
    flags = ["-O2", "-ffp-contract=off", "-fno-math-errno", "-Wno-psabi", "-DZSWARM_DEFAULT_ONLY", "-shared", "-fPIC"]
    source = golden.ROOT / "zswarm" / "math" / "_kernels.c"
    subprocess.run([gcc, *flags, "-I", sysconfig.get_paths()["include"], str(source), "-o", str(so), "-lm"], check=True, timeout=300)
    return so


def child(out: Path) -> None:
    """Every golden scenario and every gain change, under this process's setting: their numbers."""
    runs: dict[str, Any] = {}
    perturbed: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as d:
        for name in golden.SCENARIOS:
            where = Path(d) / name
            where.mkdir()
            runs[name] = golden.run(name, where)["summary"]
        for name, gains in (GAINS | GAINS_ALSO).items():
            for field, value in gains.items():
                where = Path(d) / f"{name} {field}"
                where.mkdir()
                perturbed[f"{name} {field}"] = golden.run(name, where, (changed(field, value),))["summary"]
    from zswarm.math import kernels

    loaded = getattr(kernels._lib, "__file__", None)
    out.write_text(json.dumps({"fingerprint": golden.fingerprint(), "kernels_file": loaded, "runs": runs, "perturbed": perturbed}))


def moved(got: dict[str, Any], want: dict[str, Any]) -> dict[str, Any]:
    """The numbers of a run's summary that differ from the reference's (NaN equal to NaN)."""
    out = {}
    for k, w in want.items():
        g = got.get(k)
        if g != w and not (isinstance(g, float) and isinstance(w, float) and math.isnan(g) and math.isnan(w)):
            out[k] = g
    return out


def _run(want: dict[str, Any], values: dict[str, Any]) -> dict[str, Any]:
    """A run rebuilt from the reference and the numbers that moved."""
    return {"summary": {**want["summary"], **values}, "csv_sha256": None, "scale": want["scale"]}


def margins(settings: dict[str, Any], reference: dict[str, Any]) -> dict[str, Any]:
    """For each setting: the largest |Δ|/bound of each scenario's numbers (below 1/SAFETY is what
    the bound promises), and for each gain change the largest |Δ|/bound and how many numbers
    are beyond their bound (the comparison fails where that is > 0)."""
    out: dict[str, Any] = {}
    for setting, m in settings.items():
        spread = {}
        for name, values in m["moved"].items():
            want = reference[name]
            got = _run(want, values)
            tol = golden.bounds(name, got, want)
            worst = max(((abs(got["summary"][k] - want["summary"][k]) / tol[k], k) for k in values if k in tol), default=(0.0, None))
            unequal = sorted(k for k in values if k not in tol and k not in golden.ADDED)
            spread[name] = {"worst_over_bound": worst[0], "worst": worst[1], "unequal": unequal}
        gains = {}
        for change, values in m["gain_changes"].items():
            name = change.split()[0]
            want = reference[name]
            got = _run(want, values)
            tol = golden.bounds(name, got, want)
            ratios = sorted(((abs(got["summary"][k] - want["summary"][k]) / tol[k], k) for k in values if k in tol), reverse=True)
            gains[change] = {
                "largest_over_bound": ratios[0][0] if ratios else 0.0,
                "largest": ratios[0][1] if ratios else None,
                "beyond_bound": sum(r > 1 for r, _ in ratios),
                "fails": bool(golden.compare(got, want, False, name)),
            }
        out[setting] = {"spread": spread, "gain_changes": gains}
    return out


FLOOR_BELOW = 1e-3  # a measure this small is read for its floor: K·u·(1 + w) at K = 64 is < 0.02 ulps of its square 2w·Δ


def _pow2(x: float) -> int:
    return 1 << max(0, math.ceil(math.log2(x))) if x > 0 else 1


def derived(settings: dict[str, Any], reference: dict[str, Any]) -> dict[str, Any]:
    """The measured quantities the bound's constants are SAFETY times (tests/golden.py), each with
    where it was measured, over every setting and every per-agent or per-edge number (a mean or
    maximum is bound by its terms):

    - C: the most the square of a measure below FLOOR_BELOW moved, in ulps (|g² − w²|/u);
    - K_other: the most a number that is not a measure moved, in ulps of S + |w|;
    - K_measure: the most a measure moved beyond its floor C·u/(g + w), in ulps of 1 + |w|;
    - K_amplified: for each run of golden.AMPLIFIED, the larger of the two K over its numbers.

    C and the two K are over the other runs."""
    u = golden.U
    rows = []
    for setting, m in settings.items():
        for name, values in m["moved"].items():
            want = reference[name]
            S = want["scale"]["S"]
            for k, g in values.items():
                w = want["summary"][k]
                if isinstance(w, float) and isinstance(g, float) and not (math.isnan(w) or math.isnan(g)) and not golden.is_aggregate(k):
                    rows.append((setting, name, k, w, g, S))

    def best(items: list[tuple[float, str, str, str]]) -> dict[str, Any]:
        v, setting, name, key = max(items, default=(0.0, "", "", ""))
        return {"ulps": v, "setting": setting, "scenario": name, "key": key}

    C = best([(abs(g * g - w * w) / u, s, n, k) for s, n, k, w, g, _ in rows if n not in golden.AMPLIFIED and golden.is_measure(k) and abs(w) < FLOOR_BELOW])
    c = C["ulps"]

    def K(s: str, n: str, k: str, w: float, g: float, S: float) -> tuple[float, str, str, str]:
        if golden.is_measure(k):
            return max(0.0, abs(g - w) - c * u / max(abs(g) + abs(w), 1e-300)) / (u * (1.0 + abs(w))), s, n, k
        return abs(g - w) / (u * (S + abs(w))), s, n, k

    return {
        "C": C,
        "K_other": best([K(*r) for r in rows if r[1] not in golden.AMPLIFIED and not golden.is_measure(r[2])]),
        "K_measure": best([K(*r) for r in rows if r[1] not in golden.AMPLIFIED and golden.is_measure(r[2])]),
        "K_amplified": {n: best([K(*r) for r in rows if r[1] == n]) for n in sorted(golden.AMPLIFIED)},
    }


def constants(d: dict[str, Any]) -> dict[str, Any]:
    """The bound's constants SAFETY times the measured ``derived`` gives, each rounded up to a power of two."""
    f = golden.SAFETY
    return {
        "K_ULPS": _pow2(f * max(d["K_other"]["ulps"], d["K_measure"]["ulps"])),
        "C_TRACE": _pow2(f * d["C"]["ulps"]),
        "AMPLIFIED": {n: _pow2(f * v["ulps"]) for n, v in d["K_amplified"].items()},
    }


def write(settings: dict[str, Any], machine: str) -> None:
    reference = golden.reference()
    doc = {
        "about": (
            "The golden sim runs (tests/data/golden_sim.json) under each kernel and SIMD setting of this machine: the numbers that "
            "moved from the reference (moved), and the numbers of each run with a gain times 1 + 1e-6 that differ from the reference "
            "(gain_changes).  margins: each scenario's largest |Δ|/bound (the bound promises <= 1/SAFETY) and each gain change's "
            "largest |Δ|/bound and count of numbers beyond their bound.  derived: what the bound's constants are SAFETY times.  "
            "Written by `python -m tests.measure_golden_spread`; tests/golden.py derives its bound from it."
        ),
        "machine": machine,
        "reference_fingerprint": reference["fingerprint"],
        "gain_change": GAIN_CHANGE,
        "bound": {"SAFETY": golden.SAFETY, "K_ULPS": golden.K_ULPS, "C_TRACE": golden.C_TRACE, "AMPLIFIED": golden.AMPLIFIED},
        "settings": settings,
        "derived": derived(settings, reference["scenarios"]),
        "margins": margins(settings, reference["scenarios"]),
    }
    SPREAD.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")


GROWTH = golden.ROOT / "tests" / "data" / "golden_growth.json"
LENGTHS = (1.0, 2.0, 4.0, 8.0)  # s of world time
LENGTH_RUNS = ("thesis-3.2-fixed8", "thesis-3.3-moving5", "thesis-4.5-hybrid-pose5", "thesis-5.6-hybrid7", "thesis-5.6-velocity-free7-noisy")
LENGTH_SETTINGS = ("default", "openblas=Prescott", "libm-FMA")
TURN = 1e-12  # rad: one initial estimate turned by this much
TURNS = {  # run -> the initial estimate turned (its angle as the scenario gives it)
    "thesis-4.5-continuous5": ("agents[0].estimate.R.angle", "-pi/2"),
    "thesis-4.5-continuous5-noisy": ("agents[0].estimate.R.angle", "-pi/2"),
    "thesis-4.5-hybrid5": ("agents[0].estimate.R.angle", "-pi/2"),
    "thesis-5.6-velocity-free7": ("agents[2].estimate.Q.angle", "pi/2"),
}


def child_lengths(out: Path) -> None:
    """The LENGTH_RUNS for each of LENGTHS, under this process's setting: their numbers."""
    runs = {}
    with tempfile.TemporaryDirectory() as d:
        for length in LENGTHS:
            golden.DURATION = length
            for name in LENGTH_RUNS:
                where = Path(d) / f"{name} {length}"
                where.mkdir()
                runs[f"{name} {length:g}"] = golden.run(name, where)
    out.write_text(json.dumps(runs))


def growth() -> None:
    """How far the constants measured at DURATION hold at other lengths (the default against two
    settings, each number's |Δ| over its bound as it stands), and how much a run grows what it is
    given (one initial estimate turned by TURN: the largest move of a number at the end)."""
    raw = {}
    with tempfile.TemporaryDirectory() as d:
        for setting in LENGTH_SETTINGS:
            out = Path(d) / f"{setting}.json"
            argv = [sys.executable, "-m", "tests.measure_golden_spread", "--child-lengths", str(out)]
            subprocess.run(argv, env={**os.environ, **SETTINGS[setting]}, cwd=golden.ROOT, check=True, timeout=3600)
            raw[setting] = json.loads(out.read_text())
        turned = {}
        for name, (field, angle) in TURNS.items():
            (Path(d) / name).mkdir()
            (Path(d) / f"{name} turned").mkdir()
            base = golden.run(name, Path(d) / name)["summary"]
            moved_ = golden.run(name, Path(d) / f"{name} turned", (f'{field}="{angle}+{TURN!r}"',))["summary"]
            floats = [(abs(moved_[k] - w), k, w) for k, w in base.items() if isinstance(w, float) and isinstance(moved_.get(k), float) and not math.isnan(w)]
            d_, key, w = max(floats)
            turned[name] = {"turned": field, "by_rad": TURN, "largest_move": d_, "of": key, "value": w, "gain": d_ / TURN}
    lengths: dict[str, Any] = {}
    for setting in LENGTH_SETTINGS[1:]:
        for run, got in raw[setting].items():
            name = run.split()[0]
            want = raw["default"][run]
            tol = golden.bounds(name, got, want, golden.k_ulps(name, golden.N_MEASURED))
            r, k = max(((abs(got["summary"][k] - want["summary"][k]) / tol[k], k) for k in tol), default=(0.0, ""))
            S = want["scale"]["S"]
            other = [abs(got["summary"][k] - want["summary"][k]) / (golden.U * (S + abs(want["summary"][k]))) for k in tol if not golden.is_measure(k)]
            lengths.setdefault(setting, {})[run] = {
                "N": want["scale"]["N"],
                "worst_over_bound": r,
                "worst": k,
                "value": want["summary"].get(k),
                "moved_by": abs(got["summary"][k] - want["summary"][k]) if k else 0.0,
                "K_other": max(other, default=0.0),
            }
    doc = {
        "about": (
            "Written by `python -m tests.measure_golden_spread --growth`.  lengths: the golden runs LENGTH_RUNS at 1, 2, 4 and 8 s of "
            "world time under two settings against the default, each run's largest |Δ|/bound with the bound's constants as they "
            "stand (measured at 2 s) and its K of the numbers that are not measures (ulps of S + |w|).  turned: one initial "
            "estimate turned by 1e-12 rad, the largest move of a number at 2 s and its ratio to the turn."
        ),
        "machine": _cpu(),
        "lengths": lengths,
        "turned": turned,
    }
    GROWTH.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")


def _cpu() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").exists() else []:
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown"


def main(argv: list[str]) -> int:
    if argv[:1] == ["--child"]:
        child(Path(argv[1]))
        return 0
    if argv[:1] == ["--child-lengths"]:
        child_lengths(Path(argv[1]))
        return 0
    if argv[:1] == ["--growth"]:
        growth()
        print(f"wrote {GROWTH.relative_to(golden.ROOT)}")
        return 0
    if argv[:1] == ["--margins"]:  # the bound's constants changed: the margins anew from the numbers kept
        doc = json.loads(SPREAD.read_text())
        write(doc["settings"], doc["machine"])
        print(f"wrote {SPREAD.relative_to(golden.ROOT)} (margins only)")
        return 0
    reference = golden.reference()
    if reference.get("fingerprint") is None:
        print("measure_golden_spread: no reference (make golden first)", file=sys.stderr)
        return 2
    want = reference["scenarios"]
    settings: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as d:
        so = build_default_clone(Path(d))
        for name, env in SETTINGS.items():
            real = {k: (str(so) if v == DEFAULT_BUILD else v) for k, v in env.items()}
            out = Path(d) / f"{len(settings)}.json"
            t = time.perf_counter()
            argv = [sys.executable, "-m", "tests.measure_golden_spread", "--child", str(out)]
            subprocess.run(argv, env={**os.environ, **real}, cwd=golden.ROOT, check=True, timeout=3600)
            r = json.loads(out.read_text())
            if env.get("ZSWARM_KERNELS_FILE") == DEFAULT_BUILD and r["kernels_file"] != str(so):
                raise SystemExit(f"measure_golden_spread: {name}: the default build was not loaded ({r['kernels_file']})")
            settings[name] = {
                "env": env,
                "fingerprint": r["fingerprint"],
                "kernels_file": DEFAULT_BUILD if r["kernels_file"] == str(so) else r["kernels_file"] and Path(r["kernels_file"]).name,
                "moved": {n: moved(v, want[n]["summary"]) for n, v in r["runs"].items()},
                "gain_changes": {c: moved(v, want[c.split()[0]]["summary"]) for c, v in r["perturbed"].items()},
            }
            print(f"  {name}: {time.perf_counter() - t:.0f} s", flush=True)
    write(settings, _cpu())
    print(f"wrote {SPREAD.relative_to(golden.ROOT)}: {len(settings)} settings")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
