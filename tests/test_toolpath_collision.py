"""Torch collision check and tilt search on synthetic walls beside the path."""

from __future__ import annotations

import numpy as np
from helpers import surface_patch

from scrapcut_cli.toolpath.collision import choose_torch_axes, thin_cloud

STANDOFF = 0.008
LENGTH = 0.15
RADIUS = 0.012


def _path_beside_wall(gap_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A straight path along x on the floor z = 0 and a wall y = gap_m rising 10 cm beside it."""
    x = np.linspace(-0.05, 0.05, 21)
    points = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    normals = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    tangents = np.tile([1.0, 0.0, 0.0], (len(x), 1))
    floor = surface_patch([-0.12, -0.08, 0.0], [0.24, 0, 0], [0, 0.08 + gap_m, 0])
    wall = surface_patch([-0.12, gap_m, 0.0], [0.24, 0, 0], [0, 0, 0.1])
    return points, normals, tangents, np.vstack([floor, wall])


def _axes(points: np.ndarray, normals: np.ndarray, tangents: np.ndarray, cloud: np.ndarray):
    return choose_torch_axes(
        points,
        normals,
        tangents,
        cloud,
        standoff_m=STANDOFF,
        length_m=LENGTH,
        radius_m=RADIUS,
        max_tilt_deg=20.0,
    )


def _inside_counts(points: np.ndarray, axes: np.ndarray, cloud: np.ndarray) -> np.ndarray:
    """Brute force: observed points inside each torch body (tip at standoff along the axis)."""
    tips = points + STANDOFF * axes
    v = cloud[None, :, :] - tips[:, None, :]
    along = np.einsum("nmk,nk->nm", v, axes)
    radial = np.sqrt(np.maximum(np.einsum("nmk,nmk->nm", v, v) - along**2, 0.0))
    return ((along >= 0) & (along <= LENGTH) & (radial <= RADIUS)).sum(axis=1)


def test_free_path_keeps_the_normal() -> None:
    points, normals, tangents, cloud = _path_beside_wall(0.05)  # 5 cm: far beyond 12 mm
    result = _axes(points, normals, tangents, cloud)
    np.testing.assert_array_equal(result.axes, normals)
    assert not result.tilted.any() and not result.colliding.any()
    assert np.all(result.tilt_rad == 0.0)


def test_wall_beside_the_path_tilts_the_torch_away_within_the_bound() -> None:
    points, normals, tangents, cloud = _path_beside_wall(0.010)  # 10 mm < torch radius 12 mm
    assert np.all(_inside_counts(points, normals, cloud) >= 3)  # the upright torch hits
    result = _axes(points, normals, tangents, cloud)
    assert result.tilted.all() and not result.colliding.any()
    assert np.all(result.tilt_rad > 0) and np.all(result.tilt_rad <= np.radians(20.0) + 1e-12)
    np.testing.assert_allclose(
        np.degrees(np.arccos(result.axes @ [0.0, 0.0, 1.0])), np.degrees(result.tilt_rad)
    )
    assert np.all(result.axes[:, 1] < 0)  # away from the wall, towards the free side
    np.testing.assert_allclose(np.linalg.norm(result.axes, axis=1), 1.0, atol=1e-12)
    # Checked independently of the module: the chosen bodies are free of the (unthinned) cloud.
    assert np.all(_inside_counts(points, result.axes, cloud) < 3)


def test_wall_too_close_is_flagged_as_collision() -> None:
    points, normals, tangents, cloud = _path_beside_wall(0.003)  # 20 deg cannot clear 3 mm
    result = _axes(points, normals, tangents, cloud)
    assert result.colliding.all() and not result.tilted.any()
    np.testing.assert_array_equal(result.axes, normals)


def test_a_lone_speck_is_not_a_collision() -> None:
    points, normals, tangents, cloud = _path_beside_wall(0.05)
    speck = points[10] + [0.0, 0.0, 0.05]  # one noise point on the torch axis
    result = _axes(points, normals, tangents, np.vstack([cloud, speck]))
    assert not result.colliding.any() and not result.tilted.any()


def test_thin_cloud_keeps_one_point_per_voxel_in_order() -> None:
    rng = np.random.default_rng(0)
    cloud = rng.uniform(0.0, 0.03, (2000, 3))
    thin = thin_cloud(cloud, 0.01)
    assert len(thin) == 27
    keys = np.floor(thin / 0.01).astype(int)
    assert len({tuple(k) for k in keys}) == 27
    index = [int(np.flatnonzero((cloud == p).all(axis=1))[0]) for p in thin]
    assert index == sorted(index)


def test_a_needle_thin_torch_still_works() -> None:
    # A torch radius far below the cloud's spacing (a typo in --torch-radius-mm): no crash
    # from the thinning grid, and a needle beside the wall is free.
    points, normals, tangents, cloud = _path_beside_wall(0.010)
    result = choose_torch_axes(
        points, normals, tangents, cloud,
        standoff_m=STANDOFF, length_m=LENGTH, radius_m=1e-7, max_tilt_deg=20.0,
    )  # fmt: skip
    assert not result.tilted.any() and not result.colliding.any()
