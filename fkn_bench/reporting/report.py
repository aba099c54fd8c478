"""Plain-text rendering of run summaries (the table ``fkn-bench run`` prints)."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Collection, Sequence
from typing import Any

__all__ = ["format_number", "format_percent", "text_table", "summary_text"]


def format_number(value: Any, digits: int = 4) -> str:
    """``digits`` significant digits; ``-`` for missing values; no exponent in [1e-4, 1e6)."""
    if value is None:
        return "-"
    value = float(value)
    if not math.isfinite(value):
        return "-" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if value == 0:
        return "0"
    if 1e-4 <= abs(value) < 1e6:
        decimals = max(digits - 1 - int(math.floor(math.log10(abs(value)))), 0)
        return f"{value:.{decimals}f}"
    return f"{value:.{digits - 1}e}"


def text_table(header: Sequence[str], rows: Sequence[Sequence[str]], *, right: Collection[int] | None = None) -> str:
    """A fixed-width table: the columns ``right`` (default: all but the first) right-aligned, the
    others left-aligned."""
    widths = [max(len(str(cell)) for cell in column) for column in zip(header, *rows)]
    right = set(range(1, len(widths)) if right is None else right)

    def line(cells: Sequence[str]) -> str:
        return "  ".join(str(c).rjust(w) if i in right else str(c).ljust(w)
                         for i, (c, w) in enumerate(zip(cells, widths))).rstrip()

    return "\n".join([line(header), line(["-" * w for w in widths]), *(line(r) for r in rows)])


def format_percent(value: Any, missing: str = "-") -> str:
    """A fraction as a whole percentage; ``missing`` for missing values."""
    return missing if value is None or not math.isfinite(float(value)) else f"{100 * float(value):.0f}%"


def _column_groups(header: Sequence[str], rows: Sequence[Sequence[str]], width: int) -> list[list[int]]:
    """Columns ``1..`` packed in order into groups that fit ``width`` beside column 0 (the row
    names, repeated in every group); a group holds at least one column."""
    widths = [max(len(header[i]), *(len(row[i]) for row in rows)) + 2 for i in range(len(header))]
    groups: list[list[int]] = [[]]
    used = widths[0]
    for index in range(1, len(header)):
        if groups[-1] and used + widths[index] > width:
            groups.append([])
            used = widths[0]
        groups[-1].append(index)
        used += widths[index]
    return groups


def _seeds(summary: dict[str, Any]) -> str:
    """The seeds column: ``"2"``, or ``"2 (1 not finite)"`` when seeds have a non-finite 13-state
    RMSE (they are left out of the means: the count says so)."""
    bad = int(summary.get("non_finite_runs") or 0)
    return f"{summary['runs']}" + (f" ({bad} not finite)" if bad else "")


def summary_text(summaries: Sequence[dict[str, Any]], width: int | None = None) -> str:
    """The run table: one line per (estimator, scenario), then a legend. With ``width`` (a
    terminal's columns), a table wider than that is printed as two stacked tables (accuracy;
    settling, consistency and speed), each row led by its estimator and scenario, and the legend
    is wrapped to the width."""
    header = [
        "estimator / scenario", "seeds", "13-state RMSE", "IQR", "att deg", "pos m", "w rad/s", "v m/s",
        "settle s", "diverged", "ANEES", "95% bounds", "in", "us/step",
    ]
    rows = []
    for s in summaries:
        stats = s["statistics"]["state_rmse"]
        lo, hi = s["anees_bounds"]
        rows.append([
            f"{s['estimator']} / {s['scenario']}",
            _seeds(s),
            format_number(s["state_rmse"]),
            f"{format_number(stats['q25'], 3)}-{format_number(stats['q75'], 3)}",
            format_number(s["attitude_rmse_deg"], 3),
            format_number(s["position_rmse_m"], 3),
            format_number(s["omega_rmse_rad_s"], 3),
            format_number(s["velocity_rmse_m_s"], 3),
            format_number(s["settling_time_s"], 3),
            format_percent(s["diverged_fraction"]),
            format_number(s["anees"], 3),
            f"[{format_number(lo, 3)}, {format_number(hi, 3)}]",
            format_percent(s["nees_in_bounds_fraction"]),
            format_number(s["us_per_step"], 3),
        ])
    legend = (
        "13-state RMSE: root mean square over the 13 state components and the scored window (steps >= cut), "
        "mean over seeds (lower is better); IQR over seeds.\n"
        "att/pos/w/v: RMSE of the attitude angle (deg), position (m), angular rate (rad/s), velocity (m/s). "
        "settle: mean settling time (all groups). diverged: share of seeds.\n"
        "ANEES: average NEES (12-dim error) over seeds and steps; in: share of steps whose average over seeds "
        "lies in the 95% chi-square bounds. us/step: online step latency."
    )
    if any(s.get("non_finite_runs") for s in summaries):
        legend += ("\nseeds \"N (K not finite)\": the 13-state RMSE of K of the N seeds is NaN or infinite (diverged "
                   "or failed); the means and IQRs are over the other seeds.")
    errors = [f"{s['estimator']} / {s['scenario']}: {e}" for s in summaries for e in s["errors"]]
    table = text_table(header, rows)
    if width is not None and max(map(len, table.splitlines())) > width:
        table = "\n\n".join(text_table([header[0], *(header[i] for i in group)], [[row[0], *(row[i] for i in group)] for row in rows])
                              for group in _column_groups(header, rows, width))
        legend = "\n".join(textwrap.fill(line, width=max(width, 40)) for line in legend.splitlines())
    text = table + "\n\n" + legend
    if errors:
        text += "\n\nFailures:\n" + "\n".join(f"  {e}" for e in errors)
    return text
