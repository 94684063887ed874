"""What the batched engine returns of M draws, and what a family's measure of them is built on.

The batched engine (``agent/batched.py``) steps M draws of one scenario together; a family's
measure (:class:`zswarm.families.contract.Batched`) watches them and fills a :class:`Result` with what
``zswarm basin`` and ``zswarm sweep`` read of each draw: its basin measure on a grid, and for
a sweep's rows its finals and its team measure on the report's 0.1 s grid.  The engine calls,
by the plant and the links:

* a truth per draw (rigid bodies): ``sample(k, t, truth)`` at every world sample, a
  :class:`Truth` (attitudes and angular velocities of every draw's bodies);
* a shared truth, every draw's agents ticking together: ``tick(truth, estimates)`` after each
  tick's publications (``truth.R`` (n, 3, 3), ``truth.p`` (n, 3); ``estimates[i][field]``
  with a leading draw axis) — :class:`Ticks` keeps what a report reads at those ticks;
* a shared truth, each draw's agents publishing at stamps of their own (lossy or jittery
  sensor links): ``tick(truths, published)`` with :class:`Published` per agent and the
  truth at each sample a stamp may name (:func:`truth_at`);

and at the end ``result(res) -> res``.  The helpers reproduce the report's arithmetic
(:func:`rounded`: the values as its CSVs hold them; :func:`mean_rows`, :func:`nanmean_of`:
its means over one run's values) so that a draw's row equals its run's on ``sim``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from zswarm.report.base import grid as coarse_grid
from zswarm.report.series import FINAL_WINDOW_S

__all__ = ["FINAL_WINDOW_S", "Context", "Published", "Result", "Ticks", "Truth", "coarse_grid", "mean_rows", "nanmean_of", "rounded", "truth_at"]


@dataclass(frozen=True)
class Context:
    """What a measure is built from: the scenario ``sc`` (every draw shares its schedule and
    graph), ``M`` draws, ``duration`` s of world time, the world's ``sample_dt`` and
    ``n_samples``, the agents' ticks every ``tick_every`` samples, the family's basin grid
    ``grid_s``, ``rows``: whether a sweep's rows are wanted too, and ``stamps``: with a
    sensor delay, the stamps of what the ticks publish (else every tick's own time)."""

    sc: Any
    M: int
    duration: float
    sample_dt: float
    n_samples: int
    tick_every: int
    grid_s: float
    rows: bool
    stamps: np.ndarray | None = None


@dataclass(frozen=True, slots=True)
class Truth:
    """Every draw's bodies at a world sample: ``R`` (M, n, 3, 3) attitudes, ``omega`` (M, n, 3)
    body-frame angular velocities (rad/s), n the scenario's agents in its order."""

    R: np.ndarray
    omega: np.ndarray


@dataclass
class Result:
    """What a basin or a sweep reads of M draws: the family's basin measure on its grid and
    the engine's counts.  The measure sets ``t``, ``max_rel`` (or ``draw_grid``) and, for a
    sweep's rows, ``final_att``, ``final_pos``, ``t_coarse``, ``att_coarse``, ``pos_coarse``
    and any values of its own columns in ``extra``."""

    t: np.ndarray  # (T,) world times of the grid
    max_rel: np.ndarray  # (M, T) the basin measure
    jumps: np.ndarray  # (M,) ξ_k jumps of every edge
    agent_jumps: np.ndarray  # (M,) jumps of the agents' own hybrid variables
    steps: int  # agent steps taken (per draw)
    # For a sweep's rows (run(rows=True)): what zswarm.studies.sweep reads of a sim run's files.
    final_att: np.ndarray | None = None  # (M,) summary.json's mean_attitude_error_final (the family's)
    final_pos: np.ndarray | None = None  # (M,) its mean_position_error_final (NaN: none)
    t_coarse: np.ndarray | None = None  # the report's 0.1 s grid up to the duration (zswarm.report.base.grid)
    att_coarse: np.ndarray | None = None  # (M, len(t_coarse)) the family's team attitude measure on it, from its CSV's %.6e values
    pos_coarse: np.ndarray | None = None  # (M, len(t_coarse)) the same of positions (None: the family has none)
    edge_messages: int = 0  # agent -> agent messages sent (each delivered: lockstep), per draw
    commands: int = 0  # commands sent to the world, per draw
    command_links: Any = None  # emulated command links (agent.batched_links.Commands): their counters per draw (None: perfect, none lost, late or expired)
    edge_links: Any = None  # emulated agent→agent links (batched_links.Edges or DrawInbox): their counters per draw (link_counters, stale_terms; None: perfect)
    t_end: float = 0.0  # the last sample's time: what a link released by then was delivered
    # Sensor links with jitter or loss: per draw, what its agents sent (they idle in some draws
    # and not in others), its lost sensor packets and its stale reads.
    draw_edge_messages: np.ndarray | None = None
    draw_commands: np.ndarray | None = None
    sensor_dropped: np.ndarray | None = None
    stale_terms: np.ndarray | None = None
    # On a prescribed truth with such links: each draw's basin measure on a grid of its own (t, v).
    draw_grid: list[tuple[np.ndarray, np.ndarray]] | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)  # (M,) values a family's measure adds for its sweep columns

    def series(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Draw ``n``'s basin measure and the times of its grid."""
        if self.draw_grid is not None:
            return self.draw_grid[n]
        return self.t, self.max_rel[n]


class Ticks:
    """A shared truth's measure of the estimates at the agents' ticks (lockstep: every agent
    ticks at ``k · tick_every`` samples).  The sweep rows read it where the report reads its
    CSV on the 0.1 s grid and over the last second, so only those ticks are kept: a subclass
    sets ``keep`` (tick indexes) and gives :meth:`measure`."""

    def __init__(self, ctx: Context) -> None:
        self.sc, self.M, self.duration, self.grid_s, self.rows = ctx.sc, ctx.M, ctx.duration, ctx.grid_s, ctx.rows
        # The estimates' stamps: k · sample_dt at every tick, as the loop computes them; with a
        # sensor delay the packet times the ticks that publish stepped to (Context.stamps).
        self.t_ticks = np.arange(0, ctx.n_samples, ctx.tick_every) * ctx.sample_dt if ctx.stamps is None else ctx.stamps
        self.n = 0  # ticks seen
        self.basin: list[np.ndarray] = []  # the basin measure (M,) at every tick
        self.kept: dict[int, Any] = {}  # tick index -> what the rows read there
        self.keep: set[int] = set()

    def tick(self, truth: Any, estimates: Mapping[int, Mapping[str, Any]]) -> None:
        basin, kept = self.measure(truth, estimates, self.n in self.keep)
        self.basin.append(basin)
        if kept is not None:
            self.kept[self.n] = kept
        self.n += 1

    def measure(self, truth: Any, estimates: Mapping[int, Mapping[str, Any]], keep: bool) -> tuple[np.ndarray, Any]:
        """The basin measure (M,) at this tick, and (``keep``) what the rows read here."""
        raise NotImplementedError

    def basin_series(self, res: Result) -> Result:
        """The basin measure held on the family's grid (the newest tick at or before each point)."""
        tk = self.t_ticks[: self.n]
        if not len(tk):
            res.t, res.max_rel = np.zeros(0), np.zeros((self.M, 0))
            return res
        res.t = np.arange(tk[0], tk[-1] + 1e-9, self.grid_s)
        res.max_rel = np.array(self.basin)[np.searchsorted(tk, res.t, side="right") - 1].T
        return res

    def result(self, res: Result) -> Result:
        return self.basin_series(res)


class Published:
    """One agent's estimates of one tick, per draw: ``mask`` (M,) the draws that published,
    ``stamp`` (M,) their stamps (world time of the packet stepped to) and the estimate fields a
    measure reads (``shapes``: name -> shape of one draw's value), each with a leading draw axis
    (valid where ``mask``; zeros where a draw's estimate lacks it)."""

    __slots__ = ("mask", "stamp", "values")

    def __init__(self, M: int, shapes: Mapping[str, tuple[int, ...]]) -> None:
        self.mask = np.zeros(M, dtype=bool)
        self.stamp = np.full(M, np.nan)
        self.values = {f: np.zeros((M, *s)) for f, s in shapes.items()}

    def put(self, idx: np.ndarray, stamp: float, estimate: Mapping[str, Any], m: int) -> None:
        """The draws ``idx`` (the first len(idx) of a sub-stack of ``m`` rows) published
        ``estimate`` stamped ``stamp`` (a value with the sub-stack's axis, or one for all)."""
        if not any(f in estimate for f in self.values):
            return
        n = len(idx)
        self.mask[idx], self.stamp[idx] = True, stamp
        for f, store in self.values.items():
            if f in estimate:
                store[idx] = np.broadcast_to(np.asarray(estimate[f], dtype=float), (m, *store.shape[1:]))[:n]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.values[name]


Truths = Mapping[int, tuple[np.ndarray, np.ndarray]]  # sample -> the truth's (R (n, 3, 3), p (n, 3)) there


def truth_at(truths: Truths, stamps: np.ndarray, sample_dt: float, a: int) -> tuple[np.ndarray, np.ndarray]:
    """Body ``a``'s truth (R (len, 3, 3), p (len, 3)) at each stamp: a stamp is a sample's time
    (k · sample_dt, as the world computes it), so the truth sample there, as the report takes
    it (estimates_with_truth: the sample before moved on by 0 s)."""
    k = np.rint(stamps / sample_dt).astype(np.int64)
    uniq, inv = np.unique(k, return_inverse=True)
    R = np.stack([truths[int(q)][0][a] for q in uniq])[inv.reshape(-1)]
    p = np.stack([truths[int(q)][1][a] for q in uniq])[inv.reshape(-1)]
    return R, p


def rounded(x: np.ndarray, fmt: str) -> np.ndarray:
    """The values as a CSV of the report holds them (``fmt``: "%.6e", "%.6f", "%.3f")."""
    return np.array(np.char.mod(fmt, x), dtype=float)


def mean_rows(x: np.ndarray) -> np.ndarray:
    """np.mean of each row of (M, K) as of a 1-D array of its K values (the same sum: a
    contiguous row), the way the report averages one run's values over its last second."""
    out: np.ndarray = np.ascontiguousarray(x).mean(axis=1)
    return out


def nanmean_of(values: Sequence[np.ndarray]) -> np.ndarray:
    """zswarm.report.series.nanmean per draw (the mean of the finite values; NaN where none)."""
    x = np.array(values).T  # (M, F)
    fine = np.all(np.isfinite(x), axis=1)
    out = mean_rows(x)
    for m in np.flatnonzero(~fine):
        v = x[m][np.isfinite(x[m])]
        out[m] = float(np.mean(v)) if len(v) else np.nan
    return out
