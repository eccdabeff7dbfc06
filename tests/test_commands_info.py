"""``scrapcut info``: the fixed JSON keys, the tables, and one-line errors for bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from helpers import (
    SCAN_COLOR_TOPIC,
    SCAN_DEPTH_TOPIC,
    SCAN_INFO_TOPIC,
    SyntheticScan,
    synthetic_scan,
    tiny_recording,
    write_scan,
)

from scrapcut_cli.cli import cli
from scrapcut_cli.recording.writer import McapWriter


@pytest.fixture(scope="module")
def scan() -> SyntheticScan:
    return synthetic_scan()


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory, scan: SyntheticScan) -> Path:
    path = tmp_path_factory.mktemp("info") / "scan.mcap"
    write_scan(path, scan, "mcap")
    return path


def _run(*args: str) -> Result:
    return CliRunner().invoke(cli, ["info", *args])


def test_json_has_the_fixed_keys(recording: Path, scan: SyntheticScan) -> None:
    result = _run(str(recording), "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["schema"] == "scrapcut.info/v1" and data["tool_version"]
    fixed = {
        "format",
        "duration_s",
        "topics",
        "camera",
        "frames",
        "base_frame",
        "camera_frame",
        "has_reference",
        "has_exploration_log",
    }
    assert fixed <= set(data)
    assert data["format"] == "mcap"
    assert data["duration_s"] == pytest.approx(0.7366666, abs=1e-6)
    topics = {t["name"]: (t["type"], t["count"]) for t in data["topics"]}
    assert topics[SCAN_COLOR_TOPIC] == ("sensor_msgs/msg/Image", 6)
    assert all(set(t) >= {"name", "type", "count"} for t in data["topics"])
    cam = scan.camera
    assert {k: data["camera"][k] for k in ("width", "height", "fx", "fy", "cx", "cy")} == {
        "width": cam.width,
        "height": cam.height,
        "fx": cam.fx,
        "fy": cam.fy,
        "cx": cam.cx,
        "cy": cam.cy,
    }
    assert data["frames"] == {
        "usable": 4,
        "skipped": 2,
        "skip_reasons": {"no_depth": 1, "pose_out_of_range": 1},
        "unpaired_depth": 1,
    }
    assert (data["base_frame"], data["camera_frame"]) == (
        "panda_link0",
        "camera_color_optical_frame",
    )
    assert data["has_reference"] is True and data["has_exploration_log"] is True
    assert data["metadata"] == {"scrapcut": {"object": "synthetic", "paint": "orange"}}


def test_options_reach_the_reader(recording: Path) -> None:
    result = _run(
        str(recording), "--json", "--sync-tolerance-ms", "1", "--base-frame", "/panda_link0"
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["frames"]["usable"] == 0
    assert data["frames"]["skip_reasons"] == {"no_depth": 6}
    assert data["base_frame"] == "panda_link0"
    # The hand moves during the scan: as a base frame it is refused, naming the fixed one.
    _assert_one_line_error(
        _run(str(recording), "--base-frame", "panda_hand"),
        "--base-frame panda_hand moves during the scan",
        "(panda_link0)",
    )


def test_tables_name_every_topic_whole(recording: Path) -> None:
    result = _run(str(recording))
    assert result.exit_code == 0, result.output
    for name in (SCAN_COLOR_TOPIC, SCAN_DEPTH_TOPIC, SCAN_INFO_TOPIC, "/tf_static"):
        assert name in result.stdout
    assert "4 usable, 2 skipped (no_depth 1, pose_out_of_range 1)" in result.stdout


def test_tables_stay_readable_on_a_simulated_recording(tmp_path: Path) -> None:
    # The simulator's metadata holds a JSON of every parameter (kB): shown in --json only.
    # Brackets in the name are text, not rich markup.
    fixture = tmp_path / "scan[bold].mcap"
    shutil.copy(
        Path(__file__).resolve().parents[1] / "fixtures" / "sim_cylinder_small.mcap", fixture
    )
    result = _run(str(fixture))
    assert result.exit_code == 0, result.output
    assert "scan[bold].mcap" in result.stdout
    assert "object=cylinder" in result.stdout and "params=(" in result.stdout
    assert max(len(line) for line in result.stdout.splitlines()) < 120
    data = json.loads(_run(str(fixture), "--json").stdout)
    assert json.loads(data["metadata"]["scrapcut"]["params"])["sim"]["views"] == 6


# --------------------------------------------------------------------------- bad input


def _assert_one_line_error(result: Result, *fragments: str) -> None:
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("scrapcut: error: ")
    for fragment in fragments:
        assert fragment in lines[0]
    assert "Traceback" not in result.output
    assert result.stdout == ""


def test_missing_path(tmp_path: Path) -> None:
    _assert_one_line_error(_run(str(tmp_path / "absent.mcap")), "recording not found")


def test_not_a_recording(tmp_path: Path) -> None:
    path = tmp_path / "photo.mcap"
    path.write_bytes(b"\xff\xd8\xff\xe0 not an mcap")
    _assert_one_line_error(_run(str(path)), "is not a recording")


def test_truncated_mcap(recording: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(recording.read_bytes()[:5000])
    _assert_one_line_error(_run(str(cut)), "truncated", "mcap recover")


@pytest.mark.parametrize(
    ("option", "topic", "expected"),
    [
        ("--color-topic", "/camera/missing", "image topics present:"),
        ("--depth-topic", "/camera/missing", "image topics present:"),
        ("--info-topic", "/camera/missing", "CameraInfo topics present: " + SCAN_INFO_TOPIC),
    ],
)
def test_missing_topics(recording: Path, option: str, topic: str, expected: str) -> None:
    _assert_one_line_error(
        _run(str(recording), option, topic), f"topic {topic} is not in", expected, option
    )


def test_default_topics_missing(tmp_path: Path) -> None:
    path = tmp_path / "left.mcap"
    with McapWriter(path) as writer:
        writer.write_image("/left/image_raw", 1, "cam", np.zeros((4, 6, 3), np.uint8))
    _assert_one_line_error(
        _run(str(path)), "no colour topic", "image topics present: /left/image_raw", "--color-topic"
    )


def test_no_tf_path(tmp_path: Path) -> None:
    path = tiny_recording(tmp_path / "lost.mcap", image_frame="camera_optical")
    _assert_one_line_error(_run(str(path)), "'camera_optical'", "TF frames: base, cam, flange")
    _assert_one_line_error(
        _run(str(tiny_recording(tmp_path / "ok.mcap")), "--base-frame", "world"),
        "'world'",
        "TF frames: base, cam, flange",
    )


def test_color_depth_size_mismatch(tmp_path: Path) -> None:
    path = tiny_recording(tmp_path / "mismatch.mcap", depth_shape=(2, 3))
    _assert_one_line_error(_run(str(path)), "6x4", "3x2", "--depth-topic")


def test_a_good_tiny_recording_works(tmp_path: Path) -> None:
    result = _run(str(tiny_recording(tmp_path / "ok.mcap")), "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["frames"]["usable"] == 1
    assert data["base_frame"] == "base"
    assert data["has_reference"] is False


def test_frames_and_time_crop_a_recording(recording: Path) -> None:
    """--frames A:B / --time A:B (every command that reads recordings has them) keep part of
    the usable frames; the rest are counted as outside_crop."""
    from scrapcut_cli.recording.reader import open_recording

    with open_recording(recording) as rec:
        stamps = rec.plan().stamps_ns
        start = rec.start_ns
    data = json.loads(_run(str(recording), "--frames", "1:3", "--json").stdout)
    assert data["frames"]["usable"] == 2 and data["frames"]["skip_reasons"]["outside_crop"] == 2
    # From just before the second usable frame to the end.
    t = (int(stamps[1]) - start) / 1e9 - 1e-6
    data = json.loads(_run(str(recording), "--time", f"{t}:", "--json").stdout)
    assert data["frames"]["usable"] == 3 and data["frames"]["skip_reasons"]["outside_crop"] == 1
    empty = _run(str(recording), "--frames", "7:9")
    assert empty.exit_code == 1
    assert "keep no frame: the recording has 4 usable frames (0:4)" in empty.stderr
    for bad in ("3:1", "x:2", "5", "1.5:3"):
        result = _run(str(recording), "--frames", bad)
        assert result.exit_code == 2 and "--frames" in result.output, bad
    replay = CliRunner().invoke(cli, ["explore", str(recording), "--frames", "0:2"])
    assert replay.exit_code == 2 and "a replay repeats its whole log" in replay.output
