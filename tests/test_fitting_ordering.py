"""Ordering an unordered curve-like cloud by geodesic distance."""

from __future__ import annotations

import numpy as np
from helpers import arc_on_cylinder, noisy_helix, painted_stroke
from scipy.sparse import csr_matrix
from scipy.stats import spearmanr

from scrapcut_cli.fitting.ordering import geodesic_positions, tree_diameter


def u_shape(gap: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A U of two 0.2 m arms ``gap`` apart joined by a half circle: (points, true arc length)."""
    rng = np.random.default_rng(seed)
    r = gap / 2
    total = 0.4 + np.pi * r
    s = np.sort(rng.uniform(0.0, total, 3000))
    x = np.where(s < 0.2, s, np.where(s < 0.2 + np.pi * r, 0.2, 0.2 - (s - 0.2 - np.pi * r)))
    phi = np.clip((s - 0.2) / r, 0.0, np.pi)
    bend = (s >= 0.2) & (s < 0.2 + np.pi * r)
    x = np.where(bend, 0.2 + r * np.sin(phi), x)
    y = np.where(s < 0.2, 0.0, np.where(bend, r - r * np.cos(phi), gap))
    pts = np.column_stack([x, y, np.zeros_like(s)]) + rng.normal(0, 0.001, (len(s), 3))
    return pts, s


def test_positions_follow_a_u_whose_arms_are_close():
    pts, s = u_shape(0.04, seed=1)
    position, length = geodesic_positions(pts)
    rho = spearmanr(position, s).statistic
    assert abs(rho) > 0.99
    # Centroid to centroid the chain zig-zags a little: the length is an estimate.
    assert abs(length - s.max()) < 0.15 * s.max()


def test_positions_do_not_jump_between_turns_of_a_helix():
    pts, _ = noisy_helix(seed=3)
    angle = np.unwrap(np.arctan2(pts[:, 1], pts[:, 0]))
    # True position along the helix from the height (the helix rises steadily).
    position, _ = geodesic_positions(pts)
    assert abs(spearmanr(position, pts[:, 2]).statistic) > 0.99
    assert np.isfinite(angle).all()


def test_positions_across_a_band_grow_along_it():
    line, normals = arc_on_cylinder()
    pts = painted_stroke(line, normals, seed=2)
    angle = np.mod(np.arctan2(pts[:, 1], pts[:, 0]), 2 * np.pi)
    position, length = geodesic_positions(pts)
    assert abs(spearmanr(position, angle).statistic) > 0.99
    assert 0.35 < length < 0.45


def test_tree_diameter_of_a_path_with_a_spur():
    # 0-1-2-3-4 with a spur 2-5: the longest path is 0..4 (either direction).
    rows, cols = [0, 1, 2, 3, 2], [1, 2, 3, 4, 5]
    tree = csr_matrix((np.ones(5), (rows, cols)), shape=(6, 6))
    path = tree_diameter(tree).tolist()
    assert path in ([0, 1, 2, 3, 4], [4, 3, 2, 1, 0])
