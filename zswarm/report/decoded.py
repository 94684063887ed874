"""A run's recording as the report reads it: :class:`Recording` (decoded, filed under each
message's key), the per-agent estimate errors against the truth, and where the truth has gaps.

Errors are those of the thesis figures: attitude error ``|R̃_i|_I`` with
``R̃_i = R_i R̂_i^T``, and position error ``‖p̃_i‖`` with ``p̃_i = p_i − R̃_i p̂_i``
((3.15), (3.26); §3, Figs. 3.4–3.17) — which is 6.0 at t = 0 in §3.2.5, where
the direct ``‖p_i − p̂_i‖`` (kept as ``position_error_direct``) is 4.85; the two
agree once the attitude has converged.  Both are evaluated at each
estimate's world time against the truth at that same time (the attitude of
the truth sample before it, propagated with the true ω over the
< 1/sensor_rate gap: error O(ω̇ Δt²) ≈ 3e-5 rad; positions interpolated
linearly between samples).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from zswarm.math import so3
from zswarm.recording.mcap_io import ALIVE_CHANNEL, LOST_CHANNEL, MALFORMED_CHANNEL, decode, read, unpack
from zswarm.recording.mcap_read import Lost
from zswarm.transport import run_control, wire


class NoTruth(ValueError):
    """A recording without one ground-truth message: nothing to report on (a recorder stopped
    before the world's first message reached it, or a file cut short before it)."""


@dataclass
class Recording:
    """What the report needs, decoded from a recording."""

    truth_t: np.ndarray
    truth_ids: list[int]
    truth_R: np.ndarray  # (T, n, 3, 3)
    truth_p: np.ndarray  # (T, n, 3)
    truth_w: np.ndarray  # (T, n, 3)
    est: dict[int, list[tuple[float, np.ndarray, np.ndarray]]]
    stats: dict[tuple[str, int], dict[str, Any]]
    alive_events: list[dict[str, Any]]
    start: dict[str, Any] | None
    stop_seen: bool
    counts: dict[str, int] = field(default_factory=dict)
    streams: dict[str, int] = field(default_factory=dict)  # messages recorded per channel (est/3, edge/1/3, ...)
    malformed: int = 0
    # The per-edge values the estimates report (SPEC.estimate's "edges" outputs): name -> edge k ->
    # (t, value) as its head reports it, e.g. edge_values["xi"][k] = [(t, ξ_k), ...].
    edge_values: dict[str, dict[int, list[tuple[float, float]]]] = field(default_factory=dict)
    jumps: list[tuple[int, float, float, float]] = field(default_factory=list)  # jumps of an edge's variable (SPEC.jumps): (k, t, before, after)
    agent_jumps: list[tuple[int, float, float, float]] = field(default_factory=list)  # jumps of an agent's own: (agent, t, before, after)
    extra: dict[int, list[tuple[float, dict[str, Any]]]] = field(default_factory=dict)  # agent -> (t, named values)
    truth_tau: np.ndarray | None = None  # (T, n, 3): the torques the plant applied (rigid bodies)
    stats_by_inc: dict[tuple[str, int, int], dict[str, Any]] = field(default_factory=dict)  # (role, src, incarnation): its last stats
    envelopes: dict[str, list[tuple[float, int, int]]] = field(default_factory=dict)  # stream -> (t, inc, seq) per message, when asked
    outside_run: dict[str, int] = field(default_factory=dict)  # stream kind -> messages stamped outside the run (ignored)
    lost: list[str] = field(default_factory=list)  # the file's damage, a line each (zswarm.recording.mcap_read.Lost.text)


# A message stamped more than this outside [0, duration] of world time is not the run's: it
# is counted (summary.json "recording.outside_run") and ignored.  Every process stamps world
# time, and the last ones come at most a tick after the world's stop (an agent's step at
# 100 Hz, stats within a second); one estimate stamped t = 1e12 made the report build a
# 10 ms grid to that time (MemoryError: 728 TiB) or became the "final" error.
OUTSIDE_RUN_MARGIN_S = 1.0
# No error is computed where the truth has a gap longer than TRUTH_GAP_S or this many of its
# median sample periods, whichever is longer: the attitude there would be the sample before
# propagated with its ω over the gap, error ½|ω̇|τ² (0.2 rad over 0.3 s at the §3.2
# |ω̇| ≤ 5 rad/s²), and a recorder stopped for 3 s made errors.csv read 0.91 where the real
# error was 0.01.  Estimates in a gap (or after the last sample by more than it) get NaN;
# the gaps are in summary.json "recording.truth_gaps".  A run on a loaded machine has short
# gaps of its own, which must not blank its errors (a NaN at a grid point also counts as
# not converged): a world woken late takes the samples it missed, up to 0.1 s behind
# (world.CATCH_UP_S), and skips to the newest due sample past that.
# Across 0.1 s the propagation errs by at most 0.025 rad on §3.2.
TRUTH_GAP_S = 0.1
TRUTH_GAP_PERIODS = 4.0


def load_recording(path: Path | Iterable[tuple[str, Any, int]], envelopes: bool = False, duration: float | None = None, source: str | None = None) -> Recording:
    """Decode a recording file, or the messages of an in-memory recording; with ``envelopes``,
    also every message's ``(t, inc, seq)`` per stream (the loss a fault caused).

    A message is filed under the process of its key (wire.check_stream); with ``duration``
    (else the run's ``ctl/start``, if it comes first), truth, estimates and stats stamped
    more than OUTSIDE_RUN_MARGIN_S outside ``[0, duration]`` are counted and ignored.
    ``source``: the file that messages are (or will be) in, for what is said of them."""
    truth: list[dict[str, Any]] = []
    est: dict[int, list[tuple[float, np.ndarray, np.ndarray]]] = defaultdict(list)
    edge_values: dict[str, dict[int, list[tuple[float, float]]]] = {}
    jumps: list[tuple[int, float, float, float]] = []
    agent_jumps: list[tuple[int, float, float, float]] = []
    extra: dict[int, list[tuple[float, dict[str, Any]]]] = defaultdict(list)
    stats: dict[tuple[str, int], dict[str, Any]] = {}
    alive: list[dict[str, Any]] = []
    start = None
    stop_seen = False
    counts: dict[str, int] = defaultdict(int)
    streams: dict[str, int] = defaultdict(int)
    malformed = 0
    env: dict[str, list[tuple[float, int, int]]] = defaultdict(list)
    by_inc: dict[tuple[str, int, int], dict[str, Any]] = {}
    outside: dict[str, int] = defaultdict(int)
    t_lo, t_hi = -OUTSIDE_RUN_MARGIN_S, (math.inf if duration is None else duration + OUTSIDE_RUN_MARGIN_S)
    losses: list[Lost] = []
    lost_texts: list[str] = []
    for topic, payload, _t in read(path, losses) if isinstance(path, (str, Path)) else path:
        counts[topic.split("/")[0]] += 1
        streams[topic] += 1
        if topic == ALIVE_CHANNEL:
            alive.append({**unpack(payload), "log_t": _t})
            continue
        if topic == LOST_CHANNEL:  # what the transcode could not read of the raw recording
            lost_texts.append(str(payload.get("text", "") if isinstance(payload, dict) else "a loss not described")[:400])
            continue
        if topic == MALFORMED_CHANNEL:  # what the recorder (or the transcode) dropped as malformed
            n = payload.get("count", 1) if isinstance(payload, dict) else 1  # described, or counted on a key
            malformed += n if isinstance(n, int) and not isinstance(n, bool) and 0 < n < 2**53 else 1
            continue
        kind = topic.split("/")[0]
        if envelopes and kind != "events":
            try:
                e = msgpack.unpackb(payload, raw=False, strict_map_key=False) if isinstance(payload, bytes) else payload
                if isinstance(e, dict):  # JSON or msgpack: both leave out the incarnation at its default, 0
                    env[topic].append((float(e["t"]), int(e.get("inc", 0)), int(e["seq"])))
                else:  # a decoded message (sim's, the run report's read in the transcode's pass)
                    env[topic].append((float(e.t), int(e.inc), int(e.seq)))
            except Exception:  # noqa: BLE001, S110 - malformed: counted where it is decoded
                pass
        if kind not in ("truth", "est", "stats", "ctl"):
            continue
        try:
            m = decode(payload)
            wire.check_stream(topic, m)  # est/i is agent i's, whatever src it claims (counted malformed)
            if kind == "ctl":
                run_control.check_signature(m)  # the world's, signed when the run has a secret
        except wire.MessageError:
            malformed += 1
            counts[kind] -= 1  # not a message of this stream: not counted as recorded on it
            streams[topic] -= 1
            continue
        if kind != "ctl" and not t_lo <= m["t"] <= t_hi:
            outside[kind] += 1
            continue
        if m["type"] == "truth" and kind == "truth":
            truth.append(m)
        elif m["type"] == "est" and kind == "est":
            if "R_hat" in m and "p_hat" in m:
                est[m["src"]].append((m["t"], m["R_hat"], m["p_hat"]))
            for name, per in m.edges.items():
                by_k = edge_values.setdefault(name, defaultdict(list))
                for k, x in per.items():
                    by_k[k].append((m.t, x))
            for _var, owner, k, t, before, after in m.jumps:
                (jumps if owner == "edge" else agent_jumps).append((k, t, before, after))
            if m.values:
                extra[m.src].append((m.t, m.values))
        elif m["type"] == "stats" and kind == "stats":
            role = m["role"]
            prev = stats.get((role, m["src"]))
            # Keep the final stats if any, else the newest.
            if prev is None or not prev.get("final") or m["counters"].get("final"):
                stats[(role, m["src"])] = {**m["counters"], "t": m["t"], "seq": m["seq"]}
            prev = by_inc.get((role, m["src"], m["inc"]))
            if prev is None or not prev.get("final") or m["counters"].get("final"):
                by_inc[(role, m["src"], m["inc"])] = {**m["counters"], "t": m["t"], "seq": m["seq"]}
        elif m["type"] == "start":
            start = m
            if duration is None:
                t_hi = m["duration"] + OUTSIDE_RUN_MARGIN_S
        elif m["type"] == "stop":
            stop_seen = True
    if not truth:
        raise NoTruth(f"{path if isinstance(path, (str, Path)) else source or 'recording'}: the recording holds no ground truth")
    truth.sort(key=lambda m: m["t"])
    ids = truth[0]["ids"]
    return Recording(
        truth_t=np.array([m["t"] for m in truth]),
        truth_ids=ids,
        truth_R=np.array([m["R"] for m in truth]),
        truth_p=np.array([m["p"] for m in truth]),
        truth_w=np.array([m["w"] for m in truth]),
        est={i: sorted(v, key=lambda e: e[0]) for i, v in est.items()},
        stats=stats,
        alive_events=alive,
        start=start,
        stop_seen=stop_seen,
        lost=lost_texts + [x.text() for x in losses],
        counts=dict(counts),
        streams=dict(streams),
        malformed=malformed,
        edge_values={name: {k: sorted(v) for k, v in sorted(per.items())} for name, per in sorted(edge_values.items())},
        jumps=sorted(jumps, key=lambda j: (j[1], j[0])),
        agent_jumps=sorted(agent_jumps, key=lambda j: (j[1], j[0])),
        extra={i: sorted(v, key=lambda e: e[0]) for i, v in sorted(extra.items())},
        truth_tau=np.array([m["tau"] for m in truth]) if all("tau" in m for m in truth) else None,
        stats_by_inc=by_inc,
        envelopes=dict(env),
        outside_run=dict(outside),
    )


def errors(rec: Recording) -> dict[int, np.ndarray]:
    """Per agent an array of rows ``(t, |R̃_i|_I, ‖p̃_i‖, ‖p_i − p̂_i‖)``, p̃_i = p_i − R̃_i p̂_i (3.15)."""
    out: dict[int, np.ndarray] = {}
    col = {i: k for k, i in enumerate(rec.truth_ids)}
    for i, samples in rec.est.items():
        if i not in col:
            continue
        t, R_hat, p_hat, R, p = estimates_with_truth(rec, samples, col[i])
        tr = np.einsum("nij,nij->n", R, R_hat)  # tr(R R̂^T)
        att = np.sqrt(np.clip((3.0 - tr) * 0.25, 0.0, 1.0))
        R_tilde_p_hat = np.einsum("nij,nkj,nk->ni", R, R_hat, p_hat)  # R R̂^T p̂
        out[i] = np.column_stack((t, att, np.linalg.norm(p - R_tilde_p_hat, axis=1), np.linalg.norm(p - p_hat, axis=1)))
    return out


def estimates_with_truth(
    rec: Recording, samples: list[tuple[float, np.ndarray, np.ndarray]], a: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(t, R̂, p̂, R, p)`` of an agent's estimates from the first truth sample on, with
    the truth of column ``a`` at each estimate's time: the attitude of the sample
    before ``t`` moved on with its ω, the position interpolated linearly (positions
    move slowly, < 2 m/s in the papers' scenarios)."""
    T = rec.truth_t
    t = np.array([s[0] for s in samples], dtype=float).reshape(-1)
    k = np.searchsorted(T, t, side="right") - 1
    ok = k >= 0
    t, k = t[ok], k[ok]
    R_hat = np.array([s[1] for s, o in zip(samples, ok, strict=True) if o]).reshape(-1, 3, 3)
    p_hat = np.array([s[2] for s, o in zip(samples, ok, strict=True) if o]).reshape(-1, 3)
    tau = t - T[k]
    R = rec.truth_R[k, a] @ so3.exp_batch(tau[:, None] * rec.truth_w[k, a]) if len(t) else np.zeros((0, 3, 3))
    k1 = np.minimum(k + 1, len(T) - 1)
    span = T[k1] - T[k]
    frac = np.where(k1 > k, tau / np.where(span > 0, span, 1.0), 0.0)
    p = (1 - frac)[:, None] * rec.truth_p[k, a] + frac[:, None] * rec.truth_p[k1, a]
    # In a truth gap, or past the last sample by more than the bound: no truth to compare with.
    bound = truth_gap_bound(T)
    blind = np.where(k1 > k, (span > bound) & (tau > 0), tau > bound)
    if np.any(blind):
        R, p = R.copy(), p.copy()
        R[blind], p[blind] = np.nan, np.nan
    return t, R_hat, p_hat, R, p


def truth_gap_bound(T: np.ndarray) -> float:
    """The longest interval between truth samples (s) across which errors are computed."""
    if len(T) < 2:
        return math.inf
    return max(TRUTH_GAP_S, TRUTH_GAP_PERIODS * float(np.median(np.diff(T))))


def truth_gaps(rec: Recording, duration: float, most: int = 50) -> dict[str, Any]:
    """The truth's gaps longer than :func:`truth_gap_bound` within the run, where no error is
    computed (summary.json ``recording.truth_gaps``); the recording's end counts when it
    stops short of the run's end (a recorder that died, a run stopped early)."""
    T = rec.truth_t
    bound = truth_gap_bound(T)
    spans = [(float(a), float(b)) for a, b in zip(T[:-1], T[1:], strict=True) if b - a > bound]
    if len(T) and duration - T[-1] > bound:
        spans.append((float(T[-1]), float(duration)))
    return {
        "bound_s": round(bound, 6) if math.isfinite(bound) else None,
        "count": len(spans),
        "total_s": round(sum(b - a for a, b in spans), 6),
        "spans": [[round(a, 6), round(b, 6)] for a, b in spans[:most]],
    }
