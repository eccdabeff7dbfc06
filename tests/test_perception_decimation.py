"""Frames read at every 2nd (4th, 8th) pixel when their pixels are finer than the voxels need."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from perception_scenes import (
    CYLINDER_AXIS_YZ,
    CYLINDER_RADIUS_M,
    NOISY,
    cylinder_top_line,
    render_cylinder,
    small_camera,
    top_view,
)
from scipy.spatial import cKDTree

from scrapcut_cli.config import PerceptionConfig, ScrapcutConfig
from scrapcut_cli.errors import ConfigError
from scrapcut_cli.geometry import PolylineDistance
from scrapcut_cli.perception.cloud import _usable, decimation, process_frame
from scrapcut_cli.perception.paint import PAINT_PRESETS
from scrapcut_cli.recording.frame import CameraModel, Frame

ORANGE = PAINT_PRESETS["orange"].hsv
EVERY_PIXEL = PerceptionConfig(max_decimation=1)
CONFIG = PerceptionConfig()  # the default reads a fine frame at every 2nd (4th, 8th) pixel
#: A D435i-like lens with radial and tangential distortion, at 1280x720.
LENS = CameraModel(
    1280,
    720,
    920.0,
    918.0,
    641.3,
    362.7,
    distortion_model="plumb_bob",
    distortion=(0.08, -0.2, 0.001, -0.0015, 0.1),
)


@pytest.mark.parametrize("step", [2, 4, 8])
def test_a_decimated_camera_is_every_steps_pixel_of_the_lens(step: int) -> None:
    coarse = LENS.decimated(step)
    assert (coarse.width, coarse.height) == (-(-1280 // step), -(-720 // step))
    rng = np.random.default_rng(3)
    points = np.column_stack(
        [rng.uniform(-0.15, 0.15, 200), rng.uniform(-0.1, 0.1, 200), rng.uniform(0.2, 0.6, 200)]
    )
    # Projection: the coarse pixel is the fine one divided by the step (1e-9 px).
    np.testing.assert_allclose(coarse.project(points), LENS.project(points) / step, atol=1e-9)
    # Rays: the coarse grid's pixel (u, v) is the fine grid's (step u, step v), distortion
    # and all (float32 grids: 1e-6 of a normalised coordinate).
    fine_rays = LENS.ray_grid()[::step, ::step]
    np.testing.assert_allclose(coarse.ray_grid(), fine_rays, atol=1e-6)
    assert LENS.decimated(1) is LENS


def test_a_decimated_frame_keeps_every_steps_pixel_of_colour_and_depth() -> None:
    rng = np.random.default_rng(5)
    camera = CameraModel(101, 75, 90.0, 90.0, 50.0, 37.0)
    frame = Frame(
        index=4,
        stamp_ns=7,
        color=rng.integers(0, 256, (75, 101, 3), dtype=np.uint8),
        depth=rng.uniform(0.2, 0.5, (75, 101)).astype(np.float32),
        camera=camera,
        T_base_cam=np.eye(4),
        extras={"depth_stamp_ns": 8},
    )
    coarse = frame.decimated(4)
    assert coarse.color.shape == (19, 26, 3) and coarse.depth.shape == (19, 26)
    np.testing.assert_array_equal(coarse.color, frame.color[::4, ::4])
    np.testing.assert_array_equal(coarse.depth, frame.depth[::4, ::4])
    assert coarse.extras["decimation"] == 4 and coarse.extras["depth_stamp_ns"] == 8
    assert coarse.extras["full_depth"] is frame.depth
    assert (coarse.index, coarse.stamp_ns, coarse.camera) == (4, 7, camera.decimated(4))
    assert frame.decimated(1) is frame  # a frame read at its own resolution is itself


def test_a_decimated_frames_depth_gate_looks_one_camera_pixel_away() -> None:
    # A wire 8 px wide at 0.2 m before a wall at 0.6 m, a flying pixel at each rim: every
    # pixel's gate drops the wire's two rim pixels; read at every other pixel, the gate still
    # compares each sample with its neighbours one camera pixel away, not two.
    depth = np.full((40, 240), 0.6, dtype=np.float32)
    depth[:, 100:108] = 0.2
    depth[:, [99, 108]] = 0.4
    camera = CameraModel(240, 40, 300.0, 300.0, 120.0, 20.0)
    colour = np.zeros((40, 240, 3), dtype=np.uint8)
    frame = Frame(
        index=0, stamp_ns=0, color=colour, depth=depth, camera=camera, T_base_cam=np.eye(4)
    )
    full = usable_depth(frame, np.flatnonzero(depth.reshape(-1) < 0.3))
    assert set(np.unique(full % 240)) == set(range(101, 107))
    half = frame.decimated(2)
    kept = usable_depth(half, np.flatnonzero(half.depth.reshape(-1) < 0.3))
    # The samples at columns 102, 104, 106 of the camera: as the full frame's gate says.
    assert set(np.unique(kept % 120)) == {51, 52, 53}
    # Without the full frame's depth the rims grow to two camera pixels: 106 goes too.
    plain = replace(half, extras={})
    narrow = usable_depth(plain, np.flatnonzero(half.depth.reshape(-1) < 0.3))
    assert set(np.unique(narrow % 120)) == {51, 52}


def usable_depth(frame: Frame, pixels: np.ndarray) -> np.ndarray:
    """The depth gate perception applies to a frame's pixels (the default configuration's)."""
    return _usable(frame, pixels.astype(np.intp), CONFIG)


def flat_frame(camera: CameraModel, depth_m: float) -> Frame:
    h, w = camera.height, camera.width
    return Frame(
        index=0,
        stamp_ns=0,
        color=np.zeros((h, w, 3), dtype=np.uint8),
        depth=np.full((h, w), depth_m, dtype=np.float32),
        camera=camera,
        T_base_cam=np.eye(4),
    )


@pytest.mark.parametrize(
    ("size", "depth_m", "max_step", "expected"),
    [
        # 1280x720 (focal 920): 2 mm voxels want pixels <= 0.67 mm apart; at 0.28 m a pixel
        # is 0.30 mm (step 2), at 0.14 m 0.15 mm (step 4), at 0.06 m 0.07 mm (8, the most).
        ((1280, 720), 0.28, 8, 2),
        ((1280, 720), 0.14, 8, 4),
        ((1280, 720), 0.06, 8, 8),
        # A step that is not a power of two is rounded down to one; 1 reads every pixel.
        ((1280, 720), 0.14, 3, 2),
        ((1280, 720), 0.14, 1, 1),
        # 640x360 (focal 460) at 0.25 m: 0.54 mm pixels, kept; at 0.14 m (0.30 mm), halved.
        ((640, 360), 0.25, 8, 1),
        ((640, 360), 0.14, 8, 2),
    ],
)
def test_the_step_keeps_pixels_a_third_of_a_voxel_apart(
    size: tuple[int, int], depth_m: float, max_step: int, expected: int
) -> None:
    camera = LENS.decimated(1280 // size[0])
    assert decimation(flat_frame(camera, depth_m).depth, camera, 0.002, max_step) == expected


def test_the_step_follows_the_near_part_of_the_scene_and_needs_depth() -> None:
    frame = flat_frame(LENS, 0.6)
    near = frame.depth.copy()
    near[:, :300] = 0.14  # a quarter of the image near the camera (the piece), the rest far
    assert decimation(near, LENS, 0.002, 8) == 4
    assert (
        decimation(frame.depth, LENS, 0.002, 8) == 1
    )  # 0.6 m: 0.65 mm pixels, already coarse enough
    none = np.full_like(frame.depth, np.nan)
    assert decimation(none, LENS, 0.002, 8) == 1


def radial_error(points: np.ndarray) -> np.ndarray:
    """Distance (N,) of points from the cylinder's surface, metres."""
    y0, z0 = CYLINDER_AXIS_YZ
    return np.abs(np.hypot(points[:, 1] - y0, points[:, 2] - z0) - CYLINDER_RADIUS_M)


@pytest.fixture(scope="module")
def fine_frames() -> list[Frame]:
    """The painted cylinder at 1280x960 (focal 1230) from 0.3 m, noisy (holes, flying
    pixels, colour noise): pixels of 0.24 mm, read at every 2nd."""
    camera = small_camera(1280, 960)
    reference = cylinder_top_line()
    return [
        render_cylinder(camera, top_view(x, tilt_m=0.03), reference, noise=NOISY, seed=k)
        for k, x in enumerate((-0.03, 0.04))
    ]


def test_a_fine_frame_read_at_every_other_pixel_gives_the_same_clouds(
    fine_frames: list[Frame],
) -> None:
    reference = cylinder_top_line()
    for frame in fine_frames:
        assert (
            decimation(frame.depth, frame.camera, CONFIG.voxel_size_m, CONFIG.max_decimation) == 2
        )
        fast = process_frame(frame, ORANGE, CONFIG)
        full = process_frame(frame, ORANGE, EVERY_PIXEL)
        assert fast.skip_reason is None and full.skip_reason is None
        # The same stroke: as many voxels within 10 %, each within half a voxel of the other
        # cloud at the median (1.5 mm at the 99th percentile), on the stroke.
        assert abs(len(fast.paint_base) - len(full.paint_base)) <= 0.1 * len(full.paint_base)
        there, _ = cKDTree(full.paint_base).query(fast.paint_base)
        back, _ = cKDTree(fast.paint_base).query(full.paint_base)
        for d in (there, back):
            assert np.median(d) < 0.001 and np.quantile(d, 0.99) < 0.0015
        across = PolylineDistance(reference).distance(fast.paint_base)
        assert across.max() < 0.0125 + 0.002
        # On the surface as closely as every pixel's cloud (the depth noise's 0.5 mm sets
        # both): the 99th percentile of the distance to the cylinder within 0.2 mm of it.
        fast_off, full_off = radial_error(fast.paint_base), radial_error(full.paint_base)
        assert np.quantile(fast_off, 0.99) < np.quantile(full_off, 0.99) + 0.0002
        # The filter's count in the image's own pixels: its quarter, times four (within 3 %);
        # as many samples back-projected as every pixel's frame sampled at its stride of 2.
        assert fast.paint_pixels == pytest.approx(full.paint_pixels, rel=0.03)
        assert fast.valid_paint_pixels == pytest.approx(full.valid_paint_pixels, rel=0.05)
        # Edges and the surface band are found as at full resolution (counts within 25 %: the
        # edges' 1 mm voxels see the boundary's pixels half as often).
        assert len(fast.edge_base) == pytest.approx(len(full.edge_base), rel=0.25)
        assert len(fast.surface_base) == pytest.approx(len(full.surface_base), rel=0.25)


def test_max_decimation_is_a_checked_config_key_8_by_default() -> None:
    assert ScrapcutConfig().perception.max_decimation == 8
    config = ScrapcutConfig().override("perception", max_decimation=1)
    assert config.perception.max_decimation == 1
    for bad in (0, 9):
        with pytest.raises(ConfigError, match="max_decimation"):
            ScrapcutConfig().override("perception", max_decimation=bad)
