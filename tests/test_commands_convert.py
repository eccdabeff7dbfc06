"""``scrapcut convert``: format from the output name, frames kept, one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import synthetic_scan, write_scan

from scrapcut_cli.cli import cli
from scrapcut_cli.recording.reader import open_recording


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("convert") / "scan.mcap"
    write_scan(path, synthetic_scan(n_frames=4), "mcap")
    return path


@pytest.mark.parametrize(
    ("output", "extra", "fmt"),
    [
        ("out.bag", [], "ros1"),
        ("out_dir", [], "ros2"),
        ("out_sqlite", ["--storage", "sqlite3"], "ros2"),
        ("out.mcap", [], "mcap"),
        ("run[red].bag", [], "ros1"),  # brackets are part of the name, not rich markup
        ("looks_like.mcap", ["--format", "ros2"], "ros2"),  # --format beats the suffix
    ],
)
def test_convert_and_read_back(
    recording: Path, tmp_path: Path, output: str, extra: list[str], fmt: str
) -> None:
    target = tmp_path / output
    result = CliRunner().invoke(cli, ["convert", str(recording), "-o", str(target), *extra])
    assert result.exit_code == 0, result.output
    assert f"wrote {target} ({fmt}, " in result.stderr
    with open_recording(recording) as a, open_recording(target) as b:
        assert b.format == fmt
        frames_a, frames_b = list(a.frames()), list(b.frames())
        assert len(frames_a) == len(frames_b) == 2  # frame 2 lacks depth, 3 lacks a pose
        for x, y in zip(frames_a, frames_b, strict=True):
            np.testing.assert_array_equal(x.color, y.color)
            np.testing.assert_array_equal(x.depth, y.depth)
            np.testing.assert_allclose(x.T_base_cam, y.T_base_cam, atol=1e-12)


def test_errors_are_one_line(recording: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    missing = runner.invoke(cli, ["convert", str(tmp_path / "no.mcap"), "-o", "x.bag"])
    assert missing.exit_code == 1
    assert missing.stderr.strip() == f"scrapcut: error: recording not found: {tmp_path / 'no.mcap'}"
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(recording.read_bytes()[:3000])
    truncated = runner.invoke(cli, ["convert", str(cut), "-o", str(tmp_path / "o.bag")])
    assert truncated.exit_code == 1
    assert len(truncated.stderr.strip().splitlines()) == 1
    assert "truncated" in truncated.stderr and "Traceback" not in truncated.output
    assert not (tmp_path / "o.bag").exists()
    usage = runner.invoke(cli, ["convert", str(recording)])
    assert usage.exit_code == 2  # -o is required


@pytest.mark.parametrize(
    ("output", "extra"),
    [("out.mcap", []), ("out.bag", []), ("out_dir", []), ("out_sqlite", ["--storage", "sqlite3"])],
)
def test_output_is_compressed_unless_asked_not_to(
    recording: Path, tmp_path: Path, output: str, extra: list[str]
) -> None:
    import json

    sizes = {}
    for compress in ("default", "none"):
        target = tmp_path / compress / output
        target.parent.mkdir()
        flag = [] if compress == "default" else ["--compress", "none"]
        args = ["convert", str(recording), "-o", str(target), "--json", *extra, *flag]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        summary = json.loads(result.stdout)
        assert summary["schema"] == "scrapcut.convert/v1" and summary["tool_version"]
        sizes[compress] = summary["size_bytes"]
        with open_recording(target) as rec:
            assert len(list(rec.frames())) == 2
    # The synthetic images are noise (they shrink by ~20 %; a real scan's by more): the default
    # output is compressed, --compress none is not.
    assert sizes["default"] < 0.9 * sizes["none"], sizes


def test_topics_keeps_only_those_named(recording: Path, tmp_path: Path) -> None:
    from helpers import SCAN_COLOR_TOPIC

    target = tmp_path / "tf_only.mcap"
    result = CliRunner().invoke(
        cli, ["convert", str(recording), "-o", str(target), "--topics", f"/tf,{SCAN_COLOR_TOPIC}"]
    )
    assert result.exit_code == 0, result.output
    with open_recording(recording) as a, open_recording(target) as b:
        assert [t.name for t in b.topics()] == [SCAN_COLOR_TOPIC, "/tf"]
        counts = {t.name: t.count for t in a.topics()}
        assert {t.name: t.count for t in b.topics()} == {
            "/tf": counts["/tf"],
            SCAN_COLOR_TOPIC: counts[SCAN_COLOR_TOPIC],
        }
        assert b.metadata == a.metadata


def test_convert_refusals_name_what_to_do(recording: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    missing = runner.invoke(
        cli, ["convert", str(recording), "-o", str(tmp_path / "x.mcap"), "--topics", "/nope"]
    )
    assert missing.exit_code == 1
    (line,) = missing.stderr.strip().splitlines()
    assert line.startswith(f"scrapcut: error: no topic /nope in {recording}; it has ")
    assert "/tf" in line
    zstd_bag = runner.invoke(
        cli, ["convert", str(recording), "-o", str(tmp_path / "x.bag"), "--compress", "zstd"]
    )
    assert zstd_bag.exit_code == 1
    assert "a ROS 1 bag cannot be compressed with zstd; it takes lz4, bz2, none" in (
        zstd_bag.stderr
    )
    assert not list(tmp_path.iterdir())
