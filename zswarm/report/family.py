"""Report families: how a run of one kind of algorithm becomes figures.

An algorithm names its family in ``SPEC.report``; a family is a module with
some of these functions (the ones it leaves out are the leader–follower
defaults of :mod:`zswarm.report.base`):

``metrics(sc, rec) -> M``
    The family's own metrics from the recording (any object; None: none).
``summary(sc, rec, m, agents, duration) -> dict``
    Its keys of summary.json (per-agent figures may be set in ``agents`` in place).
``headline(sc, agents, extra) -> dict``
    ``mean_attitude_error_final``, ``mean_position_error_final`` and ``mean_over``:
    the team's figures (``extra``: what ``summary`` returned).
``series(sc, errs, m, duration) -> (t, attitude, position)``
    The team's error measure over time: what convergence, a fault's re-convergence
    and the convergence study judge.
``finals(summary) -> (attitude, position)``
    The team's final errors as the summary states them (zswarm study).
``convergence(sc, errs, m, duration, thresholds) -> dict``
    summary.json ``convergence`` (settle times).
``series_from_files(folder, sc, duration) -> (t, attitude, position)``
    The same series from a results folder's files (zswarm sweep).
``write(out_dir, sc, rec, m)``, ``plot(out_dir, sc, errs, m, rec)``
    Its CSVs beside errors.csv, and its figures.
``table_lines(summary) -> list[str]``
    Its lines of the table printed at the end of a run.
``basin_start(sc) -> list[(field, value)]``, ``basin_series(sc, rec) -> (t, v)``
    Optional (zswarm basin): the rotations a draw randomises (the scenario field and its
    own value), and the max-over-edges error whose settle time the basin tabulates.

Families are found like algorithms: by a name registered in the entry-point group
``zswarm.report_families`` (``leader_follower``, ``tree``, ``sync``, ``formation`` are
zswarm's, in ``pyproject.toml``), or by a module path.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from zswarm.algorithm import family_module
from zswarm.report import base
from zswarm.scenario import Scenario

FUNCTIONS = ("metrics", "summary", "headline", "series", "finals", "convergence", "series_from_files", "write", "plot", "table_lines")
OPTIONAL = ("basin_start", "basin_series")


@dataclass(frozen=True)
class Family:
    """A family's functions (see the module docstring), the defaults filled in."""

    name: str
    metrics: Callable[..., Any]
    summary: Callable[..., dict[str, Any]]
    headline: Callable[..., dict[str, Any]]
    series: Callable[..., base.Series]
    finals: Callable[[dict[str, Any]], tuple[float | None, float | None]]
    convergence: Callable[..., dict[str, Any]]
    series_from_files: Callable[..., base.Series]
    write: Callable[..., None]
    plot: Callable[..., None]
    table_lines: Callable[[dict[str, Any]], list[str]]
    basin_start: Callable[[Scenario], list[tuple[str, Any]]] | None = None
    basin_series: Callable[..., Any] | None = None
    basin_grid_s: float = base.GRID_S  # the grid step of basin_series (a family's BASIN_GRID_S)


_cache: dict[str, Family] = {}


def resolve(name: str) -> Family:
    """The family registered as ``name`` (or the module of that path)."""
    if name in _cache:
        return _cache[name]
    target = family_module(name)
    if target is None:
        raise ValueError(f"no report family {name!r} (an entry point of zswarm.report_families, or a module path)")
    module = importlib.import_module(target)
    fns = {f: getattr(module, f, getattr(base, f)) for f in FUNCTIONS} | {f: getattr(module, f, None) for f in OPTIONAL}
    bad = [f for f, fn in fns.items() if fn is not None and not callable(fn)]
    if bad:
        raise ValueError(f"report family {name!r} ({target}): {', '.join(bad)} must be functions")
    _cache[name] = Family(name, **fns, basin_grid_s=float(getattr(module, "BASIN_GRID_S", base.GRID_S)))
    return _cache[name]


def of(sc: Scenario) -> Family:
    """The report family of the scenario's algorithm (``SPEC.report``)."""
    return resolve(sc.info.report)
