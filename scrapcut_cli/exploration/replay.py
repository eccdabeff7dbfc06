"""Algorithm 1 over a recording: verify an exploration run, or tune the planner on a dense scan.

Two recipes, both returning an :class:`ExplorationRun`:

:func:`replay_exploration`
    An exploration recording (``scrapcut record --mode explore``) holds the frames the planner
    saw and its log on /scrapcut/exploration, one JSON object per decision. The replay rebuilds
    the planner from the log's first entry (method, paint, every parameter, initial view),
    feeds it the logged frames (by image stamp), answers its reachability queries with the
    logged answers (:class:`RecordedAnswers`; the simulator is not needed) and compares every
    decision with the log: growth, size, endpoints, action, reason, planned pose, the end
    evidence's verdicts (which frame observed an end, and how) and the queries themselves.
    The planner is deterministic, so any difference is a divergence.

:func:`what_if`
    On a dense recording (a ``survey`` in the simulator, or any real scan), the planner runs
    with other parameters and each planned view is answered with the recorded frame nearest to
    it (:class:`NearestView`: camera position and viewing angle within tolerances; that is also
    the reachability answer). Views used, endpoints found and, with a reference, the coverage
    of the global fit tell whether the parameters would have worked, without a robot.

Both keep the planner's stitched clouds (:attr:`ExplorationRun.stitch`); the global fit, its
cutting path and its error against the reference are the pipeline's
(:func:`scrapcut_cli.pipeline.explore.fit_exploration`, the same job as ``scrapcut fit``), so no
reference is read here. Nothing here prints; ``scrapcut explore`` renders the result.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli import __version__
from scrapcut_cli.cell import Reach, ReachAnswer, ReachQuery
from scrapcut_cli.config import ScrapcutConfig, config_from_dict
from scrapcut_cli.errors import ConfigError, ExplorationError
from scrapcut_cli.exploration.planner import (
    LOG_SCHEMA,
    ExplorationPlanner,
    Observation,
    StepTiming,
    check_exploration_config,
    perceive,
    pose_from_dict,
)
from scrapcut_cli.geometry import rotation_angle
from scrapcut_cli.perception.paint import HsvRange
from scrapcut_cli.perception.stitch import StitchResult
from scrapcut_cli.recording.frame import Frame

FloatArray = NDArray[np.float64]

#: Logged and replayed poses agree within these (the log keeps full float precision; the
#: executed pose goes through /tf and its interpolation, exact to ~1e-12).
POSE_TOLERANCE_M = 1e-6
POSE_TOLERANCE_RAD = 1e-6
#: Log entries compared key by key between the recording and the replay.
COMPARED_KEYS = ("growth", "size", "endpoints_found", "direction", "action", "reason", "stop")
#: A what-if keeps one frame per resting pose: frames closer than this to the last kept one.
SAME_POSE_M = 0.002
SAME_POSE_RAD = float(np.radians(0.5))

#: Exploration options added after the log schema; a log without them ran without them.
LATER_OPTIONS = ("other_side_views", "observed_end", "look_back")

ProgressFn = Callable[[int, int], None]


@dataclass(frozen=True, eq=False)
class ReplayStep:
    """One decision of a replayed or what-if run.

    Attributes
    ----------
    k : int
        Frames observed before this one.
    frame_index, stamp_ns : int
        The recorded frame observed.
    growth, size, endpoints_found : int
        New paint voxels, their running sum, endpoints found so far.
    action, reason : str
        What the decision asks for (``extrapolate``, ``look_past``, ``return``, ``stop``) and why.
    requested : (4, 4) float64 or None
        The pose the previous decision asked for (the initial view for k = 0).
    executed : (4, 4) float64
        The frame's pose: where the camera really was.
    planned : (4, 4) float64 or None
        The pose this decision asks for (None when it stops).
    queries : int
        Reachability queries made for this decision.
    divergences : tuple of str
        How this step differs from the log (replay only).
    """

    k: int
    frame_index: int
    stamp_ns: int
    growth: int
    size: int
    endpoints_found: int
    action: str
    reason: str
    requested: FloatArray | None
    executed: FloatArray
    planned: FloatArray | None
    queries: int
    divergences: tuple[str, ...] = ()

    def execution_error(self) -> tuple[float, float] | None:
        """(camera position error m, viewing direction error rad) of the executed pose against
        the requested one; the roll about the optical axis is free, so it is not counted."""
        if self.requested is None:
            return None
        dp = float(np.linalg.norm(self.executed[:3, 3] - self.requested[:3, 3]))
        cos = float(np.clip(self.executed[:3, 2] @ self.requested[:3, 2], -1.0, 1.0))
        return dp, float(np.arccos(cos))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready row (poses as position + xyzw, errors in mm and degrees)."""
        from scrapcut_cli.exploration.planner import pose_to_dict

        error = self.execution_error()
        return {
            "k": self.k,
            "frame": self.frame_index,
            "stamp_ns": self.stamp_ns,
            "growth": self.growth,
            "size": self.size,
            "endpoints_found": self.endpoints_found,
            "action": self.action,
            "reason": self.reason,
            "requested_pose": None if self.requested is None else pose_to_dict(self.requested),
            "executed_pose": pose_to_dict(self.executed),
            "planned_pose": None if self.planned is None else pose_to_dict(self.planned),
            "execution_error_mm": None if error is None else 1000.0 * error[0],
            "execution_error_deg": None if error is None else float(np.degrees(error[1])),
            "queries": self.queries,
            "divergences": list(self.divergences),
        }


@dataclass(frozen=True, eq=False)
class ExplorationRun:
    """A replayed (``mode="replay"``) or what-if (``mode="what_if"``) exploration.

    Attributes
    ----------
    source : str
        The recording.
    method : str
        ``nurbs`` or ``skeleton``.
    steps : list of ReplayStep
        One per observed frame.
    stop_reason : str or None
        Why the planner stopped; ``recorder: <reason>`` when the simulator's recorder stopped
        first (its view budget, a view it could not execute).
    ends : list of dict
        Per explored direction: ``direction``, ``reason``, ``tip``.
    divergences : list of str
        Every difference from the log (replay; empty when the replay matches).
    paint_points : (N, 3) float64
        The stitched paint, metres, base frame.
    config : dict
        The planner's parameters (``planner_config_dict``) and the what-if's matching options.
    timings : list of StepTiming
        Wall time per observe (perception, stitch, fit, plan, reachability), milliseconds.
    frames_available : int
        Frames in the recording the run could use (what-if: after dropping repeated poses).
    stitch : StitchResult
        The planner's stitched paint and surface with its perception counts (the global fit's
        input: :func:`scrapcut_cli.pipeline.explore.fit_exploration`).
    settings : ScrapcutConfig
        The configuration the planner ran with.
    """

    mode: str
    source: str
    method: str
    steps: list[ReplayStep]
    stop_reason: str | None
    ends: list[dict[str, Any]]
    divergences: list[str]
    paint_points: FloatArray
    config: dict[str, Any]
    timings: list[StepTiming] = field(default_factory=list)
    frames_available: int = 0
    stitch: StitchResult | None = None
    settings: ScrapcutConfig | None = None

    @property
    def views(self) -> int:
        """Frames observed."""
        return len(self.steps)

    @property
    def endpoints_found(self) -> int:
        return self.steps[-1].endpoints_found if self.steps else 0

    @property
    def camera_travel_m(self) -> float:
        """Straight-line length of the camera's path through the executed views, metres."""
        if len(self.steps) < 2:
            return 0.0
        positions = np.array([s.executed[:3, 3] for s in self.steps])
        return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())

    @property
    def matches(self) -> bool:
        """True when a replay reproduced the log exactly."""
        return not self.divergences

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary and steps (travel in mm, as in reports; the ``ends`` tips and the
        poses in metres, as in the log)."""
        timings = np.array([[t.planner, t.total] for t in self.timings]) if self.timings else None
        return {
            "mode": self.mode,
            "source": self.source,
            "method": self.method,
            "views": self.views,
            "frames_available": self.frames_available,
            "endpoints_found": self.endpoints_found,
            "stop_reason": self.stop_reason,
            "ends": self.ends,
            "camera_travel_mm": 1000.0 * self.camera_travel_m,
            "paint_points": len(self.paint_points),
            "matches_log": self.matches if self.mode == "replay" else None,
            "divergences": list(self.divergences),
            "decision_ms_median": None
            if timings is None
            else {
                "planner": float(np.median(timings[:, 0])),
                "total": float(np.median(timings[:, 1])),
            },
            "config": self.config,
            "steps": [s.to_dict() for s in self.steps],
        }


# --------------------------------------------------------------------------- answers


class RecordedAnswers:
    """Answers a replayed planner's reachability queries from the log, checking each pose.

    Call :meth:`begin` with a step's logged queries before the planner observes its frame,
    :meth:`finish` after; differences are collected in :attr:`divergences`.
    """

    def __init__(self) -> None:
        self._queue: list[dict[str, Any]] = []
        self._k = -1
        self.divergences: list[str] = []

    def begin(self, k: int, queries: Sequence[dict[str, Any]]) -> None:
        self._k = k
        self._queue = list(queries)

    def __call__(self, query: ReachQuery) -> ReachAnswer:
        if not self._queue:
            self.divergences.append(f"step {self._k}: a reachability query the log does not have")
            return ReachAnswer(False, Reach.NO_RECORD, "not in the log")
        logged = self._queue.pop(0)
        T = pose_from_dict(logged)
        if not _same_pose(T, np.asarray(query.T_base_cam, dtype=np.float64)):
            self.divergences.append(
                f"step {self._k}: reachability asked at {_pose_text(query.T_base_cam)}, "
                f"log has {_pose_text(T)}"
            )
        ok = bool(logged.get("ok", False))
        # Logs before the cell contract kept no reason.
        reason, detail = Reach.parse(str(logged.get("reason", "ok" if ok else "no_record")))
        return ReachAnswer(ok, reason, detail, T_base_cam=T if ok else None)

    def finish(self) -> None:
        if self._queue:
            self.divergences.append(
                f"step {self._k}: {len(self._queue)} logged reachability queries were not asked"
            )
        self._queue = []


class NearestView:
    """Answers planned views with the recorded frame nearest in position and viewing angle.

    Parameters
    ----------
    poses : (F, 4, 4) float64
        ``T_base_cam`` of the recorded frames.
    match_distance_m, match_angle_deg : float
        A frame answers a planned view only if its camera is within this distance and its
        optical axis within this angle of the planned one.
    angle_weight_m : float
        Metres of position difference one radian of viewing angle costs in the ranking.
    """

    def __init__(
        self,
        poses: ArrayLike,
        *,
        match_distance_m: float,
        match_angle_deg: float,
        angle_weight_m: float = 0.2,
    ) -> None:
        P = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        if not (match_distance_m > 0 and 0 < match_angle_deg <= 180):
            raise ExplorationError(
                f"what-if matching needs a positive distance and an angle within (0, 180], got "
                f"{match_distance_m * 1000:g} mm and {match_angle_deg:g} deg"
            )
        self.positions = P[:, :3, 3].copy()
        self.axes = P[:, :3, 2].copy()
        self.match_distance_m = float(match_distance_m)
        self.match_angle_rad = float(np.radians(match_angle_deg))
        self.angle_weight_m = float(angle_weight_m)

    def nearest(self, T_base_cam: ArrayLike) -> int | None:
        """Index of the best matching frame, or None when none is within the tolerances."""
        T = np.asarray(T_base_cam, dtype=np.float64)
        distance = np.linalg.norm(self.positions - T[:3, 3], axis=1)
        angle = np.arccos(np.clip(self.axes @ T[:3, 2], -1.0, 1.0))
        ok = (distance <= self.match_distance_m) & (angle <= self.match_angle_rad)
        if not ok.any():
            return None
        cost = np.where(ok, distance + self.angle_weight_m * angle, np.inf)
        return int(np.argmin(cost))  # lowest index wins ties: deterministic

    def __call__(self, query: ReachQuery) -> ReachAnswer:
        k = self.nearest(query.T_base_cam)
        if k is None:
            return ReachAnswer(False, Reach.NO_RECORD, "no recorded frame near the pose")
        return ReachAnswer(True, Reach.OK, T_base_cam=np.asarray(query.T_base_cam).copy())


# --------------------------------------------------------------------------- replay


def replay_exploration(
    recording: str | os.PathLike[str],
    *,
    config: ScrapcutConfig | None = None,
    method: str | None = None,
    progress: ProgressFn | None = None,
) -> ExplorationRun:
    """Recompute every decision of an exploration recording and compare it with the log.

    Parameters
    ----------
    recording : path
        A recording with /scrapcut/exploration (MCAP, ROS 1 bag or ROS 2 bag directory).
    config : ScrapcutConfig, optional
        Only ``recording`` (topics) and ``evaluation`` are used: the planner's parameters come
        from the log, so the replay repeats the run.
    method : str, optional
        Must match the logged method (a different one cannot be verified: use :func:`what_if`).
    progress : callable, optional
        ``progress(steps_done, steps_total)``.

    Raises
    ------
    ExplorationError
        No exploration log, a log this version cannot read, or a method mismatch.
    """
    from scrapcut_cli.recording.reader import open_recording

    base = config if config is not None else ScrapcutConfig()
    path = Path(recording)
    with open_recording(path, base.recording) as rec:
        log = [entry for entry in rec.exploration_log() if "k" in entry]
        if not log:
            raise ExplorationError(
                f"{path} has no exploration log (/scrapcut/exploration); "
                "use --what-if to run the planner over its frames"
            )
        first = log[0]
        if first.get("schema") != LOG_SCHEMA or "config" not in first:
            raise ExplorationError(
                f"{path}: the exploration log is not {LOG_SCHEMA} (first entry has schema "
                f"{first.get('schema')!r}); it cannot be replayed by this version"
            )
        logged_method = str(first.get("method"))
        if method is not None and method != logged_method:
            raise ExplorationError(
                f"{path} was explored with {logged_method}; a replay with {method} cannot be "
                f"verified against its log: add --what-if to run {method} over its frames"
            )
        planner_config = _logged_config(first, base)
        try:
            hsv = HsvRange(**first["paint_hsv"])
            initial_view = pose_from_dict(first["initial_view"])
            wanted = {int(entry["frame_stamp_ns"]): entry for entry in log}
        except (KeyError, TypeError, ValueError) as exc:
            raise ExplorationError(
                f"{path}: the exploration log is malformed ({type(exc).__name__}: {exc})"
            ) from None
        answers = RecordedAnswers()
        planner = ExplorationPlanner(
            initial_view, reachable=answers, hsv=hsv, config=planner_config
        )
        divergences: list[str] = []
        stopped_by: str | None = None
        requested: FloatArray | None = planner.start().T_base_cam
        steps: list[ReplayStep] = []
        frames = (f for f in rec.frames() if f.stamp_ns in wanted)
        for index, entry in enumerate(log):
            frame = next(frames, None)
            if frame is None or frame.stamp_ns != int(entry["frame_stamp_ns"]):
                divergences.append(
                    f"step {entry['k']}: the frame stamped {entry['frame_stamp_ns']} ns is not "
                    "in the recording"
                )
                break
            frame = _with_logged_pose(frame, entry)
            answers.begin(int(entry["k"]), entry.get("reachability", []))
            decision = planner.observe(frame)
            answers.finish()
            step_divergences = [*answers.divergences, *_compare(entry, decision.info, frame)]
            answers.divergences = []
            divergences += step_divergences
            steps.append(
                _step(decision.info, frame, requested, decision.T_base_cam, step_divergences)
            )
            requested = decision.T_base_cam
            if progress is not None:
                progress(index + 1, len(log))
            if decision.stop and index + 1 < len(log):
                divergences.append(
                    f"step {entry['k']}: the replay stopped ({decision.reason}) but the log "
                    f"goes on for {len(log) - index - 1} more steps"
                )
                break
        else:
            if not planner.finished:
                # The recorder may stop first (its view budget, a view the robot could not
                # execute): that is in its metadata, and not the planner's decision.
                recorder = rec.metadata.get("scrapcut_result", {}).get("stop_reason")
                if recorder and recorder != log[-1].get("reason"):
                    stopped_by = f"recorder: {recorder}"
                else:
                    divergences.append(
                        f"the log ends after {len(log)} steps but the replayed planner did not stop"
                    )
        recorded_by = first.get("tool_version")
        if divergences and recorded_by != __version__:
            divergences.append(
                f"the run was recorded by scrapcut {recorded_by}, this is scrapcut {__version__}"
            )
    return _finish(
        "replay",
        path,
        planner,
        steps,
        divergences,
        config=planner_config,
        frames_available=len(log),
        stop_reason=stopped_by,
    )


def _logged_config(first: dict[str, Any], base: ScrapcutConfig) -> ScrapcutConfig:
    """The planner's configuration from the log, with ``base``'s recording and evaluation."""
    settings = dict(first["config"])
    if isinstance(settings.get("exploration"), dict):
        # Logged before these options existed: the run had neither, and its replay neither.
        exploration = dict(settings["exploration"])
        for key in LATER_OPTIONS:
            exploration.setdefault(key, False)
        settings["exploration"] = exploration
    try:
        logged = config_from_dict(settings, where="exploration log")
    except ConfigError as exc:
        raise ExplorationError(f"the exploration log's configuration is unusable: {exc}") from None
    return replace(logged, recording=base.recording, evaluation=base.evaluation)


def _with_logged_pose(frame: Frame, entry: dict[str, Any]) -> Frame:
    """``frame`` with the exact pose matrix the planner saw, if /tf agrees with it.

    The recording's pose is re-composed from /tf (quaternions, interpolation) and can differ
    from the planner's by ~1e-16; a point exactly on a voxel boundary would then change sides.
    A disagreement beyond the tolerance is left in place and reported by :func:`_compare`.
    """
    rows = entry.get("executed_T")
    if rows is None:
        return frame
    T = np.eye(4)
    try:
        T[:3] = np.asarray(rows, dtype=np.float64).reshape(3, 4)
    except ValueError:
        return frame
    if not _same_pose(T, frame.T_base_cam):
        return frame
    return replace(frame, T_base_cam=T)


def _compare(logged: Mapping[str, Any], replayed: Mapping[str, Any], frame: Frame) -> list[str]:
    """Differences between a logged decision and the replayed one (empty when equal)."""
    k = logged.get("k")
    out = []
    for key in COMPARED_KEYS:
        if logged.get(key) != replayed.get(key):
            out.append(f"step {k}: {key} {replayed.get(key)!r}, log {logged.get(key)!r}")
    verdicts = [_evidence_verdicts(e) for e in (logged, replayed)]
    if verdicts[0] != verdicts[1]:
        out.append(f"step {k}: end evidence {verdicts[1]!r}, log {verdicts[0]!r}")
    a, b = logged.get("planned_pose"), replayed.get("planned_pose")
    if (a is None) != (b is None):
        out.append(f"step {k}: planned pose {b!r:.60}, log {a!r:.60}")
    elif a is not None and not _same_pose(pose_from_dict(a), pose_from_dict(b)):
        out.append(
            f"step {k}: planned pose {_pose_text(pose_from_dict(b))}, "
            f"log {_pose_text(pose_from_dict(a))}"
        )
    executed = logged.get("executed_pose")
    if executed is not None and not _same_pose(pose_from_dict(executed), frame.T_base_cam):
        out.append(
            f"step {k}: the recording's camera pose {_pose_text(frame.T_base_cam)} differs from "
            f"the one the planner saw {_pose_text(pose_from_dict(executed))}"
        )
    return out


def _evidence_verdicts(entry: Mapping[str, Any]) -> list[tuple[Any, ...]]:
    """(direction, observed, frame, how) of each end-evidence check of a log entry."""
    return [
        (e.get("direction"), e.get("observed"), e.get("frame"), e.get("how"))
        for e in entry.get("end_evidence", [])
    ]


# --------------------------------------------------------------------------- what-if


def what_if(
    recording: str | os.PathLike[str],
    *,
    config: ScrapcutConfig,
    start_frame: int | None = None,
    match_distance_m: float = 0.10,
    match_angle_deg: float = 30.0,
    progress: ProgressFn | None = None,
) -> ExplorationRun:
    """Run the planner (``config.exploration``, any method) over a recording's frames.

    Parameters
    ----------
    recording : path
        Any recording with frames; a dense one (``survey``) answers most views.
    config : ScrapcutConfig
        The planner's parameters to try, perception, stitching and fitting.
    start_frame : int, optional
        Index of the frame to start from (the worker's initial segment); default the frame
        showing the most paint.
    match_distance_m, match_angle_deg : float
        How far a recorded frame may be from a planned view and still answer it
        (:class:`NearestView`).
    progress : callable, optional
        ``progress(done, total)`` while perceiving the frames, then per decision.

    Raises
    ------
    ExplorationError
        A planner parameter out of range (before any frame is read), no usable frames, no
        paint in any, or ``start_frame`` out of range.
    """
    from scrapcut_cli.pipeline.fit import paint_for_recording
    from scrapcut_cli.recording.reader import open_recording

    path = Path(recording)
    check_exploration_config(config)  # before minutes of perceiving every frame
    library: list[Observation] = []
    from scrapcut_cli.calibration.recipe import camera_mount_for

    mount, _ = camera_mount_for(path, config)
    with open_recording(path, config.recording, mount=mount) as rec:
        hsv, _ = paint_for_recording(rec, config)
        total = rec.plan().usable
        last: FloatArray | None = None
        for done, frame in enumerate(rec.frames(), start=1):
            if last is None or not _same_pose(frame.T_base_cam, last, SAME_POSE_M, SAME_POSE_RAD):
                library.append(perceive(frame, hsv, config))
                last = frame.T_base_cam
            if progress is not None:
                progress(done, total)
    if not library:
        raise ExplorationError(f"{path} has no usable frames to explore")
    paint = np.array([len(o.clouds.paint_base) for o in library])
    if start_frame is None:
        start = int(np.argmax(paint))
        if paint[start] == 0:
            raise ExplorationError(f"no frame of {path} shows paint of {hsv.describe()}")
    else:
        matches = [i for i, o in enumerate(library) if o.frame_index == start_frame]
        if not matches:
            raise ExplorationError(
                f"start frame {start_frame} is not among the {total} frames of {path} "
                "(or repeats the pose of the frame before it)"
            )
        start = matches[0]
    answers = NearestView(
        np.array([o.T_base_cam for o in library]),
        match_distance_m=match_distance_m,
        match_angle_deg=match_angle_deg,
    )
    planner = ExplorationPlanner(
        library[start].T_base_cam, reachable=answers, hsv=hsv, config=config
    )
    decision = planner.start()
    requested = decision.T_base_cam
    steps: list[ReplayStep] = []
    while not decision.stop:
        assert decision.T_base_cam is not None
        pick = answers.nearest(decision.T_base_cam)
        if pick is None:  # only the initial view is planned without asking
            raise ExplorationError("no recorded frame answers the initial view")
        observation = library[pick]
        decision = planner.observe_perceived(observation)
        steps.append(_step(decision.info, observation, requested, decision.T_base_cam, []))
        requested = decision.T_base_cam
        if progress is not None:
            progress(len(steps), max(len(steps), config.exploration.max_steps))
    options = {
        "match_distance_m": match_distance_m,
        "match_angle_deg": match_angle_deg,
        "start_frame": library[start].frame_index,
    }
    return _finish(
        "what_if",
        path,
        planner,
        steps,
        [],
        config=planner.config,
        frames_available=len(library),
        extra=options,
    )


# --------------------------------------------------------------------------- shared


def _step(
    info: Mapping[str, Any],
    frame: Frame | Observation,
    requested: FloatArray | None,
    planned: FloatArray | None,
    divergences: Sequence[str],
) -> ReplayStep:
    index = frame.index if isinstance(frame, Frame) else frame.frame_index
    return ReplayStep(
        k=int(info["k"]),
        frame_index=int(index),
        stamp_ns=int(frame.stamp_ns),
        growth=int(info["growth"]),
        size=int(info["size"]),
        endpoints_found=int(info["endpoints_found"]),
        action=str(info["action"]),
        reason=str(info["reason"]),
        requested=None if requested is None else np.asarray(requested, dtype=np.float64),
        executed=np.asarray(frame.T_base_cam, dtype=np.float64).copy(),
        planned=None if planned is None else np.asarray(planned, dtype=np.float64),
        queries=len(info.get("reachability", [])),
        divergences=tuple(divergences),
    )


def _finish(
    mode: str,
    path: Path,
    planner: ExplorationPlanner,
    steps: list[ReplayStep],
    divergences: list[str],
    *,
    config: ScrapcutConfig,
    frames_available: int,
    extra: dict[str, Any] | None = None,
    stop_reason: str | None = None,
) -> ExplorationRun:
    """The run, with the planner's stitched clouds for the global fit."""
    from scrapcut_cli.exploration.planner import planner_config_dict

    st = planner.stitcher
    paint = st.paint_points
    stitch = StitchResult(
        paint_points=paint,
        paint_viewpoints=st.paint_viewpoints,
        surface_points=st.surface_points,
        surface_viewpoints=st.surface_viewpoints,
        steps=list(st.steps),
        tally=planner.tally,
        hsv=planner.hsv,
        base_frame=planner.base_frame,
        paint_rgb=st.paint_rgb,
        other_points=st.other_points,
        other_rgb=st.other_rgb,
        **st.kept_clouds(),
    )
    settings = planner_config_dict(config)
    if extra:
        settings["what_if"] = extra
    return ExplorationRun(
        mode=mode,
        source=str(path),
        method=planner.method,
        steps=steps,
        stop_reason=planner.stop_reason if stop_reason is None else stop_reason,
        ends=[dict(e) for e in planner.ends],
        divergences=divergences,
        paint_points=paint,
        config=settings,
        timings=list(planner.timings),
        frames_available=frames_available,
        stitch=stitch,
        settings=config,
    )


def _same_pose(
    a: ArrayLike,
    b: ArrayLike,
    tolerance_m: float = POSE_TOLERANCE_M,
    tolerance_rad: float = POSE_TOLERANCE_RAD,
) -> bool:
    A = np.asarray(a, dtype=np.float64)
    B = np.asarray(b, dtype=np.float64)
    if float(np.linalg.norm(A[:3, 3] - B[:3, 3])) > tolerance_m:
        return False
    return rotation_angle(A[:3, :3], B[:3, :3]) <= tolerance_rad


def _pose_text(T: ArrayLike) -> str:
    M = np.asarray(T, dtype=np.float64)
    x, y, z = (1000.0 * M[:3, 3]).tolist()
    a, b, c = M[:3, 2].tolist()
    return f"({x:.1f}, {y:.1f}, {z:.1f}) mm looking ({a:.3f}, {b:.3f}, {c:.3f})"
