"""The tree family's measures on the batched engine (zswarm.families.measure): the §4.5 observers'
estimates on the prescribed truth, which the draws share, as tree_metrics measures a
recording: at the agents' common ticks (:class:`TreeTicks`), or at each draw's own stamps
when lossy or jittery sensor links make the draws publish apart (:class:`TreeStamps`)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from zswarm.families.measure import FINAL_WINDOW_S, Context, Published, Result, Ticks, Truths, coarse_grid, mean_rows, nanmean_of, rounded, truth_at
from zswarm.math.so3 import nearest_rotations

BASIN_GRID_S = 0.01  # s: the basin series' grid (tree_metrics' default step)


class TreeTicks(Ticks):
    """The tree family (zswarm.families.tree.tree_metrics) at the common ticks: R̃_i = R_i R̂_i^T and per edge
    |R̄_k|_I = |R̃_t^T R̃_h|_I at every tick (the basin measure: their max); for the rows, each
    agent's |R̃_i R̃_c^T|_I up to the chordal mean R̃_c over the last second, and the edges'
    mean on the 0.1 s grid as edges.csv holds it (%.3f times, %.6e values)."""

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self.edges = list(self.sc.oriented)
        self.col = {i: a for a, i in enumerate(self.sc.ids)}
        tk = self.t_ticks
        # tree_metrics' grid (step 0.01 from the first estimate), each point's newest tick ...
        self.tm_t = np.arange(tk[0], tk[-1] + 1e-9, 0.01) if len(tk) else np.zeros(0)
        self.tm_at = np.searchsorted(tk, self.tm_t, side="right") - 1
        # ... and edges_on_grid's 0.1 s points on edges.csv's times
        t_csv = np.array([float(f"{t:.3f}") for t in self.tm_t])
        self.coarse_t = coarse_grid(self.duration)
        self.coarse_at = self.tm_at[np.clip(np.searchsorted(t_csv, self.coarse_t, side="right") - 1, 0, len(t_csv) - 1)] if len(t_csv) else np.zeros(0, dtype=int)
        self.final_at = self.tm_at[self.tm_t >= self.duration - FINAL_WINDOW_S]  # series.final's window on tm.t
        if self.rows:
            self.keep = set(self.coarse_at.tolist()) | set(self.final_at.tolist())

    def measure(self, truth: Any, estimates: Mapping[int, Mapping[str, Any]], keep: bool) -> tuple[np.ndarray, Any]:
        R = truth.R
        Rt = {i: R[a] @ np.swapaxes(estimates[i]["R_hat"], -1, -2) for i, a in self.col.items()}
        vals = []
        for h, tl in self.edges:
            tr = np.einsum("mji,mji->m", Rt[tl], Rt[h])  # tr(R̃_t^T R̃_h), without the product
            vals.append(np.sqrt(np.clip((3.0 - tr) / 4.0, 0.0, 1.0)))
        basin = np.max(vals, axis=0) if vals else np.zeros(self.M)
        return basin, (np.array(vals), Rt) if keep else None

    def result(self, res: Result) -> Result:
        res = self.basin_series(res)
        if not self.rows:
            return res
        sc = self.sc
        # The agents' errors up to the chordal mean over the last second (tree.summary), their mean over followers.
        finals = []
        for n in self.final_at:
            Rt = self.kept[int(n)][1]
            Rc = nearest_rotations(np.mean([Rt[i] for i in sc.ids], axis=0))  # (M, 3, 3)
            finals.append([np.sqrt(np.clip((3.0 - np.einsum("mij,mij->m", Rt[i], Rc)) / 4.0, 0.0, 1.0)) for i in sc.ids])
        fin = np.array(finals)  # (K, agents, M)
        per = [mean_rows(fin[:, q, :].T) for q, i in enumerate(sc.ids) if sc.agent(i).role == "follower"]
        res.final_att = nanmean_of(per)
        res.final_pos = np.full(self.M, np.nan)  # tree's positions: the §4.4 pose observer's only
        E = len(self.edges)
        held = np.array([rounded(self.kept[int(n)][0], "%.6e") for n in self.coarse_at])  # (T, E, M)
        res.t_coarse = self.coarse_t
        res.att_coarse = np.mean([held[:, e, :].T for e in range(E)], axis=0)  # edges_on_grid(..., np.mean)
        return res


class TreeStamps:
    """The tree family (zswarm.families.tree.tree_metrics) per draw when each draw's agents publish at stamps of their own: R̃_i = R_i R̂_i^T of
    each agent's estimates at their stamps, each agent's newest at or before each point of the
    draw's own 100 Hz grid (from the latest first estimate of the agents to the latest
    estimate: np.arange(t0, t1 + 1e-9, 0.01)), per edge |R̄_k|_I = |R̃_t^T R̃_h|_I there.

    A grid point is final once every agent has an estimate stamped at or after it (a later one
    is stamped later still); each agent keeps its estimates since the oldest point not final
    (a ring per agent, grown when an agent runs ahead).  The basin measure is the max over the
    edges at every point; for a sweep's rows, edges.csv's 0.1 s points (%.3f times, %.6e values,
    the mean over edges) and each agent's |R̃_i R̃_c^T|_I up to their chordal mean R̃_c at the
    points of the last second (tree.summary's finals, the mean over followers)."""

    fields: Mapping[str, tuple[int, ...]] = MappingProxyType({"R_hat": (3, 3)})  # what it reads of the estimates (Published)

    def __init__(self, ctx: Context) -> None:
        sc, M, duration = ctx.sc, ctx.M, ctx.duration
        self.sc, self.M, self.duration, self.sample_dt, self.rows = sc, M, duration, ctx.sample_dt, ctx.rows
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
            self._keep(q, idx, s, R @ e["R_hat"][idx].transpose(0, 2, 1))  # tree_metrics: R̃ = R R̂^T
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
