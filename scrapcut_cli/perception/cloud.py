"""Per-frame clouds: paint pixels → base-frame points, cleaned and downsampled, plus the surface.

The recipe of one frame (:func:`process_frame`), in order:

0. decimation (:func:`decimation`, up to ``max_decimation``, 8 by default; 1 is off): a
   frame whose pixels are finer than the voxels need at the scene's near depth is read at
   every 2nd (4th, 8th) pixel each way, colour and depth alike: what follows costs the same
   at 1280x720 as at 640x360;
1. colour filter (:func:`~scrapcut_cli.perception.paint.paint_pixel_indices`); when the
   filter's pixels fall into two saturation clusters (a clear dip between modes,
   :func:`~scrapcut_cli.perception.paint.saturation_splits`: fresh paint against rust or an
   old mark of the same hue, which a range cannot tell apart), the duller ones are kept apart
   (``other_base``, processed alike) so the frame's paint is the paint's own colour; then
   isolated paint pixels are dropped (fewer than ``min_paint_neighbors`` of 4 neighbours in
   the range: camera noise lifting single pixels of rust into the range), then small blobs
   (8-connected paint covering less than ``min_paint_area_m2`` of surface: overspray specks,
   which stitch into a halo around the stroke and past its ends); blobs wider than any stroke
   (``max_stroke_width_m``: a crate's face, a cone) join the other paint;
2. depth gate: valid depth within ``[min_depth_m, max_depth_m]`` and no flying pixel (a depth
   that jumps by more than ``flying_pixel_ratio × depth`` to one of its 4-neighbours: the
   smeared pixels a stereo camera produces across depth edges);
3. back-projection of only those pixels through the camera's cached, distortion-aware ray grid,
   into the base frame with ``T_base_cam`` (the full cloud is never built);
4. voxel downsampling (``voxel_size_m``) and then statistical outlier removal (open3d's, to
   the bit; computed on a grid in C, :mod:`scrapcut_cli._kernels`). The paper removes
   outliers first; downsampling first makes the outlier test see neighbours on the scale of
   the stroke instead of sensor noise, and costs 1 ms instead of 30 ms per frame;
5. the surface band: non-paint pixels within ``surface_band_m`` (in 3-D) of the paint, sampled
   on a pixel grid about half a ``surface_voxel_m`` apart, downsampled at ``surface_voxel_m``.
   The tool path takes its normals and collision checks from it, on both sides of the stroke;
6. the stroke's edges (:func:`stroke_edge_points`): where the paint stops and metal goes on.
   A paint pixel next to a non-paint one is an edge of the stroke only if the depth beyond it
   shows a surface that could carry paint: a short run of valid depth continuing the paint's
   surface. Where it shows a hole (no depth, or the background far behind, with the flying
   pixels at the rim between), the paint's boundary is not the stroke's edge and is left out.
   The image is where this is decided: a frame's depth says directly which neighbour of a
   paint pixel is metal, before stitching blurs views together (``fitting.stroke`` explains
   the choice).

:class:`PerceptionTally` counts frames, pixels, points and skip reasons over a recording and
raises the "no paint found" error with the dominant hues the images showed instead.
"""

from __future__ import annotations

import functools
import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import label, maximum_filter

from scrapcut_cli import _kernels
from scrapcut_cli._open3d import o3d
from scrapcut_cli.config import PerceptionConfig
from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.perception.paint import (
    HsvRange,
    HueHistogram,
    paint_pixels_with_saturation,
    saturation_splits,
)
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
#: The paint's colour only in blobs wider than PerceptionConfig.max_stroke_width_m (a crate, a
#: cone, a painted wall): kept apart as other paint, no stroke.
SKIP_PAINT_TOO_WIDE = "paint_too_wide"


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
        ``no_paint``, ``scattered_paint``, ``no_valid_depth``, ``too_little_paint``,
        ``paint_too_wide`` or ``paint_fills_image`` when ``paint_base`` is empty.
    paint_rgb : (N, 3) float32
        Mean sRGB (0-1) of the pixels behind each paint point (empty: colour unknown).
    other_base : (P, 3) float64
        Metres, base frame: the filter's pixels of a duller saturation cluster than the paint
        (rust, an old mark) in this frame, processed as the paint; ``other_rgb`` (P, 3) their
        colours. Empty when the frame's filtered pixels form one cluster.
    view_centre : (3,) float64 or None
        Where the optical axis meets the observed surface (metres, base frame): what the view
        looks at. None when the image centre has no depth.
    edge_base : (E, 3) float64
        Metres, base frame: the stroke's edges seen in this frame (paint next to metal, not
        next to a hole), downsampled (:func:`stroke_edge_points`).
    """

    frame_index: int
    stamp_ns: int
    paint_base: FloatArray
    surface_base: FloatArray
    paint_pixels: int
    valid_paint_pixels: int
    T_base_cam: FloatArray
    skip_reason: str | None = None
    paint_rgb: NDArray[np.float32] = field(
        default_factory=lambda: np.zeros((0, 3), dtype=np.float32)
    )
    view_centre: FloatArray | None = None
    other_base: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    other_rgb: NDArray[np.float32] = field(
        default_factory=lambda: np.zeros((0, 3), dtype=np.float32)
    )
    edge_base: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))

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
    if not config.max_stroke_width_m >= 0:  # NaN fails too
        raise PerceptionError(
            f"perception.max_stroke_width_m must be >= 0, got {config.max_stroke_width_m}"
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
    blobs = _Blobs.of(pixels, depth_m.shape[1])
    if blobs.n <= 1:
        return pixels
    return pixels[~blobs.small(pixels, depth_m, camera, min_area_m2, nearest_m)[blobs.blob]]


def split_wide_blobs(
    pixels: NDArray[np.intp],
    depth_m: NDArray[np.float32],
    camera: CameraModel,
    *,
    max_width_m: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(pixels of blobs that may be a stroke, pixels of blobs wider than any stroke) of
    ``pixels`` (ascending flat indices into the (H, W) ``depth_m`` image).

    A marking stroke is a few centimetres wide; paint a hand's width across or more is
    something else of the paint's colour: a crate's face, a traffic cone. A blob's width is
    its pixel count over the diagonal of its bounding box (a band's width, whatever its
    direction; a square's 0.7 side), in metres at its median depth. Blobs without depth are
    kept. ``max_width_m = 0`` keeps all.
    """
    if max_width_m <= 0 or pixels.size == 0:
        return pixels, pixels[:0]
    blobs = _Blobs.of(pixels, depth_m.shape[1])
    wide = blobs.wide(pixels, depth_m, camera, max_width_m)[blobs.blob]
    return pixels[~wide], pixels[wide]


@dataclass(frozen=True, eq=False)
class _Blobs:
    """The 8-connected blobs of a set of pixels: ``blob`` (K,) the label of each (1..n),
    ``count`` (n + 1,) pixels per label.

    scipy's labelling is the costly step (0.65 ms for a whole 640x480 frame), so it runs on
    the box the pixels span only (they are sorted by row), once for both blob tests."""

    blob: NDArray[np.intp]
    n: int
    count: NDArray[np.intp]

    @classmethod
    def of(cls, pixels: NDArray[np.intp], width: int) -> _Blobs:
        row = pixels // width
        col = pixels - row * width
        r0, c0 = int(row[0]), int(col.min())
        box_w = int(col.max()) - c0 + 1
        local = (row - r0) * box_w + (col - c0)
        mask = np.zeros((int(row[-1]) - r0 + 1) * box_w, dtype=bool)
        mask[local] = True
        labels, n = label(mask.reshape(-1, box_w), structure=_EIGHT)
        blob = labels.reshape(-1)[local]
        return cls(blob, int(n), np.bincount(blob, minlength=n + 1))

    def small(
        self,
        pixels: NDArray[np.intp],
        depth_m: NDArray[np.float32],
        camera: CameraModel,
        min_area_m2: float,
        nearest_m: float,
    ) -> NDArray[np.bool_]:
        """(n + 1,) the blobs covering less than ``min_area_m2`` (see reject_small_blobs)."""
        footprint = 1.0 / (camera.fx * camera.fy)  # pixel area per metre^2 of depth^2
        small = self.count * (max(nearest_m, 1e-3) ** 2 * footprint) < min_area_m2
        small[0] = False
        candidate = small[self.blob]
        if not candidate.any():
            return np.zeros(self.n + 1, dtype=bool)
        z = np.take(depth_m.reshape(-1), pixels[candidate]).astype(np.float64)
        which = self.blob[candidate]
        valid = np.isfinite(z) & (z > 0.0)
        z2 = np.bincount(which[valid], weights=z[valid] ** 2, minlength=self.n + 1)
        seen = np.bincount(which[valid], minlength=self.n + 1)
        area = self.count * z2 / np.maximum(seen, 1) * footprint
        return np.asarray(small & (seen > 0) & (area < min_area_m2))

    def wide(
        self,
        pixels: NDArray[np.intp],
        depth_m: NDArray[np.float32],
        camera: CameraModel,
        max_width_m: float,
    ) -> NDArray[np.bool_]:
        """(n + 1,) the blobs wider than ``max_width_m`` (see split_wide_blobs)."""
        focal = np.sqrt(camera.fx * camera.fy)
        width = depth_m.shape[1]
        wide = np.zeros(self.n + 1, dtype=bool)
        # A blob's box holds its pixels, so its diagonal is at least sqrt(2 * count) and its
        # width in pixels (count / diagonal) at most sqrt(count / 2): a blob narrower than
        # the limit even so, 3 m away, needs no box (most are specks; the margin covers
        # rounding). The others' boxes come from their own pixels (rows ascending).
        bound = np.sqrt(self.count / 2.0) * 3.0 / focal
        for k in np.flatnonzero(bound >= max_width_m * (1.0 - 1e-9)):
            if k == 0:
                continue
            own = pixels[self.blob == k]
            cols = own % width
            rows = int(own[-1] // width) - int(own[0] // width) + 1
            diagonal = float(np.hypot(rows, int(cols.max()) - int(cols.min()) + 1))
            blob_px = self.count[k] / max(diagonal, 1.0)
            if blob_px * 3.0 / focal < max_width_m:  # narrower than that even 3 m away
                continue
            z = np.take(depth_m.reshape(-1), own[::7]).astype(np.float64)
            z = z[np.isfinite(z) & (z > 0)]
            if z.size and blob_px * float(np.median(z)) / focal > max_width_m:
                wide[k] = True
        return wide


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
        Metres, base frame, one point per usable paint pixel (of a grid, see sampling_stride).
    pixels : (K,) intp
        Their flat pixel indices.
    paint_pixels : int
        Pixels in the colour range before the depth gate.
    """
    paint, saturation = paint_pixels_with_saturation(frame.color, hsv)
    own, _ = _split_by_saturation(paint, saturation)
    strokes, _ = _solid_paint(frame, own, config, max_width_m=config.max_stroke_width_m)
    points, usable = _backproject(frame, strokes, config)
    return points, usable, int(paint.size)


def split_by_saturation(
    rgb: NDArray[np.uint8], pixels: NDArray[np.intp]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(the paint's own pixels, duller ones) of the filter's ``pixels`` (flat indices into
    the (H, W, 3) ``rgb``): those below the top split of their saturations' histogram
    (:func:`~scrapcut_cli.perception.paint.saturation_splits`) are another colour cluster;
    without a split, all are the paint's."""
    if pixels.size == 0:
        return pixels, pixels[:0]
    c = np.take(np.asarray(rgb).reshape(-1, 3), pixels, axis=0)
    cmax = c.max(axis=1).astype(np.float64)
    return _split_by_saturation(pixels, (cmax - c.min(axis=1)) / np.maximum(cmax, 1.0))


def _split_by_saturation(
    pixels: NDArray[np.intp], saturation: NDArray[Any]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    if pixels.size == 0:
        return pixels, pixels[:0]
    # The histogram needs a sample, not every pixel of a 1280x720 frame.
    splits = saturation_splits(saturation[:: max(1, pixels.size // 20_000)])
    if not splits:
        return pixels, pixels[:0]
    own = saturation >= splits[-1]
    return pixels[own], pixels[~own]


def _backproject_solid(
    frame: Frame, pixels: NDArray[np.intp], config: PerceptionConfig
) -> tuple[FloatArray, NDArray[np.intp]]:
    """Solid-paint filters, depth gate and back-projection of a set of filter pixels."""
    solid, _ = _solid_paint(frame, pixels, config, max_width_m=0.0)
    return _backproject(frame, solid, config)


def _backproject(
    frame: Frame, solid: NDArray[np.intp], config: PerceptionConfig
) -> tuple[FloatArray, NDArray[np.intp]]:
    """Depth gate and back-projection of solid paint pixels, on a pixel grid fine enough
    for the voxel (:func:`sampling_stride`)."""
    stride = sampling_stride(frame, solid, config.voxel_size_m)
    if stride > 1:
        height, width = frame.depth.shape
        solid = solid[_grid_mask(int(height), int(width), stride).take(solid)]
    usable = _usable(frame, solid, config)
    return backproject_pixels(frame.camera, frame.depth, usable, frame.T_base_cam), usable


@functools.lru_cache(maxsize=8)
def _grid_mask(height: int, width: int, stride: int) -> NDArray[np.bool_]:
    """(H * W,) True at the pixels whose row and column are multiples of ``stride``: one
    gather tells a pixel set's grid pixels, where a divmod and two remainders took three times
    as long."""
    mask = np.zeros((height, width), dtype=bool)
    mask[::stride, ::stride] = True
    mask.setflags(write=False)
    return mask.reshape(-1)


def _usable(frame: Frame, pixels: NDArray[np.intp], config: PerceptionConfig) -> NDArray[np.intp]:
    """:func:`usable_depth_pixels` with the configuration's depth gate.

    In a decimated frame (:meth:`Frame.decimated`) each pixel is tested against its
    neighbours in the full-resolution depth: the flying pixels at a depth edge stay a band
    one camera pixel wide, where the decimated image's neighbours (``step`` pixels away) would
    widen it ``step`` times, enough to strip a thin wire seen from close up of its paint."""
    gate = {
        "min_depth_m": config.min_depth_m,
        "max_depth_m": config.max_depth_m,
        "flying_pixel_ratio": config.flying_pixel_ratio,
    }
    full, step = frame.extras.get("full_depth"), frame.extras.get("decimation")
    if not isinstance(full, np.ndarray) or not isinstance(step, int) or step < 2:
        return usable_depth_pixels(frame.depth, pixels, **gate)
    width, full_width = frame.depth.shape[1], full.shape[1]
    v, u = np.divmod(pixels, width)
    kept = usable_depth_pixels(full, v * (step * full_width) + u * step, **gate)
    kv, ku = np.divmod(kept, full_width)
    return np.asarray((kv // step) * width + ku // step, dtype=np.intp)


def boundary_pixels(pixels: NDArray[np.intp], shape: tuple[int, ...]) -> NDArray[np.intp]:
    """The pixels of a set (ascending flat indices into an image of ``shape``) with a
    4-neighbour outside the set or outside the image."""
    height, width = int(shape[0]), int(shape[1])
    if pixels.size == 0:
        return pixels
    # A mask padded by one pixel all round, flat: np.take on it is several times faster than
    # 2-D fancy indexing.
    stride = width + 2
    mask = np.zeros((height + 2) * stride, dtype=bool)
    padded = pixels + 2 * (pixels // width) + stride + 1
    mask[padded] = True
    inside = np.take(mask, padded - 1)
    inside &= np.take(mask, padded + 1)
    inside &= np.take(mask, padded - stride)
    inside &= np.take(mask, padded + stride)
    return pixels[~inside]


def sorted_union(a: NDArray[np.intp], b: NDArray[np.intp]) -> NDArray[np.intp]:
    """The sorted union of two ascending arrays of pixel indices (np.union1d's result):
    a stable sort of the two runs merges them in linear time, where np.union1d hashes."""
    merged = np.concatenate([a, b])
    merged.sort(kind="stable")
    if merged.size < 2:
        return merged
    return merged[np.concatenate([[True], merged[1:] != merged[:-1]])]


#: Samples kept along a voxel's side (each way): pixels at most a third of a voxel apart leave
#: nine or more to average in each voxel.
SAMPLES_PER_VOXEL_SIDE = 3.0


def _pixels_per_sample(camera: CameraModel, depth: NDArray[Any], voxel_m: float) -> float:
    """How many pixels apart samples may be, at the near depth (10 % quantile) of the valid
    ``depth`` values, for :data:`SAMPLES_PER_VOXEL_SIDE` samples a voxel side; 1 when none is
    valid."""
    z = depth[np.isfinite(depth) & (depth > 0)]
    if z.size == 0:
        return 1.0
    focal = min(camera.fx, camera.fy)
    return voxel_m * focal / (SAMPLES_PER_VOXEL_SIDE * float(np.quantile(z, 0.1)))


def sampling_stride(frame: Frame, pixels: NDArray[np.intp], voxel_m: float) -> int:
    """Every how many pixels (each way) the paint is back-projected: as many as keep samples
    at most a third of a voxel apart at the paint's near depth (its 10 % quantile), so each
    voxel still averages nine or more. At 640x480 and 0.3 m every pixel (0.5 mm), at 1280x720
    every other one (0.3 mm): the work after the mask no longer grows with the resolution
    (after :func:`decimation`, the work before it neither)."""
    if pixels.size == 0:
        return 1
    z = np.take(frame.depth.reshape(-1), pixels[:: max(1, pixels.size // 256)])
    return max(1, int(_pixels_per_sample(frame.camera, z, voxel_m)))


def decimation(
    depth: NDArray[np.float32], camera: CameraModel, voxel_m: float, max_step: int
) -> int:
    """Every how many pixels (each way: 1, 2, 4 or 8, at most ``max_step``) a frame with this
    ``depth`` image (H, W) is read (:meth:`Frame.decimated`): the most that keep its pixels a
    third of a voxel apart or closer at the scene's near depth, the 10 % quantile of the valid
    depth (on a sample); the paint lies on the scanned piece, the near part of the scene.

    Every per-pixel step (the colour filter, the pixel tests, the blobs, the edges) then costs
    what it does at the resolution the voxels need, not the camera's: 1280x720 at the wrist's
    0.3 m reads like 640x360 (0.65 mm pixels against 2 mm voxels), and 640x480 like itself
    until nearer than 0.2 m. The depth gate still compares a sample with its neighbours one
    camera pixel away (``_usable``): its flying-pixel band at a depth edge would otherwise be
    ``step`` times as wide in metres and strip a thin wire seen from close up of its paint.
    ``max_decimation`` is 8 by default (1 reads every pixel): Table I and the yard table
    hold with it (``benchmarks/scenes.md``)."""
    if max_step < 2:
        return 1
    flat = depth.reshape(-1)
    sample = flat[:: max(1, flat.size // 4096)]
    limit = min(_pixels_per_sample(camera, sample, voxel_m), float(max_step))
    step = 1
    while 2 * step <= limit:
        step *= 2
    return step


def _solid_paint(
    frame: Frame, paint: NDArray[np.intp], config: PerceptionConfig, *, max_width_m: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(solid paint pixels, pixels of blobs wider than ``max_width_m``) of the colour
    filter's pixels: isolated pixels and small blobs dropped (step 1), one labelling."""
    solid = reject_isolated_pixels(
        paint, frame.depth.shape, min_neighbors=config.min_paint_neighbors
    )
    empty = solid[:0]
    if solid.size == 0 or (config.min_paint_area_m2 <= 0 and max_width_m <= 0):
        return solid, empty
    blobs = _Blobs.of(solid, frame.depth.shape[1])
    drop = np.zeros(blobs.n + 1, dtype=bool)
    if config.min_paint_area_m2 > 0 and blobs.n > 1:
        drop = blobs.small(
            solid, frame.depth, frame.camera, config.min_paint_area_m2, config.min_depth_m
        )
    wide = blobs.wide(solid, frame.depth, frame.camera, max_width_m) if max_width_m > 0 else drop
    if max_width_m <= 0:
        return solid[~drop[blobs.blob]], empty
    wide &= ~drop
    return solid[~(drop | wide)[blobs.blob]], solid[wide[blobs.blob]]


def voxel_downsample(points: ArrayLike, voxel_size_m: float) -> FloatArray:
    """Centroids (M, 3) of the points in each occupied voxel of ``voxel_size_m`` (open3d)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return pts.copy()
    o3 = o3d()
    cloud = o3.geometry.PointCloud(o3.utility.Vector3dVector(pts))
    return np.asarray(cloud.voxel_down_sample(voxel_size_m).points, dtype=np.float64)


def voxel_downsample_colored(
    points: ArrayLike, rgb: NDArray[np.uint8], voxel_size_m: float
) -> tuple[FloatArray, NDArray[np.float32]]:
    """Centroids (M, 3) and mean sRGB (M, 3) float32 in 0-1 of the points (N, 3) with byte
    colours ``rgb`` (N, 3) in each occupied voxel of ``voxel_size_m`` (open3d)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return pts.copy(), np.zeros((0, 3), dtype=np.float32)
    o3 = o3d()
    cloud = o3.geometry.PointCloud(o3.utility.Vector3dVector(pts))
    cloud.colors = o3.utility.Vector3dVector(np.asarray(rgb, dtype=np.float64) / 255.0)
    down = cloud.voxel_down_sample(voxel_size_m)
    return (
        np.asarray(down.points, dtype=np.float64),
        np.asarray(down.colors, dtype=np.float32),
    )


def remove_statistical_outliers(
    points: ArrayLike, *, neighbors: int, std_ratio: float
) -> FloatArray:
    """Points (M, 3) whose mean distance to their ``neighbors`` nearest is not an outlier.

    open3d's statistical outlier removal: a point goes when its mean neighbour distance exceeds
    the cloud's mean by more than ``std_ratio`` standard deviations. ``neighbors = 0`` keeps all.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return pts[statistical_inliers(pts, neighbors=neighbors, std_ratio=std_ratio)]


def statistical_inliers(points: ArrayLike, *, neighbors: int, std_ratio: float) -> NDArray[np.intp]:
    """Indices (M,) ascending of the points (N, 3) that
    :func:`remove_statistical_outliers` keeps (compiled, :mod:`scrapcut_cli._kernels`)."""
    return _kernels.statistical_inliers(points, neighbors=neighbors, std_ratio=std_ratio)


def view_centre(frame: Frame, *, window: float = 0.05) -> FloatArray | None:
    """Where the optical axis meets the observed surface, metres, base frame (3,): the median
    depth of the valid pixels in a window (``window`` of the image's size each way) around the
    principal point, back-projected along the axis; None when the window has no depth."""
    camera = frame.camera
    h, w = frame.depth.shape
    ru, rv = max(1, int(window * w)), max(1, int(window * h))
    u0 = int(np.clip(round(camera.cx), 0, w - 1))
    v0 = int(np.clip(round(camera.cy), 0, h - 1))
    patch = frame.depth[max(v0 - rv, 0) : v0 + rv + 1, max(u0 - ru, 0) : u0 + ru + 1]
    z = patch[np.isfinite(patch) & (patch > 0)]
    if z.size == 0:
        return None
    T = np.asarray(frame.T_base_cam, dtype=np.float64)
    return np.asarray(T[:3, 3] + float(np.median(z)) * T[:3, 2])


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
    usable = _usable(frame, candidates.astype(np.intp), config)
    points = backproject_pixels(camera, frame.depth, usable, frame.T_base_cam)
    if len(points) == 0:
        return points
    # Distances to the paint's centroids on a band/4 grid: 10x fewer targets than the paint
    # itself, and the band's edge moves by less than that grid's half diagonal.
    coarse = voxel_downsample(paint_base, config.surface_band_m / 4.0)
    near = _kernels.within_distance(points, coarse, config.surface_band_m)
    return voxel_downsample(points[near], config.surface_voxel_m)


#: How far beyond a paint pixel the depth must go on as a surface for its boundary to be the
#: stroke's edge, metres (a few pixels at the wrist's distances: past one flying pixel at a
#: hole's rim, short of the next hole of a mesh).
EDGE_PROBE_M = 0.002
#: At most this many pixels are probed (a far view's probe is still a few pixels).
EDGE_PROBE_MAX_PX = 6


def stroke_edge_points(
    frame: Frame,
    paint_pixels: NDArray[np.intp],
    paint_depth_m: float,
    config: PerceptionConfig,
    *,
    stroke_pixels: NDArray[np.intp] | None = None,
) -> FloatArray:
    """The stroke's edges seen in one frame: (E, 3) float64, metres, base frame.

    ``paint_pixels`` are the usable paint pixels (ascending flat indices; valid, non-flying
    depth); ``stroke_pixels`` all pixels of the stroke's colour (default: the same), with or
    without usable depth: a paint pixel whose depth was dropped (beside a hole's flying
    pixels, say) is still paint, not the metal beyond the stroke. For each usable paint pixel
    and each of its 4-neighbours outside the stroke, the pixels
    beyond it in that direction are probed for ``EDGE_PROBE_M`` at ``paint_depth_m`` (1 to
    ``EDGE_PROBE_MAX_PX`` pixels): every one must be outside the paint, have depth within the
    gate and continue
    the surface (each step, and the whole run, within ``flying_pixel_ratio × depth`` of the
    paint pixel's: the flying-pixel test's tolerance). Then the neighbour is metal that stayed
    unpainted and the boundary is the stroke's edge: the midpoint of the paint pixel's and the
    neighbour's points. A neighbour without depth, far behind (a hole's background), or a
    flying pixel at a rim is no edge: what lies beyond the paint is unknown there. The points
    are averaged on a voxel grid of half ``voxel_size_m``.
    """
    height, width = frame.depth.shape
    if paint_pixels.size == 0:
        return np.zeros((0, 3))
    flat = frame.depth.reshape(-1)
    mask = np.zeros(height * width, dtype=bool)
    mask[paint_pixels if stroke_pixels is None else stroke_pixels] = True
    focal = max(frame.camera.fx, frame.camera.fy)
    probe = int(
        np.clip(np.ceil(EDGE_PROBE_M * focal / max(paint_depth_m, 1e-3)), 1, EDGE_PROBE_MAX_PX)
    )
    v, u = np.divmod(paint_pixels, width)
    z0 = np.take(flat, paint_pixels).astype(np.float64)
    tolerance = config.flying_pixel_ratio * z0
    inner: list[NDArray[np.intp]] = []
    outer: list[NDArray[np.intp]] = []
    for dv, du in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        step = dv * width + du
        # Only the stroke's boundary pixels in this direction are probed (a few per cent of
        # the paint), with room for the whole probe inside the image.
        room = (
            (u + probe * du >= 0)
            & (u + probe * du < width)
            & (v + probe * dv >= 0)
            & (v + probe * dv < height)
        )
        at = np.flatnonzero(room)
        at = at[~np.take(mask, paint_pixels[at] + step)]
        start = paint_pixels[at]
        z_start = z0[at]
        limit = tolerance[at]
        ok = np.ones(len(at), dtype=bool)
        previous = z_start
        for k in range(1, probe + 1):
            if not ok.any():
                break
            pixel = start + k * step
            ok &= ~np.take(mask, pixel)  # a gap of a pixel or two inside the paint is no edge
            z = np.take(flat, pixel).astype(np.float64)
            with np.errstate(invalid="ignore"):
                ok &= (z >= config.min_depth_m) & (z <= config.max_depth_m)  # NaN fails
                ok &= np.abs(z - previous) <= limit
                ok &= np.abs(z - z_start) <= limit
            previous = z
        inner.append(start[ok])
        outer.append(start[ok] + step)
    p = np.concatenate(inner)
    if p.size == 0:
        return np.zeros((0, 3))
    q = np.concatenate(outer)
    a = backproject_pixels(frame.camera, frame.depth, p, frame.T_base_cam)
    b = backproject_pixels(frame.camera, frame.depth, q, frame.T_base_cam)
    return voxel_downsample(0.5 * (a + b), 0.5 * config.voxel_size_m)


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
    step = decimation(frame.depth, frame.camera, config.voxel_size_m, config.max_decimation)
    clouds = _process_frame(frame.decimated(step), hsv, config)
    if step == 1:
        return clouds
    # The filter's count in the image's own pixels, whatever the step it was read at (the
    # back-projected count is of samples: a fine frame's paint was sampled at a stride before).
    return replace(clouds, paint_pixels=clouds.paint_pixels * step * step)


def _process_frame(frame: Frame, hsv: HsvRange, config: PerceptionConfig) -> FrameClouds:
    T = np.asarray(frame.T_base_cam, dtype=np.float64)
    empty = np.zeros((0, 3))
    centre = view_centre(frame)

    def skipped(reason: str, paint_pixels: int, valid: int) -> FrameClouds:
        return FrameClouds(
            frame.index,
            frame.stamp_ns,
            empty,
            empty,
            paint_pixels,
            valid,
            T,
            reason,
            view_centre=centre,
        )

    filtered, saturation = paint_pixels_with_saturation(frame.color, hsv)
    own, duller = _split_by_saturation(filtered, saturation)
    strokes, wide = _solid_paint(frame, own, config, max_width_m=config.max_stroke_width_m)
    points, pixels = _backproject(frame, strokes, config)
    paint_pixels = int(filtered.size)
    if paint_pixels == 0:
        return skipped(SKIP_NO_PAINT, 0, 0)
    if paint_pixels > config.max_paint_share * frame.color.shape[0] * frame.color.shape[1]:
        return skipped(SKIP_PAINT_FILLS_IMAGE, paint_pixels, 0)
    if len(points) == 0:
        # Scattered specks (rust lifted into the range by noise, overspray) and paint without
        # usable depth need different remedies; telling them apart costs a second filter on
        # skipped frames only.
        if strokes.size == 0 and wide.size:
            return skipped(SKIP_PAINT_TOO_WIDE, paint_pixels, 0)
        solid, _ = _solid_paint(frame, filtered, config, max_width_m=0.0)
        return skipped(SKIP_NO_VALID_DEPTH if solid.size else SKIP_SCATTERED_PAINT, paint_pixels, 0)
    paint, paint_rgb = _thin(frame, points, pixels, config)
    # The other paint (duller colour clusters, blobs too wide for a stroke), to be reported:
    # noise dropped, downsampled; no outlier removal.
    solid_other = sorted_union(
        reject_isolated_pixels(duller, frame.depth.shape, min_neighbors=config.min_paint_neighbors),
        wide,
    )
    other, other_rgb = _thin(
        frame, *_backproject(frame, solid_other, config), config, outliers=False
    )
    if len(paint) < max(config.min_paint_points, 1):
        return skipped(SKIP_TOO_LITTLE_PAINT, paint_pixels, len(pixels))
    # The nearest quartile of the paint sets the pixel scale of the band (nearer = wider).
    depth = frame.depth.reshape(-1)[pixels[:: max(1, len(pixels) // 512)]]
    paint_depth = float(np.percentile(depth, 25))
    surface = surface_band(frame, pixels, paint, paint_depth, config)
    # Edges are probed from every boundary pixel of the stroke, not only from the sampled ones.
    edges = stroke_edge_points(
        frame,
        _usable(frame, boundary_pixels(strokes, frame.depth.shape), config),
        paint_depth,
        config,
        stroke_pixels=strokes,
    )
    return FrameClouds(
        frame.index,
        frame.stamp_ns,
        paint,
        surface,
        paint_pixels,
        len(pixels),
        T,
        paint_rgb=paint_rgb,
        view_centre=centre,
        other_base=other,
        other_rgb=other_rgb,
        edge_base=edges,
    )


def _thin(
    frame: Frame,
    points: FloatArray,
    pixels: NDArray[np.intp],
    config: PerceptionConfig,
    *,
    outliers: bool = True,
) -> tuple[FloatArray, NDArray[np.float32]]:
    """Voxel downsampling (with the pixels' mean colour) and statistical outlier removal."""
    colours = np.take(np.asarray(frame.color).reshape(-1, 3), pixels, axis=0)
    down, down_rgb = voxel_downsample_colored(points, colours, config.voxel_size_m)
    if not outliers:
        return down, down_rgb
    kept = statistical_inliers(down, neighbors=config.sor_neighbors, std_ratio=config.sor_std_ratio)
    return down[kept], down_rgb[kept]


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
        if self.skip_reasons[SKIP_PAINT_TOO_WIDE]:
            hints.append(
                "the paint's colour lies only in blobs wider than a stroke (a crate, a cone, a "
                "wall): raise perception.max_stroke_width_m (--config) if the line is that wide"
            )
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
