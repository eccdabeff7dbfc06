"""Reading recordings: one synthetic scan written as MCAP, ROS 1 bag and ROS 2 bags (MCAP and
sqlite3 storage) must read back to identical Frames that match the truth."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import (
    SCAN_COLOR_TOPIC,
    SCAN_DEPTH_TOPIC,
    SCAN_INFO_TOPIC,
    SyntheticScan,
    assert_same_frames,
    scan_T_base_cam,
    synthetic_scan,
    tiny_recording,
    write_scan,
)

from scrapcut_cli.config import RecordingConfig
from scrapcut_cli.errors import RecordingError
from scrapcut_cli.recording import messages as m
from scrapcut_cli.recording.frame import CameraModel, Frame
from scrapcut_cli.recording.reader import open_recording, sha256_first_mib
from scrapcut_cli.recording.writer import McapWriter

FORMATS = {
    "mcap": ("scan.mcap", "mcap", "mcap"),
    "ros1": ("scan.bag", "ros1", "mcap"),
    "ros2-mcap": ("scan_ros2_mcap", "ros2", "mcap"),
    "ros2-sqlite3": ("scan_ros2_sqlite3", "ros2", "sqlite3"),
}
# Frames 0, 1, 3 and 4 are usable: frame 2 has no depth, frame 5 is past the last TF sample.
USABLE = [0, 1, 3, 4]


@pytest.fixture(scope="module")
def scan() -> SyntheticScan:
    return synthetic_scan()


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory, scan: SyntheticScan) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("recordings")
    out = {}
    for key, (name, fmt, storage) in FORMATS.items():
        write_scan(root / name, scan, fmt, storage=storage)
        out[key] = root / name
    return out


def _frames(path: Path, config: RecordingConfig | None = None) -> list[Frame]:
    with open_recording(path, config) as rec:
        return list(rec.frames())


def _expected_depth(mm: np.ndarray) -> np.ndarray:
    depth = mm.astype(np.float32) * np.float32(0.001)
    depth[mm == 0] = np.nan
    return depth


@pytest.mark.parametrize("key", list(FORMATS))
def test_frames_match_the_truth(recordings: dict[str, Path], scan: SyntheticScan, key: str) -> None:
    frames = _frames(recordings[key])
    assert [f.index for f in frames] == list(range(len(USABLE)))
    assert [f.stamp_ns for f in frames] == [scan.color_stamps[k] for k in USABLE]
    truth = scan_T_base_cam(scan.seconds([f.stamp_ns for f in frames]))
    depth_of = dict(zip(scan.depth_stamps, scan.depths_mm, strict=True))
    for frame, k, T in zip(frames, USABLE, truth, strict=True):
        np.testing.assert_array_equal(frame.color, scan.colors[k])
        depth_stamp = scan.color_stamps[k] + 3_000_000
        assert frame.extras["depth_stamp_ns"] == depth_stamp
        np.testing.assert_array_equal(frame.depth, _expected_depth(depth_of[depth_stamp]))
        np.testing.assert_allclose(frame.T_base_cam, T, atol=1e-9)
        assert frame.camera == scan.camera
        assert (frame.base_frame, frame.camera_frame) == (
            "panda_link0",
            "camera_color_optical_frame",
        )
        assert not frame.color.flags.writeable and not frame.depth.flags.writeable


def test_all_formats_read_back_to_identical_frames(recordings: dict[str, Path]) -> None:
    reference = _frames(recordings["mcap"])
    for key in ("ros1", "ros2-mcap", "ros2-sqlite3"):
        assert_same_frames(reference, _frames(recordings[key]))


@pytest.mark.parametrize("key", list(FORMATS))
def test_plan_counts_without_decoding(recordings: dict[str, Path], key: str) -> None:
    with open_recording(recordings[key]) as rec:
        plan = rec.plan()
        assert rec.format == FORMATS[key][1]
        assert (plan.usable, plan.skipped) == (4, 2)
        assert plan.skip_reasons == {"no_depth": 1, "pose_out_of_range": 1}
        assert plan.unpaired_depth == 1
        assert plan.T_base_cam.shape == (4, 4, 4)
        assert plan.color_index.tolist() == USABLE


@pytest.mark.parametrize("key", list(FORMATS))
def test_summary_topics_and_simulator_extras(
    recordings: dict[str, Path], scan: SyntheticScan, key: str
) -> None:
    with open_recording(recordings[key]) as rec:
        topics = {t.name: (t.msgtype, t.count) for t in rec.topics()}
        assert topics[SCAN_COLOR_TOPIC] == ("sensor_msgs/msg/Image", 6)
        assert topics[SCAN_DEPTH_TOPIC] == ("sensor_msgs/msg/Image", 6)
        assert topics[SCAN_INFO_TOPIC] == ("sensor_msgs/msg/CameraInfo", 1)
        assert topics["/tf_static"] == ("tf2_msgs/msg/TFMessage", 2)
        assert topics["/tf"] == ("tf2_msgs/msg/TFMessage", len(scan.tf_stamps))
        # First log: the first /tf_static at t0 - 50 ms; last: the last depth image + 20 ms.
        expected = (scan.depth_stamps[-1] + 20_000_000 - (scan.t0_ns - 50_000_000)) / 1e9
        assert rec.duration_s == pytest.approx(expected, abs=1e-9)
        np.testing.assert_allclose(rec.reference(), scan.reference, atol=1e-15)
        assert rec.exploration_log() == [{"step": 0, "grow": 12}, {"step": 1, "grow": 3}]
        if key == "mcap":
            assert rec.metadata == {"scrapcut": {"object": "synthetic", "paint": "orange"}}
        else:
            assert rec.metadata == {}


def test_frames_use_header_stamps_not_log_times(
    recordings: dict[str, Path], scan: SyntheticScan
) -> None:
    # Log times trail the stamps by 20 ms; with a 5 ms tolerance, pairing by log time would
    # still work but the poses would be 20 ms off: check both the stamps and messages().
    with open_recording(recordings["mcap"], RecordingConfig(sync_tolerance_s=0.005)) as rec:
        assert rec.plan().usable == 4
        stamps = [stamp for _, stamp, _ in rec.messages([SCAN_COLOR_TOPIC])]
    assert stamps == scan.color_stamps


def test_sync_tolerance_controls_pairing(recordings: dict[str, Path]) -> None:
    with open_recording(recordings["mcap"], RecordingConfig(sync_tolerance_s=0.002)) as rec:
        plan = rec.plan()
        assert plan.usable == 0
        assert plan.skip_reasons == {"no_depth": 6}
        assert list(rec.frames()) == []


def test_base_frame_option(recordings: dict[str, Path], scan: SyntheticScan) -> None:
    frames = _frames(recordings["ros1"], RecordingConfig(base_frame="/panda_link0"))
    seconds = scan.seconds([f.stamp_ns for f in frames])
    for frame, T in zip(frames, scan_T_base_cam(seconds), strict=True):
        assert frame.base_frame == "panda_link0"
        np.testing.assert_allclose(frame.T_base_cam, T, atol=1e-9)
    # The flange moves during the scan: a path in its frame would be no path at all.
    moving = r"--base-frame panda_link8 moves during the scan .*panda_link0 -> panda_link8"
    flange = RecordingConfig(base_frame="panda_link8")
    with open_recording(recordings["ros1"], flange) as rec, pytest.raises(RecordingError) as info:
        rec.plan()
    assert re.search(moving, str(info.value))


def test_frames_stream_lazily(recordings: dict[str, Path]) -> None:
    with open_recording(recordings["mcap"]) as rec:
        stream = rec.frames()
        first = next(stream)
        assert first.index == 0
        stream.close()
        # The recording stays usable after an abandoned stream.
        assert len(list(rec.frames())) == 4


def test_sha256_first_mib(recordings: dict[str, Path]) -> None:
    path = recordings["mcap"]
    assert sha256_first_mib(path) == hashlib.sha256(path.read_bytes()[: 1 << 20]).hexdigest()
    bag_dir = recordings["ros2-mcap"]
    storage = bag_dir / f"{bag_dir.name}.mcap"
    assert sha256_first_mib(bag_dir) == hashlib.sha256(storage.read_bytes()[: 1 << 20]).hexdigest()


def test_metadata_yaml_path_opens_its_bag(recordings: dict[str, Path]) -> None:
    with open_recording(recordings["ros2-sqlite3"] / "metadata.yaml") as rec:
        assert rec.format == "ros2"
        assert rec.plan().usable == 4


# --------------------------------------------------------------------------- encodings


def test_compressed_topics_and_32fc1_through_a_recording(tmp_path: Path) -> None:
    camera = CameraModel(16, 12, 14.0, 14.0, 7.5, 5.5, frame_id="cam")
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, (12, 16, 3), dtype=np.uint8)
    mm = rng.integers(1, 3000, (12, 16)).astype(np.uint16)
    path = tmp_path / "compressed.mcap"
    with McapWriter(path) as writer:
        writer.write_tf(0, [("base", "cam", np.eye(4))], static=True)
        writer.write_camera_info("/info", 10, camera)
        writer.write_compressed_image("/rgb/compressed", 10, "cam", rgb, fmt="png")
        writer.write_compressed_depth("/depth/compressedDepth", 10, "cam", mm)
        writer.write_image("/depth_m", 10, "cam", mm.astype(np.float32) / 1000)
        writer.write_image("/bgr", 10, "cam", rgb[:, :, ::-1], encoding="bgr8")
    for color_topic, depth_topic in [
        ("/rgb/compressed", "/depth/compressedDepth"),
        ("/bgr", "/depth_m"),
    ]:
        config = RecordingConfig(
            color_topic=color_topic, depth_topic=depth_topic, info_topic="/info"
        )
        [frame] = _frames(path, config)
        np.testing.assert_array_equal(frame.color, rgb)
        np.testing.assert_allclose(frame.depth, mm / 1000, rtol=1e-6)
        np.testing.assert_array_equal(frame.T_base_cam, np.eye(4))
        assert frame.base_frame == "base"


# --------------------------------------------------------------------------- bad input


def test_missing_path(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match=r"recording not found: .*nothing.mcap"):
        open_recording(tmp_path / "nothing.mcap")


def test_not_a_recording(tmp_path: Path) -> None:
    path = tmp_path / "notes.mcap"
    path.write_text("hello")
    with pytest.raises(RecordingError, match="is not a recording"):
        open_recording(path)
    (tmp_path / "folder").mkdir()
    with pytest.raises(RecordingError, match=r"not a ROS 2 bag \(it has no metadata\.yaml\)"):
        open_recording(tmp_path / "folder")


def test_bag_directory_without_metadata_points_at_its_storage_file(
    recordings: dict[str, Path], tmp_path: Path
) -> None:
    # `ros2 bag record` killed hard leaves the storage file but no metadata.yaml.
    interrupted = tmp_path / "interrupted"
    interrupted.mkdir()
    storage = interrupted / "interrupted_0.mcap"
    shutil.copy(recordings["mcap"], storage)
    advice = re.escape(f"open {storage} itself, or run `ros2 bag reindex`")
    with pytest.raises(RecordingError, match=advice):
        open_recording(interrupted)
    with open_recording(storage) as rec:  # and the advice works
        assert rec.plan().usable == 4


def test_wrong_suffix_is_named(recordings: dict[str, Path], tmp_path: Path) -> None:
    copy = tmp_path / "scan.data"
    shutil.copy(recordings["ros1"], copy)
    with pytest.raises(RecordingError, match=r"a ROS 1 bag but is not named \*\.bag; rename it"):
        open_recording(copy)


def test_truncated_mcap(recordings: dict[str, Path], tmp_path: Path) -> None:
    data = recordings["mcap"].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match=r"truncated .*mcap recover"):
        open_recording(cut)


def test_truncated_bags_name_the_tool_that_repairs_them(
    recordings: dict[str, Path], tmp_path: Path
) -> None:
    bag = recordings["ros1"].read_bytes()
    (tmp_path / "cut.bag").write_bytes(bag[: len(bag) // 2])
    with pytest.raises(RecordingError, match=r"cut.bag: .*index.*; .*`rosbag reindex`"):
        open_recording(tmp_path / "cut.bag")
    source = recordings["ros2-mcap"]
    cut_dir = tmp_path / "cut_ros2"
    shutil.copytree(source, cut_dir)
    storage = cut_dir / f"{source.name}.mcap"
    storage.write_bytes(storage.read_bytes()[:5000])
    with pytest.raises(RecordingError, match=rf"MCAP file {storage} is truncated .*mcap recover"):
        open_recording(cut_dir)


def test_missing_topics_list_what_exists(recordings: dict[str, Path]) -> None:
    with open_recording(recordings["mcap"], RecordingConfig(color_topic="/nope")) as rec:
        with pytest.raises(
            RecordingError,
            match=(
                "colour topic /nope is not in scan.mcap; image topics present: "
                f"{SCAN_DEPTH_TOPIC}, {SCAN_COLOR_TOPIC}; pick one with --color-topic"
            ),
        ):
            rec.plan()
        assert rec.reference() is not None  # the rest of the recording still reads


def test_missing_default_topics(tmp_path: Path) -> None:
    path = tmp_path / "other.mcap"
    with McapWriter(path) as writer:
        writer.write_image("/left/image", 1, "cam", np.zeros((4, 4, 3), np.uint8))
    no_color = r"no colour topic .*image topics present: /left/image; pick one with --color-topic"
    with open_recording(path) as rec, pytest.raises(RecordingError, match=no_color):
        rec.plan()
    no_info = r"no camera_info topic .*no CameraInfo topics at all; pick one with --info-topic"
    with open_recording(path) as rec, pytest.raises(RecordingError, match=no_info):
        _ = rec.camera
    config = RecordingConfig(color_topic="/left/image")
    no_depth = r"no depth topic .*; pick one with --depth-topic"
    with open_recording(path, config) as rec, pytest.raises(RecordingError, match=no_depth):
        rec.plan()


def test_topic_of_the_wrong_type(recordings: dict[str, Path]) -> None:
    config = RecordingConfig(color_topic="/tf")
    wrong = "carries tf2_msgs/msg/TFMessage, not"
    with (
        open_recording(recordings["mcap"], config) as rec,
        pytest.raises(RecordingError, match=wrong),
    ):
        rec.plan()


def test_no_tf_path_names_both_frames_and_lists_the_existing(tmp_path: Path) -> None:
    path = tmp_path / "lost.mcap"
    tiny_recording(path, image_frame="camera_optical")
    lost = r"no TF path from image frame 'camera_optical' .*TF frames: base, cam, flange"
    with open_recording(path) as rec, pytest.raises(RecordingError, match=lost):
        rec.plan()
    config = RecordingConfig(base_frame="world")
    unknown = "base frame 'world' is not in the TF tree; TF frames: base, cam, flange"
    with open_recording(path, config) as rec, pytest.raises(RecordingError, match=unknown):
        rec.plan()


def test_a_topic_of_the_wrong_kind_fails_before_frames_are_counted(tmp_path: Path) -> None:
    camera = CameraModel(6, 4, 5.0, 5.0, 2.5, 1.5, frame_id="cam")
    path = tmp_path / "kinds.mcap"
    with McapWriter(path) as writer:
        writer.write_tf(0, [("base", "cam", np.eye(4))], static=True)
        writer.write_camera_info("/info", 5, camera)
        uncalibrated = m.camera_info_msg(5, camera)
        uncalibrated.k = np.zeros(9)  # what a camera without intrinsics publishes
        writer.write_message("/uncalibrated", m.CAMERA_INFO, uncalibrated, log_time_ns=5)
        for topic in ("/rgb", "/ir_rgb"):
            writer.write_image(topic, 5, "cam", np.zeros((4, 6, 3), np.uint8))
        writer.write_image("/depth", 5, "cam", np.ones((4, 6), np.uint16))
        writer.write_compressed_image("/depth/jpeg", 5, "cam", np.zeros((4, 6, 3), np.uint8))
    good = RecordingConfig(color_topic="/rgb", depth_topic="/depth", info_topic="/info")
    with open_recording(path, good) as rec:
        assert rec.plan().usable == 1
    for depth_topic, why in (
        ("/ir_rgb", "unsupported depth encoding 'rgb8'"),
        ("/depth/jpeg", "unsupported compressed depth format"),
    ):
        config = replace(good, depth_topic=depth_topic)
        wrong = rf"^{depth_topic}: {why}.*; pick another with --depth-topic$"
        with open_recording(path, config) as rec, pytest.raises(RecordingError, match=wrong):
            rec.plan()
    config = replace(good, color_topic="/depth", depth_topic="/rgb")
    with open_recording(path, config) as rec, pytest.raises(RecordingError, match="--color-topic"):
        rec.plan()
    zero_k = r"focal lengths must be positive.*CameraInfo on /uncalibrated; pick another"
    with (
        open_recording(path, replace(good, info_topic="/uncalibrated")) as rec,
        pytest.raises(RecordingError, match=zero_k),
    ):
        rec.plan()


def test_color_depth_size_mismatch(tmp_path: Path) -> None:
    path = tmp_path / "mismatch.mcap"
    tiny_recording(path, depth_shape=(3, 6))
    with (
        open_recording(path) as rec,
        pytest.raises(
            RecordingError, match=r"colour images on .* are 6x4 but depth images on .* are 6x3"
        ),
    ):
        rec.plan()


def test_exploration_log_must_be_json_objects(tmp_path: Path) -> None:
    path = tmp_path / "log.mcap"
    with McapWriter(path) as writer:
        writer.write_string("/scrapcut/exploration", 1, json.dumps([1, 2]))
    with open_recording(path) as rec, pytest.raises(RecordingError, match="JSON objects"):
        rec.exploration_log()


def test_reference_in_another_frame_is_moved_to_the_base(tmp_path: Path) -> None:
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 3.0]
    path = tmp_path / "ref.mcap"
    with McapWriter(path) as writer:
        writer.write_tf(0, [("panda_link0", "table", T)], static=True)
        writer.write_path("/scrapcut/reference", 5, "table", [[0, 0, 0], [0.1, 0, 0]])
    with open_recording(path) as rec:
        np.testing.assert_allclose(rec.reference(), [[1, 2, 3], [1.1, 2, 3]])
        assert rec.exploration_log() == []
    with open_recording(path, RecordingConfig(base_frame="table")) as rec:
        np.testing.assert_allclose(rec.reference(), [[0, 0, 0], [0.1, 0, 0]])


@pytest.mark.parametrize("head_bytes", [40, 64, 4096])
def test_sqlite_index_reads_image_heads_with_the_same_result(
    recordings: dict[str, Path], monkeypatch: pytest.MonkeyPatch, head_bytes: int
) -> None:
    """A sqlite3 bag's index pass reads only the first bytes of each raw image (the whole
    message when its header does not fit): the same stamps, frame ids and sizes as reading
    every image whole, each head the start of its message, in the same order."""
    from scrapcut_cli.recording import reader as reader_module

    monkeypatch.setattr(reader_module, "IMAGE_HEAD_BYTES", head_bytes)
    path = recordings["ros2-sqlite3"]
    with open_recording(path) as rec:
        topics = [rec.color_topic, rec.depth_topic]
        heads = rec._sqlite_image_heads(topics)
        assert heads is not None
        heads = list(heads)
        full = list(rec.raw_messages(topics))
        assert [h[:3] for h in heads] == [f[:3] for f in full]
        assert all(bytes(f[3]).startswith(h[3]) for h, f in zip(heads, full, strict=True))
        shorter = [len(h[3]) < len(f[3]) for h, f in zip(heads, full, strict=True)]
        if head_bytes == 40:  # no room for the header and size: every message whole
            assert not any(shorter)
        if head_bytes == 64:
            assert all(shorter)
        fast = rec._image_headers()
    monkeypatch.setattr(reader_module, "_sqlite_storages", lambda reader: None)
    with open_recording(path) as rec:
        slow = rec._image_headers()
        assert rec._sqlite_image_heads(topics) is None
    for a, b in zip(fast, slow, strict=True):
        assert (a.topic, a.stamps, a.frame_id, a.size) == (b.topic, b.stamps, b.frame_id, b.size)
