"""Tests of the camera model and Frame validation (scrapcut_cli.recording.frame)."""

from __future__ import annotations

import numpy as np
import pytest

from scrapcut_cli.recording.frame import CameraModel, Frame

D435I = dict(width=640, height=480, fx=615.0, fy=615.0, cx=319.5, cy=239.5)


@pytest.mark.parametrize(
    ("model", "coeffs"),
    [
        ("none", ()),
        ("plumb_bob", (0.12, -0.25, 0.001, -0.0015, 0.08)),
        ("rational_polynomial", (0.1, -0.2, 0.001, 0.001, 0.05, 0.01, -0.02, 0.01)),
        ("equidistant", (0.05, -0.01, 0.002, -0.001)),
    ],
)
def test_project_unproject_round_trip(model: str, coeffs: tuple[float, ...]) -> None:
    cam = CameraModel(**D435I, distortion_model=model, distortion=coeffs)
    rng = np.random.default_rng(0)
    u = rng.uniform(0, 639, 500)
    v = rng.uniform(0, 479, 500)
    z = rng.uniform(0.2, 1.5, 500)
    pts = cam.unproject(u, v, z)
    np.testing.assert_allclose(pts[:, 2], z)
    uv = cam.project(pts)
    # Sub-micro-pixel: the iterative undistortion has converged.
    np.testing.assert_allclose(uv, np.column_stack([u, v]), atol=1e-6)


def test_distortion_changes_rays() -> None:
    plain = CameraModel(**D435I)
    bent = CameraModel(**D435I, distortion_model="plumb_bob", distortion=(0.1, 0, 0, 0, 0))
    corner = bent.normalized_rays(np.array([0.0]), np.array([0.0]))
    assert not np.allclose(corner, plain.normalized_rays(np.array([0.0]), np.array([0.0])))


def test_ray_grid_matches_normalized_rays_and_is_read_only() -> None:
    cam = CameraModel(
        width=64, height=48, fx=60.0, fy=61.0, cx=31.0, cy=24.0,
        distortion_model="plumb_bob", distortion=(0.05, -0.02, 0.0, 0.0, 0.0),
    )  # fmt: skip
    grid = cam.ray_grid()
    assert grid.shape == (48, 64, 2) and grid.dtype == np.float32
    v, u = 17, 40
    np.testing.assert_allclose(grid[v, u], cam.normalized_rays(u, v), atol=1e-6)
    with pytest.raises(ValueError):
        grid[0, 0, 0] = 1.0
    assert cam.ray_grid() is grid


def test_scaled_camera_keeps_field_of_view() -> None:
    cam = CameraModel(**D435I)
    half = cam.scaled(320, 240)
    assert half.fx == pytest.approx(307.5)
    # The image centre maps to the same ray at both resolutions.
    np.testing.assert_allclose(
        half.normalized_rays(159.5, 119.5), cam.normalized_rays(319.5, 239.5), atol=1e-12
    )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(width=0), "size"),
        (dict(fx=-1.0), "focal"),
        (dict(distortion_model="kannala"), "distortion model"),
    ],
)
def test_camera_rejects_bad_values(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        CameraModel(**{**D435I, **kwargs})  # type: ignore[arg-type]


def test_frame_validates_shapes_and_dtypes() -> None:
    cam = CameraModel(width=4, height=3, fx=3.0, fy=3.0, cx=1.5, cy=1.0)
    color = np.zeros((3, 4, 3), np.uint8)
    depth = np.ones((3, 4), np.float32)
    frame = Frame(0, 1, color, depth, cam, np.eye(4))
    np.testing.assert_array_equal(frame.optical_axis, [0, 0, 1])
    with pytest.raises(ValueError, match="colour"):
        Frame(0, 1, np.zeros((3, 4, 3), np.float32), depth, cam, np.eye(4))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="depth"):
        Frame(0, 1, color, np.ones((4, 3), np.float32), cam, np.eye(4))
