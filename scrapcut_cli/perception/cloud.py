"""Per-frame clouds: paint pixels → base-frame points, cleaned and downsampled, plus the surface.

The recipe of one frame (:func:`process_frame`), in order:

1. colour filter (:func:`~scrapcut_cli.perception.paint.paint_pixel_indices`), then isolated
   paint pixels dropped (fewer than ``min_paint_neighbors`` of 4 neighbours in the range:
   camera noise lifting single pixels of rust into the range), then small blobs (8-connected
   paint covering less than ``min_paint_area_m2`` of surface: overspray specks, which stitch
   into a halo around the stroke and past its ends);
2. depth gate: valid depth within ``[min_depth_m, max_depth_m]`` and no flying pixel (a depth
   that jumps by more than ``flying_pixel_ratio × depth`` to one of its 4-neighbours: the
   smeared pixels a stereo camera produces across depth edges);
3. back-projection of only those pixels through the camera's cached, distortion-aware ray grid,
   into the base frame with ``T_base_cam`` (the full cloud is never built);
4. voxel downsampling (``voxel_size_m``) and then statistical outlier removal (open3d). The
   paper removes outliers first; downsampling first makes the outlier test see neighbours on the
   scale of the stroke instead of sensor noise, and costs 1 ms instead of 30 ms per frame;
5. the surface band: non-paint pixels within ``surface_band_m`` (in 3-D) of the paint, sampled
   on a pixel grid about half a ``surface_voxel_m`` apart, downsampled at ``surface_voxel_m``.
   The tool path takes its normals and collision checks from it, on both sides of the stroke.

:class:`PerceptionTally` counts frames, pixels, points and skip reasons over a recording and
raises the "no paint found" error with the dominant hues the images showed instead.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import label, maximum_filter
from scipy.spatial import cKDTree

from scrapcut_cli._open3d import o3d
from scrapcut_cli.config import PerceptionConfig
from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.perception.paint import HsvRange, HueHistogram, paint_pixel_indices
from scrapcut_cli.recording.frame import CameraModel, Frame

FloatArray = NDArray[np.float64]

#: 8-connectivity of image blobs: specks touching at a corner are one blob.
_EIGHT = np.ones((3, 3), dtype=bool)

#: Why a frame contributed no paint points.
SKIP_NO_PAINT = "no_paint"
#: Pixels in the colour range, but only isolated ones or small blobs (camera noise on rust,
#: overspray specks): no stroke.
SKIP_SCATTERED_PAINT = "scattered_paint"
SKIP_NO_VALID_DEPTH = "no_valid_depth"
SKIP_TOO_LITTLE_PAINT = "too_little_paint"
#: More of the image in the paint's colour than PerceptionConfig.max_paint_share: no stroke.
SKIP_PAINT_FILLS_IMAGE = "paint_fills_image"


@dataclass(frozen=True, eq=False)
class FrameClouds:
    """The clouds of one frame, base frame.

    Attributes
    ----------
    frame_index, stamp_ns : int
        The frame's position in the recording and its image stamp.
    paint_base : (N, 3) float64
        Metres, base frame: paint points after depth gate, downsampling and outlier removal.
    surface_base : (M, 3) float64
        Metres, base frame: non-paint points within ``surface_band_m`` of the paint, downsampled.
    paint_pixels : int
        Pixels in the colour range.
    valid_paint_pixels : int
        Of those, pixels with usable depth (in range, not flying) that were back-projected.
    T_base_cam : (4, 4) float64
        The camera pose the points were projected with.
    skip_reason : str or None
        ``no_paint``, ``scattered_paint``, ``no_valid_depth`` or ``too_little_paint`` when
        ``paint_base`` is empty.
    """

    frame_index: int
    stamp_ns: int
    paint_base: FloatArray
    surface_base: FloatArray
    paint_pixels: int
    valid_paint_pixels: int
    T_base_cam: FloatArray
    skip_reason: str | None = None

    @property
    def camera_position(self) -> FloatArray:
        """Optical centre (3,), metres, base frame."""
        return np.asarray(self.T_base_cam[:3, 3], dtype=np.float64)

    @property
    def skipped(self) -> bool:
        """True when the frame gave no paint points."""
        return self.skip_reason is not None


def check_perception_config(config: PerceptionConfig) -> None:
    """Raise :class:`PerceptionError` naming the first parameter out of its range."""
    positive = {
        "voxel_size_m": config.voxel_size_m,
        "surface_voxel_m": config.surface_voxel_m,
        "max_depth_m": config.max_depth_m,
        "sor_std_ratio": config.sor_std_ratio,
        "flying_pixel_ratio": config.flying_pixel_ratio,
    }
    for name, value in positive.items():
        if not value > 0:
            raise PerceptionError(f"perception.{name} must be positive, got {value}")
    if config.min_depth_m < 0 or config.min_depth_m >= config.max_depth_m:
        raise PerceptionError(
            f"perception depth range must satisfy 0 <= min < max, got "
            f"{config.min_depth_m}-{config.max_depth_m} m"
        )
    if config.surface_band_m < 0:
        raise PerceptionError(
            f"perception.surface_band_m must be >= 0, got {config.surface_band_m}"
        )
    if not config.min_paint_area_m2 >= 0:  # NaN fails too
        raise PerceptionError(
            f"perception.min_paint_area_m2 must be >= 0, got {config.min_paint_area_m2}"
        )
    if config.sor_neighbors < 0 or config.min_paint_points < 0:
        raise PerceptionError(
            f"perception.sor_neighbors and min_paint_points must be >= 0, got "
            f"{config.sor_neighbors} and {config.min_paint_points}"
        )


# --------------------------------------------------------------------------- stages


def usable_depth_pixels(
    depth_m: NDArray[np.float32],
    pixels: NDArray[np.intp],
    *,
    min_depth_m: float,
    max_depth_m: float,
    flying_pixel_ratio: float,
) -> NDArray[np.intp]:
    """The subset of ``pixels`` (flat indices into an (H, W) depth image) with usable depth.

    Usable: finite, within ``[min_depth_m, max_depth_m]``, and not a flying pixel — its depth
    differs from none of its 4-neighbours by more than ``flying_pixel_ratio × depth``
    (neighbours that are holes are ignored). Only the given pixels are examined.
    """
    height, width = depth_m.shape
    flat = depth_m.reshape(-1)
    z = np.take(flat, pixels)
    keep = (z >= min_depth_m) & (z <= max_depth_m)  # NaN compares False
    pixels, z = pixels[keep], z[keep]
    if pixels.size == 0:
        return pixels
    v, u = np.divmod(pixels, width)
    jump = np.zeros(pixels.size, dtype=np.float32)
    step = np.empty(pixels.size, dtype=np.float32)
    for neighbour in (
        np.where(u > 0, pixels - 1, pixels),
        np.where(u < width - 1, pixels + 1, pixels),
        np.where(v > 0, pixels - width, pixels),
        np.where(v < height - 1, pixels + width, pixels),
    ):
        np.subtract(np.take(flat, neighbour), z, out=step)
        np.abs(step, out=step)
        np.fmax(jump, step, out=jump)  # fmax skips NaN holes
    return pixels[jump <= flying_pixel_ratio * z]


def grid_pixels(shape: tuple[int, int], stride: int) -> tuple[NDArray[np.intp], tuple[int, int]]:
    """Flat indices of every ``stride``-th pixel of an (H, W) image, starting at
    ``stride // 2`` in both directions (row-major), and the grid's (rows, cols)."""
    height, width = shape
    v, u = np.mgrid[stride // 2 : height : stride, stride // 2 : width : stride]
    return (v * width + u).reshape(-1).astype(np.intp), (v.shape[0], v.shape[1])


def reject_isolated_pixels(
    pixels: NDArray[np.intp], shape: tuple[int, int], *, min_neighbors: int
) -> NDArray[np.intp]:
    """The subset of ``pixels`` (ascending flat indices) with >= ``min_neighbors`` of their
    4-neighbours also in ``pixels``.

    A stroke is a solid region (its inside and straight edges keep 3 of 4 neighbours); camera
    noise that lifts a few pixels of a dull colour such as rust into the paint range scatters
    them (at a 10 % scatter rate ~5 % of them have two such neighbours, 0.4 % three), and
    overspray specks are blobs of a few pixels.
    """
    if min_neighbors <= 0 or pixels.size == 0:
        return pixels
    height, width = shape
    mask = np.zeros(height * width + 2 * width + 2, dtype=np.int8)  # padded by a row and 1
    padded = pixels + width + 1
    mask[padded] = 1
    count = np.take(mask, padded - 1) + np.take(mask, padded + 1)
    count += np.take(mask, padded - width)
    count += np.take(mask, padded + width)
    # Left/right neighbours of a row's ends wrap to the other side of the image; only the
    # two outermost columns are affected, which a stroke tolerates.
    return pixels[count >= min_neighbors]


def reject_small_blobs(
    pixels: NDArray[np.intp],
    depth_m: NDArray[np.float32],
    camera: CameraModel,
    *,
    min_area_m2: float,
    nearest_m: float,
) -> NDArray[np.intp]:
    """The subset of ``pixels`` (ascending flat indices into the (H, W) ``depth_m`` image) in
    8-connected blobs covering at least ``min_area_m2`` of surface.

    A blob's area is its pixel count times the footprint of a pixel at the blob's RMS depth,
    z^2 / (fx fy), metres^2 (seen face-on; an oblique surface looks smaller). Overspray
    specks are drops a few millimetres across, separate from the stroke in the image; a stroke,
    even a sliver at the image's edge or the paint on one wire of a mesh, covers far more.
    Blobs whose pixels have no valid depth are kept (their size is unknown; the depth gate
    decides). Only blobs small enough to be under the limit at ``nearest_m`` (the nearest
    usable depth) have their depth looked up. ``min_area_m2 = 0`` keeps all.
    """
    if min_area_m2 <= 0 or pixels.size == 0:
        return pixels
    width = depth_m.shape[1]
    # scipy's labelling is the costly step (0.65 ms for a whole 640x480 frame), so it runs on
    # the box the paint spans only (the pixels are sorted by row); the rest is on the paint.
    row = pixels // width
    col = pixels - row * width
    r0, c0 = int(row[0]), int(col.min())
    box_w = int(col.max()) - c0 + 1
    local = (row - r0) * box_w + (col - c0)
    mask = np.zeros((int(row[-1]) - r0 + 1) * box_w, dtype=bool)
    mask[local] = True
    labels, n = label(mask.reshape(-1, box_w), structure=_EIGHT)
    if n <= 1:
        return pixels
    blob = labels.reshape(-1)[local]
    count = np.bincount(blob, minlength=n + 1)
    footprint = 1.0 / (camera.fx * camera.fy)  # pixel area per metre^2 of depth^2
    small = count * (max(nearest_m, 1e-3) ** 2 * footprint) < min_area_m2
    candidate = small[blob]
    if not candidate.any():
        return pixels
    z = np.take(depth_m.reshape(-1), pixels[candidate]).astype(np.float64)
    which = blob[candidate]
    valid = np.isfinite(z) & (z > 0.0)
    z2 = np.bincount(which[valid], weights=z[valid] ** 2, minlength=n + 1)
    seen = np.bincount(which[valid], minlength=n + 1)
    area = count * z2 / np.maximum(seen, 1) * footprint
    drop = small & (seen > 0) & (area < min_area_m2)
    return pixels[~drop[blob]]


def backproject_pixels(
    camera: CameraModel,
    depth_m: NDArray[np.float32],
    pixels: NDArray[np.intp],
    T_base_cam: ArrayLike,
) -> FloatArray:
    """Points (K, 3) float64, metres, base frame, of the given pixels (flat indices) at their depth.

    Rays come from ``camera.ray_grid()`` (cached per camera, distortion-aware), so a pixel
    costs one gather and a multiply.
    """
    T = np.asarray(T_base_cam, dtype=np.float64)
    rays = np.take(camera.ray_grid().reshape(-1, 2), pixels, axis=0)
    z = np.take(depth_m.reshape(-1), pixels).astype(np.float64)
    x = rays[:, 0] * z
    y = rays[:, 1] * z
    points = np.empty((pixels.size, 3), dtype=np.float64)
    for i in range(3):  # column by column: faster than a (K, 3) @ (3, 3) product here
        points[:, i] = T[i, 0] * x + T[i, 1] * y + T[i, 2] * z + T[i, 3]
    return points


def backproject_paint(
    frame: Frame, hsv: HsvRange, config: PerceptionConfig
) -> tuple[FloatArray, NDArray[np.intp], int]:
    """Colour filter, depth gate and back-projection of one frame: the benchmarked hot path.

    Returns
    -------
    points_base : (K, 3) float64
        Metres, base frame, one point per usable paint pixel.
    pixels : (K,) intp
        Their flat pixel indices.
    paint_pixels : int
        Pixels in the colour range before the depth gate.
    """
    paint = paint_pixel_indices(frame.color, hsv)
    solid = _solid_paint(frame, paint, config)
    usable = usable_depth_pixels(
        frame.depth,
        solid,
        min_depth_m=config.min_depth_m,
        max_depth_m=config.max_depth_m,
        flying_pixel_ratio=config.flying_pixel_ratio,
    )
    return (
        backproject_pixels(frame.camera, frame.depth, usable, frame.T_base_cam),
        usable,
        int(paint.size),
    )


def _solid_paint(
    frame: Frame, paint: NDArray[np.intp], config: PerceptionConfig
) -> NDArray[np.intp]:
    """The colour filter's pixels without isolated pixels and small blobs (step 1)."""
    solid = reject_isolated_pixels(
        paint, frame.depth.shape, min_neighbors=config.min_paint_neighbors
    )
    return reject_small_blobs(
        solid,
        frame.depth,
        frame.camera,
        min_area_m2=config.min_paint_area_m2,
        nearest_m=config.min_depth_m,
    )


def voxel_downsample(points: ArrayLike, voxel_size_m: float) -> FloatArray:
    """Centroids (M, 3) of the points in each occupied voxel of ``voxel_size_m`` (open3d)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return pts.copy()
    o3 = o3d()
    cloud = o3.geometry.PointCloud(o3.utility.Vector3dVector(pts))
    return np.asarray(cloud.voxel_down_sample(voxel_size_m).points, dtype=np.float64)


def remove_statistical_outliers(
    points: ArrayLike, *, neighbors: int, std_ratio: float
) -> FloatArray:
    """Points (M, 3) whose mean distance to their ``neighbors`` nearest is not an outlier.

    open3d's statistical outlier removal: a point goes when its mean neighbour distance exceeds
    the cloud's mean by more than ``std_ratio`` standard deviations. ``neighbors = 0`` keeps all.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if neighbors == 0 or len(pts) <= neighbors:
        return pts.copy()
    o3 = o3d()
    cloud = o3.geometry.PointCloud(o3.utility.Vector3dVector(pts))
    _, kept = cloud.remove_statistical_outlier(nb_neighbors=neighbors, std_ratio=std_ratio)
    return pts[np.asarray(kept, dtype=np.intp)]


def surface_band(
    frame: Frame,
    paint_pixels: NDArray[np.intp],
    paint_base: FloatArray,
    paint_depth_m: float,
    config: PerceptionConfig,
) -> FloatArray:
    """Non-paint points (M, 3), metres, base frame, within ``surface_band_m`` of ``paint_base``.

    Pixels are sampled on a grid of stride ``s`` ≈ half a surface voxel at ``paint_depth_m``;
    grid cells holding paint are dilated by the band's width in pixels at that depth (a box, so
    a superset), and the candidates with usable depth are kept if within the band in 3-D
    (measured to the paint's centroids on a ``surface_band_m / 4`` grid, which moves the band's
    edge by at most ~0.2 band widths and is ten times faster than the full paint cloud).
    """
    if config.surface_band_m == 0 or len(paint_base) == 0:
        return np.zeros((0, 3))
    camera = frame.camera
    height, width = frame.depth.shape
    focal = max(camera.fx, camera.fy)
    stride = max(1, int(config.surface_voxel_m * min(camera.fx, camera.fy) / (2 * paint_depth_m)))
    rows, cols = height // stride, width // stride
    if rows == 0 or cols == 0:
        return np.zeros((0, 3))
    v, u = np.divmod(paint_pixels, width)
    inside = (v < rows * stride) & (u < cols * stride)
    cells = np.zeros(rows * cols, dtype=np.uint8)
    cells[(v[inside] // stride) * cols + u[inside] // stride] = 1
    cells = cells.reshape(rows, cols)
    radius = math.ceil(config.surface_band_m * focal / (paint_depth_m * stride))
    band = maximum_filter(cells, size=2 * radius + 1, mode="constant") > cells
    bi, bj = np.nonzero(band)
    candidates = (bi * stride + stride // 2) * width + bj * stride + stride // 2
    usable = usable_depth_pixels(
        frame.depth,
        candidates.astype(np.intp),
        min_depth_m=config.min_depth_m,
        max_depth_m=config.max_depth_m,
        flying_pixel_ratio=config.flying_pixel_ratio,
    )
    points = backproject_pixels(camera, frame.depth, usable, frame.T_base_cam)
    if len(points) == 0:
        return points
    # Distances to the paint's centroids on a band/4 grid: 10x fewer tree nodes than the paint
    # itself, and the band's edge moves by less than that grid's half diagonal.
    coarse = voxel_downsample(paint_base, config.surface_band_m / 4.0)
    distance, _ = cKDTree(coarse).query(points, distance_upper_bound=config.surface_band_m)
    return voxel_downsample(points[np.isfinite(distance)], config.surface_voxel_m)


# --------------------------------------------------------------------------- the recipe


def process_frame(frame: Frame, hsv: HsvRange, config: PerceptionConfig) -> FrameClouds:
    """Paint and surface clouds of one frame, base frame (see the module docstring's steps).

    Parameters
    ----------
    frame : Frame
        Colour (H, W, 3) uint8, depth (H, W) float32 metres (NaN = invalid), camera, pose.
    hsv : HsvRange
        The paint's colour range.
    config : PerceptionConfig
        Depth gate, flying-pixel ratio, voxel sizes, outlier removal, surface band.

    Returns
    -------
    FrameClouds
        Empty clouds and a ``skip_reason`` when the frame shows no usable paint.
    """
    check_perception_config(config)
    T = np.asarray(frame.T_base_cam, dtype=np.float64)
    empty = np.zeros((0, 3))

    def skipped(reason: str, paint_pixels: int, valid: int) -> FrameClouds:
        return FrameClouds(
            frame.index, frame.stamp_ns, empty, empty, paint_pixels, valid, T, reason
        )

    points, pixels, paint_pixels = backproject_paint(frame, hsv, config)
    if paint_pixels == 0:
        return skipped(SKIP_NO_PAINT, 0, 0)
    if paint_pixels > config.max_paint_share * frame.color.shape[0] * frame.color.shape[1]:
        return skipped(SKIP_PAINT_FILLS_IMAGE, paint_pixels, 0)
    if len(points) == 0:
        # Scattered specks (rust lifted into the range by noise, overspray) and paint without
        # usable depth need different remedies; telling them apart costs a second filter on
        # skipped frames only.
        solid = _solid_paint(frame, paint_pixel_indices(frame.color, hsv), config)
        return skipped(SKIP_NO_VALID_DEPTH if solid.size else SKIP_SCATTERED_PAINT, paint_pixels, 0)
    paint = remove_statistical_outliers(
        voxel_downsample(points, config.voxel_size_m),
        neighbors=config.sor_neighbors,
        std_ratio=config.sor_std_ratio,
    )
    if len(paint) < max(config.min_paint_points, 1):
        return skipped(SKIP_TOO_LITTLE_PAINT, paint_pixels, len(pixels))
    # The nearest quartile of the paint sets the pixel scale of the band (nearer = wider).
    depth = frame.depth.reshape(-1)[pixels[:: max(1, len(pixels) // 512)]]
    paint_depth = float(np.percentile(depth, 25))
    surface = surface_band(frame, pixels, paint, paint_depth, config)
    return FrameClouds(frame.index, frame.stamp_ns, paint, surface, paint_pixels, len(pixels), T)


# --------------------------------------------------------------------------- counting frames


@dataclass
class PerceptionTally:
    """Counts over the frames of a recording; knows what the images showed when paint is absent.

    ``add`` every processed frame; ``raise_if_no_paint`` after the last one.
    """

    hsv: HsvRange
    frames: int = 0
    frames_with_paint: int = 0
    paint_pixels: int = 0
    valid_paint_pixels: int = 0
    paint_points: int = 0
    surface_points: int = 0
    skip_reasons: Counter[str] = field(default_factory=Counter)
    hues: HueHistogram = field(default_factory=HueHistogram)

    def add(self, clouds: FrameClouds, color: NDArray[np.uint8] | None = None) -> None:
        """Count one frame; give its colour image so a paint-less recording can be described."""
        self.frames += 1
        self.paint_pixels += clouds.paint_pixels
        self.valid_paint_pixels += clouds.valid_paint_pixels
        self.paint_points += len(clouds.paint_base)
        self.surface_points += len(clouds.surface_base)
        if clouds.skip_reason is None:
            self.frames_with_paint += 1
        else:
            self.skip_reasons[clouds.skip_reason] += 1
        if (
            color is not None
            and self.frames_with_paint == 0
            and clouds.skip_reason in (SKIP_NO_PAINT, SKIP_SCATTERED_PAINT)
        ):
            # Only needed while no usable paint has been seen; costs ~1 ms a frame then.
            self.hues.add(color)

    def raise_if_no_paint(self) -> None:
        """Raise :class:`PerceptionError` when no frame gave paint points (one line, with hints)."""
        if self.frames == 0:
            raise PerceptionError("the recording has no usable frames to look for paint in")
        if self.frames_with_paint > 0:
            return
        hues = f"dominant hues seen: {self.hues.describe()}"
        if self.paint_pixels == 0:
            raise PerceptionError(
                f"no paint found in any of {self.frames} frames with {self.hsv.describe()}; "
                f"{hues}; try --paint or --hsv H1,H2,S,V"
            )
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(self.skip_reasons.items()))
        hints = []
        if self.skip_reasons[SKIP_SCATTERED_PAINT]:
            hints.append(
                f"scattered pixels are no stroke ({hues}): try --paint, --hsv H1,H2,S,V, "
                "--min-paint-neighbors or a smaller perception.min_paint_area_m2 (--config)"
            )
        if self.skip_reasons[SKIP_NO_VALID_DEPTH]:
            hints.append("check the depth range (--min-depth-mm/--max-depth-mm)")
        if self.skip_reasons[SKIP_TOO_LITTLE_PAINT]:
            hints.append("lower --min-paint-points")
        if self.skip_reasons[SKIP_PAINT_FILLS_IMAGE]:
            hints.append(
                "the colour range covers most of the image, not a stroke (a paint-coloured "
                "surface or light?): choose the paint with --paint or --hsv H1,H2,S,V"
            )
        raise PerceptionError(
            f"{self.paint_pixels} pixels of {self.hsv.describe()} in {self.frames} frames but "
            f"no usable paint points ({reasons}); {'; '.join(hints)}"
        )

    def to_dict(self) -> dict[str, Any]:
        """Counts as a JSON-ready dictionary."""
        return {
            "paint": self.hsv.describe(),
            "frames": self.frames,
            "frames_with_paint": self.frames_with_paint,
            "frames_skipped": self.frames - self.frames_with_paint,
            "skip_reasons": dict(sorted(self.skip_reasons.items())),
            "paint_pixels": self.paint_pixels,
            "valid_paint_pixels": self.valid_paint_pixels,
            "paint_points": self.paint_points,
            "surface_points": self.surface_points,
        }
