"""The tables of the study pages that single ``zswarm sim`` runs make, and the Markdown they are
printed as.

Each subcommand runs its ``zswarm sim`` commands (one results folder each under ``--out``), keeps
what the page's table shows in a CSV of docs/data/ (``--csv``) and prints the table;
tests/component/test_publications_more.py holds each page's table to the file through the same
functions (:func:`decarli_measured`, :func:`decarli_noise`, :func:`chapter5_scenarios`,
:func:`spot_check`, :func:`run_against_sim`, :func:`quickstart_cells`)::

    .venv/bin/python docs/examples/sim_tables.py decarli --csv docs/data/decarli-sim.csv
    .venv/bin/python docs/examples/sim_tables.py chapter5 --csv docs/data/scenarios-5.6.csv
    .venv/bin/python docs/examples/sim_tables.py engines --csv docs/data/run-against-sim-sim.csv
    .venv/bin/python docs/examples/sim_tables.py quickstart --csv docs/data/quickstart-sim.csv

communication.md's spot check needs no script: its ``sim`` side is the sweep.csv of ``zswarm sweep
topologies/thesis-3.2-fixed8.toml --engine sim --vary links.delay_ms=0,50,150 --set
links.drop=0.2`` (docs/data/spot-check-3.2-sim.csv), and :func:`spot_check` prints the table.

Where a table sets ``zswarm run`` beside ``sim``, the ``run`` side is a measurement of one machine
on one day (real processes, wall-clock ticks): it is kept as it was measured in a JSON file of
docs/data/ that names its command, its machine and its date, and is not made again here.
"""

from __future__ import annotations

import argparse
import csv
import json
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
TOPO = ROOT / "topologies"


def sim(out: Path, topology: str, sets: tuple[str, ...] = (), duration: float | None = None, seed: int = 1) -> float:
    """``zswarm sim`` of ``topologies/<topology>.toml`` into ``out``; the CPU seconds it took."""
    cmd = [sys.executable, "-m", "zswarm", "sim", str(TOPO / f"{topology}.toml"), "--seed", str(seed), "--out", str(out), "--no-plots", "--no-recording", "--quiet"]
    if duration is not None:
        cmd += ["--duration", f"{duration:g}"]
    for s in sets:
        cmd += ["--set", s]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    subprocess.run(cmd, check=True)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    print(f"{out.name}: {time.monotonic() - t0:.0f} s of wall time, {cpu:.1f} s of CPU", file=sys.stderr, flush=True)
    return cpu


def summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def write_csv(path: Path, rows: list[dict]) -> None:
    from zswarm.util import rows as rows_io

    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows([{k: rows_io.cell(v) for k, v in r.items()} for r in rows])
    print(f"rows: {path}", file=sys.stderr)


def num(x: str | float | None, unit: str = "") -> str:
    """A number as the pages write an error: two significant digits, below 0.1 in the short
    exponent form (4.5e-2); "never" for a blank cell."""
    if x in ("", None):
        return "never"
    v = float(x)
    if v >= 0.1:
        s = f"{v:#.2g}".rstrip(".")
    else:
        m, e = f"{v:.1e}".split("e")
        s = f"{m}e{int(e)}"
    return s + unit


def secs(x: str | float | None, digits: int = 2) -> str:
    return "never" if x in ("", None) else f"{float(x):.{digits}f} s"


# --------------------------------------------------------------------------- decarli.md

DECARLI = "decarli-8-formation"
# The noise table's rows: its label, and the variances per 200 Hz sample (σ²) that give its σ.
DECARLI_NOISE = (
    ("0 (the table above)", ()),
    ("1 mm / 1 mm/s / 1e-3 rad/s", ("noise.rel_pos_var=1e-6", "noise.velocity_var=1e-6", "noise.gyro_var=1e-6")),
    ("2 cm / 1 cm/s / 1e-2 rad/s", ("noise.rel_pos_var=4e-4", "noise.velocity_var=1e-4", "noise.gyro_var=1e-4")),
)
# (short name, summary.json's formation key, formation.csv's column prefix, unit, the table's quantity)
STAGES = (
    ("rel", "relative_yaw", "rel_yaw_", "", "relative yaw ‖ẑ_ψij − z_ψij‖"),
    ("yaw", "yaw", "yaw_", "", "common-frame yaw"),
    ("pos", "position", "position_", " m", "common-frame position"),
    ("form", "formation", "formation_", " m", "formation error"),
)
FINAL_KEYS = {"rel": "relative_yaw_error_max_final", "yaw": "yaw_error_max_final", "pos": "position_error_max_final_m", "form": "formation_error_max_final_m"}
MEAN_FROM_S = 20.0  # the noise table's means: over 20-40 s of the 40 s run


def decarli_row(out: Path, label: str, sets: tuple[str, ...], cpu: float) -> dict:
    """A run's row: per stage the time after which its max over edges / robots stays below its
    threshold (summary.json's formation.settle_s), the max at the end, and the means over 5-20 s
    and 20-40 s of the max on formation.csv's 10 Hz rows; the common rotation's drift over the
    second half."""
    f = summary(out)["formation"]
    rows = read_csv(out / "formation.csv")
    t = np.array([float(r["t"]) for r in rows])
    row: dict = {"noise": label, "sets": " ".join(sets)}
    for short, key, prefix, _, _ in STAGES:
        cols = [c for c in rows[0] if c.startswith(prefix)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # the first rows: no estimate yet (NaN)
            mx = np.nanmax(np.array([[float(r[c]) for c in cols] for r in rows]), axis=1)
        row[f"{short}_settle_s"] = f["settle_s"][f"{key}_max"]
        row[f"{short}_final"] = f[FINAL_KEYS[short]]
        row[f"{short}_mean_5_20"] = float(mx[(t >= 5.0) & (t < MEAN_FROM_S)].mean())  # while the robots still travel
        row[f"{short}_mean_20_40"] = float(mx[t >= MEAN_FROM_S].mean())
    row["alpha_drift_rad"] = f["common_rotation_alpha_drift_rad"]
    row["cpu_s"] = round(cpu, 1)
    return row


def decarli_measured(sim_row: dict, run: dict) -> list[list[str]]:
    """decarli.md's measured table (cells): the noise-free ``sim`` row beside ``run``'s numbers
    (docs/data/decarli-run.json)."""
    from zswarm.families.formation import THRESHOLDS

    below = {"rel": THRESHOLDS["relative_yaw"], "yaw": THRESHOLDS["yaw"], "pos": THRESHOLDS["position_m"], "form": THRESHOLDS["formation_m"]}
    return [
        [q, f"{below[s]:g}{u}", secs(sim_row[f"{s}_settle_s"]), num(sim_row[f"{s}_final"], u), secs(run[f"{s}_settle_s"]), num(run[f"{s}_final"], u)]
        for s, _, _, u, q in STAGES
    ]


def decarli_noise(rows: list[dict]) -> list[list[str]]:
    """decarli.md's noise table (cells): per row the four stages' means over 20-40 s of their max,
    and the four settle times ("never" for a stage that does not stay below its threshold)."""
    out = []
    for r in rows:
        t = [r[f"{s}_settle_s"] for s, *_ in STAGES]
        settle = "never" if all(x in ("", None) for x in t) else " / ".join("never" if x in ("", None) else f"{float(x):.2f}" for x in t) + " s"
        out.append([r["noise"], *(num(r[f"{s}_mean_20_40"], u) for s, _, _, u, _ in STAGES), settle])
    return out


def markdown(header: str, cells: list[list[str]]) -> str:
    n = header.count("|") - 1
    return "\n".join([header, "|" + "---|" * n, *("| " + " | ".join(c) + " |" for c in cells)])


DECARLI_MEASURED_HEADER = "| quantity (max over edges / robots) | below | `sim` from | `sim` at 40 s | `run` from | `run` at 40 s |"
DECARLI_NOISE_HEADER = "| σ: ⁱp_ij / velocity / gyro | relative yaw | yaw | position | formation | settle times |"


def decarli(out: Path, csv_path: Path | None) -> None:
    rows = []
    for n, (label, sets) in enumerate(DECARLI_NOISE):
        d = out / f"{DECARLI}-noise{n}"
        cpu = sim(d, DECARLI, sets, duration=40.0)
        rows.append(decarli_row(d, label, sets, cpu))
    if csv_path is not None:
        write_csv(csv_path, rows)
    run = json.loads((ROOT / "docs" / "data" / "decarli-run.json").read_text())["values"]
    print(markdown(DECARLI_MEASURED_HEADER, decarli_measured(rows[0], run)))
    print()
    print(markdown(DECARLI_NOISE_HEADER, decarli_noise(rows)))


# --------------------------------------------------------------------------- chapter5.md

SYNC_LAWS = ("hybrid", "continuous", "velocity-free")
FIRST_STEP_S = 0.011  # the agents' first step is at 10 ms: a jump by then is a jump "at the first step"
Q_TILDE_FROM_S = 0.5
# What READING-NOTES (Chapter 5: Lie–Euler at 1 ms, 2 ms for the velocity-free law) prints for the
# same starts: when the max leaves the start, below 0.1 from, below 0.01 from (s); cited, not made
# here (tests/component/test_sim_sync.py holds sim within 25 % of the last two).
NOTES = {"hybrid": ("58.5", "102"), "continuous": ("≈ 10", "67.5", "119"), "velocity-free": ("62", "108")}


def chapter5_row(out: Path, law: str, cpu: float) -> dict:
    """A §5.6 law's run: summary.json's synchronization block (max_k |R̄_k|_I), its ξ- and ζ-jumps
    (those after the first step by their times), and the largest |Q̃_i|_I from 0.5 s on
    (agents.csv; the velocity-free law only)."""
    s = summary(out)
    sy = s["synchronization"]
    later = sorted(j["t"] for e in s["edges"].values() for j in e.get("jump_log", []) if j["t"] > FIRST_STEP_S)
    first = sum(1 for e in s["edges"].values() for j in e.get("jump_log", []) if j["t"] <= FIRST_STEP_S)
    q = [float(r["Q_tilde"]) for r in read_csv(out / "agents.csv") if r.get("Q_tilde") not in ("", None) and float(r["t"]) >= Q_TILDE_FROM_S]
    q = [x for x in q if np.isfinite(x)]  # the laws without Q_i write none
    return {
        "law": law,
        "leaves_start_s": sy["leaves_start_at"],
        "settle_01_s": sy["settles_below_0.1_at"],
        "settle_001_s": sy["settles_below_0.01_at"],
        "jumps": s.get("jumps_total"),
        "jumps_first_step": first if "jumps_total" in s else None,
        "jumps_later_s": " ".join(f"{t:.3f}" for t in later),
        "zeta_jumps": s.get("zeta_jumps_total"),
        "q_tilde_max_from_0.5_s": max(q) if q else None,
        "cpu_s": round(cpu, 1),
    }


WORDS = {1: "one", 2: "two", 3: "three", 4: "four", 5: "five", 6: "six", 7: "seven", 8: "eight"}


def chapter5_scenarios(rows: list[dict]) -> list[str]:
    """The "what it shows" cells of chapter5.md's first table for the three laws (its rows 1-3),
    from the runs' rows (as written or read back)."""
    r = {x["law"]: x for x in rows}
    h, c, v = r["hybrid"], r["continuous"], r["velocity-free"]

    def t(x: str | float) -> str:
        return f"{float(x):.1f} s"

    later = [float(x) for x in h["jumps_later_s"].split()]
    hybrid = (
        "7 bodies on the tree N1={2}, N2={1,3}, N3={2,4,6}, N4={3,5}, N5={4}, N6={3,7}, N7={6}, started on the undesired "
        f"equilibria (every R̄_k(0) = Ra(π, e3)): all {WORDS[int(h['jumps_first_step'])]} ξ_k jump 0 → 0.9π at the first step, "
        f"{WORDS[len(later)]} more jumps at {' and '.join(f'{x:.1f} s' for x in later)} ({int(h['jumps'])} in all), then max_k \\|R̄_k\\|_I "
        f"stays below 0.1 from **{t(h['settle_01_s'])}** and below 0.01 from **{t(h['settle_001_s'])}** on `sim` "
        f"(the exact equations: {NOTES['hybrid'][0]} s, {NOTES['hybrid'][1]} s)."
    )
    continuous = (
        "The same start is an exact equilibrium of (5.24): on `sim` round-off alone takes it off "
        f"(max \\|R̄_k\\|_I < 0.9 from {t(c['leaves_start_s'])}), then below 0.1 from **{t(c['settle_01_s'])}** and 0.01 from "
        f"**{t(c['settle_001_s'])}** (the exact equations: {NOTES['continuous'][0]} s, {NOTES['continuous'][1]} s, "
        f"{NOTES['continuous'][2]} s). Almost global only."
    )
    velocity_free = (
        f"No gyro: every ξ_k and ζ_i jumps to 0.9π at the first step ({int(v['jumps'])} ξ-jumps, {int(v['zeta_jumps'])} ζ-jumps in "
        f"150 s), \\|Q̃_i\\|_I at most {float(v['q_tilde_max_from_0.5_s']):.2g} from 0.5 s on, below 0.1 from **{t(v['settle_01_s'])}**, "
        f"0.01 from **{t(v['settle_001_s'])}** (the exact equations integrated at 2 ms: {NOTES['velocity-free'][0]} s, "
        f"{NOTES['velocity-free'][1]} s)."
    )
    return [hybrid, continuous, velocity_free]


def chapter5(out: Path, csv_path: Path | None) -> None:
    rows = []
    for law in SYNC_LAWS:
        d = out / f"thesis-5.6-{law}7"
        rows.append(chapter5_row(d, law, sim(d, f"thesis-5.6-{law}7")))
    if csv_path is not None:
        write_csv(csv_path, rows)
    print("\n".join(chapter5_scenarios(rows)))


# --------------------------------------------------------------------------- communication.md's spot check on run


def spot_check(sim_rows: list[dict[str, str]], run: dict) -> list[list[str]]:
    """communication.md's spot-check table (cells): per delay ``run`` (docs/data/spot-check-3.2-run.json)
    beside ``sim`` (the rows of ``zswarm sweep --engine sim``, docs/data/spot-check-3.2-sim.csv)."""
    out = []
    for s in sim_rows:
        r = run["rows"][s["links.delay_ms"]]
        out.append(
            [
                f"{s['links.delay_ms']} ms",
                f"{r['conv_attitude_s']:.1f} / {float(s['conv_attitude_s']):.1f} s",
                f"{r['conv_position_s']:.1f} / {float(s['conv_position_s']):.1f} s",
                f"{r['final_position_error']:.4f} / {float(s['final_position_error']):.4f} m",
                f"{r['edge_drop_ratio']:.4f} / {float(s['edge_drop_ratio']):.4f}",
                f"{r['edge_latency_p50_ms']:.1f} ms",
            ]
        )
    return out


SPOT_CHECK_HEADER = "| delay | attitude < 0.01 (run / sim) | position < 0.1 m (run / sim) | final position error (run / sim) | edge loss (run / sim) | edge latency p50 (run) |"


# --------------------------------------------------------------------------- engines.md: run against sim

# (the table's scenario, the topology, the measure(s) shown)
ENGINE_ROWS = (
    ("§3.2 fixed8", "thesis-3.2-fixed8", "attitude / position"),
    ("§3.2 fixed8-filtered", "thesis-3.2-fixed8-filtered", "attitude / position"),
    ("§3.3 moving5", "thesis-3.3-moving5", "attitude / position"),
    ("§4.5 continuous5", "thesis-4.5-continuous5", "\\|R̄\\|_I"),
    ("§4.5 hybrid5", "thesis-4.5-hybrid5", "\\|R̄\\|_I"),
    ("§4.5 hybrid-pose5", "thesis-4.5-hybrid-pose5", "\\|R̄\\|_I / relative position"),
)


def engines_row(out: Path, topology: str, cpu: float) -> dict:
    """A run's final mean errors over the last second (summary.json): the followers' attitude and
    position errors for §3 (mean_attitude_error_final, mean_position_error_final), the edges'
    relative attitude |R̄_k|_I and relative position for §4.5 (mean_relative_*_final)."""
    s = summary(out)
    rel = "mean_relative_attitude_error_final" in s
    att = s["mean_relative_attitude_error_final"] if rel else s["mean_attitude_error_final"]
    pos = s.get("mean_relative_position_error_final") if rel else s["mean_position_error_final"]
    return {"scenario": topology, "attitude_final": att, "position_final": pos, "cpu_s": round(cpu, 1)}


def run_against_sim(sim_rows: list[dict[str, str]], run: dict) -> list[list[str]]:
    """engines.md's table (cells): ``run``'s final mean errors (docs/data/run-against-sim-run.json)
    beside ``sim``'s (docs/data/run-against-sim-sim.csv) and their ratio."""

    def e(x: float) -> str:
        m, ex = f"{x:.2e}".split("e")
        return f"{m}e{int(ex)}"

    by = {r["scenario"]: r for r in sim_rows}
    out = []
    for label, topology, measure in ENGINE_ROWS:
        s, r = by[topology], run["rows"][topology]
        att = [e(r["attitude_final"]), e(float(s["attitude_final"])), f"{r['attitude_final'] / float(s['attitude_final']):.2f}"]
        if "/" in measure:
            pos = [f"{r['position_final']:.4f}", f"{float(s['position_final']):.4f}", f"{r['position_final'] / float(s['position_final']):.2f}"]
            att = [f"{a} / {p}" for a, p in zip(att, pos, strict=True)]
        out.append([label, measure, *att])
    return out


RUN_AGAINST_SIM_HEADER = "| scenario | measure | `run` | `sim` | ratio |"


def engines(out: Path, csv_path: Path | None) -> None:
    rows = []
    for _, topology, _ in ENGINE_ROWS:
        d = out / topology
        rows.append(engines_row(d, topology, sim(d, topology)))
    if csv_path is not None:
        write_csv(csv_path, rows)
    run = json.loads((ROOT / "docs" / "data" / "run-against-sim-run.json").read_text())
    print(markdown(RUN_AGAINST_SIM_HEADER, run_against_sim([{k: str(v) for k, v in r.items()} for r in rows], run)))


# --------------------------------------------------------------------------- quickstart.md's scenario table

QUICKSTART = (
    "thesis-3.3-moving5",
    "thesis-3.3-moving5-noisy",
    "thesis-4.5-continuous5",
    "thesis-4.5-continuous5-noisy",
    "thesis-4.5-hybrid5",
    "thesis-4.5-hybrid5-noisy",
    "thesis-4.5-hybrid-pose5",
)
FINE = ("clock.rate=1000", "world.sensor_rate=1000")  # agents and sensors at 1 kHz (the sensors at most 1 kHz): the step's own error


def _follower_means(out: Path, times: tuple[float, ...]) -> dict[float, tuple[float, float, float]]:
    """errors.csv's mean over the followers (agents 3-) of the attitude error, the position error
    and the direct ‖p − p̂‖ at each time (the row nearest it)."""
    rows = read_csv(out / "errors.csv")
    by: dict[str, list[tuple[float, float, float, float]]] = {}
    for r in rows:
        if int(r["agent"]) > 2:
            by.setdefault(r["agent"], []).append((float(r["t"]), float(r["attitude_error"]), float(r["position_error"]), float(r["position_error_direct"])))
    res = {}
    for T in times:
        near = [min(v, key=lambda x: abs(x[0] - T)) for v in by.values()]
        res[T] = (float(np.mean([x[1] for x in near])), float(np.mean([x[2] for x in near])), float(np.mean([x[3] for x in near])))
    return res


def _edges_at(out: Path, col: str, T: float) -> list[float]:
    """edges.csv's ``col`` per edge at the first row at or after ``T``."""
    by: dict[str, float] = {}
    for r in read_csv(out / "edges.csv"):
        if float(r["t"]) >= T - 1e-9 and r["edge"] not in by and r[col] not in ("", None):
            by[r["edge"]] = float(r[col])
    return [by[k] for k in sorted(by, key=int)]


def quickstart_measures(out: Path, name: str) -> dict[str, float | str]:
    """What quickstart.md's row of ``name`` quotes, from its results folder."""
    s = summary(out)
    m: dict[str, float | str] = {}
    if name.startswith("thesis-3.3"):
        f = _follower_means(out, (0.0, 2.0, 10.0, 20.0, 30.0))
        m |= {"att_0": f[0.0][0], "pos_direct_0": f[0.0][2], "att_2s": f[2.0][0], "pos_10s": f[10.0][1], "pos_20s": f[20.0][1], "pos_30s": f[30.0][1]}
        m |= {"att_final": s["mean_attitude_error_final"], "pos_final": s["mean_position_error_final"]}
    else:
        m["rel_att_final_mean"] = s["mean_relative_attitude_error_final"]
        m["rel_att_final_max"] = s["max_relative_attitude_error_final"]
        e = s["edges"]
        if "jumps" in e["1"]:
            j = [e[k]["jumps"] for k in e]
            m |= {"jumps_min": min(j), "jumps_max": max(j)}
        a10, a20 = _edges_at(out, "relative_attitude_error", 10.0), _edges_at(out, "relative_attitude_error", 20.0)
        m |= {"rel_att_10s_min": min(a10), "rel_att_10s_max": max(a10), "rel_att_20s_min": min(a20), "rel_att_20s_max": max(a20)}
        st = [e[k]["relative_attitude_error_settles_below_1e-2_at"] for k in e]
        if all(x is not None for x in st):
            m |= {"settle_1e-2_min": min(st), "settle_1e-2_max": max(st)}
        first = [float(r["t"]) for r in read_csv(out / "edges.csv") if float(r["relative_attitude_error"]) < 0.9]
        m["leaves_start_s"] = min(first) if first else ""
        if "relative_position_error_final" in e["1"]:
            p0 = _edges_at(out, "relative_position_error", 0.0)
            m |= {"rel_pos_0_min": min(p0), "rel_pos_0_max": max(p0)}
            m["rel_pos_final"] = " / ".join(f"{e[k]['relative_position_error_final']:.3g}" for k in sorted(e, key=int))
            m["rel_pos_final_max"] = s["max_relative_position_error_final"]
    return m


def _e(x: float, digits: int = 1) -> str:
    """1.3e-3, not 1.3e-03."""
    m, ex = f"{x:.{digits}e}".split("e")
    return f"{m}e{int(ex)}"


def quickstart_cells(rows: list[dict]) -> dict[str, str]:
    """The "what it shows" cells of quickstart.md's table for the §3.3 and §4.5 scenarios, from
    the measures (as written or read back: scenario, measure, value)."""
    m: dict[str, dict[str, str]] = {}
    for r in rows:
        m.setdefault(r["scenario"], {})[r["measure"]] = str(r["value"])

    def f(name: str, key: str) -> float:
        return float(m[name][key])

    mv, nz = "thesis-3.3-moving5", "thesis-3.3-moving5-noisy"
    fine = "thesis-3.3-moving5 " + " ".join(FINE)
    c, cn, h, hn, hp = (f"thesis-4.5-{x}" for x in ("continuous5", "continuous5-noisy", "hybrid5", "hybrid5-noisy", "hybrid-pose5"))
    ratio = f(hn, "rel_att_final_mean") / f(cn, "rel_att_final_mean")
    return {
        mv: "Thesis §3.3.4: a pentagon rotating about x at π/6 rad/s, observer (3.23) + (3.25), k_p = 1, k_i^R = 10/5/3 (Figs. 3.14–3.15). "
        f"Attitude errors fall from {f(mv, 'att_0'):.2f} to {_e(f(mv, 'att_2s'))} at 2 s, position errors (‖p − p̂‖) from {f(mv, 'pos_direct_0'):.1f} "
        f"to {f(mv, 'pos_10s'):.2g} (10 s), {f(mv, 'pos_20s'):.2g} (20 s), {f(mv, 'pos_final'):.2g} at the end (30 s) on `sim` at 100 Hz, against "
        f"{f(fine, 'pos_final'):.2g} with agents and sensors at 1 kHz (the equations: 0.022–0.023). Agent 4's two bearings are collinear at every "
        "instant (the thesis' own set-up): it converges by persistent excitation, and the loader says so.",
        nz: "The same with the §3.3.4 gyro biases, velocity and gyro noise (variance 0.1) and bearing noise (0.01) (Figs. 3.16–3.17): bounded, "
        f"final mean attitude error {f(nz, 'att_final'):.2g} and position error {f(nz, 'pos_final'):.2g} on `sim`.",
        c: "Thesis §4.5: a square pyramid rotating about z, relative-attitude observer (4.3) + (4.8) started **on** the undesired equilibrium "
        "(every `\\|R̄_k\\|_I = 1`). It is an unstable equilibrium (Theorem 4.1): round-off and asynchronous steps push it off "
        f"(the first edge below 0.9 at {f(c, 'leaves_start_s'):.2f} s, every edge below 1e-2 from {f(c, 'settle_1e-2_max'):.2f} s on `sim`), after which "
        f"`\\|R̄_k\\|_I` ends at {_e(f(c, 'rel_att_final_max'))} at most — convergence by luck, not by design (Fig. 4.4, continuous).",
        cn: f"The same with `R_ij exp([n_R]×)` and `ω + n_ω`, variances 0.01 (Fig. 4.6): `\\|R̄_k\\|_I` {f(cn, 'rel_att_final_mean'):.2g} at the end "
        "(mean over edges).",
        h: "The hybrid observer (4.25)–(4.26), Ξ = {0.08π}, δ = 0.003 (Figs. 4.4–4.5): at the first step every ξ_k jumps from 0 to 0.08π "
        f"(once), then `\\|R̄_k\\|_I` is {f(h, 'rel_att_10s_min'):.2g}–{f(h, 'rel_att_10s_max'):.2g} at 10 s, "
        f"{_e(f(h, 'rel_att_20s_min'))}–{_e(f(h, 'rel_att_20s_max'))} at 20 s and stays below 1e-2 from "
        f"{f(h, 'settle_1e-2_min'):.1f}–{f(h, 'settle_1e-2_max'):.1f} s on (per edge, `sim`).",
        hn: f"The hybrid observer with the §4.5 noise (Figs. 4.6–4.7): bounded, but `\\|R̄_k\\|_I` {f(hn, 'rel_att_final_mean'):.2g} at the end "
        f"with {int(f(hn, 'jumps_min'))}–{int(f(hn, 'jumps_max'))} jumps per edge in 30 s — the noise moves U by far more than δ = 0.003, "
        f"so ξ chatters near 0.08π; the continuous observer does {ratio:.0f}× better here.",
        hp: "Hybrid pose observer: attitude (4.25)–(4.26) + position (4.30)–(4.31), k_p = 1 (Figs. 4.8–4.9). Poses are recovered up to a "
        f"common rotation and translation: relative position errors {f(hp, 'rel_pos_0_min'):.1f}–{f(hp, 'rel_pos_0_max'):.1f} m at t = 0, "
        f"at most {f(hp, 'rel_pos_final_max'):.3f} m at the end of the 60 s run on `sim` (per edge {m[hp]['rel_pos_final']} m); they still "
        "swing with the formation's 12 s turn.",
    }


def quickstart(out: Path, csv_path: Path | None) -> None:
    rows = []
    for name in QUICKSTART:
        d = out / name
        cpu = sim(d, name)
        rows += [{"scenario": name, "measure": k, "value": v} for k, v in quickstart_measures(d, name).items()]
        rows.append({"scenario": name, "measure": "cpu_s", "value": round(cpu, 1)})
    d = out / "thesis-3.3-moving5-1kHz"
    cpu = sim(d, "thesis-3.3-moving5", FINE)
    rows.append({"scenario": "thesis-3.3-moving5 " + " ".join(FINE), "measure": "pos_final", "value": summary(d)["mean_position_error_final"]})
    rows.append({"scenario": "thesis-3.3-moving5 " + " ".join(FINE), "measure": "cpu_s", "value": round(cpu, 1)})
    if csv_path is not None:
        write_csv(csv_path, rows)
    for name, cell in quickstart_cells(rows).items():
        print(f"{name}: {cell}")


# --------------------------------------------------------------------------- main


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("table", choices=("decarli", "chapter5", "engines", "quickstart"))
    ap.add_argument("--out", type=Path, default=Path("runs/sim-tables"), help="where the runs' results folders go")
    ap.add_argument("--csv", type=Path, default=None, help="write the table's rows there (docs/data/...)")
    a = ap.parse_args()
    {"decarli": decarli, "chapter5": chapter5, "engines": engines, "quickstart": quickstart}[a.table](a.out, a.csv)


if __name__ == "__main__":
    main()
