"""A real browser for the viewer tests and the README's pictures: Debian's ``chromium``,
headless, driven over the Chrome DevTools Protocol (CDP) with ``websockets``.

:func:`screenshot` opens a page, takes screenshots until the caller's test says it has
drawn, waits ``settle`` s more for the last frames and returns the PNG and the page's
title.  WebGL runs on SwiftShader (software), so no GPU is needed.  The browser
is a child in its own process group, killed with the group however the call ends.
"""

from __future__ import annotations

import base64
import contextlib
import itertools
import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-extensions",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--remote-debugging-address=127.0.0.1",
    "--remote-debugging-port=0",
)


def find_chromium() -> str | None:
    """The browser's path: ``chromium`` (Debian) or ``chromium-browser``/``google-chrome``."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def install_chromium() -> tuple[str | None, str]:
    """``(path, why not)``: Debian's ``chromium``, installed with apt-get first if missing (as
    root; one installer at a time across processes, by a lock file); the path, or None and the
    reason in one line."""
    found = find_chromium()
    if found:
        return found, ""
    if os.geteuid() != 0 or not shutil.which("apt-get"):
        return None, "no chromium, and apt-get cannot install it here (not root, or not Debian)"
    import fcntl

    env = os.environ | {"DEBIAN_FRONTEND": "noninteractive"}
    with open(Path(tempfile.gettempdir()) / "zswarm-chromium-install.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another test process may be installing it
        if find_chromium():
            return find_chromium(), ""
        for cmd in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "-o", "DPkg::Lock::Timeout=600", "chromium"]):
            r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=1200)
            if r.returncode != 0:
                return None, f"apt-get could not install chromium: {' '.join(cmd)}: {(r.stderr or r.stdout).strip().splitlines()[-1:]}"
    found = find_chromium()
    return found, "" if found else "apt-get installed chromium but no chromium program is on PATH"


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _started(proc: subprocess.Popen[bytes], log: Path, pattern: bytes, timeout: float, what: str) -> re.Match[bytes]:
    """Wait for ``pattern`` in the child's ``log``: the match, or RuntimeError with the log's tail
    if the child exits or ``timeout`` s pass first."""
    deadline = time.monotonic() + timeout
    while True:
        m = re.search(pattern, log.read_bytes())
        if m:
            return m
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{what} did not start: {log.read_text(errors='replace')[-2000:]}")
        time.sleep(0.1)


def reap(proc: subprocess.Popen[bytes], grace: float, group: bool = False) -> None:
    """SIGTERM to ``proc``, ``grace`` s to exit, then SIGKILL (to its process group with
    ``group``, whatever of it is left); reaped by PID."""
    with contextlib.suppress(ProcessLookupError):
        proc.terminate()
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        pass
    with contextlib.suppress(ProcessLookupError):
        if group:
            os.killpg(proc.pid, signal.SIGKILL)
        elif proc.poll() is None:
            proc.kill()
    proc.wait()


@contextlib.contextmanager
def _browser(chromium: str, size: tuple[int, int]) -> Iterator[int]:
    """A headless browser; yields its DevTools port."""
    profile = tempfile.mkdtemp(prefix="zswarm-chromium-")
    log = Path(profile) / "stderr.log"
    with open(log, "wb") as err:
        proc = subprocess.Popen(
            [chromium, *FLAGS, f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}", "about:blank"],
            stdout=subprocess.DEVNULL,
            stderr=err,
            start_new_session=True,
        )
    try:
        port = int(_started(proc, log, rb"DevTools listening on ws://127\.0\.0\.1:(\d+)/", 60, "chromium").group(1))
        yield port
    finally:
        # SIGTERM to the browser alone: it closes and reaps its own helper processes (killed
        # together, they would be left to init as zombies); then the group, whatever is left.
        reap(proc, 10.0, group=True)
        shutil.rmtree(profile, ignore_errors=True)


class _Page:
    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.ids = itertools.count(1)

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        n = next(self.ids)
        self.ws.send(json.dumps({"id": n, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=120))
            if msg.get("id") == n:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})

    def evaluate(self, expr: str) -> Any:
        r = self.call("Runtime.evaluate", expression=expr, returnByValue=True)
        return r.get("result", {}).get("value")


def screenshot(
    url: str, ready: Callable[[bytes], bool], timeout: float = 180.0, settle: float = 3.0, size: tuple[int, int] = (1600, 1000)
) -> tuple[bytes, str, float]:
    """``(PNG, page title, seconds until ready)`` of ``url`` in headless Chromium: screenshots
    every 2 s until ``ready(png)`` holds, then one more after ``settle`` s (the last frames).
    Raises TimeoutError with the last screenshot's size if ``ready`` never holds."""
    from urllib.request import urlopen

    from websockets.sync.client import connect

    chromium = find_chromium()
    if chromium is None:
        raise RuntimeError("no chromium on this machine")
    with _browser(chromium, size) as port:
        targets = json.loads(urlopen(f"http://127.0.0.1:{port}/json/list", timeout=30).read())
        page_ws = next(t["webSocketDebuggerUrl"] for t in targets if t.get("type") == "page")
        with connect(page_ws, max_size=64 << 20, open_timeout=30) as ws:
            page = _Page(ws)
            page.call("Page.enable")
            t0 = time.monotonic()
            page.call("Page.navigate", url=url)
            while True:
                time.sleep(2.0)
                png = base64.b64decode(page.call("Page.captureScreenshot", format="png")["data"])
                if ready(png):
                    break
                if time.monotonic() - t0 > timeout:
                    raise TimeoutError(f"{url}: not drawn after {timeout:g} s (last screenshot {len(png)} bytes)")
            took = time.monotonic() - t0
            time.sleep(settle)
            png = base64.b64decode(page.call("Page.captureScreenshot", format="png")["data"])
            title = str(page.evaluate("document.title") or "")
    return png, title, took


def view_screenshot(run_dir: Path, ready: Callable[[bytes], bool], settle: float = 3.0, timeout: float = 180.0) -> tuple[bytes, str, float]:
    """``zswarm view RUN_DIR --web`` on a free localhost port, its page in :func:`screenshot`
    (Rerun's WebGL renderer); the server is stopped (its process group) however this ends."""
    import sys

    port = _free_port()
    log = Path(tempfile.mkdtemp(prefix="zswarm-view-log-")) / "view.log"
    env = os.environ | {"TELEMETRY_ENABLED": "false"}
    with open(log, "wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "zswarm", "view", str(run_dir), "--web", f"127.0.0.1:{port}"],
            stdout=out,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
        )
    try:
        url = _started(proc, log, rb"serving the web viewer: (\S+)", 120, "zswarm view --web").group(1).decode()
        return screenshot(url + "&renderer=webgl", ready, timeout=timeout, settle=settle)
    finally:
        reap(proc, 10.0, group=True)  # zswarm view stops its viewer program on SIGTERM; the group: whatever is left
        shutil.rmtree(log.parent, ignore_errors=True)


# The share of the 3-D view (the left half of a 1600x1000 page from its top bar to half its
# height, ~3.5e5 pixels) in the bodies' blue that says they are drawn: 0.002 is ~700 pixels, a
# §3.2 body or two seen whole; measured 0.0 before the data arrives, 0.0035 (§3.2's eight small
# bodies from zswarm's camera, 2.5 spreads away) to 0.025 (§5.6's seven) once drawn.
BODIES_DRAWN = 0.002


def body_pixels(png: bytes) -> tuple[float, float]:
    """(share of the 3-D view's pixels in the true bodies' blue, std of the whole image): the
    3-D view is the left half below the top bar, its upper two thirds above the tabs (zswarm's
    blueprint, side panels collapsed): measured from the bar to half the page's height."""
    import io

    import numpy as np
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)
    left = img[60 : img.shape[0] // 2, : img.shape[1] // 2]
    r, g, b = left[..., 0], left[..., 1], left[..., 2]
    blue = (b > r + 60) & (b > g + 25) & (b > 80)
    return float(blue.mean()), float(img.std())


@contextlib.contextmanager
def rerun_receiver(out: Path) -> Iterator[str]:
    """The wheel's ``rerun`` program saving what it receives to ``out`` (``rerun --save``) on a
    free localhost port; yields the URL to stream to; stopped (SIGTERM: it ends the file) and
    reaped by PID at the end."""
    from zswarm.recording.rerun_view import viewer_program

    port = _free_port()
    log = out.with_suffix(".log")
    with open(log, "wb") as err:
        proc = subprocess.Popen(
            [viewer_program(), "--save", str(out), "--bind", "127.0.0.1", "--port", str(port)],
            stdout=err,
            stderr=subprocess.STDOUT,
            env=os.environ | {"TELEMETRY_ENABLED": "false"},
        )
    try:
        _started(proc, log, rb"Listening for gRPC connections", 60, "rerun --save")
        yield f"rerun+http://127.0.0.1:{port}/proxy"
    finally:
        reap(proc, 30.0)  # SIGTERM: it ends the file
