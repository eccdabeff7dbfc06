"""Surface normals at set-points: accuracy, orientation, sharp edges, wires, gaps, smoothing."""

from __future__ import annotations

import numpy as np
from helpers import arc_on_cylinder, corner_on_beam, cylinder_surface, surface_patch

from scrapcut_cli.geometry import cumulative_length
from scrapcut_cli.toolpath.normals import (
    estimate_normals,
    estimate_path_normals,
    fill_unsupported,
    smooth_along_path,
)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _convex_edge_scene(noise_m: float = 0.0005) -> tuple[np.ndarray, np.ndarray]:
    """Top face z = 0 (x <= 0) and side face x = 0 (z <= 0), seen from above and from the side."""
    top = surface_patch([-0.2, -0.06, 0.0], [0.2, 0, 0], [0, 0.12, 0], noise_m=noise_m, seed=1)
    side = surface_patch([0.0, -0.06, -0.2], [0, 0, 0.2], [0, 0.12, 0], noise_m=noise_m, seed=2)
    points = np.vstack([top, side])
    viewpoints = np.vstack(
        [np.tile([-0.05, 0.0, 0.3], (len(top), 1)), np.tile([0.3, 0.0, -0.05], (len(side), 1))]
    )
    return points, viewpoints


def test_cylinder_normals_are_radial_and_face_the_camera() -> None:
    curve, truth = arc_on_cylinder(radius=0.08, n=200)
    surface, viewpoints = cylinder_surface(0.08, noise_m=0.0005, seed=3)
    est = estimate_normals(curve, surface, viewpoints, radius_m=0.015)
    assert est.supported.all()
    assert not est.line_like.any()
    # 0.5 mm noise on a 15 mm neighbourhood: the plane is good to well under 2 degrees.
    assert _angle_deg(est.normals, truth).max() < 2.0
    np.testing.assert_allclose(np.linalg.norm(est.normals, axis=1), 1.0, atol=1e-12)


def test_orientation_follows_the_viewpoints_not_the_point_order() -> None:
    curve, truth = arc_on_cylinder(radius=0.08, n=50)
    surface, viewpoints = cylinder_surface(0.08, seed=0)
    inside_view = surface - 0.3 * (viewpoints - surface) / 0.3  # cameras inside the pipe
    est_out = estimate_normals(curve, surface, viewpoints, radius_m=0.015)
    est_in = estimate_normals(curve, surface, inside_view, radius_m=0.015)
    assert np.all(np.einsum("ij,ij->i", est_out.normals, truth) > 0.99)
    assert np.all(np.einsum("ij,ij->i", est_in.normals, truth) < -0.99)


def test_sharp_convex_edge_keeps_each_face_normal() -> None:
    curve, truth = corner_on_beam(arm=0.15, n=61)  # 5 mm apart, the edge at index 30
    surface, viewpoints = _convex_edge_scene()
    est = estimate_normals(curve, surface, viewpoints, radius_m=0.015)
    distance_to_edge = np.abs(np.linspace(-0.15, 0.15, 61))
    away = distance_to_edge >= 0.005
    # A plain PCA over the 15 mm ball would tilt these by up to ~20 degrees.
    assert _angle_deg(est.normals[away], truth[away]).max() < 4.0
    # At the edge itself: a direction between the two faces, never outside that quarter.
    edge = est.normals[30]
    assert edge[0] > -0.05 and edge[2] > -0.05 and abs(edge[1]) < 0.05


def test_wire_neighbourhood_takes_the_viewing_direction() -> None:
    x = np.linspace(-0.1, 0.1, 201)
    wire = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    viewpoints = np.tile([0.05, 0.1, 0.3], (len(wire), 1))
    query = wire[::20]
    est = estimate_normals(query, wire, viewpoints, radius_m=0.015)
    assert est.line_like.all()
    # The view direction (0.05 - x, 0.1, 0.3) without its component along the wire.
    expected = np.tile([0.0, 0.1, 0.3], (len(query), 1))
    assert _angle_deg(est.normals, expected).max() < 1e-4


def test_points_without_surface_are_reported_and_filled() -> None:
    curve, truth = arc_on_cylinder(radius=0.08, angle=np.pi, n=101)
    surface, viewpoints = cylinder_surface(0.08, angle=np.pi, seed=0)
    phi = np.arctan2(surface[:, 1], surface[:, 0])
    keep = ~((phi > 1.2) & (phi < 1.9))  # a 56 mm gap (the basket's wires, a shadow)
    est = estimate_normals(curve, surface[keep], viewpoints[keep], radius_m=0.015)
    assert 5 < (~est.supported).sum() < 40
    assert np.all(est.normals[~est.supported] == 0.0)
    arc = cumulative_length(curve)
    filled = fill_unsupported(arc, est.normals, est.supported)
    np.testing.assert_allclose(np.linalg.norm(filled, axis=1), 1.0, atol=1e-12)
    # Interpolated across the gap: within the gap's own turning (0.7 rad) of the truth.
    assert _angle_deg(filled, truth).max() < 25.0
    np.testing.assert_array_equal(filled[est.supported], est.normals[est.supported])


def test_gap_between_opposite_normals_takes_the_nearer_side() -> None:
    # Interpolation across a gap between opposite normals (a thin plate seen from both sides)
    # cancels out in the gap's middle; those rows take the nearer supported neighbour's normal.
    arc = np.linspace(0.0, 0.14, 15)
    normals = np.zeros((15, 3))
    normals[:3] = [0.0, 0.0, 1.0]
    normals[10:] = [0.0, 0.0, -1.0]
    supported = np.ones(15, dtype=bool)
    supported[3:10] = False  # rows 5-7 interpolate to less than half a unit vector
    filled = fill_unsupported(arc, normals, supported)
    np.testing.assert_array_equal(filled[:6], np.tile([0.0, 0.0, 1.0], (6, 1)))
    np.testing.assert_array_equal(filled[7:], np.tile([0.0, 0.0, -1.0], (8, 1)))
    np.testing.assert_allclose(np.abs(filled[6, 2]), 1.0)  # the middle: a tie, either side


def test_smoothing_reduces_noise_without_bias_on_a_turning_surface() -> None:
    rng = np.random.default_rng(7)
    curve, truth = arc_on_cylinder(radius=0.06, angle=np.pi, n=121)
    arc = cumulative_length(curve)
    noisy = truth + rng.normal(scale=0.05, size=truth.shape)
    noisy /= np.linalg.norm(noisy, axis=1, keepdims=True)
    smooth = smooth_along_path(arc, noisy, sigma_m=0.01, edge_angle_deg=30.0)
    before = _angle_deg(noisy, truth)
    after = _angle_deg(smooth, truth)
    assert after.mean() < 0.6 * before.mean()
    # The locally linear fit follows the turning normal to the ends: no one-sided pull.
    exact = smooth_along_path(arc, truth, sigma_m=0.01, edge_angle_deg=30.0)
    assert _angle_deg(exact, truth).max() < 0.3


def test_smoothing_does_not_average_across_an_edge() -> None:
    n = 41
    arc = np.linspace(0.0, 0.2, n)
    normals = np.where((np.arange(n) < 20)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    smooth = smooth_along_path(arc, normals, sigma_m=0.01, edge_angle_deg=30.0)
    np.testing.assert_allclose(smooth, normals, atol=1e-12)
    inputs = normals.copy()
    smooth_along_path(arc, normals, sigma_m=0.01, edge_angle_deg=30.0)
    np.testing.assert_array_equal(normals, inputs)


def _wire_grid(pitch: float = 0.025, r: float = 0.002, half: float = 0.15) -> np.ndarray:
    """The visible upper halves of a basket's two wire layers: 4 mm wires at 25 mm pitch, along
    y at z = 0 on top of wires along x 4 mm lower (as the simulator's basket)."""
    t = np.arange(-half, half + 1e-9, 0.002)
    parts = []
    for c in np.arange(-half, half + 1e-9, pitch):
        for a in np.linspace(0.0, np.pi, 5):
            dx, dz = r * np.cos(a), r * np.sin(a)
            parts.append(np.column_stack([np.full_like(t, c + dx), t, np.full_like(t, dz)]))
            parts.append(np.column_stack([t, np.full_like(t, c + dx), np.full_like(t, dz - 2 * r)]))
    return np.vstack(parts)


def test_wire_mesh_normals_come_from_the_coarse_radius() -> None:
    grid = _wire_grid()
    viewpoints = grid + np.array([0.0, 0.0, 0.3])
    rng = np.random.default_rng(1)
    query = np.column_stack(
        [rng.uniform(-0.08, 0.08, 60), rng.uniform(-0.08, 0.08, 60), np.full(60, 0.002)]
    )
    up = np.tile([0.0, 0.0, 1.0], (60, 1))
    # A path across the grid (in x), so the running median sees its neighbours.
    query = query[np.argsort(query[:, 0])]
    fine = estimate_normals(query, grid, viewpoints, radius_m=0.015)
    both = estimate_path_normals(query, grid, viewpoints, radius_m=0.015, coarse_radius_m=0.03)
    # At 15 mm two crossing wire layers 4 mm apart are no plane: tilts of ~20 degrees.
    assert np.median(fine.rms_m) > 0.001 and np.median(_angle_deg(fine.normals, up)) > 10.0
    assert both.coarse.all()
    assert _angle_deg(both.normals, up).max() < 2.0


def test_clean_faces_keep_the_fine_radius_at_a_sharp_edge() -> None:
    curve, _ = corner_on_beam(arm=0.15, n=61)
    surface, viewpoints = _convex_edge_scene(noise_m=0.0003)
    fine = estimate_normals(curve, surface, viewpoints, radius_m=0.015)
    both = estimate_path_normals(curve, surface, viewpoints, radius_m=0.015, coarse_radius_m=0.03)
    assert fine.rms_m[30] > 0.001  # the edge itself is rough at 15 mm ...
    assert not both.coarse.any()  # ... but it is no rough region
    np.testing.assert_array_equal(both.normals, fine.normals)
