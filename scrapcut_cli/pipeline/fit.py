"""The pipeline's first steps: recording → stitched clouds → curve → cutting path.

:func:`stitch_recording_file` reads a recording (through :mod:`scrapcut_cli.recording`) and
stitches its paint and surface (:func:`~scrapcut_cli.perception.stitch.stitch_recording`) into a
:class:`StitchedRecording`; :func:`fit_stitched` fits the curve
(:func:`~scrapcut_cli.fitting.fit_line`: open or closed) and makes the cutting path
(:func:`~scrapcut_cli.toolpath.setpoints.make_cutting_path`) into a :class:`FitResult` that knows
how to become a path file. Split in two so that one stitched recording serves several methods (a
sweep in ``reproduce``) and an exploration replay can start from the planner's own clouds.
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

from scrapcut_cli.config import FitMethod, ScrapcutConfig, choice_names
from scrapcut_cli.errors import ToolpathError
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.geometry import PolylineDistance
from scrapcut_cli.toolpath.path import CuttingPath
from scrapcut_cli.toolpath.pathfile import path_to_dict
from scrapcut_cli.toolpath.setpoints import check_toolpath_config, make_cutting_path
from scrapcut_cli.toolpath.speeds import SpeedTable, load_speed_table

if TYPE_CHECKING:
    from scrapcut_cli.perception.stitch import StitchResult

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

    @property
    def method_params(self) -> dict[str, Any]:
        """The fitting method's parameters (its config section)."""
        return dataclasses.asdict(getattr(self.config, self.method))

    def residual_m(self) -> tuple[float, float]:
        """(RMS, max) distance in metres of the stitched paint to the curve polyline: the
        spread of the paint around the curve, not an accuracy.

        The same measure for both methods; it includes the paint band's own half width.
        """
        d = PolylineDistance(self.curve.polyline).distance(self.stitch.paint_points)
        return float(np.sqrt(np.mean(d * d))), float(d.max())

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
        )

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures for the summary table and ``--json``."""
        rms, worst = self.residual_m()
        info = self.path.info
        tally = self.stitch.tally
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
            "paint": tally.hsv.describe(),
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
            "paint_spread_rms_m": rms,
            "paint_spread_max_m": worst,
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
    from scrapcut_cli.perception.paint import resolve_recording_paint
    from scrapcut_cli.perception.stitch import stitch_recording
    from scrapcut_cli.recording.reader import open_recording, sha256_first_mib

    t0 = time.perf_counter()
    path = Path(recording)
    mount, calibration = camera_mount_for(path, config, progress=progress)
    with open_recording(path, config.recording, mount=mount) as rec:
        plan = rec.plan()
        hsv = resolve_recording_paint(config.paint, rec.metadata)
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
    )


def check_fit_options(
    method: str, config: ScrapcutConfig, speeds: SpeedTable | None = None
) -> SpeedTable:
    """Refuse an unknown method, tool-path parameters out of range, or a material/thickness
    missing from the speed chart — before minutes of stitching. Returns the speed chart."""
    if method not in METHODS:
        raise ToolpathError(f"unknown fitting method {method!r}; known: {', '.join(METHODS)}")
    check_toolpath_config(config.toolpath)
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
) -> FitResult:
    """Fit the curve to stitched paint and make the cutting path on the stitched surface."""
    from scrapcut_cli.fitting import fit_line

    if method not in METHODS:
        raise ToolpathError(f"unknown fitting method {method!r}; known: {', '.join(METHODS)}")
    stitch = stitched.stitch
    if speeds is None:
        speeds = load_speed_table(config.toolpath.speed_table)
    t0 = time.perf_counter()
    curve = fit_line(stitch.paint_points, stitch.surface_points, method, config)
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
