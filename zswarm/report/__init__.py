"""Results of a run from its recording: errors.csv, summary.json, a family's CSVs, plots, the table.

The package, from the bottom up (each module imports only those above it in this list):

* :mod:`~zswarm.report.recording` — the recording decoded, each message filed under its
  key's process; the per-agent estimate errors; the truth's gaps;
* :mod:`~zswarm.report.series` — time-series helpers (the one settle-time function);
* :mod:`~zswarm.report.text` — the text pieces of the end-of-run table;
* :mod:`~zswarm.report.faults` — what each fault cost, and its marks on the plots;
* :mod:`~zswarm.report.base` — the leader–follower measures every family defaults to;
* :mod:`~zswarm.report.pipeline` — summary.json and the files of every run.

The experiment families (:mod:`zswarm.family`, the contract; zswarm's own in
:mod:`zswarm.families`) build on these modules; the pipeline asks the run's family
(``SPEC.report``) for its part and never which family a run is.
"""

from __future__ import annotations

from zswarm.report.base import GRID_S, THRESHOLDS
from zswarm.report.pipeline import (
    MAX_FAILED_STEPS_SHARE,
    OVERLOAD_PCT,
    completeness,
    make_report,
    make_report_parts,
    overload,
    recording_section,
    run_problems,
    strict_json,
    summarize,
    table,
    write_errors_csv,
    write_summary,
)
from zswarm.report.recording import OUTSIDE_RUN_MARGIN_S, TRUTH_GAP_PERIODS, TRUTH_GAP_S, Recording, errors, load_recording, truth_gap_bound, truth_gaps
from zswarm.report.series import settle_time

convergence_time = settle_time  # the name zswarm sweep, study and the tests use

__all__ = [
    "GRID_S",
    "MAX_FAILED_STEPS_SHARE",
    "OUTSIDE_RUN_MARGIN_S",
    "OVERLOAD_PCT",
    "THRESHOLDS",
    "TRUTH_GAP_PERIODS",
    "TRUTH_GAP_S",
    "Recording",
    "completeness",
    "convergence_time",
    "errors",
    "load_recording",
    "make_report",
    "make_report_parts",
    "overload",
    "recording_section",
    "run_problems",
    "settle_time",
    "strict_json",
    "summarize",
    "table",
    "truth_gap_bound",
    "truth_gaps",
    "write_errors_csv",
    "write_summary",
]
