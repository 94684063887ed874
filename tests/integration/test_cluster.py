"""zswarm basin and zswarm sweep on a real Dask distributed cluster (issue 31): a scheduler and
two worker processes on 127.0.0.1 (free ports, no dashboard), the commands with
``--cluster tcp://127.0.0.1:PORT``, and the same rows as the same commands run locally (a
basin in its local process pool, a sweep with a ``zswarm sim`` process per run).  Every
process is started in its own session and reaped by PID (the procs fixture)."""

from __future__ import annotations

import csv
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, TOPO
from tests.integration.conftest import wait_for

# Real processes, no real time (marker "processes"): make test runs the file in its first layer,
# beside the component tests (tests/layers.sh); each wait below is a hang's deadline.
pytestmark = pytest.mark.processes

DASK = str(Path(sys.executable).parent / "dask")
# The waits below are deadlines for a hang, not measures: a scheduler or worker starts in
# 2-4 s here (importing distributed), a command of this file runs in 5-25 s on a quiet
# machine; each deadline is over 10x that, for a loaded CI machine, and a pass never waits it out.
ROW_KEYS = ("draw", "kind", "synchronized", "left_s", "settle_01_s", "settle_s", "final_max", "initial_max", "jumps", "status")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _accepting(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


@pytest.fixture
def cluster(procs, tmp_path):
    """A scheduler and two single-threaded workers on 127.0.0.1; its address."""
    port = _free_port()
    procs.start([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard", "--no-show"], tmp_path / "scheduler.log")
    wait_for(lambda: _accepting(port), 60, "the Dask scheduler listening")
    addr = f"tcp://127.0.0.1:{port}"
    workers = []
    for n in range(2):
        workers.append(procs.start(
            [DASK, "worker", addr, "--host", "127.0.0.1", "--nthreads", "1", "--no-dashboard", "--local-directory", str(tmp_path / f"w{n}"), "--name", f"w{n}"],
            tmp_path / f"worker{n}.log",
        ))
    from distributed import Client

    with Client(addr, timeout=30) as c:
        wait_for(lambda: len(c.nthreads()) == 2, 60, "two Dask workers registered")
    return addr, workers


def _zswarm(*args: str) -> None:
    r = subprocess.run([sys.executable, "-m", "zswarm", *args], cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
    assert r.returncode == 0, r.stderr[-3000:]


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "basin.csv", newline="") as f:
        return sorted(({k: row[k] for k in ROW_KEYS} for row in csv.DictReader(f)), key=lambda row: int(row["draw"]))


def _basin(out: Path, *extra: str) -> list[dict[str, str]]:
    _zswarm("basin", str(TOPO / "thesis-5.6-hybrid7.toml"), "--draws", "5", "--duration", "3", "--jobs", "2", "--out", str(out), "--no-plots", *extra)
    return _rows(out)


def test_basin_on_a_dask_cluster_gives_the_local_rows(cluster, tmp_path):
    addr, _ = cluster
    local = _basin(tmp_path / "local")
    for engine in ("batched", "sim"):
        remote = _basin(tmp_path / f"cluster-{engine}", "--cluster", addr, "--engine", engine, "--chunk", "2")
        assert remote == local, engine
    assert len(local) == 5 and all(r["status"] == "ok" for r in local)


def test_a_lost_worker_is_retried(cluster, tmp_path):
    """A worker killed (SIGKILL, with its nanny) while draws run on it: the scheduler gives its
    draws to the other worker and the basin completes with the local rows."""
    addr, workers = cluster
    args = [sys.executable, "-m", "zswarm", "basin", str(TOPO / "thesis-5.6-hybrid7.toml"), "--draws", "6", "--duration", "6", "--engine", "sim"]
    _zswarm(*args[3:], "--jobs", "2", "--out", str(tmp_path / "local"))
    out = tmp_path / "remote"
    p = subprocess.Popen([*args, "--cluster", addr, "--out", str(out)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        # Kill a worker once the first draw is in: the others are under way on both workers.
        wait_for(lambda: (out / "basin.csv").exists() and len((out / "basin.csv").read_text().splitlines()) >= 2, 300, "the first draw's row")
        os.killpg(workers[0].pid, signal.SIGKILL)
        _, err = p.communicate(timeout=600)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(10)
    assert p.returncode == 0, err[-3000:]
    assert _rows(out) == _rows(tmp_path / "local")


def test_an_unreachable_cluster_is_one_line(tmp_path):
    port = _free_port()  # nothing listens there
    r = subprocess.run(
        [sys.executable, "-m", "zswarm", "basin", str(TOPO / "thesis-5.6-hybrid7.toml"), "--draws", "2", "--duration", "1", "--out", str(tmp_path / "b"), "--cluster", f"tcp://127.0.0.1:{port}"],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
    )
    assert r.returncode == 1, r.stderr
    assert "cannot reach the Dask scheduler" in r.stderr and "Traceback" not in r.stderr, r.stderr[-2000:]


SWEEP_KEYS = ("run_id", "point", "repeat", "seed", "links.delay_ms", "final_attitude_error", "final_position_error", "conv_attitude_s", "edge_sent", "edge_delivered", "edge_dropped", "status")


def _sweep(out: Path, *extra: str) -> list[dict[str, str]]:
    _zswarm("sweep", str(TOPO / "thesis-3.2-fixed8.toml"), "--vary", "links.delay_ms=0,20", "--repeats", "2", "--duration", "3", "--out", str(out), "--no-plots", *extra)
    with open(out / "sweep.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows and set(SWEEP_KEYS) <= set(rows[0]), list(rows[0])
    return sorted(({k: row[k] for k in SWEEP_KEYS} for row in rows), key=lambda row: row["run_id"])


def test_sweep_on_a_dask_cluster_gives_the_local_rows(cluster, tmp_path):
    # sim runs as the cluster's tasks (the run without link delay would go to the batched engine:
    # the next test); the local side with --keep-recordings, a `zswarm sim` process per run (the
    # other local path, sweep.run_sweep; without it the runs go to local workers, as on a cluster)
    local = _sweep(tmp_path / "local", "--jobs", "2", "--engine", "sim", "--keep-recordings")
    remote = _sweep(tmp_path / "cluster", "--cluster", cluster[0], "--engine", "sim")
    assert remote == local
    assert len(local) == 4 and all(r["status"] == "ok" for r in local)
    # each run's files came back into the sweep's folder
    assert all((tmp_path / "cluster" / "runs" / r["run_id"] / "summary.json").exists() for r in remote)


def test_batched_sweep_on_a_dask_cluster_gives_the_local_rows(cluster, tmp_path):
    """The batched engine's batches as the cluster's tasks: the rows of the local pool, emulated
    agent→agent and command links included (each run its own losses, wherever it is stepped)."""

    def batched_rows(out: Path, *extra: str) -> list[dict[str, str]]:
        links = ("--set", "links.delay_ms=20", "--set", "links.drop=0.2", "--set", "links.commands.drop=0.1")
        args = ("--vary", "noise.rel_att_var=0.005,0.02", *links, "--repeats", "2", "--duration", "2", "--engine", "batched", "--chunk", "2", "--out", str(out))
        _zswarm("sweep", str(TOPO / "thesis-5.6-hybrid7-noisy.toml"), *args, *extra)
        with open(out / "sweep.csv", newline="") as f:
            return sorted(({k: v for k, v in row.items() if k != "wall_s"} for row in csv.DictReader(f)), key=lambda row: row["run_id"])

    local = batched_rows(tmp_path / "local", "--jobs", "2")
    remote = batched_rows(tmp_path / "cluster", "--cluster", cluster[0])
    assert remote == local and len(local) == 4 and all(r["status"] == "ok" for r in local)
    assert all(int(r["edge_dropped"]) > 0 and int(r["cmd_dropped"]) > 0 for r in local)
