"""Leader–follower observers (thesis Chapter 3, Figs. 3.4–3.17): the errors of each follower's
own estimate against the truth, and their means over followers.

Everything is :mod:`zswarm.report.base`'s: this family is the default one, and the
module states it so that the name resolves like any other family's.
"""

from __future__ import annotations

from zswarm.report.base import convergence, finals, headline, metrics, plot, series, series_from_files, summary, table_lines, write

__all__ = ["convergence", "finals", "headline", "metrics", "plot", "series", "series_from_files", "summary", "table_lines", "write"]
