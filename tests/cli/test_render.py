"""``fkn-bench render``: a picture (or video) of an estimator in the environment."""

from __future__ import annotations

from pathlib import Path

import pytest

from fkn_bench.cli import main


def test_render_writes_the_last_frame_as_png(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "frame.png"
    assert main(["render", "--estimator", "manual-ekf", "--steps", "4", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "wrote" in capsys.readouterr().err and list(tmp_path.iterdir()) == [out]  # nothing left beside it


def test_render_writes_a_gif(tmp_path: Path) -> None:
    pytest.importorskip("imageio", reason="videos need the video extra")
    out = tmp_path / "run.gif"
    assert main(["render", "--steps", "4", "--every", "2", "--out", str(out)]) == 0
    assert out.read_bytes()[:6] == b"GIF89a" and list(tmp_path.iterdir()) == [out]
