"""The experiment-family contract: everything particular to one kind of experiment.

An algorithm names its family in ``SPEC.report``.  A family is a module that exports
``FAMILY``, a :class:`Family`: the report of a run (its metrics, summary keys, CSVs,
figures and table lines), its columns and figures of ``zswarm sweep``, its verdict of
``zswarm basin``, its measure on the batched engine, its recipes of ``zswarm generate`` and
any commands of its own.  The core (sim, run, the report pipeline, sweep, basin, generate,
the batched engine, the CLI) asks the family of a scenario for these and never names one.

Families are found like algorithms: by a name registered in the entry-point group
``zswarm.families`` (``leader_follower``, ``tree``, ``sync`` and ``formation`` are zswarm's,
in ``pyproject.toml``; a user's package registers its own the same way), or by a module path.

The parts:

:class:`Report`
    How a recording becomes summary.json, CSVs, figures and the end-of-run table; each
    function left out is :mod:`zswarm.report.base`'s (each agent's own estimate errors and
    their means over the followers).
:class:`Sweep`
    The family's columns of sweep.csv after the generic ones (links, timing, counters, the
    team's errors and convergence times), from a finished run's folder and from a batched
    draw, and the four metrics its sweep figures plot.
:class:`Basin`
    What a basin draw randomises, the series whose settle time it judges, and the words:
    what a draw that settles is called (``verdict``) and what the series is (``measure``).
:class:`Batched`
    The plant the batched engine runs the family's draws on and its measure of them
    (:mod:`zswarm.families.measure`: a truth per draw, or a shared truth measured at the agents'
    ticks or at each draw's own stamps).
:class:`Recipe`
    A ``zswarm generate`` recipe: the algorithm, world and graph shape of a paper's scenario.
:class:`Command`
    A subcommand of ``zswarm`` the family adds (``design-hybrid``).
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from zswarm.report import base
from zswarm.util import plugins
from zswarm.util.plugins import FAMILY_GROUP as GROUP
from zswarm.util.plugins import OWN_FAMILIES as OWN
from zswarm.util.plugins import family_module as module_of

if TYPE_CHECKING:
    import argparse
    from pathlib import Path

    import numpy as np

    from zswarm.scenario import Scenario

__all__ = ["GROUP", "OWN", "Basin", "Batched", "Command", "Family", "FamilyError", "Recipe", "Report", "Sweep", "commands", "every", "module_of", "of", "recipes", "registered", "resolve"]

Figure = tuple[str, str, bool]  # (sweep.csv column, axis label, log scale)


@dataclass(frozen=True)
class Report:
    """How a run's recording becomes its results (None: :mod:`zswarm.report.base`'s).

    ``metrics(sc, rec) -> M``: the family's own metrics from the recording (any object).
    ``summary(sc, rec, m, agents, duration) -> dict``: its keys of summary.json (per-agent
    figures may be set in ``agents`` in place).  ``headline(sc, agents, extra) -> dict``:
    ``mean_attitude_error_final``, ``mean_position_error_final``, ``mean_over``.
    ``series(sc, errs, m, duration) -> (t, attitude, position)``: the team's error measure on
    the 0.1 s grid (what convergence, a fault's re-convergence and zswarm study judge).
    ``finals(summary) -> (attitude, position)``.  ``convergence(sc, errs, m, duration,
    thresholds) -> dict``.  ``series_from_files(folder, sc, duration)``: ``series`` from a
    results folder's files.  ``write(out_dir, sc, rec, m)``, ``plot(out_dir, sc, errs, m,
    rec)``: its CSVs and figures.  ``table_lines(summary) -> list[str]``: its lines of the
    table printed at the end of a run."""

    metrics: Callable[..., Any] | None = None
    summary: Callable[..., dict[str, Any]] | None = None
    headline: Callable[..., dict[str, Any]] | None = None
    series: Callable[..., Any] | None = None
    finals: Callable[[dict[str, Any]], tuple[float | None, float | None]] | None = None
    convergence: Callable[..., dict[str, Any]] | None = None
    series_from_files: Callable[..., Any] | None = None
    write: Callable[..., None] | None = None
    plot: Callable[..., None] | None = None
    table_lines: Callable[[dict[str, Any]], list[str]] | None = None


# The team's figures of merit every sweep row has (zswarm.studies.sweep), plotted unless a family says otherwise.
DEFAULT_FIGURES: tuple[Figure, ...] = (
    ("final_attitude_error", "final attitude error |R̃|_I", True),
    ("final_position_error", "final position error (m)", True),
    ("conv_attitude_s", "attitude convergence time (s)", False),
    ("conv_position_s", "position convergence time (s)", False),
)


@dataclass(frozen=True)
class Sweep:
    """The family's part of ``zswarm sweep``.

    ``columns``: its columns of sweep.csv, after the generic ones.  ``from_run(folder,
    summary, sc, t, attitude) -> dict``: their values from a finished run's results folder
    (its summary.json as a dict, and the team's attitude measure on the 0.1 s grid).
    ``from_batch(res, n, sc) -> dict``: the same for draw ``n`` of a batched run
    (:class:`zswarm.families.measure.Result`).  ``figures``: the four metrics a sweep figure plots."""

    columns: tuple[str, ...] = ()
    from_run: Callable[[Path, dict[str, Any], Scenario, np.ndarray, np.ndarray], dict[str, Any]] | None = None
    from_batch: Callable[[Any, int, Scenario], dict[str, Any]] | None = None
    figures: tuple[Figure, ...] = DEFAULT_FIGURES


@dataclass(frozen=True)
class Basin:
    """The family's part of ``zswarm basin``.

    ``start(sc) -> [(field, value)]``: the scenario fields (rotations) a draw randomises, with
    the scenario's own values.  ``series(sc, rec) -> (t, v)``: the measure whose settle time
    the basin tabulates, on a grid of ``grid_s``.  ``verdict``: what basin.csv and the table
    call a draw whose measure settles below the threshold; ``measure``: the measure's name in
    the table and the figures."""

    start: Callable[[Scenario], list[tuple[str, Any]]]
    series: Callable[[Scenario, Any], tuple[np.ndarray, np.ndarray]]
    verdict: str = "settled"
    measure: str = "the basin measure"
    grid_s: float = 0.1


@dataclass(frozen=True)
class Batched:
    """The family's measure on the batched engine (:mod:`zswarm.families.measure`).

    ``plant``: the plant its draws run on there (``prescribed``: one truth for every draw;
    ``rigid_body``: a truth per draw).  Each factory takes a :class:`zswarm.families.measure.Context`
    and returns a measure: ``truth`` for a truth per draw (``sample(k, t, truth)`` at every world
    sample, a :class:`zswarm.families.measure.Truth`), ``ticks`` for a shared truth with every draw's agents ticking together
    (``tick(truth, estimates)``), ``stamps`` for a shared truth whose draws publish at stamps
    of their own (``tick(truths, published)``); each ends with ``result(res) -> res``.  A
    factory left None: the engine refuses such runs, saying so."""

    plant: str
    truth: Callable[[Any], Any] | None = None
    ticks: Callable[[Any], Any] | None = None
    stamps: Callable[[Any], Any] | None = None


@dataclass(frozen=True)
class Recipe:
    """A ``zswarm generate`` recipe: what a generated scenario shares with a paper's one."""

    source: str  # the shipped scenario (topologies/) its algorithm section comes from
    what: str
    graph: str  # the graph shape the loader checks (zswarm.scenario.graph.SHAPES)
    algorithm: Mapping[str, Any]
    world: Mapping[str, Any]
    rate: float = 100.0  # agents' clock, Hz
    duration: float = 40.0
    estimate: tuple[str, ...] = ()  # what each agent's initial estimate sets (besides xi)
    params: Callable[[int], dict[str, Any]] | None = None  # [algorithm.params] of a scenario of n agents (None: the algorithm's own)


@dataclass(frozen=True)
class Command:
    """A subcommand a family adds to ``zswarm``: ``arguments(parser)`` declares its options,
    ``run(args) -> exit code`` runs it."""

    name: str
    help: str
    description: str
    arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    examples: tuple[str, ...] = ()  # command lines shown at the end of its --help


@dataclass(frozen=True)
class Family:
    """One experiment family (see the module docstring).  ``name`` is the name it was found by."""

    report: Report = field(default_factory=Report)
    sweep: Sweep = field(default_factory=Sweep)
    basin: Basin | None = None
    batched: Batched | None = None
    recipes: Mapping[str, Recipe] = field(default_factory=lambda: MappingProxyType({}))
    commands: tuple[Command, ...] = ()
    name: str = ""

    @property
    def grid_s(self) -> float:
        """The grid of the family's basin measure (its Basin's; without one, the report's 0.1 s):
        what the batched engine measures its draws on."""
        return self.basin.grid_s if self.basin is not None else base.GRID_S

    # The report's functions, its own or zswarm.report.base's.
    def __getattr__(self, name: str) -> Any:
        if name in _REPORT:
            fn = getattr(self.report, name)
            return getattr(base, name) if fn is None else fn
        raise AttributeError(name)


_REPORT = frozenset(f.name for f in fields(Report))


class FamilyError(ValueError):
    """A family name that resolves to nothing, or a module that is not a family."""


@functools.cache
def resolve(name: str) -> Family:
    """The family registered as ``name`` (or the module of that path)."""
    target = module_of(name)
    if target is None:
        known = ", ".join(plugins.registered(GROUP, OWN))
        raise FamilyError(f"no family {name!r} (registered: {known}; or a module path like mylab.my_family)")
    module = importlib.import_module(target)
    fam = getattr(module, "FAMILY", None)
    if not isinstance(fam, Family):
        raise FamilyError(f"family {name!r} ({target}): the module has no FAMILY = zswarm.families.contract.Family(...)")
    bad = [f.name for f in fields(Report) if getattr(fam.report, f.name) is not None and not callable(getattr(fam.report, f.name))]
    if bad:
        raise FamilyError(f"family {name!r} ({target}): report.{', report.'.join(bad)} must be functions")
    return replace(fam, name=name)


def of(sc: Scenario) -> Family:
    """The family of the scenario's algorithm (``SPEC.report``)."""
    return resolve(sc.info.report)


def registered() -> Mapping[str, str]:
    """Every registered family's name -> its module path, zswarm's own first."""
    return plugins.registered(GROUP, OWN)


def every() -> list[Family]:
    """Every registered family, zswarm's own first (those that fail to load are left out:
    a broken plugin must not take the command line down)."""
    out = []
    for name in registered():
        try:
            out.append(resolve(name))
        except (ImportError, FamilyError):
            continue
    return out


def recipes() -> dict[str, tuple[Family, Recipe]]:
    """Every family's ``zswarm generate`` recipes by name (the first family to name one keeps it)."""
    out: dict[str, tuple[Family, Recipe]] = {}
    for fam in every():
        for name, r in fam.recipes.items():
            out.setdefault(name, (fam, r))
    return out


def commands() -> dict[str, Command]:
    """Every family's extra subcommands by name (the first family to name one keeps it)."""
    out: dict[str, Command] = {}
    for fam in every():
        for c in fam.commands:
            out.setdefault(c.name, c)
    return out
