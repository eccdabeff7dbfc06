"""The planner's occupancy map: a voxel hash of observed depth and its clearance tests."""

from __future__ import annotations

import numpy as np
import pytest
from perception_scenes import small_camera

from scrapcut_cli.exploration.occupancy import OccupancyMap, depth_points
from scrapcut_cli.geometry import look_at
from scrapcut_cli.recording.frame import Frame


def _plate(z: float, half: float = 0.1, spacing: float = 0.004) -> np.ndarray:
    g = np.arange(-half, half + 1e-9, spacing)
    x, y = np.meshgrid(g, g)
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z)])


def test_add_counts_new_cells_once() -> None:
    occupancy = OccupancyMap(0.01)
    plate = _plate(0.0)
    first = occupancy.add(plate)
    assert first == len(occupancy) == 21 * 21  # 0.2 m square at 1 cm, cell edges included
    assert occupancy.add(plate) == 0
    assert occupancy.add(np.array([[np.nan, 0.0, 0.0]])) == 0  # invalid points ignored
    centres = occupancy.centres
    assert np.allclose(centres[:, 2], 0.005)  # cell centres, not corners


def test_occupied_within_sees_cells_from_their_nearest_point() -> None:
    occupancy = OccupancyMap(0.01)
    occupancy.add(_plate(0.0))
    queries = np.array([[0.0, 0.0, 0.03], [0.0, 0.0, 0.12], [0.5, 0.5, 0.0]])
    assert occupancy.occupied_within(queries, 0.05).tolist() == [True, False, False]
    assert OccupancyMap(0.01).occupied_within(queries, 1.0).tolist() == [False] * 3


def test_segment_clear_refuses_a_segment_through_a_plate_not_one_beside_it() -> None:
    occupancy = OccupancyMap(0.01)
    occupancy.add(_plate(0.2))
    assert not occupancy.segment_clear([0, 0, 0.0], [0, 0, 0.4], 0.0)
    assert occupancy.segment_clear([0.3, 0, 0.0], [0.3, 0, 0.4], 0.05)
    assert not occupancy.segment_clear([0.3, 0, 0.0], [0.3, 0, 0.4], 0.25)  # inflated


def test_depth_points_back_project_a_floor_seen_from_above() -> None:
    camera = small_camera(160, 120)
    T = look_at([0.4, 0.1, 0.3], [0.4, 0.1, 0.0], up_hint=(1.0, 0.0, 0.0))
    depth = np.full((120, 160), 0.3, dtype=np.float32)
    depth[:10, :] = np.nan  # holes are skipped
    frame = Frame(0, 0, np.zeros((120, 160, 3), np.uint8), depth, camera, T)
    before = depth.copy()
    points = depth_points(
        frame,
        voxel_size_m=0.01,
        near_m=0.2,
        min_depth_m=0.1,
        max_depth_m=2.0,
        flying_pixel_ratio=0.03,
    )
    assert np.array_equal(np.isnan(before), np.isnan(frame.depth))
    assert len(points) > 100
    assert np.allclose(points[:, 2], 0.0, atol=1e-6)
    # Sampled about every half cell at 0.2 m: at 0.3 m neighbours are < 1 cm apart.
    xs = np.unique(np.round(points[:, 0], 6))
    assert np.max(np.diff(np.sort(xs))) < 0.01
    # The depth gate applies.
    far = depth_points(
        frame,
        voxel_size_m=0.01,
        near_m=0.2,
        min_depth_m=0.1,
        max_depth_m=0.25,
        flying_pixel_ratio=0.03,
    )
    assert len(far) == 0


def test_bad_voxel_size_is_refused() -> None:
    with pytest.raises(ValueError, match="voxel_size_m"):
        OccupancyMap(0.0)


def test_centres_within_lists_the_cells_around_a_point() -> None:
    occupancy = OccupancyMap(0.01)
    occupancy.add(_plate(0.0))
    near = occupancy.centres_within([0.0, 0.0, 0.0], 0.012)
    assert len(near) == 4  # the four cells meeting at the origin, centres 7 mm away
    assert np.all(np.linalg.norm(near, axis=1) <= 0.012)
    assert OccupancyMap(0.01).centres_within([0, 0, 0], 1.0).shape == (0, 3)
