"""Algorithm 1: scan the painted line segment by segment, extrapolating the fitted curve.

:class:`ExplorationPlanner` implements :class:`~scrapcut_cli.cell.ViewPlanner` (the planner
contract with the robot cell).
It is pure and deterministic — no pybullet, no files, no printing, no clock in its decisions —
so the same frames and the same reachability answers give the same decisions, which is what
``scrapcut explore`` checks on a recording. Each :meth:`~ExplorationPlanner.observe`:

1. perceives the frame with perception's recipe (paint and surface clouds) and adds it to a
   :class:`~scrapcut_cli.perception.stitch.Stitcher`; its depth goes into the planner's own
   occupancy map (:mod:`~scrapcut_cli.exploration.occupancy`; never the true mesh);
2. measures growth(k): the frame's paint voxels farther than ``novelty_m`` from the cloud stitched
   before it. The paper compares raw sizes, size(k) − size(k−1), but re-observing known paint
   with a D435i adds hundreds of 2 mm voxels (depth noise thickens the band), so the raw count
   never falls to a small δ; the novelty count is ~0 on re-observation and hundreds on new paint.
   ``size`` is the running sum of growth;
3. fits the curve (``nurbs`` or ``skeleton``) to the stitched paint around the frontier, thinned
   to ``fit_voxel_m``, and extrapolates from the end being explored (``fitting.extrapolate_end``:
   two points near the NURBS end, or the last two skeleton vertices; the curve's last 2 cm when
   those two points turn away from it, as at a thinning fork). When that fit fails at every
   skeleton leaf (paint that is not the line in view: a crate of the paint's colour, overspray
   on rust), it is fitted to the marked line alone, picked among the stitched paint's
   candidates with the sight lines so far as ``fit`` does
   (:mod:`~scrapcut_cli.perception.candidates`);
4. chooses the next view: the target ``step_m`` beyond the curve's end (on a wall rising across
   the line's way, if the occupancy map shows one; then half a step, then the tip itself if no
   view of the farther target is feasible: the paper's conservative move towards the edge); the
   optical axis along the inverse surface normal there (observed surface, raised to
   ``min_elevation_deg``); the distance from ``min_distance_m`` upward and the roll about the
   axis searched until the camera and hand clear the occupancy map, the target and the known
   tip are in sight and deep enough for the camera, and the cell's ``reachable`` says yes (its
   IK, limits and collision model of what its camera observed; never the true piece). Only if
   the normal gives no view are the last viewing direction, straight down and then the surface's
   other side (``other_side_views``: a mesh or a sheet seen from behind) tried.

Stopping on a closed line (a ring round a pipe, a cut-out): after every view that found new
paint the stitched paint is checked for closure (:mod:`~scrapcut_cli.fitting.closure`); when the
line being followed has run into the paint seen from the other direction, the run stops
(``loop_closed``). When the second direction ends (no growth, no feasible view) and the paint
closes through an arc no frame saw (both ends unobserved, facing each other along one arc),
the run stops with ``unobserved_arc``. The final log entry carries the closure (``loop``).

Stopping: growth(k) <= ``delta_size`` ends a direction. Before declaring an endpoint there, the
planner checks that the observed surface goes on past the curve's end in a fan of directions (a
paint end on a continuing surface is a real end) and that the curve does not turn sharply there;
otherwise the line may go on behind an edge (the paper's slanted piece) and it looks once more,
from a view tilted about the edge (``look_past_angles_deg``). If that finds no paint either and
no frame so far has observed the end (the space past the tip is unknown, not free), it looks
once from over the known line (``look_back``: a wall rising at a concave corner shows its
painted side only from there). A next target within
``revisit_radius_m`` of a visited one also ends the direction (the paper's log of visited
positions; it counts as an endpoint). After the first end the camera returns to the initial view
and explores the other direction; the second end stops the run ("done"). A run also stops, with
the reason, on the step budget; a direction also ends when no view is feasible, the paint is
lost or the fit fails. The paint counts as lost only from over the tip: when a view past it saw
no paint at all (a crate or a cone beside the piece may fill the view, or the view looked past
the piece's edge), the tip itself is looked at once first (``view_axis`` ``tip``). When no
view past an end is feasible, the end still counts as an endpoint if a frame taken so far
observed it (``observed_end``, :mod:`~scrapcut_cli.exploration.evidence`: the tip well inside
that image and the depth past it showing bare surface, or the surface ending in sight, not the
image border or an occluding edge); the evidence, for or against, is logged with the step
(``end_evidence``) and the end's entry names the frame (``observed_by``). Otherwise the
direction ends with ``no_feasible_view``.

Calibration views (``calibration_views`` > 0): once both directions are done, the planner
visits that many views of the initial stretch of paint, tilted round its normal by
``calibration_tilt_deg`` and rolled (:mod:`.calibration_views`), before it stops; their log
entries have the reason ``calibration``, and ``scrapcut calibrate`` reports what they added.

Every decision carries its log entry (``Decision.info``, JSON-ready): k, frame, growth, size,
endpoints found, the executed pose (the frame's) and the planned one, the reason, and every
reachability query with its answer, so a replay can answer them without the simulator.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli import __version__
from scrapcut_cli.cell import (
    Decision,
    PlannerContext,
    PlannerFactory,
    Reachability,
    ReachQuery,
    ViewPlanner,
)
from scrapcut_cli.config import FitMethod, ScrapcutConfig, SkeletonConfig, choice_names
from scrapcut_cli.errors import ExplorationError, FittingError, PerceptionError
from scrapcut_cli.exploration.calibration_views import CALIBRATION_REASON, calibration_view_poses
from scrapcut_cli.exploration.evidence import DepthView, EndEvidence, depth_view, end_evidence
from scrapcut_cli.exploration.occupancy import OccupancyMap, depth_points
from scrapcut_cli.exploration.views import (
    UP,
    search_distances,
    search_rolls,
    tilt_about_edge,
    tilt_up,
    unit,
    view_pose,
)
from scrapcut_cli.fitting import detect_closure, extrapolate_end, fit_curve
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.geometry import (
    PolylineDistance,
    cumulative_length,
    interpolate_polyline,
    matrix_to_quat_xyzw,
    orient_over_edge,
    pack_voxel_keys,
    sight_cosines,
    transform_from_pose,
    voxel_keys,
)
from scrapcut_cli.perception.cloud import FrameClouds, PerceptionTally, process_frame
from scrapcut_cli.perception.paint import HsvRange
from scrapcut_cli.perception.stitch import Stitcher
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.toolpath.normals import estimate_normals

FloatArray = NDArray[np.float64]

METHODS = choice_names(FitMethod)
#: Log schema of /scrapcut/exploration entries written from :attr:`Decision.info`.
LOG_SCHEMA = "scrapcut.exploration/v1"
#: Keep the line of sight this far short of the target: the surface it lies on is occupied.
SIGHT_MARGIN_M = 0.04
#: Fewer observed surface points than this within the radius: no normal there.
MIN_NORMAL_POINTS = 8
#: The skeleton's leaf sizes tried when the local fit breaks into pieces (the paper's fix for
#: the basket was a 2 cm leaf).
SKELETON_RETRY_LEAVES_M = (0.01, 0.02, 0.04)
#: A direction ends at an endpoint when growth stops there or the next target was explored
#: already (the paper's log of visited positions).
ENDPOINT_REASONS = ("endpoint", "revisit")
#: A run on a closed line stops when its two directions meet (the paint goes all round), or
#: when both ended where no view reached further and the line closes across what no frame saw.
LOOP_CLOSED, UNOBSERVED_ARC = "loop_closed", "unobserved_arc"
#: Targets tried beyond a curve's end, in steps: a full one, half, the tip itself.
STEP_FRACTIONS = (1.0, 0.5, 0.0)
#: A wall across the line's way: observed cells this high above the surface's plane at the tip
#: (and below the second height), from a little behind the tip (the wall beside the corner is
#: often all that was seen of it) to a step ahead, within the half width of the line.
WALL_LIFT_M = 0.02
WALL_HEIGHT_M = 0.10
WALL_BEHIND_M = 0.02
WALL_HALF_WIDTH_M = 0.05
#: A fallback viewing direction within ~15 degrees of the normal adds nothing.
FALLBACK_COS = float(np.cos(np.radians(15.0)))
#: A surface counts as seen from in front when the median sight line of the cameras that saw
#: it lies within 45 degrees of its normal; and two normals this close lie in one plane.
FRONT_COS = float(np.cos(np.radians(45.0)))
#: Offsets along a normal within this are in its plane when orienting a normal over an edge (a
#: mesh's layers, a surface's noise).
ORIENT_MARGIN_M = 0.012
#: The local fit window grows up to this radius while the end it finds lies at its rim.
FIT_MAX_RADIUS_M = 0.5
#: The skeleton's local fit thins the paint to at most this share of its leaf size.
SKELETON_THINNING = 0.8
#: Directions past a paint end (degrees from the line's, about the surface normal) in which
#: the surface must go on for the end to be confirmed.
FAN_DEG = (0.0, 30.0, -30.0, 60.0, -60.0)
#: Chord over the curve's last centimetres checked against the model's end direction.
END_CHORD_M = 0.02
#: A curve shorter than this has no meaningful turn near its end.
TURN_SPAN_M = 0.05


class ReachLog(TypedDict):
    """One reachability query as the log keeps it (``reachability`` of a step): the asked camera
    pose (metres, xyzw, base frame) and the cell's answer (``ReachAnswer.describe()``)."""

    position: list[float]
    orientation_xyzw: list[float]
    ok: bool
    reason: str


@dataclass(frozen=True, eq=False)
class Observation:
    """One frame as the planner uses it (what a replay can keep for every frame of a survey).

    Attributes
    ----------
    frame_index, stamp_ns : int
        The frame's position in the recording and its image stamp.
    T_base_cam : (4, 4) float64
        The executed camera pose (optical frame, base frame).
    clouds : FrameClouds
        Paint and surface clouds, metres, base frame (perception's recipe).
    obstacles_base : (M, 3) float64
        Observed depth points for the occupancy map, metres, base frame.
    base_frame : str
        TF frame of every coordinate.
    depth : DepthView or None
        The frame's pose, camera and strided usable depth, kept to tell later whether it
        observed a line's end (:mod:`~scrapcut_cli.exploration.evidence`); None: not kept.
    """

    frame_index: int
    stamp_ns: int
    T_base_cam: FloatArray
    clouds: FrameClouds
    obstacles_base: FloatArray
    base_frame: str = "panda_link0"
    depth: DepthView | None = None


def perceive(frame: Frame, hsv: HsvRange, config: ScrapcutConfig) -> Observation:
    """Perception's clouds and the occupancy points of one frame (see :class:`Observation`)."""
    clouds = process_frame(frame, hsv, config.perception)
    p = config.perception
    obstacles = depth_points(
        frame,
        voxel_size_m=config.exploration.occupancy_voxel_m,
        near_m=config.exploration.min_distance_m,
        min_depth_m=p.min_depth_m,
        max_depth_m=p.max_depth_m,
        flying_pixel_ratio=p.flying_pixel_ratio,
    )
    kept = None
    if config.exploration.observed_end:
        kept = depth_view(
            frame,
            min_depth_m=p.min_depth_m,
            max_depth_m=p.max_depth_m,
            flying_pixel_ratio=p.flying_pixel_ratio,
        )
    return Observation(
        frame_index=frame.index,
        stamp_ns=frame.stamp_ns,
        T_base_cam=np.asarray(frame.T_base_cam, dtype=np.float64).copy(),
        clouds=clouds,
        obstacles_base=obstacles,
        base_frame=frame.base_frame,
        depth=kept,
    )


def pose_to_dict(T: ArrayLike) -> dict[str, list[float]]:
    """``{"position": [x, y, z], "orientation_xyzw": [qx, qy, qz, qw]}`` of a (4, 4) pose."""
    M = np.asarray(T, dtype=np.float64)
    return {
        "position": [float(v) for v in M[:3, 3]],
        "orientation_xyzw": [float(v) for v in matrix_to_quat_xyzw(M[:3, :3])],
    }


def pose_from_dict(data: Any) -> FloatArray:
    """The (4, 4) pose of a :func:`pose_to_dict` dictionary (ExplorationError if malformed)."""
    try:
        position = np.asarray(data["position"], dtype=np.float64).reshape(3)
        quat = np.asarray(data["orientation_xyzw"], dtype=np.float64).reshape(4)
    except (KeyError, TypeError, ValueError):
        raise ExplorationError(f"malformed pose in the exploration log: {data!r:.80}") from None
    norm = float(np.linalg.norm(quat))
    if not (np.isfinite(position).all() and np.isfinite(norm) and norm > 1e-9):
        raise ExplorationError(f"malformed pose in the exploration log: {data!r:.80}")
    return transform_from_pose(position, quat / norm)


def check_exploration_config(config: ScrapcutConfig) -> None:
    """Raise :class:`ExplorationError` naming the first exploration parameter out of range."""
    c = config.exploration
    if c.method not in METHODS:
        raise ExplorationError(
            f"unknown exploration.method {c.method!r}; known: {', '.join(METHODS)}"
        )
    positive = {
        "step_m": c.step_m,
        "min_distance_m": c.min_distance_m,
        "distance_step_m": c.distance_step_m,
        "max_steps": c.max_steps,
        "novelty_m": c.novelty_m,
        "fit_voxel_m": c.fit_voxel_m,
        "normal_radius_m": c.normal_radius_m,
        "roll_step_deg": c.roll_step_deg,
        "occupancy_voxel_m": c.occupancy_voxel_m,
        "edge_probe_m": c.edge_probe_m,
        "observed_end_window_m": c.observed_end_window_m,
        "observed_end_tolerance_m": c.observed_end_tolerance_m,
    }
    for name, value in positive.items():
        if not (np.isfinite(value) and value > 0):
            raise ExplorationError(f"exploration.{name} must be a finite number > 0, got {value}")
    non_negative = {
        "delta_size": c.delta_size,
        "fit_margin_m": c.fit_margin_m,
        "revisit_radius_m": c.revisit_radius_m,
        "inflation_m": c.inflation_m,
        "body_front_m": c.body_front_m,
        "body_back_m": c.body_back_m,
        "body_radius_m": c.body_radius_m,
    }
    for name, value in non_negative.items():
        if not (np.isfinite(value) and value >= 0):
            raise ExplorationError(f"exploration.{name} must be a finite number >= 0, got {value}")
    if c.max_distance_m < c.min_distance_m:
        raise ExplorationError(
            f"exploration.max_distance_m ({c.max_distance_m}) is below min_distance_m "
            f"({c.min_distance_m})"
        )
    if not 0 <= c.observed_end_margin < 0.5:
        raise ExplorationError(
            f"exploration.observed_end_margin must be within [0, 0.5), got {c.observed_end_margin}"
        )
    if c.roll_step_deg > 180:
        raise ExplorationError(f"exploration.roll_step_deg must be <= 180, got {c.roll_step_deg}")
    if not 0 <= c.min_elevation_deg < 90:
        raise ExplorationError(
            f"exploration.min_elevation_deg must be within 0-90, got {c.min_elevation_deg}"
        )
    if not 0 < c.turn_angle_deg <= 180:
        raise ExplorationError(
            f"exploration.turn_angle_deg must be within (0, 180], got {c.turn_angle_deg}"
        )
    if any(not 0 < a <= 135 for a in c.look_past_angles_deg):
        raise ExplorationError(
            f"exploration.look_past_angles_deg must be within (0, 135], got "
            f"{list(c.look_past_angles_deg)}"
        )


@dataclass(frozen=True)
class _End:
    """An end of the fitted curve: the tip (3,), metres, base frame; the unit direction out of
    it (3,); and how sharply the curve turns over its last few centimetres, degrees."""

    tip: FloatArray
    direction: FloatArray
    turn_deg: float
    source: str = "model"  # where the direction came from: "model" (the paper's) or "chord"


@dataclass(frozen=True)
class StepTiming:
    """Wall time of one observe in milliseconds (kept out of the log: logs are deterministic).

    ``reachability`` is the time spent in the ``reachable`` callback (the simulator's IK), which
    ``planner`` excludes.
    """

    perception: float
    stitch: float
    fit: float
    plan: float
    reachability: float

    @property
    def planner(self) -> float:
        """Everything but perception and the reachability callback."""
        return self.stitch + self.fit + self.plan

    @property
    def total(self) -> float:
        return self.perception + self.planner + self.reachability


class ExplorationPlanner:
    """Algorithm 1's next-view planner (see the module docstring).

    Attributes of a run: ``stitcher`` (the stitched clouds), ``tally`` (perception counts),
    ``occupancy``, ``log`` (one entry per observed frame), ``timings``, ``ends``,
    ``endpoints_found``, ``stop_reason``.

    Parameters
    ----------
    initial_view : (4, 4) float64
        ``T_base_cam`` of the first view, with the initial segment of the line in it (the
        worker's pointing). The camera returns here after the first endpoint.
    reachable : Reachability
        ``reachable(ReachQuery) -> ReachAnswer`` (:mod:`scrapcut_cli.cell`): can the robot
        place the camera exactly there, from where it is, without collision (the cell's IK and
        collision model, or recorded answers in replay).
    hsv : HsvRange
        The paint's colour range.
    config : ScrapcutConfig
        ``exploration`` (the method and every planner parameter), ``perception``, ``stitch``
        and the fitter's section.
    """

    def __init__(
        self,
        initial_view: ArrayLike,
        *,
        reachable: Reachability,
        hsv: HsvRange,
        config: ScrapcutConfig | None = None,
    ) -> None:
        self.config = config if config is not None else ScrapcutConfig()
        check_exploration_config(self.config)
        T0 = np.asarray(initial_view, dtype=np.float64)
        if T0.shape != (4, 4) or not np.all(np.isfinite(T0)):
            raise ExplorationError("the initial view must be a finite (4, 4) camera pose")
        self.initial_view = T0.copy()
        self.hsv = hsv
        self._reachable = reachable
        c = self.config.exploration
        self.method = c.method
        self._distances = search_distances(c.min_distance_m, c.max_distance_m, c.distance_step_m)
        self._rolls = search_rolls(c.roll_step_deg)
        self.stitcher = Stitcher(self.config.stitch, perception=self.config.perception)
        self.tally = PerceptionTally(hsv)
        self.base_frame = ""
        self.occupancy = OccupancyMap(c.occupancy_voxel_m)
        self.log: list[dict[str, Any]] = []
        self.timings: list[StepTiming] = []
        self.size = 0
        self.endpoints_found = 0
        self.ends: list[dict[str, Any]] = []
        self.finished = False
        self.stop_reason: str | None = None
        self.loop: dict[str, Any] | None = None  # the closure found when the run stopped on it
        self._k = 0
        self._pending = "initial"  # what the last decision asked for
        self._direction = 0
        self._initial_ends: list[_End] = []
        self._frontier: _End | None = None
        self._looked_back = False  # the frontier's end was looked at from over the line
        self._step_fraction = 0.0  # of the step past the frontier the last view went
        # This direction's last tip whose surface the cameras saw from in front, and its normal.
        self._front: tuple[FloatArray, FloatArray] | None = None
        self._initial_front: tuple[FloatArray, FloatArray] | None = None
        # (stitched frames, the selected line's paint or None, why none) of the last selection.
        self._line_cache: tuple[int, FloatArray | None, str | None] | None = None
        self._visited: list[FloatArray] = []
        self._queries: list[ReachLog] = []
        self._reach_s = 0.0
        self._fit_note: dict[str, Any] = {}
        self._look_note: dict[str, Any] = {}
        self._fit_s = 0.0
        self._last_pose = self.initial_view.copy()
        self._surface_cache: tuple[FloatArray, FloatArray] | None = None
        self._depth_views: list[DepthView] = []
        self._depth_steps: list[int] = []
        self._evidence_notes: list[dict[str, Any]] = []
        self._final_reason = "done"
        self._calibration_target = np.zeros(3)
        self._calibration_poses: list[FloatArray] = []

    @property
    def total(self) -> int:
        """The most views this run can take (the step budget): the recorder's progress total."""
        return int(self.config.exploration.max_steps)

    # ------------------------------------------------------------------ the contract

    def start(self) -> Decision:
        """The initial view."""
        self._pending = "initial"
        return Decision(self.initial_view.copy(), "initial", info={"action": "initial"})

    def observe(self, frame: Frame) -> Decision:
        """Take the frame captured at the last decided pose; return the next decision."""
        t0 = time.perf_counter()
        observation = perceive(frame, self.hsv, self.config)
        return self.observe_perceived(observation, perception_ms=1e3 * (time.perf_counter() - t0))

    def observe_perceived(
        self, observation: Observation, *, perception_ms: float = 0.0
    ) -> Decision:
        """:meth:`observe` for a frame already perceived (what-if replays cache them)."""
        if self.finished:
            raise ExplorationError(
                f"the planner already stopped ({self.stop_reason}); start a new one to go on"
            )
        t0 = time.perf_counter()
        obs = observation
        growth = self._novel_growth(obs.clouds.paint_base)
        step = self.stitcher.add(obs.clouds, T_base_cam=obs.T_base_cam)
        self.tally.add(obs.clouds)
        self.base_frame = obs.base_frame
        self.occupancy.add(obs.obstacles_base)
        self._surface_cache = None
        self._last_pose = obs.T_base_cam
        self.size += growth
        k = self._k
        self._k += 1
        if obs.depth is not None:
            self._depth_views.append(obs.depth)
            self._depth_steps.append(k)
        self._evidence_notes = []
        self._queries = []
        self._reach_s = 0.0
        self._fit_note = {}
        self._look_note = {}
        self._fit_s = 0.0
        t1 = time.perf_counter()
        pending = self._pending
        decision = self._decide(obs, growth)
        t2 = time.perf_counter()
        info: dict[str, Any] = {
            "schema": LOG_SCHEMA,
            "k": k,
            "frame": obs.frame_index,
            "frame_stamp_ns": obs.stamp_ns,
            "observed": pending,
            "growth": growth,
            "size": self.size,
            "stitched_size": step.size,
            "stitched_growth": step.growth,
            "frame_paint_points": len(obs.clouds.paint_base),
            "paint_skip": obs.clouds.skip_reason,
            "endpoints_found": self.endpoints_found,
            "direction": self._direction,
            "executed_pose": pose_to_dict(obs.T_base_cam),
            # The exact matrix the decision was computed from: a replay uses it (after checking
            # it against the recording's /tf), so ~1e-16 differences from re-composing the TF
            # chain cannot flip a voxel and change a decision.
            "executed_T": [[float(v) for v in row] for row in obs.T_base_cam[:3]],
            "planned_pose": None
            if decision.T_base_cam is None
            else pose_to_dict(decision.T_base_cam),
            "action": decision.info.get("action", "stop"),
            "reason": decision.reason,
            "stop": decision.stop,
            "reachability": list(self._queries),
        }
        frontier = decision.info.get("end")
        if frontier is not None:
            info["end"] = frontier
        if "view_axis" in decision.info:
            info["view_axis"] = decision.info["view_axis"]
        if self._fit_note:
            info["fit"] = dict(self._fit_note)
        if self._look_note:
            info["look_past"] = dict(self._look_note)
        if self._evidence_notes:
            info["end_evidence"] = [dict(e) for e in self._evidence_notes]
        if decision.stop:
            info["ends"] = [dict(e) for e in self.ends]
            if self.loop is not None:
                info["loop"] = dict(self.loop)
        if k == 0:
            info["tool_version"] = __version__
            info["initial_view"] = pose_to_dict(self.initial_view)
            info["method"] = self.method
            info["paint_hsv"] = dataclasses.asdict(self.hsv)
            info["config"] = planner_config_dict(self.config)
        self.log.append(info)
        plan_s = t2 - t1 - self._fit_s - self._reach_s
        self.timings.append(
            StepTiming(
                perception=perception_ms,
                stitch=1e3 * (t1 - t0),
                fit=1e3 * self._fit_s,
                plan=1e3 * plan_s,
                reachability=1e3 * self._reach_s,
            )
        )
        return Decision(decision.T_base_cam, decision.reason, decision.stop, info)

    # ------------------------------------------------------------------ decisions

    def _decide(self, obs: Observation, growth: int) -> Decision:
        c = self.config.exploration
        if self._k >= c.max_steps:
            return self._stop("budget")
        pending = self._pending
        if pending == "initial":
            if obs.clouds.skipped:
                return self._stop("paint_lost")
            seen = obs.clouds.paint_base
            centre = np.median(seen, axis=0)
            radius = float(np.max(np.linalg.norm(seen - centre, axis=1))) + c.fit_margin_m
            curve = self._local_fit(centre, radius)
            if curve is None:
                return self._stop("fit_failed")
            # Both directions set out from the first view's paint, seen from in front (usually).
            normal, where, front = self._surface_normal(centre, centre)
            if front and where is not None:
                self._initial_front = self._front = (where, normal)
            self._initial_ends = [self._end_of(curve, "end"), self._end_of(curve, "start")]
            self._direction = 0
            return self._advance(self._initial_ends[0])
        if pending == CALIBRATION_REASON:
            return self._next_calibration_view()
        if pending == "return":
            end = self._extend(self._initial_ends[1], obs)
            return self._advance(self._initial_ends[1] if end is None else end)
        # pending is "extrapolate" or "look_past": the view looked beyond the frontier.
        if growth > c.delta_size and self._closes_loop(gap=False):
            # The line ran into the paint explored from the other side: a loop, closed.
            return self._finish(LOOP_CLOSED)
        if obs.clouds.skipped:
            tip = self._view_tip() if pending == "extrapolate" else None
            return tip if tip is not None else self._end_direction("paint_lost")
        if growth <= c.delta_size:
            look = None
            if pending == "extrapolate" and c.look_past:
                look = self._look_past()
            elif pending == "look_past":
                look = self._look_back()
            return look if look is not None else self._end_direction("endpoint")
        assert self._frontier is not None
        end = self._extend(self._frontier, obs)
        if end is None:
            return self._end_direction("fit_failed")
        return self._advance(end)

    def _extend(self, frontier: _End, obs: Observation) -> _End | None:
        """The end of the line past ``frontier`` in the stitched paint, or None if no fit.

        The fit window is centred on the frontier's tip and holds all of this frame's paint plus
        ``fit_margin_m``; when the end found lies at the window's rim (paint seen earlier goes
        on beyond it) the window grows, up to :data:`FIT_MAX_RADIUS_M`. Otherwise a view
        centred past a cut end would see only known paint and stop with a false endpoint.
        """
        c = self.config.exploration
        centre = frontier.tip
        seen = obs.clouds.paint_base
        extent = float(np.max(np.linalg.norm(seen - centre, axis=1))) if len(seen) else 0.0
        radius = min(extent + c.fit_margin_m, FIT_MAX_RADIUS_M)
        while True:
            curve = self._local_fit(centre, radius)
            if curve is None:
                return None
            end = self._end_of(curve, self._following(curve, frontier))
            at_rim = float(np.linalg.norm(end.tip - centre)) > radius - 0.5 * c.fit_margin_m
            if not at_rim or radius >= FIT_MAX_RADIUS_M:
                return end
            radius = min(FIT_MAX_RADIUS_M, 1.5 * radius)

    def _advance(self, end: _End) -> Decision:
        """Plan the view past ``end``, or end the direction if there is none.

        The target is ``step_m`` beyond the tip; when no view of it is feasible (it may lie past
        the piece's edge, under the floor) half a step and the tip itself are tried: moving
        towards the fitted curve's edge is the paper's conservative estimate. The optical axis
        is the inverse surface normal there. Where observed surface rises across the line's way
        (a concave corner: the line runs into a flange), the first target is half a step up
        that wall, seen from over the known line (the corner's bisector). Only when no target
        can be seen along its normal are the camera's last viewing direction, straight down and
        the surface's other side tried (a wire mesh seen from inside has its normal pointing
        inwards, where the hand does not fit; from outside it is open). With no view at all,
        the end counts if an earlier frame observed it (:meth:`_observed_end`), else the
        direction ends with ``no_feasible_view``.
        """
        c = self.config.exploration
        self._frontier = end
        self._looked_back = False
        normal, where, front = self._surface_normal(end.tip, end.tip)
        if front and where is not None:
            self._front = (where, normal)  # this direction's last tip seen from in front
        tip_normal = self._outward(normal, where, front)
        candidates: list[tuple[float, FloatArray, FloatArray]] = []
        if self._rises_ahead(end, tip_normal):
            wall_target = end.tip + 0.5 * c.step_m * tip_normal
            candidates.append((0.5, wall_target, tilt_about_edge(tip_normal, -end.direction, 45.0)))
        for fraction in STEP_FRACTIONS:
            target = end.tip + fraction * c.step_m * end.direction
            candidates.append((fraction, target, self._normal_at(target, fallback=end.tip)))
        for tried, (_, target, _) in enumerate(candidates):
            if any(np.linalg.norm(target - v) < c.revisit_radius_m for v in self._visited):
                if tried == 0:
                    return self._end_direction("revisit")
                candidates = candidates[:tried]
                break
        camera_axis = unit(-self._last_pose[:3, 2])
        axes: list[tuple[str, FloatArray | None]] = [
            ("normal", None),
            ("camera", camera_axis),
            ("up", UP),
        ]
        if c.other_side_views:
            axes.append(("other_side", None))
        for axis_name, axis in axes:
            for fraction, target, normal in candidates:
                if axis_name == "other_side":
                    # The normal's sign comes from the cameras that saw the surface; a mesh or
                    # a sheet seen from behind has a free side there. Inside a solid the map or
                    # the robot refuses it. Skipped where the camera and up views were tried.
                    outward = -normal
                    if max(float(outward @ camera_axis), float(outward @ UP)) > FALLBACK_COS:
                        continue
                else:
                    outward = normal if axis is None else axis
                    if axis is not None and float(np.dot(unit(outward), normal)) > FALLBACK_COS:
                        continue  # the same view as the normal's, tried already
                T = self.find_view(target, outward, end.direction, keep_in_view=end.tip)
                if T is not None:
                    self._visited.append(target)
                    self._step_fraction = fraction
                    self._pending = "extrapolate"
                    info = {
                        "action": "extrapolate",
                        "end": _end_dict(end, target, fraction),
                        "view_axis": axis_name,
                    }
                    return Decision(T, "extrapolate", info=info)
        evidence = self._observed_end(end)
        if evidence is not None and evidence.observed:
            return self._end_direction("endpoint", evidence=evidence)
        return self._end_direction("no_feasible_view", evidence=evidence)

    def _view_tip(self) -> Decision | None:
        """After a view past the frontier that saw no paint at all: a view of the frontier's
        tip itself, along the surface normal there, once per frontier; None when the view went
        no farther than the tip, a view of it was taken or none is feasible.

        A frame without paint beyond a tip the fit extrapolated is no evidence of the line's
        end when the view looked past it: the camera may have looked at something standing
        beside the piece (a crate, a cone: closer than the surface, it fills the view) or past
        the piece's edge. From over the tip the camera sees whether the paint goes on.
        """
        c = self.config.exploration
        end = self._frontier
        if end is None or self._step_fraction <= 0.0:
            return None
        self._step_fraction = 0.0
        if any(np.linalg.norm(end.tip - v) < c.revisit_radius_m for v in self._visited):
            return None
        normal = self._normal_at(end.tip, fallback=end.tip)
        T = self.find_view(end.tip, normal, end.direction, keep_in_view=end.tip)
        if T is None:
            return None
        self._visited.append(end.tip)
        self._pending = "extrapolate"
        info = {"action": "extrapolate", "end": _end_dict(end, end.tip, 0.0), "view_axis": "tip"}
        return Decision(T, "extrapolate", info=info)

    def _observed_end(self, end: _End) -> EndEvidence | None:
        """Whether a frame taken so far observed the line's end at ``end`` (None when
        ``observed_end`` is off or no depth was kept): see :mod:`.evidence`."""
        c = self.config.exploration
        if not c.observed_end or not self._depth_views:
            return None
        return end_evidence(
            self._depth_views,
            end.tip,
            end.direction,
            self._normal_at(end.tip, fallback=end.tip),
            probe_m=c.edge_probe_m,
            margin=c.observed_end_margin,
            window_m=c.observed_end_window_m,
            tolerance_m=c.observed_end_tolerance_m,
            steps=self._depth_steps,
        )

    def _rises_ahead(self, end: _End, normal: FloatArray) -> bool:
        """True when observed surface stands above the surface's plane around the tip: more
        than :data:`WALL_LIFT_M` (and less than :data:`WALL_HEIGHT_M`) above it, from
        :data:`WALL_BEHIND_M` behind the tip to a step ahead along the line and within
        :data:`WALL_HALF_WIDTH_M` to either side — a wall the line runs into (a concave corner),
        where a view past the tip would look over the wall."""
        c = self.config.exploration
        reach = float(np.hypot(c.step_m, WALL_HEIGHT_M)) + WALL_HALF_WIDTH_M
        near = self.occupancy.centres_within(end.tip, reach)
        if len(near) == 0:
            return False
        d = end.direction - np.dot(end.direction, normal) * normal
        if np.linalg.norm(d) < 1e-9:
            return False
        d = unit(d)
        side = np.cross(normal, d)
        r = near - end.tip
        along, height, across = r @ d, r @ normal, np.abs(r @ side)
        ahead = (along > -WALL_BEHIND_M) & (along < c.step_m) & (across < WALL_HALF_WIDTH_M)
        return bool(np.any(ahead & (height > WALL_LIFT_M) & (height < WALL_HEIGHT_M)))

    def _end_direction(self, reason: str, *, evidence: EndEvidence | None = None) -> Decision:
        """The direction being explored is finished: return for the other one, or stop.

        ``evidence``: whether an earlier frame observed the end (when no view past it was
        feasible); logged with the step, and named in the end's entry when it counts.
        """
        frontier = self._frontier
        entry: dict[str, Any] = {
            "direction": self._direction,
            "reason": reason,
            "tip": None if frontier is None else [float(v) for v in frontier.tip],
        }
        if evidence is not None:
            self._evidence_notes.append({"direction": self._direction, **evidence.to_dict()})
            if evidence.observed:
                entry["observed_by"] = {
                    "frame": evidence.frame,
                    "k": evidence.k,
                    "how": evidence.how,
                }
        self.ends.append(entry)
        if reason in ENDPOINT_REASONS:
            self.endpoints_found += 1
        if self._direction == 0 and self._closes_loop(gap=False):
            # The first direction came round to where it started (a revisit): paint all
            # round, the loop is closed without going back for the other direction.
            return self._finish(LOOP_CLOSED)
        if self._direction == 1:
            final = "done" if self.endpoints_found == 2 else reason
            if self._closes_loop(gap=True):
                # Both directions ended where no view reached further, facing each other
                # across what no frame saw: a loop with an unobserved arc.
                gap = self.loop is not None and self.loop.get("reason") == "unobserved_gap"
                final = UNOBSERVED_ARC if gap else LOOP_CLOSED
            return self._finish(final)
        self._direction = 1
        self._frontier = self._initial_ends[1]
        self._front = self._initial_front
        if self._pending in ("initial", "return"):
            # Still at the initial view: no need to go back to it.
            return self._advance(self._initial_ends[1])
        self._pending = "return"
        return Decision(self.initial_view.copy(), reason, info={"action": "return"})

    # ------------------------------------------------------------------ calibration views

    def _start_calibration_views(self, final: str) -> Decision:
        """Both directions are done: views of the initial stretch for the self-calibration
        (:mod:`.calibration_views`), then stop with ``final``.

        The target is the stitched paint nearest the initial view's optical axis (seen first,
        so surely paint); the views look at it from the surface normal tilted round it and
        rolled, each at the initial view's distance or the nearest feasible one.
        """
        c = self.config.exploration
        self._final_reason = final
        self._calibration_poses = []
        paint = self.stitcher.paint_points
        if len(paint) == 0:
            return self._stop(final)
        eye, axis = self.initial_view[:3, 3], self.initial_view[:3, 2]
        rel = paint - eye
        off_axis = np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1)
        target = paint[int(np.argmin(off_axis))]
        normal = self._normal_at(target, fallback=target)
        near = paint[np.linalg.norm(paint - target, axis=1) <= 0.03]
        along = self.initial_view[:3, 0]
        if len(near) >= 3:
            _, _, vt = np.linalg.svd(near - near.mean(axis=0), full_matrices=False)
            along = vt[0]
        distance = float(np.clip(np.linalg.norm(target - eye), c.min_distance_m, c.max_distance_m))
        self._calibration_target = target
        self._calibration_poses = calibration_view_poses(
            target,
            normal,
            along,
            count=c.calibration_views,
            distance_m=distance,
            tilt_deg=c.calibration_tilt_deg,
        )
        return self._next_calibration_view()

    def _next_calibration_view(self) -> Decision:
        """The next feasible calibration view (its roll kept if the cell allows), or stop."""
        while self._calibration_poses:
            wanted = self._calibration_poses.pop(0)
            outward = -wanted[:3, 2]
            T = self.find_view(self._calibration_target, outward, wanted[:3, 0])
            if T is not None:
                self._pending = CALIBRATION_REASON
                info = {"action": CALIBRATION_REASON, "left": len(self._calibration_poses)}
                return Decision(T, CALIBRATION_REASON, info=info)
        return self._stop(self._final_reason)

    def _closes_loop(self, *, gap: bool) -> bool:
        """Whether the stitched paint closes on itself (:func:`~scrapcut_cli.fitting.closure.
        detect_closure` with the stitched surface): paint all round, or (``gap``) also through
        an arc no frame saw. The decision is kept in ``loop`` and logged."""
        if self.config.closure.mode == "open" or self.stitcher.size < 8:
            return False
        try:
            closure = detect_closure(
                self.stitcher.paint_points,
                self.stitcher.surface_points,
                config=self.config.closure,
            )
        except FittingError:
            return False
        closed = closure.closed and (gap or closure.reason != "unobserved_gap")
        if closed:
            info = closure.info()
            self.loop = {
                k: info[k] for k in ("reason", "gap_m", "bridge_length_m", "chain_length_m")
            }
        return closed

    def _finish(self, final: str) -> Decision:
        """The line is explored: the calibration views if asked for, then stop with ``final``."""
        if self.config.exploration.calibration_views > 0:
            return self._start_calibration_views(final)
        return self._stop(final)

    def _stop(self, reason: str) -> Decision:
        self.finished = True
        self.stop_reason = reason
        self._pending = "stopped"
        return Decision(None, reason, stop=True, info={"action": "stop"})

    # ------------------------------------------------------------------ look past an edge

    def _look_past(self) -> Decision | None:
        """A view over the edge at the frontier when the end is not confirmed, else None.

        The end is confirmed when the observed surface goes on past the tip in every direction
        of a fan around the line's (:data:`FAN_DEG`, in the surface's plane) and the curve does
        not turn sharply there. Otherwise the camera turns about the edge, towards the first
        direction in which the surface stops (the line's own first), to look past it.
        """
        c = self.config.exploration
        end = self._frontier
        if end is None:
            return None
        normal = self._normal_at(end.tip, fallback=end.tip)
        off = self._surface_stops(end, normal)
        why = []
        if end.turn_deg > c.turn_angle_deg:
            why.append("turn")
        if off:
            why.append("edge")
        self._look_note = {
            "why": why,
            "turn_deg": round(end.turn_deg, 3),
            "surface_stops_deg": [round(a, 1) for a, _ in off],
        }
        if not why:
            return None
        towards = off[0][1] if off else end.direction
        if self._rises_ahead(end, normal):
            # A concave corner: look back at the wall from over the known line.
            towards = -end.direction
            self._look_note["concave"] = True
            self._looked_back = True
        return self._look_towards(end, normal, towards)

    def _look_back(self) -> Decision | None:
        """After a look past the frontier's edge that found no new paint: a view of the end
        from over the known line, when no frame so far has observed the end; else None.

        A look over an edge sees what lies beyond it; a wall rising at the line's end (a
        concave corner, the flange of a beam) shows its painted side only to a camera over the
        line. When the occupancy map showed the wall, the first look came from there already
        (``concave``); when the wall was seen only beside the line or not at all, the space
        past the tip is unknown, not free, and one look back settles it. An end observed
        without paint past it (:mod:`.evidence`: surface, fold, edge) needs no second look.
        """
        c = self.config.exploration
        end = self._frontier
        if end is None or self._looked_back or not c.look_back:
            return None
        evidence = self._observed_end(end)
        if evidence is None or evidence.observed:
            return None
        self._evidence_notes.append({"direction": self._direction, **evidence.to_dict()})
        self._looked_back = True
        normal = self._normal_at(end.tip, fallback=end.tip)
        self._look_note = {"why": ["unobserved"], "concave": True}
        return self._look_towards(end, normal, -end.direction)

    def _look_towards(self, end: _End, normal: FloatArray, towards: FloatArray) -> Decision | None:
        """A view of the tip from the surface normal tilted towards ``towards`` by one of
        ``look_past_angles_deg`` (the first feasible), or None."""
        for angle in self.config.exploration.look_past_angles_deg:
            outward = tilt_about_edge(normal, towards, angle)
            T = self.find_view(end.tip, outward, end.direction)
            if T is not None:
                self._look_note["angle_deg"] = float(angle)
                self._pending = "look_past"
                info = {"action": "look_past", "end": _end_dict(end, end.tip, 0.0)}
                return Decision(T, "look_past", info=info)
        self._look_note["angle_deg"] = None
        return None

    def _surface_stops(self, end: _End, normal: FloatArray) -> list[tuple[float, FloatArray]]:
        """(fan angle in degrees, unit direction (3,)) of the directions past the tip along
        which no observed surface lies ``edge_probe_m`` and two thirds of it away, nearest to
        the line's direction first. Empty: the surface goes on all around the paint's end."""
        c = self.config.exploration
        surface, _ = self._observed_surface()
        near = surface[np.all(np.abs(surface - end.tip) <= 2.0 * c.edge_probe_m, axis=1)]
        d = end.direction - np.dot(end.direction, normal) * normal
        if np.linalg.norm(d) < 1e-9:
            d = end.direction
        d = unit(d)
        side = np.cross(normal, d)
        radius = max(1.5 * self.config.perception.surface_voxel_m, 0.004)
        tree = cKDTree(near) if len(near) else None
        stops = []
        for angle in FAN_DEG:
            a = np.radians(angle)
            direction = np.cos(a) * d + np.sin(a) * side
            probes = end.tip + np.outer([2.0 * c.edge_probe_m / 3.0, c.edge_probe_m], direction)
            if tree is None or not np.all(tree.query(probes)[0] <= radius):
                stops.append((float(angle), np.asarray(direction)))
        return stops

    # ------------------------------------------------------------------ views

    def find_view(
        self,
        target: FloatArray,
        outward: FloatArray,
        x_hint: FloatArray,
        *,
        keep_in_view: FloatArray | None = None,
    ) -> FloatArray | None:
        """The first acceptable view of ``target``, or None.

        Parameters
        ----------
        target : (3,) float64
            Where the optical axis points, metres, base frame.
        outward : (3,) float64
            Direction from the target to the camera (the surface normal there); raised to
            ``min_elevation_deg``.
        x_hint : (3,) float64
            Image x axis before the roll (the line's direction: across the wide image axis).
        keep_in_view : (3,) float64, optional
            A point that must be seen as well (the known tip: the overlap that ties the next
            frame to the stitched cloud).

        Returns
        -------
        (4, 4) float64 or None
            ``T_base_cam`` of the first candidate — distance from ``min_distance_m`` upward in
            ``distance_step_m``, then roll nearest to zero first — whose camera and hand (a
            capsule along the axis) clear the occupancy map by ``inflation_m``, that sees the
            target and ``keep_in_view`` unoccluded and at least ``min_distance_m`` deep, and
            that ``reachable`` accepts. Only candidates passing the map are asked.
        """
        c = self.config.exploration
        out = tilt_up(outward, c.min_elevation_deg)
        clearance = c.body_radius_m + c.inflation_m
        sights = [target] if keep_in_view is None else [target, keep_in_view]
        for distance in self._distances:
            eye = target + distance * out
            front = eye - c.body_front_m * out
            back = eye + c.body_back_m * out
            if not self.occupancy.segment_clear(front, back, clearance):
                continue
            if not all(self._in_sight(eye, out, point) for point in sights):
                continue
            for roll in self._rolls:
                T = view_pose(target, out, x_hint, distance_m=float(distance), roll_rad=float(roll))
                if self._ask(T):
                    return T
        return None

    def _in_sight(self, eye: FloatArray, outward: FloatArray, point: FloatArray) -> bool:
        """``point`` is at least the camera's minimum depth in front of ``eye`` (looking along
        ``-outward``) and no occupied cell lies on the way (short of the surface around it)."""
        ray = point - eye
        length = float(np.linalg.norm(ray))
        if float(np.dot(ray, -outward)) < self.config.exploration.min_distance_m - 1e-9:
            return False
        stop = eye + ray * max(0.0, 1.0 - min(SIGHT_MARGIN_M, 0.5 * length) / length)
        return self.occupancy.segment_clear(eye, stop, 0.0)

    def _ask(self, T: FloatArray) -> bool:
        t0 = time.perf_counter()
        answer = self._reachable(ReachQuery(T))
        self._reach_s += time.perf_counter() - t0
        pose = pose_to_dict(T)
        self._queries.append(
            ReachLog(
                position=pose["position"],
                orientation_xyzw=pose["orientation_xyzw"],
                ok=answer.feasible,
                reason=answer.describe(),
            )
        )
        return answer.feasible

    def _observed_surface(self) -> tuple[FloatArray, FloatArray]:
        """Stitched surface and paint points (N, 3) and their viewpoints (N, 3), base frame;
        stacked once per observed frame."""
        if self._surface_cache is None:
            st = self.stitcher
            self._surface_cache = (
                np.vstack([st.surface_points, st.paint_points]),
                np.vstack([st.surface_viewpoints, st.paint_viewpoints]),
            )
        return self._surface_cache

    def _normal_at(self, point: FloatArray, *, fallback: FloatArray) -> FloatArray:
        """Outward unit normal (3,) of the observed surface at ``point`` (else at ``fallback``,
        else towards the camera of the last frame).

        Its side is the cameras' where they saw the surface there from in front. Where they
        saw it only from behind or at a grazing angle (a wire basket's side wall, seen through
        its top from above), the side comes from the last tip of this direction that was seen
        from in front, over the edge between them (:func:`~scrapcut_cli.geometry.orient_over_edge`:
        the side a closed piece has)."""
        return self._outward(*self._surface_normal(point, fallback))

    def _outward(self, normal: FloatArray, where: FloatArray | None, front: bool) -> FloatArray:
        """A normal from :meth:`_surface_normal`, turned out of the piece over the edge from
        this direction's last tip seen from in front where the cameras did not see it so."""
        if front or where is None or self._front is None:
            return normal
        known_at, known_normal = self._front
        oriented = orient_over_edge(
            normal,
            where,
            known_normal,
            known_at,
            margin_m=ORIENT_MARGIN_M,
            same_plane_cos=FRONT_COS,
        )
        return normal if oriented is None else unit(oriented)

    def _surface_normal(
        self, point: FloatArray, fallback: FloatArray
    ) -> tuple[FloatArray, FloatArray | None, bool]:
        """The normal at ``point`` or ``fallback`` oriented towards the cameras that saw the
        surface there, where it was estimated (None: the last camera's axis) and whether those
        cameras looked at it from in front (median sight line within 45 degrees of it)."""
        c = self.config.exploration
        surface, viewpoints = self._observed_surface()
        for at in (point, fallback):
            box = np.all(np.abs(surface - at) <= c.normal_radius_m, axis=1)
            if box.sum() < MIN_NORMAL_POINTS:
                continue
            estimate = estimate_normals(
                at[None, :],
                surface[box],
                viewpoints[box],
                radius_m=c.normal_radius_m,
                min_points=MIN_NORMAL_POINTS,
            )
            if estimate.supported[0]:
                normal = unit(estimate.normals[0])
                facing = sight_cosines(surface[box], viewpoints[box], normal)
                return normal, at, bool(np.median(facing) >= FRONT_COS)
        return unit(-self._last_pose[:3, 2]), None, False

    # ------------------------------------------------------------------ growth and fitting

    def _novel_growth(self, paint_base: FloatArray) -> int:
        """Paint voxels of the frame (stitching voxel) farther than ``novelty_m`` from the cloud
        stitched so far: growth(k)."""
        if len(paint_base) == 0:
            return 0
        voxel = self.config.stitch.voxel_size_m
        keys = np.unique(pack_voxel_keys(voxel_keys(paint_base, voxel)))
        if self.stitcher.size == 0:
            return int(keys.size)
        cloud = self.stitcher.paint_points
        lo = paint_base.min(axis=0) - self.config.exploration.novelty_m
        hi = paint_base.max(axis=0) + self.config.exploration.novelty_m
        cloud = cloud[np.all((cloud >= lo) & (cloud <= hi), axis=1)]
        if len(cloud) == 0:
            return int(keys.size)
        distance, _ = cKDTree(cloud).query(
            paint_base, distance_upper_bound=self.config.exploration.novelty_m
        )
        far = paint_base[~np.isfinite(distance)]
        if len(far) == 0:
            return 0
        return int(np.unique(pack_voxel_keys(voxel_keys(far, voxel))).size)

    def _local_fit(self, centre: FloatArray, radius: float) -> Curve | None:
        """The method's curve through the stitched paint within ``radius`` of ``centre``,
        thinned to ``fit_voxel_m`` for speed; None when it cannot be fitted (the skeleton is
        retried at coarser leaves first)."""
        t0 = time.perf_counter()
        try:
            return self._fit_window(centre, radius)
        finally:
            self._fit_s += time.perf_counter() - t0

    def _fit_window(self, centre: FloatArray, radius: float) -> Curve | None:
        c = self.config.exploration
        paint = self.stitcher.paint_points
        voxel = c.fit_voxel_m
        if self.method == "skeleton":
            # Thinned coarser than the leaf, the band would fall apart into separate voxels.
            voxel = min(voxel, SKELETON_THINNING * self.config.skeleton.leaf_size_m)
        local = thin_points(paint[np.linalg.norm(paint - centre, axis=1) <= radius], voxel)
        self._fit_note = {"points": len(local), "radius_m": round(radius, 6)}
        attempts: list[SkeletonConfig | None] = [None]
        if self.method == "skeleton":
            leaf = self.config.skeleton.leaf_size_m
            attempts += [
                dataclasses.replace(self.config.skeleton, leaf_size_m=r)
                for r in SKELETON_RETRY_LEAVES_M
                if r > leaf
            ]
        # Paint that is not the line (a crate or a cone of the paint's colour in view) bends
        # the fit towards itself, or breaks it: where the window holds paint farther from the
        # marked line than a stroke is wide (however little: a curve through all the points
        # runs to a cluster of a dozen), the line alone, as `fit` selects it, is fitted first;
        # the plain fit stays the fallback.
        line = self._selected_line()
        if line is None:
            return self._fit_points(local, attempts)
        near = thin_points(line[np.linalg.norm(line - centre, axis=1) <= radius], voxel)
        off = _off_line(local, near, self.config.selection.max_width_m)
        if off:
            self._fit_note["off_line_points"] = off
            self._fit_note["selected_points"] = len(near)
            curve = self._fit_points(near, attempts)
            if curve is not None:
                return curve
        curve = self._fit_points(local, attempts)
        if curve is not None or off:
            return curve
        # The plain fit can fail where too little of the other paint was seen to count: the
        # marked line alone is tried last.
        self._fit_note["selected_points"] = len(near)
        return self._fit_points(near, attempts)

    def _selected_line(self) -> FloatArray | None:
        """The stitched paint of the marked line: the first line ``select_line``
        (:mod:`scrapcut_cli.perception.candidates`) picks from the paint, the duller clusters
        and the sight lines so far; None when it finds none (the reason is logged). Selected
        once per stitched frame: a decision's growing fit windows share it."""
        from scrapcut_cli.perception.candidates import select_line

        st = self.stitcher
        if self._line_cache is None or self._line_cache[0] != len(st.steps):
            points = np.vstack([st.paint_points, st.other_points])
            try:
                selection = select_line(
                    points,
                    np.vstack([st.paint_rgb, st.other_rgb]),
                    st.views,
                    voxel_m=self.config.stitch.voxel_size_m,
                    config=self.config.selection,
                )
                self._line_cache = (len(st.steps), points[selection.line.points], None)
            except PerceptionError as exc:
                self._line_cache = (len(st.steps), None, str(exc))
        _, line, error = self._line_cache
        if error is not None:
            self._fit_note["selection_error"] = error
        return line

    def _fit_points(self, local: FloatArray, attempts: list[SkeletonConfig | None]) -> Curve | None:
        """The method's curve through ``local`` with the first of ``attempts`` (None: the
        configured skeleton; else a coarser leaf) that fits, or None; the last error is noted
        for the log."""
        config = self.config
        for skeleton in attempts:
            trial = config if skeleton is None else dataclasses.replace(config, skeleton=skeleton)
            try:
                curve = fit_curve(local, self.method, trial)
            except FittingError as exc:
                self._fit_note["error"] = str(exc)
                continue
            if skeleton is not None:
                self._fit_note["leaf_size_m"] = skeleton.leaf_size_m
            self._fit_note["length_m"] = round(curve.length, 6)
            return curve
        return None

    def _end_of(self, curve: Curve, which: str) -> _End:
        """The ``which`` end ("start" or "end") of ``curve``: tip, outward direction, turn.

        The direction is the paper's (``fitting.extrapolate_end``: two points near the NURBS
        end, or the last two skeleton vertices). Two skeleton vertices one leaf apart can point
        along a thinning fork instead of the line; when that direction leaves the curve's last
        :data:`END_CHORD_M` by more than ``turn_angle_deg``, the chord is used instead.
        """
        _, direction = extrapolate_end(curve, "start" if which == "start" else "end", step_m=0.0)
        pts = curve.points[::-1] if which == "start" else curve.points
        direction = np.asarray(direction, dtype=np.float64)
        source = "model"
        chord = _chord_direction(pts, END_CHORD_M)
        limit = np.cos(np.radians(self.config.exploration.turn_angle_deg))
        if chord is not None and float(np.dot(chord, direction)) < limit:
            direction, source = chord, "chord"
        return _End(
            tip=np.asarray(pts[-1], dtype=np.float64).copy(),
            direction=direction,
            turn_deg=_end_turn_deg(pts, direction),
            source=source,
        )

    @staticmethod
    def _following(curve: Curve, frontier: _End) -> str:
        """Which end of ``curve`` continues the exploration past ``frontier``: the end the curve
        runs towards where it passes the frontier's tip, measured along the frontier's
        direction."""
        pts = curve.points
        _, _, u = PolylineDistance(pts).query(frontier.tip)
        i = int(np.clip(np.floor(u[0]), 0, len(pts) - 2))
        reach = max(1, round(0.01 / max(curve.spacing_m, 1e-6)))
        chord = pts[min(i + 1 + reach, len(pts) - 1)] - pts[max(i - reach, 0)]
        return "end" if float(np.dot(chord, frontier.direction)) >= 0.0 else "start"


# --------------------------------------------------------------------------- helpers


def _off_line(local: FloatArray, line: FloatArray, distance_m: float) -> int:
    """How many of the window's paint points ``local`` (N, 3) lie farther than ``distance_m``
    from every point of the selected line's paint ``line`` (M, 3) in the same window."""
    if len(line) == 0:
        return len(local)
    if len(local) == 0:
        return 0
    distance, _ = cKDTree(line).query(local, distance_upper_bound=distance_m)
    return int(np.count_nonzero(~np.isfinite(distance)))


def thin_points(points: ArrayLike, voxel_m: float) -> FloatArray:
    """Mean point (M, 3) of each occupied voxel, in ascending voxel-key order.

    open3d's voxel filter gives the same means in hash-map order; the fitters orient their
    curves by the input order, so a sorted, reproducible order is what the planner needs.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return pts.copy()
    _, inverse, counts = np.unique(
        pack_voxel_keys(voxel_keys(pts, voxel_m)), return_inverse=True, return_counts=True
    )
    inverse = inverse.reshape(-1)
    sums = np.column_stack(
        [np.bincount(inverse, weights=pts[:, i], minlength=counts.size) for i in range(3)]
    )
    return np.asarray(sums / counts[:, None])


def _chord_direction(points: FloatArray, length_m: float) -> FloatArray | None:
    """Unit direction (3,) from ``length_m`` before the polyline's last point to it (None if the
    polyline is shorter)."""
    s = cumulative_length(points)
    if s[-1] < length_m:
        return None
    a = interpolate_polyline(points, [s[-1] - length_m], cumulative=s)[0]
    chord = points[-1] - a
    n = float(np.linalg.norm(chord))
    return None if n <= 0.0 else np.asarray(chord / n)


def _end_turn_deg(points: FloatArray, direction: FloatArray) -> float:
    """Angle in degrees between the end direction and the curve's direction 2–5 cm back."""
    s = cumulative_length(points)
    length = float(s[-1])
    if length < TURN_SPAN_M:
        return 0.0
    a, b = interpolate_polyline(points, [length - TURN_SPAN_M, length - 0.02], cumulative=s)
    chord = b - a
    n = float(np.linalg.norm(chord))
    if n <= 0.0:
        return 0.0
    cos = float(np.clip(np.dot(chord / n, direction), -1.0, 1.0))
    return float(np.degrees(np.arccos(cos)))


def _end_dict(end: _End, target: FloatArray, fraction: float) -> dict[str, Any]:
    return {
        "tip": [float(v) for v in end.tip],
        "direction": [float(v) for v in end.direction],
        "target": [float(v) for v in target],
        "step_fraction": float(fraction),
        "turn_deg": float(end.turn_deg),
        "direction_source": end.source,
    }


def planner_config_dict(config: ScrapcutConfig) -> dict[str, Any]:
    """The configuration sections a planner's decisions depend on (for the log)."""
    full = config.to_dict()
    return {key: full[key] for key in ("exploration", "perception", "stitch", "nurbs", "skeleton")}


def planner_factory(config: ScrapcutConfig, *, hsv: HsvRange | None = None) -> PlannerFactory:
    """A factory a cell (the simulator's explore mode) calls with its
    :class:`~scrapcut_cli.cell.PlannerContext`: the worker's start view, ``reachable``, the
    paint. The paint's colour range defaults to the context's preset (``hsv`` overrides it)."""

    def make(context: PlannerContext) -> ViewPlanner:
        from scrapcut_cli.perception.paint import PAINT_PRESETS

        paint = hsv
        if paint is None:
            preset = PAINT_PRESETS.get(context.paint)
            if preset is None:
                raise PerceptionError(f"unknown paint preset {context.paint!r}")
            paint = preset.hsv
        return ExplorationPlanner(
            context.start_view, reachable=context.reachable, hsv=paint, config=config
        )

    return make
