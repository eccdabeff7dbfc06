"""Tests of scrapcut_cli.sim.observed: the simulated cell's obstacles from depth images: the
observed surface, the space seen free, and the unknown band around the surface."""

from __future__ import annotations

from collections import Counter

import numpy as np

from scrapcut_cli.geometry import look_at, pack_voxel_keys, unpack_voxel_keys
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


def _has(keys: np.ndarray, point: tuple[float, float, float]) -> bool:
    key = pack_voxel_keys(np.floor(np.asarray([point]) / 0.01).astype(np.int64))[0]
    return bool(np.isin(key, keys))


def test_space_near_the_surface_is_free_only_where_rays_crossed_it() -> None:
    """A table top 0.155 m high seen from 0.3 m above its middle: the air above it is seen
    free; below it (its inside) and just past the image's edge it is unknown and counts as an
    obstacle, within the 5 cm band; farther out nothing is assumed."""
    scene = ObservedScene()
    scene.add(_looking_down(np.full((120, 160), 0.3, dtype=np.float32), 0.455))
    obstacles = scene.obstacle_keys()
    cells = unpack_voxel_keys(scene.keys)
    x_edge = (cells[:, 0].max() + 1) * 0.01  # where the image's view of the top ends
    assert _has(obstacles, (0.5, 0.0, 0.155))  # the surface
    assert _has(scene.free, (0.5, 0.0, 0.20)) and not _has(obstacles, (0.5, 0.0, 0.20))
    assert _has(obstacles, (0.5, 0.0, 0.125))  # 3 cm inside the top: unknown
    assert _has(obstacles, (x_edge + 0.03, 0.0, 0.155))  # 3 cm past the seen edge
    assert not _has(obstacles, (x_edge + 0.08, 0.0, 0.155))  # 8 cm past it: not assumed
    assert not _has(obstacles, (0.5, 0.0, 0.09))  # 6.5 cm under the top: not assumed
    # A second view from the side sees into the band past the edge: that space becomes free.
    side = look_at((x_edge + 0.25, 0.0, 0.30), (x_edge + 0.03, 0.0, 0.0), up_hint=(0.0, 0.0, 1.0))
    floor = np.full((120, 160), np.nan, dtype=np.float32)
    frame = _looking_down(floor, 0.455)
    depth = np.full((120, 160), float(np.linalg.norm(side[:3, 3] - (x_edge + 0.03, 0.0, 0.0))))
    scene.add(Frame(1, 2, frame.color, depth.astype(np.float32), frame.camera, side))
    assert not _has(scene.obstacle_keys(), (x_edge + 0.03, 0.0, 0.155))


def test_the_mesh_is_the_closed_boundary_of_the_voxels() -> None:
    scene = ObservedScene()
    assert scene.mesh()[1].shape == (0, 3)
    depth = np.full((12, 16), 0.3, dtype=np.float32)
    scene.add(_looking_down(depth, 0.455))
    vertices, faces = scene.mesh()
    cells = unpack_voxel_keys(scene.obstacle_keys())
    assert len(faces) > 0 and len(faces) % 2 == 0  # two triangles per exposed face
    # Closed: every edge is shared by two triangles (four where two cells meet along an edge).
    edges = Counter(
        tuple(sorted(e)) for f in faces.tolist() for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))
    )
    assert set(edges.values()) <= {2, 4} and 2 in set(edges.values())
    # The vertices are the voxels' corners, in metres.
    assert np.allclose(vertices / 0.01, np.round(vertices / 0.01))
    lo, hi = cells.min(axis=0) * 0.01, (cells.max(axis=0) + 1) * 0.01
    assert np.allclose(vertices.min(axis=0), lo) and np.allclose(vertices.max(axis=0), hi)
