"""Tests of ``scrapcut record`` through click's CliRunner."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from scrapcut_cli.cli import cli
from scrapcut_cli.recording.reader import open_recording
from scrapcut_cli.sim import list_objects


def _reject(constant: str) -> None:
    raise AssertionError(f"metadata is not strict JSON: {constant}")


def test_object_list_prints_every_piece() -> None:
    result = CliRunner().invoke(cli, ["record", "--object", "list"])
    assert result.exit_code == 0, result.output
    for name, _ in list_objects():
        assert name in result.output


def test_record_writes_a_readable_mcap_with_the_options_applied(tmp_path: Path) -> None:
    out = tmp_path / "box.mcap"
    args = [
        "record",
        "--object",
        "planar_box",
        "--noise",
        "ideal",
        "--paint",
        "green",
        "--seed",
        "9",
        "--width",
        "48",
        "--height",
        "36",
        "--views",
        "2",
        "--stroke-width-mm",
        "30",
        "--distance-mm",
        "320",
        "--depth-encoding",
        "32FC1",
        "-o",
        str(out),
    ]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "views executed" in result.output
    with open_recording(out) as rec:
        meta = rec.metadata["scrapcut"]
        assert (meta["object"], meta["noise"], meta["paint"], meta["seed"]) == (
            "planar_box",
            "ideal",
            "green",
            "9",
        )
        params = json.loads(meta["params"], parse_constant=_reject)  # strict JSON, no Infinity
        assert params["noise_preset"]["max_z_m"] == "inf"
        assert params["sim"]["view_distance_m"] == 0.32
        assert float(meta["stroke_width_m"]) == 0.03
        assert rec.plan().usable == 2 and rec.camera.width == 48


def test_explore_mode_runs_algorithm_1_and_logs_its_steps(tmp_path: Path) -> None:
    out = tmp_path / "explore.mcap"
    args = ["record", "--mode", "explore", "--object", "planar_box", "--method", "skeleton"]
    args += ["--hsv", "5,45,0.6,0.3", "--width", "96", "--height", "72"]
    result = CliRunner().invoke(cli, [*args, "-o", str(out)])
    assert result.exit_code == 0, result.output
    with open_recording(out) as rec:
        log = rec.exploration_log()
        frames = rec.plan().usable
        assert rec.metadata["scrapcut"]["mode"] == "explore"
    assert frames >= 2 and len(log) == frames  # one decision logged per observed view
    assert log[-1]["stop"] is True
    # The summary says what the robot's collision checks saw, and that nothing was hit.
    assert "what the camera observed" in result.stdout
    assert "0 (0 moving)" in result.stdout
    # --method and --hsv reach the planner; the piece is still painted with the preset.
    assert log[0]["method"] == "skeleton"
    hsv = log[0]["paint_hsv"]
    assert (hsv["hue_min_deg"], hsv["hue_max_deg"], hsv["sat_min"], hsv["val_min"]) == (
        5.0,
        45.0,
        0.6,
        0.3,
    )


def test_config_file_sets_simulator_parameters(tmp_path: Path) -> None:
    config = tmp_path / "sim.toml"
    config.write_text("[sim]\nobject = 'slanted'\nviews = 1\nwidth = 32\nheight = 24\n")
    out = tmp_path / "s.mcap"
    result = CliRunner().invoke(cli, ["record", "--config", str(config), "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    printed = json.loads(result.stdout)  # strict JSON: an infinite clearance is null
    assert printed["schema"] == "scrapcut.record/v1" and printed["tool_version"]
    assert printed["object"] == "slanted" and printed["path"] == str(out)
    assert printed["size_bytes"] == out.stat().st_size
    with open_recording(out) as rec:
        assert rec.metadata["scrapcut"]["object"] == "slanted"


def test_known_errors_are_one_line_with_exit_code_one(tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    for args, message in (
        (["--object", "anvil"], "unknown object 'anvil'"),
        (["--paint", "mauve"], "unknown paint preset 'mauve'"),
    ):
        result = CliRunner().invoke(cli, ["record", *args, "-o", str(out)])
        assert result.exit_code == 1, result.output
        lines = [line for line in result.output.splitlines() if line.startswith("scrapcut: error")]
        assert len(lines) == 1 and message in lines[0]
        assert "Traceback" not in result.output
    assert not out.exists()


def test_usage_errors_exit_with_two(tmp_path: Path) -> None:
    assert CliRunner().invoke(cli, ["record"]).exit_code == 2  # no -o
    bad = CliRunner().invoke(cli, ["record", "--noise", "foggy", "-o", str(tmp_path / "x.mcap")])
    assert bad.exit_code == 2
    # MCAP or a ROS 2 bag folder: a file named scan.bag would not open in any reader.
    bag = CliRunner().invoke(cli, ["record", "--views", "1", "-o", str(tmp_path / "scan.bag")])
    assert bag.exit_code == 2 and "convert` makes a ROS 1 bag" in bag.output
    for option, value, message in (
        ("--resolution", "1280by720", "expected WIDTHxHEIGHT"),
        ("--distractors", "box,anvil", "unknown distractor 'anvil'"),
    ):
        result = CliRunner().invoke(cli, ["record", option, value, "-o", str(tmp_path / "a")])
        assert result.exit_code == 2 and message in result.output
    both = ["record", "--resolution", "64x36", "--width", "64", "-o", str(tmp_path / "a")]
    assert CliRunner().invoke(cli, both).exit_code == 2
    assert list(tmp_path.iterdir()) == []


def test_realsense_ros_defaults_jpeg_colour_in_a_ros2_sqlite3_bag(tmp_path: Path) -> None:
    """--resolution, JPEG colour on .../compressed only, a ROS 2 bag with sqlite3 storage;
    distractors and an old mark in the scene (and in the metadata)."""
    out = tmp_path / "scan"
    args = ["record", "--object", "planar_box", "--noise", "ideal", "--views", "1"]
    args += ["--resolution", "64x36", "--color-encoding", "jpeg", "--jpeg-quality", "80"]
    args += ["--distractors", "box", "--faded-marks", "1", "--glints", "-o", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert any(p.suffix == ".db3" for p in out.iterdir())
    with open_recording(out) as rec:
        assert rec.format == "ros2"
        names = {t.name for t in rec.topics()}
        assert "/camera/camera/color/image_raw/compressed" in names
        assert "/camera/camera/color/image_raw" not in names
        assert (rec.camera.width, rec.camera.height) == (64, 36)
        assert abs(rec.camera.fx - rec.camera.fy) < 0.5  # 16:9 pixels are square
        params = json.loads(rec.metadata["scrapcut"]["params"])
        scene = params["scene"]
        assert [d["kind"] for d in scene["distractors"]] == ["box"]
        assert len(scene["faded_marks"]) == 1 and scene["glints"] is True
        assert params["sim"]["color_encoding"] == "jpeg"
        assert rec.plan().usable == 1
