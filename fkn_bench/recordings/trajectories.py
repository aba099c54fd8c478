"""Estimates written by any program as plain text: the TUM trajectory format and CSV with a header.

Both give a :class:`TrajectorySeries` (a :class:`~fkn_bench.recordings.PoseSeries` with pose
covariances), which :mod:`fkn_bench.envs.association` puts onto a replayed truth's time grid.

**TUM** (``.tum``, ``.txt``; Sturm et al., "A benchmark for the evaluation of RGB-D SLAM
systems", IROS 2012): one pose per line, eight whitespace-separated numbers
``timestamp tx ty tz qx qy qz qw`` (seconds; metres; a unit quaternion, scalar last, body to
world). Lines starting with ``#`` and blank lines are skipped.

**CSV** (``.csv``): comma-separated, the first line that is not a ``#`` comment or blank is the
header; columns are found by name, in any order (surrounding spaces ignored):

* required: ``time`` (s), ``qw qx qy qz`` (scalar first, body to world), ``x y z`` (m);
* optional, all six or none: ``wx wy wz`` (angular velocity, rad/s) and ``vx vy vz`` (velocity,
  m/s), both expressed in the **world** frame (fkn-bench's state convention);
* optional, all 21 or none: ``cov_i_j`` for ``0 <= i <= j <= 5``, the upper triangle of the 6x6
  pose covariance in fkn-bench's error order ``[dtheta (3), dr (3)]`` (rad^2, rad m, m^2), where
  ``dtheta`` is the world-frame rotation-vector error, ``q_true = exp(dtheta / 2) (x) q_est``; the
  lower triangle is its mirror (symmetric by construction).

Any other column name is an error (a misspelt ``qW`` would otherwise be lost without a word).

Times are on the recording's clock: seconds since the Unix epoch, as the recording's header
stamps (e.g. ``1735689600.1`` for 2025-01-01T00:00:00.1Z), read as exact decimals into integer
nanoseconds (a double would round a 2025 epoch time to about 0.2 us).

Validation (each a :class:`~fkn_bench.recordings.RecordingError` of one line naming the file and
the line, counted from 1): a wrong number of values, a value that is not a number or not finite,
a position or rate beyond the plausibility limits (:mod:`fkn_bench.recordings.plausibility`), a
zero quaternion (norm below 1e-9), a quaternion whose norm is off 1 by more than
``quaternion_tolerance`` (default :data:`TEXT_QUATERNION_TOLERANCE`), a non-finite covariance,
times that do not strictly increase, and a file without data lines.

Quaternions are divided by their norm (text rounds them: four printed decimals leave the norm off
1 by up to about 1e-4), so every pose holds a unit quaternion; one off by more than the tolerance
is refused as a wrong column order or garbage rather than silently renormalised (the MCAP reader
refuses a norm off by more than its tolerance unless repairing; a text file has no repair).
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from fkn_bench.recordings.plausibility import component_limits
from fkn_bench.recordings.reader import PoseSeries, RecordingError
from fkn_bench.types import STATE_NAMES

__all__ = [
    "TUM_COLUMNS", "CSV_REQUIRED", "CSV_TWIST", "CSV_COVARIANCE", "TEXT_QUATERNION_TOLERANCE",
    "TrajectorySeries", "read_trajectory", "read_tum", "read_csv",
]

TUM_COLUMNS: tuple[str, ...] = ("timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw")
"""The eight values of a TUM line, in order."""
CSV_REQUIRED: tuple[str, ...] = ("time", "qw", "qx", "qy", "qz", "x", "y", "z")
"""Columns every CSV trajectory has."""
CSV_TWIST: tuple[str, ...] = ("wx", "wy", "wz", "vx", "vy", "vz")
"""Optional world-frame twist columns (all or none)."""
CSV_COVARIANCE: tuple[str, ...] = tuple(f"cov_{i}_{j}" for i in range(6) for j in range(i, 6))
"""Optional pose-covariance columns (all or none): the upper triangle of the 6x6 covariance of
``[dtheta, dr]``, row by row."""
TEXT_QUATERNION_TOLERANCE = 1e-3
"""Largest accepted ``| |q| - 1 |`` of a quaternion in a text file (module docstring)."""

_NS = 10**9
_UPPER = np.triu_indices(6)


@dataclass(frozen=True, eq=False, kw_only=True)
class TrajectorySeries(PoseSeries):
    """Poses read from a text file (the fields of :class:`~fkn_bench.recordings.PoseSeries`).

    ``topic`` is the file path, ``type_name`` ``"tum"`` or ``"csv"``, ``encoding`` ``"text"``,
    ``frame_id`` and ``child_frame_id`` ``"world"`` (so ``twists``, when present, are world-frame:
    ``[w (3), v (3)]``), ``indices`` the line numbers (from 1), ``time_source`` ``"file"``,
    ``covariances`` the ``(N, 6, 6)`` pose covariances of ``[dtheta, dr]`` or None.
    """


def _error(path: Path, line: int | None, message: str) -> RecordingError:
    where = f"{path}, line {line}" if line is not None else str(path)
    return RecordingError(f"{where}: {message}", path=path, index=line)


def _lines(path: Path) -> list[tuple[int, str]]:
    """(line number, text) of the lines that are neither blank nor ``#`` comments."""
    if not path.exists():
        raise RecordingError(f"estimate file not found: {path}", path=path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise _error(path, None, f"cannot be read as UTF-8 text ({type(exc).__name__}: {exc})") from None
    return [(n, s.strip()) for n, s in enumerate(text.splitlines(), 1) if s.strip() and not s.lstrip().startswith("#")]


def _nanoseconds(path: Path, line: int, text: str) -> int:
    try:
        value = Decimal(text)
    except InvalidOperation:
        raise _error(path, line, f"time {text!r} is not a number") from None
    if not value.is_finite():
        raise _error(path, line, f"time {text!r} is not finite")
    return int((value * _NS).to_integral_value())


def _numbers(path: Path, line: int, texts: list[str], names: tuple[str, ...]) -> list[float]:
    values = []
    for text, name in zip(texts, names):
        try:
            value = float(text)
        except ValueError:
            raise _error(path, line, f"{name} = {text!r} is not a number") from None
        if not np.isfinite(value):
            raise _error(path, line, f"{name} = {text} is not finite")
        values.append(value)
    return values


def _series(
    path: Path, kind: str, lines: list[int], stamps: list[int], poses: np.ndarray, twists: np.ndarray | None,
    covariances: np.ndarray | None, quaternion_tolerance: float,
) -> TrajectorySeries:
    """Checks shared by both formats (module docstring) and the series."""
    if not lines:
        raise _error(path, None, "has no data lines")
    line = np.array(lines, dtype=np.int64)
    stamp = np.array(stamps, dtype=np.int64)
    back = np.flatnonzero(np.diff(stamp) <= 0)
    if len(back):
        i = int(back[0]) + 1
        raise _error(path, int(line[i]), f"time {stamp[i] / _NS:.9f} s is not after line {line[i - 1]}'s "
                                         f"{stamp[i - 1] / _NS:.9f} s (times must strictly increase)")
    names = STATE_NAMES[4:7] + (STATE_NAMES[7:] if twists is not None else ())
    checked = poses[:, 4:] if twists is None else np.concatenate([poses[:, 4:], twists], axis=1)
    beyond = np.abs(checked) > component_limits(names)
    if beyond.any():
        i, j = np.argwhere(beyond)[0]
        raise _error(path, int(line[i]), f"{names[j]} = {checked[i, j]:.6g} is beyond the plausible +-"
                                         f"{component_limits(names)[j]:g} (fkn_bench.recordings.plausibility)")
    norms = np.linalg.norm(poses[:, :4], axis=1)
    zero = norms < 1e-9
    off = np.abs(norms - 1.0) > quaternion_tolerance
    if zero.any() or off.any():
        i = int(np.argmax(zero | off))
        problem = "a zero quaternion" if zero[i] else (
            f"a quaternion of norm {norms[i]:.9g}, off 1 by more than {quaternion_tolerance:g} (a wrong column "
            "order or not a quaternion?)")
        raise _error(path, int(line[i]), f"has {problem}")
    poses = poses.copy()
    poses[:, :4] /= norms[:, None]
    return TrajectorySeries(
        topic=str(path), type_name=kind, encoding="text", stamps_ns=stamp, frame_id="world", indices=line,
        time_source="file", poses=poses, child_frame_id="world", twists=twists, covariances=covariances,
    )


def read_tum(path: str | Path, *, quaternion_tolerance: float = TEXT_QUATERNION_TOLERANCE) -> TrajectorySeries:
    """Poses of a TUM trajectory file (module docstring); no twists or covariances."""
    path = Path(path)
    lines, stamps, rows = [], [], []
    for n, text in _lines(path):
        fields = text.split()
        if len(fields) != len(TUM_COLUMNS):
            raise _error(path, n, f"{len(fields)} values; a TUM line has {len(TUM_COLUMNS)} ({' '.join(TUM_COLUMNS)})")
        stamps.append(_nanoseconds(path, n, fields[0]))
        tx, ty, tz, qx, qy, qz, qw = _numbers(path, n, fields[1:], TUM_COLUMNS[1:])
        rows.append((qw, qx, qy, qz, tx, ty, tz))
        lines.append(n)
    return _series(path, "tum", lines, stamps, np.array(rows, dtype=np.float64).reshape(-1, 7), None, None,
                   quaternion_tolerance)


def _csv_columns(path: Path, line: int, header: list[str]) -> tuple[list[int], list[int] | None, list[int] | None]:
    """Indices of the required, twist and covariance columns in ``header``."""
    known = set(CSV_REQUIRED) | set(CSV_TWIST) | set(CSV_COVARIANCE)
    unknown = [h for h in header if h not in known]
    if unknown:
        raise _error(path, line, f"unknown column(s) {', '.join(map(repr, unknown))}; the columns are "
                                 f"{', '.join(CSV_REQUIRED)}, optionally {', '.join(CSV_TWIST)} (world frame) and "
                                 "cov_0_0 .. cov_5_5 (upper triangle) (fkn_bench.recordings.trajectories)")
    repeated = sorted({h for h in header if header.count(h) > 1})
    if repeated:
        raise _error(path, line, f"column(s) {', '.join(map(repr, repeated))} appear more than once")
    missing = [c for c in CSV_REQUIRED if c not in header]
    if missing:
        raise _error(path, line, f"missing column(s) {', '.join(missing)} (required: {', '.join(CSV_REQUIRED)})")
    groups = []
    for group, what in ((CSV_TWIST, "twist"), (CSV_COVARIANCE, "covariance")):
        present = [c for c in group if c in header]
        if present and len(present) != len(group):
            absent = [c for c in group if c not in header]
            raise _error(path, line, f"the {what} columns are all or none; missing {', '.join(absent)}")
        groups.append([header.index(c) for c in group] if present else None)
    return [header.index(c) for c in CSV_REQUIRED], groups[0], groups[1]


def read_csv(path: str | Path, *, quaternion_tolerance: float = TEXT_QUATERNION_TOLERANCE) -> TrajectorySeries:
    """Poses, and twists and pose covariances where the columns are present, of a CSV file (module
    docstring)."""
    path = Path(path)
    content = _lines(path)
    if not content:
        raise _error(path, None, "has no header line")
    (header_line, header_text), rows_text = content[0], content[1:]
    header = [h.strip() for h in header_text.split(",")]
    required, twist_columns, covariance_columns = _csv_columns(path, header_line, header)
    lines, stamps, poses, twists, covariances = [], [], [], [], []
    others = [i for i in range(len(header)) if i != required[0]]  # every column but the time
    other_names = tuple(header[i] for i in others)
    for n, text in rows_text:
        fields = [f.strip() for f in text.split(",")]
        if len(fields) != len(header):
            raise _error(path, n, f"{len(fields)} values; the header has {len(header)} columns")
        stamps.append(_nanoseconds(path, n, fields[required[0]]))
        values = np.full(len(header), np.nan)
        values[others] = _numbers(path, n, [fields[i] for i in others], other_names)
        poses.append(values[required[1:]])
        if twist_columns is not None:
            twists.append(values[twist_columns])
        if covariance_columns is not None:
            covariances.append(values[covariance_columns])
        lines.append(n)
    twist_array = np.array(twists, dtype=np.float64).reshape(-1, 6) if twist_columns is not None else None
    covariance_array = None
    if covariance_columns is not None:
        upper = np.array(covariances, dtype=np.float64).reshape(-1, 21)
        covariance_array = np.zeros((len(upper), 6, 6))
        covariance_array[:, _UPPER[0], _UPPER[1]] = upper
        covariance_array[:, _UPPER[1], _UPPER[0]] = upper
    return _series(path, "csv", lines, stamps, np.array(poses, dtype=np.float64).reshape(-1, 7), twist_array,
                   covariance_array, quaternion_tolerance)


def read_trajectory(path: str | Path, *, quaternion_tolerance: float = TEXT_QUATERNION_TOLERANCE) -> TrajectorySeries:
    """A text trajectory by its suffix: ``.csv`` is CSV, anything else (``.tum``, ``.txt``) TUM."""
    path = Path(path)
    reader = read_csv if path.suffix.lower() == ".csv" else read_tum
    return reader(path, quaternion_tolerance=quaternion_tolerance)
