"""``scrapcut stitch`` through click's CliRunner on a small synthetic recording."""

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
from scrapcut_cli.config import ScrapcutConfig
from scrapcut_cli.perception.paint import PAINT_PRESETS
from scrapcut_cli.perception.stitch import stitch_recording
from scrapcut_cli.recording.reader import open_recording


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    reference = cylinder_top_line()
    frames = [
        render_cylinder(small_camera(), top_view(x), reference, noise=NOISY_LIGHT, seed=i, index=i)
        for i, x in enumerate(np.linspace(-0.1, 0.1, 5))
    ]
    path = tmp_path_factory.mktemp("rec") / "scene.mcap"
    write_scene_recording(path, frames, reference=reference)
    return path


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.stdout, result.stderr


def read_points(path: Path) -> np.ndarray:
    return np.asarray(o3d().io.read_point_cloud(str(path)).points)


def test_stitch_writes_the_libraries_cloud_and_growth_json(recording: Path, tmp_path: Path) -> None:
    cloud, surface = tmp_path / "paint.ply", tmp_path / "surface.pcd"
    code, out, err = run(
        "stitch", str(recording), "-o", str(cloud), "--surface", str(surface), "--json"
    )
    assert code == 0, err
    summary = json.loads(out)
    assert summary["schema"] == "scrapcut.stitch/v1" and summary["tool_version"]
    with open_recording(recording) as rec:
        expected = stitch_recording(rec.frames(), PAINT_PRESETS["orange"].hsv, ScrapcutConfig())
    assert summary["size"] == expected.size == len(read_points(cloud))
    np.testing.assert_allclose(read_points(cloud), expected.paint_points, atol=1e-12)
    np.testing.assert_allclose(read_points(surface), expected.surface_points, atol=1e-6)  # f32
    steps = summary["steps"]
    assert [s["growth"] for s in steps] == [s.growth for s in expected.steps]
    assert sum(s["growth"] for s in steps) == summary["size"]
    assert summary["config"]["stitch"]["voxel_size_m"] == 0.002
    assert sorted(p.name for p in tmp_path.iterdir()) == ["paint.ply", "surface.pcd"]


def test_table_and_options(recording: Path, tmp_path: Path) -> None:
    cloud = tmp_path / "coarse.pcd"
    code, out, err = run(
        "stitch", str(recording), "-o", str(cloud), "--stitch-voxel-mm", "5", "--icp"
    )
    assert code == 0, err
    assert "paint voxels (size)" in out and "ICP corrections accepted" in out
    fine = tmp_path / "fine.pcd"
    assert run("stitch", str(recording), "-o", str(fine))[0] == 0
    assert len(read_points(cloud)) < len(read_points(fine)) / 3  # 5 mm voxels vs 2 mm


def test_no_paint_fails_in_one_line_and_writes_nothing(recording: Path, tmp_path: Path) -> None:
    cloud = tmp_path / "paint.ply"
    code, _, err = run("stitch", str(recording), "-o", str(cloud), "--hsv", "190,250,0.5,0.2")
    assert code == 1
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "no paint found in any of 5 frames with custom (hue 190-250 deg" in err
    assert list(tmp_path.iterdir()) == []


def test_empty_surface_fails_before_either_cloud_is_written(
    recording: Path, tmp_path: Path
) -> None:
    cloud, surface = tmp_path / "paint.ply", tmp_path / "surface.ply"
    args = ["stitch", str(recording), "-o", str(cloud), "--surface", str(surface)]
    code, _, err = run(*args, "--surface-band-mm", "0")
    assert code == 1 and err.count("\n") == 1
    assert "no surface points to write to" in err and "--surface-band-mm" in err
    assert list(tmp_path.iterdir()) == []  # not the paint cloud alone either


def test_usage_errors(recording: Path, tmp_path: Path) -> None:
    assert run("stitch", str(recording), "-o", str(tmp_path / "a.xyz"))[0] == 2
    same = str(tmp_path / "a.ply")
    assert run("stitch", str(recording), "-o", same, "--surface", same)[0] == 2
    assert run("stitch", str(recording))[0] == 2  # -o is required


def test_missing_recording_is_a_known_error(tmp_path: Path) -> None:
    code, _, err = run("stitch", str(tmp_path / "nope.mcap"), "-o", str(tmp_path / "a.ply"))
    assert code == 1 and err.startswith("scrapcut: error:") and "Traceback" not in err
