"""Figures that follow their data: each PNG fkn-bench writes for the leaderboards names, in PNG
text chunks, the command that draws it, and a figure drawn from numbers (a comparison chart of
stored results) also carries those numbers and their SHA-256 fingerprint.

Text chunks (tEXt/iTXt, read by any PNG tool, e.g. ``python -c "from PIL import Image;
print(Image.open('f.png').text)"``)::

    fkn-bench command       the command that draws the figure (:data:`COMMAND_KEY`)
    fkn-bench data          the plotted numbers as canonical JSON (:data:`DATA_KEY`)
    fkn-bench data sha256   SHA-256 of that JSON (:data:`FINGERPRINT_KEY`, :func:`fingerprint`)

A PNG drawn by a command that does not write these chunks itself can be given them afterwards,
pixels untouched (:func:`add_text`: tEXt chunks inserted before the image end); such a figure also
carries :data:`NOTE_KEY` saying so.

The fingerprint is over canonical JSON (sorted keys, no spaces, non-finite numbers refused), so
anybody can recompute it from the same results: a figure whose fingerprint differs from the one
computed from the results beside it was drawn from other numbers (:func:`figure_problems`).
"""

from __future__ import annotations

import hashlib
import io
import json
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from fkn_bench.io import write_bytes_atomic

__all__ = ["COMMAND_KEY", "DATA_KEY", "FINGERPRINT_KEY", "NOTE_KEY", "fingerprint", "png_bytes", "write_png", "png_text",
           "add_text", "figure_problems"]

COMMAND_KEY = "fkn-bench command"
DATA_KEY = "fkn-bench data"
FINGERPRINT_KEY = "fkn-bench data sha256"
NOTE_KEY = "fkn-bench note"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _canonical(data: Any) -> str:
    return json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


def fingerprint(data: Any) -> str:
    """SHA-256 (hex) of ``data`` as canonical JSON (module docstring); raises ``ValueError`` for a
    non-finite number (write None instead)."""
    return hashlib.sha256(_canonical(data).encode("ascii")).hexdigest()


def png_bytes(figure: Figure, *, command: str, data: Any = None, dpi: int = 100) -> bytes:
    """``figure`` as PNG bytes whose text chunks name ``command`` and, when given, hold ``data``
    and its :func:`fingerprint` (module docstring)."""
    if not command.strip():
        raise ValueError("a figure needs the command that draws it")
    metadata = {COMMAND_KEY: command}
    if data is not None:
        metadata.update({DATA_KEY: _canonical(data), FINGERPRINT_KEY: fingerprint(data)})
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, metadata=metadata)
    return buffer.getvalue()


def write_png(figure: Figure, path: str | Path, *, command: str, data: Any = None, dpi: int = 100) -> Path:
    """Write :func:`png_bytes` atomically (:func:`fkn_bench.io.write_bytes_atomic`); returns the path."""
    return write_bytes_atomic(Path(path), png_bytes(figure, command=command, data=data, dpi=dpi))


def png_text(source: str | Path | bytes) -> dict[str, str]:
    """The text chunks of a PNG file (or its bytes); raises ``ValueError`` for what is no PNG."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(source) if isinstance(source, bytes) else source) as image:
            if image.format != "PNG":
                raise ValueError(f"{source if not isinstance(source, bytes) else 'the data'} is not a PNG file")
            image.load()  # text chunks after the image data
            return {str(k): str(v) for k, v in getattr(image, "text", {}).items()}
    except UnidentifiedImageError:
        raise ValueError(f"{source if not isinstance(source, bytes) else 'the data'} is not a PNG file") from None


def add_text(png: bytes, text: Mapping[str, str]) -> bytes:
    """``png`` with a tEXt chunk per ``{keyword: value}`` (Latin-1, keyword 1-79 characters)
    inserted before its IEND chunk; the image data is not touched. Raises ``ValueError`` for what
    is no PNG or a keyword or value PNG cannot hold."""
    if not png.startswith(_PNG_SIGNATURE) or png[-12:-8] != (0).to_bytes(4, "big") or png[-8:-4] != b"IEND":
        raise ValueError("not a PNG file ending in its IEND chunk")
    chunks = b""
    for keyword, value in text.items():
        if not 1 <= len(keyword) <= 79 or "\0" in keyword or "\0" in value:
            raise ValueError(f"PNG text keyword {keyword!r}: 1-79 characters, no NUL")
        try:
            body = keyword.encode("latin-1") + b"\0" + value.encode("latin-1")
        except UnicodeEncodeError:
            raise ValueError(f"PNG text {keyword!r}: tEXt holds Latin-1 only") from None
        chunks += len(body).to_bytes(4, "big") + b"tEXt" + body + zlib.crc32(b"tEXt" + body).to_bytes(4, "big")
    return png[:-12] + chunks + png[-12:]


def figure_problems(path: str | Path, data: Any = None) -> list[str]:
    """What is wrong with the figure at ``path`` (empty: nothing): missing, no PNG, no command in
    its text chunks, and -- when ``data`` (the numbers it should plot) is given -- a fingerprint
    other than ``data``'s, i.e. a figure drawn from other numbers."""
    path = Path(path)
    if not path.is_file():
        return [f"{path}: missing"]
    try:
        text = png_text(path)
    except ValueError as exc:
        return [str(exc)]
    problems = [] if text.get(COMMAND_KEY, "").strip() else [f"{path}: no '{COMMAND_KEY}' text chunk names the command that draws it"]
    if data is not None:
        expected = fingerprint(data)
        found = text.get(FINGERPRINT_KEY)
        if found != expected:
            problems.append(
                f"{path}: drawn from other numbers (its '{FINGERPRINT_KEY}' is {found or 'missing'}, the results give "
                f"{expected}); redraw it with: {text.get(COMMAND_KEY) or 'its command'}"
            )
    return problems
