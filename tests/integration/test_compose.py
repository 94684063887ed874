"""docker-compose runs of zswarm in a real Docker engine.

What it needs it installs and starts itself, and removes what it made:

* Debian's ``docker.io`` and ``docker-compose`` (apt-get, as root) if ``dockerd``
  or ``docker-compose`` is missing; ``dockerd`` started if no engine answers, and
  stopped at the end if this module started it;
* a base image from ``debootstrap --variant=minbase`` (Docker Hub is not
  reachable here), imported with ``docker import``, unless one exists;
* the zswarm image, built on that base from a wheelhouse made on the host
  (``pip wheel``), installed offline in the image.

Where no engine can be had it says why in one line and the test is skipped.  The compose
files alone (``docker-compose config``) are checked in test_compose_config.py.
Every container, network and image it created is removed, whatever happens.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import time

import pytest

from tests.conftest import ROOT, TOPO
from tests.integration.conftest import _machine_problems_only, judged_if_kept_up, not_kept_up
from tests.integration.dockerbase import BASE_IMAGE, Rootfs, compose_command
from tests.integration.dockerbase import image_exists as _image_exists
from tests.integration.dockerbase import run as _run
from tests.keepup import MachineDidNotKeepUp

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def compose_cli():
    """The docker-compose command (installed if missing)."""
    return compose_command()


@pytest.fixture(scope="module")
def engine(compose_cli, tmp_path_factory):
    """A Docker engine answering ``docker info`` (started here if none runs)."""
    started = None
    if _run(["docker", "info"], 30).returncode != 0:
        log = tmp_path_factory.mktemp("dockerd") / "dockerd.log"
        with open(log, "wb") as f:
            started = subprocess.Popen(["dockerd"], stdin=subprocess.DEVNULL, stdout=f, stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.monotonic() + 90
        while _run(["docker", "info"], 30).returncode != 0:
            if started.poll() is not None or time.monotonic() > deadline:
                tail = log.read_text(errors="replace").strip().splitlines()[-1:] or ["(no output)"]
                _stop(started)
                pytest.skip(f"no Docker engine: dockerd did not come up ({tail[0][:200]})")
            time.sleep(0.5)
    try:
        yield
    finally:
        if started is not None:
            _stop(started)


def _stop(p: subprocess.Popen) -> None:
    """Stop a dockerd we started (and the containerd it started), by process group."""
    try:
        os.killpg(p.pid, signal.SIGTERM)
        p.wait(30)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.wait(10)


@pytest.fixture(scope="module")
def image(engine, base_rootfs, tmp_path_factory):
    """The zswarm image on a locally built base, removed at the end with what it made.  The
    base's root was started with the session (conftest.base_rootfs) where it was missing then."""
    made: list[str] = []
    t0 = time.monotonic()
    try:
        if not _image_exists(BASE_IMAGE):
            early = base_rootfs is not None
            build = base_rootfs or Rootfs(tmp_path_factory.mktemp("rootfs"))
            try:
                root = build.wait()
            except Rootfs.Unavailable as e:
                pytest.skip(f"no base image, and {e}")
            finally:
                build.stop()
            print(f"\nbase root: debootstrap took {build.seconds:.0f} s (at idle priority{', from the session start' if early else ''})", file=sys.stderr)
            tar = subprocess.Popen(["tar", "-C", str(root), "-c", "."], stdout=subprocess.PIPE)
            r = subprocess.run(["docker", "import", "-", BASE_IMAGE], stdin=tar.stdout, capture_output=True, text=True, timeout=600)
            tar.wait(60)
            assert r.returncode == 0, f"docker import: {r.stderr}"
            made.append(BASE_IMAGE)
            shutil.rmtree(root, ignore_errors=True)
        t_base = time.monotonic() - t0
        ctx = tmp_path_factory.mktemp("context")
        shutil.copy(ROOT / "Dockerfile", ctx / "Dockerfile")
        r = _run([sys.executable, "-m", "pip", "wheel", "--quiet", str(ROOT), "-w", str(ctx / "wheelhouse")], 900)
        assert r.returncode == 0, f"pip wheel: {r.stderr[-2000:]}"
        tag = f"zswarm-test:{os.getpid()}"
        r = _run(["docker", "build", "--quiet", "--build-arg", f"BASE={BASE_IMAGE}", "-t", tag, str(ctx)], 900)
        assert r.returncode == 0, f"docker build: {r.stderr[-2000:]}"
        made.insert(0, tag)
        shutil.rmtree(ctx / "wheelhouse", ignore_errors=True)
        print(f"\nimages: base {t_base:.0f} s, zswarm {time.monotonic() - t0 - t_base:.0f} s", file=sys.stderr)
        yield tag
    finally:
        for name in made:
            _run(["docker", "image", "rm", "-f", name], 120)


ACTIVE_ENDPOINTS = "has active endpoints"


def _project_networks(project: str) -> list[str]:
    return _run(["docker", "network", "ls", "--filter", f"label=com.docker.compose.project={project}", "--format", "{{.Name}}"], 60).stdout.split()


def _compose_down(base: list[str], project: str, cwd) -> list[str]:
    """``down -v --remove-orphans``; what went wrong or is left of the project.

    The engine sometimes refuses to remove a network whose containers are already
    gone ("network ... has active endpoints"): libnetwork releases endpoints after the
    container removal returns (moby/moby#42119, #43286; CI hit it once on
    2026-12-03 with all 12 containers removed). That race is retried: ``down`` again
    after a pause, then with a forced disconnect of the project's containers by name.
    Any other failure of ``down``, and anything of the project still there at the end,
    is returned for the test to fail on."""
    label = f"label=com.docker.compose.project={project}"
    names = _run(["docker", "ps", "-a", "--filter", label, "--format", "{{.Names}}"], 60).stdout.split()
    down = _run([*base, "down", "-v", "--remove-orphans"], 180, cwd=cwd)
    for attempt in range(4):
        if down.returncode == 0 or ACTIVE_ENDPOINTS not in down.stderr:
            break
        print(f"\ndocker-compose down: the engine's endpoint race (attempt {attempt + 1}), retrying", file=sys.stderr)
        time.sleep(2.0 * (attempt + 1))
        if attempt >= 1:  # a stale endpoint goes with a forced disconnect by container name
            for n in _project_networks(project):
                for name in names:
                    _run(["docker", "network", "disconnect", "-f", n, name], 60)
        down = _run([*base, "down", "-v", "--remove-orphans"], 180, cwd=cwd)
    problems = [f"down: exit {down.returncode}: {down.stderr[-2000:]}"] if down.returncode else []
    if left := _run(["docker", "ps", "-aq", "--filter", label], 60).stdout.split():
        problems.append(f"containers left: {left}")
    if left := _project_networks(project):
        problems.append(f"networks left: {left}")
    return problems


def test_compose_run_converges_in_a_real_engine(image, compose_cli, tmp_path):
    """§3.2 (8 agents, 40 s) in 12 containers (router, recorder, world, 8 agents, a
    second router for the routed topology): the run ends by itself, summary.json
    shows the thesis' convergence, and the networks let nothing out.

    At time scale 1 (40 s of wall time).  Before issue 28 the twelve containers needed
    about 1.7 of this machine's two cores at 1, and with another process keeping a core
    busy agent 3 fell to 25 Hz and its estimate was lost (attitude error 0.99 at 18 s).
    At 1 beside `stress-ng --cpu 1` (2026-12-03) the agents kept up (≤ 0.08 % missed
    ticks) but the world skipped 2.5 % of its samples, while it skipped every sample it
    woke a period late; it now takes them late, up to 0.1 s (0.05 % skipped in
    test_run.py's runs), so this no longer runs at 0.5 (80 s).  The convergence is
    judged as the other runs' are: a run whose data came late reruns when it fails
    (judged_if_kept_up)."""
    results = tmp_path / "results"
    results.mkdir()
    f = tmp_path / "compose.yml"
    r = _run(
        [sys.executable, "-m", "zswarm", "compose", str(TOPO / "thesis-3.2-fixed8.toml"), "-o", str(f), "--no-build", "--image", image, "--results", str(results), "--network", "routed", "--time-scale", "1"],
        60,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr
    project = f"zswarmtest{os.getpid()}"
    base = [compose_cli, "-p", project, "-f", str(f)]
    t0 = time.monotonic()
    try:
        # With a run secret in the environment (keys.SECRET_ENV): the compose file hands it to
        # every container, whose run control is then signed (checked on the recording below).
        up = _run([*base, "up", "--no-color"], 300, cwd=tmp_path, env={**os.environ, "ZSWARM_RUN_SECRET": secrets.token_hex(16)})
        elapsed = time.monotonic() - t0
        (tmp_path / "up.log").write_text(up.stdout + up.stderr)
        assert up.returncode == 0, up.stdout[-3000:] + up.stderr[-2000:]
        nets = _project_networks(project)
        assert len(nets) == 2, nets
        for n in nets:
            assert json.loads(_run(["docker", "network", "inspect", n], 60).stdout)[0]["Internal"] is True, n
        codes = {
            c["Name"]: c["State"]["ExitCode"]
            for c in json.loads(_run(["docker", "inspect", *_run([*base, "ps", "-q"], 60, cwd=tmp_path).stdout.split()], 60).stdout or "[]")
        }
        assert len(codes) == 12, codes
    finally:
        left = _compose_down(base, project, tmp_path)
    assert not left, left
    print(f"\ncompose run: {elapsed:.1f} s wall for 40 s of world time at time scale 1", file=sys.stderr)
    s = json.loads((results / "thesis-3.2-fixed8" / "summary.json").read_text())
    assert all(v == 0 for v in codes.values()), codes  # the recorder exits 0 on a hole too: any other exit is a failure
    assert s["engine"] == "run" and s["duration_s"] == 40.0
    # As assert_run_exit_ok: a run not completed for recording holes alone, in a run that did not
    # keep up, is the machine's doing (a rerun); a run not completed for anything else fails at once.
    if not s["completed"] and _machine_problems_only(s["problems"]) and (why := not_kept_up(s)):
        raise MachineDidNotKeepUp(f"this machine did not keep up with the compose run ({'; '.join(why)}), which did not complete on what that leaves: {'; '.join(s['problems'])}")
    assert s["completed"], s["problems"]
    with judged_if_kept_up(s, "the thesis' final errors in containers"):
        for i, a in s["agents"].items():
            assert a["alive_at_end"], i
            if a["role"] == "follower":
                # The thesis' thresholds; sim reaches 7e-5 and 1.2e-2 (a wrong frame or timing gives 0.1–1).
                assert a["attitude_error_final"] < 1e-2, (i, a)
                assert a["position_error_final"] < 0.1, (i, a)
    assert (results / "thesis-3.2-fixed8" / "recording.mcap").stat().st_size > 100_000
    from zswarm.recording.mcap_io import read

    ctl = [m for stream, m, _ in read(results / "thesis-3.2-fixed8" / "recording.mcap") if stream.startswith("ctl/")]
    assert ctl and all(len(m.get("mac", "")) == 32 for m in ctl), ctl[:2]  # signed in the containers
