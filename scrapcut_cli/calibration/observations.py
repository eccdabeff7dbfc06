"""What one frame tells the calibration: surface samples and paint edges, in the camera frame.

The calibration compares frames with each other after posing them with a candidate mount and
clock offset, so it keeps each frame's measurements in the camera's own optical frame:

- surface samples: the depth image on a pixel grid (about ``surface_samples`` points, every
  pixel kind: paint, bare metal, floor), each with a normal from its neighbours ``stride / 2``
  pixels away (a central difference: ~4 degrees of noise at 0.3 m with the D435i, enough for a
  point-to-plane residual). Pixels across a depth jump (flying pixels, silhouettes) are dropped;
- paint edges: where a paint pixel (the perception filter's solid paint: isolated pixels and
  overspray specks removed) meets a bare pixel of the same surface, a point half-way between
  the two pixels at the depth half-way between them, with the edge's direction (from its
  neighbours along the edge) and the in-surface direction across it, pointing out of the
  paint. Boundaries at the
  image border or across a depth jump are not paint edges (the paint goes on out of sight).
  Points are thinned to one per ``edge_spacing_m`` cell.

A flat surface constrains only three of the six mount directions (distance along its normal and
the two tilts); the paint's edges constrain the directions in the surface, which is why both are
kept. All vectorised over pixels; nothing here prints or reads files.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.config import CalibrationConfig, PerceptionConfig
from scrapcut_cli.perception.cloud import reject_isolated_pixels, reject_small_blobs
from scrapcut_cli.perception.paint import HsvRange, paint_pixel_indices
from scrapcut_cli.recording.frame import CameraModel, Frame

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class FrameObservation:
    """One frame's measurements, camera optical frame, metres.

    Attributes
    ----------
    index, stamp_ns : int
        The frame's position in the recording and its image header stamp.
    surface : (N, 3) float64
        Depth samples, camera frame.
    normals : (N, 3) float64
        Unit surface normals at ``surface``, facing the camera.
    edges : (M, 3) float64
        Paint-edge points, camera frame.
    edge_across : (M, 3) float64
        Unit vectors in the surface, across the edge, pointing out of the paint.
    T_base_cam : (4, 4) float64
        The pose the recording gives the frame (published mount), for pairing frames only.
    """

    index: int
    stamp_ns: int
    surface: FloatArray
    normals: FloatArray
    edges: FloatArray
    edge_across: FloatArray
    T_base_cam: FloatArray

    @property
    def median_depth_m(self) -> float:
        """Median z of the surface samples (0 when there are none)."""
        return float(np.median(self.surface[:, 2])) if len(self.surface) else 0.0


def observe_frame(
    frame: Frame,
    hsv: HsvRange | None,
    *,
    config: CalibrationConfig,
    perception: PerceptionConfig,
) -> FrameObservation:
    """Surface samples and paint edges of ``frame`` (see the module docstring).

    Parameters
    ----------
    frame : Frame
        Colour (H, W, 3) uint8, depth (H, W) float32 metres (NaN = invalid), camera, pose.
    hsv : HsvRange or None
        The paint's colour range; None: surface samples only.
    config : CalibrationConfig
        ``surface_samples`` and ``edge_spacing_m``.
    perception : PerceptionConfig
        The depth gate, flying-pixel ratio and paint clean-up the pipeline uses.
    """
    depth = np.where(
        (frame.depth >= perception.min_depth_m) & (frame.depth <= perception.max_depth_m),
        frame.depth,
        np.nan,
    ).astype(np.float32)
    points = _points_image(frame.camera, depth)
    h, w = depth.shape
    stride = max(2, round(np.sqrt(h * w / max(config.surface_samples, 1))))
    surface, normals = _surface_samples(points, stride, perception.flying_pixel_ratio)
    edges = np.zeros((0, 3))
    across = np.zeros((0, 3))
    if hsv is not None:
        edges, across = _paint_edges(frame, depth, points, hsv, config, perception)
    return FrameObservation(
        index=frame.index,
        stamp_ns=frame.stamp_ns,
        surface=surface,
        normals=normals,
        edges=edges,
        edge_across=across,
        T_base_cam=np.asarray(frame.T_base_cam, dtype=np.float64).copy(),
    )


def _points_image(camera: CameraModel, depth: NDArray[np.float32]) -> NDArray[np.float32]:
    """(H, W, 3) float32 camera-frame points of every pixel (NaN where depth is invalid)."""
    rays = camera.ray_grid()
    out = np.empty((*depth.shape, 3), dtype=np.float32)
    out[..., 0] = rays[..., 0] * depth
    out[..., 1] = rays[..., 1] * depth
    out[..., 2] = depth
    return out


def _continuous(
    z0: NDArray[np.float32], z1: NDArray[np.float32], ratio: float
) -> NDArray[np.bool_]:
    """Both depths valid and within ``ratio`` × depth of each other (no jump between them)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(z0) & np.isfinite(z1) & (np.abs(z1 - z0) <= ratio * z0)


def _surface_samples(
    points: NDArray[np.float32], stride: int, ratio: float
) -> tuple[FloatArray, FloatArray]:
    """Grid samples (N, 3) and normals (N, 3) from an (H, W, 3) point image."""
    h, w, _ = points.shape
    k = max(1, stride // 2)
    v, u = np.mgrid[k : h - k : stride, k : w - k : stride]
    v, u = v.ravel(), u.ravel()
    p = points[v, u]
    left, right = points[v, u - k], points[v, u + k]
    up, down = points[v - k, u], points[v + k, u]
    z = p[:, 2]
    ok = (
        _continuous(z, left[:, 2], ratio * k)
        & _continuous(z, right[:, 2], ratio * k)
        & _continuous(z, up[:, 2], ratio * k)
        & _continuous(z, down[:, 2], ratio * k)
    )
    p, left, right, up, down = p[ok], left[ok], right[ok], up[ok], down[ok]
    n = np.cross((right - left).astype(np.float64), (down - up).astype(np.float64))
    norm = np.linalg.norm(n, axis=1)
    good = norm > 0
    n = n[good] / norm[good, None]
    p64 = p[good].astype(np.float64)
    # Face the camera (at the origin): the normal points against the viewing ray.
    flip = np.einsum("ij,ij->i", n, p64) > 0
    n[flip] *= -1.0
    return p64, n


def _paint_edges(
    frame: Frame,
    depth: NDArray[np.float32],
    points: NDArray[np.float32],
    hsv: HsvRange,
    config: CalibrationConfig,
    perception: PerceptionConfig,
) -> tuple[FloatArray, FloatArray]:
    """Paint-edge points (M, 3) and across-edge directions (M, 3), camera frame."""
    h, w = depth.shape
    paint = paint_pixel_indices(frame.color, hsv)
    paint = reject_isolated_pixels(paint, (h, w), min_neighbors=perception.min_paint_neighbors)
    paint = reject_small_blobs(
        paint,
        frame.depth,
        frame.camera,
        min_area_m2=perception.min_paint_area_m2,
        nearest_m=perception.min_depth_m,
    )
    if paint.size == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    mask = np.zeros(h * w, dtype=bool)
    mask[paint] = True
    mask = mask.reshape(h, w)
    ratio = perception.flying_pixel_ratio
    centres: list[FloatArray] = []
    steps: list[FloatArray] = []
    # Each paint pixel with a bare 4-neighbour on the same surface: an edge crossing between them.
    for dv, du in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        v0, v1 = max(0, -dv), h - max(0, dv)
        u0, u1 = max(0, -du), w - max(0, du)
        here = mask[v0:v1, u0:u1]
        there = mask[v0 + dv : v1 + dv, u0 + du : u1 + du]
        z_here = depth[v0:v1, u0:u1]
        z_there = depth[v0 + dv : v1 + dv, u0 + du : u1 + du]
        vv, uu = np.nonzero(here & ~there & _continuous(z_here, z_there, ratio))
        if vv.size == 0:
            continue
        vv, uu = vv + v0, uu + u0
        # The depth half-way between the two pixels: on a surface seen at an angle the paint
        # pixel's own depth would put the point off the surface, on one side per edge.
        z = 0.5 * (depth[vv, uu].astype(np.float64) + depth[vv + dv, uu + du])
        rays = frame.camera.normalized_rays(uu + 0.5 * du, vv + 0.5 * dv)
        centres.append(np.column_stack([rays[:, 0] * z, rays[:, 1] * z, z]))
        outward = points[vv + dv, uu + du].astype(np.float64) - points[vv, uu].astype(np.float64)
        steps.append(outward)
    if not centres:
        return np.zeros((0, 3)), np.zeros((0, 3))
    edge = np.vstack(centres)
    outward = np.vstack(steps)
    edge, outward = _thin(edge, outward, config.edge_spacing_m)
    return _across_directions(edge, outward, points, frame.camera, config.edge_spacing_m)


def _thin(points: FloatArray, vectors: FloatArray, cell_m: float) -> tuple[FloatArray, FloatArray]:
    """Mean point and summed vector per occupied ``cell_m`` voxel (deterministic order)."""
    keys = np.floor(points / cell_m).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    n = len(counts)
    mean = np.zeros((n, 3))
    total = np.zeros((n, 3))
    for i in range(3):
        mean[:, i] = np.bincount(inverse, weights=points[:, i], minlength=n) / counts
        total[:, i] = np.bincount(inverse, weights=vectors[:, i], minlength=n)
    return mean, total


def _across_directions(
    edge: FloatArray,
    outward: FloatArray,
    points: NDArray[np.float32],
    camera: CameraModel,
    spacing_m: float,
) -> tuple[FloatArray, FloatArray]:
    """Edge points on a line-like stretch of edge, and the unit in-surface direction across it.

    The edge's direction is the principal axis of its neighbours within 3 spacings; the surface
    normal comes from the point image around the edge point's pixel. Points whose neighbourhood
    is not line-like (a speck, a corner) are dropped.
    """
    if len(edge) < 3:
        return np.zeros((0, 3)), np.zeros((0, 3))
    tree = cKDTree(edge)
    neighbours = tree.query_ball_point(edge, r=3.0 * spacing_m)
    counts = np.array([len(nb) for nb in neighbours])
    keep = np.flatnonzero(counts >= 3)
    if keep.size == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    # Principal direction of each neighbourhood from its covariance (vectorised over points).
    flat = np.concatenate([neighbours[i] for i in keep])
    owner = np.repeat(np.arange(keep.size), counts[keep])
    centred = edge[flat] - np.repeat(
        np.column_stack(
            [np.bincount(owner, weights=edge[flat, i]) / counts[keep] for i in range(3)]
        ),
        counts[keep],
        axis=0,
    )
    cov = np.zeros((keep.size, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = np.bincount(owner, weights=centred[:, a] * centred[:, b])
            cov[:, b, a] = cov[:, a, b]
    values, vectors = np.linalg.eigh(cov)
    line_like = values[:, 2] > 4.0 * (values[:, 1] + 1e-18)
    tangent = vectors[:, :, 2]
    normal = _normals_at(edge[keep], points, camera)
    across = np.cross(normal, tangent)
    norm = np.linalg.norm(across, axis=1)
    ok = line_like & (norm > 0.5) & np.all(np.isfinite(normal), axis=1)
    across = across[ok] / norm[ok, None]
    sign = np.sign(np.einsum("ij,ij->i", across, outward[keep][ok]))
    sign[sign == 0] = 1.0
    return edge[keep][ok], across * sign[:, None]


def _normals_at(
    points_cam: FloatArray, image: NDArray[np.float32], camera: CameraModel
) -> FloatArray:
    """Surface normals (N, 3) at camera-frame points from the point image (NaN if unknown).

    Central differences 3 pixels either side of the point's pixel.
    """
    h, w, _ = image.shape
    uv = camera.project(points_cam)
    u = np.clip(np.rint(uv[:, 0]).astype(np.intp), 3, w - 4)
    v = np.clip(np.rint(uv[:, 1]).astype(np.intp), 3, h - 4)
    dx = image[v, u + 3].astype(np.float64) - image[v, u - 3]
    dy = image[v + 3, u].astype(np.float64) - image[v - 3, u]
    n = np.cross(dx, dy)
    norm = np.linalg.norm(n, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / norm[:, None]
    return np.asarray(n)
