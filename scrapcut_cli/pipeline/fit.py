"""The pipeline's first steps: recording → stitched clouds → the line → curve → cutting path.

:func:`stitch_recording_file` reads a recording (through :mod:`scrapcut_cli.recording`),
stitches its paint, surface and stroke edges
(:func:`~scrapcut_cli.perception.stitch.stitch_recording`) and finds the marked line among the
paint's candidates (:func:`~scrapcut_cli.perception.candidates.select_line`) into a
:class:`StitchedRecording`; :func:`fit_stitched` fits the curve to the line's paint
(:func:`~scrapcut_cli.fitting.fit_line`: open or closed; an open fit follows the stroke model of
the stitched edges, :func:`~scrapcut_cli.fitting.stroke.stroke_model`, and says how sure each
point is, :func:`~scrapcut_cli.fitting.stroke.with_confidence`), cuts back what runs past that
paint (:func:`~scrapcut_cli.fitting.trim_to_paint`) and makes the cutting path
(:func:`~scrapcut_cli.toolpath.setpoints.make_cutting_path`) into a :class:`FitResult` that
knows how to become a path file. Split in two so that one stitched recording serves several
methods (a sweep in ``reproduce``) or several lines (``--pick all``) and an exploration replay
can start from the planner's own clouds.
:class:`~scrapcut_cli.pipeline.job.Pipeline` calls them in order; nothing here prints.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.config import FitMethod, ScrapcutConfig, choice_names
from scrapcut_cli.errors import ToolpathError
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.geometry import PolylineDistance, resample_polyline
from scrapcut_cli.toolpath.path import CuttingPath
from scrapcut_cli.toolpath.pathfile import path_to_dict
from scrapcut_cli.toolpath.setpoints import check_toolpath_config, make_cutting_path
from scrapcut_cli.toolpath.speeds import SpeedTable, load_speed_table

if TYPE_CHECKING:
    from scrapcut_cli.fitting.stroke import StrokeObservations
    from scrapcut_cli.perception.candidates import LineSelection
    from scrapcut_cli.perception.paint import HsvRange
    from scrapcut_cli.perception.stitch import StitchResult
    from scrapcut_cli.recording.reader import Recording

METHODS = choice_names(FitMethod)


@dataclass(frozen=True, eq=False)
class FitResult:
    """Everything one fit produced, with what it was made from.

    Attributes
    ----------
    curve, path : Curve, CuttingPath
        The fitted curve and the torch set-points (base frame).
    stitch : StitchResult
        The stitched paint and surface clouds and per-frame counts.
    method : str
        ``nurbs`` or ``skeleton``.
    source : dict
        ``path``, ``sha256_first_mib``, ``frames_used``, ``frames_skipped`` (path file "source").
    frame_id : str
        The base frame of every coordinate.
    config : ScrapcutConfig
        Every parameter used.
    frames_read : int
        Frames the reader delivered (paired, posed); ``reader_skipped`` more were skipped.
    stamp_ns : int
        Stamp of the last frame.
    start_ns : int
        The recording's start (the review MCAP is stamped with it, to overlay its timeline).
    timings_s : dict
        Wall time of ``read_stitch``, ``fit``, ``toolpath`` and ``total``, seconds.
    calibration : dict, optional
        The camera mount and clock offset the frames were posed with, when not the
        recording's own (the path file's ``calibration``).
    selection : LineSelection or None
        The paint's candidates: the line(s) and everything rejected.
    line_index : int
        Which of ``selection.lines`` this fit is of.
    """

    curve: Curve
    path: CuttingPath
    stitch: StitchResult
    method: str
    source: dict[str, Any]
    frame_id: str
    config: ScrapcutConfig
    frames_read: int
    reader_skipped: int
    reader_skip_reasons: dict[str, int] = field(default_factory=dict)
    stamp_ns: int = 0
    timings_s: dict[str, float] = field(default_factory=dict)
    calibration: dict[str, Any] | None = None
    start_ns: int = 0
    selection: LineSelection | None = None
    line_index: int = 0
    paint_estimate: Any = None  # perception.auto.PaintEstimate with --paint auto

    @property
    def paint_text(self) -> str:
        """The paint range looked for, in preset terms when it was estimated."""
        if self.paint_estimate is not None:
            return str(self.paint_estimate.describe())
        return self.stitch.tally.hsv.describe()

    @property
    def line_points(self) -> np.ndarray:
        """The paint (N, 3) of the line this fit is of, metres, base frame."""
        if self.selection is None:
            return self.stitch.paint_points
        return self.stitch.all_paint_points[self.selection.lines[self.line_index].points]

    @property
    def method_params(self) -> dict[str, Any]:
        """The fitting method's parameters (its config section)."""
        return dataclasses.asdict(getattr(self.config, self.method))

    def residual_m(self) -> tuple[float, float]:
        """(RMS, max) distance in metres of the line's stitched paint to the curve polyline:
        the spread of the paint around the curve, not an accuracy.

        The same measure for both methods; it includes the paint band's own half width.
        """
        d = PolylineDistance(self.curve.polyline).distance(self.line_points)
        return float(np.sqrt(np.mean(d * d))), float(d.max())

    def reverse_m(self) -> tuple[float, float]:
        """(mean, max) distance in metres from the curve (every ~1 mm) to the line's paint:
        where the path runs without paint under it (past an end, across a gap)."""
        d, _ = cKDTree(self.line_points).query(resample_polyline(self.curve.polyline, 0.001))
        return float(d.mean()), float(d.max())

    def to_path_dict(self, *, created: str | None = None) -> dict[str, Any]:
        """The ``scrapcut.path/v1`` dictionary (see :func:`~.pathfile.path_to_dict`)."""
        return path_to_dict(
            self.curve,
            self.path,
            source=self.source,
            method_params=self.method_params,
            config=self.config.to_dict(),
            frame_id=self.frame_id,
            created=created,
            calibration=self.calibration,
            selection=None if self.selection is None else self.selection_report(),
        )

    def selection_report(self) -> dict[str, Any]:
        """The line-selection report of this fit (its line first, rejected candidates)."""
        assert self.selection is not None
        report = self.selection.to_dict()
        report["line_index"] = self.line_index
        report["lines_found"] = len(self.selection.lines)
        report["paint"] = self.paint_text
        if self.paint_estimate is not None:
            report["paint_estimate"] = self.paint_estimate.to_dict()
        return report

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures for the summary table and ``--json``."""
        rms, worst = self.residual_m()
        reverse_mean, reverse_max = self.reverse_m()
        info = self.path.info
        perception_skips = dict(self.stitch.skip_reasons)
        reasons = dict(self.reader_skip_reasons)
        for reason, count in perception_skips.items():
            reasons[reason] = reasons.get(reason, 0) + count
        return {
            "recording": self.source["path"],
            "method": self.method,
            "method_params": self.method_params,
            "frame_id": self.frame_id,
            "frames_used": self.source["frames_used"],
            "frames_skipped": self.source["frames_skipped"],
            "skip_reasons": dict(sorted(reasons.items())),
            "frames_read": self.frames_read,
            "paint": self.paint_text,
            "paint_points": len(self.stitch.paint_points),
            "surface_points": len(self.stitch.surface_points),
            "curve_length_m": float(self.curve.length),
            "curve_points": len(self.curve.points),
            "setpoints": len(self.path),
            "flagged": self.path.flagged,
            "tilted": info.get("tilted", 0),
            "collision": info.get("collision", 0),
            "no_surface": info.get("no_surface", 0),
            "closed": bool(self.curve.closed),
            "unobserved": info.get("unobserved", 0),
            "unobserved_arcs": list(info.get("unobserved_arcs", [])),  # type: ignore[call-overload]
            "loop": info.get("loop"),
            "confidence": confidence_summary(self.path),
            "paint_spread_rms_m": rms,
            "paint_spread_max_m": worst,
            "reverse_mean_m": reverse_mean,
            "reverse_max_m": reverse_max,
            "paint_trim_m": self.curve.info.get("paint_trim_m", [0.0, 0.0]),
            "line_points": len(self.line_points),
            "selection": None if self.selection is None else self.selection_report(),
            "fitter_info": _scalars(self.curve.info),
            "material": info.get("material"),
            "thickness_mm": info.get("thickness_mm"),
            "speed_m_s": info.get("speed_m_s"),
            "pierce_s": info.get("pierce_s"),
            "cut_time_s": info.get("cut_time_s"),
            "time_s": dict(self.timings_s),
            "calibration": self.calibration,
        }


@dataclass(frozen=True, eq=False)
class StitchedRecording:
    """A recording's stitched clouds with where they came from (fit several methods on one).

    ``source`` is the path file's "source" block; ``frame_id`` the base frame; ``reader_*``
    count the frames the reader skipped (unpaired, pose out of range) and why.
    """

    stitch: StitchResult
    source: dict[str, Any]
    frame_id: str
    reader_skipped: int
    reader_skip_reasons: dict[str, int]
    stamp_ns: int
    time_s: float
    calibration: dict[str, Any] | None = None
    start_ns: int = 0
    selection: LineSelection | None = None
    paint_estimate: Any = None  # perception.auto.PaintEstimate with --paint auto


def select_stitched(stitch: StitchResult, config: ScrapcutConfig) -> LineSelection:
    """The marked line among the stitched paint's candidates (``config.selection``)."""
    from scrapcut_cli.perception.candidates import select_line

    return select_line(
        stitch.all_paint_points,
        stitch.all_paint_rgb,
        stitch.views,
        voxel_m=config.stitch.voxel_size_m,
        config=config.selection,
    )


#: --paint auto looks at this many images, evenly over the recording.
AUTO_PAINT_IMAGES = 12


def paint_for_recording(rec: Recording, config: ScrapcutConfig) -> tuple[HsvRange, Any]:
    """(the paint range to look for in ``rec``, the ``PaintEstimate`` when it was estimated
    from its images: ``--paint auto``, or no paint named by the user nor the recording)."""
    from scrapcut_cli.perception.auto import estimate_paint
    from scrapcut_cli.perception.paint import resolve_recording_paint

    hsv = resolve_recording_paint(config.paint, rec.metadata)
    if hsv is not None:
        return hsv, None
    usable = rec.plan().usable
    picks = np.unique(np.linspace(0, max(usable - 1, 0), min(usable, AUTO_PAINT_IMAGES)))
    images = [frame.color for frame in rec.frames(only=set(picks.astype(int).tolist()))]
    estimate = estimate_paint(images)
    return estimate.hsv, estimate


def stitch_recording_file(
    recording: str | os.PathLike[str],
    *,
    config: ScrapcutConfig,
    progress: Callable[[int, int], None] | None = None,
    stamps_ns: Collection[int] | None = None,
) -> StitchedRecording:
    """Read a recording and stitch its paint and surface clouds (only the frames with these
    header ``stamps_ns``, when given: an exploration's own views).

    The paint defaults to the recording's own (simulator metadata) unless ``config.paint`` was
    set. ``progress(frames_done, frames_total)`` is called after each frame. Frames are posed
    with the calibration ``config.calibration`` names (a file, or estimated from the recording
    first); the result keeps its record for the path file.
    """
    from scrapcut_cli.calibration.recipe import camera_mount_for
    from scrapcut_cli.perception.stitch import stitch_recording
    from scrapcut_cli.recording.reader import open_recording, sha256_first_mib

    t0 = time.perf_counter()
    path = Path(recording)
    mount, calibration = camera_mount_for(path, config, progress=progress)
    with open_recording(path, config.recording, mount=mount) as rec:
        plan = rec.plan()
        hsv, estimate = paint_for_recording(rec, config)
        frame_id = rec.base_frame
        start_ns = rec.start_ns
        done = 0

        def step(_: object) -> None:
            nonlocal done
            done += 1
            if progress is not None:
                progress(done, plan.usable)

        frames = rec.frames()
        if stamps_ns is not None:
            wanted = set(stamps_ns)
            frames = (f for f in frames if f.stamp_ns in wanted)
        stitch = stitch_recording(frames, hsv, config, progress=step)
    tally = stitch.tally
    source = {
        "path": str(path),
        "sha256_first_mib": sha256_first_mib(path),
        "frames_used": int(tally.frames_with_paint),
        "frames_skipped": int(plan.skipped + tally.frames - tally.frames_with_paint),
        "start_ns": int(start_ns),
    }
    return StitchedRecording(
        stitch=stitch,
        source=source,
        frame_id=frame_id,
        reader_skipped=int(plan.skipped),
        reader_skip_reasons=dict(plan.skip_reasons),
        stamp_ns=max((s.stamp_ns for s in stitch.steps), default=0),
        time_s=time.perf_counter() - t0,
        calibration=calibration,
        start_ns=int(start_ns),
        selection=select_stitched(stitch, config),
        paint_estimate=estimate,
    )


def check_fit_options(
    method: str, config: ScrapcutConfig, speeds: SpeedTable | None = None
) -> SpeedTable:
    """Refuse an unknown method, tool-path parameters out of range, or a material/thickness
    missing from the speed chart — before minutes of stitching. Returns the speed chart."""
    from scrapcut_cli.perception.candidates import check_selection_config

    if method not in METHODS:
        raise ToolpathError(f"unknown fitting method {method!r}; known: {', '.join(METHODS)}")
    check_toolpath_config(config.toolpath)
    check_selection_config(config.selection)
    if speeds is None:
        speeds = load_speed_table(config.toolpath.speed_table)
    speeds.lookup(config.toolpath.material, config.toolpath.thickness_mm)
    return speeds


def fit_stitched(
    stitched: StitchedRecording,
    *,
    method: str,
    config: ScrapcutConfig,
    speeds: SpeedTable | None = None,
    line: int = 0,
) -> FitResult:
    """Fit the curve to the paint of the picked line ``line`` (of ``selection.lines``), cut
    back what runs past that paint, and make the cutting path on the stitched surface."""
    from scrapcut_cli.fitting import fit_line, trim_to_paint
    from scrapcut_cli.fitting.stroke import stroke_model, with_confidence

    if method not in METHODS:
        raise ToolpathError(f"unknown fitting method {method!r}; known: {', '.join(METHODS)}")
    stitch = stitched.stitch
    if speeds is None:
        speeds = load_speed_table(config.toolpath.speed_table)
    t0 = time.perf_counter()
    selection = stitched.selection
    if selection is None:
        selection = select_stitched(stitch, config)
    if not 0 <= line < len(selection.lines):
        raise ToolpathError(f"line {line} asked for, {len(selection.lines)} picked")
    chosen = selection.lines[line].points
    paint = stitch.all_paint_points[chosen]
    observations = stroke_observations(stitch, config, chosen)
    model = stroke_model(paint, observations) if len(observations.edges) else None
    curve = fit_line(paint, stitch.surface_points, method, config, stroke=model)
    # No cut past the paint: what lies beyond the paint's extent along the curve and farther
    # than two stitching voxels from it is cut back.
    curve = trim_to_paint(curve, paint, tolerance_m=2.0 * config.stitch.voxel_size_m)
    if not curve.closed:
        curve = with_confidence(curve, paint, observations, model)
    t1 = time.perf_counter()
    # Paint lies on the surface too: both clouds give normals and both can hit the torch.
    surface = np.vstack([stitch.surface_points, stitch.paint_points])
    viewpoints = np.vstack([stitch.surface_viewpoints, stitch.paint_viewpoints])
    cutting = make_cutting_path(curve, surface, viewpoints, config=config.toolpath, speeds=speeds)
    t2 = time.perf_counter()
    return FitResult(
        curve=curve,
        path=cutting,
        stitch=stitch,
        method=method,
        source=dict(stitched.source),
        frame_id=stitched.frame_id,
        config=config,
        frames_read=int(stitch.tally.frames),
        reader_skipped=stitched.reader_skipped,
        reader_skip_reasons=dict(stitched.reader_skip_reasons),
        stamp_ns=stitched.stamp_ns,
        start_ns=stitched.start_ns,
        timings_s={
            "read_stitch": stitched.time_s,
            "fit": t1 - t0,
            "toolpath": t2 - t1,
            "total": stitched.time_s + (t2 - t0),
        },
        calibration=stitched.calibration,
        selection=selection,
        line_index=line,
        paint_estimate=stitched.paint_estimate,
    )


def confidence_summary(path: CuttingPath) -> dict[str, Any] | None:
    """The set-points' confidence in brief (None when the fit estimated none): σ's median and
    max (metres), the mean support, the flag counts and the stretches of path bridged over a
    gap as [start, end] arc lengths, metres."""
    if path.sigma_m is None or path.support is None or len(path) == 0:
        return None
    bridged = np.array(["bridged_gap" in f for f in path.flags], dtype=bool)
    edges = np.diff(np.concatenate([[0], bridged.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return {
        "sigma_median_m": float(np.median(path.sigma_m)),
        "sigma_max_m": float(np.max(path.sigma_m)),
        "support_mean": float(np.mean(path.support)),
        "bridged_gap": int(bridged.sum()),
        "low_support": sum("low_support" in f for f in path.flags),
        "bridged_stretches_m": [
            [float(path.arc_length[a]), float(path.arc_length[b])]
            for a, b in zip(starts, ends, strict=True)
        ],
    }


def stroke_observations(
    stitch: StitchResult, config: ScrapcutConfig, chosen: NDArray[np.intp] | None = None
) -> StrokeObservations:
    """What the stitched clouds say about the stroke besides its paint: its edges, the surface
    around it and how many frames saw each voxel (``fitting.stroke``). ``chosen`` indexes the
    line's points in ``stitch.all_paint_points`` (default: the paint points, in order)."""
    from scrapcut_cli.fitting.stroke import StrokeObservations

    frames, viewpoints = stitch.paint_frames, stitch.paint_viewpoints
    if chosen is not None:
        every_frames, every_viewpoints = stitch.all_paint_frames, stitch.all_paint_viewpoints
        frames = every_frames[chosen] if len(every_frames) else every_frames
        viewpoints = every_viewpoints[chosen] if len(every_viewpoints) else every_viewpoints
    return StrokeObservations(
        edges=stitch.edge_points,
        surface=stitch.surface_points,
        paint_frames=frames,
        surface_frames=stitch.surface_frames,
        voxel_m=config.stitch.voxel_size_m,
        paint_viewpoints=viewpoints,
        envelope_reach_m=config.perception.surface_band_m,
    )


def _scalars(info: dict[str, Any]) -> dict[str, Any]:
    """The plain numbers, strings and flags of a diagnostics dictionary."""
    out: dict[str, Any] = {}
    for key, value in info.items():
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, str | bool | int | float):
            out[str(key)] = value
    return out
