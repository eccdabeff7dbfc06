"""Stitching per-frame clouds into one paint cloud: voxel deduplication, optional ICP, growth.

:class:`Stitcher` is the first half of Algorithm 1's loop: it takes frames one at a time and
reports the stitched cloud's size — the number of occupied paint voxels, ``size(k)`` — and its
growth ``size(k) − size(k−1)``, which the stopping criterion compares with δ_size. A voxel
holds the running mean of the points that fell into it, so re-observing the same paint averages
noise down and grows nothing.

:func:`stitch_recording` is the recipe that ``scrapcut stitch``, ``scrapcut fit`` and the
exploration replay share: perception of each frame, then the stitcher.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli._open3d import o3d
from scrapcut_cli.config import PerceptionConfig, ScrapcutConfig, StitchConfig
from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.geometry import pack_voxel_keys, rotation_angle, transform_points, voxel_keys
from scrapcut_cli.perception.cloud import FrameClouds, PerceptionTally, process_frame
from scrapcut_cli.perception.paint import HsvRange
from scrapcut_cli.recording.frame import Frame

FloatArray = NDArray[np.float64]

ICP_METHODS = ("point_to_point", "point_to_plane")


@dataclass(frozen=True, eq=False)
class IcpOutcome:
    """What ICP refinement of one frame against the stitched cloud did.

    ``T_correction`` (4, 4) maps the frame's base-frame points onto the stitched cloud; it is
    the identity unless ``accepted``. ``reason``: ``accepted``, ``first_frame``,
    ``low_overlap``, ``no_improvement``, ``translation_too_large``, ``rotation_too_large``.
    Fitness is the share of the frame's overlapping points (those with a stitched point within
    ``icp_max_distance_m``) that lie within one paint voxel of the stitched cloud; RMSE is
    over those inliers. With ``low_overlap``, ``fitness_before`` is the overlapping share.
    """

    accepted: bool
    reason: str
    fitness_before: float = 0.0
    fitness_after: float = 0.0
    rmse_before_m: float = 0.0
    rmse_after_m: float = 0.0
    translation_m: float = 0.0
    rotation_deg: float = 0.0
    T_correction: FloatArray = field(default_factory=lambda: np.eye(4))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (millimetres for readability, as in reports)."""
        return {
            "accepted": self.accepted,
            "reason": self.reason,
            "fitness_before": round(self.fitness_before, 6),
            "fitness_after": round(self.fitness_after, 6),
            "rmse_before_mm": round(1000.0 * self.rmse_before_m, 4),
            "rmse_after_mm": round(1000.0 * self.rmse_after_m, 4),
            "translation_mm": round(1000.0 * self.translation_m, 4),
            "rotation_deg": round(self.rotation_deg, 5),
        }


@dataclass(frozen=True, eq=False)
class StitchStep:
    """One frame's effect on the stitched cloud.

    ``k`` counts the frames given to the stitcher from 0; ``size`` is the number of occupied
    paint voxels after the frame (Algorithm 1's size(k)); ``growth`` = size(k) − size(k−1).
    """

    k: int
    frame_index: int
    stamp_ns: int
    size: int
    growth: int
    surface_size: int
    paint_pixels: int
    valid_paint_pixels: int
    frame_points: int
    skip_reason: str | None = None
    icp: IcpOutcome | None = None

    @property
    def icp_accepted(self) -> bool:
        """True when an ICP correction was applied to this frame."""
        return self.icp is not None and self.icp.accepted

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record (fixed keys: k, frame, size, growth)."""
        out: dict[str, Any] = {
            "k": self.k,
            "frame": self.frame_index,
            "stamp_ns": self.stamp_ns,
            "size": self.size,
            "growth": self.growth,
            "surface_size": self.surface_size,
            "paint_pixels": self.paint_pixels,
            "valid_paint_pixels": self.valid_paint_pixels,
            "frame_points": self.frame_points,
            "skip_reason": self.skip_reason,
        }
        if self.icp is not None:
            out["icp"] = self.icp.to_dict()
        return out


class _VoxelMap:
    """Running-mean points on a world-aligned voxel grid, keyed by packed voxel index.

    Keys are kept sorted, so a frame is merged with one ``searchsorted`` (vectorised, no
    Python loop over points) and the output order is deterministic. Each voxel also counts
    the frames that put a point in it (``frames``): a voxel's points are averaged, its frames
    say how often it was seen. The per-voxel values are stored in the order the voxels were
    first seen (appended, with room to grow), the sorted keys carrying each one's slot: a new
    frame's voxels shift two integer arrays, not all six; the properties read them in key
    order.
    """

    def __init__(self, voxel_size_m: float, *, option: str) -> None:
        self.voxel_size_m = voxel_size_m
        self.option = option  # the command-line option that sets the voxel, for messages
        self.keys = np.zeros(0, dtype=np.int64)  # sorted
        self._slot = np.zeros(0, dtype=np.intp)  # each sorted key's slot in the arrays below
        self._sums = np.zeros((0, 3))
        self._counts = np.zeros(0, dtype=np.int64)
        self._frames = np.zeros(0, dtype=np.int64)
        self._viewpoints = np.zeros((0, 3))
        self._rgb_sums = np.zeros((0, 3))  # NaN once a point of unknown colour fell in

    def __len__(self) -> int:
        return int(self.keys.size)

    def _sorted(self, values: NDArray[Any]) -> NDArray[Any]:
        return np.asarray(values[self._slot])

    @property
    def sums(self) -> FloatArray:
        return self._sorted(self._sums)

    @property
    def counts(self) -> NDArray[np.int64]:
        return self._sorted(self._counts)

    @property
    def frames(self) -> NDArray[np.int64]:
        return self._sorted(self._frames)

    @property
    def viewpoints(self) -> FloatArray:
        return self._sorted(self._viewpoints)

    @property
    def points(self) -> FloatArray:
        return np.asarray(self.sums / self.counts[:, None])

    @property
    def rgb(self) -> FloatArray:
        """Mean sRGB (N, 3) in 0-1 of what fell in each voxel (NaN: unknown)."""
        return np.asarray(self._sorted(self._rgb_sums) / self.counts[:, None])

    def add(self, points: FloatArray, viewpoint: FloatArray, rgb: ArrayLike | None = None) -> int:
        """Merge points (N, 3) with sRGB colours ``rgb`` (N, 3) in 0-1 (None: unknown); new
        voxels remember ``viewpoint`` (3,). Returns voxels added."""
        if len(points) == 0:
            return 0
        try:
            packed = pack_voxel_keys(voxel_keys(points, self.voxel_size_m))
        except ValueError:
            far = float(np.abs(points).max())
            raise PerceptionError(
                f"{self.option} {1000 * self.voxel_size_m:g} is too fine for points {far:.3g} m "
                "from the base frame's origin (at most 2^20 voxels each way)"
            ) from None
        keys, inverse = np.unique(packed, return_inverse=True)
        counts = np.bincount(inverse, minlength=keys.size)
        sums = np.column_stack(
            [np.bincount(inverse, weights=points[:, i], minlength=keys.size) for i in range(3)]
        )
        colours = (
            np.full((len(points), 3), np.nan)
            if rgb is None or len(rgb) != len(points)  # type: ignore[arg-type]
            else np.asarray(rgb, dtype=np.float64)
        )
        rgb_sums = np.column_stack(
            [np.bincount(inverse, weights=colours[:, i], minlength=keys.size) for i in range(3)]
        )
        n = self.keys.size
        pos = np.searchsorted(self.keys, keys)
        found = pos < n
        found[found] = self.keys[pos[found]] == keys[found]
        slots = self._slot[pos[found]]
        self._sums[slots] += sums[found]
        self._rgb_sums[slots] += rgb_sums[found]
        self._counts[slots] += counts[found]
        self._frames[slots] += 1
        new = ~found
        n_new = int(new.sum())
        if n_new == 0:
            return 0
        self._append(n, sums[new], rgb_sums[new], counts[new], viewpoint)
        # np.insert's result for the two index arrays: the new keys go to their insertion
        # points shifted by the new keys before them, the old ones fill the rest.
        at = pos[new] + np.arange(n_new)
        old = np.ones(n + n_new, dtype=bool)
        old[at] = False
        keys_out = np.empty(n + n_new, dtype=np.int64)
        keys_out[old] = self.keys
        keys_out[at] = keys[new]
        slot_out = np.empty(n + n_new, dtype=np.intp)
        slot_out[old] = self._slot
        slot_out[at] = np.arange(n, n + n_new)
        self.keys, self._slot = keys_out, slot_out
        return n_new

    def _append(
        self,
        n: int,
        sums: NDArray[Any],
        rgb_sums: NDArray[Any],
        counts: NDArray[Any],
        viewpoint: FloatArray,
    ) -> None:
        """Store new voxels' values in slots n, n + 1, ... (growing the arrays by half)."""
        end = n + len(counts)
        if end > len(self._counts):
            room = max(end, len(self._counts) * 3 // 2, 1024)

            def grown(values: NDArray[Any]) -> NDArray[Any]:
                out = np.zeros((room, *values.shape[1:]), dtype=values.dtype)
                out[:n] = values[:n]
                return out

            self._sums, self._rgb_sums = grown(self._sums), grown(self._rgb_sums)
            self._counts, self._frames = grown(self._counts), grown(self._frames)
            self._viewpoints = grown(self._viewpoints)
        self._sums[n:end] = sums
        self._rgb_sums[n:end] = rgb_sums
        self._counts[n:end] = counts
        self._frames[n:end] = 1
        self._viewpoints[n:end] = viewpoint


def check_stitch_config(config: StitchConfig) -> None:
    """Raise :class:`PerceptionError` naming the first stitching parameter out of its range."""
    positive = {
        "voxel_size_m": config.voxel_size_m,
        "icp_max_distance_m": config.icp_max_distance_m,
        "icp_max_iterations": config.icp_max_iterations,
    }
    for name, value in positive.items():
        if not value > 0:
            raise PerceptionError(f"stitch.{name} must be positive, got {value}")
    if config.icp_max_translation_m < 0 or config.icp_max_rotation_deg < 0:
        raise PerceptionError(
            "stitch.icp_max_translation_m and icp_max_rotation_deg must be >= 0, got "
            f"{config.icp_max_translation_m} and {config.icp_max_rotation_deg}"
        )
    if not 0.0 <= config.icp_min_overlap <= 1.0:
        raise PerceptionError(
            f"stitch.icp_min_overlap must be within 0-1, got {config.icp_min_overlap}"
        )
    if config.icp_method not in ICP_METHODS:
        raise PerceptionError(
            f"unknown stitch.icp_method {config.icp_method!r}; known: {', '.join(ICP_METHODS)}"
        )


class Stitcher:
    """Accumulates per-frame paint and surface clouds (base frame) into deduplicated clouds.

    Parameters
    ----------
    config : StitchConfig
        Paint voxel size (the unit of ``size``) and the ICP options.
    perception : PerceptionConfig
        Its ``surface_voxel_m`` is the grid of the stitched surface cloud.

    Attributes
    ----------
    paint_points : (N, 3) float64
        Metres, base frame: one point per occupied paint voxel (mean of what fell in it).
    paint_viewpoints : (N, 3) float64
        Camera centre of the first frame that saw each paint voxel.
    surface_points, surface_viewpoints : (M, 3) float64
        The same for the non-paint surface band (normals point towards the viewpoint).
    edge_points : (E, 3) float64
        The stroke's edges (paint next to metal, ``perception.cloud.stroke_edge_points``), one
        point per occupied paint-sized voxel.
    paint_frames, surface_frames, edge_frames : (N,), (M,), (E,) int64
        How many frames put a point in each voxel.
    size : int
        Number of occupied paint voxels: Algorithm 1's size(k).
    steps : list of StitchStep
        One per :meth:`add`.
    """

    def __init__(self, config: StitchConfig, *, perception: PerceptionConfig) -> None:
        check_stitch_config(config)
        self.config = config
        self.perception = perception
        self._paint = _VoxelMap(config.voxel_size_m, option="--stitch-voxel-mm")
        self._surface = _VoxelMap(perception.surface_voxel_m, option="--surface-voxel-mm")
        # The filter's duller colour clusters (rust, old marks): kept apart from the paint and
        # its size(k), for line selection to report.
        self._other = _VoxelMap(config.voxel_size_m, option="--stitch-voxel-mm")
        self._edges = _VoxelMap(config.voxel_size_m, option="--stitch-voxel-mm")
        self.steps: list[StitchStep] = []
        self._sights: list[FloatArray] = []

    @property
    def size(self) -> int:
        return len(self._paint)

    @property
    def paint_points(self) -> FloatArray:
        return self._paint.points

    @property
    def paint_viewpoints(self) -> FloatArray:
        return self._paint.viewpoints.copy()

    @property
    def views(self) -> FloatArray:
        """(K, 2, 3) each added frame's sight line, base frame: its camera centre (the pose
        it was added with, before ICP) and its view centre (a metre along the optical axis when
        the axis met no surface)."""
        return np.asarray(self._sights, dtype=np.float64).reshape(-1, 2, 3)

    @property
    def paint_rgb(self) -> FloatArray:
        """Mean sRGB (N, 3) in 0-1 of each paint voxel (NaN where unknown)."""
        return self._paint.rgb

    @property
    def other_points(self) -> FloatArray:
        """Voxels (P, 3) of the filter's duller colour clusters, metres, base frame."""
        return self._other.points

    @property
    def other_rgb(self) -> FloatArray:
        """Their mean sRGB (P, 3) in 0-1."""
        return self._other.rgb

    @property
    def surface_points(self) -> FloatArray:
        return self._surface.points

    @property
    def surface_viewpoints(self) -> FloatArray:
        return self._surface.viewpoints.copy()

    @property
    def edge_points(self) -> FloatArray:
        return self._edges.points

    @property
    def paint_frames(self) -> NDArray[np.int64]:
        return self._paint.frames.copy()

    @property
    def surface_frames(self) -> NDArray[np.int64]:
        return self._surface.frames.copy()

    @property
    def edge_frames(self) -> NDArray[np.int64]:
        return self._edges.frames.copy()

    def add(self, clouds: FrameClouds, *, T_base_cam: ArrayLike | None = None) -> StitchStep:
        """Merge one frame's clouds; returns its step (size, growth, ICP outcome).

        ``T_base_cam`` (4, 4) is the pose the clouds were projected with (default: theirs); the
        camera centre, corrected by ICP when it is accepted, becomes the new voxels' viewpoint.
        """
        pose = clouds.T_base_cam if T_base_cam is None else np.asarray(T_base_cam, np.float64)
        k = len(self.steps)
        origin = np.asarray(pose[:3, 3], dtype=np.float64)
        centre = clouds.view_centre
        self._sights.append(np.stack([origin, origin + pose[:3, 2] if centre is None else centre]))
        before = self.size
        icp: IcpOutcome | None = None
        paint, surface = clouds.paint_base, clouds.surface_base
        other, edges = clouds.other_base, clouds.edge_base
        if clouds.skip_reason is None and len(paint):
            if self.config.icp:
                icp = self._refine(paint)
                if icp.accepted:
                    paint = transform_points(icp.T_correction, paint)
                    surface = transform_points(icp.T_correction, surface)
                    if len(other):
                        other = transform_points(icp.T_correction, other)
                    if len(edges):
                        edges = transform_points(icp.T_correction, edges)
                    pose = icp.T_correction @ pose
            viewpoint = np.asarray(pose[:3, 3], dtype=np.float64)
            self._paint.add(paint, viewpoint, clouds.paint_rgb)
            self._surface.add(surface, viewpoint)
            self._other.add(other, viewpoint, clouds.other_rgb)
            self._edges.add(edges, viewpoint)
        step = StitchStep(
            k=k,
            frame_index=clouds.frame_index,
            stamp_ns=clouds.stamp_ns,
            size=self.size,
            growth=self.size - before,
            surface_size=len(self._surface),
            paint_pixels=clouds.paint_pixels,
            valid_paint_pixels=clouds.valid_paint_pixels,
            frame_points=len(clouds.paint_base),
            skip_reason=clouds.skip_reason,
            icp=icp,
        )
        self.steps.append(step)
        return step

    def kept_clouds(self) -> dict[str, Any]:
        """The edges and per-voxel frame counts, as :class:`StitchResult` keywords."""
        return {
            "edge_points": self.edge_points,
            "paint_frames": self.paint_frames,
            "surface_frames": self.surface_frames,
            "edge_frames": self.edge_frames,
            "other_frames": self._other.frames.copy(),
            "other_viewpoints": self._other.viewpoints.copy(),
        }

    # ------------------------------------------------------------------ ICP

    def _refine(self, paint: FloatArray) -> IcpOutcome:
        """ICP (``icp_method``) of the frame's paint against the stitched paint near it, guarded.

        Only the frame's points that already have a stitched neighbour within
        ``icp_max_distance_m`` take part: in a sweep each new frame also shows paint that is
        not stitched yet, and those points would pull the frame back onto the old cloud's end
        (the partial-overlap bias). Fitness, before and after, is the share of those points
        within one paint voxel of the stitched cloud. The paint alone is registered: the
        surface around it is often a plane or a cylinder, along which ICP slides freely, while
        the stroke's edges and bends hold it.
        """
        cfg = self.config
        if self.size == 0:
            return IcpOutcome(False, "first_frame")
        target_pts = self._paint.points
        lo = paint.min(axis=0) - cfg.icp_max_distance_m
        hi = paint.max(axis=0) + cfg.icp_max_distance_m
        target_pts = target_pts[np.all((target_pts >= lo) & (target_pts <= hi), axis=1)]
        if len(target_pts) < 10:
            return IcpOutcome(False, "low_overlap")
        tree = cKDTree(target_pts)
        distance, _ = tree.query(paint, distance_upper_bound=cfg.icp_max_distance_m)
        overlap = np.isfinite(distance)
        share = float(overlap.mean())
        if share < cfg.icp_min_overlap or overlap.sum() < 10:
            return IcpOutcome(False, "low_overlap", fitness_before=share)
        source_pts = paint[overlap]
        inlier = cfg.voxel_size_m
        fitness_before, rmse_before = _fitness(tree, source_pts, inlier)
        T = _icp(source_pts, target_pts, cfg)
        fitness_after, rmse_after = _fitness(tree, transform_points(T, source_pts), inlier)
        # The correction's size is judged where it acts: at the frame's centroid.
        centroid = source_pts.mean(axis=0)
        translation = float(np.linalg.norm(transform_points(T, centroid)[0] - centroid))
        outcome: dict[str, Any] = {
            "fitness_before": fitness_before,
            "fitness_after": fitness_after,
            "rmse_before_m": rmse_before,
            "rmse_after_m": rmse_after,
            "translation_m": translation,
            "rotation_deg": math.degrees(rotation_angle(np.eye(3), T[:3, :3])),
        }
        if fitness_after <= fitness_before:
            return IcpOutcome(False, "no_improvement", **outcome)
        if translation > cfg.icp_max_translation_m:
            return IcpOutcome(False, "translation_too_large", **outcome)
        if outcome["rotation_deg"] > cfg.icp_max_rotation_deg:
            return IcpOutcome(False, "rotation_too_large", **outcome)
        return IcpOutcome(True, "accepted", T_correction=T, **outcome)


def _fitness(tree: cKDTree, points: FloatArray, inlier_m: float) -> tuple[float, float]:
    """(share of points within ``inlier_m`` of the tree's points, RMS distance of those)."""
    distance, _ = tree.query(points, distance_upper_bound=inlier_m)
    inliers = distance[np.isfinite(distance)]
    rmse = float(np.sqrt(np.mean(inliers**2))) if inliers.size else 0.0
    return float(inliers.size / max(len(points), 1)), rmse


def _icp(source_pts: FloatArray, target_pts: FloatArray, config: StitchConfig) -> FloatArray:
    """open3d ICP of source onto target (N, 3); the (4, 4) correction in the base frame."""
    o3 = o3d()
    reg = o3.pipelines.registration
    source = o3.geometry.PointCloud(o3.utility.Vector3dVector(source_pts))
    target = o3.geometry.PointCloud(o3.utility.Vector3dVector(target_pts))
    if config.icp_method == "point_to_plane":
        radius = 3.0 * config.voxel_size_m
        target.estimate_normals(o3.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
        estimation = reg.TransformationEstimationPointToPlane()
    else:
        estimation = reg.TransformationEstimationPointToPoint()
    result = reg.registration_icp(
        source,
        target,
        config.icp_max_distance_m,
        np.eye(4),
        estimation,
        reg.ICPConvergenceCriteria(max_iteration=config.icp_max_iterations),
    )
    return np.asarray(result.transformation, dtype=np.float64).copy()


# --------------------------------------------------------------------------- the recipe


@dataclass(frozen=True, eq=False)
class StitchResult:
    """The stitched clouds of a recording and what each frame contributed.

    Attributes
    ----------
    paint_points, paint_viewpoints : (N, 3) float64
        Metres, base frame (see :class:`Stitcher`).
    surface_points, surface_viewpoints : (M, 3) float64
        Metres, base frame.
    paint_rgb : (N, 3) float64
        Mean sRGB in 0-1 of each paint point's pixels (NaN where unknown).
    other_points, other_rgb : (P, 3) float64
        The filter's duller colour clusters (rust, old marks), stitched apart from the paint.
    view_centres : (K, 3) float64
        Where each frame's optical axis met the surface, in frame order, metres, base frame
        (1 m along the axis when the image centre has no depth): the track the scan followed.
    view_origins : (K, 3) float64
        The camera centres of those frames: ``views`` pairs them into sight lines.
    edge_points : (E, 3) float64
        The stroke's edges, metres, base frame (see :class:`Stitcher`).
    paint_frames, surface_frames, edge_frames, other_frames : (N,), (M,), (E,), (P,) int64
        Frames that saw each point's voxel (empty when not kept).
    other_viewpoints : (P, 3) float64
        The camera centre that first saw each of the duller clusters' voxels.
    steps : list of StitchStep
        One per frame, in order.
    tally : PerceptionTally
        Frame, pixel and point counts, skip reasons.
    hsv : HsvRange
        The paint range used.
    base_frame : str
        TF frame of the points (from the frames; empty if there were none).
    """

    paint_points: FloatArray
    paint_viewpoints: FloatArray
    surface_points: FloatArray
    surface_viewpoints: FloatArray
    steps: list[StitchStep]
    tally: PerceptionTally
    hsv: HsvRange
    base_frame: str = ""
    paint_rgb: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    view_centres: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    other_points: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    other_rgb: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    view_origins: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    edge_points: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    paint_frames: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    surface_frames: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    edge_frames: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    other_frames: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    other_viewpoints: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def views(self) -> FloatArray:
        """(K, 2, 3) sight lines (camera centre, view centre) of the frames, base frame."""
        if len(self.view_origins) != len(self.view_centres):
            return np.asarray(self.view_centres).reshape(-1, 1, 3).repeat(2, axis=1)
        return np.stack([self.view_origins, self.view_centres], axis=1)

    @property
    def all_paint_points(self) -> FloatArray:
        """The paint and the duller clusters, (N + P, 3): what line selection splits."""
        return np.vstack([self.paint_points, self.other_points])

    @property
    def all_paint_rgb(self) -> FloatArray:
        """Their colours (N + P, 3), in the same order."""
        return np.vstack([self._rgb(self.paint_rgb, self.paint_points), self.other_rgb])

    @property
    def all_paint_frames(self) -> NDArray[np.int64]:
        """Frames that saw each of those points (N + P,); empty when not kept for all."""
        if len(self.paint_frames) != len(self.paint_points) or len(self.other_frames) != len(
            self.other_points
        ):
            return np.zeros(0, dtype=np.int64)
        return np.concatenate([self.paint_frames, self.other_frames])

    @property
    def all_paint_viewpoints(self) -> FloatArray:
        """The camera centre that first saw each of those points (N + P, 3); empty when not
        kept for all."""
        if len(self.other_viewpoints) != len(self.other_points):
            return np.zeros((0, 3))
        return np.vstack([self.paint_viewpoints, self.other_viewpoints])

    @staticmethod
    def _rgb(rgb: FloatArray, points: FloatArray) -> FloatArray:
        return rgb if len(rgb) == len(points) else np.full((len(points), 3), np.nan)

    @property
    def size(self) -> int:
        """Occupied paint voxels at the end."""
        return len(self.paint_points)

    @property
    def skip_reasons(self) -> dict[str, int]:
        return dict(Counter(s.skip_reason for s in self.steps if s.skip_reason is not None))

    @property
    def icp_accepted(self) -> int:
        """Frames whose ICP correction was applied."""
        return sum(s.icp_accepted for s in self.steps)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary with the per-frame growth (``steps``)."""
        return {
            **self.tally.to_dict(),
            "base_frame": self.base_frame,
            "size": self.size,
            "surface_size": len(self.surface_points),
            "icp_accepted": self.icp_accepted,
            "steps": [s.to_dict() for s in self.steps],
        }


def stitch_recording(
    frames: Iterable[Frame],
    hsv: HsvRange,
    config: ScrapcutConfig,
    *,
    progress: Callable[[StitchStep], None] | None = None,
) -> StitchResult:
    """Perceive and stitch every frame: the stitched paint and surface clouds of a recording.

    Parameters
    ----------
    frames : iterable of Frame
        Streamed; each is processed and dropped (memory stays bounded).
    hsv : HsvRange
        The paint's colour range.
    config : ScrapcutConfig
        ``config.perception`` and ``config.stitch`` are used.
    progress : callable, optional
        Called with each frame's :class:`StitchStep`.

    Raises
    ------
    PerceptionError
        When no frame shows usable paint: one line naming the colour range and the dominant
        hues the images showed instead. Frames without paint are only counted.
    """
    stitcher = Stitcher(config.stitch, perception=config.perception)
    tally = PerceptionTally(hsv)
    base_frame = ""
    for frame in frames:
        base_frame = frame.base_frame
        clouds = process_frame(frame, hsv, config.perception)
        tally.add(clouds, frame.color)
        step = stitcher.add(clouds, T_base_cam=frame.T_base_cam)
        if progress is not None:
            progress(step)
    tally.raise_if_no_paint()
    return StitchResult(
        paint_points=stitcher.paint_points,
        paint_viewpoints=stitcher.paint_viewpoints,
        surface_points=stitcher.surface_points,
        surface_viewpoints=stitcher.surface_viewpoints,
        steps=list(stitcher.steps),
        tally=tally,
        hsv=hsv,
        base_frame=base_frame,
        paint_rgb=stitcher.paint_rgb,
        view_centres=stitcher.views[:, 1].copy(),
        view_origins=stitcher.views[:, 0].copy(),
        other_points=stitcher.other_points,
        other_rgb=stitcher.other_rgb,
        **stitcher.kept_clouds(),
    )
