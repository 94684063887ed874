"""A run's results from its recording: summary.json, errors.csv, its family's CSVs and
figures, the end-of-run table (pipeline).  It asks the run's experiment family
(zswarm.families) for its part.  Imports every layer below (up to families)."""

from __future__ import annotations

from zswarm.results.pipeline import (
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

__all__ = [
    "MAX_FAILED_STEPS_SHARE",
    "OVERLOAD_PCT",
    "completeness",
    "make_report",
    "make_report_parts",
    "overload",
    "recording_section",
    "run_problems",
    "strict_json",
    "summarize",
    "table",
    "write_errors_csv",
    "write_summary",
]
