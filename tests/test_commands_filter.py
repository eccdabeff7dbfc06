"""``scrapcut filter`` through click's CliRunner on a small synthetic recording."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from perception_scenes import (
    NOISY_LIGHT,
    cylinder_top_line,
    render_cylinder,
    small_camera,
    top_view,
    write_scene_recording,
)

from scrapcut_cli._open3d import o3d
from scrapcut_cli.cli import cli
from scrapcut_cli.config import PerceptionConfig
from scrapcut_cli.perception.cloud import process_frame
from scrapcut_cli.perception.paint import PAINT_PRESETS
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.recording.reader import open_recording


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Frame]]:
    """Five views along the stroke, and one grey frame looking at the floor."""
    reference = cylinder_top_line()
    views = [top_view(x) for x in np.linspace(-0.1, 0.1, 5)]
    frames = [
        render_cylinder(small_camera(), T, reference, noise=NOISY_LIGHT, seed=i, index=i)
        for i, T in enumerate(views)
    ]
    floor = render_cylinder(small_camera(), top_view(0.6), reference, index=5)
    path = tmp_path_factory.mktemp("rec") / "scene.mcap"
    write_scene_recording(path, [*frames, floor], reference=reference)
    with open_recording(path) as rec:  # depth went through 16UC1 millimetres
        read = list(rec.frames())
    return path, read


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.stdout, result.stderr


def test_summary_only(scene: tuple[Path, list[Frame]]) -> None:
    path, _ = scene
    code, out, err = run("filter", str(path))
    assert code == 0, err
    assert "frames with paint" in out and "no_paint 1" in out


def test_mcap_output_holds_one_base_frame_cloud_per_frame(
    scene: tuple[Path, list[Frame]], tmp_path: Path
) -> None:
    path, frames = scene
    target = tmp_path / "paint.mcap"
    code, out, err = run("filter", str(path), "-o", str(target), "--with-surface", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["schema"] == "scrapcut.filter/v1" and summary["tool_version"]
    assert summary["frames"] == 6 and summary["frames_with_paint"] == 5
    assert summary["skip_reasons"] == {"no_paint": 1}
    hsv = PAINT_PRESETS["orange"].hsv
    expected = [process_frame(f, hsv, PerceptionConfig()) for f in frames]
    assert summary["paint_points"] == sum(len(c.paint_base) for c in expected)
    with open_recording(target) as rec:
        paint = list(rec.messages(["/scrapcut/paint"]))
        surface = list(rec.messages(["/scrapcut/surface"]))
        assert rec.metadata["scrapcut"]["kind"] == "paint_clouds"
    assert len(paint) == len(surface) == 6  # the paint-less frame clears the view
    for (_, stamp, msg), clouds in zip(paint, expected, strict=True):
        assert stamp == clouds.stamp_ns and msg.header.frame_id == "panda_link0"
        assert msg.width * msg.height == len(clouds.paint_base)
        assert [f.name for f in msg.fields] == ["x", "y", "z", "rgb"]
        xyz = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(-1, msg.point_step)
        points = xyz[:, :12].copy().view("<f4").reshape(-1, 3)
        np.testing.assert_allclose(points, clouds.paint_base, atol=1e-6)  # float32


def test_ply_folder(scene: tuple[Path, list[Frame]], tmp_path: Path) -> None:
    path, frames = scene
    target = tmp_path / "clouds"
    code, _, err = run("filter", str(path), "-o", str(target), "--voxel-mm", "4")
    assert code == 0, err
    names = sorted(p.name for p in target.iterdir())
    assert names == [f"paint_{i:06d}.ply" for i in range(5)]
    config = PerceptionConfig(voxel_size_m=0.004)
    clouds = process_frame(frames[2], PAINT_PRESETS["orange"].hsv, config)
    read = np.asarray(o3d().io.read_point_cloud(str(target / "paint_000002.ply")).points)
    np.testing.assert_allclose(read, clouds.paint_base, atol=1e-12)
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_no_paint_is_one_line_naming_range_and_hues_and_writes_nothing(
    scene: tuple[Path, list[Frame]], tmp_path: Path
) -> None:
    path, _ = scene
    target = tmp_path / "paint.mcap"
    code, _, err = run("filter", str(path), "--paint", "blue", "-o", str(target))
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].startswith("scrapcut: error: no paint found in any of 6 frames with blue")
    assert "dominant hues seen: 30 deg" in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_depth_options_reach_the_filter(scene: tuple[Path, list[Frame]]) -> None:
    path, _ = scene
    code, _, err = run("filter", str(path), "--min-depth-mm", "5000", "--max-depth-mm", "6000")
    assert code == 1 and "no usable paint points" in err and "no_valid_depth 5" in err


def test_the_recordings_paint_is_the_default(
    scene: tuple[Path, list[Frame]], tmp_path: Path
) -> None:
    _, frames = scene
    green = tmp_path / "green.mcap"
    write_scene_recording(green, frames[:2], paint="green")
    code, _, err = run("filter", str(green))
    assert code == 1 and "with green (hue 85-165 deg" in err
    code, out, err = run("filter", str(green), "--paint", "orange", "--json")
    assert code == 0, err
    assert json.loads(out)["frames_with_paint"] == 2


def test_bad_output_name_is_a_usage_error(scene: tuple[Path, list[Frame]]) -> None:
    path, _ = scene
    code, _, err = run("filter", str(path), "-o", "clouds.ply")
    assert code == 2 and ".mcap" in err


def test_an_existing_folder_is_replaced_only_if_filter_wrote_it(
    scene: tuple[Path, list[Frame]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path, _ = scene
    data = tmp_path / "data"
    data.mkdir()
    (data / "notes.txt").write_text("keep me")
    code, _, err = run("filter", str(path), "-o", str(data))
    assert code == 2 and "would be replaced as a whole" in err
    assert (data / "notes.txt").read_text() == "keep me"
    monkeypatch.chdir(data)
    code, _, err = run("filter", str(path), "-o", ".")
    assert code == 2 and "holds the current folder" in err
    assert sorted(p.name for p in data.iterdir()) == ["notes.txt"]
    # A folder an earlier run wrote is replaced whole: no stale frame survives.
    clouds = tmp_path / "clouds"
    assert run("filter", str(path), "-o", str(clouds))[0] == 0
    (clouds / "paint_000099.ply").write_text("stale")
    assert run("filter", str(path), "-o", str(clouds))[0] == 0
    assert len(list(clouds.iterdir())) == 5 and not (clouds / "paint_000099.ply").exists()
    (tmp_path / "file").write_text("")
    code, _, err = run("filter", str(path), "-o", str(tmp_path / "file"))
    assert code == 2 and "is not a folder" in err


def test_the_recording_is_not_overwritten(scene: tuple[Path, list[Frame]]) -> None:
    path, _ = scene
    before = path.read_bytes()
    code, _, err = run("filter", str(path), "-o", str(path))
    assert code == 2 and "is the recording itself" in err
    assert path.read_bytes() == before
