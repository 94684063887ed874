"""A prescribed truth's measures of the estimates when each draw's agents publish at stamps of
their own (agent/batched.py: sensor links with jitter, loss or cuts on the §3 and §4.5 observers).

On ``sim`` the report measures every estimate a run's agents published on the truth at the
estimate's stamp (zswarm.report.recording.estimates_with_truth: a stamp is a sensor packet's
time, so the truth sample there) and then holds each agent's newest estimate on a grid.  With
lossy or jittery sensor links the draws of a batch publish at ticks and stamps of their own:
an agent that heard nothing new at a tick publishes nothing, a late packet stamps an older
time.  These classes take each tick's estimates per draw (:class:`Published`) and build what
the report builds of a recording, draw by draw, without keeping every estimate: the
leader–follower rows (:class:`FollowerErrors`: zswarm.report.base.series and the finals of
pipeline.final_mean) and the tree family's 100 Hz grid (:class:`TreeErrors`:
zswarm.report.families.tree.tree_metrics, its basin series, edges.csv's 0.1 s points and the
agents' errors up to their chordal mean over the last second).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from zswarm.report.base import grid as coarse_grid
from zswarm.report.families.tree import BASIN_GRID_S, nearest_rotations
from zswarm.report.series import FINAL_WINDOW_S


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


@dataclass(slots=True)
class Published:
    """One agent's estimates of one tick, per draw: ``mask`` (M,) the draws that published,
    ``stamp`` (M,) their stamps (world time of the packet stepped to), ``R_hat`` (M, 3, 3) and
    ``p_hat`` (M, 3) (valid where ``mask``)."""

    mask: np.ndarray
    stamp: np.ndarray
    R_hat: np.ndarray
    p_hat: np.ndarray


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


class FollowerErrors:
    """The leader–follower family's rows (zswarm.report.base): each follower's |R̃_i|_I and
    ||p̃_i|| (3.15) at each of its estimates, held on the 0.1 s grid at the newest estimate
    whose errors.csv time (%.6f) is at or before each point (%.6e values; the mean over the
    followers, NaN until each has one), and the finals: per follower the mean over its
    estimates stamped in the last second, then over the followers.  Streams: an estimate's
    values go to the grid points before the next one's time when that one comes."""

    def __init__(self, sc: Any, M: int, duration: float, sample_dt: float, rows: bool) -> None:
        self.followers = [(i, a) for a, i in enumerate(sc.ids) if sc.agent(i).role == "follower"]
        F = len(self.followers)
        self.M, self.duration, self.sample_dt, self.rows = M, duration, sample_dt, rows
        self.coarse_t = coarse_grid(duration)
        self.lim = self.coarse_t + 1e-9  # base.series: searchsorted(t, grid + 1e-9, "right") − 1
        self.coarse = np.full((2, F, M, len(self.coarse_t)), np.nan)
        self.prev = np.full((2, F, M), np.nan)  # each follower's newest estimate's rounded errors, per draw
        self.j_prev = np.full((F, M), -1, dtype=np.int64)  # the first grid point it holds (−1: none yet)
        self.final: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []  # (follower, draws, |R̃|, ||p̃||) stamped in the last second

    def tick(self, truths: Truths, est: Mapping[int, Published]) -> None:
        for f, (i, a) in enumerate(self.followers):
            e = est.get(i)
            if e is None or not e.mask.any():
                continue
            idx = np.flatnonzero(e.mask)
            s = e.stamp[idx]
            R, p = truth_at(truths, s, self.sample_dt, a)
            R_hat, p_hat = e.R_hat[idx], e.p_hat[idx]
            tr = np.einsum("nij,nij->n", R, R_hat)  # recording.errors: tr(R R̂^T)
            att = np.sqrt(np.clip((3.0 - tr) * 0.25, 0.0, 1.0))
            pos = np.linalg.norm(p - np.einsum("nij,nkj,nk->ni", R, R_hat, p_hat), axis=1)
            late = s >= self.duration - FINAL_WINDOW_S  # pipeline.final_mean's window (t_end: the duration)
            if late.any():
                self.final.append((f, idx[late], att[late], pos[late]))
            if not self.rows:
                continue
            # The points before this estimate's time hold the previous one (those from it on, this one until the next)
            j_new = np.searchsorted(self.lim, rounded(s, "%.6f"), side="left")
            j_old = self.j_prev[f, idx]
            for c in range(int(np.max(j_new - np.maximum(j_old, 0), initial=0))):
                j = j_old + c
                ok = (j_old >= 0) & (j < j_new)
                self.coarse[:, f, idx[ok], j[ok]] = self.prev[:, f, idx[ok]]
            self.j_prev[f, idx] = j_new
            self.prev[0, f, idx], self.prev[1, f, idx] = rounded(att, "%.6e"), rounded(pos, "%.6e")

    def result(self, res: Any) -> Any:
        F, M = len(self.followers), self.M
        res.t, res.max_rel = np.zeros(0), np.zeros((M, 0))  # no basin measure (the family has none)
        if not self.rows:
            return res
        for f in range(F):  # the newest estimate holds to the end of the grid
            for m in np.flatnonzero(self.j_prev[f] >= 0):
                self.coarse[:, f, m, self.j_prev[f, m] :] = self.prev[:, f, m, None]
        per: list[list[np.ndarray]] = [[np.full(M, np.nan) for _ in range(F)] for _ in (0, 1)]
        if self.final:
            fs = np.concatenate([np.full(len(d), f) for f, d, _, _ in self.final])
            ms = np.concatenate([d for _, d, _, _ in self.final])
            vals = [np.concatenate([x[c + 2] for x in self.final]) for c in (0, 1)]
            order = np.lexsort((ms, fs))  # stable: each (follower, draw)'s estimates in stamp order
            keys = fs[order] * M + ms[order]
            cuts = np.flatnonzero(np.diff(keys)) + 1
            for g in np.split(np.arange(len(order)), cuts):
                fo, mo = divmod(int(keys[g[0]]), M)
                for c in (0, 1):
                    per[c][fo][mo] = np.mean(vals[c][order[g]])  # series.final: the mean over the window
        res.final_att, res.final_pos = (nanmean_of(per[c]) if F else np.full(M, np.nan) for c in (0, 1))
        res.t_coarse = self.coarse_t
        res.att_coarse, res.pos_coarse = (np.mean(self.coarse[c], axis=0) for c in (0, 1))
        return res


class TreeErrors:
    """The tree family (zswarm.report.families.tree.tree_metrics) per draw: R̃_i = R_i R̂_i^T of
    each agent's estimates at their stamps, each agent's newest at or before each point of the
    draw's own 100 Hz grid (from the latest first estimate of the agents to the latest
    estimate: np.arange(t0, t1 + 1e-9, 0.01)), per edge |R̄_k|_I = |R̃_t^T R̃_h|_I there.

    A grid point is final once every agent has an estimate stamped at or after it (a later one
    is stamped later still); each agent keeps its estimates since the oldest point not final
    (a ring per agent, grown when an agent runs ahead).  The basin measure is the max over the
    edges at every point; for a sweep's rows, edges.csv's 0.1 s points (%.3f times, %.6e values,
    the mean over edges) and each agent's |R̃_i R̃_c^T|_I up to their chordal mean R̃_c at the
    points of the last second (tree.summary's finals, the mean over followers)."""

    def __init__(self, sc: Any, M: int, duration: float, sample_dt: float, rows: bool) -> None:
        self.sc, self.M, self.duration, self.sample_dt, self.rows = sc, M, duration, sample_dt, rows
        self.ids = list(sc.ids)
        self.col = {i: a for a, i in enumerate(self.ids)}
        self.edges = [(self.ids.index(h), self.ids.index(t)) for h, t in sc.oriented]
        n = len(self.ids)
        self.K = 16
        self.ring_s = np.full((n, self.K, M), np.nan)  # per agent: its estimates' stamps ...
        self.ring_R = np.zeros((n, self.K, M, 3, 3))  # ... and R̃ = R R̂^T, at slot count % K
        self.count = np.zeros((n, M), dtype=np.int64)
        self.first = np.full((n, M), np.nan)
        self.last = np.full((n, M), np.nan)
        self.L = len(np.arange(0.0, duration + 1e-9, BASIN_GRID_S)) + 1  # the most points a draw's grid has
        self.G = np.full((M, self.L), np.inf)  # each draw's grid, once its t0 is known
        self.t0 = np.full(M, np.nan)
        self.next = np.zeros(M, dtype=np.int64)  # the first point not final
        self.V = np.full((M, self.L), np.nan)  # the basin measure at the final points
        self.coarse_t = coarse_grid(duration)
        self.need = np.zeros((M, len(self.coarse_t)), dtype=np.int64)  # per draw, the grid point each 0.1 s point reads (edges_on_grid)
        self.coarse = np.full((M, len(self.coarse_t)), np.nan)
        self.final: list[tuple[np.ndarray, np.ndarray]] = []  # (draws, |R̃_i R̃_c^T|_I (n, len)) at the points of the last second
        self.last_rel = np.full((len(self.edges), M), np.nan)  # the edges at each draw's latest final point

    def tick(self, truths: Truths, est: Mapping[int, Published]) -> None:
        for i, e in est.items():
            if not e.mask.any():
                continue
            q = self.col[i]
            idx = np.flatnonzero(e.mask)
            s = e.stamp[idx]
            R, _ = truth_at(truths, s, self.sample_dt, q)
            self._keep(q, idx, s, R @ e.R_hat[idx].transpose(0, 2, 1))  # tree_metrics: R̃ = R R̂^T
        fresh = np.isnan(self.t0) & np.all(np.isfinite(self.first), axis=0)
        for m in np.flatnonzero(fresh):  # every agent has an estimate: the draw's grid begins
            self.t0[m] = t0 = float(np.max(self.first[:, m]))
            g = np.arange(t0, self.duration + 1e-9, BASIN_GRID_S)  # a prefix of np.arange(t0, t1 + 1e-9, 0.01) for any t1 ≤ duration
            self.G[m, : len(g)] = g
            if self.rows:
                self.need[m] = np.maximum(np.searchsorted(rounded(g, "%.3f"), self.coarse_t, side="right") - 1, 0)
        self._settle(np.min(self.last, axis=0))  # NaN (an agent with no estimate yet) compares False

    def _keep(self, q: int, idx: np.ndarray, s: np.ndarray, Rt: np.ndarray) -> None:
        """Agent q's new estimates in the draws ``idx``; the ring grows first when the slot they
        take holds an estimate some point not yet final may read."""
        c = self.count[q, idx]
        if np.any(c >= self.K):
            nxt = self.ring_s[q, (c + 1) % self.K, idx]  # the estimate after the one overwritten
            pending = np.where(np.isnan(self.t0[idx]), -np.inf, self.G[idx, np.minimum(self.next[idx], self.L - 1)])
            if np.any((c >= self.K) & ~(nxt <= pending)):  # it is the newest at or before that point, or may be
                self._grow()
        slot = c % self.K
        self.ring_s[q, slot, idx] = s
        self.ring_R[q, slot, idx] = Rt
        self.count[q, idx] += 1
        self.first[q, idx] = np.where(np.isnan(self.first[q, idx]), s, self.first[q, idx])
        self.last[q, idx] = s

    def _grow(self) -> None:
        K, K2 = self.K, 2 * self.K
        n, M = self.count.shape
        s2, R2 = np.full((n, K2, M), np.nan), np.zeros((n, K2, M, 3, 3))
        for q in range(n):
            c = self.count[q][None, :] - K + np.arange(K)[:, None]  # (K, M) each draw's last K estimates
            ok = c >= 0
            cols = np.broadcast_to(np.arange(M), c.shape)
            s2[q, c[ok] % K2, cols[ok]] = self.ring_s[q, c[ok] % K, cols[ok]]
            R2[q, c[ok] % K2, cols[ok]] = self.ring_R[q, c[ok] % K, cols[ok]]
        self.ring_s, self.ring_R, self.K = s2, R2, K2

    def _settle(self, upto: np.ndarray, ends: np.ndarray | None = None) -> None:
        """Compute the points at or before ``upto`` (M,) of the draws whose grid has begun (up
        to ``ends`` (M,) points: the grid's length at the end of the run)."""
        live = np.isfinite(self.t0)
        while True:
            j = self.next
            g = self.G[np.arange(self.M), np.minimum(j, self.L - 1)]
            go = live & (j < self.L) & (g <= upto)
            if ends is not None:
                go &= j < ends
            if not go.any():
                return
            D = np.flatnonzero(go)
            self._point(D, j[D], g[D])
            self.next[D] += 1

    def _point(self, D: np.ndarray, j: np.ndarray, g: np.ndarray) -> None:
        """Grid point ``j`` (at ``g``) of the draws ``D``: each agent's newest estimate at or before it."""
        Rg = []
        for q in range(len(self.ids)):
            S = self.ring_s[q][:, D]  # (K, len(D))
            best = np.where(S <= g, S, -np.inf)
            slot = np.argmax(best, axis=0)
            if np.any(~np.isfinite(best[slot, np.arange(len(D))])):
                raise RuntimeError("the batched engine lost an estimate a grid point reads (TreeErrors' ring)")
            Rg.append(self.ring_R[q][slot, D])
        rel = []
        for h, tl in self.edges:
            Rbar = np.einsum("tji,tjk->tik", Rg[tl], Rg[h])
            rel.append(np.sqrt(np.clip((3.0 - np.trace(Rbar, axis1=1, axis2=2)) / 4.0, 0.0, 1.0)))
        self.V[D, j] = np.max(rel, axis=0) if rel else 0.0
        if not self.rows:
            return
        if rel:
            self.last_rel[:, D] = rel
        hit = self.need[D] == j[:, None]  # (len(D), C): the 0.1 s points that read this one
        if hit.any():
            mean = np.mean([rounded(r, "%.6e") for r in rel], axis=0)
            rr, cc = np.nonzero(hit)
            self.coarse[D[rr], cc] = mean[rr]
        late = g >= self.duration - FINAL_WINDOW_S
        if late.any():
            Rc = nearest_rotations(np.mean([R[late] for R in Rg], axis=0))
            common = [np.sqrt(np.clip((3.0 - np.trace(np.einsum("tij,tkj->tik", R[late], Rc), axis1=1, axis2=2)) / 4.0, 0.0, 1.0)) for R in Rg]
            self.final.append((D[late], np.array(common)))

    def result(self, res: Any) -> Any:
        M = self.M
        t1 = np.max(np.where(np.isnan(self.last), -np.inf, self.last), axis=0)
        ends = np.array([len(np.arange(self.t0[m], t1[m] + 1e-9, BASIN_GRID_S)) if np.isfinite(self.t0[m]) else 0 for m in range(M)])
        self._settle(np.full(M, np.inf), ends)  # every estimate is in: the rest of each grid
        res.draw_grid = [(self.G[m, : ends[m]], self.V[m, : ends[m]]) for m in range(M)]
        res.t, res.max_rel = np.zeros(0), np.zeros((M, 0))
        if not self.rows:
            return res
        # edges_on_grid clips to the grid's last point: the 0.1 s points after it hold its edges
        for m in np.flatnonzero((ends > 0) & np.any(self.need >= ends[:, None], axis=1)):
            self.coarse[m, self.need[m] >= ends[m]] = np.mean([rounded(self.last_rel[e, m : m + 1], "%.6e")[0] for e in range(len(self.edges))])
        n = len(self.ids)
        per = np.full((n, M), np.nan)
        if self.final:
            ms = np.concatenate([d for d, _ in self.final])
            vals = np.concatenate([v for _, v in self.final], axis=1)  # (n, points)
            order = np.argsort(ms, kind="stable")  # each draw's points in grid order
            cuts = np.flatnonzero(np.diff(ms[order])) + 1
            for g in np.split(order, cuts):
                per[:, ms[g[0]]] = [np.mean(vals[q, g]) for q in range(n)]
        res.final_att = nanmean_of([per[q] for q, i in enumerate(self.ids) if self.sc.agent(i).role == "follower"])
        res.final_pos = np.full(M, np.nan)  # tree's positions: the §4.4 pose observer's only
        res.t_coarse, res.att_coarse = self.coarse_t, self.coarse
        return res
