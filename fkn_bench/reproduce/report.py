"""The report: a small document model written as Markdown (``index.md``) and HTML
(``index.html``) from the same blocks, plus one CSV per table (``tables/<name>.csv``).

Blocks: :class:`Heading`, :class:`Paragraph` (plain text; ``**bold**`` and backticks are kept in
Markdown and rendered in HTML), :class:`Bullets`, :class:`~fkn_bench.reporting.tables.Table` (the
leaderboards' table; its ``name`` is the CSV file stem) and :class:`FigureRef` (a PNG in the report
directory). Every file is written atomically.
"""

from __future__ import annotations

import html
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from fkn_bench.io import write_text_atomic
from fkn_bench.reporting.tables import Table, markdown_table

__all__ = ["Heading", "Paragraph", "Bullets", "Table", "FigureRef", "Block", "render_markdown", "render_html", "write_report"]


@dataclass(frozen=True)
class Heading:
    text: str
    level: int = 2


@dataclass(frozen=True)
class Paragraph:
    text: str


@dataclass(frozen=True)
class Bullets:
    items: tuple[str, ...]


@dataclass(frozen=True)
class FigureRef:
    """A figure file (relative to the report directory) with its caption."""

    path: str
    caption: str


Block = Heading | Paragraph | Bullets | Table | FigureRef


def render_markdown(blocks: Sequence[Block]) -> str:
    """The blocks as GitHub-flavoured Markdown."""
    out: list[str] = []
    for block in blocks:
        if isinstance(block, Heading):
            out.append(f"{'#' * block.level} {block.text}\n")
        elif isinstance(block, Paragraph):
            out.append(f"{block.text}\n")
        elif isinstance(block, Bullets):
            out.append("\n".join(f"- {item}" for item in block.items) + "\n")
        elif isinstance(block, Table):  # the title in bold, not as a heading; notes as plain paragraphs
            out.append(f"**{block.title}**\n\n{markdown_table(replace(block, title=''))}"
                       f"\n(CSV: [`tables/{block.name}.csv`](tables/{block.name}.csv))\n")
        elif isinstance(block, FigureRef):
            out.append(f"![{block.caption}]({block.path})\n\n*{block.caption}*\n")
        else:  # pragma: no cover - the union is closed
            raise TypeError(f"unknown block {block!r}")
    return "\n".join(out)


_INLINE = [
    (re.compile(r"\*\*(.+?)\*\*"), r"<strong>\1</strong>"),
    (re.compile(r"`(.+?)`"), r"<code>\1</code>"),
    (re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)"), r'<a href="\2">\1</a>'),
]


def _inline(text: str) -> str:
    escaped = html.escape(text, quote=False)
    for pattern, replacement in _INLINE:
        escaped = pattern.sub(replacement, escaped)
    return escaped


_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; line-height: 1.45; }
table { border-collapse: collapse; margin: 0.5em 0 0.3em; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; }
th { background: #f2f2f2; }
td.r { text-align: right; font-variant-numeric: tabular-nums; }
caption { font-weight: bold; text-align: left; padding-bottom: 0.3em; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
.note { font-size: 0.88em; color: #444; margin: 0.1em 0; }
"""


def render_html(blocks: Sequence[Block], *, title: str) -> str:
    """The blocks as one self-contained HTML page (figures referenced by relative path)."""
    body: list[str] = []
    for block in blocks:
        if isinstance(block, Heading):
            level = min(max(block.level, 1), 6)
            anchor = re.sub(r"[^a-z0-9]+", "-", block.text.lower()).strip("-")
            body.append(f'<h{level} id="{anchor}">{_inline(block.text)}</h{level}>')
        elif isinstance(block, Paragraph):
            body.append(f"<p>{_inline(block.text)}</p>")
        elif isinstance(block, Bullets):
            body.append("<ul>" + "".join(f"<li>{_inline(item)}</li>" for item in block.items) + "</ul>")
        elif isinstance(block, Table):
            head = "".join(f"<th>{_inline(c)}</th>" for c in block.header)
            rows = "".join(
                "<tr>" + "".join(f'<td class="{a}">{_inline(c)}</td>' for c, a in zip(row, block.alignment())) + "</tr>"
                for row in block.rows
            )
            notes = "".join(f'<p class="note">{_inline(n)}</p>' for n in block.notes)
            link = f'<p class="note">CSV: <a href="tables/{block.name}.csv">tables/{block.name}.csv</a></p>'
            body.append(f"<table><caption>{_inline(block.title)}</caption><thead><tr>{head}</tr></thead>"
                        f"<tbody>{rows}</tbody></table>{notes}{link}")
        elif isinstance(block, FigureRef):
            body.append(f'<figure><img src="{html.escape(block.path)}" alt="{html.escape(block.caption)}">'
                        f"<figcaption>{_inline(block.caption)}</figcaption></figure>")
        else:  # pragma: no cover
            raise TypeError(f"unknown block {block!r}")
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
        + "\n".join(body)
        + "\n</body>\n</html>\n"
    )


def write_report(out: str | Path, blocks: Sequence[Block], *, title: str) -> dict[str, Path]:
    """Write ``index.md``, ``index.html`` and ``tables/<name>.csv`` into ``out``."""
    out = Path(out)
    written = {
        "markdown": write_text_atomic(out / "index.md", render_markdown(blocks)),
        "html": write_text_atomic(out / "index.html", render_html(blocks, title=title)),
    }
    for block in blocks:
        if isinstance(block, Table):
            written[f"table:{block.name}"] = write_text_atomic(out / "tables" / f"{block.name}.csv", block.to_csv())
    return written
