"""Presentation of the harness's results: tables (Markdown, HTML, terminal text), leaderboards,
figures (PNG files that name the command and the numbers they draw), the shift and cross-scenario
tables, and the output directories they are written to (:mod:`~fkn_bench.reporting.manifest`).
Nothing here runs an estimator: the numbers come from :mod:`fkn_bench.harness` (stored cells and
their summaries, traces, off-grid scores) and the paper's quoted numbers
(:mod:`~fkn_bench.reporting.reference`). Each submodule's docstring says its part.

Names are re-exported lazily (:mod:`fkn_bench.lazy`): importing the package imports no submodule
(matplotlib stays unloaded) until one of its names is used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fkn_bench.lazy import lazy_exports

_EXPORTS = {
    "cross_table": ".cross",
    "figure_problems": ".figures",
    "png_bytes": ".figures",
    "png_text": ".figures",
    "write_png": ".figures",
    "build_leaderboards": ".leaderboard",
    "ranked_summaries": ".leaderboard",
    "write_leaderboards": ".leaderboard",
    "ForeignFileError": ".manifest",
    "check_files": ".manifest",
    "write_files": ".manifest",
    "comparison_chart": ".plots",
    "comparison_data": ".plots",
    "errors_figure": ".plots",
    "ratio_figure": ".plots",
    "save_figure": ".plots",
    "states_figure": ".plots",
    "uncertainty_figure": ".plots",
    "QuotedRow": ".reference",
    "quoted_rows": ".reference",
    "format_number": ".report",
    "format_percent": ".report",
    "summary_text": ".report",
    "text_table": ".report",
    "shift_documents": ".shift",
    "shift_misses": ".shift",
    "shift_table": ".shift",
    "Table": ".tables",
    "html_page": ".tables",
    "html_table": ".tables",
    "markdown_table": ".tables",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:  # what the names are, for type checkers and IDEs
    from fkn_bench.reporting.cross import cross_table
    from fkn_bench.reporting.figures import figure_problems, png_bytes, png_text, write_png
    from fkn_bench.reporting.leaderboard import build_leaderboards, ranked_summaries, write_leaderboards
    from fkn_bench.reporting.manifest import ForeignFileError, check_files, write_files
    from fkn_bench.reporting.plots import (
        comparison_chart,
        comparison_data,
        errors_figure,
        ratio_figure,
        save_figure,
        states_figure,
        uncertainty_figure,
    )
    from fkn_bench.reporting.reference import QuotedRow, quoted_rows
    from fkn_bench.reporting.report import format_number, format_percent, summary_text, text_table
    from fkn_bench.reporting.shift import shift_documents, shift_misses, shift_table
    from fkn_bench.reporting.tables import Table, html_page, html_table, markdown_table

__all__ = [
    "ForeignFileError",
    "QuotedRow",
    "Table",
    "build_leaderboards",
    "check_files",
    "comparison_chart",
    "comparison_data",
    "cross_table",
    "errors_figure",
    "figure_problems",
    "format_number",
    "format_percent",
    "html_page",
    "html_table",
    "markdown_table",
    "png_bytes",
    "png_text",
    "quoted_rows",
    "ranked_summaries",
    "ratio_figure",
    "save_figure",
    "shift_documents",
    "shift_misses",
    "shift_table",
    "states_figure",
    "summary_text",
    "text_table",
    "uncertainty_figure",
    "write_files",
    "write_leaderboards",
    "write_png",
]
