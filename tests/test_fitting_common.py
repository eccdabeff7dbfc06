"""Shared fitting helpers: canonical frame, data extent, corners, moving average."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    apply_se3,
    corner_on_beam,
    line_on_plane,
    noisy_arc,
    on_wire_grid,
    painted_stroke,
    random_se3,
)

from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting._common import (
    CanonicalFrame,
    as_points,
    band_fill,
    clip_to_extent,
    corner_indices,
    data_extent,
    follows_input_order,
    moving_average,
)
from scrapcut_cli.geometry import resample_polyline


def test_canonical_coordinates_do_not_depend_on_the_pose():
    pts, _ = noisy_arc(seed=4)
    T = random_se3(3)
    a = CanonicalFrame.of(pts)
    b = CanonicalFrame.of(apply_se3(T, pts))
    assert np.abs(a.to_local(pts) - b.to_local(apply_se3(T, pts))).max() < 1e-12
    assert abs(np.linalg.det(a.axes) - 1.0) < 1e-12
    np.testing.assert_allclose(a.to_base(a.to_local(pts)), pts, atol=1e-15)


def test_as_points_copies():
    pts = np.ones((10, 3)) * np.arange(10)[:, None]
    out = as_points(pts, minimum=3, what="x")
    out[0] = 5.0
    assert pts[0, 0] == 0.0
    with pytest.raises(FittingError, match="x: need at least 20 points, got 10"):
        as_points(pts, minimum=20, what="x")


def test_input_order():
    assert follows_input_order(np.linspace(0.0, 1.0, 10))
    assert not follows_input_order(np.linspace(1.0, 0.0, 10))


def test_data_extent_finds_the_paint_ends():
    rng = np.random.default_rng(0)
    pts = np.column_stack(
        [rng.uniform(0.1, 0.4, 5000), rng.uniform(-0.01, 0.01, 5000), 0 * np.ones(5000)]
    )
    line = np.array([[0.15, 0.0, 0.0], [0.3, 0.0, 0.0]])
    start, end = data_extent(line, pts, quantile=0.001, radius=0.02, reach=0.1)
    assert abs(start - (-0.05)) < 0.001  # 5 cm before the polyline's start
    assert abs(end - 0.25) < 0.001
    clipped = clip_to_extent(line, start, end)
    np.testing.assert_allclose(clipped[[0, -1], 0], [0.1, 0.4], atol=0.001)
    inner = clip_to_extent(resample_polyline(line, 0.01), 0.02, 0.1)
    np.testing.assert_allclose(inner[[0, -1], 0], [0.17, 0.25], atol=1e-12)


def test_corner_found_on_a_joint_not_on_an_arc():
    corner, _ = corner_on_beam()
    idx = corner_indices(corner, reach=0.02, angle=np.radians(30))
    assert len(idx) == 1
    assert np.linalg.norm(corner[idx[0]]) < 0.002
    phi = np.linspace(0.0, np.pi, 500)
    arc = 0.03 * np.column_stack([np.cos(phi), np.sin(phi), 0 * phi])  # tight: r = 3 cm
    assert len(corner_indices(arc, reach=0.02, angle=np.radians(30))) == 0
    line, _ = line_on_plane(0.3)
    assert len(corner_indices(line, reach=0.02, angle=np.radians(30))) == 0


def test_moving_average_keeps_ends_and_lines():
    line, _ = line_on_plane(0.3, 31)
    np.testing.assert_allclose(moving_average(line, 5), line, atol=1e-15)
    noisy = line + np.random.default_rng(1).normal(0, 0.001, line.shape)
    smooth = moving_average(noisy, 5)
    np.testing.assert_array_equal(smooth[[0, -1]], noisy[[0, -1]])
    assert np.std(smooth[2:-2, 1]) < np.std(noisy[2:-2, 1])


def test_band_fill_tells_a_sprayed_stroke_from_paint_on_a_wire_mesh():
    line, normals = line_on_plane(0.5)
    stroke = painted_stroke(line, normals, seed=5, caps=True)
    assert band_fill(line, stroke) > 0.95
    # 4 mm wires every 40 mm, two layers: about a fifth of the band's area, but where a
    # wire runs along the line its paint fills whole rows of cells.
    assert 0.2 < band_fill(line, on_wire_grid(stroke, angle_deg=25.0)) < 0.6
    # A thin line (a stroke narrower than a cell) counts as full.
    thin = painted_stroke(line, normals, seed=5, width_m=0.004, noise_m=0.0002)
    assert band_fill(line, thin) == 1.0
