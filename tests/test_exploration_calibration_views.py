"""Calibration views: tilt and roll diversity over paint already seen makes the mount observable."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from calibration_scenes import (
    PARALLEL_VIEWS,
    CalibrationScan,
    look_down,
    mount_error,
    write_calibration_recording,
)
from click.testing import CliRunner
from exploration_scenes import REACH_ALL, CylinderScan, explore
from perception_scenes import CYLINDER_AXIS_YZ, CYLINDER_RADIUS_M, NOISY
from scipy.spatial.transform import Rotation

from scrapcut_cli.cli import cli
from scrapcut_cli.config import ScrapcutConfig
from scrapcut_cli.exploration.calibration_views import CALIBRATION_REASON, calibration_view_poses
from scrapcut_cli.exploration.planner import ExplorationPlanner
from scrapcut_cli.perception.paint import PAINT_PRESETS

TARGET = np.array([0.0, CYLINDER_AXIS_YZ[0], CYLINDER_AXIS_YZ[1] + CYLINDER_RADIUS_M])


def test_views_look_at_the_target_from_tilted_rolled_directions() -> None:
    poses = calibration_view_poses(
        TARGET, [0, 0, 1], [1, 0, 0], count=5, distance_m=0.3, tilt_deg=25.0
    )
    assert len(poses) == 5
    rotvecs = []
    for T in poses:
        to_target = TARGET - T[:3, 3]
        assert np.linalg.norm(to_target) == pytest.approx(0.3)
        assert np.allclose(T[:3, 2], to_target / 0.3)  # optical axis through the target
        assert np.degrees(np.arccos(-T[2, 2])) == pytest.approx(25.0)  # tilted off the normal
        assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3))
    for a in poses:
        for b in poses:
            rotvecs.append(Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).as_rotvec())
    # Rotations between views about axes spanning all three directions.
    singular = np.linalg.svd(np.array(rotvecs), compute_uv=False)
    assert singular[2] > 0.2 * singular[0]
    assert calibration_view_poses(TARGET, [0, 0, 1], [1, 0, 0], count=0, distance_m=0.3) == []


def test_calibration_views_make_the_mount_observable_and_calibrate_says_how_much(
    tmp_path: Path,
) -> None:
    # Four of the solver tests' parallel views (translation and clock unobservable), then three
    # calibration views of the middle, one frame on each move; the log marks them.
    extra = calibration_view_poses(
        TARGET, [0, 0, 1], [1, 0, 0], count=3, distance_m=0.28, tilt_deg=25.0
    )
    views = [look_down(**v) for v in PARALLEL_VIEWS[1:5]] + extra
    scan = CalibrationScan(
        views=views,
        error=mount_error((1.5, -1.0, 0.8), (0.3, -0.2, 0.25)),
        stamp_offset_s=0.015,
        moving_fps=2.0,
        noise=NOISY,
    )
    reasons = ["extrapolate"] * 3 + [CALIBRATION_REASON] * 3 + ["done"]
    path = tmp_path / "scan.mcap"
    write_calibration_recording(path, scan, reasons=reasons)
    result = CliRunner().invoke(cli, ["calibrate", str(path), "--json"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["observable"] == {
        "translation": [True, True, True],
        "rotation": [True, True, True],
        "time_offset": True,
    }
    effect = data["calibration_views"]
    # Sliding along the pipe hid the translation and the rotation about the pipe; the frames
    # on the moves between the parallel views already showed the clock.
    assert set(effect["became_observable"]) == {"tx_mm", "ty_mm", "tz_mm", "ry_deg"}
    assert effect["frames"] == 6  # three views and the frame on each move to them
    ratio = dict(zip(effect["units"], effect["sigma_ratio"], strict=True))
    assert ratio["rx_deg"] > 1.0  # observable before, narrowed by the views
    t = np.array(data["correction"]["translation_m"]) * 1000.0
    np.testing.assert_allclose(t, (1.5, -1.0, 0.8), atol=0.35)
    assert data["correction"]["time_offset_s"] == pytest.approx(-0.015, abs=0.001)


def test_the_planner_ends_with_calibration_views_of_the_first_stretch() -> None:
    scan = CylinderScan()
    config = ScrapcutConfig().override("exploration", calibration_views=3)
    planner = ExplorationPlanner(
        scan.initial_view, reachable=REACH_ALL, hsv=PAINT_PRESETS["orange"].hsv, config=config
    )
    loop = explore(planner, scan)
    reasons = [d.reason for d in loop.decisions]
    assert reasons[-4:] == [CALIBRATION_REASON] * 3 + ["done"]
    assert CALIBRATION_REASON not in reasons[:-4] and planner.endpoints_found == 2
    views = [d.T_base_cam for d in loop.decisions if d.reason == CALIBRATION_REASON]
    # All look at one point of the first view's paint, from directions 30 deg off the pipe's
    # top normal (+z there) and at different rolls.
    eye0, axis0 = scan.initial_view[:3, 3], scan.initial_view[:3, 2]
    targets = []
    for T in views:
        assert T is not None
        # Where the optical axis meets the horizontal plane of the pipe's top.
        t = (CYLINDER_AXIS_YZ[1] + CYLINDER_RADIUS_M - T[2, 3]) / T[2, 2]
        targets.append(T[:3, 3] + t * T[:3, 2])
        assert np.degrees(np.arccos(-T[2, 2])) == pytest.approx(30.0, abs=3.0)
    assert np.ptp(np.array(targets), axis=0).max() < 0.005
    t0 = (targets[0][2] - eye0[2]) / axis0[2]
    assert np.linalg.norm(eye0 + t0 * axis0 - targets[0]) < 0.03
    x_axes = np.array([T[:3, 0] for T in views if T is not None])
    assert np.abs(x_axes @ x_axes.T - np.eye(3)).max() < 0.99  # no two rolls alike
