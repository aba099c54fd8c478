"""Presentation tables (the leaderboards' and the reproduction report's) and their Markdown,
HTML and CSV renderings (deterministic text: no dates)."""

from __future__ import annotations

import csv
import html
import io
from collections.abc import Sequence
from dataclasses import dataclass, field

__all__ = ["Table", "markdown_grid", "markdown_table", "html_table", "html_page"]


@dataclass(frozen=True)
class Table:
    """A titled table of pre-formatted strings, with notes printed under it.

    ``align`` holds ``"l"`` or ``"r"`` per column (default: first left, others right); ``name``
    is the file stem where the table is also written as CSV (the reproduction report)."""

    title: str
    header: Sequence[str]
    rows: Sequence[Sequence[str]]
    notes: Sequence[str] = field(default_factory=tuple)
    align: Sequence[str] | None = None
    name: str = ""

    def __post_init__(self) -> None:
        for row in self.rows:
            if len(row) != len(self.header):
                raise ValueError(f"table {self.name or self.title}: row {row} has {len(row)} cells for "
                                 f"{len(self.header)} columns")

    def alignment(self) -> list[str]:
        if self.align is not None:
            return list(self.align)
        return ["l"] + ["r"] * (len(self.header) - 1)

    def to_csv(self) -> str:
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(self.header)
        writer.writerows(self.rows)
        return buffer.getvalue()


def _md_cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def markdown_grid(table: Table) -> list[str]:
    """The GitHub-flavoured Markdown lines of the table itself: header, alignment, rows."""
    lines = ["| " + " | ".join(_md_cell(h) for h in table.header) + " |"]
    lines.append("|" + "|".join(":---" if a == "l" else "---:" for a in table.alignment()) + "|")
    lines.extend("| " + " | ".join(_md_cell(c) for c in row) + " |" for row in table.rows)
    return lines


def markdown_table(table: Table, *, level: int = 2) -> str:
    """GitHub-flavoured Markdown: ``## title``, the table, then the notes as a paragraph."""
    lines = [f"{'#' * level} {table.title}", ""] if table.title else []
    lines += markdown_grid(table)
    for note in table.notes:
        lines.extend(["", note])
    return "\n".join(lines) + "\n"


def html_table(table: Table, *, level: int = 2) -> str:
    """An HTML fragment: heading, ``<table>`` and notes (escaped)."""
    esc = html.escape

    def row(cells: Sequence[str], tag: str) -> str:
        return "<tr>" + "".join(f'<{tag} class="{a}">{esc(str(c))}</{tag}>'
                                for c, a in zip(cells, table.alignment())) + "</tr>"

    parts = [f"<h{level}>{esc(table.title)}</h{level}>"] if table.title else []
    parts += ["<table>", f"<thead>{row(table.header, 'th')}</thead>", "<tbody>"]
    parts += [row(cells, "td") for cells in table.rows]
    parts += ["</tbody></table>", *(f'<p class="note">{esc(note)}</p>' for note in table.notes)]
    return "\n".join(parts) + "\n"


_STYLE = (
    "body{font-family:system-ui,sans-serif;margin:2em;max-width:80em}"
    "table{border-collapse:collapse;margin:1em 0}"
    "th,td{border:1px solid #ccc;padding:.3em .6em}"
    "th{background:#f3f3f3}td.r,th.r{text-align:right}td.l,th.l{text-align:left}"
    "p.note{color:#444;font-size:.9em}"
)


def html_page(title: str, intro: Sequence[str], tables: Sequence[Table]) -> str:
    """A standalone HTML page: title, intro paragraphs, then the tables."""
    esc = html.escape
    body = [f"<h1>{esc(title)}</h1>"] + [f"<p>{esc(p)}</p>" for p in intro] + [html_table(t) for t in tables]
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<title>{esc(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
        + "\n".join(body)
        + "</body>\n</html>\n"
    )
