"""Converting recordings between MCAP, ROS 1 bags and ROS 2 bags keeps every frame."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import (
    SCAN_COLOR_TOPIC,
    SCAN_INFO_TOPIC,
    SyntheticScan,
    assert_same_frames,
    synthetic_scan,
    write_scan,
)
from rosbags.highlevel import AnyReader

from scrapcut_cli.errors import RecordingError
from scrapcut_cli.recording.convert import convert_recording, format_for_path
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.recording.reader import open_recording

TARGETS = {
    "out.mcap": ("mcap", "mcap"),
    "out.bag": ("ros1", "mcap"),
    "out_ros2": ("ros2", "mcap"),
    "out_sqlite": ("ros2", "sqlite3"),
}


@pytest.fixture(scope="module")
def scan() -> SyntheticScan:
    return synthetic_scan(n_frames=5)


@pytest.fixture(scope="module")
def sources(tmp_path_factory: pytest.TempPathFactory, scan: SyntheticScan) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("sources")
    write_scan(root / "scan.mcap", scan, "mcap")
    write_scan(root / "scan.bag", scan, "ros1")
    write_scan(root / "scan_ros2", scan, "ros2")
    return {"mcap": root / "scan.mcap", "ros1": root / "scan.bag", "ros2": root / "scan_ros2"}


def _read(path: Path) -> tuple[list[Frame], dict[str, dict[str, str]], dict[str, int]]:
    with open_recording(path) as rec:
        counts = {t.name: t.count for t in rec.topics()}
        return list(rec.frames()), rec.metadata, counts


@pytest.mark.parametrize("source", ["mcap", "ros1", "ros2"])
@pytest.mark.parametrize("target", list(TARGETS))
def test_conversion_keeps_frames_topics_and_metadata(
    sources: dict[str, Path], tmp_path: Path, source: str, target: str
) -> None:
    fmt, storage = TARGETS[target]
    dst = tmp_path / target
    convert_recording(sources[source], dst, fmt=fmt, storage=storage)
    frames, metadata, counts = _read(dst)
    src_frames, src_metadata, src_counts = _read(sources[source])
    assert_same_frames(src_frames, frames, atol_m=1e-12)
    carrier = "/scrapcut/metadata"  # ROS 1 bags carry metadata on a topic of their own
    assert {k: v for k, v in counts.items() if k != carrier} == src_counts
    assert (carrier in counts) == (fmt == "ros1" and bool(metadata))
    assert metadata == src_metadata
    with open_recording(dst) as rec:
        assert rec.format == fmt


def test_metadata_survives_a_trip_through_ros1_and_ros2(
    sources: dict[str, Path], tmp_path: Path
) -> None:
    convert_recording(sources["mcap"], tmp_path / "a.bag")
    convert_recording(tmp_path / "a.bag", tmp_path / "b_ros2")
    convert_recording(tmp_path / "b_ros2", tmp_path / "c.mcap")
    _, metadata, counts = _read(tmp_path / "c.mcap")
    assert metadata == {"scrapcut": {"object": "synthetic", "paint": "orange"}}
    assert "/scrapcut/metadata" not in counts  # the ROS 1 carrier topic is not copied on
    _, ros1_metadata, ros1_counts = _read(tmp_path / "a.bag")
    assert ros1_metadata == metadata
    assert ros1_counts["/scrapcut/metadata"] == 1


def test_ros1_output_has_ros1_field_names_and_sequence_numbers(
    sources: dict[str, Path], tmp_path: Path
) -> None:
    dst = tmp_path / "out.bag"
    convert_recording(sources["mcap"], dst)
    with AnyReader([dst]) as reader:
        info = [c for c in reader.connections if c.topic == SCAN_INFO_TOPIC]
        assert "float64[9] K" in info[0].msgdef.data
        images = [c for c in reader.connections if c.topic == SCAN_COLOR_TOPIC]
        seqs = [
            reader.deserialize(raw, conn.msgtype).header.seq
            for conn, _, raw in reader.messages(connections=images)
        ]
        static = [c for c in reader.connections if c.topic == "/tf_static"]
    assert seqs == [1, 2, 3, 4, 5]
    assert all(c.ext.latching == 1 for c in static)


def test_ros1_publishers_stay_separate_connections(
    sources: dict[str, Path], tmp_path: Path
) -> None:
    dst = tmp_path / "again.bag"
    convert_recording(sources["ros1"], dst)
    with AnyReader([dst]) as reader:
        static = sorted(c.ext.callerid for c in reader.connections if c.topic == "/tf_static")
    assert static == ["/static_publisher_1", "/static_publisher_2"]


def test_ros2_family_conversion_copies_cdr_bytes(sources: dict[str, Path], tmp_path: Path) -> None:
    dst = tmp_path / "out_ros2"
    convert_recording(sources["mcap"], dst)
    assert sorted(p.name for p in dst.iterdir()) == ["metadata.yaml", "out_ros2.mcap"]
    with open_recording(sources["mcap"]) as a, open_recording(dst) as b:
        assert list(a.raw_messages()) == list(b.raw_messages())
    with AnyReader([dst]) as reader:
        static = [c for c in reader.connections if c.topic == "/tf_static"]
        assert static[0].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"


@pytest.mark.parametrize("target", ["x.mcap", "x.bag"])
def test_same_input_gives_identical_bytes(
    sources: dict[str, Path], tmp_path: Path, target: str
) -> None:
    convert_recording(sources["ros2"], tmp_path / "1" / target)
    convert_recording(sources["ros2"], tmp_path / "2" / target)
    assert (tmp_path / "1" / target).read_bytes() == (tmp_path / "2" / target).read_bytes()


def test_failures_leave_no_output(sources: dict[str, Path], tmp_path: Path) -> None:
    broken = tmp_path / "broken.mcap"
    data = sources["mcap"].read_bytes()
    broken.write_bytes(data[: len(data) // 3])
    for target in ("out.mcap", "out.bag", "out_dir"):
        with pytest.raises(RecordingError, match="truncated"):
            convert_recording(broken, tmp_path / target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.mcap"]
    with pytest.raises(RecordingError, match="is the input"):
        convert_recording(sources["mcap"], sources["mcap"])
    with pytest.raises(RecordingError, match="unknown recording format 'zip'"):
        convert_recording(sources["mcap"], tmp_path / "x.zip", fmt="zip")
    with pytest.raises(RecordingError, match="a ROS 2 bag is a directory"):
        convert_recording(sources["mcap"], broken, fmt="ros2")


def test_existing_output_is_replaced(sources: dict[str, Path], tmp_path: Path) -> None:
    dst = tmp_path / "bag_dir"
    convert_recording(sources["mcap"], dst)
    convert_recording(sources["ros1"], dst)
    frames, _, _ = _read(dst)
    assert len(frames) == 3


def test_a_directory_that_is_not_a_bag_is_never_replaced(
    sources: dict[str, Path], tmp_path: Path
) -> None:
    # `-o results` names a ROS 2 bag directory; an existing folder of other files must survive.
    folder = tmp_path / "results"
    folder.mkdir()
    (folder / "table1.csv").write_text("keep me")
    with pytest.raises(RecordingError, match="is a directory that is not a ROS 2 bag"):
        convert_recording(sources["mcap"], folder)
    assert [p.name for p in folder.iterdir()] == ["table1.csv"]
    empty = tmp_path / "empty"
    empty.mkdir()
    convert_recording(sources["mcap"], empty)  # nothing to lose: becomes the bag
    assert (empty / "metadata.yaml").is_file()


def test_format_for_path() -> None:
    assert format_for_path("a.mcap") == "mcap"
    assert format_for_path("a.BAG") == "ros1"
    assert format_for_path("some/dir") == "ros2"
