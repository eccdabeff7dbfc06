"""Calibration views: tilt and roll diversity over paint already seen makes the mount observable."""

from __future__ import annotations

import numpy as np
import pytest
from calibration_scenes import PARALLEL_VIEWS, CalibrationScan, look_down, mount_error
from perception_scenes import CYLINDER_AXIS_YZ, CYLINDER_RADIUS_M, NOISY
from scipy.spatial.transform import Rotation

from scrapcut_cli.calibration.observations import observe_frame
from scrapcut_cli.calibration.solver import solve
from scrapcut_cli.config import CalibrationConfig, PaintConfig, PerceptionConfig
from scrapcut_cli.exploration.calibration_views import calibration_view_poses
from scrapcut_cli.perception.paint import resolve_paint

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


def test_calibration_views_make_translation_and_clock_observable() -> None:
    # Four of the parallel views of the solver tests (translation and clock unobservable), then
    # three calibration views of the middle, and a frame on each move.
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
    hsv = resolve_paint(PaintConfig(preset="orange"))
    config = CalibrationConfig()
    obs = [
        observe_frame(f, hsv, config=config, perception=PerceptionConfig()) for f in scan.frames()
    ]
    solution = solve(obs, scan.trajectory, scan.published, config)
    assert solution.observable.all(), [d.what for d in solution.unobservable]
    np.testing.assert_allclose(solution.correction[:3], (1.5, -1.0, 0.8), atol=0.35)
    assert solution.correction[6] == pytest.approx(-15.0, abs=1.0)
