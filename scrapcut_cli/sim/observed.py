"""What the simulated cell's camera has observed: occupied voxels, and a collision mesh of them.

A real cell cannot know the mesh of a piece it has not seen. Like MoveIt's occupancy map
monitor, which fills the planning scene's octomap from the depth stream, the simulated cell
keeps the occupied voxels of every depth image it captured (read back as a reader would: the
recorded depth and the pose from the joint encoders and the NOMINAL hand-eye calibration),
and answers collision queries against them, never against the piece's true mesh.

Occupied space is what the depth showed. Space near it is not assumed free: like an octomap
that keeps free, occupied and unknown cells apart, the scene carves free space along each depth
ray up to the surface it hit, and the cells within ``unknown_band_m`` of an observed surface
that no ray crossed (a piece's unseen rim, its back, where it goes on out of view) count as
occupied too. Without that band, a hand came within 3 mm of a beam's flange the first view had
not seen (yard noise, seed 0). What a link passes near is kept ``RobotLimits.object_margin_m``
away from all of it. Points below ``floor_band_m`` are dropped: the floor is known to the cell
as a plane with its own margin (what stands on it is observed), as a real cell crops its table
from the depth.

Voxels are ``voxel_m`` cubes on a grid at the origin of the base frame, kept as sorted packed
int64 keys (``geometry.pack_voxel_keys``). :meth:`ObservedScene.mesh` is the boundary of their
union as triangles (faces between two occupied voxels are dropped), which pybullet takes as one
concave collision mesh (``sim.robot.PandaSim.set_observed``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.geometry import pack_voxel_keys, unpack_voxel_keys, voxel_keys
from scrapcut_cli.perception.cloud import backproject_pixels, grid_pixels, usable_depth_pixels
from scrapcut_cli.recording.frame import Frame

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ObservedSettings:
    """How the simulated cell turns depth images into obstacles (metres).

    ``voxel_m`` edge of a cell (10 mm, a common octomap resolution for arm planning); depth
    pixels are sampled on a grid giving about ``samples_per_voxel`` per cell at ``near_m``;
    depth outside ``min_depth_m``–``max_depth_m`` and flying pixels (a jump of more than
    ``flying_pixel_ratio`` × depth to a neighbour) are ignored, as in perception; points lower
    than ``floor_band_m`` are the floor, which the cell knows as a plane; space within
    ``unknown_band_m`` of an observed surface that no ray has passed through is unknown, and
    counts as occupied (assumed: what was seen of a piece goes on, or has a rim or a back, at
    most that far out of sight).
    """

    voxel_m: float = 0.01
    samples_per_voxel: float = 2.0
    near_m: float = 0.2
    min_depth_m: float = 0.1
    max_depth_m: float = 2.0
    flying_pixel_ratio: float = 0.03
    floor_band_m: float = 0.01
    unknown_band_m: float = 0.05


class ObservedScene:
    """What the cell's camera observed, as voxel sets (packed keys, ascending, base frame).

    ``keys`` the occupied cells (observed surface); ``free`` the cells depth rays passed
    through on their way to a surface (seen empty); ``near`` the cells within
    ``unknown_band_m`` of an occupied one. The obstacles are ``keys`` and the ``near`` cells
    not seen free (:meth:`obstacle_keys`).
    """

    def __init__(self, settings: ObservedSettings | None = None) -> None:
        self.settings = settings or ObservedSettings()
        if not self.settings.voxel_m > 0:
            raise ValueError(f"voxel_m must be positive, got {self.settings.voxel_m}")
        self.keys = np.zeros(0, dtype=np.int64)
        self.free = np.zeros(0, dtype=np.int64)
        self.near = np.zeros(0, dtype=np.int64)
        self.frames = 0
        r = int(np.floor(self.settings.unknown_band_m / self.settings.voxel_m + 1e-9))
        grid = np.mgrid[-r : r + 1, -r : r + 1, -r : r + 1].reshape(3, -1).T
        self._ball = grid[np.einsum("ij,ij->i", grid, grid) <= r * r].astype(np.int64)

    def __len__(self) -> int:
        return int(self.keys.size)

    def add(self, frame: Frame) -> int:
        """Take ``frame``'s depth: its surface points become occupied, the space their rays
        crossed free, and the band around new surface cells near. Returns the number of newly
        occupied cells."""
        s = self.settings
        camera = frame.camera
        focal = min(camera.fx, camera.fy)
        stride = max(1, int(s.voxel_m * focal / (s.samples_per_voxel * s.near_m)))
        pixels, _ = grid_pixels(frame.depth.shape, stride)
        usable = usable_depth_pixels(
            frame.depth,
            pixels,
            min_depth_m=s.min_depth_m,
            max_depth_m=s.max_depth_m,
            flying_pixel_ratio=s.flying_pixel_ratio,
        )
        points = backproject_pixels(camera, frame.depth, usable, frame.T_base_cam)
        self.frames += 1
        if len(points) == 0:
            return 0
        eye = np.asarray(frame.T_base_cam, dtype=np.float64)[:3, 3]
        self.free = np.union1d(self.free, self._crossed(eye, points))
        # The floor is known (a plane with its own margin); what lies on it is observed.
        surface = points[points[:, 2] >= s.floor_band_m]
        if len(surface) == 0:
            return 0
        keys = np.unique(pack_voxel_keys(voxel_keys(surface, s.voxel_m)))
        new = keys[~_sorted_contains(self.keys, keys)]
        self.keys = np.union1d(self.keys, keys)
        if new.size:
            band = unpack_voxel_keys(new)[:, None, :] + self._ball[None, :, :]
            self.near = np.union1d(self.near, pack_voxel_keys(band.reshape(-1, 3)))
        return int(new.size)

    def _crossed(self, eye: FloatArray, points: FloatArray) -> NDArray[np.int64]:
        """Cells (packed keys) the rays from ``eye`` to ``points`` (N, 3) cross before they come
        within one cell of the surface they hit."""
        s = self.settings
        rays = points - eye
        length = np.linalg.norm(rays, axis=1)
        step = 0.5 * s.voxel_m
        t = np.arange(0.0, float(length.max()), step)
        reach = (length - s.voxel_m)[:, None]
        inside = t[None, :] < reach
        ray_index, sample = np.nonzero(inside)
        if ray_index.size == 0:
            return np.zeros(0, dtype=np.int64)
        along = rays[ray_index] / length[ray_index, None] * t[sample, None]
        return np.unique(pack_voxel_keys(voxel_keys(eye + along, s.voxel_m)))

    def obstacle_keys(self) -> NDArray[np.int64]:
        """Cells (packed keys, ascending) collision checks treat as occupied: the observed
        surface, and the unknown band around it (``near`` minus ``free``)."""
        unknown = self.near[~_sorted_contains(self.free, self.near)]
        return np.union1d(self.keys, unknown)

    def mesh(self) -> tuple[FloatArray, NDArray[np.int64]]:
        """Boundary of the obstacle cells (:meth:`obstacle_keys`): vertices (V, 3) float64
        metres, base frame, and triangles (F, 3) int64, two per exposed cell face (empty arrays
        when there are none)."""
        occupied = self.obstacle_keys()
        if occupied.size == 0:
            return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
        cells = unpack_voxel_keys(occupied)  # (N, 3) integer voxel coordinates
        corners: list[NDArray[np.int64]] = []
        for axis in range(3):
            for side in (0, 1):
                step = np.zeros(3, dtype=np.int64)
                step[axis] = 1 if side else -1
                neighbour = pack_voxel_keys(cells + step)
                exposed = cells[~_sorted_contains(occupied, neighbour)]
                if len(exposed) == 0:
                    continue
                corners.append(_face_corners(exposed, axis, side))
        quads = np.concatenate(corners)  # (Q, 4, 3) integer corner coordinates
        unique, inverse = np.unique(pack_voxel_keys(quads.reshape(-1, 3)), return_inverse=True)
        index = inverse.reshape(-1, 4).astype(np.int64)
        faces = np.concatenate([index[:, [0, 1, 2]], index[:, [0, 2, 3]]])
        return unpack_voxel_keys(unique).astype(np.float64) * self.settings.voxel_m, faces


def _sorted_contains(sorted_keys: NDArray[np.int64], keys: NDArray[np.int64]) -> NDArray[np.bool_]:
    """(N,) True where ``keys`` (N,) occur in the ascending array ``sorted_keys``."""
    at = np.searchsorted(sorted_keys, keys)
    inside = at < sorted_keys.size
    found = np.zeros(keys.size, dtype=bool)
    found[inside] = sorted_keys[at[inside]] == keys[inside]
    return found


def _face_corners(cells: NDArray[np.int64], axis: int, side: int) -> NDArray[np.int64]:
    """Integer corners (N, 4, 3) of the face of each cell (N, 3) on ``axis``'s low (0) or high
    (1) side, in order around the face."""
    u, v = [a for a in range(3) if a != axis]
    square = np.zeros((4, 3), dtype=np.int64)
    square[:, axis] = side
    square[:, u] = (0, 1, 1, 0)
    square[:, v] = (0, 0, 1, 1)
    return cells[:, None, :] + square[None, :, :]
