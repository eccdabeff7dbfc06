"""View poses: optical axis along the inverse normal, distance, roll, elevation, edge tilt."""

from __future__ import annotations

import numpy as np
import pytest

from scrapcut_cli.exploration.views import (
    search_distances,
    search_rolls,
    tilt_about_edge,
    tilt_up,
    view_pose,
)


def _elevation_deg(v: np.ndarray) -> float:
    return float(np.degrees(np.arcsin(v[2] / np.linalg.norm(v))))


def test_tilt_up_keeps_high_directions_and_raises_low_ones_to_the_minimum() -> None:
    high = np.array([0.3, 0.0, 0.9])
    assert np.allclose(tilt_up(high, 35.0), high / np.linalg.norm(high))
    low = np.array([0.0, -0.88, 0.48])  # the slanted piece's face: 28.6 degrees up
    raised = tilt_up(low, 35.0)
    assert np.isclose(np.linalg.norm(raised), 1.0)
    assert _elevation_deg(raised) == pytest.approx(35.0, abs=1e-9)
    assert np.isclose(np.arctan2(raised[1], raised[0]), np.arctan2(low[1], low[0]))  # azimuth
    down = tilt_up([0.0, 0.0, -1.0], 35.0)
    assert _elevation_deg(down) == pytest.approx(35.0, abs=1e-9)
    assert np.array_equal(low, [0.0, -0.88, 0.48])  # input unchanged


def test_view_pose_looks_at_the_target_from_the_distance_with_x_along_the_hint() -> None:
    target = np.array([0.5, 0.1, 0.2])
    outward = np.array([0.0, 0.6, 0.8])
    T = view_pose(target, outward, [1.0, 0.0, 0.0], distance_m=0.3)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(T[:3, :3]), 1.0)
    assert np.allclose(T[:3, 2], -outward)  # optical axis = inverse normal
    assert np.allclose(T[:3, 3], target + 0.3 * outward)
    assert np.allclose(T[:3, 0], [1.0, 0.0, 0.0])  # the line across the wide image axis
    # The target projects onto the optical axis at depth 0.3 m.
    in_cam = T[:3, :3].T @ (target - T[:3, 3])
    assert np.allclose(in_cam, [0.0, 0.0, 0.3])


def test_roll_turns_the_image_about_the_optical_axis_only() -> None:
    target = np.zeros(3)
    T0 = view_pose(target, [0, 0, 1], [1, 0, 0], distance_m=0.25)
    T90 = view_pose(target, [0, 0, 1], [1, 0, 0], distance_m=0.25, roll_rad=np.pi / 2)
    assert np.allclose(T90[:3, 3], T0[:3, 3])
    assert np.allclose(T90[:3, 2], T0[:3, 2])
    assert np.allclose(T90[:3, 0], T0[:3, 1])  # x turned onto the old y


def test_search_distances_start_at_the_minimum_and_include_the_maximum() -> None:
    d = search_distances(0.2, 0.45, 0.025)
    assert d[0] == pytest.approx(0.2) and d[-1] == pytest.approx(0.45)
    assert len(d) == 11 and np.all(np.diff(d) > 0)
    assert search_distances(0.3, 0.3, 0.05).tolist() == [pytest.approx(0.3)]
    with pytest.raises(ValueError, match="distance search"):
        search_distances(0.3, 0.2, 0.05)


def test_search_rolls_go_out_from_zero_and_cover_the_circle_once() -> None:
    rolls = np.degrees(search_rolls(45.0))
    assert rolls.tolist() == pytest.approx([0, 45, -45, 90, -90, 135, -135, 180])
    assert len(np.degrees(search_rolls(30.0))) == 12
    with pytest.raises(ValueError, match="roll step"):
        search_rolls(0.0)


def test_tilt_about_edge_turns_the_normal_towards_the_line_direction() -> None:
    n = np.array([0.0, -0.878, 0.479])
    n /= np.linalg.norm(n)
    d = np.array([0.0, 0.479, 0.878])  # up the face, towards the ridge
    for angle in (40.0, 60.0, 90.0):
        v = tilt_about_edge(n, d, angle)
        assert np.isclose(np.linalg.norm(v), 1.0)
        assert np.degrees(np.arccos(np.clip(v @ n, -1, 1))) == pytest.approx(angle)
        assert v @ d > 0  # towards what lies past the edge
    # Past the slanted ridge, 60 degrees brings the camera nearly straight above it.
    assert tilt_about_edge(n, d, 60.0)[2] > 0.99
