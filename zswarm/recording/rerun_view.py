"""A run in Rerun (issue 32): ``zswarm view RUN_DIR`` and the sink that draws it.

:class:`RerunSink` draws what :class:`zswarm.recording.foxglove.Views` derives from a run's
messages (the same derivation as the recording's Foxglove channels) on a Rerun
recording, on two timelines: ``world_time`` (the run's world seconds) and
``log_time`` (when the message was logged).  The entities:

``world/agent_<i>`` and ``world/agent_<i>_est``
    the true and the estimated pose (Transform3D); under each a ``body`` box
    (true: blue, labelled i; estimate: translucent orange).
``world/edges``
    the graph's edges between the true positions (LineStrips3D).
``errors/<quantity>/<i>``, ``errors/edge/<quantity>/<h>_<t>``, ``sync/edge/attitude/<h>_<t>``,
``sync/omega/<i>``, ``hybrid/xi/<k>``, ``hybrid/zeta/<i>``, ``links/<counter>/<j>_to_<i>``,
``commands/<component>/<i>``
    every number of the viewer's JSON records as a time series (Scalars),
    grouped by quantity (:func:`entity`): attitude and position errors,
    |R̄_k|_I and ‖ω_i‖, ξ_k and ζ_i, link counters, command components.
``hybrid/jumps``
    one text entry per jump of ξ_k or ζ_i (TextLog).
``events/alive``
    each process's liveliness token coming and going (TextLog, log_time only).
``faults``
    the scenario's fault windows: a text entry at each start and end, and
    ``faults/<n>/active`` 1 inside the window, 0 outside.

:func:`view` reads a results folder's ``recording.mcap`` (the messages as the
recorder wrote them) through :class:`RerunViewer`, which decodes, checks and
counts like the Foxglove writer (:class:`zswarm.recording.mcap_io.ViewerOut`).  The viewer
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

from zswarm.scenario import Scenario
from zswarm.transport import wire

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


def entity(stream: str, field: str) -> str:
    """The entity of one number of a record: grouped by quantity, the agent, edge or link last
    (``errors/3`` attitude -> ``errors/attitude/3``, ``links/1_to_2`` dropped ->
    ``links/dropped/1_to_2``, ξ_k -> ``hybrid/xi/k``), so that one view plots a quantity for
    all and its legend names them."""
    if field.startswith("xi_") and stream.startswith("hybrid/"):
        return f"hybrid/xi/{field[3:]}"
    head, _, last = stream.rpartition("/")
    return f"{head}/{field}/{last}" if head else f"{stream}/{field}"


def layout(sc: Scenario | None) -> dict[int, np.ndarray]:
    """Where the 3-D view draws each agent, as an offset from its true position: zero, unless
    every agent starts at the same point (the Chapter 5 laws steer attitudes only), when they
    stand on a circle in the x-y plane, a body's length apart (display only; the series and
    the Foxglove channels keep the truth)."""
    if sc is None or len(sc.agents) < 2:
        return {}
    pts = np.array([a.p for a in sc.agents], dtype=float)
    if float(np.max(np.ptp(pts, axis=0))) > 1e-9:
        return {}
    n = len(sc.agents)
    r = 2.0 * n / (2.0 * math.pi)  # neighbours 2 apart on the circle, bodies 1 long
    return {a.id: np.array([r * math.cos(2 * math.pi * k / n), r * math.sin(2 * math.pi * k / n), 0.0]) for k, a in enumerate(sc.agents)}


class RerunSink:
    """A :class:`zswarm.recording.foxglove.Sink` on a ``rerun.RecordingStream`` (see the module docstring).
    Bodies are boxes 1 : 0.6 : 0.3 (so that an attitude shows) with their frame's axes;
    ``offsets`` moves an agent's drawing (:func:`layout`)."""

    def __init__(self, rec: Any, offsets: dict[int, np.ndarray] | None = None) -> None:
        self.rr = rerun_module()
        self.rec = rec
        self.bodies: set[tuple[int, bool]] = set()
        self.offsets = offsets or {}

    def _offset(self, frame: str) -> np.ndarray | float:
        i = frame.removeprefix("agent_").removesuffix("_est")
        return self.offsets.get(int(i), 0.0) if i.isdigit() else 0.0

    def _time(self, t: float, log_time: int) -> None:
        self.rec.set_time("world_time", duration=float(t))
        self.rec.set_time("log_time", timestamp=log_time * 1e-9)

    def frames(self, log_time: int, t: float, frames: list[tuple[str, np.ndarray, np.ndarray]]) -> None:
        self._time(t, log_time)
        for name, p, R in frames:
            self.rec.log(f"world/{name}", self.rr.Transform3D(translation=np.asarray(p, dtype=float) + self._offset(name), mat3x3=np.asarray(R, dtype=float)))

    def scene(self, log_time: int, t: float, bodies: list[tuple[int, bool]], size: float, edges: list[tuple[int, int, np.ndarray, np.ndarray]]) -> None:
        rr = self.rr
        for i, est in bodies:
            if (i, est) in self.bodies:
                continue
            self.bodies.add((i, est))
            frame = f"agent_{i}_est" if est else f"agent_{i}"
            length = size if not self.offsets else 1.0
            box = rr.Boxes3D(
                half_sizes=[[length / 2, 0.3 * length, 0.15 * length]], colors=[_EST if est else _TRUE], labels=None if est else [str(i)], fill_mode="solid"
            )
            self.rec.log(f"world/{frame}/body", box, static=True)
            if not est:
                self.rec.log(f"world/{frame}", rr.TransformAxes3D(0.9 * length), static=True)
        if edges:
            self._time(t, log_time)
            strips = [[pa + self.offsets.get(a, 0.0), pb + self.offsets.get(b, 0.0)] for a, b, pa, pb in edges]
            self.rec.log("world/edges", rr.LineStrips3D(strips, colors=[_EDGE]))

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
            self.rec.log(entity(stream, k), rr.Scalars(float(v)))

    def event(self, payload: Any, log_time: int) -> None:
        """A process's liveliness token came or went (``events/alive``), on the log_time timeline."""
        from zswarm.recording.mcap_io import unpack

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


def blueprint(sc: Scenario | None, sync: bool) -> Any:
    """The layout: the 3-D scene beside the run's error series (|R̄_k|_I per edge and ‖ω_i‖ for
    a synchronization law, relative errors per edge for the §4 observers, else each agent's
    errors), the hybrid variables of a hybrid scheme, and tabs of commands (a plant driven by
    the agents), links and the text log (jumps, faults, processes)."""
    import rerun as rr
    import rerun.blueprint as rrb

    whole = rr.VisibleTimeRange("world_time", start=rr.TimeRangeBoundary.infinite(), end=rr.TimeRangeBoundary.infinite())
    from_zero = rrb.TimeAxis(view_range=rr.TimeRange(start=rr.TimeRangeBoundary.absolute(seconds=0.0), end=rr.TimeRangeBoundary.infinite()))

    def series(origin: str, name: str) -> Any:  # the whole run on the x axis, not a window around the cursor
        return rrb.TimeSeriesView(origin=origin, name=name, time_ranges=whole, axis_x=from_zero)

    if sync:
        views = [series("sync/edge/attitude", "|R̄_k|_I per edge (5.24)"), series("sync/omega", "‖ω_i‖ (rad/s)")]
    elif sc is not None and sc.oriented:
        views = [series("errors/edge/attitude", "relative attitude error per edge"), series("errors/edge/position", "relative position error per edge (m)")]
    else:
        views = [series("errors/attitude", "attitude error |R̃_i|_I"), series("errors/position", "position error (m)")]
    # Two series on the right, each half the window high (a legend of 8 fits); the rest in tabs.
    tab_views = [series("hybrid", "hybrid variables ξ_k, ζ_i")] if sc is not None and getattr(sc.params, "Xi", ()) else []
    tab_views += [series("commands", "commands")] if sc is not None and sc.plant != "prescribed" else []
    # The links' counters, one series per link and counter (66 on §3.2): no legend could fit them
    # all; hovering a line names it.
    links = rrb.TimeSeriesView(origin="links", name="links", time_ranges=whole, axis_x=from_zero, plot_legend=rrb.PlotLegend(visible=False))
    tabs = rrb.Tabs(*tab_views, links, rrb.TextLogView(origin="/", name="jumps, faults, processes"))
    title = "bodies: true (blue) and estimated (orange)" if not sync else "bodies (true attitudes)"
    # The series on the right have the whole column (the tabs under the scene): a legend of 8
    # agents fits a view half the window high (it was cut at 5 with three views stacked).  Tabs
    # with series of their own (hybrid variables, commands) get two fifths of the left column.
    scene = rrb.Spatial3DView(origin="world", name=title, eye_controls=_eye(sc))
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(scene, tabs, row_shares=[3, 2] if tab_views else [2, 1]), rrb.Vertical(*views), column_shares=[3, 2]),
        rrb.TimePanel(timeline="world_time"),
        collapse_panels=True,
    )


def _eye(sc: Scenario | None) -> Any:
    """A camera that takes in every body at the start: looking at the bodies' centre from a
    corner, 2.5 times their spread (at least 3 m) away (the viewer's own framing cut off the
    highest and lowest §3.2 agents); None without a scenario (the viewer frames it itself)."""
    import rerun.blueprint as rrb

    if sc is None or not sc.agents:
        return None
    drawn = layout(sc)  # where the bodies are drawn (the Chapter 5 laws' on a circle)
    ps = np.array([np.asarray(a.p, dtype=float) + drawn.get(a.id, 0.0) for a in sc.agents])
    centre = ps.mean(axis=0)
    # At least 3 m: the Chapter 5 laws' circle (2.2 m) of bodies drawn 1 m long with their axes.
    spread = max(3.0, float(np.linalg.norm(ps - centre, axis=1).max()))
    way = np.array([1.0, -1.2, 0.8]) / np.linalg.norm([1.0, -1.2, 0.8])
    return rrb.EyeControls3D(position=tuple(centre + 2.5 * spread * way), look_target=tuple(centre), eye_up=(0.0, 0.0, 1.0))


# Chunks of up to 4096 rows or 16 MiB, at most every 10 s of wall time (the SDK's defaults send
# within milliseconds: right for a live view, small chunks for a file written at once).
OFFLINE_BATCHES = {"flush_tick": 10.0, "flush_num_bytes": 16 << 20, "flush_num_rows": 4096}


class RerunViewer:
    """A run's messages into a Rerun recording: decoded and checked as the Foxglove writer
    does (a malformed one is counted and dropped), then drawn by :class:`zswarm.recording.foxglove.Views`."""

    def __init__(self, scenario: Scenario | None, recording_id: str | None = None, offline: bool = False) -> None:
        """``offline`` (a file written after the run): rows gathered into large chunks, not
        sent within milliseconds: the file is a fraction of the size and the viewer loads it
        that much faster (measured: see :data:`OFFLINE_BATCHES`)."""
        from zswarm.recording.foxglove import Views

        rr = rerun_module()
        batcher = rr.ChunkBatcherConfig(**OFFLINE_BATCHES) if offline else None
        self.rec = rr.RecordingStream(APP, recording_id=recording_id, batcher_config=batcher)
        self.sink = RerunSink(self.rec, layout(scenario))
        self.views = Views(self.sink, scenario)
        self.scenario = scenario
        self.count = 0
        self.malformed = 0
        self.lost: list[str] = []  # the recording's damage, a line each (mcap_read.Lost.text)
        self.horizon = 0.0  # the newest world time seen

    def save(self, path: Path) -> None:
        self.rec.save(str(path), default_blueprint=blueprint(self.scenario, self.views.sync))

    def connect(self, url: str) -> None:
        """Stream to a Rerun viewer (or ``rerun --serve-web``/``--save``) listening at ``url``."""
        self.rec.connect_grpc(url, default_blueprint=blueprint(self.scenario, self.views.sync))

    def finish(self, horizon: float) -> None:
        """The fault windows up to ``horizon`` (world s), then flush and disconnect."""
        if self.scenario is not None:
            self.sink.faults(self.scenario, horizon)
        self.close()

    def message(self, stream: str, payload: Any, t: int) -> dict[str, Any] | None:
        from zswarm.recording.mcap_io import STREAM_TYPES, decode

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
        if isinstance(m.get("t"), (int, float)):
            self.horizon = max(self.horizon, float(m["t"]))
        self.views.on_message(stream, m, t)
        return m

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()


def live(scenario: Scenario | None, run: str, url: str) -> RerunViewer:
    """A viewer streaming to the Rerun program at ``url`` (``--rerun``), for a Recorder."""
    viewer = RerunViewer(scenario, recording_id=run)
    viewer.connect(url)
    return viewer


def view(run_dir: Path, save: Path) -> RerunViewer:
    """Every message of ``run_dir``'s recording into the Rerun file ``save``."""
    from zswarm.recording import mcap_io as record
    from zswarm.scenario import load

    mcap = record.ensure_recording(run_dir, None)
    sc_file = run_dir / "scenario.toml"
    sc = load(sc_file) if sc_file.exists() else None
    viewer = RerunViewer(sc, recording_id=record.recorded_run_id(mcap), offline=True)
    viewer.save(save)
    losses: list[Any] = []
    try:
        for stream, payload, t in record.read(mcap, losses):
            if stream == record.LOST_CHANNEL:  # what the transcode could not read of the raw file
                viewer.lost.append(str(payload.get("text", "") if isinstance(payload, dict) else "a loss not described"))
                continue
            viewer.message(stream, payload, t)
    except BaseException:
        viewer.close()
        raise
    viewer.lost += [x.text() for x in losses]
    viewer.finish(viewer.horizon)
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


def serve_web(rrd: Path, host: str, port: int, grpc_port: int = 0) -> tuple[subprocess.Popen[bytes], str]:
    """The ``rerun`` program of the installed SDK serving ``rrd`` to its web viewer on
    ``host:port`` (HTTP) and a gRPC server on ``grpc_port`` (0: a free one); with the page's
    address, which tells the viewer where the data is (``?url=``)."""
    from urllib.parse import quote

    grpc = grpc_port or _free_port(host)
    cmd = [viewer_program(), "--serve-web", "--bind", host, "--web-viewer-port", str(port), "--port", str(grpc), str(rrd)]
    return _child(cmd), f"http://{host}:{port}/?url={quote(f'rerun+http://{host}:{grpc}/proxy', safe='')}"


def viewer_program() -> str:
    """The ``rerun`` program of the installed ``rerun-sdk`` wheel (its viewer and server), run
    directly: ``python -m rerun`` would put a Python process between us and it."""
    import rerun_cli

    path = os.environ.get("RERUN_CLI_PATH") or os.path.join(os.path.dirname(rerun_cli.__file__), "rerun")
    if not os.path.exists(path):
        raise SystemExit(f"zswarm view: the Rerun viewer program is missing ({path}): reinstall 'zswarm[rerun]'")
    return path


def _child(cmd: list[str]) -> subprocess.Popen[bytes]:
    """The viewer program as a child in our process group (a Ctrl-C or a kill of the group
    reaches it) that the kernel stops when this process dies, however it dies (Linux)."""

    def on_parent_death() -> None:
        if sys.platform.startswith("linux"):
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG

    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, env=os.environ | {"TELEMETRY_ENABLED": "false"}, preexec_fn=on_parent_death)  # noqa: PLW1509


def _free_port(host: str) -> int:
    import socket

    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


_TERMINATED = False


def _terminated(signum: int, frame: Any) -> None:
    global _TERMINATED
    _TERMINATED = True
    raise KeyboardInterrupt  # SIGTERM stops like Ctrl-C: the viewer program is stopped and reaped


def command(args: argparse.Namespace) -> int:
    signal.signal(signal.SIGTERM, _terminated)
    try:
        return _command(args)
    except KeyboardInterrupt:
        print("zswarm view: interrupted", file=sys.stderr)
        return 128 + (signal.SIGTERM if _TERMINATED else signal.SIGINT)  # 143 or 130, as the shell's convention


def _command(args: argparse.Namespace) -> int:
    run_dir = Path(args.run_dir)
    if not run_dir.is_dir():
        print(f"zswarm view: {run_dir}: not a results folder", file=sys.stderr)
        return 2
    if args.save is None and args.web is None and sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        print("zswarm view: no display to open Rerun's viewer on: use --web [HOST:PORT] (and open the address it prints) or --save FILE.rrd", file=sys.stderr)
        return 2
    from zswarm.recording.mcap_io import RAW_SUFFIX, RecordingError

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
        for line in v.lost:  # a damaged recording: what was read is shown, each loss named
            print(line, file=sys.stderr, flush=True)
        if args.web is None:
            if args.save:
                return 1 if v.lost else 0
            return _open_native(save)
        host, port = _host_port(args.web)
        proc, url = serve_web(save, host, port)
        print(f"serving the web viewer: {url} (Ctrl-C stops it)", flush=True)
        return _until_stopped(proc)
    finally:
        if tmp is not None:
            tmp.cleanup()


def _open_native(rrd: Path) -> int:
    """The native viewer on ``rrd`` (needs a display); until it is closed."""
    return _until_stopped(_child([viewer_program(), str(rrd)]))


def _until_stopped(proc: subprocess.Popen[bytes]) -> int:
    """Wait for the viewer program; Ctrl-C (or SIGTERM) stops it: exit 0 either way."""
    try:
        return proc.wait()
    except KeyboardInterrupt:
        return 0
    finally:
        _stop(proc)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """Stop the viewer program and reap it (by its PID)."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            proc.wait()
