"""The studies' published numbers against their files, and a few of their runs made again (issue 61,
item 6).

Each table of results in docs/studies/ comes from a file in the repository that a named command
writes (a ``zswarm sweep``'s sweep.csv, a ``zswarm basin`` folder, docs/examples/basin_under_delay.py's
CSV).  Two kinds of test per table:

* **the page is its file**: the table is parsed from the Markdown and compared with what its file
  gives, cell by cell, so that editing either alone fails;
* **the file is what the code computes**: one of its rows or draws (two for a basin table that
  has a kept folder beside it), picked here with a fixed seed among the cheap ones, is run again
  on the engine the study used (the same code path, so the cells must be equal as the file writes
  them, six significant digits, rows.cell).  That ``sim`` gives the batched engine's rows is
  tests/component/test_sweep_engines.py's, run by run.

Where a study's per-draw rows were not kept (the sensor-side basin) a re-run draw can only be
held to its verdict where the basin is unanimous; decarli.md's sweeps are held to their files but
not re-run (27 s of CPU a row on sim).

The re-runs are CPU-bound simulations that keep no real time and have no wall-clock limit.  A
batch of a few draws costs about what one draw does (the engine's per-step cost dominates: a
150 s §5.6 batch 25-36 s of CPU with one or two hybrid draws, a 40 s §3.2 one 5-12 s), so
where two rows are run they share a batch.  The file's re-runs: ~120 s of CPU, 165 s before
2026-12-08 (each test's docstring says its share).
"""

from __future__ import annotations

import csv
import importlib.util
import itertools
import json
import random
from pathlib import Path

import numpy as np
import pytest

from tests import reproduce
from tests.conftest import ROOT
from zswarm.scenario import load, parse_override, with_rotations
from zswarm.studies import basin
from zswarm.studies.sweep import Job
from zswarm.studies.sweep_batched import run_batch

DOCS = ROOT / "docs"
CHAPTER5 = DOCS / "studies" / "chapter5.md"
COMMUNICATION = DOCS / "studies" / "communication.md"
FIGURES = DOCS / "figures"
DATA = DOCS / "data"
THRESHOLDS = (0.01, 0.1)  # zswarm sweep's defaults, which every sweep of the pages ran with


def md_table(page: Path, header: str) -> list[list[str]]:
    """The rows (cells stripped) of the Markdown table of ``page`` whose header line starts with
    ``header``; the separator line left out."""
    lines = page.read_text().splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith(header)]
    assert len(starts) == 1, f"{page.name}: {len(starts)} tables begin with {header!r}"
    out = []
    for line in lines[starts[0] + 2 :]:
        if not line.startswith("|"):
            break
        out.append([c.strip() for c in line.strip().strip("|").split("|")])
    assert out, f"{page.name}: the table {header!r} has no rows"
    return out


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _example(name: str):
    """A script of docs/examples/ as a module (they are not a package)."""
    spec = importlib.util.spec_from_file_location(name, DOCS / "examples" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# --------------------------------------------------------------------------- sweeps


def _varied(header: list[str]) -> list[str]:
    """The --vary fields of a sweep.csv: the columns between ``seed`` and ``status``."""
    return header[header.index("seed") + 1 : header.index("status")]


def _job(row: dict[str, str], varied: list[str], sets: tuple[str, ...] = ()) -> Job:
    """The sweep's job of a row of its sweep.csv: its seed and its point's values, as
    ``zswarm sweep`` planned it (zswarm.studies.sweep.plan)."""
    ovs = tuple(parse_override(s, "--set") for s in sets) + tuple(parse_override(f"{f}={row[f]}", "--vary") for f in varied)
    return Job(row["run_id"], int(row["point"]), int(row["repeat"]), int(row["seed"]), tuple(row[f] for f in varied), ovs)


def _pick(rows: list[dict[str, str]], k: int, seed: int) -> list[dict[str, str]]:
    return random.Random(seed).sample(rows, k)


def _same_cells(got: dict, row: dict[str, str], what: str) -> None:
    """A re-run's result columns as sweep.csv writes them (rows.cell: six significant digits)
    against the file's row, the wall time aside: equal on the machine that wrote the file, the
    same printed figure elsewhere (tests/reproduce.py)."""
    skip = ["wall_s"]
    if not reproduce.same_machine() and "conv_attitude_s" in row and not row["conv_attitude_s"]:
        # A run that never settles does not contract: the §5.6 hybrid loop at 100-200 ms of
        # command delay chatters, and round-off differences grow without bound over its 150 s
        # (under layers.sh's other-machine settings p013-r3 of the coarse grid gave 210 jumps and
        # a final error 0.879 against the file's 220 and 0.845).  Off the machine that wrote the
        # file only its verdict (never settled) and its seeded link counts are reproducible.
        skip += ["final_attitude_error", "final_position_error", "jumps", "stale_terms", "conv_attitude_01_s"]
    diff = reproduce.differ(got, row, skip=skip)
    assert not diff, f"{what} {row['run_id']}: (re-run, file) differ in {diff}"


SWEEP_56 = [
    # (file, the grid's command as the page shows it); each file is that command's sweep.csv
    (FIGURES / "sweep-5.6-commands.csv", "--vary links.commands.delay_ms=0,50,100,150,200 --vary links.commands.drop=0,0.25,0.5"),
    (FIGURES / "sweep-5.6-commands-fine.csv", "--vary links.commands.delay_ms=0,2,5,10,20 --vary links.commands.drop=0,0.1,0.25"),
]


def test_the_sweep_files_are_the_commands_the_pages_name():
    """Each sweep file has the rows of its command: every grid point × repeat, each seed
    ``1 + repeat``, every run finished."""
    for path, vary, repeats, page in (
        *((p, v, 10, CHAPTER5) for p, v in SWEEP_56),
        (FIGURES / "sweep-3.2.csv", "--vary links.delay_ms=0,25,50,75,100,125,150,200 --vary links.drop=0,0.125,0.25,0.375,0.5", 30, COMMUNICATION),
    ):
        assert vary in " ".join(page.read_text().replace("\\\n", " ").split()), (page.name, vary)
        assert f"]({Path('..') / path.relative_to(DOCS)})" in page.read_text(), (page.name, path.name)
        table = read_csv(path)
        varies = [v.strip() for v in vary.split("--vary ")[1:]]
        grids = [v.split("=", 1)[1].split(",") for v in varies]
        fields = [v.split("=", 1)[0] for v in varies]
        assert _varied(list(table[0])) == fields
        want = {(tuple(c), r) for c in itertools.product(*grids) for r in range(repeats)}
        assert {(tuple(row[f] for f in fields), int(row["repeat"])) for row in table} == want, path.name
        assert all(row["status"] == "ok" and int(row["seed"]) == 1 + int(row["repeat"]) for row in table), path.name


def _fine_grid_table(table: list[dict[str, str]]) -> list[list[str]]:
    """chapter5.md's table of the fine grid, computed from its sweep.csv: per point over its
    seeds, the runs settled below 0.01 (conv_attitude_s: max_k |R̄_k|_I below the threshold from
    then to the end), their median (min-max), below 0.1 (conv_attitude_01_s), the ξ jumps and
    the commands lost (the mean of cmd_drop_ratio)."""
    points: dict[tuple[float, float], list[dict[str, str]]] = {}
    for r in table:
        points.setdefault((float(r["links.commands.delay_ms"]), float(r["links.commands.drop"])), []).append(r)
    out = []
    for (d, p), rs in sorted(points.items()):
        s = [float(r["conv_attitude_s"]) for r in rs if r["conv_attitude_s"]]
        s1 = [float(r["conv_attitude_01_s"]) for r in rs if r["conv_attitude_01_s"]]
        j = [int(r["jumps"]) for r in rs]
        lost = float(np.mean([float(r["cmd_drop_ratio"]) for r in rs]))
        out.append(
            [
                f"{d:g}",
                f"{p:g}",
                f"{len(s)} of {len(rs)}",
                f"{np.median(s):.1f} ({min(s):.1f}–{max(s):.1f})" if s else "never",
                f"{np.median(s1):.1f} ({len(s1)} of {len(rs)})" if s1 else "never",
                f"{np.median(j):g} ({min(j)}–{max(j)})",
                f"{100 * lost:.1f} %",
            ]
        )
    return out


def test_the_command_delay_table_is_its_sweep():
    """chapter5.md's fine-grid table, cell by cell, is what its sweep.csv gives; and the
    coarse grid's jump counts the text quotes."""
    assert md_table(CHAPTER5, "| delay (ms) | loss | settled < 0.01 |") == _fine_grid_table(read_csv(SWEEP_56[1][0]))
    coarse = read_csv(SWEEP_56[0][0])
    assert not any(r["conv_attitude_s"] for r in coarse if float(r["links.commands.delay_ms"]) >= 50)  # "nothing settles from 50 ms on"
    jumps: dict[tuple[str, str], list[int]] = {}
    for r in coarse:
        jumps.setdefault((r["links.commands.delay_ms"], r["links.commands.drop"]), []).append(int(r["jumps"]))
    lossy = [j for (d, p), js in jumps.items() if float(d) >= 50 and p != "0" for j in js]
    assert len(set(jumps["50", "0"])) == len(set(jumps["200", "0"])) == 1  # without loss every seed runs the same
    quoted = f"{jumps['50', '0'][0]} times at 50 ms and {jumps['200', '0'][0]} at 200 ms without loss ({min(lossy)}–{max(lossy)} with loss, over 50–200 ms)"
    assert quoted in " ".join(CHAPTER5.read_text().split()), quoted


def test_command_delay_sweep_rows_run_again():
    """A row of the fine §5.6 command-delay sweep (the file of chapter5.md's table; 150 s runs),
    picked with a fixed seed among its delayed and lossy points (p013-r3: 20 ms, 10 % loss), run
    again as ``zswarm sweep`` runs it (the batched engine, zswarm.studies.sweep_batched.run_batch):
    every column as the file has it, the seeded command losses included.

    One row: 29-32 s of CPU alone, 36 s with the coarse grid's row beside it in one batch
    (measured 2026-12-08; the engine's per-step cost dominates at a few draws).  The coarse grid
    is no table of the page (the text quotes its jump counts, held to its file above) and its
    rows run the same code with other link parameters, so its row is not run again."""
    path = SWEEP_56[1][0]
    table = read_csv(path)
    lossy = [r for r in table if float(r["links.commands.drop"]) > 0 and float(r["links.commands.delay_ms"]) > 0]
    row = _pick(lossy, 1, seed=61)[0]
    topology = ROOT / "topologies" / "thesis-5.6-hybrid7.toml"
    (got,) = run_batch((topology.read_text(), str(topology)), [_job(row, _varied(list(table[0])))], 150.0, THRESHOLDS)
    _same_cells(got, row, path.name)
    assert int(row["cmd_dropped"]) > 0


SWEEP_32 = FIGURES / "sweep-3.2.csv"


def test_the_communication_study_numbers_are_its_sweep():
    """communication.md's bullets on the 1200-run §3.2 sweep, from its sweep.csv."""
    table = read_csv(SWEEP_32)
    text = " ".join(COMMUNICATION.read_text().split())
    att = [float(r["conv_attitude_s"]) for r in table]
    pos = [float(r["conv_position_s"]) for r in table]
    ideal = [r for r in table if r["links.delay_ms"] == "0" and r["links.drop"] == "0"]
    assert len(table) == 1200 and f"in all {len(table)} runs" in text
    assert f"between {min(att):.1f} and {max(att):.1f} s, against {float(ideal[0]['conv_attitude_s']):.1f} s on ideal links" in text
    assert f"between {min(pos):.1f} and {max(pos):.1f} s, against {float(ideal[0]['conv_position_s']):.1f} s on ideal links" in text
    final = _by_point(table, "final_position_error")
    m = {k: float(np.mean(v)) for k, v in final.items()}
    assert f"At 40 s the mean position error is {m['0', '0']:.4f} m on ideal links and {m['200', '0']:.4f} m at 200 ms" in text
    half = final["200", "0.5"]  # its 30 seeds
    quoted = f"at 200 ms, {m['200', '0']:.4f} m with no loss and {min(half):.4f}–{max(half):.4f} m (mean {m['200', '0.5']:.4f})"
    quoted += " with half of the messages lost"
    assert quoted in text, quoted
    spread_t = max(max(v) - min(v) for v in _by_point(table, "conv_position_s").values())
    spread_f = max((max(v) - min(v)) / min(v) for v in final.values())
    assert f"spreads by at most {spread_t:.1f} s and the final position error by at most {100 * spread_f:.1f} %" in text


def _by_point(table: list[dict[str, str]], col: str) -> dict[tuple[str, str], list[float]]:
    """``col`` of each grid point's runs (its seeds)."""
    out: dict[tuple[str, str], list[float]] = {}
    for r in table:
        out.setdefault((r["links.delay_ms"], r["links.drop"]), []).append(float(r[col]))
    return out


def test_communication_sweep_row_runs_again():
    """A row of the §3.2 sweep (40 s), picked with a fixed seed among the lossy and delayed points
    (p026-r26: 125 ms, 12.5 % loss), run again on the batched engine as the sweep ran it (the same
    code path, so every column as written, the seeded losses included).

    10-12 s of CPU (measured 2026-12-08; 13 s with a second row in the batch, and ``sim``'s run of
    the row 9 s more).  That ``sim`` gives the batched engine's rows on these agent links (delay,
    jitter, Bernoulli and burst loss, stale terms held or dropped, on this very scenario) is
    tests/component/test_sweep_engines.py's test_batched_rows_are_sims_with_agent_links, column by
    column, so it is not run again here."""
    table = read_csv(SWEEP_32)
    lossy = [r for r in table if float(r["links.drop"]) > 0 and float(r["links.delay_ms"]) > 0]
    row = _pick(lossy, 1, seed=61)[0]
    topology = ROOT / "topologies" / "thesis-3.2-fixed8.toml"
    (got,) = run_batch((topology.read_text(), str(topology)), [_job(row, _varied(list(table[0])))], 40.0, THRESHOLDS)
    _same_cells(got, row, "sweep-3.2.csv")
    assert int(row["edge_dropped"]) > 0


# --------------------------------------------------------------------------- basins

LAWS = ("continuous", "hybrid", "velocity-free")


def _basin_dir(law: str) -> Path:
    return FIGURES / "basins" / f"thesis-5.6-{law}7"


def test_the_basin_under_delay_table_is_its_file():
    """chapter5.md's basin-under-delay table is docs/data/basin-delay-5.6.csv as
    docs/examples/basin_under_delay.py prints it (its ``markdown``), row by row."""
    bud = _example("basin_under_delay")
    want = bud.markdown(bud.read_csv(DATA / "basin-delay-5.6.csv")).splitlines()
    got = md_table(CHAPTER5, "| law | command delay (ms) | loss |")
    assert got == [[c.strip() for c in line.strip("|").split("|")] for line in want[2:]]


def test_the_lossless_undelayed_cells_are_the_uniform_basins_first_thousand():
    """The table's three cells without delay or loss are the same 1000 draws as the first 1000
    of the 10,000-draw basins of docs/figures/basins/ (the starts are seeded by the draw's number;
    no random link, so each draw's run seed is the scenario's): summarized from those rows, the
    file's numbers to every digit."""
    for row in read_csv(DATA / "basin-delay-5.6.csv"):
        if row["delay_ms"] != "0" or row["loss"] != "0":
            continue
        assert row["rows"].startswith(str(_basin_dir(row["law"]).relative_to(ROOT))), row
        rows = [r for r in basin.read_rows(_basin_dir(row["law"]) / "basin.csv") if int(r["draw"]) <= 1000]
        s = basin.summarize(rows, 0.01, 150.0, verdict="synchronized")
        assert (s["drawn"], s["synchronized"]) == (int(row["drawn"]), int(row["synchronized"]))
        assert [100 * x for x in s["fraction_95ci"]] == [float(row["ci95_lo_pct"]), float(row["ci95_hi_pct"])]
        assert [s["settle_s"][q] for q in ("p10", "median", "p90")] == [float(row[f"settle_{q}_s"]) for q in ("p10", "median", "p90")]
        assert [s["jumps"]["median"], s["jumps"]["max"]] == [float(row["jumps_median"]), float(row["jumps_max"])]


DELAY_BASINS = FIGURES / "basins" / "delay"


def test_each_kept_basin_under_delay_cell_is_its_folders_draws():
    """The cells of docs/data/basin-delay-5.6.csv whose basin folder is kept (under
    docs/figures/basins/delay/, one ``zswarm basin`` each, made again on 2026-12-07: all 21
    delayed or lossy cells, every one giving the page's figures) are that folder's 1000 draws summarized again here (basin.summarize of its
    basin.csv), to every digit."""
    kept = [r for r in read_csv(DATA / "basin-delay-5.6.csv") if r["rows"].startswith(str(DELAY_BASINS.relative_to(ROOT)))]
    assert sorted((r["law"], r["delay_ms"], r["loss"]) for r in kept) == sorted((law, d, p) for law in ("continuous", "hybrid", "velocity-free") for d in "0125" for p in ("0", "0.1") if (d, p) != ("0", "0"))
    for row in kept:
        d = DELAY_BASINS / f"thesis-5.6-{row['law']}7-d{row['delay_ms']}-p{row['loss']}"
        assert row["rows"] == str((d / "basin.csv").relative_to(ROOT)), row
        s = basin.summarize(basin.read_rows(d / "basin.csv"), 0.01, 150.0, verdict="synchronized")
        assert (s["drawn"], s["synchronized"]) == (int(row["drawn"]), int(row["synchronized"])), row
        assert [100 * x for x in s["fraction_95ci"]] == [float(row["ci95_lo_pct"]), float(row["ci95_hi_pct"])], row
        st, j = s.get("settle_s") or {}, s["jumps"]
        assert [st.get(q, "") for q in ("p10", "median", "p90")] == [float(row[f"settle_{q}_s"]) if row[f"settle_{q}_s"] else "" for q in ("p10", "median", "p90")], row
        assert [j["median"], j["max"]] == [float(row["jumps_median"]), float(row["jumps_max"])], row


def _file_row(law: str, draw: int) -> dict[str, str]:
    return next(r for r in basin.read_rows(_basin_dir(law) / "basin.csv") if int(r["draw"]) == draw)


def test_basin_under_delay_draws_run_again():
    """Two draws of the continuous law (150 s) run again on the batched engine in one batch, as
    ``zswarm basin --engine batched`` steps a chunk (run_chunk), each draw with its own cell's
    command delay and loss and its own seeds (the draw's number for the start, ``seed + draw``
    for the losses): a draw of the cell without delay or loss, which gives its row of
    docs/figures/basins/thesis-5.6-continuous7/basin.csv (the uniform basin's table), and a draw
    of a kept cell (its folder under docs/figures/basins/delay/), picked with a fixed seed among
    the kept cells where every draw synchronized (1 ms without loss, draw 994; the other is draw 67),
    which gives its row of that folder's basin.csv
    (tests/reproduce.py: to every digit on the machine that wrote them, a batch's other draws
    changing nothing of a draw).

    The continuous law's kept cells: a draw costs 16-18 s of CPU there against 25 s of the hybrid
    law's, and the two draws 23 s against 45 s for the four hybrid draws (two of them only held to
    their cell's verdict, their rows not kept) this test ran before (measured 2026-12-07).  The
    hybrid law under command delay and loss is run again by test_command_delay_sweep_rows_run_again;
    the cells whose rows are not kept are held to the table by the tests above only."""
    cells = {(r["law"], r["delay_ms"], r["loss"]): r for r in read_csv(DATA / "basin-delay-5.6.csv")}
    kept = sorted(
        (d, p)
        for (law, d, p), c in cells.items()
        if law == "continuous" and c["rows"].startswith(str(DELAY_BASINS.relative_to(ROOT))) and c["synchronized"] == c["drawn"]
    )
    assert len(kept) == 4, kept
    rng = random.Random(62)
    plan = [("0", "0"), rng.choice(kept)]
    draws = [rng.randrange(1, 1001) for _ in plan]
    path = ROOT / "topologies" / "thesis-5.6-continuous7.toml"
    from zswarm.util import plugins

    scs, seeds = [], []
    for (d, p), draw in zip(plan, draws, strict=True):
        sc = load(path, [parse_override(f"links.commands.delay_ms={d}", "--set"), parse_override(f"links.commands.drop={p}", "--set")])
        scs.append(with_rotations(sc, basin.draw_overrides(sc, 1, draw)))
        seeds.append(basin.run_seed(sc, draw))
    b = basin.basin_of(scs[0])
    res = plugins.engine("batched").run(scs, 150.0, scs[0].seed, b.grid_s, seeds=seeds)
    got = [basin._row(draw, None, *res.series(n), 0.01, int(res.jumps[n]), int(res.agent_jumps[n]), 0.0, b.verdict) for n, draw in enumerate(draws)]
    (d, p), draw = plan[1], draws[1]
    folder = DELAY_BASINS / f"thesis-5.6-continuous7-d{d}-p{p}"
    assert cells["continuous", d, p]["rows"] == str((folder / "basin.csv").relative_to(ROOT))
    for g, want in zip(got, [_file_row("continuous", draws[0]), next(r for r in basin.read_rows(folder / "basin.csv") if int(r["draw"]) == draw)], strict=True):
        diff = reproduce.differ(g, want)
        assert not diff, (g["draw"], plan, diff)


SENSOR_BASIN = DATA / "basin-sensors-5.6.json"


def test_the_sensor_side_basin_is_its_file():
    """chapter5.md's sensor-side basin (its command, counts, interval, settle quantiles and
    jumps) is docs/data/basin-sensors-5.6.json."""
    s = json.loads(SENSOR_BASIN.read_text())
    text = " ".join(CHAPTER5.read_text().replace("\\\n", " ").split())
    assert " ".join(s["command"].split()) in text
    assert f"[`{s['rows']}`]" in text  # the page names the folder of its draws
    lo, hi = s["fraction_95ci_pct"]
    st, j = s["settle_s"], s["jumps"]
    quoted = (
        f"**{s['synchronized']} of {s['drawn']}** uniform starts (95 % CI {lo:.1f}–{hi:.1f} %), settling below 0.01 at "
        f"{st['p10']:.1f} / {st['median']:.1f} / {st['p90']:.1f} s (p10 / median / p90; jumps median {j['median']}, at most {j['max']})"
    )
    assert quoted in text, quoted
    assert f"{s['cpu_s']:,} s of CPU for the {s['drawn'] + 1} draws" in text


def test_the_sensor_side_basin_file_is_its_folders_draws():
    """docs/data/basin-sensors-5.6.json is its folder's draws (docs/figures/basins/sensors/, the
    page's command run once) summarized again here (basin.summarize of its basin.csv), as the
    page prints them: the interval to 0.1 %, the settle quantiles to 0.1 s; the counts and the
    jumps exactly.  The folder's basin_def.json is the command's."""
    s = json.loads(SENSOR_BASIN.read_text())
    folder = ROOT / Path(s["rows"]).parent
    d = json.loads((folder / "basin_def.json").read_text())
    argv = s["command"].split()
    assert d["topology"] == argv[2] and d["set"] == [a for a in argv if a.startswith("links.")] and d["duration_s"] == 150.0, d
    got = basin.summarize(basin.read_rows(folder / "basin.csv"), 0.01, 150.0, verdict="synchronized")
    assert got["drawn"] + 1 == int(argv[argv.index("--draws") + 1])  # draw 0 is the scenario's own start, not counted
    assert (got["drawn"], got["synchronized"]) == (s["drawn"], s["synchronized"])
    assert [round(100 * x, 1) for x in got["fraction_95ci"]] == s["fraction_95ci_pct"]
    assert {q: round(got["settle_s"][q], 1) for q in ("p10", "median", "p90")} == s["settle_s"]
    assert {q: got["jumps"][q] for q in ("median", "max")} == s["jumps"]


def test_a_sensor_side_basin_draw_runs_again_on_sim():
    """A draw of the sensor-side basin (150 s, lossy and jittered sensor links), picked with a
    fixed seed, on ``sim`` (one draw costs less there than on the batched engine, 27 s of CPU
    against 61 s: the batched engine's gain is in stepping many draws together; the two give the
    same row, tests/component/test_sweep_engines.py): its row of the folder's basin.csv, to the
    printed figure (another code path than the batched engine's that wrote it: tests/reproduce.py)."""
    s = json.loads(SENSOR_BASIN.read_text())
    path = ROOT / "topologies" / "thesis-5.6-hybrid7.toml"
    sets = [a for a in s["command"].split() if a.startswith("links.")]
    sc = load(path, [parse_override(x, "--set") for x in sets])
    assert sc.random_links  # each draw its own losses: the draw's run seed is seed + draw
    draw = random.Random(61).randrange(1, s["drawn"] + 1)
    got = basin.run_draw((sc.text, str(path)), 1, draw, 150.0, 0.01)
    want = next(r for r in basin.read_rows(ROOT / s["rows"]) if int(r["draw"]) == draw)
    diff = reproduce.differ(got, want, same_path=False)
    assert not diff, (draw, diff)


# --------------------------------------------------------------------------- communication.md's smaller §3.2 sweeps


def sig(x: float, n: int = 2) -> str:
    """A number as the pages write it: ``n`` significant digits, trailing zeros kept, and below
    0.01 in the short exponent form (8.7e-5)."""
    if x >= 0.01:
        return f"{x:#.{n}g}".rstrip(".")
    m, e = f"{x:.{n - 1}e}".split("e")
    return f"{m}e{int(e)}"


def _errors(r: dict[str, str]) -> str:
    return f"{sig(float(r['final_attitude_error']))} / {sig(float(r['final_position_error']))} m"


def _s(cell: str, unit: str = " s") -> str:
    return f"{float(cell):.1f}{unit}" if cell else "never"


SMALL_SWEEPS = {
    "far": DATA / "sweep-3.2-far.csv",
    "stale": DATA / "sweep-3.2-stale.csv",
    "sensor-delay": DATA / "sweep-3.2-sensor-delay.csv",
}


def test_the_communication_tables_are_their_sweeps():
    """communication.md's three tables of one-seed §3.2 sweeps (how far, hold or drop, sensor
    delay), cell by cell, from their sweep.csv files; each file is the sweep the page shows."""
    text = " ".join(COMMUNICATION.read_text().replace("\\\n", " ").split())
    far = {(r["links.delay_ms"], r["links.drop"]): r for r in read_csv(SMALL_SWEEPS["far"])}
    losses = ["0", "0.5", "0.8", "0.9", "0.95"]
    assert md_table(COMMUNICATION, "| delay \\ loss |") == [
        [f"{d} ms", *(f"{_s(far[d, p]['conv_position_s'], '')} / {sig(float(far[d, p]['final_position_error']))}" for p in losses)]
        for d in ["0", "500", "1000", "2000", "4000"]
    ]
    assert f"The attitude gets below 0.01 at {float(far['4000', '0']['conv_attitude_s']):.1f} s" in text
    stale = {(r["links.delay_ms"], r["algorithm.stale.policy"]): r for r in read_csv(SMALL_SWEEPS["stale"])}
    assert md_table(COMMUNICATION, "| delay | policy |") == [
        [f"{d} ms", p, _s(r["conv_attitude_s"]), _s(r["conv_position_s"]), _errors(r)]
        for d in ["200", "1000"]
        for p in ["hold", "drop"]
        for r in [stale[d, p]]
    ]
    assert f"At 200 ms every term is stale ({int(stale['200', 'hold']['stale_terms']):,} stale terms in a run)".replace(",", " ") in text
    sens = read_csv(SMALL_SWEEPS["sensor-delay"])
    assert md_table(COMMUNICATION, "| sensor delay |") == [
        [f"{r['links.sensors.delay_ms']} ms", _s(r["conv_attitude_s"]), sig(float(r["final_attitude_error"])), f"{float(r['final_position_error']):.4f} m"]
        for r in sens
    ]
    for name, vary in (
        ("far", "--vary links.delay_ms=0,500,1000,2000,4000 --vary links.drop=0,0.5,0.8,0.9,0.95"),
        ("stale", "--vary links.delay_ms=200,1000 --vary algorithm.stale.policy=hold,drop"),
        ("sensor-delay", "--vary links.sensors.delay_ms=0,10,50"),
    ):
        assert f"zswarm sweep topologies/thesis-3.2-fixed8.toml {vary} ```" in text, name
        assert f"(../data/{SMALL_SWEEPS[name].name})" in text, name
        varies = [v.strip() for v in vary.split("--vary ")[1:]]
        table = read_csv(SMALL_SWEEPS[name])
        assert {tuple(r[v.split("=")[0]] for v in varies) for r in table} == set(itertools.product(*(v.split("=")[1].split(",") for v in varies)))
        assert all(r["status"] == "ok" and r["seed"] == "1" for r in table)


def test_communication_table_rows_run_again():
    """A row of each of the three small sweeps, picked with a fixed seed among the ones off the
    ideal links, run again on the batched engine as the sweep ran it: every column as written.

    The "how far" and "hold or drop" rows run in one batch (they differ in link parameters only,
    which a batch's draws may, as a sweep's points do), so the latter's row is picked among its
    points that hold stale terms (the default policy; a dropping one is another scenario, a batch
    of its own); the sensor-delay row runs alone (a batch per sensor delay).  The two batches:
    17 s of CPU, against 26 s for a batch per row (measured 2026-12-08: a batch costs
    about as much with two draws as with one)."""
    topology = ROOT / "topologies" / "thesis-3.2-fixed8.toml"
    rng = random.Random(61)
    picked: dict[str, tuple[dict[str, str], list[str]]] = {}
    for name, path in SMALL_SWEEPS.items():
        table = read_csv(path)
        varied = _varied(list(table[0]))
        off = [r for r in table if any(r[f] not in ("0", "hold") for f in varied) and r.get("algorithm.stale.policy", "hold") == "hold"]
        picked[name] = (rng.choice(off), varied)
    for batch in (["far", "stale"], ["sensor-delay"]):
        got = run_batch((topology.read_text(), str(topology)), [_job(*picked[name]) for name in batch], 40.0, THRESHOLDS)
        for g, name in zip(got, batch, strict=True):
            _same_cells(g, picked[name][0], name)


# --------------------------------------------------------------------------- the uniform basins of docs/figures/basins


@pytest.mark.parametrize("family", ["thesis-5.6-*", "thesis-4.5-*"])
def test_the_uniform_basin_tables_are_their_folders(family):
    """chapter5.md's 10,000-draw tables and their "paired" lines are what ``zswarm basin-compare``
    prints from the basin folders of docs/figures/basins/ (their basin.csv rows)."""
    from zswarm.studies import basin_compare

    entries = basin_compare.compare(sorted((FIGURES / "basins").glob(family)))
    text = CHAPTER5.read_text()
    assert basin_compare.compare_table(entries) in text
    for line in basin_compare.paired(entries):
        assert line in text, line
    assert f"zswarm basin-compare docs/figures/basins/{family} --out docs/figures/basin-compare-{family[7:10]}.png" in text


def test_uniform_basin_draws_of_the_observers_run_again():
    """Draws of the §4.5 hybrid observer's 10,000-draw basin (30 s), picked with a fixed seed, run
    again as ``zswarm basin --engine batched`` runs a chunk: each row as basin.csv has it, but
    ``final_max``, which is in no table and is not held here.  The measure at the horizon is
    1.9e-5 in draw 2978, and |R̄|_I = sqrt((3 − tr R̄)/4) divides the round-off of its square by
    2|R̄|_I: the re-run gives 1.8809492e-05, the file (written on 2026-12-04) 1.88094e-05, a
    difference of 1.6e-15 to 5.3e-15 in the square (the file's sixth digit is rounded), 4 to 12
    units of the trace's last place; sim gives 1.8809516e-05 today (9e-16 in the square).  A
    bound on how far round-off moves that square over 3000 steps is not derived here, so the
    column is left out rather than held to a guessed tolerance; re-making the basin would take
    527 s of CPU."""
    law = "thesis-4.5-hybrid5"
    draws = sorted(random.Random(61).sample(range(1, 10001), 2))
    want = {r["draw"]: r for r in basin.read_rows(FIGURES / "basins" / law / "basin.csv")}
    for got in basin.run_chunk(str(ROOT / "topologies" / f"{law}.toml"), 1, draws, 30.0, 0.01):
        diff = reproduce.differ(got, want[str(got["draw"])], skip=("wall_s", "final_max"))
        assert not diff, (got["draw"], diff)


# --------------------------------------------------------------------------- decarli.md's communication sweeps


def test_the_decarli_communication_numbers_are_its_sweeps():
    """decarli.md's numbers on its two 15-run sweeps (each stage's late max error, ``*_late_max_mean``,
    and its settle time), from their sweep.csv files.  Nothing is run again here: a row is a 30 s
    run of eight agents at 200 Hz on ``sim`` (the batched engine has no De Carli family), 27 s of
    CPU."""
    page = DOCS / "studies" / "decarli.md"
    text = " ".join(page.read_text().split())

    def by_point(name: str, prefix: str) -> dict[tuple[str, str], dict[str, str]]:
        return {(r[f"{prefix}delay_ms"], r[f"{prefix}drop"]): r for r in read_csv(FIGURES / f"sweep-decarli-{name}.csv")}

    def e(x: str) -> str:
        """Below 0.1 as the page writes it, 4.5e-2."""
        m, ex = f"{float(x):.1e}".split("e")
        return f"{m}e{int(ex)}"

    edges, cmds = by_point("edges", "links."), by_point("commands", "links.commands.")
    ten, fifty, hundred = edges["10", "0"], edges["50", "0"], edges["100", "0"]
    quoted = [
        f"raises its floor from {sig(float(edges['0', '0']['rel_late_max_mean']), 1)} to {e(ten['rel_late_max_mean'])}",
        f"no longer stays below 0.05 after {float(ten['rel_settle_s']):.1f} s",
        f"the common-frame yaw is at {e(ten['yaw_late_max_mean'])}, the position at {e(ten['pos_late_max_mean'])} m "
        f"and the formation at {e(ten['form_late_max_mean'])} m",
        f"hover at their thresholds ({float(fifty['yaw_late_max_mean']):.3f}, {float(fifty['pos_late_max_mean']):.2f} m)",
        f"relative yaw {float(hundred['rel_late_max_mean']):.2f}, yaw {float(hundred['yaw_late_max_mean']):.2f}, "
        f"position {float(hundred['pos_late_max_mean']):.2f} m, formation {float(hundred['form_late_max_mean']):.2f} m",
        f"25 % gives {e(edges['0', '0.25']['rel_late_max_mean'])} relative yaw and {e(edges['0', '0.25']['form_late_max_mean'])} m formation, "
        f"50 % gives {e(edges['0', '0.5']['rel_late_max_mean'])} and {e(edges['0', '0.5']['form_late_max_mean'])} m",
        f"10 ms leaves the relative yaw at {e(cmds['10', '0']['rel_late_max_mean'])} and the formation at {e(cmds['10', '0']['form_late_max_mean'])} m",
        f"it ends {float(cmds['100', '0.25']['form_late_max_mean']):.1f}–{float(cmds['100', '0.5']['form_late_max_mean']):.1f} m off",
    ]
    for q in quoted:
        assert q in text, q
    upto20 = [r for (d, _), r in edges.items() if float(d) <= 20]
    for col, unit in (("yaw_settle_s", 2), ("pos_settle_s", 1), ("form_settle_s", 1)):
        v = [float(r[col]) for r in upto20]
        assert f"{min(v):.{unit}f}–{max(v):.{unit}f}" in text, col
    assert not any(r["form_settle_s"] for (d, _), r in cmds.items() if d == "50")  # "at 50 ms the formation never gets below 0.1 m"


# --------------------------------------------------------------------------- the near-start basins


RADII = ["1e-1", "1e-2", "1e-3", "1e-4", "1e-6", "1e-8"]


def _radii(start: str) -> list[str]:
    """The --near radii of a row's start ("0.01 rad from its own", "1e-04 to 1e-08 rad (each)"), as
    the folders name them."""

    def name(x: str) -> str:
        m, e = f"{float(x):.0e}".split("e")
        return f"{m}e{int(e)}"

    words = start.split()
    if words[1] == "to":
        lo, hi = RADII.index(name(words[0])), RADII.index(name(words[2]))
        return RADII[lo : hi + 1]
    return [name(words[0])]


NEAR_HEADER = "| scenario | start | synchronized | below threshold, min / median / max (s) |"


@pytest.mark.parametrize(("header", "agents"), [(NEAR_HEADER + " below 0.1", "7"), (NEAR_HEADER + " below 0.9", "5")])
def test_the_near_start_tables_are_their_folders(header, agents):
    """chapter5.md's tables of starts ε from the undesired equilibrium, from the basin.json of
    docs/figures/basins/near-<law><agents>-<ε>/; a row that stands for several radii ("each")
    holds for every one of them."""
    for cells in md_table(CHAPTER5, header):
        law = cells[0].removeprefix("thesis-5.6-").removeprefix("thesis-4.5-").removesuffix(agents)
        for r in _radii(cells[1]):
            s = json.loads((FIGURES / "basins" / f"near-{law}{agents}-{r}" / "basin.json").read_text())
            st, left, j = s["settle_s"], s["left_s"], s["jumps"]
            got = [f"{s['synchronized']} of {s['drawn']}", f"{st['min']:.1f} / {st['median']:.1f} / {st['max']:.1f}"]
            if agents == "7":
                got += [f"{s['settle_01_s']['median']:.1f}", f"{left['min']:.2f} / {left['median']:.2f} / {left['max']:.2f}"]
            else:
                got += [f"{left['median']:.1f}"]
            got += [f"{j['median']:g} / {j['max']:g}"]
            assert cells[2:] == got, (cells[:2], r)
