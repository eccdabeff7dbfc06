"""Tests of scrapcut_cli.sim.observed: the simulated cell's obstacles from depth images."""

from __future__ import annotations

from collections import Counter

import numpy as np

from scrapcut_cli.geometry import look_at, unpack_voxel_keys
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.sim.camera import d435i_color_camera
from scrapcut_cli.sim.observed import ObservedScene


def _looking_down(depth_m: np.ndarray, camera_z_m: float) -> Frame:
    height, width = depth_m.shape
    camera = d435i_color_camera(width, height)
    T = look_at((0.5, 0.0, camera_z_m), (0.5, 0.0, 0.0), up_hint=(1.0, 0.0, 0.0))
    color = np.zeros((height, width, 3), dtype=np.uint8)
    return Frame(0, 1, color, depth_m.astype(np.float32), camera, T)


def test_a_plane_seen_from_above_becomes_one_layer_of_voxels() -> None:
    scene = ObservedScene()
    depth = np.full((120, 160), 0.3, dtype=np.float32)  # a table top 0.155 m high
    new = scene.add(_looking_down(depth, 0.455))
    cells = unpack_voxel_keys(scene.keys)
    assert new == len(scene) > 300
    assert set(cells[:, 2]) == {15}  # z in [0.15, 0.16): one layer
    # The image spans about 0.32 m x 0.24 m at 0.3 m: so does the layer (10 mm cells).
    extent = (cells.max(axis=0) - cells.min(axis=0) + 1)[:2] * 0.01
    assert np.allclose(sorted(extent), [0.24, 0.32], atol=0.03)
    assert scene.add(_looking_down(depth, 0.455)) == 0  # seen again: nothing new


def test_the_floor_is_left_to_the_cell_and_invalid_depth_is_ignored() -> None:
    scene = ObservedScene()
    depth = np.full((120, 160), 0.455, dtype=np.float32)  # the floor itself
    depth[:, :40] = np.nan  # no depth
    depth[:, 40:80] = 0.3  # a box top, 0.155 m high
    assert scene.add(_looking_down(depth, 0.455)) > 0
    cells = unpack_voxel_keys(scene.keys)
    assert set(cells[:, 2]) == {15}  # the box's top only: no floor cells


def test_the_mesh_is_the_closed_boundary_of_the_voxels() -> None:
    scene = ObservedScene()
    assert scene.mesh()[1].shape == (0, 3)
    depth = np.full((12, 16), 0.3, dtype=np.float32)
    scene.add(_looking_down(depth, 0.455))
    vertices, faces = scene.mesh()
    n = len(scene)
    cells = unpack_voxel_keys(scene.keys)
    # Every voxel has its top and bottom exposed; a one-layer sheet shares its side faces.
    assert len(faces) >= 4 * n and len(faces) % 2 == 0
    # Closed and consistent: every edge is shared by exactly two triangles.
    edges = Counter(
        tuple(sorted(e)) for f in faces.tolist() for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))
    )
    assert set(edges.values()) == {2}
    # The vertices are the voxels' corners, in metres.
    assert np.allclose(vertices / 0.01, np.round(vertices / 0.01))
    lo, hi = cells.min(axis=0) * 0.01, (cells.max(axis=0) + 1) * 0.01
    assert np.allclose(vertices.min(axis=0), lo) and np.allclose(vertices.max(axis=0), hi)
