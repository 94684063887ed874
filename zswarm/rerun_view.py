"""A run in Rerun (issue 32): ``zswarm view RUN_DIR`` and the sink that draws it.

:class:`RerunSink` draws what :class:`zswarm.viz.Views` derives from a run's
messages (the same derivation as the recording's Foxglove channels) on a Rerun
recording, on two timelines: ``world_time`` (the run's world seconds) and
``log_time`` (when the message was logged).  The entities:

``world/agent_<i>`` and ``world/agent_<i>_est``
    the true and the estimated pose (Transform3D); under each a ``body`` box
    (true: blue, labelled i; estimate: translucent orange).
``world/edges``
    the graph's edges between the true positions (LineStrips3D).
``errors/<i>/…``, ``errors/edge/<h>_<t>/…``, ``sync/edge/<h>_<t>/…``, ``sync/<i>/…``, ``hybrid/<i>/…``, ``links/<j>_to_<i>/…``, ``commands/<i>/…``
    every number of the corresponding JSON record as a time series (Scalars):
    attitude and position errors, ξ_k and ζ_i, link counters, command components.
``hybrid/jumps``
    one text entry per jump of ξ_k or ζ_i (TextLog).
``events/alive``
    each process's liveliness token coming and going (TextLog, log_time only).
``faults``
    the scenario's fault windows: a text entry at each start and end, and
    ``faults/<n>/active`` 1 inside the window, 0 outside.

:func:`view` reads a results folder's ``recording.mcap`` (the messages as the
recorder wrote them) through :class:`RerunViewer`, which decodes, checks and
counts like the Foxglove writer (:class:`zswarm.record.ViewerOut`).  The viewer
itself is the ``rerun`` program of the same ``rerun-sdk`` wheel (its version is
the SDK's): ``--web`` runs it as a child serving the web viewer on localhost.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from zswarm import wire
from zswarm.scenario import Scenario

log = logging.getLogger("zswarm.view")

# No usage data leaves the machine (the viewer asks on its first start otherwise).
os.environ.setdefault("TELEMETRY_ENABLED", "false")

_TRUE = (51, 115, 230, 255)
_EST = (255, 140, 26, 115)
_EDGE = (153, 153, 153, 204)
APP = "zswarm"
_SKIP = frozenset({"t", "head", "tail", "agent", "index", "link"})  # record keys that name, not measure


def rerun_module() -> Any:
    """``import rerun``, or a clear error naming the extra to install."""
    try:
        import rerun
    except ImportError as exc:  # pragma: no cover - the test extra installs it
        raise SystemExit("zswarm: Rerun is not installed: pip install 'zswarm[rerun]'") from exc
    return rerun


class RerunSink:
    """A :class:`zswarm.viz.Sink` on a ``rerun.RecordingStream`` (see the module docstring)."""

    def __init__(self, rec: Any) -> None:
        self.rr = rerun_module()
        self.rec = rec
        self.bodies: set[tuple[int, bool]] = set()

    def _time(self, t: float, log_time: int) -> None:
        self.rec.set_time("world_time", duration=float(t))
        self.rec.set_time("log_time", timestamp=log_time * 1e-9)

    def frames(self, log_time: int, t: float, frames: list[tuple[str, np.ndarray, np.ndarray]]) -> None:
        self._time(t, log_time)
        for name, p, R in frames:
            self.rec.log(f"world/{name}", self.rr.Transform3D(translation=np.asarray(p, dtype=float), mat3x3=np.asarray(R, dtype=float)))

    def scene(self, log_time: int, t: float, bodies: list[tuple[int, bool]], size: float, edges: list[tuple[np.ndarray, np.ndarray]]) -> None:
        rr = self.rr
        for i, est in bodies:
            if (i, est) in self.bodies:
                continue
            self.bodies.add((i, est))
            path = f"world/agent_{i}_est/body" if est else f"world/agent_{i}/body"
            box = rr.Boxes3D(half_sizes=[[size / 2] * 3], colors=[_EST if est else _TRUE], labels=None if est else [str(i)], fill_mode="solid")
            self.rec.log(path, box, static=True)
        if edges:
            self._time(t, log_time)
            self.rec.log("world/edges", rr.LineStrips3D([[a, b] for a, b in edges], colors=[_EDGE]))

    def record(self, stream: str, schema: dict[str, Any], obj: dict[str, Any], log_time: int) -> None:
        rr = self.rr
        t = obj.get("t")
        if not isinstance(t, (int, float)) or not math.isfinite(t):
            return
        self._time(t, log_time)
        if stream == "hybrid/jumps":
            text = f"agent {obj['agent']}: {'ξ' if obj['variable'] == 'xi' else 'ζ'}_{obj['index']} {obj['before']:.4f} -> {obj['after']:.4f}"
            self.rec.log("hybrid/jumps", rr.TextLog(text, level="INFO"))
            return
        for k, v in obj.items():
            if k in _SKIP or isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            self.rec.log(f"{stream}/{k}", rr.Scalars(float(v)))

    def event(self, payload: Any, log_time: int) -> None:
        """A process's liveliness token came or went (``events/alive``), on the log_time timeline."""
        from zswarm.record import unpack

        e = unpack(payload)
        if not isinstance(e, dict) or not isinstance(e.get("key"), str):
            return
        self.rec.set_time("log_time", timestamp=log_time * 1e-9)
        self.rec.log("events/alive", self.rr.TextLog(f"{e['key']} {'alive' if e.get('alive') else 'gone'}", level="INFO" if e.get("alive") else "WARN"))

    def faults(self, sc: Scenario, horizon: float) -> None:
        """The scenario's fault windows: text at each start and end, and a 0/1 series."""
        rr = self.rr
        for n, f in enumerate(sc.faults):
            end = min(f.end, horizon)
            for t, text in ((f.at, f.describe()), (end, f"over: {f.describe()}")):
                if t > horizon:
                    continue
                self.rec.set_time("world_time", duration=float(t))
                self.rec.log("faults", rr.TextLog(text, level="WARN"))
            for t, v in ((0.0, 0.0), (f.at, 1.0), (end, 0.0)):
                self.rec.set_time("world_time", duration=float(t))
                self.rec.log(f"faults/{n}/active", rr.Scalars(v))


def blueprint() -> Any:
    """The layout: the 3-D scene beside the error, hybrid, link and command series."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="bodies: true (blue) and estimated (orange)"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="errors", name="estimation errors"),
                rrb.TimeSeriesView(origin="sync", name="synchronization: |R̄_k|_I per edge, ‖ω_i‖"),
                rrb.TimeSeriesView(origin="hybrid", name="hybrid variables"),
                rrb.Tabs(rrb.TimeSeriesView(origin="commands", name="commands"), rrb.TimeSeriesView(origin="links", name="links"), rrb.TextLogView(origin="/", name="jumps and faults")),
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="world_time"),
    )


class RerunViewer:
    """A run's messages into a Rerun recording: decoded and checked as the Foxglove writer
    does (a malformed one is counted and dropped), then drawn by :class:`zswarm.viz.Views`."""

    def __init__(self, scenario: Scenario | None, recording_id: str | None = None) -> None:
        from zswarm.viz import Views

        rr = rerun_module()
        self.rec = rr.RecordingStream(APP, recording_id=recording_id)
        self.sink = RerunSink(self.rec)
        self.views = Views(self.sink, scenario)
        self.count = 0
        self.malformed = 0

    def save(self, path: Path) -> None:
        self.rec.save(str(path), default_blueprint=blueprint())

    def message(self, stream: str, payload: Any, t: int) -> dict[str, Any] | None:
        from zswarm.record import STREAM_TYPES, decode

        if stream == "events/alive":
            self.sink.event(payload, t)
            return None
        expect = STREAM_TYPES.get(stream.split("/", 1)[0])
        try:
            if expect is None:
                raise wire.MessageError("not a zswarm stream")
            m = decode(payload, expect)
            wire.check_stream(stream, m)
        except wire.MessageError as exc:
            self.malformed += 1
            if self.malformed <= 10:
                log.warning("dropped a malformed message on %s: %s", stream, exc)
            return None
        self.count += 1
        self.views.on_message(stream, m, t)
        return m

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()


def view(run_dir: Path, save: Path) -> RerunViewer:
    """Every message of ``run_dir``'s recording into the Rerun file ``save``."""
    from zswarm import record
    from zswarm.replay import recorded_run_id
    from zswarm.scenario import load

    mcap = record.ensure_recording(run_dir, None)
    sc_file = run_dir / "scenario.toml"
    sc = load(sc_file) if sc_file.exists() else None
    viewer = RerunViewer(sc, recording_id=recorded_run_id(mcap))
    viewer.save(save)
    horizon = 0.0
    try:
        for stream, payload, t in record.read(mcap):
            m = viewer.message(stream, payload, t)
            if m is not None and isinstance(m.get("t"), (int, float)):
                horizon = max(horizon, float(m["t"]))
        if sc is not None:
            viewer.sink.faults(sc, horizon)
    finally:
        viewer.close()
    return viewer


def _host_port(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    try:
        p = int(port)
    except ValueError:
        raise SystemExit(f"zswarm view: --web: expected HOST:PORT or PORT, got {text!r}") from None
    if not 0 <= p <= 65535:
        raise SystemExit(f"zswarm view: --web: port {p} out of range")
    return host or "127.0.0.1", p


def serve_web(rrd: Path, host: str, port: int, grpc_port: int = 0) -> subprocess.Popen[bytes]:
    """The ``rerun`` program of the installed SDK serving ``rrd`` to its web viewer on
    ``host:port`` (HTTP) and a gRPC server on ``grpc_port`` (0: a free one)."""
    cmd = [sys.executable, "-m", "rerun", "--serve-web", "--bind", host, "--web-viewer-port", str(port), "--port", str(grpc_port or _free_port(host)), str(rrd)]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, env=os.environ | {"TELEMETRY_ENABLED": "false"}, start_new_session=True)


def _free_port(host: str) -> int:
    import socket

    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def command(args: argparse.Namespace) -> int:
    run_dir = Path(args.run_dir)
    if not run_dir.is_dir():
        print(f"zswarm view: {run_dir}: not a results folder", file=sys.stderr)
        return 2
    from zswarm.record import RAW_SUFFIX, RecordingError

    if not (run_dir / "recording.mcap").exists() and not (run_dir / ("recording" + RAW_SUFFIX)).exists():
        print(f"zswarm view: {run_dir / 'recording.mcap'}: no recording there", file=sys.stderr)
        return 2
    tmp = None
    save = Path(args.save) if args.save else None
    if save is None:
        tmp = tempfile.TemporaryDirectory(prefix="zswarm-view-")
        save = Path(tmp.name) / "run.rrd"
    try:
        try:
            v = view(run_dir, save)
        except (RecordingError, OSError) as exc:
            print(f"zswarm view: {run_dir}: {exc}", file=sys.stderr)
            return 2
        print(f"{run_dir}: {v.count} messages" + (f", {v.malformed} malformed (dropped)" if v.malformed else "") + f" -> {save}", flush=True)
        if args.web is None:
            if args.save:
                return 0
            return _open_native(save)
        host, port = _host_port(args.web)
        proc = serve_web(save, host, port)
        print(f"serving the web viewer at http://{host}:{port} (Ctrl-C stops it)", flush=True)
        try:
            return proc.wait()
        except KeyboardInterrupt:
            return 0
        finally:
            _stop(proc)
    finally:
        if tmp is not None:
            tmp.cleanup()


def _open_native(rrd: Path) -> int:
    """The native viewer on ``rrd`` (needs a display); until it is closed."""
    proc = subprocess.Popen([sys.executable, "-m", "rerun", str(rrd)], env=os.environ | {"TELEMETRY_ENABLED": "false"}, start_new_session=True)
    try:
        return proc.wait()
    except KeyboardInterrupt:
        return 0
    finally:
        _stop(proc)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
