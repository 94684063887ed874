"""More of the docs' published tables against their files, and a few of their runs made again
(issue 61, item 6; tests/component/test_publications.py has the sweeps and basins).

Two kinds of table:

* **made by ``zswarm sim``** (decarli.md's measured and noise tables, chapter5.md's scenario
  table, communication.md's spot check, engines.md's run against sim, quickstart.md's scenario
  table): the ``sim`` side is a file of docs/data/ that a named command writes
  (docs/examples/sim_tables.py, or ``zswarm sweep --engine sim``), the page's table is printed
  from it by the same functions the test calls, and a row, picked with a fixed seed, is run again
  on ``sim`` (the same code path: every number as the file writes it, six significant digits);
  decarli.md's rows are not run again (35 s of CPU a row, see its test);
* **measured on one machine on one day** (the ``run`` sides, development.md's benchmarks, the
  suite's times, engines.md's load table, chapter5.md's CPU per draw): wall-clock times, CPU
  shares, missed ticks of real processes.  They cannot be made again to the same digits, so each
  is kept as published in a JSON file of docs/data/ that names its command, machine and date; the
  test holds the page's table to it, cell by cell, and the table's caption to the command, the
  date and the file (and a ratio column to the times it is the ratio of).

The re-runs are CPU-bound ``zswarm sim`` processes that keep no real time: ~40 s of CPU in all.
Their equality holds on the machine that wrote the files (its rounding): under tests/layers.sh's
other-machine settings (OpenBLAS Prescott, libm without FMA, numpy without AVX-512) two of the four
differ, the spot check's 50 ms row by a sixth digit that was a tie (7.426385e-05) and §4.5
continuous5's final |R̄|_I, an attitude measure at its round-off floor, by 1.1e-3 relative
(6.2123e-07 against 6.20559e-07).  tests/golden.py bounds such moves for its 2 s runs only; a
bound for these 30-150 s runs is not derived, so none is guessed here.
"""

from __future__ import annotations

import json
import math
import random
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests import reproduce
from tests.component.test_publications import _example, _job, _same_cells, _varied, read_csv
from tests.conftest import ROOT
from zswarm.studies.sweep import run_job

DOCS = ROOT / "docs"
DATA = DOCS / "data"
STUDIES = DOCS / "studies"
DECARLI = STUDIES / "decarli.md"
CHAPTER5 = STUDIES / "chapter5.md"
COMMUNICATION = STUDIES / "communication.md"
ENGINES = STUDIES / "engines.md"
DEVELOPMENT = DOCS / "development.md"
QUICKSTART = DOCS / "quickstart.md"
THRESHOLDS = (0.01, 0.1)  # zswarm sweep's defaults


def cells(line: str) -> list[str]:
    """A Markdown table line's cells, stripped; an escaped bar (``\\|``, as in ``\\|R̄\\|_I``) is
    part of its cell."""
    return [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().removeprefix("|").removesuffix("|"))]


def md_tables(page: Path, header: str) -> list[tuple[int, list[str], list[list[str]]]]:
    """Every Markdown table of ``page`` whose header line starts with ``header``: its line's
    index, its header cells and its rows (the separator left out)."""
    lines = page.read_text().splitlines()
    out = []
    for i, line in enumerate(lines):
        if line.startswith(header):
            rows = []
            for row in lines[i + 2 :]:
                if not row.startswith("|"):
                    break
                rows.append(cells(row))
            out.append((i, cells(line), rows))
    return out


def md_table(page: Path, header: str) -> list[list[str]]:
    """The rows of the one table of ``page`` whose header line starts with ``header``."""
    (table,) = md_tables(page, header)
    assert table[2], (page.name, header)
    return table[2]


def caption(page: Path, line: int) -> str:
    """The paragraph(s) just above a table (up to its previous blank-line-separated two), one
    space between words."""
    text = "\n".join(page.read_text().splitlines()[:line]).rstrip()
    paras = text.split("\n\n")
    return " ".join(" ".join(paras[-2:]).split())


def sim(topology: str, out: Path, *sets: str, duration: float | None = None) -> dict:
    """``zswarm sim`` as docs/examples/sim_tables.py runs it (the same command line, seed 1);
    its summary.json."""
    cmd = [sys.executable, "-m", "zswarm", "sim", str(ROOT / "topologies" / f"{topology}.toml"), "--seed", "1", "--out", str(out), "--no-plots", "--no-recording", "--quiet"]
    cmd += ["--duration", f"{duration:g}"] if duration is not None else []
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, check=True, cwd=ROOT)
    return json.loads((out / "summary.json").read_text())


# --------------------------------------------------------------------------- measured on one machine


# chapter5.md's CPU per draw, sim against the batched engine (make bench-batched and its cases)
BENCH_BATCHED = [
    (CHAPTER5, "| scheme | `sim`, s per draw | batched, 10 / 100 / 1000 draws together | ratio |", 0, "bench-batched-2026-12-04.json",
     "`make bench-batched`", "bench/bench_batched.py --duration 3 --draws 10,100,1000"),
    (CHAPTER5, "| scheme | `sim`, s per draw | batched, 100 / 1000 draws together | ratio | the same without links |", 0, "bench-batched-links-2026-12-05.json",
     "`--draws 100,1000 --schemes thesis-5.6-hybrid7,thesis-5.6-velocity-free7 --sweep-schemes ''`", "bench/bench_batched.py --draws 100,1000"),
    (CHAPTER5, "| scheme | `sim`, s per draw | batched, 100 / 1000 draws together | ratio |", 1, "bench-batched-sensors-2026-12-05.json",
     "`--duration 3 --draws 100,1000 --schemes thesis-5.6-hybrid7,thesis-5.6-velocity-free7 --sweep-schemes '' --links ''`", "--links ''"),
    (CHAPTER5, "| scheme | `sim` | batched, 100 / 1000 draws together | ratio |", 0, "bench-batched-observers-2026-12-04.json",
     "`--duration 30 --draws 100,1000 --schemes thesis-4.5-continuous5,thesis-4.5-hybrid5`", "bench/bench_batched.py --duration 30"),
]
# (page, the table's header line as it starts, which of the tables so headed, its file, the
# command as its caption shows it, the program the file's command names)
MEASURED = [
    (ENGINES, "| load | missed per agent |", 0, "run-under-load-3.2-filtered.json", "`stress-ng --cpu 1`", "zswarm run topologies/thesis-3.2-fixed8-filtered.toml"),
    (DEVELOPMENT, "| | unit + component |", 0, "suite-time.json", "`bash .ci/run`", "bash .ci/run"),
    (DEVELOPMENT, "| N | zswarm missed |", 0, "bench-capacity-2026-11-23.json", "`make bench-capacity`, `--n 8 16 24 --duration 15`", "bench/bench_capacity.py --n 8 16 24 --duration 15"),
    (DEVELOPMENT, "| N | zswarm missed |", 1, "bench-capacity-2026-12-01.json", "`--n 8 16 --duration 15`", "bench/bench_capacity.py --n 8 16 --duration 15"),
    (DEVELOPMENT, "| | d017381 | aef1f82 | fbd00f6 |", 0, "agent-tick.json", "`bench/bench_capacity.py --n 8 --duration 15`", "bench/bench_capacity.py --n 8 --duration 15"),
    (DEVELOPMENT, "| what | first measurement |", 0, "bench-runtime.json", "`python bench/bench_runtime.py --duration 20`", "bench/bench_runtime.py --duration 20"),
    (DEVELOPMENT, "| flood on est/3 |", 0, "recorder-floods.json", "`pytest -s tests/integration/test_fuzz_zenoh.py`", "tests/integration/test_fuzz_zenoh.py"),
    *BENCH_BATCHED,
]


@pytest.mark.parametrize(("page", "header", "nth", "name", "on_page", "program"), MEASURED, ids=[m[3] for m in MEASURED])
def test_a_measured_table_is_its_file(page, header, nth, name, on_page, program):
    """A table of one machine's measurements, cell by cell, is its file; the caption links the
    file, names the command and says the date(s) the file says, and the file names that command."""
    f = json.loads((DATA / name).read_text())
    tables = md_tables(page, header)
    assert len(tables) > nth, (page.name, header)
    line, head, rows = tables[nth]
    assert head == f["header"] and rows == f["rows"], name
    assert f["page"] == str(page.relative_to(ROOT))
    cap = caption(page, line)
    link = Path("data", name) if page.parent == DOCS else Path("..", "data", name)
    assert f"]({link})" in cap, (name, cap)
    dates = re.findall(r"\d{4}-\d\d-\d\d", f["measured"])
    words = re.sub(r"\[[^][]*\]\([^)]*\)", "", cap)  # the text without its links (a file's name may hold a date)
    assert dates and all(d in words for d in dates), (name, dates, cap)
    assert on_page in cap and program in f["command"], (name, on_page, f["command"])
    assert f["machine"] and f["made_again"].startswith("no: ")


def _printed(cell: str) -> tuple[float, float]:
    """The interval a printed number stands for: ± half a unit of its last digit ("0.0020" is
    [0.00195, 0.00205])."""
    x = cell.strip().removesuffix(" s").removesuffix("x")
    digits = len(x.split(".")[1]) if "." in x else 0
    h = 0.5 * 10.0**-digits
    return float(x) - h, float(x) + h


@pytest.mark.parametrize("name", [b[3] for b in BENCH_BATCHED])
def test_the_batched_benchmarks_ratios_follow_from_their_times(name):
    """A ratio column of chapter5.md's CPU tables is `sim`'s time over the batched engine's, each
    as measured, not as printed: the printed ratio must lie in what the printed times allow (each
    time ± half a unit of its last digit; the ratio ± 0.5)."""
    f = json.loads((DATA / name).read_text())
    for row in f["rows"]:
        sim_lo, sim_hi = _printed(row[1])
        for b, r in zip(row[2].split(" / "), row[3].split(" / "), strict=True):
            b_lo, b_hi = _printed(b)
            r_lo, r_hi = _printed(r)
            assert sim_lo / b_hi <= r_hi and sim_hi / b_lo >= r_lo, (name, row[0], b, r)


# --------------------------------------------------------------------------- decarli.md


def test_the_decarli_tables_are_their_files():
    """decarli.md's measured table (``sim`` beside ``run``) and its noise table, cell by cell, are
    docs/data/decarli-sim.csv (docs/examples/sim_tables.py decarli) and docs/data/decarli-run.json;
    the figures the text draws from them too.

    No row is run again here: a row is one 40 s run of eight agents at 200 Hz on ``sim`` (the
    batched engine has no De Carli family), 34-35 s of CPU (the file's ``cpu_s``; 105 s the three),
    over twice what a re-run here may cost; a shorter run would not give the row's numbers (its
    means are over 20-40 s, its settle times over the whole run)."""
    st = _example("sim_tables")
    rows = read_csv(DATA / "decarli-sim.csv")
    run = json.loads((DATA / "decarli-run.json").read_text())
    assert [(r["noise"], r["sets"]) for r in rows] == [(label, " ".join(sets)) for label, sets in st.DECARLI_NOISE]
    assert md_table(DECARLI, st.DECARLI_MEASURED_HEADER) == st.decarli_measured(rows[0], run["values"])
    assert md_table(DECARLI, st.DECARLI_NOISE_HEADER) == st.decarli_noise(rows)
    text = " ".join(DECARLI.read_text().split())
    assert "python docs/examples/sim_tables.py decarli" in text and "(../data/decarli-sim.csv)" in text and "(../data/decarli-run.json)" in text
    assert run["measured"] in text and run["command"] in text
    cpu = sum(float(r["cpu_s"]) for r in rows)
    assert f"{cpu:.0f} s of CPU for the three runs" in text
    # "The settle times agree within N %": the largest |run − sim| / sim over the four stages.
    worst = max(abs(run["values"][f"{s}_settle_s"] - float(rows[0][f"{s}_settle_s"])) / float(rows[0][f"{s}_settle_s"]) for s, *_ in st.STAGES)
    assert f"The settle times agree within {100 * worst:.0f} %" in text
    drift = f"it moves by {st.num(rows[0]['alpha_drift_rad'])} rad on `sim` and by {st.num(run['values']['alpha_drift_rad'])} rad on `run`"
    assert drift in text, drift
    # The relative-yaw observer under the 2 cm noise: its max while the robots travel and once formed.
    loud = rows[2]
    quoted = (
        f"With 2 cm noise its max averages {st.num(loud['rel_mean_5_20'])} while the robots still travel (5–20 s) "
        f"and {st.num(loud['rel_mean_20_40'])} once they have formed (20–40 s)."
    )
    assert quoted in text, quoted
    # The floor at the paper's rates: the 50 Hz position part's, the table's sim position at 40 s.
    assert f"the 50 Hz position part's first-order one ({st.num(rows[0]['pos_final'], ' m')})" in text


# --------------------------------------------------------------------------- chapter5.md's scenario table


def test_the_chapter5_scenario_table_is_its_file():
    """chapter5.md's first table (the three §5.6 laws from their shipped starts on ``sim``) is
    docs/data/scenarios-5.6.csv (docs/examples/sim_tables.py chapter5): its first three rows'
    "what it shows", cell by cell; the exact equations' figures quoted beside them are
    READING-NOTES', the ones tests/component/test_sim_sync.py holds ``sim`` to."""
    from tests.component.test_sim_sync import NOTES

    st = _example("sim_tables")
    rows = read_csv(DATA / "scenarios-5.6.csv")
    assert [r["law"] for r in rows] == list(st.SYNC_LAWS)
    assert [r[2] for r in md_table(CHAPTER5, "| scenario | law | what it shows |")[:3]] == st.chapter5_scenarios(rows)
    for law in st.SYNC_LAWS:
        assert tuple(float(x) for x in st.NOTES[law][-2:]) == NOTES[f"thesis-5.6-{law}7"], law
    text = " ".join(CHAPTER5.read_text().split())
    assert "python docs/examples/sim_tables.py chapter5" in text and "(../data/scenarios-5.6.csv)" in text
    assert f"{sum(float(r['cpu_s']) for r in rows):.0f} s of CPU" in text
    # The real-process paragraph's sim figures beside run's: the file's.
    by = {r["law"]: r for r in rows}
    for law in st.SYNC_LAWS:
        quoted = f"`sim` {float(by[law]['settle_01_s']):.1f} s / {float(by[law]['settle_001_s']):.1f} s"
        assert quoted in text, quoted


def test_the_hybrid_law_row_is_the_batched_engines_too():
    """The hybrid law's row (on ``sim``) against the fine command-delay sweep's undelayed lossless
    point, which the batched engine ran (an engine of its own, whose rows equal sim's to round-off,
    ~1e-15 relative: tests/component/test_sweep_engines.py).  Nothing is run.

    The two engines place a settle time on different grids: the sweep's column is the first point
    of the 0.1 s grid after the last time τ the max is above its threshold, so it lies in
    [τ, τ + 0.1); summary.json's is the first point of the family's 10 ms grid after τ, in
    [τ, τ + 0.01).  The two differ by less than 0.1 s; the jumps are counts, equal."""
    hybrid = next(r for r in read_csv(DATA / "scenarios-5.6.csv") if r["law"] == "hybrid")
    sweep = [r for r in read_csv(DOCS / "figures" / "sweep-5.6-commands-fine.csv") if r["links.commands.delay_ms"] == "0" and r["links.commands.drop"] == "0"]
    assert sweep
    for r in sweep:  # every seed: nothing random without loss
        for col, mine in (("conv_attitude_s", "settle_001_s"), ("conv_attitude_01_s", "settle_01_s")):
            assert abs(float(r[col]) - float(hybrid[mine])) < 0.1, (col, r[col], hybrid[mine])
        assert int(r["jumps"]) == int(hybrid["jumps"])


def test_a_chapter5_law_runs_again_on_sim(tmp_path):
    """One of the three laws, picked with a fixed seed, run again with the script's command line
    (150 s on ``sim``: 21-39 s of CPU, the file's cpu_s; the continuous law, picked, 21 s): its row
    as the file writes it, every column but the CPU."""
    st = _example("sim_tables")
    law = random.Random(61).choice(st.SYNC_LAWS)
    want = next(r for r in read_csv(DATA / "scenarios-5.6.csv") if r["law"] == law)
    out = tmp_path / law
    sim(f"thesis-5.6-{law}7", out)
    diff = reproduce.differ(st.chapter5_row(out, law, 0.0), want, skip=("cpu_s",))
    assert not diff, (law, diff)


# --------------------------------------------------------------------------- communication.md's spot check


SPOT_SIM = DATA / "spot-check-3.2-sim.csv"
SPOT_RUN = DATA / "spot-check-3.2-run.json"
SPOT_COMMAND = "zswarm sweep topologies/thesis-3.2-fixed8.toml --engine sim --vary links.delay_ms=0,50,150 --set links.drop=0.2"


def test_the_spot_check_table_is_its_files():
    """communication.md's spot check: ``sim``'s side is the sweep.csv of the command the page
    shows (docs/data/spot-check-3.2-sim.csv), ``run``'s is docs/data/spot-check-3.2-run.json as
    measured; the table is the two, cell by cell."""
    st = _example("sim_tables")
    rows = read_csv(SPOT_SIM)
    run = json.loads(SPOT_RUN.read_text())
    assert [r["links.delay_ms"] for r in rows] == ["0", "50", "150"] and all(r["status"] == "ok" and r["seed"] == "1" for r in rows)
    assert md_table(COMMUNICATION, st.SPOT_CHECK_HEADER) == st.spot_check(rows, run)
    text = " ".join(COMMUNICATION.read_text().replace("\\\n", " ").split())
    assert SPOT_COMMAND in text and "(../data/spot-check-3.2-sim.csv)" in text and "(../data/spot-check-3.2-run.json)" in text
    assert run["measured"] in text
    # "The engines agree within N %": the largest |run − sim| / sim of the settle times and final
    # errors (run's as published, to its digits), rounded up to a whole percent.
    cols = ("conv_attitude_s", "conv_position_s", "final_position_error")
    worst = max(abs(run["rows"][r["links.delay_ms"]][c] - float(r[c])) / float(r[c]) for r in rows for c in cols)
    assert f"The engines agree within {math.ceil(100 * worst)} % on the settle times and the final error" in text, worst
    assert f"({sum(float(r['wall_s']) for r in rows) / len(rows):.0f} s a run here, its rows' `wall_s`;" in text


def test_a_spot_check_row_runs_again_on_sim():
    """A row of the spot check's ``sim`` side, picked with a fixed seed, run again as ``zswarm
    sweep --engine sim`` runs it (zswarm.studies.sweep.run_job, a 40 s §3.2 run): every column as
    the file writes it (the losses are the run seed's draws)."""
    table = read_csv(SPOT_SIM)
    row = random.Random(61).choice(table)
    topology = ROOT / "topologies" / "thesis-3.2-fixed8.toml"
    got, problems, _ = run_job(topology.read_text(), str(topology), _job(row, _varied(list(table[0])), ("links.drop=0.2",)), 40.0, THRESHOLDS)
    assert problems is None
    _same_cells(got, row, SPOT_SIM.name)
    assert int(row["edge_dropped"]) > 0


# --------------------------------------------------------------------------- engines.md: run against sim


def test_the_run_against_sim_table_is_its_files():
    """engines.md's table: ``run``'s final errors as measured (docs/data/run-against-sim-run.json)
    beside ``sim``'s (docs/data/run-against-sim-sim.csv, docs/examples/sim_tables.py engines) and
    their ratio, cell by cell; the load table's ``sim`` figures are the filtered row's."""
    st = _example("sim_tables")
    rows = read_csv(DATA / "run-against-sim-sim.csv")
    run = json.loads((DATA / "run-against-sim-run.json").read_text())
    assert [r["scenario"] for r in rows] == [t for _, t, _ in st.ENGINE_ROWS]
    assert md_table(ENGINES, st.RUN_AGAINST_SIM_HEADER) == st.run_against_sim(rows, run)
    text = " ".join(ENGINES.read_text().split())
    assert "python docs/examples/sim_tables.py engines" in text and "(../data/run-against-sim-sim.csv)" in text and "(../data/run-against-sim-run.json)" in text
    assert f"{sum(float(r['cpu_s']) for r in rows):.0f} s of CPU for the six runs" in text
    filtered = next(r for r in rows if r["scenario"] == "thesis-3.2-fixed8-filtered")
    load = json.loads((DATA / "run-under-load-3.2-filtered.json").read_text())
    e = f"{float(filtered['attitude_final']):.2e}".split("e")
    assert load["header"][3] == f"final attitude / position (`sim`: {e[0]}e{int(e[1])} / {float(filtered['position_final']):.4f})"


def test_a_run_against_sim_row_runs_again(tmp_path):
    """A row of the ``sim`` side, picked with a fixed seed (a run costs 4-16 s of CPU), run again
    with the script's command line: its final errors as the file writes them (six significant
    digits; the same code path)."""
    st = _example("sim_tables")
    rows = read_csv(DATA / "run-against-sim-sim.csv")
    row = random.Random(61).choice(rows)
    out = tmp_path / "run"
    sim(row["scenario"], out)
    diff = reproduce.differ(st.engines_row(out, row["scenario"], 0.0), row, skip=("cpu_s",))
    assert not diff, (row["scenario"], diff)


# --------------------------------------------------------------------------- quickstart.md's scenario table


def test_the_quickstart_table_is_its_file():
    """quickstart.md's "what it shows" of the §3.3 and §4.5 scenarios, cell by cell, is
    docs/data/quickstart-sim.csv (docs/examples/sim_tables.py quickstart: each scenario once on
    ``sim``, and §3.3 once more with agents and sensors at 1 kHz)."""
    st = _example("sim_tables")
    rows = read_csv(DATA / "quickstart-sim.csv")
    assert {r["scenario"] for r in rows} == {*st.QUICKSTART, "thesis-3.3-moving5 " + " ".join(st.FINE)}
    want = st.quickstart_cells(rows)
    got = {r[0].strip("`").removeprefix("topologies/").removesuffix(".toml"): r[2] for r in md_table(QUICKSTART, "| scenario | command | what it shows |")}
    assert {k: got.get(k) for k in want} == want
    text = " ".join(QUICKSTART.read_text().split())
    assert "python docs/examples/sim_tables.py quickstart" in text and "(data/quickstart-sim.csv)" in text
    cpu = sum(float(r["value"]) for r in rows if r["measure"] == "cpu_s")
    assert f"{cpu:.0f} s of CPU for the eight runs" in text


def test_a_quickstart_scenario_runs_again(tmp_path):
    """One of the seven scenarios, picked with a fixed seed (4-17 s of CPU), run again with the
    script's command line: its measures as the file writes them."""
    st = _example("sim_tables")
    name = random.Random(61).choice(st.QUICKSTART)
    want = {r["measure"]: r["value"] for r in read_csv(DATA / "quickstart-sim.csv") if r["scenario"] == name and r["measure"] != "cpu_s"}
    out = tmp_path / name
    sim(name, out)
    diff = reproduce.differ(st.quickstart_measures(out, name), want)
    assert not diff, (name, diff)


def test_the_suite_time_cpu_figures_are_their_file():
    """development.md's CPU figures of each measured run (cpu_s_<commit>) are
    docs/data/suite-time.json's, and they add up."""
    d = json.loads((ROOT / "docs" / "data" / "suite-time.json").read_text())
    text = " ".join((ROOT / "docs" / "development.md").read_text().split())
    runs = [k for k in d if k.startswith("cpu_s_")]
    assert len(runs) >= 2, runs
    for k in runs:
        c = d[k]
        assert c["first_layer"] + c["integration"] + c["background"] + c["other_machine_reruns"] == c["total"], k
        want = f"{c['total']:,} s of CPU (the first layer {c['first_layer']:,}, the integration layer {c['integration']:,}, the background part {c['background']:,}, the other-machine reruns {c['other_machine_reruns']:,}; `{k}` in the data file"
        assert want in text, want
        share = c["total"] / (c["wall_s"] - 35)  # less about 35 s of pip install
        assert f"{share:.1f} cores on average" in text, k
        assert f"at that share needs about {round((1800 - 35) * share, -2):,.0f} s" in text, k  # the CPU 30 min would hold at it


def test_the_sweep_examples_times_are_their_file():
    """running.md's three sweeps timed on both engines are docs/data/sweep-examples.json's
    (bench/bench_sweep_examples.py writes it): each example's four numbers after its own
    arguments (before the next example's), and its rows, which the engines gave the same."""
    d = json.loads((DATA / "sweep-examples.json").read_text())
    text = " ".join((DOCS / "running.md").read_text().split()).replace("`", "")
    assert f"measured {d['measured']}, python bench/bench_sweep_examples.py" in text
    args = [" ".join(r["args"]) for r in d["rows"]]
    for r, a in zip(d["rows"], args, strict=True):
        assert r["same_rows"], r["what"]
        want = f"{r['batched_wall_s']:.1f} s of wall time and {r['batched_cpu_s']:.1f} s of CPU batched, {r['sim_wall_s']:.1f} s and {r['sim_cpu_s']:.1f} s on sim, the same {r['runs']} rows"
        at = text.index(a)
        pos = text.find(want, at)
        assert pos >= 0 and not any(b in text[at + len(a) : pos] for b in args), (r["what"], want)
