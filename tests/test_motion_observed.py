"""Tests of scrapcut_cli.motion.observed: the surface, free space and the unseen around a piece."""

from __future__ import annotations

import numpy as np
from perception_scenes import (
    CYLINDER_AXIS_YZ,
    CYLINDER_RADIUS_M,
    cylinder_top_line,
    render_cylinder,
    small_camera,
    top_view,
)
from scipy.spatial import cKDTree

from scrapcut_cli.config import PerceptionConfig
from scrapcut_cli.motion.observed import observe


def test_under_the_pipe_is_unseen_beside_it_is_free_and_nothing_above_counts() -> None:
    camera = small_camera(160, 120)
    line = cylinder_top_line(length_m=0.2)
    frames = [
        render_cylinder(camera, top_view(x, height_m=0.3), line, index=i)
        for i, x in enumerate((-0.06, 0.0, 0.06))
    ]
    scene = observe(frames, surface_voxel_m=0.003, free_voxel_m=0.01, perception=PerceptionConfig())
    y0, z0 = CYLINDER_AXIS_YZ
    # The surface: the pipe's top, where the cameras looked.
    top = scene.surface[np.abs(scene.surface[:, 1] - y0) < 0.02]
    assert abs(top[:, 2].max() - (z0 + CYLINDER_RADIUS_M)) < 0.004
    assert scene.bounds is not None
    assert scene.bounds[1, 2] <= z0 + CYLINDER_RADIUS_M + 0.011  # nothing above the piece
    unseen = cKDTree(scene.unseen)

    def is_unseen(p: tuple[float, float, float]) -> bool:
        return bool(np.isfinite(unseen.query(p, distance_upper_bound=0.009)[0]))

    # Inside the pipe and in the shadow under its flank: never seen.
    assert is_unseen((0.0, y0, z0))
    assert is_unseen((0.0, y0 + 0.095, 0.03))
    # Just above the top (beyond the piece's bounds), and the air in view beside the top: free.
    assert not is_unseen((0.0, y0, z0 + CYLINDER_RADIUS_M + 0.02))
    assert not is_unseen((0.0, y0 + 0.09, 0.18))
    # One voxel in (x = 0, z = 0.1) the pipe's flank shadows what lies under it.
    assert is_unseen((0.0, y0 - 0.095, 0.03))
    assert scene.info["unseen_voxels"] == len(scene.unseen) > 0
