"""PNG text chunks that tie a figure to its command and its numbers (issue 39, item 8)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fkn_bench.reporting.figures import (COMMAND_KEY, DATA_KEY, FINGERPRINT_KEY, NOTE_KEY, add_text, figure_problems,
                                       fingerprint, png_bytes, png_text, write_png)
from fkn_bench.plotting import new_figure


def _figure():  # noqa: ANN202
    figure = new_figure(2, 1)
    figure.subplots().plot([0, 1], [1, 0])
    return figure


def test_the_chunks_hold_the_command_the_numbers_and_their_fingerprint(tmp_path: Path) -> None:
    data = {"b": [1.5, None], "a": "x"}
    path = write_png(_figure(), tmp_path / "f.png", command="fkn-bench leaderboard", data=data, dpi=20)
    text = png_text(path)
    assert text[COMMAND_KEY] == "fkn-bench leaderboard" and text[DATA_KEY] == '{"a":"x","b":[1.5,null]}'
    assert text[FINGERPRINT_KEY] == fingerprint({"a": "x", "b": [1.5, None]}) != fingerprint({"a": "x", "b": [1.5, 0]})
    assert figure_problems(path, data) == [] and figure_problems(path) == []
    assert FINGERPRINT_KEY not in png_text(png_bytes(_figure(), command="c", dpi=20))


def test_bad_inputs_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="command"):
        png_bytes(_figure(), command=" ")
    with pytest.raises(ValueError):
        fingerprint({"x": float("nan")})  # a missing number is None, never NaN
    (tmp_path / "x.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="not a PNG"):
        png_text(tmp_path / "x.png")
    assert figure_problems(tmp_path / "x.png") == [f"{tmp_path / 'x.png'} is not a PNG file"]
    with pytest.raises(ValueError, match="not a PNG"):
        add_text(b"GIF89a", {"k": "v"})
    with pytest.raises(ValueError, match="Latin-1"):
        add_text(png_bytes(_figure(), command="c", dpi=20), {"k": "\u2603"})


def test_text_added_afterwards_leaves_the_pixels_alone(tmp_path: Path) -> None:
    from fkn_bench.plotting import save_png

    plain = save_png(_figure(), tmp_path / "plain.png", dpi=20).read_bytes()
    stamped = add_text(plain, {COMMAND_KEY: "fkn-bench train --out runs/x", NOTE_KEY: "added afterwards"})
    (tmp_path / "stamped.png").write_bytes(stamped)
    assert png_text(stamped)[COMMAND_KEY] == "fkn-bench train --out runs/x" and NOTE_KEY in png_text(stamped)
    with Image.open(tmp_path / "plain.png") as a, Image.open(tmp_path / "stamped.png") as b:
        assert np.array_equal(np.asarray(a), np.asarray(b))
    assert figure_problems(tmp_path / "plain.png") and not figure_problems(tmp_path / "stamped.png")
