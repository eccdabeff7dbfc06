"""What the camera has seen as obstacles: a voxel hash of observed depth, and the clearance tests.

The planner never sees the piece's mesh. Like OctoMap in the paper, it keeps the occupied cells
of every depth image it took; a candidate view is refused when the camera and hand (a capsule
along the optical axis) would come within the inflation margin of an occupied cell, or when an
occupied cell hides the target from the camera. Only occupied cells are stored (free and unknown
space are not told apart): the simulator's reachability answer, from the robot's own model,
is the second check.

The map is a sorted array of packed int64 voxel keys (``geometry.pack_voxel_keys``), merged
with ``np.union1d`` per frame; clearance queries use a KD-tree over the occupied voxel centres
(scipy), rebuilt lazily after the map grows. A capsule test is a handful of ball queries along
its axis, so a candidate view costs well under a millisecond.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.geometry import pack_voxel_keys, unpack_voxel_keys, voxel_keys
from scrapcut_cli.perception.cloud import backproject_pixels, grid_pixels, usable_depth_pixels
from scrapcut_cli.recording.frame import Frame

FloatArray = NDArray[np.float64]

#: Depth pixels are sampled about this many per occupancy voxel at the nearest depth used.
SAMPLES_PER_VOXEL = 2.0


class OccupancyMap:
    """Occupied voxels (``voxel_size_m`` cubes on a grid at the origin, base frame).

    Parameters
    ----------
    voxel_size_m : float
        Edge of a cell, metres.
    """

    def __init__(self, voxel_size_m: float) -> None:
        if not voxel_size_m > 0:
            raise ValueError(f"voxel_size_m must be positive, got {voxel_size_m}")
        self.voxel_size_m = float(voxel_size_m)
        self.keys = np.zeros(0, dtype=np.int64)
        self._tree: cKDTree | None = None

    def __len__(self) -> int:
        return int(self.keys.size)

    def add(self, points_base: ArrayLike) -> int:
        """Mark the cells holding ``points_base`` (N, 3) float64, metres, base frame, occupied.

        Returns the number of newly occupied cells.
        """
        pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 3)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts) == 0:
            return 0
        before = self.keys.size
        self.keys = np.union1d(self.keys, pack_voxel_keys(voxel_keys(pts, self.voxel_size_m)))
        if self.keys.size != before:
            self._tree = None
        return int(self.keys.size - before)

    @property
    def centres(self) -> FloatArray:
        """Centres (M, 3) float64, metres, base frame, of the occupied cells."""
        return np.asarray((unpack_voxel_keys(self.keys) + 0.5) * self.voxel_size_m)

    def _kdtree(self) -> cKDTree | None:
        if self.keys.size == 0:
            return None
        if self._tree is None:
            self._tree = cKDTree(self.centres)
        return self._tree

    def centres_within(self, point: ArrayLike, radius_m: float) -> FloatArray:
        """Centres (K, 3) of the occupied cells within ``radius_m`` of ``point`` (3,), in
        ascending key order."""
        tree = self._kdtree()
        if tree is None:
            return np.zeros((0, 3))
        index = sorted(tree.query_ball_point(np.asarray(point, dtype=np.float64), radius_m))
        return np.asarray(tree.data[index], dtype=np.float64).reshape(-1, 3)

    def occupied_within(self, points_base: ArrayLike, radius_m: float) -> NDArray[np.bool_]:
        """(N,) True where an occupied cell lies within ``radius_m`` of the point.

        A cell counts from its nearest point: its centre within ``radius_m`` plus half its
        diagonal, so a thin obstacle is never missed between two centres.
        """
        pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 3)
        tree = self._kdtree()
        if tree is None or len(pts) == 0:
            return np.zeros(len(pts), dtype=bool)
        reach = float(radius_m) + 0.5 * np.sqrt(3.0) * self.voxel_size_m
        distance, _ = tree.query(pts, distance_upper_bound=reach)
        return np.asarray(np.isfinite(distance))

    def segment_clear(self, start: ArrayLike, end: ArrayLike, radius_m: float) -> bool:
        """True when no occupied cell is within ``radius_m`` of the segment start–end (metres).

        The segment is sampled every half voxel (or finer), each sample a ball query.
        """
        a = np.asarray(start, dtype=np.float64).reshape(3)
        b = np.asarray(end, dtype=np.float64).reshape(3)
        length = float(np.linalg.norm(b - a))
        spacing = 0.5 * self.voxel_size_m
        n = max(int(np.ceil(length / spacing)), 1) + 1
        samples = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        return not bool(self.occupied_within(samples, radius_m).any())


def depth_points(
    frame: Frame,
    *,
    voxel_size_m: float,
    near_m: float,
    min_depth_m: float,
    max_depth_m: float,
    flying_pixel_ratio: float,
) -> FloatArray:
    """Observed surface points (N, 3) float64, metres, base frame, for the occupancy map.

    Valid depth pixels on a regular grid whose stride gives about :data:`SAMPLES_PER_VOXEL`
    samples per ``voxel_size_m`` at depth ``near_m`` (the nearest views; a surface twice as far
    is still sampled once per cell), gated like the paint (depth range ``min_depth_m`` to
    ``max_depth_m``, flying pixels), back-projected with the frame's pose.
    """
    camera = frame.camera
    focal = min(camera.fx, camera.fy)
    stride = max(1, int(voxel_size_m * focal / (SAMPLES_PER_VOXEL * max(near_m, 0.05))))
    pixels, _ = grid_pixels(frame.depth.shape, stride)
    usable = usable_depth_pixels(
        frame.depth,
        pixels,
        min_depth_m=min_depth_m,
        max_depth_m=max_depth_m,
        flying_pixel_ratio=flying_pixel_ratio,
    )
    return backproject_pixels(camera, frame.depth, usable, frame.T_base_cam)
