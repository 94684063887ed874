"""The building blocks of a run's report, from its recording.

The package, from the bottom up (each module imports only those above it in this list):

* :mod:`~zswarm.report.decoded` — the recording decoded, each message filed under its
  key's process; the per-agent estimate errors; the truth's gaps;
* :mod:`~zswarm.report.series` — time-series helpers (the one settle-time function);
* :mod:`~zswarm.report.table` — the text pieces of the end-of-run table;
* :mod:`~zswarm.report.fault_costs` — what each fault cost, and its marks on the plots;
* :mod:`~zswarm.report.base` — the leader–follower measures every family defaults to.

The experiment families (:mod:`zswarm.families`) build on these modules, and
:mod:`zswarm.results` puts a run's report together, asking the run's family for its part.
"""

from __future__ import annotations

from zswarm.report.base import GRID_S, THRESHOLDS
from zswarm.report.decoded import OUTSIDE_RUN_MARGIN_S, TRUTH_GAP_PERIODS, TRUTH_GAP_S, Recording, errors, load_recording, truth_gap_bound, truth_gaps
from zswarm.report.series import settle_time

convergence_time = settle_time  # the name zswarm sweep, study and the tests use

__all__ = [
    "GRID_S",
    "OUTSIDE_RUN_MARGIN_S",
    "THRESHOLDS",
    "TRUTH_GAP_PERIODS",
    "TRUTH_GAP_S",
    "Recording",
    "convergence_time",
    "errors",
    "load_recording",
    "settle_time",
    "truth_gap_bound",
    "truth_gaps",
]
