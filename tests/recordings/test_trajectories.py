"""Plain-text estimates (fkn_bench.recordings.trajectories): TUM and CSV parsing, and one-line
errors naming the file and line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fkn_bench.recordings import RecordingError
from fkn_bench.recordings.trajectories import CSV_COVARIANCE, read_csv, read_trajectory, read_tum

TUM = """# timestamp tx ty tz qx qy qz qw
1735689600.0 1.0 2.0 3.0 0.0 0.0 0.0 1.0

1735689600.100000001 1.5 2.0 3.0 0.0 0.0 0.7071 0.7071
"""


def test_tum_lines_become_wxyz_poses_with_exact_nanosecond_stamps(tmp_path: Path) -> None:
    path = tmp_path / "est.tum"
    path.write_text(TUM)
    series = read_trajectory(path)
    assert series.type_name == "tum" and series.twists is None and series.covariances is None
    assert series.stamps_ns.tolist() == [1_735_689_600_000_000_000, 1_735_689_600_100_000_001]
    assert series.indices.tolist() == [2, 4]
    np.testing.assert_allclose(series.poses[0], [1, 0, 0, 0, 1, 2, 3])
    np.testing.assert_allclose(series.poses[1], [np.sqrt(0.5), 0, 0, np.sqrt(0.5), 1.5, 2, 3], atol=1e-15)
    assert np.linalg.norm(series.poses[1, :4]) == pytest.approx(1.0, abs=1e-15)  # renormalised


def test_csv_columns_by_name_with_world_twist_and_upper_triangle_covariance(tmp_path: Path) -> None:
    cov = np.arange(36.0).reshape(6, 6)
    cov = cov + cov.T
    upper = [cov[int(c[4]), int(c[6])] for c in CSV_COVARIANCE]
    header = ["x", "y", "z", "time", "qw", "qx", "qy", "qz", "wx", "wy", "wz", "vx", "vy", "vz", *CSV_COVARIANCE]
    row = [1, 2, 3, "10.5", 1, 0, 0, 0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, *upper]
    path = tmp_path / "est.csv"
    path.write_text(", ".join(header) + "\n" + ",".join(map(str, row)) + "\n" + ",".join(map(str, [*row[:3], "11", *row[4:]])))
    series = read_csv(path)
    assert series.stamps_ns.tolist() == [10_500_000_000, 11_000_000_000]
    np.testing.assert_array_equal(series.poses[0], [1, 0, 0, 0, 1, 2, 3])
    np.testing.assert_array_equal(series.twists[1], [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    np.testing.assert_array_equal(series.covariances[0], cov)
    assert series.frame_id == series.child_frame_id == "world"


@pytest.mark.parametrize("lines, message", [
    (["1 0 0 0 0 0 0 1", "2 0 0 0 0 0 1"], "line 2: 7 values; a TUM line has 8"),
    (["1 0 0 0 0 0 0 1", "2 0 x 0 0 0 0 1"], "line 2: ty = 'x' is not a number"),
    (["1 0 0 nan 0 0 0 1"], "line 1: tz = nan is not finite"),
    (["1 0 0 0 0 0 0 1", "2 0 0 0 0 0 0 0"], "line 2: has a zero quaternion"),
    (["1 0 0 0 0 0 0 1", "2 0 0 0 0 0 0 2"], "line 2: has a quaternion of norm 2"),
    (["1 0 0 0 0 0 0 1", "1 0 0 0 0 0 0 1"], "line 2: time 1.000000000 s is not after line 1's"),
    (["1 0 0 0 0 0 0 1", "0.5 0 0 0 0 0 0 1"], "times must strictly increase"),
    (["1 2e6 0 0 0 0 0 1"], "line 1: rx = 2e+06 is beyond the plausible"),
    (["# only a comment"], "has no data lines"),
])
def test_bad_tum_lines_are_one_line_errors_naming_file_and_line(tmp_path: Path, lines: list[str], message: str) -> None:
    path = tmp_path / "bad.tum"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError) as info:
        read_tum(path)
    text = str(info.value)
    assert text.startswith(str(path)) and message in text and "\n" not in text


@pytest.mark.parametrize("header, row, message", [
    ("time,qw,qx,qy,qz,x,y,z,qW", "1,1,0,0,0,0,0,0,1", "line 1: unknown column(s) 'qW'"),
    ("time,qw,qx,qy,qz,x,y", "1,1,0,0,0,0,0", "missing column(s) z"),
    ("time,qw,qx,qy,qz,x,y,z,wx", "1,1,0,0,0,0,0,0,1", "twist columns are all or none; missing wy"),
    ("time,qw,qx,qy,qz,x,y,z", "1,1,0,0,0,0,0", "line 2: 7 values; the header has 8 columns"),
    ("time,qw,qx,qy,qz,x,y,z", "soon,1,0,0,0,0,0,0", "line 2: time 'soon' is not a number"),
])
def test_bad_csv_files_are_one_line_errors(tmp_path: Path, header: str, row: str, message: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(f"{header}\n{row}\n")
    with pytest.raises(RecordingError, match=None) as info:
        read_trajectory(path)
    assert message in str(info.value) and str(path) in str(info.value)


def test_a_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="estimate file not found"):
        read_trajectory(tmp_path / "nope.tum")
