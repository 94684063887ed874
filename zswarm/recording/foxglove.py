"""What the viewers show of a run: channels derived from its messages.

A :class:`Views` is fed every decoded message of a run (in arrival order,
with its log time) and derives what a viewer shows; a sink draws it.
:class:`FoxgloveSink` logs, on a ``foxglove.Context`` (whose sinks are the
recording's MCAP writer and, for ``--live``, a WebSocket server), the channels
below; :class:`zswarm.recording.rerun_view.RerunSink` logs the same to Rerun:

``/tf`` (``foxglove.FrameTransforms``)
    ``world`` → ``agent_<i>`` (true pose, from ``truth``) and ``world`` →
    ``agent_<i>_est`` (estimated pose R̂_i, p̂_i, from ``est/<i>``), at most
    ``rate`` Hz of world time each.
``/scene`` (``foxglove.SceneUpdate``)
    every agent as a cube locked to its true frame and a translucent one locked
    to its estimated frame, a label, and the graph's edges as lines between
    the true positions (``scene_rate`` Hz of world time).
``/errors/<i>`` (JSON)
    ``attitude`` = |R̃_i|_I with R̃_i = R_i R̂_i^T, ``position`` = ‖p_i − R̃_i p̂_i‖
    and ``position_direct`` = ‖p_i − p̂_i‖, at each estimate's own world time
    against the truth at that time (the same formulas and the same truth
    alignment as :func:`zswarm.report.errors`).
``/errors/edge/<h>_<t>`` (JSON)
    per edge (the §4 orientation, else every graph edge j → i as ``<i>_<j>``)
    the relative errors ``attitude`` = |R̃_t^T R̃_h|_I and ``position`` =
    ‖p̃_h − p̃_t‖ with p̃_i = R̃_i p̂_i − p_i (thesis (4.33)), from each agent's
    newest error, at ``rate`` Hz: zero exactly when the estimates agree with
    the truth up to one common rotation and translation.
``/sync/edge/<h>_<t>`` and ``/sync/<i>`` (JSON)
    for a synchronization law (report family ``sync``, no estimates): |R̄_k|_I
    of every oriented edge, R̄_k = R_t^T R_h on the truth (the measure of
    (5.24)), and each agent's ‖ω_i‖, at ``rate`` Hz.
``/hybrid/<i>`` (JSON)
    ``xi_<k>`` for every edge k the agent heads (ξ_k), and the named scalars
    its algorithm reports (ζ_i of (5.12) as ``zeta``, ...); ``/hybrid/jumps``
    one message per jump of ξ_k or ζ_i.
``/links/<j>_to_<i>`` (JSON)
    the counters of link j → i as the receiver reports them (delivered,
    dropped, reordered, latency), every time its stats arrive (1 Hz).
``/commands/<i>`` (JSON)
    the command agent i sent (τ_i of the Chapter 5 laws, v_i and ω_i of De
    Carli's vehicles): each component of a vector and its norm, a scalar as it
    is, at most ``rate`` Hz of world time.

Every JSON channel has a JSON schema (``title`` names it), so the Plot panel
plots e.g. ``/errors/3.attitude`` or ``/links/2_to_3.dropped``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

from zswarm.math import so3
from zswarm.scenario import Scenario

_NUM = {"type": "number"}


def object_schema(title: str, description: str, props: Mapping[str, Any], required: tuple[str, ...] = ("t",), extra: Any = False) -> dict[str, Any]:
    """The JSON schema of an object message (``title`` names it in the viewers)."""
    return {"title": title, "description": description, "type": "object", "properties": dict(props), "required": list(required), "additionalProperties": extra}


ERRORS_SCHEMA = object_schema(
    "zswarm.AgentErrors",
    "Estimation errors of one agent at its estimate's world time t (s)",
    {"t": _NUM, "attitude": _NUM, "position": _NUM, "position_direct": _NUM},
    ("t", "attitude", "position", "position_direct"),
)
EDGE_ERRORS_SCHEMA = object_schema(
    "zswarm.EdgeErrors",
    "Relative errors of one edge (head h, tail t) at world time t (s): |R̃_t^T R̃_h|_I and ||p̃_h − p̃_t||",
    {"t": _NUM, "head": {"type": "integer"}, "tail": {"type": "integer"}, "attitude": _NUM, "position": _NUM},
    ("t", "head", "tail", "attitude", "position"),
)
HYBRID_SCHEMA = object_schema("zswarm.Hybrid", "ξ_k of the edges the agent heads (xi_<k>) and its named scalars (zeta, ...) at world time t (s)", {"t": _NUM}, extra=_NUM)
JUMPS_SCHEMA = object_schema(
    "zswarm.Jump",
    "One jump of a hybrid variable: ξ_k of edge k (variable 'xi') or ζ_i of agent i (variable 'zeta')",
    {"t": _NUM, "agent": {"type": "integer"}, "variable": {"enum": ["xi", "zeta"]}, "index": {"type": "integer"}, "before": _NUM, "after": _NUM},
    ("t", "agent", "variable", "index", "before", "after"),
)
LINK_SCHEMA = object_schema(
    "zswarm.LinkCounters",
    "Counters of one link as its receiver reports them, at world time t (s)",
    {"t": _NUM, "link": {"type": "string"}, "delivered": {"type": "integer"}, "dropped": {"type": "integer"}, "reordered": {"type": "integer"}},
    ("t", "link", "delivered", "dropped"),
    extra=_NUM,
)

SYNC_EDGE_SCHEMA = object_schema(
    "zswarm.SyncEdge", "Relative attitude of one edge (head h, tail t) on the truth at world time t (s): |R̄_k|_I with R̄_k = R_t^T R_h (thesis (5.24))", {"t": _NUM, "head": {"type": "integer"}, "tail": {"type": "integer"}, "attitude": _NUM}, ("t", "head", "tail", "attitude")
)
SYNC_AGENT_SCHEMA = object_schema("zswarm.SyncAgent", "Angular speed ‖ω_i‖ (rad/s) of one agent on the truth at world time t (s)", {"t": _NUM, "omega": _NUM}, ("t", "omega"))
_CMD_HEADER = frozenset({"type", "src", "seq", "inc", "t", "t_local"})
COMMAND_SCHEMA = object_schema("zswarm.Command", "The command agent i sent at world time t (s): each component and its norm (tau_x, tau_y, tau_z, tau_norm; a scalar field as it is)", {"t": _NUM}, extra=_NUM)

# Colours of the 3-D panel: true bodies blue, estimates orange, edges grey.
_TRUE = (0.2, 0.45, 0.9, 1.0)
_EST = (1.0, 0.55, 0.1, 0.45)
_EDGE = (0.6, 0.6, 0.6, 0.8)
TRUTH_KEEP = 256  # truth samples kept to place late estimates (2.5 s at 100 Hz)


def _quat(R: np.ndarray) -> Any:
    from foxglove.messages import Quaternion

    x, y, z, w = so3.quaternion(R)
    return Quaternion(x=x, y=y, z=z, w=w)


def _vec(p: Any) -> Any:
    from foxglove.messages import Vector3

    return Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _stamp(ns: int) -> Any:
    from foxglove.messages import Timestamp

    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


class Sink(Protocol):
    """Where :class:`Views` draws: frames, the 3-D scene and JSON records."""

    def frames(self, log_time: int, t: float, frames: list[tuple[str, np.ndarray, np.ndarray]]) -> None:
        """``world → frame`` transforms ``(frame, p, R)`` at world time ``t``."""

    def scene(self, log_time: int, t: float, bodies: list[tuple[int, bool]], size: float, edges: list[tuple[int, int, np.ndarray, np.ndarray]]) -> None:
        """Every agent's body ``(i, estimated?)`` as a cube of edge ``size`` locked to its frame
        (``agent_<i>`` or ``agent_<i>_est``), and the graph's edges ``(a, b, p_a, p_b)`` between
        true positions."""

    def record(self, stream: str, schema: dict[str, Any], obj: dict[str, Any], log_time: int) -> None:
        """A JSON record on the channel ``/<stream>`` (``obj["t"]`` its world time)."""


class FoxgloveSink:
    """Draws on a ``foxglove.Context``: ``/tf`` (FrameTransforms), ``/scene`` (SceneUpdate)
    and every record through ``log_json(stream, schema, obj, log_time)``."""

    def __init__(self, context: Any, log_json: Callable[[str, dict[str, Any], Any, int], None]) -> None:
        from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel

        self.tf = FrameTransformsChannel("/tf", context=context)
        self.scene_ch = SceneUpdateChannel("/scene", context=context)
        self.record = log_json

    def frames(self, log_time: int, t: float, frames: list[tuple[str, np.ndarray, np.ndarray]]) -> None:
        from foxglove.messages import FrameTransform, FrameTransforms

        stamp = _stamp(log_time)
        self.tf.log(
            FrameTransforms(transforms=[FrameTransform(timestamp=stamp, parent_frame_id="world", child_frame_id=f, translation=_vec(p), rotation=_quat(R)) for f, p, R in frames]),
            log_time=log_time,
        )

    def scene(self, log_time: int, t: float, bodies: list[tuple[int, bool]], size: float, edges: list[tuple[int, int, np.ndarray, np.ndarray]]) -> None:
        from foxglove.messages import Color, CubePrimitive, LinePrimitive, LinePrimitiveLineType, Point3, Pose, SceneEntity, SceneUpdate, TextPrimitive

        stamp = _stamp(log_time)
        ident = _quat(np.eye(3))
        origin = Pose(position=_vec((0.0, 0.0, 0.0)), orientation=ident)
        cube_size = _vec((size, size, size))
        ents = []
        for i, est in bodies:
            frame, c = (f"agent_{i}_est", _EST) if est else (f"agent_{i}", _TRUE)
            label = [] if est else [
                TextPrimitive(pose=Pose(position=_vec((0.0, 0.0, 1.2 * size)), orientation=ident), billboard=True, font_size=14.0, scale_invariant=True, text=str(i), color=Color(r=1.0, g=1.0, b=1.0, a=1.0))
            ]  # fmt: skip
            cube = CubePrimitive(pose=origin, size=cube_size, color=Color(r=c[0], g=c[1], b=c[2], a=c[3]))
            ents.append(SceneEntity(timestamp=stamp, frame_id=frame, id=frame, frame_locked=True, cubes=[cube], texts=label))
        pts = [Point3(x=float(q[0]), y=float(q[1]), z=float(q[2])) for _a, _b, pa, pb in edges for q in (pa, pb)]
        if pts:
            ents.append(
                SceneEntity(
                    timestamp=stamp,
                    frame_id="world",
                    id="edges",
                    lines=[LinePrimitive(type=LinePrimitiveLineType.LineList, pose=origin, thickness=2.0, scale_invariant=True, points=pts, color=Color(r=_EDGE[0], g=_EDGE[1], b=_EDGE[2], a=_EDGE[3]))],
                )
            )
        self.scene_ch.log(SceneUpdate(entities=ents), log_time=log_time)


class Views:
    """Derives the viewer channels from a run's messages (see the module docstring) and
    draws them on ``sink`` (:class:`FoxgloveSink`, :class:`zswarm.recording.rerun_view.RerunSink`)."""

    def __init__(self, sink: Sink, scenario: Scenario | None, rate: float = 50.0, scene_rate: float = 10.0) -> None:
        self.sink = sink
        self.period = 1.0 / rate
        self.scene_period = 1.0 / scene_rate
        self.sc = scenario
        self.edges: list[tuple[int, int]] = []
        if scenario is not None:
            self.edges = list(scenario.oriented) or [(a.id, j) for a in scenario.agents for j in (a.neighbors or a.senses)]
        pts = np.array([a.p for a in scenario.agents]) if scenario is not None and scenario.agents else np.zeros((1, 3))
        span = float(np.max(np.ptp(pts, axis=0))) if len(pts) > 1 else 1.0
        self.size = max(0.05, 0.06 * span)  # cube edge: 6 % of the team's initial extent
        self.truth: deque[tuple[float, dict[int, int], np.ndarray, np.ndarray, np.ndarray]] = deque(maxlen=TRUTH_KEEP)
        self.pending: deque[tuple[int, float, np.ndarray, np.ndarray, int]] = deque()
        self.newest: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # agent -> (R̃_i, p̃_i = R̃_i p̂_i − p_i)
        self.next_tf = -math.inf
        self.next_est_tf: dict[int, float] = {}
        self.next_cmd: dict[int, float] = {}
        self.next_scene = -math.inf
        self.next_edges = -math.inf
        # A synchronization law (its report family, SPEC.report, is "sync"): edges measured on the truth.
        self.sync = scenario is not None and scenario.info.report == "sync" and bool(scenario.oriented)

    # ------------------------------------------------------------------ inputs

    def on_message(self, stream: str, m: Mapping[str, Any], log_time: int) -> None:
        kind = m["type"]
        if kind == "truth":
            self._truth(m, log_time)
        elif kind == "est":
            self._est(m, log_time)
        elif kind == "stats":
            self._stats(m, log_time)
        elif kind == "cmd":
            self._cmd(m, log_time)

    def _truth(self, m: Mapping[str, Any], log_time: int) -> None:
        t = m["t"]
        ids = m["ids"]
        col = {i: k for k, i in enumerate(ids)}
        self.truth.append((t, col, m["R"], m["p"], m["w"]))
        if t >= self.next_tf:
            self.next_tf = t + self.period - 1e-9
            self.sink.frames(log_time, t, [(f"agent_{i}", m["p"][k], m["R"][k]) for i, k in col.items()])
        if t >= self.next_scene:
            self.next_scene = t + self.scene_period - 1e-9
            bodies = [(i, est) for i in col for est in ((False, True) if i in self.newest else (False,))]
            edges = [(a, b, m["p"][col[a]], m["p"][col[b]]) for a, b in self.edges if a in col and b in col]
            self.sink.scene(log_time, t, bodies, self.size, edges)
        while self.pending and self.pending[0][1] <= t:
            self._error(*self.pending.popleft())
        if self.sync and t >= self.next_edges:
            self.next_edges = t + self.period - 1e-9
            R = m["R"]
            for h, tl in self.edges:
                if h in col and tl in col:
                    Rbar = R[col[tl]].T @ R[col[h]]
                    self.sink.record(f"sync/edge/{h}_{tl}", SYNC_EDGE_SCHEMA, {"t": t, "head": h, "tail": tl, "attitude": so3.attitude_norm(Rbar)}, log_time)
            for i, k in col.items():
                self.sink.record(f"sync/{i}", SYNC_AGENT_SCHEMA, {"t": t, "omega": float(np.linalg.norm(m["w"][k]))}, log_time)
        elif self.edges and t >= self.next_edges and len(self.newest) > 0:
            self.next_edges = t + self.period - 1e-9
            for h, tl in self.edges:
                a, b = self.newest.get(h), self.newest.get(tl)
                if a is None or b is None:
                    continue
                Rbar = b[0].T @ a[0]
                self.sink.record(
                    f"errors/edge/{h}_{tl}",
                    EDGE_ERRORS_SCHEMA,
                    {"t": t, "head": h, "tail": tl, "attitude": so3.attitude_norm(Rbar), "position": float(np.linalg.norm(a[1] - b[1]))},
                    log_time,
                )

    def _est(self, m: Any, log_time: int) -> None:
        i, t = m["src"], m["t"]
        if "R_hat" in m and "p_hat" in m:
            if t >= self.next_est_tf.get(i, -math.inf):
                self.next_est_tf[i] = t + self.period - 1e-9
                self.sink.frames(log_time, t, [(f"agent_{i}_est", m["p_hat"], m["R_hat"])])
            item = (i, t, m["R_hat"], m["p_hat"], log_time)
            if self.truth and t <= self.truth[-1][0]:
                self._error(*item)
            else:
                self.pending.append(item)
                if len(self.pending) > 64 * max(1, len(self.newest)):
                    self.pending.popleft()  # no truth comes: keep the newest only
        # The numbers it reports (SPEC.estimate): per-edge ones as <name>_<k>, and the jumps of its
        # hybrid variables (SPEC.jumps).
        hybrid: dict[str, float] = {f"{name}_{k}": x for name, per in m.edges.items() for k, x in per.items()}
        hybrid |= {n: x for n, x in m.values.items() if isinstance(x, float)}
        if hybrid:
            self.sink.record(f"hybrid/{i}", HYBRID_SCHEMA, {"t": t, **hybrid}, log_time)
        for var, _owner, k, tj, before, after in m.jumps:
            self.sink.record("hybrid/jumps", JUMPS_SCHEMA, {"t": tj, "agent": i, "variable": var, "index": k, "before": before, "after": after}, log_time)

    def _error(self, i: int, t: float, R_hat: np.ndarray, p_hat: np.ndarray, log_time: int) -> None:
        # The truth sample before t, its attitude moved on with its ω, its position
        # interpolated to the next sample: as zswarm.report.decoded.estimates_with_truth.
        k = len(self.truth) - 1
        while k >= 0 and self.truth[k][0] > t:
            k -= 1
        if k < 0:
            return
        t0, col, R, p, w = self.truth[k]
        a = col.get(i)
        if a is None:
            return
        tau = t - t0
        # One estimate's products through so3 (compiled for one draw: this view is computed for
        # every estimate a recording holds, 12.7 -> 9.1 µs each hot, 2026-12-06); the report's stacked
        # products round otherwise by an ulp or so (test_recording_viewers holds them together).
        Ri = so3.mul(R[a], so3.exp(tau * w[a]))
        pi = p[a]
        if k + 1 < len(self.truth) and self.truth[k + 1][0] > t0:
            t1, col1, _, p1, _ = self.truth[k + 1]
            if i in col1:
                pi = pi + (tau / (t1 - t0)) * (p1[col1[i]] - pi)
        R_tilde = so3.mul(Ri, R_hat.T)
        Rp = so3.apply(R_tilde, p_hat)
        self.newest[i] = (R_tilde, Rp - pi)
        self.sink.record(
            f"errors/{i}",
            ERRORS_SCHEMA,
            {"t": t, "attitude": so3.attitude_norm(R_tilde), "position": math.hypot(*(pi - Rp).tolist()), "position_direct": math.hypot(*(pi - p_hat).tolist())},
            log_time,
        )

    def _stats(self, m: Mapping[str, Any], log_time: int) -> None:
        links = m["counters"].get("links") if isinstance(m["counters"], dict) else None
        if not isinstance(links, dict):
            return
        for name, c in links.items():
            if not (isinstance(name, str) and isinstance(c, dict)):
                continue
            src, _, dst = name.partition("->")
            if not dst:
                continue
            row = {k: v for k, v in c.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
            if not all(k in row for k in ("delivered", "dropped")):
                continue
            row = {k: (int(v) if k in ("delivered", "dropped", "reordered") else v) for k, v in row.items()}
            self.sink.record(f"links/{src}_to_{dst}", LINK_SCHEMA, {"t": m["t"], "link": name, **row}, log_time)

    def _cmd(self, m: Mapping[str, Any], log_time: int) -> None:
        i, t = m["src"], m["t"]
        if t < self.next_cmd.get(i, -math.inf):
            return
        self.next_cmd[i] = t + self.period - 1e-9
        row: dict[str, Any] = {"t": t}
        for name in m:
            if name in _CMD_HEADER:
                continue
            x = m[name]
            if isinstance(x, bool) or not isinstance(x, (int, float, np.ndarray)):
                continue
            x = np.atleast_1d(np.asarray(x, dtype=float)).ravel()
            if x.size == 1:
                row[name] = float(x[0])
            elif x.size <= 3:
                row |= {f"{name}_{c}": float(v) for c, v in zip("xyz", x, strict=False)}
                row[f"{name}_norm"] = float(np.linalg.norm(x))
        if len(row) > 1:
            self.sink.record(f"commands/{i}", COMMAND_SCHEMA, row, log_time)
