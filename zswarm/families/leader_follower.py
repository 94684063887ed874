"""Leader–follower observers (thesis Chapter 3, Figs. 3.4–3.17): the errors of each follower's
own estimate against the truth, and their means over followers.

The report is :mod:`zswarm.report.base`'s (the defaults of every family).  On the batched
engine the prescribed truth is shared by the draws and each follower's |R̃_i|_I and ||p̃_i||
(3.15) are measured at its estimates, as :func:`zswarm.report.decoded.errors` measures them
on a recording: at the agents' common ticks (:class:`FollowerTicks`), or at each draw's own
stamps when lossy or jittery sensor links make the draws publish apart
(:class:`FollowerStamps`).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from zswarm.families.contract import Batched, Family, Recipe
from zswarm.families.measure import FINAL_WINDOW_S, Context, Published, Result, Ticks, Truths, coarse_grid, mean_rows, nanmean_of, rounded, truth_at

WORLD = {"step": 0.001, "sensor_rate": 200.0}


class FollowerTicks(Ticks):
    """Each follower's |R̃_i|_I = sqrt(tr(I − R_i R̂_i^T)/4) and ||p̃_i|| = ||p_i − R_i R̂_i^T p̂_i||
    (3.15) at the common ticks; the basin measure is the largest follower attitude error."""

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self.followers = [(i, a) for a, i in enumerate(self.sc.ids) if self.sc.agent(i).role == "follower"]
        # errors.csv's times (%.6f) and the newest row at or before each point of the 0.1 s grid (base.series)
        t_csv = np.array([float(f"{t:.6f}") for t in self.t_ticks])
        self.coarse_t = coarse_grid(self.duration)
        self.coarse_at = np.searchsorted(t_csv, self.coarse_t + 1e-9, side="right") - 1
        self.final_at = np.flatnonzero(self.t_ticks >= self.duration - FINAL_WINDOW_S)  # pipeline.final_mean's window
        if self.rows:
            self.keep = set(self.coarse_at[self.coarse_at >= 0].tolist()) | set(self.final_at.tolist())

    def measure(self, truth: Any, estimates: Mapping[int, Mapping[str, Any]], keep: bool) -> tuple[np.ndarray, Any]:
        R, p = truth.R, truth.p
        att, pos = [], []
        for i, a in self.followers:
            R_hat, p_hat = estimates[i]["R_hat"], estimates[i]["p_hat"]
            tr = np.einsum("ij,mij->m", R[a], R_hat)  # tr(R R̂^T)
            att.append(np.sqrt(np.clip((3.0 - tr) * 0.25, 0.0, 1.0)))
            if keep:
                pos.append(np.linalg.norm(p[a] - np.einsum("ij,mkj,mk->mi", R[a], R_hat, p_hat), axis=1))
        basin = np.max(att, axis=0) if att else np.zeros(self.M)
        return basin, (np.array(att), np.array(pos)) if keep else None  # (F, M) each

    def result(self, res: Result) -> Result:
        res = self.basin_series(res)
        if not self.rows:
            return res
        F = len(self.followers)
        # Finals: per follower the mean over the last second of its ticks, then over followers (base.headline's nanmean).
        fin = np.array([self.kept[n] for n in self.final_at if n < self.n])  # (K, 2, F, M)
        per = [[mean_rows(fin[:, c, f, :].T) for f in range(F)] for c in (0, 1)]  # [c][f] -> (M,)
        res.final_att, res.final_pos = (nanmean_of(per[c]) for c in (0, 1))
        # The 0.1 s grid: each follower's newest row at or before the point, as errors.csv holds it; mean over followers.
        ok = self.coarse_at >= 0
        out = []
        for c in (0, 1):
            cols = np.full((F, self.M, len(self.coarse_t)), np.nan)
            for g in np.flatnonzero(ok):
                cols[:, :, g] = rounded(self.kept[int(self.coarse_at[g])][c], "%.6e")
            out.append(np.mean(cols, axis=0))
        res.t_coarse, res.att_coarse, res.pos_coarse = self.coarse_t, out[0], out[1]
        return res


class FollowerStamps:
    """The same rows per draw when each draw's agents publish at stamps of their own: each
    follower's errors at each of its estimates, held on the 0.1 s grid at the newest estimate
    whose errors.csv time (%.6f) is at or before each point (%.6e values; the mean over the
    followers, NaN until each has one), and the finals: per follower the mean over its
    estimates stamped in the last second, then over the followers.  Streams: an estimate's
    values go to the grid points before the next one's time when that one comes."""

    fields: Mapping[str, tuple[int, ...]] = MappingProxyType({"R_hat": (3, 3), "p_hat": (3,)})  # what it reads of the estimates (Published)

    def __init__(self, ctx: Context) -> None:
        sc, M, duration = ctx.sc, ctx.M, ctx.duration
        self.followers = [(i, a) for a, i in enumerate(sc.ids) if sc.agent(i).role == "follower"]
        F = len(self.followers)
        self.M, self.duration, self.sample_dt, self.rows = M, duration, ctx.sample_dt, ctx.rows
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
            R_hat, p_hat = e["R_hat"][idx], e["p_hat"][idx]
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

    def result(self, res: Result) -> Result:
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


RECIPES = {
    "bearing-fixed": Recipe(
        "thesis-3.2-fixed8",
        "§3.2: bearing-based pose observer (3.3) + (3.14), agents at fixed positions",
        "leader_follower",
        {"name": "bearing_pose_fixed", "gains": {"k_R": 1.0, "k_p": 1.0}},
        WORLD,
        estimate=("p", "R"),
    ),
    "bearing-fixed-filtered": Recipe(
        "thesis-3.2-fixed8-filtered",
        "§3.2: filtered observer (3.8)-(3.9) + (3.14), agents at fixed positions",
        "leader_follower",
        {"name": "bearing_pose_fixed_filtered", "gains": {"k_Omega": 1.0, "k_p": 1.0}},
        WORLD,
        estimate=("p", "R"),
    ),
    "bearing-moving": Recipe(
        "thesis-3.3-moving5",
        "§3.3: observer (3.23) + (3.25) on a rotating formation",
        "leader_follower",
        {"name": "bearing_pose_moving", "gains": {"k_R": 3.0, "k_p": 1.0}},
        WORLD | {"formation": {"axis": [1, 0, 0], "rate": "pi/6"}},
        duration=30.0,
        estimate=("p", "R"),
    ),
}

FAMILY = Family(
    batched=Batched("prescribed", ticks=FollowerTicks, stamps=FollowerStamps),
    recipes=MappingProxyType(RECIPES),
)
