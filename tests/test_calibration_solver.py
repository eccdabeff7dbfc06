"""Self-calibration on synthetic scans with a known hand-eye error and clock offset.

Frames of the painted cylinder (160x120, depth noise 0.5 mm, holes, flying pixels) are posed as
a reader would with the published mount; the solver must find the injected error from the
frames' disagreement alone, say what it cannot see and why, and leave a true calibration alone.
Tolerances: at 160x120 a pixel is 1.8 mm on the surface, so the paint edges are coarse (at
640x480 the simulator's recordings come out 4x tighter, see benchmarks/bench_calibrate.py).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from calibration_scenes import (
    DIVERSE_VIEWS,
    PARALLEL_VIEWS,
    CalibrationScan,
    mount_error,
)
from perception_scenes import CYLINDER_AXIS_YZ, CYLINDER_RADIUS_M, NOISY, SceneNoise

from scrapcut_cli.calibration.observations import FrameObservation, observe_frame
from scrapcut_cli.calibration.result import CONSISTENT, Calibration
from scrapcut_cli.calibration.solver import PARAMETERS, solve
from scrapcut_cli.config import CalibrationConfig, PaintConfig, PerceptionConfig
from scrapcut_cli.errors import CalibrationError
from scrapcut_cli.geometry import PolylineDistance, transform_points
from scrapcut_cli.perception.paint import resolve_paint
from scrapcut_cli.recording.mount import CameraMount

ERROR_MM = (1.5, -1.0, 0.8)
ERROR_DEG = (0.3, -0.2, 0.25)
STAMP_OFFSET_S = 0.015
HSV = resolve_paint(PaintConfig(preset="orange"))
CONFIG = CalibrationConfig()


def _observe(scan: CalibrationScan) -> list[FrameObservation]:
    return [
        observe_frame(f, HSV, config=CONFIG, perception=PerceptionConfig()) for f in scan.frames()
    ]


@pytest.fixture(scope="module")
def moving_scan() -> tuple[CalibrationScan, list[FrameObservation]]:
    """Six views with tilt and roll diversity, 4 frames on each move, images 15 ms late."""
    scan = CalibrationScan(
        views=DIVERSE_VIEWS,
        error=mount_error(ERROR_MM, ERROR_DEG),
        stamp_offset_s=STAMP_OFFSET_S,
        moving_fps=5.0,
        noise=NOISY,
    )
    return scan, _observe(scan)


@pytest.fixture(scope="module")
def parallel_scan() -> tuple[CalibrationScan, list[FrameObservation]]:
    """Six views that share one orientation, images at rest only."""
    scan = CalibrationScan(
        views=PARALLEL_VIEWS, error=mount_error(ERROR_MM, ERROR_DEG), noise=NOISY
    )
    return scan, _observe(scan)


def test_recovers_an_injected_mount_error_and_clock_offset(
    moving_scan: tuple[CalibrationScan, list[FrameObservation]],
) -> None:
    scan, obs = moving_scan
    solution = solve(obs, scan.trajectory, scan.published, CONFIG)
    x = solution.correction
    assert solution.observable.all()
    assert not solution.unobservable
    np.testing.assert_allclose(x[:3], ERROR_MM, atol=0.35)  # mm
    np.testing.assert_allclose(x[3:6], ERROR_DEG, atol=0.05)  # deg
    assert x[6] == pytest.approx(-1000 * STAMP_OFFSET_S, abs=1.0)  # ms
    # Standard deviations are finite and small against the error; the fit explains the data.
    assert np.all(np.isfinite(solution.sigma))
    assert np.all(solution.sigma[:3] < 0.2) and np.all(solution.sigma[3:6] < 0.05)
    assert solution.residual_after_mm["all"] < 0.7 * solution.residual_before_mm["all"]
    calibration = Calibration.decide(solution, scan.published, CONFIG)
    assert not calibration.consistent
    assert "corrected" in calibration.verdict
    T_true = scan.true_mount
    T = calibration.mount.T_moving_camera
    assert np.linalg.norm(T[:3, 3] - T_true[:3, 3]) < 0.0005
    assert calibration.mount.time_offset_s == pytest.approx(-STAMP_OFFSET_S, abs=0.001)


def test_a_true_calibration_is_reported_consistent_and_kept(
    moving_scan: tuple[CalibrationScan, list[FrameObservation]],
) -> None:
    # The same frames, now published with the true mount and clock offset.
    scan, obs = moving_scan
    truth = CameraMount(
        scan.published.moving_frame,
        scan.published.camera_frame,
        scan.true_mount,
        scan.true_time_offset_s,
    )
    solution = solve(obs, scan.trajectory, truth, CONFIG)
    assert np.all(np.abs(solution.correction[:3]) < 0.35)
    calibration = Calibration.decide(solution, truth, CONFIG)
    assert calibration.consistent, solution.correction
    assert calibration.verdict == CONSISTENT
    assert calibration.mount is truth


def test_views_that_share_one_orientation_leave_translation_and_clock_unobservable(
    parallel_scan: tuple[CalibrationScan, list[FrameObservation]],
) -> None:
    scan, obs = parallel_scan
    solution = solve(obs, scan.trajectory, scan.published, CONFIG)
    observable = dict(zip(PARAMETERS, solution.observable, strict=True))
    assert not any(observable[p] for p in ("tx_mm", "ty_mm", "tz_mm", "dt_ms"))
    # Held at the published values, not moved by noise.
    np.testing.assert_array_equal(solution.correction[[0, 1, 2, 6]], 0.0)
    assert np.all(np.isnan(solution.sigma[[0, 1, 2, 6]]))
    reasons = " | ".join(f"{d.what}: {d.why}" for d in solution.unobservable)
    assert "all views share one orientation" in reasons
    assert "the arm never moved while images were taken" in reasons
    # The camera only slid along the pipe (camera y): rotation about that line is invisible
    # too; rotations about the other axes show as the views drift apart and are found.
    assert not observable["ry_deg"]
    assert "rotation about camera y" in reasons and "moved along one line" in reasons
    assert observable["rx_deg"] and observable["rz_deg"]
    assert solution.correction[3] == pytest.approx(ERROR_DEG[0], abs=0.05)
    assert solution.correction[5] == pytest.approx(ERROR_DEG[2], abs=0.05)
    calibration = Calibration.decide(solution, scan.published, CONFIG)
    assert calibration.to_dict()["observable"] == {
        "translation": [False, False, False],
        "rotation": [True, False, True],
        "time_offset": False,
    }


def test_the_estimate_does_not_depend_on_where_the_base_frame_is(
    parallel_scan: tuple[CalibrationScan, list[FrameObservation]],
) -> None:
    # Moving the whole cell (base frame) by a rigid motion changes no camera-frame measurement.
    scan, obs = parallel_scan
    W = np.eye(4)
    W[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    W[:3, 3] = [1.0, -2.0, 0.5]

    def moved(stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        T, valid = scan.trajectory(stamps)
        return W @ T, valid

    moved_obs = [dataclasses.replace(o, T_base_cam=W @ o.T_base_cam) for o in obs]
    a = solve(obs, scan.trajectory, scan.published, CONFIG)
    b = solve(moved_obs, moved, scan.published, CONFIG)
    np.testing.assert_allclose(a.correction, b.correction, atol=1e-6)


def test_observations_lie_on_the_surface_and_on_the_paint_edge() -> None:
    scan = CalibrationScan(views=DIVERSE_VIEWS[:2], noise=SceneNoise())
    frame = scan.frames()[1]
    ob = observe_frame(frame, HSV, config=CONFIG, perception=PerceptionConfig())
    T = frame.T_base_cam  # published = true here
    y0, z0 = CYLINDER_AXIS_YZ
    for points, normals in ((ob.surface, ob.normals), (ob.edges, None)):
        P = transform_points(T, points)
        radial = np.hypot(P[:, 1] - y0, P[:, 2] - z0)
        # Every sample is on the pipe or the floor (exact depth: to rounding).
        on_surface = np.minimum(np.abs(radial - CYLINDER_RADIUS_M), np.abs(P[:, 2]))
        assert np.quantile(on_surface, 0.99) < 1e-4
        if normals is not None:
            n = normals @ T[:3, :3].T
            pipe = np.abs(radial - CYLINDER_RADIUS_M) < 1e-4
            true_n = (
                np.column_stack([np.zeros(pipe.sum()), (P[pipe, 1] - y0), (P[pipe, 2] - z0)])
                / CYLINDER_RADIUS_M
            )
            cos = np.einsum("ij,ij->i", n[pipe], true_n)
            assert np.median(cos) > np.cos(np.radians(3.0))
    # Edge points sit half a stroke from the painted centre line, within a pixel (1.8 mm).
    edges = transform_points(T, ob.edges)
    d = PolylineDistance(scan.reference).distance(edges)
    assert len(edges) > 100
    assert np.median(np.abs(d - 0.0125)) < 0.001
    # Across-edge directions lie in the surface.
    assert np.all(np.abs(np.linalg.norm(ob.edge_across, axis=1) - 1.0) < 1e-9)


def test_too_little_to_compare_is_one_clear_error(
    parallel_scan: tuple[CalibrationScan, list[FrameObservation]],
) -> None:
    scan, obs = parallel_scan
    with pytest.raises(CalibrationError, match="at least 2"):
        solve(obs[:1], scan.trajectory, scan.published, CONFIG)
    far = dataclasses.replace(obs[1], T_base_cam=obs[1].T_base_cam.copy())
    far.T_base_cam[:3, 3] += 5.0  # a view of somewhere else entirely
    with pytest.raises(CalibrationError, match="overlap"):
        solve([obs[0], far], scan.trajectory, scan.published, CONFIG)
