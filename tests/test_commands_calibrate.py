"""``scrapcut calibrate``, ``--calibration`` and ``fit --self-calibrate`` through the CLI.

The recording is a synthetic eye-in-hand scan of the painted cylinder (160x120, /tf at 100 Hz,
the published mount on /tf_static in two links) whose camera really sits 1.5 mm / 0.3 deg off
and whose images are stamped 15 ms late, with frames while the arm moves.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from calibration_scenes import (
    DIVERSE_VIEWS,
    CalibrationScan,
    mount_error,
    write_calibration_recording,
)
from click.testing import CliRunner, Result
from helpers import one_line_error, tiny_recording
from perception_scenes import NOISY_LIGHT

from scrapcut_cli.cli import cli
from scrapcut_cli.evaluation.metrics import path_error
from scrapcut_cli.toolpath.pathfile import read_path_file

REQUIRED_KEYS = {
    "moving_frame",
    "camera_frame",
    "T_moving_camera",
    "published_T_moving_camera",
    "time_offset_s",
    "sigma",
    "observable",
    "residual_before_mm",
    "residual_after_mm",
}


def _run(*args: object) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def scan(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, CalibrationScan]:
    scan = CalibrationScan(
        views=DIVERSE_VIEWS[:5],
        error=mount_error((1.2, -0.6, 0.8), (0.2, 0.15, -0.2)),
        stamp_offset_s=0.015,
        moving_fps=4.0,
        noise=NOISY_LIGHT,
        seed=3,
    )
    path = tmp_path_factory.mktemp("calibrate") / "scan.mcap"
    write_calibration_recording(path, scan)
    return path, scan


@pytest.fixture(scope="module")
def calibrated(
    scan: tuple[Path, CalibrationScan], tmp_path_factory: pytest.TempPathFactory
) -> tuple[dict[str, object], Path]:
    path, _ = scan
    cal = tmp_path_factory.mktemp("cal") / "cal.yaml"
    result = _run("calibrate", path, "--json", "-o", cal)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["schema"] == "scrapcut.calibration/v1" and data["tool_version"]
    return data, cal


def test_calibrate_prints_the_fixed_keys_and_finds_the_injected_error(
    scan: tuple[Path, CalibrationScan], calibrated: tuple[dict[str, object], Path]
) -> None:
    _, truth = scan
    data, cal = calibrated
    assert set(data) >= REQUIRED_KEYS
    assert data["moving_frame"] == "panda_link8"
    assert data["camera_frame"] == "camera_color_optical_frame"
    assert data["consistent"] is False
    t = np.array(data["T_moving_camera"]["translation_m"])  # type: ignore[index]
    assert np.linalg.norm(t - truth.true_mount[:3, 3]) < 0.0006
    assert data["time_offset_s"] == pytest.approx(truth.true_time_offset_s, abs=0.002)
    assert data["residual_after_mm"] < data["residual_before_mm"]  # type: ignore[operator]
    assert cal.is_file() and "static_transform_publisher" in cal.read_text()


def test_fit_self_calibrated_lands_on_the_paint_and_records_the_calibration(
    scan: tuple[Path, CalibrationScan],
    calibrated: tuple[dict[str, object], Path],
    tmp_path: Path,
) -> None:
    # With the published mount this scan's path is 1.8 mm off the paint on average (measured);
    # corrected, what is left is the fit's own error at 160x120 (0.8 mm).
    path, truth = scan
    data, _ = calibrated
    out = tmp_path / "self.json"
    result = _run("fit", path, "--method", "nurbs", "-o", out, "--self-calibrate")
    assert result.exit_code == 0, result.output
    curve, _, rest = read_path_file(out)
    assert path_error(curve.points, truth.reference).mean_m < 0.0011
    record = rest["calibration"]
    assert record["origin"] == "self-calibrate" and record["consistent"] is False
    # The same estimate as scrapcut calibrate's (what --calibration CAL.yaml would apply).
    assert record["T_moving_camera"] == data["T_moving_camera"]
    assert record["time_offset_s"] == data["time_offset_s"]


def test_reproduces_self_calibrated_rows_are_fits_of_the_scan_posed_with_its_calibration(
    scan: tuple[Path, CalibrationScan], tmp_path: Path
) -> None:
    """What ``reproduce --self-calibrate`` adds to each scan: the same job as
    ``fit --self-calibrate``, its row marked, the correction among the row's figures."""
    from scrapcut_cli.config import ScrapcutConfig
    from scrapcut_cli.pipeline.reproduce import ScanTask, _self_calibrated_rows

    path, truth = scan
    (tmp_path / "paths").mkdir()
    config = ScrapcutConfig()
    task = ScanTask("synthetic_cylinder", 0, ("nurbs",), config.to_dict(), str(tmp_path),
                    "scan", self_calibrate=True)  # fmt: skip
    timings: dict[str, float] = {}
    (row,) = _self_calibrated_rows(task, config, path, timings)
    assert row.self_calibrated and row.label == "nurbs, self-calibrated"
    assert row.note == "calibration corrected"
    assert row.error is not None and row.error.mean_m < 0.0011  # 1.8 mm with the published one
    assert row.extras["calibration_clock_ms"] == pytest.approx(
        1000.0 * truth.true_time_offset_s, abs=2.0
    )
    # The injected translation is (1.2, -0.6, 0.8) mm: 1.56 mm long.
    assert row.extras["calibration_translation_mm"] == pytest.approx(1.56, abs=0.5)
    assert row.source == "paths/synthetic_cylinder_nurbs_selfcal.json"
    written = read_path_file(tmp_path / row.source)[2]
    assert written["calibration"]["origin"] == "self-calibrate"
    assert set(timings) == {"self_calibrate", "fit_selfcal_nurbs"}


def test_stitch_and_filter_take_a_calibration(
    scan: tuple[Path, CalibrationScan],
    calibrated: tuple[dict[str, object], Path],
    tmp_path: Path,
) -> None:
    path, _ = scan
    _, cal = calibrated
    result = _run("stitch", path, "-o", tmp_path / "c.ply", "--calibration", cal, "--json")
    assert result.exit_code == 0, result.output
    result = _run("filter", path, "--calibration", cal, "--json")
    assert result.exit_code == 0, result.output


def test_calibration_errors_are_one_line(
    scan: tuple[Path, CalibrationScan],
    calibrated: tuple[dict[str, object], Path],
    tmp_path: Path,
) -> None:
    path, _ = scan
    _, cal = calibrated
    both = _run("fit", path, "-o", tmp_path / "p.json", "--self-calibrate", "--calibration", cal)
    assert both.exit_code == 2 and "drop --calibration" in both.output
    line = one_line_error(_run("fit", path, "-o", tmp_path / "p.json", "--calibration", "no.yaml"))
    assert "calibration file not found" in line
    other = tmp_path / "other.yaml"
    other.write_text(cal.read_text().replace('"panda_link8"', '"panda_hand"'))
    line = one_line_error(_run("stitch", path, "-o", tmp_path / "c.ply", "--calibration", other))
    assert "mounts the camera on 'panda_hand'" in line
    single = tiny_recording(tmp_path / "one.mcap")
    line = one_line_error(_run("calibrate", single))
    assert "1 usable frame" in line
    assert not (tmp_path / "p.json").exists()
