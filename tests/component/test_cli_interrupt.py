"""Ctrl-C on a command that does not stop on it by itself (``zswarm sim``) ends it with exit 130
and one line, no traceback, as every subcommand's --help says (issue 48)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

from tests.conftest import TOPO


def test_ctrl_c_on_sim_exits_130_with_one_line(tmp_path):
    out = tmp_path / "run"
    p = subprocess.Popen(
        [sys.executable, "-m", "zswarm", "sim", str(TOPO / "thesis-3.2-fixed8.toml"), "--duration", "100000", "--out", str(out), "--no-plots"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not out.exists() and time.monotonic() < deadline:  # the results folder: it is simulating
            time.sleep(0.1)
        time.sleep(1.0)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130, err[-2000:]
    assert "zswarm sim: interrupted" in err and "Traceback" not in err
