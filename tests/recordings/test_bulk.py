"""BulkWriter writes the same bytes as mcap's Writer called once per message."""

from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from fkn_bench.recordings.bulk import BulkWriter
from fkn_bench.recordings.writer import write_recording

_MCAP_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "": CompressionType.NONE}


def _messages(rng: np.random.Generator, n: int, channels: int):
    channel_ids = rng.integers(1, channels + 1, n)
    log_times = 10**18 + np.sort(rng.integers(0, 10**12, n))
    log_times[n // 3] = 10**18 - 5  # out of order: minimum in the middle
    publish = log_times + rng.integers(0, 1000, n)
    sequences = rng.integers(0, 2**32, n)
    payloads = [rng.bytes(int(k)) for k in rng.integers(0, 300, n)]
    return channel_ids, log_times, publish, sequences, payloads


def _write_both(calls, chunk_size: int, compression: str) -> tuple[bytes, bytes]:
    ours, theirs = io.BytesIO(), io.BytesIO()
    bulk = BulkWriter(ours, chunk_size=chunk_size, compression=compression)
    ref = Writer(theirs, chunk_size=chunk_size, compression=_MCAP_COMPRESSION[compression])
    for writer in (bulk, ref):
        writer.start(profile="ros2", library="test")
    for name, *args in calls:
        if name == "messages":
            bulk.add_messages(*args)
            for c, t, p, s, d in zip(*(a.tolist() if hasattr(a, "tolist") else a for a in args)):
                ref.add_message(c, log_time=t, data=d, publish_time=p, sequence=s)
        else:
            results = [getattr(w, name)(*args) for w in (bulk, ref)]
            assert results[0] == results[1]
    bulk.finish()
    ref.finish()
    return ours.getvalue(), theirs.getvalue()


@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
@pytest.mark.parametrize("chunk_size", [1, 700, 5000, 1 << 20])
def test_same_bytes_as_mcap_writer(compression: str, chunk_size: int) -> None:
    rng = np.random.default_rng(chunk_size)
    first = _messages(rng, 150, 3)
    second = _messages(rng, 90, 4)
    calls = [
        ("add_metadata", "info", {"a": "1", "bb": "two"}),
        ("register_schema", "geometry_msgs/msg/PoseStamped", "ros2msg", b"float64 x\n"),
        ("register_schema", "foxglove.PoseInFrame", "jsonschema", b"{}"),
        ("register_channel", "/a", "cdr", 1),
        ("register_channel", "/b", "json", 2),
        ("register_channel", "/c", "cdr", 1, {"k": "v"}),
        ("messages", *first),
        ("add_metadata", "more", {}),
        ("register_channel", "/d", "cdr", 1),
        ("messages", *second),
    ]
    ours, theirs = _write_both(calls, chunk_size, compression)
    assert ours == theirs
    summary = make_reader(io.BytesIO(ours), validate_crcs=True).get_summary()
    assert summary.statistics.message_count == 240


def test_no_messages_and_input_checks() -> None:
    calls = [("register_schema", "s", "ros2msg", b""), ("register_channel", "/a", "cdr", 1)]
    ours, theirs = _write_both(calls, 1024, "zstd")
    assert ours == theirs
    writer = BulkWriter(io.BytesIO())
    writer.start()
    with pytest.raises(ValueError, match="unknown channel"):
        writer.add_messages(np.array([1]), np.array([0]), np.array([0]), np.array([0]), [b""])
    with pytest.raises(ValueError, match="equal lengths"):
        writer.add_messages(np.array([1, 1]), np.array([0]), np.array([0]), np.array([0]), [b""])
    with pytest.raises(ValueError, match="compression"):
        BulkWriter(io.BytesIO(), compression="brotli")


def test_write_recording_engines_give_identical_files(tmp_path, short_episode) -> None:
    episodes, estimates, _ = short_episode
    options = dict(
        times=episodes.times,
        truth=episodes.truth[0],
        measurements=episodes.measurements[0],
        valid=episodes.valid[0],
        estimates=estimates.means[0],
        estimate_error_covariances=estimates.error_covariances[0],
        estimate_mask=estimates.initialised[0],
        metadata={"fkn_bench.episode": {"seed": "3"}},
        chunk_size=20_000,
    )
    write_recording(tmp_path / "bulk.mcap", engine="bulk", **options)
    write_recording(tmp_path / "mcap.mcap", engine="mcap", **options)
    assert (tmp_path / "bulk.mcap").read_bytes() == (tmp_path / "mcap.mcap").read_bytes()
    with pytest.raises(ValueError, match="engine"):
        write_recording(tmp_path / "x.mcap", engine="fast", **options)
