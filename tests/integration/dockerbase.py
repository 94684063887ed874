"""The compose test's base image root (tests/integration/test_compose.py), built early.

Docker Hub is not reachable here, so the base image is a ``debootstrap --variant=minbase``
root imported with ``docker import``: 42-49 s of downloads and unpacking on this machine
(2026-12-04), a third of the compose test's time.  It needs no Docker engine, so the
integration layer starts it when the session begins (``conftest.base_rootfs``) and runs the
compose tests last: the root is then built beside the other tests' real-time runs, at
SCHED_IDLE (``chrt --idle 0``: a waking process of a run preempts it at once; between
sessions the CPU is shared first, tests/layers.sh), and the image fixture only imports it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import threading
import time
from pathlib import Path

from tests.integration.conftest import kill_group

BASE_IMAGE = "zswarm-base:bookworm"
DEBOOTSTRAP = ["debootstrap", "--variant=minbase", "--include=python3,python3-venv", "bookworm"]
MIRROR = "http://deb.debian.org/debian"
IDLE = ["chrt", "--idle", "0"]  # util-linux: the command and its children at SCHED_IDLE
TIMEOUT_S = 900.0


def run(cmd: list[str], timeout: float, **kw) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL, check=False, **kw)


def last_line(r: subprocess.CompletedProcess[str]) -> str:
    lines = (r.stderr or r.stdout or "").strip().splitlines()
    return lines[-1] if lines else f"exit {r.returncode}"


APT_PACKAGES = ("docker.io", "docker-compose")


def compose_command() -> str:
    """The docker-compose command, Debian's docker.io and docker-compose installed first if
    ``docker-compose`` or ``dockerd`` is missing (the test is skipped, saying why, if they
    cannot be: a skip fails ``make test``, tests/conftest.py)."""
    import pytest

    if not shutil.which("docker-compose") or not shutil.which("dockerd"):
        why = apt_install(*APT_PACKAGES)
        if why:
            pytest.skip(f"no docker-compose and could not install it ({why})")
    found = shutil.which("docker-compose")
    assert found, "docker-compose installed but not on PATH"
    return found


def apt_install(*pkgs: str, prefix: tuple[str, ...] = ()) -> str | None:
    """Install Debian packages; None, or why it could not.  Another apt-get of this session
    (the base root's, the engine's) may hold dpkg's lock: wait for it rather than fail."""
    if os.geteuid() != 0 or not shutil.which("apt-get"):
        return "not root with apt-get"
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    install = [*prefix, "apt-get", "install", "-y", "-q", "-o", "DPkg::Lock::Timeout=600", *pkgs]
    r = run(install, 900, env=env)
    if r.returncode != 0:  # a fresh machine may need the package lists first
        run([*prefix, "apt-get", "update", "-q", "-o", "DPkg::Lock::Timeout=600"], 600, env=env)
        r = run(install, 900, env=env)
    return None if r.returncode == 0 else f"apt-get install {' '.join(pkgs)}: {last_line(r)}"


def image_exists(name: str) -> bool:
    return shutil.which("docker") is not None and run(["docker", "image", "inspect", name], 30).returncode == 0


class Rootfs:
    """``debootstrap`` of the base root into ``parent/root`` on a thread of its own, at
    SCHED_IDLE; :meth:`wait` gives the root, or raises with why it could not be built
    (``Unavailable``: no debootstrap and none to be had; AssertionError: it failed)."""

    class Unavailable(Exception):
        pass

    def __init__(self, parent: Path) -> None:
        self.root = parent / "root"
        self.seconds: float | None = None
        self._error: BaseException | None = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._stopped = False
        self._log = parent / "debootstrap.log"
        self._thread = threading.Thread(target=self._build, name="base-rootfs", daemon=True)
        self._thread.start()

    def _build(self) -> None:
        t0 = time.monotonic()
        try:
            if not shutil.which("debootstrap") and (why := apt_install("debootstrap", prefix=tuple(IDLE))):
                raise Rootfs.Unavailable(f"no debootstrap to build the base image ({why})")
            with open(self._log, "wb") as log:
                self._proc = subprocess.Popen([*IDLE, *DEBOOTSTRAP, str(self.root), MIRROR], stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
                if self._stopped:  # stop() came between the check and the start
                    self._kill()
                code = self._proc.wait(TIMEOUT_S)
            tail = self._log.read_text(errors="replace").strip().splitlines()[-1:] or [f"exit {code}"]
            assert code == 0, f"debootstrap: exit {code}: {tail[0]}"
            self.seconds = time.monotonic() - t0
        except BaseException as e:  # noqa: BLE001 - handed to wait()
            self._error = e
            self._kill()

    def wait(self) -> Path:
        self._thread.join(TIMEOUT_S + 60)
        if self._thread.is_alive():
            self.stop()
            raise AssertionError(f"debootstrap did not finish in {TIMEOUT_S:g} s")
        if self._error is not None:
            raise self._error
        return self.root

    def _kill(self) -> None:
        if self._proc is not None:
            kill_group(self._proc, 30)

    def stop(self) -> None:
        """Kill the build if it still runs (its process group, by PID) and wait for the thread."""
        self._stopped = True
        self._kill()
        self._thread.join(60)
