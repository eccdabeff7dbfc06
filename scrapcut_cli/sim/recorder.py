"""The recorder: drive the Panda through a planner's views, render, and write an MCAP.

One loop serves every mode (the planner contract of :mod:`scrapcut_cli.cell`)::

    decision = planner.start()
    while not decision.stop:
        execute decision.T_base_cam (IK, free DOFs, collisions at the view and on the way:
            the straight joint-space move, or a detour through the ready pose)  -> or skip it
        move there (minimum-jerk motion; /tf and /joint_states at tf_rate_hz)
            (and images at motion_frames_hz on the way, the camera streaming)
        rest, capture frames_per_view images, write them
        decision = planner.observe(frame)   # the view's last image, exactly as a reader reads it

What the loop plans with depends on the mode. ``sweep`` and ``survey`` are oracles by design:
their views follow the true line and they plan against the TRUE mesh of the piece. ``explore``
plans only with what a real cell knows: inverse kinematics within the joint limits,
self-collision, the floor, and the voxels its camera has observed so far
(``sim.observed``, filled from each captured frame as a reader returns it). Its first view is
where a worker points the robot: a view of the line at the start fraction, moved by up to
20 mm and turned by up to 10° (seeded). In every mode the true mesh is used afterwards to
count crashes: contacts of the robot or camera with the true piece or the floor at each
executed view and along each move (``RecordResult.collisions``), and the closest approach.

What is written (docs/design.md, realsense-ros 4.x names)
----------------------------------------------------
* ``/camera/camera/color/image_raw`` rgb8, ``/camera/camera/aligned_depth_to_color/image_raw``
  16UC1 mm (0 = invalid; or 32FC1 m), ``/camera/camera/color/camera_info`` with every image.
* ``/tf``: panda_link0 -> panda_link1 -> ... -> panda_link8 at ``tf_rate_hz`` (100 Hz) along
  the whole motion, not only at image stamps; ``/joint_states`` at the same rate.
* ``/tf_static``: two messages from two "publishers" with stamps seconds before the recording
  starts, as latched topics arrive in a real bag: robot_state_publisher's
  panda_link8 -> panda_hand, and the camera's panda_hand -> camera_link ->
  camera_color_optical_frame (the NOMINAL hand-eye calibration).
* ``/scrapcut/reference`` (nav_msgs/Path, panda_link0), ``/scrapcut/exploration``
  (std_msgs/String JSON per decision, explore mode only).
* MCAP metadata ``scrapcut`` (object, mode, noise, paint, stroke_width_m, seed, tool_version,
  params = JSON of everything used) and ``scrapcut_result`` (counts of this run); for a closed
  line also ``scrapcut_reference``: ``closed`` ("true") and ``unseen_arcs`` (JSON list of
  [start, end] metres along the reference from its first point, wrapping when end < start: the
  stretches no captured image showed, ``sim.visibility``), the truth ``scrapcut eval`` scores
  reported unobserved arcs against.

Image header stamps are the capture time plus the camera's clock offset (``yard``: 10–20 ms
either way; 0 otherwise; ``SimConfig.stamp_offset_s``), /tf stamps the robot's time; the
metadata ``params`` keep the true mount and offset under ``truth`` for tests (the pipeline never
reads them). Log times trail header stamps like a real bag's receive times: images by
20–40 ms, /tf and /joint_states by 0.3–2 ms (seeded), and messages are written in log-time
order, so a reader that sorts by log time instead of header stamp gets wrong poses.
The simulated clock starts at :data:`START_NS`; nothing depends on the wall clock, so the same
configuration and seed give the same bytes.
"""

from __future__ import annotations

import dataclasses
import functools
import heapq
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli import __version__
from scrapcut_cli.cell import (
    Decision,
    PlannerContext,
    PlannerFactory,
    ReachAnswer,
    ReachQuery,
    SkippingPlanner,
    ViewPlanner,
)
from scrapcut_cli.config import ScanMode, SimConfig, choice_names
from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import matrix_to_quat_xyzw
from scrapcut_cli.recording.frame import CameraModel, Frame
from scrapcut_cli.sim.camera import (
    BASE_FRAME,
    CAMERA_LINK,
    FLANGE_FRAME,
    HAND_FRAME,
    OPTICAL_FRAME,
    T_CAMLINK_OPTICAL,
    T_HAND_CAMLINK,
    NoisePreset,
    d435i_color_camera,
    depth_to_millimetres,
    draw_lighting,
    draw_stamp_offset,
    noise_preset,
    perturb_hand_eye,
    simulate_color,
    simulate_depth,
)
from scrapcut_cli.sim.objects import ScrapObject, make_object
from scrapcut_cli.sim.observed import ObservedScene
from scrapcut_cli.sim.robot import (
    FINGER_OPENING_M,
    LINK_NAMES,
    Q_READY,
    PandaSim,
    RobotLimits,
    World,
    joint_names,
)
from scrapcut_cli.sim.scene import YardScene
from scrapcut_cli.sim.surface import OVERSPRAY_PRESETS, PaintStroke
from scrapcut_cli.sim.visibility import LineVisibility

FloatArray = NDArray[np.float64]

COLOR_TOPIC = "/camera/camera/color/image_raw"
DEPTH_TOPIC = "/camera/camera/aligned_depth_to_color/image_raw"
INFO_TOPIC = "/camera/camera/color/camera_info"
JOINT_STATES_TOPIC = "/joint_states"
REFERENCE_TOPIC = "/scrapcut/reference"
EXPLORATION_TOPIC = "/scrapcut/exploration"

MODES = choice_names(ScanMode)
DEPTH_ENCODINGS = ("16UC1", "32FC1")
COLOR_ENCODINGS = ("rgb8", "jpeg")
#: realsense-ros publishes JPEG colour through image_transport's compressed plugin here.
COMPRESSED_SUFFIX = "/compressed"

#: Simulated clock at the start of every recording: 2023-11-14 22:13:20 UTC.
START_NS = 1_700_000_000 * 1_000_000_000

#: Timing of a view (seconds): settle after the motion stops (assumed: the Panda's tracking
#: error decays within ~0.2 s), then images at the D435i's 30 Hz frame rate; the first image
#: comes up to 5 ms after settling (the camera's own frame clock, not synchronised).
SETTLE_S = 0.25
FRAME_PERIOD_S = 1.0 / 30.0
POST_CAPTURE_S = 0.05
MIN_MOVE_S = 0.4
INITIAL_REST_S = 0.5
FINAL_REST_S = 0.3
#: Peak speed of a minimum-jerk profile is 1.875 × its mean speed.
MIN_JERK_PEAK = 1.875

# Independent random streams: numpy Generators seeded by (seed, stream, index...).
_STREAM_HAND_EYE, _STREAM_LATENCY, _STREAM_LIGHT, _STREAM_SENSOR, _STREAM_STAMP = range(5)
_STREAM_START = 5
_STREAM_CLOCK, _STREAM_MOVING = 6, 7


@dataclass(frozen=True)
class RecordResult:
    """What a recording run did.

    ``views`` executed views, ``frames`` colour/depth pairs written, ``infeasible_views``
    views the robot could not reach even with the free DOFs (skipped), ``adjusted_views``
    views that needed a roll or back-off, ``collisions`` crashes: executed views and moves in
    which the robot or the camera (where it really is) touched the TRUE piece, the floor or
    itself (counted with the true mesh after planning without it in explore mode; must be 0),
    ``motion_collisions`` the crashes that happened during moves, ``min_clearance_m`` the
    closest the robot and camera came to the true piece (at most 0.1 m; negative: into it),
    ``planned_with`` what collision checks saw (``truth``: the piece's mesh, the oracle modes;
    ``observed``: the camera's voxels, explore), ``camera_travel_m`` length of the camera's
    path, ``duration_s`` simulated time, ``wall_time_s`` real time, ``moving_frames`` the
    frames taken while the arm moved.
    """

    path: Path
    object: str
    mode: str
    noise: str
    seed: int
    views: int
    frames: int
    infeasible_views: int
    adjusted_views: int
    collisions: int
    motion_collisions: int
    min_clearance_m: float
    planned_with: str
    camera_travel_m: float
    duration_s: float
    wall_time_s: float
    stop_reason: str
    view_log: tuple[dict[str, Any], ...] = ()
    moving_frames: int = 0  # of ``frames``, taken while the arm moved


def validate(config: SimConfig) -> None:
    """Raise SimError naming the first bad simulator parameter."""
    from scrapcut_cli.perception.paint import PAINT_PRESETS
    from scrapcut_cli.sim.objects import list_objects

    names = [name for name, _ in list_objects()]
    if config.object not in names:
        raise SimError(f"unknown object {config.object!r}; objects: {', '.join(names)}")
    noise_preset(config.noise)
    if config.mode not in MODES:
        raise SimError(f"unknown mode {config.mode!r}; modes: {', '.join(MODES)}")
    if config.paint not in PAINT_PRESETS:
        raise SimError(
            f"unknown paint preset {config.paint!r}; the simulator paints with one of "
            f"{', '.join(PAINT_PRESETS)} (auto is for reading recordings)"
        )
    if config.depth_encoding not in DEPTH_ENCODINGS:
        raise SimError(
            f"unknown depth encoding {config.depth_encoding!r}; "
            f"encodings: {', '.join(DEPTH_ENCODINGS)}"
        )
    if config.color_encoding not in COLOR_ENCODINGS:
        raise SimError(
            f"unknown colour encoding {config.color_encoding!r}; "
            f"encodings: {', '.join(COLOR_ENCODINGS)}"
        )
    from scrapcut_cli.recording.writer import ROS2_STORAGES
    from scrapcut_cli.sim.scene import check_distractors

    if config.storage not in ROS2_STORAGES:
        raise SimError(
            f"unknown ROS 2 storage {config.storage!r}; storages: {', '.join(ROS2_STORAGES)}"
        )
    if config.distractors is not None:
        if isinstance(config.distractors, str) or not all(
            isinstance(d, str) for d in config.distractors
        ):
            raise SimError(f"sim.distractors must be a list of names, got {config.distractors!r}")
        check_distractors(tuple(config.distractors))
    checks = [
        (config.width > 0 and config.height > 0, f"resolution {config.width}x{config.height}"),
        (config.stroke_width_m > 0, f"stroke width {config.stroke_width_m} m"),
        (config.view_distance_m > 0, f"view distance {config.view_distance_m} m"),
        (config.view_step_m > 0, f"view step {config.view_step_m} m"),
        (config.survey_spacing_m > 0, f"survey spacing {config.survey_spacing_m} m"),
        (config.views >= 0, f"views {config.views}"),
        (config.frames_per_view >= 1, f"frames per view {config.frames_per_view}"),
        (config.max_views >= 1, f"max views {config.max_views}"),
        (config.max_backoff_m >= 0, f"max back-off {config.max_backoff_m} m"),
        (1 <= config.jpeg_quality <= 100, f"JPEG quality {config.jpeg_quality} (1-100)"),
        (
            config.faded_marks is None or config.faded_marks >= 0,
            f"faded marks {config.faded_marks}",
        ),
        (0 < config.speed_scale <= 1, f"speed scale {config.speed_scale} (0-1]"),
        (config.tf_rate_hz > 0, f"tf rate {config.tf_rate_hz} Hz"),
        (0 <= config.min_elevation_deg < 90, f"min elevation {config.min_elevation_deg} deg"),
        (
            config.start_fraction is None or 0.0 <= config.start_fraction <= 1.0,
            f"start fraction {config.start_fraction} (0-1)",
        ),
    ]
    for ok, what in checks:
        if not ok:
            raise SimError(f"invalid simulator parameter: {what}")


def place_object(config: SimConfig) -> ScrapObject:
    """The configured piece at the configured placement."""
    return make_object(
        config.object,
        seed=config.seed,
        placement=(config.object_x_m, config.object_y_m, config.object_yaw_deg),
    )


def make_scene(config: SimConfig, obj: ScrapObject, preset: NoisePreset) -> YardScene:
    """What lies in the scene besides the piece: the noise preset's choices, overridden by the
    configuration's (``paint_variation``, ``faded_marks``, ``distractors``, ``glints``)."""
    from scrapcut_cli.perception.paint import PAINT_PRESETS
    from scrapcut_cli.sim.scene import build_scene

    def pick(value: Any, default: Any) -> Any:
        return default if value is None else value

    return build_scene(
        obj,
        paint_rgb=PAINT_PRESETS[config.paint].rgb,
        stroke_width_m=config.stroke_width_m,
        paint_variation=bool(pick(config.paint_variation, preset.paint_variation)),
        faded_marks=int(pick(config.faded_marks, preset.faded_marks)),
        distractors=tuple(pick(config.distractors, preset.distractors)),
        glints=bool(pick(config.glints, preset.glints)),
        seed=config.seed,
    )


def planned_views(
    config: SimConfig,
    obj: ScrapObject,
    *,
    reachable: Callable[[FloatArray], bool] | None = None,
) -> list[FloatArray]:
    """The pre-planned views of ``sweep`` or ``survey`` mode (survey keeps ``reachable`` ones)."""
    from scrapcut_cli.sim.views import survey_views, sweep_views

    if config.mode == "sweep":
        return sweep_views(
            obj,
            distance_m=config.view_distance_m,
            step_m=config.view_step_m,
            count=config.views,
            min_elevation_deg=config.min_elevation_deg,
        )
    if config.mode == "survey":
        return survey_views(
            obj,
            distance_m=config.view_distance_m,
            spacing_m=config.survey_spacing_m,
            count=config.views,
            reachable=reachable,
        )
    raise SimError(f"mode {config.mode!r} has no pre-planned views")


def record(
    config: SimConfig,
    out_path: str | Path,
    *,
    planner: ViewPlanner | None = None,
    planner_factory: PlannerFactory | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RecordResult:
    """Simulate a scan of ``config.object`` and write it to ``out_path`` (MCAP, atomically).

    ``sweep`` and ``survey`` plan their views themselves; ``explore`` needs a closed-loop
    planner: ``planner``, or ``planner_factory(context)`` (:class:`~scrapcut_cli.cell.
    PlannerContext`: the camera, the worker's start view, the cell's ``reachable``, the
    paint). A planner given in another mode drives the loop instead of the mode's own views.
    In explore mode every collision check of the loop sees only what the camera observed; the
    true piece only counts crashes. ``progress(done, total)`` is called after every decided
    view.
    """
    from scrapcut_cli.sim.render import SceneRenderer
    from scrapcut_cli.sim.views import PrePlannedPlanner

    wall_start = time.perf_counter()
    validate(config)
    if config.mode == "explore" and planner is None and planner_factory is None:
        raise SimError("explore mode needs the exploration planner (issue 7); use sweep or survey")
    obj = place_object(config)
    preset = noise_preset(config.noise)
    camera = d435i_color_camera(config.width, config.height)
    T_hand_camlink_true = T_HAND_CAMLINK
    error_m = (
        preset.hand_eye_translation_m
        if config.hand_eye_error_m is None
        else config.hand_eye_error_m
    )
    error_deg = (
        preset.hand_eye_rotation_deg
        if config.hand_eye_error_deg is None
        else config.hand_eye_error_deg
    )
    if error_m > 0 or error_deg > 0:
        T_hand_camlink_true = perturb_hand_eye(
            T_HAND_CAMLINK,
            preset,
            _rng(config.seed, _STREAM_HAND_EYE),
            translation_m=error_m,
            rotation_deg=error_deg,
        )
    stamp_offset_s = config.stamp_offset_s
    if stamp_offset_s is None:
        stamp_offset_s = draw_stamp_offset(preset, _rng(config.seed, _STREAM_CLOCK))
    motion_hz = (
        preset.motion_frames_hz if config.motion_frames_hz is None else config.motion_frames_hz
    )
    overspray = OVERSPRAY_PRESETS[preset.overspray]
    scene = make_scene(config, obj, preset)
    stroke = PaintStroke(
        obj.painted_line,
        width_m=config.stroke_width_m,
        rgb=scene.can_rgb,
        overspray=overspray,
        seed=config.seed,
    )
    renderer = SceneRenderer(
        obj,
        stroke,
        seed=config.seed,
        faded=[mark.stroke for mark in scene.faded],
        distractors=scene.distractors,
        glints=scene.glints,
    )
    limits = RobotLimits(max_backoff_m=config.max_backoff_m)
    observed = ObservedScene() if config.mode == "explore" else None

    with (
        PandaSim(
            # The true world: the piece and what lies beside it (the planner never sees it).
            scene.obstacles(obj),
            T_hand_camlink_nominal=T_HAND_CAMLINK,
            T_hand_camlink_true=T_hand_camlink_true,
            limits=limits,
        ) as robot,
        _writer(out_path, config) as writer,
    ):
        session = _Session(
            writer,
            robot,
            renderer,
            camera,
            preset,
            config,
            observed=observed,
            stamp_offset_ns=round(stamp_offset_s * 1e9),
            motion_frames_hz=motion_hz,
        )
        if obj.closed:
            session.visibility = LineVisibility(stroke, closed=True)
        params = _params(config, preset, camera, T_hand_camlink_true, limits, stroke)
        params["truth"] = _truth(robot, stamp_offset_s, motion_hz)
        active: ViewPlanner
        if planner is not None:
            active = planner
        elif planner_factory is None:
            views = planned_views(
                config,
                obj,
                reachable=lambda T: robot.plan_view(T, Q_READY, check_motion=False).feasible,
            )
            active = PrePlannedPlanner(views, reason=config.mode)
        else:
            start_view = worker_start_view(config, obj)
            context = PlannerContext(
                camera=camera,
                start_view=start_view,
                reachable=session.reachable,
                paint=config.paint,
                base_frame=BASE_FRAME,
            )
            active = planner_factory(context)
            params["start_view"] = start_view.tolist()
        if observed is not None:
            params["observed"] = dataclasses.asdict(observed.settings)
        total = int(getattr(active, "total", config.max_views))
        params["scene"] = scene.describe()
        writer.add_metadata("scrapcut", _metadata(config, params))
        session.start(obj.reference)
        stop_reason = session.run(active, total, progress)
        session.finish()
        result = RecordResult(
            path=Path(out_path),
            object=obj.name,
            mode=config.mode,
            noise=config.noise,
            seed=config.seed,
            views=session.views,
            frames=session.frames,
            infeasible_views=session.infeasible,
            adjusted_views=session.adjusted,
            collisions=session.collisions,
            motion_collisions=session.motion_collisions,
            min_clearance_m=session.min_clearance_m,
            planned_with=session.world.value,
            camera_travel_m=session.travel_m,
            duration_s=(session.t_ns - START_NS) / 1e9,
            wall_time_s=0.0,
            stop_reason=stop_reason,
            view_log=tuple(session.log),
            moving_frames=session.moving_frames,
        )
        writer.add_metadata("scrapcut_result", _result_metadata(result))
        if session.visibility is not None:
            writer.add_metadata("scrapcut_reference", _reference_metadata(session.visibility))
    return dataclasses.replace(result, wall_time_s=time.perf_counter() - wall_start)


def worker_start_view(config: SimConfig, obj: ScrapObject) -> FloatArray:
    """``T_base_cam`` (4, 4) where a worker points the robot to start exploring: the sweep's
    view of the line at ``config.start_fraction`` (default: the piece's own), moved and turned
    as a hand would (``sim.views.worker_view``, seeded by ``config.seed``)."""
    from scrapcut_cli.sim.objects import explore_start_fraction
    from scrapcut_cli.sim.views import views_along, worker_view

    fraction = config.start_fraction
    if fraction is None:
        fraction = explore_start_fraction(obj.name)
    exact = views_along(
        obj,
        [fraction],
        distance_m=config.view_distance_m,
        min_elevation_deg=config.min_elevation_deg,
    )[0]
    return worker_view(exact, _rng(config.seed, _STREAM_START))


# --------------------------------------------------------------------------- the session


class _Session:
    """Simulated clock, robot state and the log-time-ordered message queue of one recording.

    ``observed``: the cell's obstacle model in explore mode (collision checks see it, never
    the true piece); None: the oracle modes plan against the true mesh.
    """

    def __init__(
        self,
        writer: Any,
        robot: PandaSim,
        renderer: Any,
        camera: CameraModel,
        preset: NoisePreset,
        config: SimConfig,
        *,
        observed: ObservedScene | None = None,
        stamp_offset_ns: int = 0,
        motion_frames_hz: float = 0.0,
    ) -> None:
        self.writer = writer
        self.robot = robot
        self.renderer = renderer
        self.camera = camera
        self.preset = preset
        self.config = config
        self.observed = observed
        self.world = World.TRUTH if observed is None else World.OBSERVED
        self.q = np.asarray(Q_READY, dtype=np.float64)
        self.t_ns = START_NS
        self.dt_ns = round(1e9 / config.tf_rate_hz)
        self._next_sample = 0  # index of the next /tf sample on the fixed grid
        self._queue: list[tuple[int, int, Callable[[], None]]] = []
        self._seq = 0
        self._latency = _rng(config.seed, _STREAM_LATENCY)
        self.views = self.frames = self.infeasible = self.adjusted = 0
        self.collisions = self.motion_collisions = 0
        self.min_clearance_m = np.inf
        self.travel_m = 0.0
        self.log: list[dict[str, Any]] = []
        self._names = list(joint_names())
        self.stamp_offset_ns = int(stamp_offset_ns)
        self.motion_frames_hz = float(motion_frames_hz)
        self.moving_frames = 0
        self._moves = 0
        self.visibility: LineVisibility | None = None  # truth of what the images showed

    # ------------------------------------------------------------------ message queue

    def _emit(self, log_ns: int, write: Callable[[], None]) -> None:
        heapq.heappush(self._queue, (int(log_ns), self._seq, write))
        self._seq += 1

    def _flush(self, upto_ns: int | None = None) -> None:
        """Write queued messages logged up to ``upto_ns`` (all if None), in log-time order."""
        while self._queue and (upto_ns is None or self._queue[0][0] <= upto_ns):
            _, _, write = heapq.heappop(self._queue)
            write()

    def _delay_ns(self, low_ms: float, high_ms: float) -> int:
        return round(self._latency.uniform(low_ms, high_ms) * 1e6)

    # ------------------------------------------------------------------ timeline

    def start(self, reference: FloatArray) -> None:
        """Static transforms, the reference, and the robot at rest before the first move."""
        w = self.writer
        robot = self.robot
        hand = [(FLANGE_FRAME, HAND_FRAME, robot.kin.T_link8_hand)]
        camera = [
            (HAND_FRAME, CAMERA_LINK, robot.T_hand_camlink),
            (CAMERA_LINK, OPTICAL_FRAME, T_CAMLINK_OPTICAL),
        ]
        t0 = self.t_ns
        # Latched topics published long before the recorder started (different publishers).
        stamp_hand, stamp_camera = t0 - 4_200_000_000, t0 - 1_700_000_000
        log_hand, log_camera = t0 + self._delay_ns(1, 5), t0 + self._delay_ns(1, 5)
        self._emit(
            log_hand, lambda: w.write_tf(stamp_hand, hand, static=True, log_time_ns=log_hand)
        )
        self._emit(
            log_camera,
            lambda: w.write_tf(stamp_camera, camera, static=True, log_time_ns=log_camera),
        )
        log_ref = t0 + self._delay_ns(1, 5)
        ref = np.asarray(reference, dtype=np.float64)
        self._emit(
            log_ref,
            lambda: w.write_path(REFERENCE_TOPIC, t0, BASE_FRAME, ref, log_time_ns=log_ref),
        )
        self._rest(INITIAL_REST_S)

    def _publish_states(self, stamps: NDArray[np.int64], qs: FloatArray) -> None:
        """/tf (link0 -> ... -> link8) and /joint_states at each sample."""
        if len(stamps) == 0:
            return
        chains = self.robot.kin.chain(qs)  # (S, 8, 4, 4)
        # One vectorised rotation-to-quaternion call for every sample (messages.tf_msg converts
        # per transform, ~0.3 ms each: 80 % of a recording's time at 100 Hz).
        quats = matrix_to_quat_xyzw(chains[:, :, :3, :3].reshape(-1, 3, 3)).reshape(-1, 8, 4)
        w = self.writer
        names = self._names
        for stamp, q, chain, quat in zip(stamps.tolist(), qs, chains, quats, strict=True):
            msg = _tf_message(stamp, chain[:, :3, 3], quat)
            positions = np.concatenate([q, [FINGER_OPENING_M, FINGER_OPENING_M]])
            log_tf = stamp + self._delay_ns(0.3, 2.0)
            log_js = stamp + self._delay_ns(0.3, 2.0)
            self._emit(
                log_tf,
                functools.partial(w.write_message, "/tf", TF_MESSAGE, msg, log_time_ns=log_tf),
            )
            self._emit(
                log_js,
                functools.partial(
                    w.write_joint_state,
                    JOINT_STATES_TOPIC,
                    stamp,
                    names,
                    positions,
                    log_time_ns=log_js,
                ),
            )

    def _samples_until(self, end_ns: int) -> NDArray[np.int64]:
        """Grid stamps in [current time, end_ns) not yet published."""
        first = self._next_sample
        last = (end_ns - START_NS - 1) // self.dt_ns  # last grid index strictly before end
        if last < first:
            return np.zeros(0, dtype=np.int64)
        self._next_sample = last + 1
        return START_NS + self.dt_ns * np.arange(first, last + 1, dtype=np.int64)

    def _rest(self, duration_s: float) -> None:
        end = self.t_ns + round(duration_s * 1e9)
        stamps = self._samples_until(end)
        self._publish_states(stamps, np.repeat(self.q[None, :], len(stamps), axis=0))
        self.t_ns = end
        self._flush(self.t_ns)

    def _move(self, q_target: FloatArray) -> str | None:
        """Minimum-jerk joint motion to ``q_target`` at the configured share of joint speeds;
        returns what the robot touched on the way (the true piece, floor or itself), if
        anything."""
        q0 = self.q
        delta = q_target - q0
        vmax = self.config.speed_scale * self.robot.kin.velocity
        duration = max(MIN_MOVE_S, float(np.max(MIN_JERK_PEAK * np.abs(delta) / vmax)))
        # Whole milliseconds: joint targets differ by ~1e-8 rad between CPUs (IK in floating
        # point), and every later stamp would inherit a few nanoseconds of that difference.
        duration = math.ceil(duration * 1000.0 - 1e-6) / 1000.0
        start, end = self.t_ns, self.t_ns + round(duration * 1e9)
        stamps = self._samples_until(end)
        tau = (stamps - start).astype(np.float64) / (end - start)
        qs = q0 + _min_jerk(tau)[:, None] * delta
        self._publish_states(stamps, qs)
        if self.motion_frames_hz > 0:
            self._capture_moving(start, end, q0, delta)
        fine = q0 + _min_jerk(np.linspace(0.0, 1.0, 101))[:, None] * delta
        positions = self.robot.camera_poses(fine)[:, :3, 3]
        self.travel_m += float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())
        self.q = np.asarray(q_target, dtype=np.float64)
        self.t_ns = end
        self._flush(self.t_ns)
        return self._count_motion(q0, self.q)

    def _count_motion(self, q_from: FloatArray, q_to: FloatArray) -> str | None:
        """Check a move (a straight joint-space path) against the TRUE piece: count a crash,
        keep the closest approach; returns what was hit, if anything."""
        contact = self.robot.motion_crash(q_from, q_to)
        self.min_clearance_m = min(self.min_clearance_m, contact.clearance_m)
        if contact.hit is not None:
            self.collisions += 1
            self.motion_collisions += 1
        return contact.hit

    # ------------------------------------------------------------------ views

    def reachable(self, query: ReachQuery) -> ReachAnswer:
        """The cell's answer to a planner's query, from the current joints: IK, limits, and
        collisions in the world this session plans with (explore: what was observed)."""
        return self.robot.reachable(query, self.q, world=self.world)

    def run(
        self, planner: ViewPlanner, total: int, progress: Callable[[int, int], None] | None
    ) -> str:
        """The recorder loop; returns why it stopped."""
        decision = planner.start()
        decided = 0
        explore = self.config.mode == "explore"
        while not decision.stop:
            if self.views >= self.config.max_views:
                return "budget"
            if decision.T_base_cam is None:
                raise SimError(f"the planner gave no camera pose for {decision.reason!r}")
            decided += 1
            frame = self._execute(decision)
            if progress is not None:
                progress(decided, max(total, decided))
            if frame is None:
                why = self.log[-1]["reason"]
                if isinstance(planner, SkippingPlanner):
                    decision = planner.skip(why)
                    continue
                return f"infeasible view ({why})"
            decision = planner.observe(frame)
            if explore:
                self._log_decision(decision, len(self.log))
        return decision.reason

    def _execute(self, decision: Decision) -> Frame | None:
        """Move to the decided view (free DOFs, detour) and capture it; None if infeasible.

        Planned in this session's world; then the view and the moves are checked against the
        true piece, and crashes counted. Logs the view (``log``).
        """
        assert decision.T_base_cam is not None
        solution = self.robot.plan_view(decision.T_base_cam, self.q, world=self.world)
        answer = solution.answer
        entry: dict[str, Any] = {
            "decision": decision.reason,
            "feasible": answer.feasible,
            "reason": answer.describe(),
            "attempts": answer.attempts,
        }
        self.log.append(entry)
        if not answer.feasible:
            self.infeasible += 1
            return None
        assert solution.q is not None
        if answer.roll_rad != 0.0 or answer.backoff_m > 0.0:
            self.adjusted += 1
        hits = [self._move(q) for q in solution.route]
        contact = self.robot.crash(self.q)
        touching = contact.hit
        self.min_clearance_m = min(self.min_clearance_m, contact.clearance_m)
        if touching is not None:
            self.collisions += 1
        frame = self._capture()
        if self.observed is not None:
            self.observed.add(frame)
            self.robot.set_observed(*self.observed.mesh())
        entry.update(
            view=self.views - 1,
            stamp_ns=frame.stamp_ns,
            roll_deg=round(float(np.degrees(answer.roll_rad)), 3),
            backoff_m=answer.backoff_m,
            collision=touching,
            motion_collision=next((h for h in hits if h is not None), None),
            detour=len(solution.route) > 1,
        )
        return frame

    def _capture(self) -> Frame:
        """Rest at the current joints, render the view and write ``frames_per_view`` images."""
        cfg = self.config
        view = self.views
        self.views += 1
        T_nominal = self.robot.camera_pose(self.q)
        T_true = self.robot.camera_pose(self.q, true=True)
        lighting = draw_lighting(self.preset, _rng(cfg.seed, _STREAM_LIGHT, view))
        rendered = self.renderer.render(T_true, self.camera, lighting=lighting)
        jitter = _rng(cfg.seed, _STREAM_STAMP, view).uniform(0.0, 0.005)
        first = self.t_ns + round((SETTLE_S + jitter) * 1e9)
        rest = SETTLE_S + jitter + cfg.frames_per_view * FRAME_PERIOD_S + POST_CAPTURE_S
        frame: Frame | None = None
        for k in range(cfg.frames_per_view):
            stamp = first + round(k * FRAME_PERIOD_S * 1e9) + self.stamp_offset_ns
            rng = _rng(cfg.seed, _STREAM_SENSOR, view, k)
            depth_m = simulate_depth(
                rendered.depth, rendered.cos_incidence, self.preset, rng, glare=rendered.glare
            )
            if self.visibility is not None:
                self.visibility.add(rendered, depth_m)
            color = simulate_color(rendered.color, self.preset, rng)
            depth_msg, depth_read = _encode_depth(depth_m, cfg.depth_encoding)
            color_msg, color = _encode_color(color, cfg, stamp)
            self._write_images(stamp, color_msg, depth_msg)
            self.frames += 1
            frame = Frame(
                index=self.frames - 1,
                stamp_ns=stamp,
                color=color,
                depth=depth_read,
                camera=self.camera,
                T_base_cam=T_nominal.copy(),
                # What a reader returns: nothing of the simulator's truth (the true pose).
                extras={"depth_stamp_ns": stamp},
            )
        self._rest(rest)
        assert frame is not None
        return frame

    def _capture_moving(
        self, start_ns: int, end_ns: int, q0: FloatArray, delta: FloatArray
    ) -> None:
        """Images while the arm moves from ``q0`` by ``delta`` (minimum jerk, start to end).

        On the camera's own clock: one every 1 / motion_frames_hz seconds from a seeded phase,
        each rendered at the arm's true pose at its capture time and stamped with the clock
        offset (motion blur is not modelled). The planner does not see them.
        """
        cfg = self.config
        move = self._moves
        self._moves += 1
        period_ns = round(1e9 / self.motion_frames_hz)
        phase = _rng(cfg.seed, _STREAM_MOVING, move).uniform(0.0, 1.0)
        first = start_ns + round(phase * period_ns)
        captures = np.arange(first, end_ns, period_ns, dtype=np.int64)
        if captures.size == 0:
            return
        lighting = draw_lighting(self.preset, _rng(cfg.seed, _STREAM_LIGHT, 100_000 + move))
        tau = (captures - start_ns).astype(np.float64) / (end_ns - start_ns)
        poses = self.robot.camera_poses(q0 + _min_jerk(tau)[:, None] * delta, true=True)
        for k, (capture, T_true) in enumerate(zip(captures.tolist(), poses, strict=True)):
            rendered = self.renderer.render(T_true, self.camera, lighting=lighting)
            rng = _rng(cfg.seed, _STREAM_SENSOR, 100_000 + move, k)
            depth_m = simulate_depth(
                rendered.depth, rendered.cos_incidence, self.preset, rng, glare=rendered.glare
            )
            if self.visibility is not None:
                self.visibility.add(rendered, depth_m)  # a reader may stitch these too
            color = simulate_color(rendered.color, self.preset, rng)
            depth_msg, _ = _encode_depth(depth_m, cfg.depth_encoding)
            stamp = capture + self.stamp_offset_ns
            color_msg, _ = _encode_color(color, cfg, stamp)
            self._write_images(stamp, color_msg, depth_msg)
            self.frames += 1
            self.moving_frames += 1

    def _write_images(self, stamp: int, color: Any, depth: NDArray[Any]) -> None:
        """Colour (an rgb8 array, or a CompressedImage message), depth and camera info."""
        w = self.writer
        camera = self.camera
        log_color = stamp + self._delay_ns(20.0, 40.0)
        log_depth = stamp + self._delay_ns(20.0, 40.0)
        log_info = log_color + self._delay_ns(0.05, 0.5)
        if isinstance(color, np.ndarray):
            self._emit(
                log_color,
                lambda: w.write_image(
                    COLOR_TOPIC, stamp, OPTICAL_FRAME, color, log_time_ns=log_color
                ),
            )
        else:
            self._emit(
                log_color,
                lambda: w.write_message(
                    COLOR_TOPIC + COMPRESSED_SUFFIX,
                    COMPRESSED_IMAGE,
                    color,
                    log_time_ns=log_color,
                ),
            )
        self._emit(
            log_depth,
            lambda: w.write_image(DEPTH_TOPIC, stamp, OPTICAL_FRAME, depth, log_time_ns=log_depth),
        )
        self._emit(
            log_info, lambda: w.write_camera_info(INFO_TOPIC, stamp, camera, log_time_ns=log_info)
        )

    def _log_decision(self, decision: Decision, step: int) -> None:
        entry = {"step": step, "stamp_ns": self.t_ns, "reason": decision.reason}
        entry["stop"] = decision.stop
        entry.update(decision.info)
        text = json.dumps(entry, sort_keys=True, default=_json_default)
        stamp = self.t_ns
        self._emit(stamp, lambda: self.writer.write_string(EXPLORATION_TOPIC, stamp, text))

    def finish(self) -> None:
        self._rest(FINAL_REST_S)
        self._flush()


# --------------------------------------------------------------------------- helpers


TF_MESSAGE = "tf2_msgs/msg/TFMessage"


def _tf_message(stamp_ns: int, translations: FloatArray, quats_xyzw: FloatArray) -> Any:
    """tf2_msgs/TFMessage of the arm chain link0 -> link1 ... link7 -> link8 at one stamp."""
    from scrapcut_cli.recording import messages as m

    types = m.typestore().types
    transform_stamped = types["geometry_msgs/msg/TransformStamped"]
    transform = types["geometry_msgs/msg/Transform"]
    vector = types["geometry_msgs/msg/Vector3"]
    quaternion = types["geometry_msgs/msg/Quaternion"]
    items = []
    for k, (t, q) in enumerate(zip(translations.tolist(), quats_xyzw.tolist(), strict=True)):
        items.append(
            transform_stamped(
                header=m.header(stamp_ns, LINK_NAMES[k]),
                child_frame_id=LINK_NAMES[k + 1],
                transform=transform(
                    translation=vector(x=t[0], y=t[1], z=t[2]),
                    rotation=quaternion(x=q[0], y=q[1], z=q[2], w=q[3]),
                ),
            )
        )
    return types[TF_MESSAGE](transforms=items)


def _rng(seed: int, *stream: int) -> np.random.Generator:
    """An independent generator per (seed, stream, index...): draws never shift each other."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, *stream])


def _min_jerk(tau: ArrayLike) -> FloatArray:
    """Minimum-jerk progress 10τ³ − 15τ⁴ + 6τ⁵ (zero speed and acceleration at both ends)."""
    t = np.clip(np.asarray(tau, dtype=np.float64), 0.0, 1.0)
    return np.asarray(t**3 * (10.0 - 15.0 * t + 6.0 * t * t))


COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"


def _encode_color(
    color: NDArray[np.uint8], config: SimConfig, stamp_ns: int
) -> tuple[Any, NDArray[np.uint8]]:
    """(what is written, what a reader decodes from it) for a colour image: the array itself
    (rgb8), or a JPEG CompressedImage and its decoded pixels (with the JPEG's losses)."""
    if config.color_encoding != "jpeg":
        return color, color
    from scrapcut_cli.recording import messages as m

    msg = m.compressed_image_msg(
        stamp_ns, OPTICAL_FRAME, color, fmt="jpeg", quality=config.jpeg_quality
    )
    return msg, m.decode_color(msg, COMPRESSED_IMAGE)


def _writer(path: str | Path, config: SimConfig) -> Any:
    """The output: MCAP for ``*.mcap``, else a ROS 2 bag directory of ``config.storage``."""
    from scrapcut_cli.recording.writer import open_writer

    try:
        return open_writer(path, storage=config.storage)
    except ValueError as exc:
        raise SimError(str(exc)) from None


def _encode_depth(
    depth_m: NDArray[np.float32], encoding: str
) -> tuple[NDArray[Any], NDArray[np.float32]]:
    """(what is written, what a reader decodes from it) for a float depth image."""
    if encoding == "32FC1":
        written = np.where(np.isfinite(depth_m), depth_m, 0.0).astype(np.float32)
        read = written.copy()
        read[read <= 0] = np.nan
        return written, read
    mm = depth_to_millimetres(depth_m)
    read = mm.astype(np.float32)
    read *= np.float32(0.001)
    read[mm == 0] = np.nan
    return mm, read


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def _strict_json(value: Any) -> Any:
    """``value`` with numpy types as Python ones and non-finite floats as strings ("inf"), so
    the metadata is strict JSON (Foxglove's JSON.parse rejects Infinity)."""
    if isinstance(value, dict):
        return {str(k): _strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_strict_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return _strict_json(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return str(value)
    return value


def _params(
    config: SimConfig,
    preset: NoisePreset,
    camera: CameraModel,
    T_hand_camlink_true: FloatArray,
    limits: RobotLimits,
    stroke: PaintStroke,
) -> dict[str, Any]:
    return {
        "sim": dataclasses.asdict(config),
        "noise_preset": dataclasses.asdict(preset),
        "camera": dataclasses.asdict(camera),
        "hand_eye_nominal": T_HAND_CAMLINK.tolist(),
        "hand_eye_true": np.asarray(T_hand_camlink_true).tolist(),
        "robot": dataclasses.asdict(limits),
        "stroke": {
            "width_m": stroke.width_m,
            "rgb": [round(float(c) * 255) for c in stroke.rgb],
            "max_half_width_m": stroke.max_half_width_m,
            "min_half_width_m": stroke.min_half_width_m,
            "overspray": dataclasses.asdict(stroke.overspray),
        },
        "timing_s": {
            "settle": SETTLE_S,
            "frame_period": FRAME_PERIOD_S,
            "min_move": MIN_MOVE_S,
        },
        "start_ns": START_NS,
    }


def _truth(robot: PandaSim, stamp_offset_s: float, motion_frames_hz: float) -> dict[str, Any]:
    """What a calibration should find, in ``scrapcut calibrate``'s terms (tests only)."""
    T = robot.kin.T_link8_hand @ robot.T_hand_camlink_true @ T_CAMLINK_OPTICAL
    return {
        "moving_frame": FLANGE_FRAME,
        "camera_frame": OPTICAL_FRAME,
        "T_moving_camera": np.asarray(T).tolist(),
        "time_offset_s": -stamp_offset_s,
        "stamp_offset_s": stamp_offset_s,
        "motion_frames_hz": motion_frames_hz,
    }


def _metadata(config: SimConfig, params: dict[str, Any]) -> dict[str, str]:
    return {
        "object": config.object,
        "mode": config.mode,
        "noise": config.noise,
        "paint": config.paint,
        "stroke_width_m": repr(float(config.stroke_width_m)),
        "seed": str(config.seed),
        "tool_version": __version__,
        "params": json.dumps(_strict_json(params), sort_keys=True, allow_nan=False),
    }


def _reference_metadata(visibility: LineVisibility) -> dict[str, str]:
    arcs = [[round(a, 6), round(b, 6)] for a, b in visibility.unseen_arcs()]
    return {
        "closed": "true" if visibility.closed else "false",
        "length_m": repr(round(visibility.length_m, 9)),
        "unseen_arcs": json.dumps(arcs),
    }


def _result_metadata(result: RecordResult) -> dict[str, str]:
    keys = (
        "views",
        "frames",
        "infeasible_views",
        "adjusted_views",
        "collisions",
        "motion_collisions",
        "camera_travel_m",
        "duration_s",
        "stop_reason",
    )
    return {k: str(getattr(result, k)) for k in keys}
