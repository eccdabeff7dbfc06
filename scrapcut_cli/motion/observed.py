"""What the camera saw of the scene: the surface, and the space it never saw around the piece.

A plan checked only against observed points treats everything the scan did not look at as
free; a scan follows the painted line, so the far flange of a beam or the inside of a corner
beyond the line's ends can be missing, and a torch or wrist swung there would hit it. So the
scene also keeps the **unseen** space near the piece, as an obstacle (OctoMap's "unknown"):

- the surface: every usable depth pixel on a grid, back-projected with its frame's pose,
  one point per ``surface_voxel_m`` voxel (fine, for the arm's and torch's clearances);
- free space: the rays of a coarser grid of pixels, from the camera to a little before the
  surface they hit, marked on ``free_voxel_m`` voxels;
- unseen: inside the piece's bounds (the box around the observed points above the floor,
  from the floor to their highest point), the voxels neither on the surface nor on any ray.

Above the piece's highest observed point nothing counts as unseen: the arm moves there, and
an eye-in-hand camera never looks at the space behind itself. All of it is numpy over voxel
keys (``geometry.pack_voxel_keys``); no simulator truth is used.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.config import PerceptionConfig
from scrapcut_cli.geometry import pack_voxel_keys, unpack_voxel_keys, voxel_keys
from scrapcut_cli.perception.cloud import backproject_pixels, grid_pixels, usable_depth_pixels
from scrapcut_cli.recording.frame import Frame

FloatArray = NDArray[np.float64]

#: Depth the sampling grids are laid out for (scans run at 0.2-0.45 m).
NEAR_M = 0.25
#: Surface samples per surface voxel at NEAR_M, and free-space rays per free voxel.
SURFACE_SAMPLES = 2.0
RAY_SAMPLES = 2.0
#: Points this close above the floor are the floor, not the piece.
FLOOR_BAND_M = 0.015


@dataclass(frozen=True, eq=False)
class ObservedScene:
    """The observed surface and the unseen space near the piece (base frame, metres).

    ``surface`` (N, 3): one point per surface voxel; ``unseen`` (M, 3): centres of the unseen
    ``free_voxel_m`` voxels inside ``bounds`` (2, 3) (min, max corner; None without a piece).
    """

    surface: FloatArray
    unseen: FloatArray
    free_voxel_m: float
    bounds: FloatArray | None
    info: dict[str, Any] = field(default_factory=dict)


class SceneBuilder:
    """Accumulates frames (:meth:`add`) into an :class:`ObservedScene` (:meth:`build`)."""

    def __init__(
        self,
        *,
        surface_voxel_m: float,
        free_voxel_m: float,
        perception: PerceptionConfig,
        floor_z_m: float = 0.0,
    ) -> None:
        self.surface_voxel_m = float(surface_voxel_m)
        self.free_voxel_m = float(free_voxel_m)
        self.perception = perception
        self.floor_z_m = float(floor_z_m)
        self._keys = np.zeros(0, dtype=np.int64)
        self._rays: list[tuple[FloatArray, FloatArray]] = []
        self.frames = 0

    def _points(self, frame: Frame, voxel_m: float, samples: float) -> FloatArray:
        camera = frame.camera
        focal = min(camera.fx, camera.fy)
        stride = max(1, int(voxel_m * focal / (samples * NEAR_M)))
        pixels, _ = grid_pixels(frame.depth.shape, stride)
        usable = usable_depth_pixels(
            frame.depth,
            pixels,
            min_depth_m=self.perception.min_depth_m,
            max_depth_m=self.perception.max_depth_m,
            flying_pixel_ratio=self.perception.flying_pixel_ratio,
        )
        return backproject_pixels(camera, frame.depth, usable, frame.T_base_cam)

    def add(self, frame: Frame) -> None:
        """Add one frame's surface points and free-space rays."""
        pts = self._points(frame, self.surface_voxel_m, SURFACE_SAMPLES)
        if len(pts):
            keys = pack_voxel_keys(voxel_keys(pts, self.surface_voxel_m))
            self._keys = np.union1d(self._keys, keys)
        ends = self._points(frame, self.free_voxel_m, RAY_SAMPLES)
        if len(ends):
            self._rays.append((np.asarray(frame.T_base_cam, dtype=np.float64)[:3, 3], ends))
        self.frames += 1

    def build(self) -> ObservedScene:
        """The scene so far (see the module docstring)."""
        surface = np.asarray(
            (unpack_voxel_keys(self._keys) + 0.5) * self.surface_voxel_m, dtype=np.float64
        )
        v = self.free_voxel_m
        piece = surface[surface[:, 2] > self.floor_z_m + FLOOR_BAND_M]
        if len(piece) == 0:
            return ObservedScene(surface, np.zeros((0, 3)), v, None, {"unseen_voxels": 0})
        lo = np.floor(piece.min(axis=0) / v) - 1
        hi = np.floor(piece.max(axis=0) / v) + 1
        lo[2] = np.floor((self.floor_z_m + FLOOR_BAND_M) / v)
        hi[2] = np.floor(piece[:, 2].max() / v)
        box_lo, box_hi = lo * v, (hi + 1) * v
        occupied = np.unique(pack_voxel_keys(voxel_keys(surface, v)))
        free = np.zeros(0, dtype=np.int64)
        for centre, ends in self._rays:
            keys = _ray_keys(centre, ends, box_lo, box_hi, v)
            if len(keys):
                free = np.union1d(free, keys)
        axes = [np.arange(lo[k], hi[k] + 1, dtype=np.int64) for k in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        keys = pack_voxel_keys(grid)
        unseen = keys[~np.isin(keys, occupied) & ~np.isin(keys, free)]
        centres = np.asarray((unpack_voxel_keys(unseen) + 0.5) * v, dtype=np.float64)
        info = {
            "unseen_voxels": len(unseen),
            "free_voxels": len(free),
            "box_voxels": len(keys),
            "bounds_m": [box_lo.tolist(), box_hi.tolist()],
        }
        return ObservedScene(surface, centres, v, np.array([box_lo, box_hi]), info)


def observe(
    frames: Iterable[Frame],
    *,
    surface_voxel_m: float,
    free_voxel_m: float,
    perception: PerceptionConfig,
    floor_z_m: float = 0.0,
) -> ObservedScene:
    """:class:`SceneBuilder` over ``frames``."""
    builder = SceneBuilder(
        surface_voxel_m=surface_voxel_m,
        free_voxel_m=free_voxel_m,
        perception=perception,
        floor_z_m=floor_z_m,
    )
    for frame in frames:
        builder.add(frame)
    return builder.build()


def _ray_keys(
    centre: FloatArray, ends: FloatArray, box_lo: FloatArray, box_hi: FloatArray, voxel_m: float
) -> NDArray[np.int64]:
    """Packed keys of the voxels the rays from ``centre`` (3,) to ``ends`` (R, 3) cross inside
    the box, stopping short of each surface point (half a voxel plus depth noise)."""
    d = ends - centre
    length = np.linalg.norm(d, axis=1)
    d = d / length[:, None]
    stop = length - 0.6 * voxel_m
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (box_lo - centre) / d
        t2 = (box_hi - centre) / d
    t_in = np.nanmax(np.minimum(t1, t2), axis=1)
    t_out = np.nanmin(np.maximum(t1, t2), axis=1)
    t_in = np.maximum(t_in, 0.0)
    t_out = np.minimum(t_out, stop)
    keep = t_out > t_in
    if not keep.any():
        return np.zeros(0, dtype=np.int64)
    d, t_in, t_out = d[keep], t_in[keep], t_out[keep]
    step = 0.5 * voxel_m
    n = int(np.ceil(float(np.max(t_out - t_in)) / step)) + 1
    t = t_in[:, None] + step * np.arange(n)[None, :]
    inside = t <= t_out[:, None]
    pts = centre + t[inside][:, None] * np.repeat(d, inside.sum(axis=1), axis=0)
    return np.unique(pack_voxel_keys(voxel_keys(pts, voxel_m)))
