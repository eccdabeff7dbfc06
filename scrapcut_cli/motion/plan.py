"""From a cutting path to a joint trajectory: the recipe of ``scrapcut trajectory``.

:func:`plan_trajectory` does, in order:

1. the set-points' inverse kinematics, continuously, from the best of a few start postures,
   tilting where needed (:mod:`~.follow`), collision-checked against the observed surface and
   the floor (:mod:`~.collision`);
2. the run-out past the far edge (when the path's summary chose one), the approach to the
   first set-point and the retreat from the last, each along the torch axis;
3. timing (:mod:`~.timing`): approach at the travel speed, the dwell at the first set-point
   (pierce, or preheat at an edge: the path's first time stamp), the cut at the path's
   speeds, the retreat; every move rest to rest within the planning share of the limits;
4. sampling: points every ``sample_period_s`` plus one at every set-point, with velocities
   and accelerations, so a controller's quintic interpolation reproduces the motion;
5. checks on what was sampled: tip and axis errors at the set-points, joint limits by finite
   differences of the interpolated points, collisions at every point.
"""

from __future__ import annotations

import itertools
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.config import MotionConfig, validate_section
from scrapcut_cli.errors import MotionError
from scrapcut_cli.geometry import quat_xyzw_to_matrix
from scrapcut_cli.motion.collision import CollisionChecker, CollisionSettings
from scrapcut_cli.motion.follow import (
    COLLISION,
    REACHED,
    TILTED,
    UNREACHABLE,
    FollowSettings,
    PathFollower,
    PathSolution,
)
from scrapcut_cli.motion.ik import TorchIk
from scrapcut_cli.motion.limits import PLANNING_SHARE, JointLimits, panda_limits
from scrapcut_cli.motion.panda import ARM_JOINTS, PandaKinematics
from scrapcut_cli.motion.timing import (
    LimitCheck,
    MoveProfile,
    TimedMove,
    check_sampled,
    time_move,
)
from scrapcut_cli.motion.tool import TorchMount
from scrapcut_cli.motion.transit import TransitSettings, plan_transit, segment_samples
from scrapcut_cli.toolpath.path import CuttingPath

FloatArray = NDArray[np.float64]

#: Point phases.
PHASES = ("approach", "pierce", "preheat", "cut", "run_out", "retreat", "transit")


@dataclass(frozen=True)
class CutEnds:
    """How the cut starts and finishes: ``start`` ``pierce`` | ``edge``; ``finish`` ``stop``
    | ``run_out``."""

    start: str = "pierce"
    finish: str = "stop"

    @classmethod
    def from_summary(cls, summary: dict[str, Any]) -> CutEnds:
        """From a path summary's ``ends`` (toolpath.ends); pierce and stop when absent."""
        ends = summary.get("ends")
        if not isinstance(ends, dict):
            return cls()
        start = ends.get("start", {})
        finish = ends.get("finish", {})
        s = start.get("kind") if isinstance(start, dict) else None
        f = finish.get("kind") if isinstance(finish, dict) else None
        return cls(
            start="edge" if s == "edge" else "pierce",
            finish="run_out" if f == "run_out" else "stop",
        )


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A joint trajectory and how it was made.

    Attributes
    ----------
    t : (T,) float64
        Seconds from the start (at rest at the approach pose).
    positions, velocities, accelerations : (T, 7) float64
        rad, rad/s, rad/s² of ``joint_names``.
    setpoint : (T,) int64
        Index of the path's set-point a point is at, −1 for none.
    phase : list of str
        One of :data:`PHASES` per point.
    tool_poses : (T, 4, 4) float64
        T_base_tool (torch tip) at every point, base frame.
    solution : PathSolution
        Per set-point outcome.
    summary : dict
        JSON-ready figures (see :func:`plan_trajectory`).
    """

    t: FloatArray
    positions: FloatArray
    velocities: FloatArray
    accelerations: FloatArray
    setpoint: NDArray[np.int64]
    phase: list[str]
    tool_poses: FloatArray
    solution: PathSolution
    mount: TorchMount
    base_frame: str
    joint_names: tuple[str, ...] = ARM_JOINTS
    robot: str = "panda"
    summary: dict[str, Any] = field(default_factory=dict)
    limit_check: LimitCheck | None = None

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class _Segment:
    """Sampled points of one part of the trajectory, times from its own start."""

    t: FloatArray
    q: FloatArray
    qd: FloatArray
    qdd: FloatArray
    setpoint: NDArray[np.int64]
    phase: list[str]


def plan_trajectory(
    path: CuttingPath,
    *,
    base_frame: str,
    surface_base: ArrayLike | None,
    mount: TorchMount,
    config: MotionConfig | None = None,
    unseen_base: ArrayLike | None = None,
    kin: PandaKinematics | None = None,
    collision_min_points: int = 3,
) -> Trajectory:
    """The joint trajectory that cuts ``path`` (see the module docstring).

    Parameters
    ----------
    path : CuttingPath
        Set-points in the base frame (``base_frame`` = the URDF's ``panda_link0``); its
        ``info`` (the path summary) says how the cut starts and finishes.
    surface_base : (M, 3) float64, metres, base frame, optional
        The observed surface the arm and torch must clear (None: the floor only).
    unseen_base : (K, 3) float64, metres, base frame, optional
        Centres of the voxels near the piece the camera never saw (``motion.observed``),
        avoided as well.
    mount : TorchMount
        ``T_flange_tool`` and the torch body.
    config : MotionConfig
        Tilts, moves, timing and clearances.
    kin : PandaKinematics
        The chain (default: the bundled URDF).

    Raises
    ------
    MotionError
        When no set-point can be reached at all.
    """
    cfg = config or MotionConfig()
    validate_section(cfg, "motion")
    if len(path) == 0:
        raise MotionError("the path has no set-points")
    kin = kin or PandaKinematics(cfg.urdf)
    limits = panda_limits(kin.lower, kin.upper)
    ik = TorchIk(kin, mount.T_flange_tool, limits)
    checker = CollisionChecker(
        kin,
        mount,
        surface_base,
        CollisionSettings(
            link_margin_m=cfg.link_margin_m,
            floor_margin_m=cfg.floor_margin_m,
            floor_z_m=cfg.floor_z_m,
            min_points=collision_min_points,
            voxel_m=cfg.collision_voxel_m,
        ),
        unseen_base=unseen_base,
    )
    follower = PathFollower(
        ik,
        checker,
        FollowSettings(
            max_tilt_deg=cfg.max_tilt_deg,
            tilt_steps=cfg.tilt_steps,
            tilt_directions=cfg.tilt_directions,
            max_joint_step_rad=cfg.max_joint_step_rad,
        ),
    )
    ends = CutEnds.from_summary(path.info)

    # 1. set-points
    axes = quat_xyzw_to_matrix(path.orientations_xyzw)[:, :, 2]
    solution = follower.follow_best(path.positions, axes, path.surface_points)
    ok = np.flatnonzero(solution.ok)
    if len(ok) == 0:
        reasons = Counter(r for r in solution.reason if r)
        raise MotionError(
            "no set-point of the path is reachable by the Panda "
            f"({', '.join(f'{k}: {v}' for k, v in reasons.most_common())})"
        )

    # 2.-3. one cut per run of consecutive reachable set-points: approach, dwell, cut (and the
    # run-out past a far edge), retreat; a transit in joint space between runs. The torch never
    # cuts across set-points it cannot reach: it retreats and pierces again after them.
    plan_limits = limits.scaled(cfg.limit_share)
    profile = MoveProfile(cfg.accel_time_s, cfg.jerk_time_s)
    cuts = np.flatnonzero((np.diff(ok) > 1) | np.isin(ok[1:], solution.breaks)) + 1
    runs = np.split(ok, cuts)
    segments: list[_Segment] = []
    scales: dict[str, float] = {}
    lengths = {"approach_m": np.inf, "retreat_m": np.inf, "run_out_m": 0.0}
    raw = path.info.get("pierce_s")
    pierce_s = float(raw) if isinstance(raw, int | float) and raw > 0 else float(path.time[0])
    transit_hits = 0
    transits_searched = 0
    q_prev_end: FloatArray | None = None
    cut_move: TimedMove | None = None
    for k, run in enumerate(runs):
        edge_start = ends.start == "edge" and int(run[0]) == 0
        run_out = ends.finish == "run_out" and int(run[-1]) == len(path) - 1
        parts, run_info = _plan_run(
            path,
            solution,
            run,
            follower,
            ik,
            cfg,
            plan_limits,
            profile,
            dwell_s=float(path.time[0]) if edge_start or k == 0 else pierce_s,
            dwell_phase="preheat" if edge_start else "pierce",
            run_out=run_out,
        )
        if q_prev_end is not None:
            transit, hits_in_transit, searched = _transit(
                q_prev_end, parts[0].q[0], checker, cfg, plan_limits, profile, seed=k
            )
            transit_hits += hits_in_transit
            transits_searched += int(searched)
            segments.append(transit)
        segments.extend(parts)
        q_prev_end = parts[-1].q[-1]
        for name, value in run_info["scales"].items():
            scales[name] = max(scales.get(name, 1.0), value)
        lengths["approach_m"] = min(lengths["approach_m"], run_info["approach_m"])
        lengths["retreat_m"] = min(lengths["retreat_m"], run_info["retreat_m"])
        lengths["run_out_m"] = max(lengths["run_out_m"], run_info["run_out_m"])
        cut_move = run_info["cut_move"] or cut_move
    dwell = float(path.time[0])

    # 4. one time line
    t, q, qd, qdd, sp, phase = _concatenate(segments)
    poses = ik.tool_poses(q)

    # 5. checks
    check = check_sampled(t, q, qd, qdd, limits)
    hits = checker.check(q)
    summary = _summary(
        path,
        solution,
        ik,
        check,
        hits,
        t,
        phase,
        ends=ends,
        dwell=dwell,
        scales=scales,
        cut_move=cut_move,
        lengths={k: float(v) for k, v in lengths.items()},
        cut_segments=len(runs),
        transit_hits=transit_hits,
        transits_searched=transits_searched,
        checker=checker,
        limits=limits,
        limit_share=cfg.limit_share,
    )
    return Trajectory(
        t=t,
        positions=q,
        velocities=qd,
        accelerations=qdd,
        setpoint=sp,
        phase=phase,
        tool_poses=poses,
        solution=solution,
        mount=mount,
        base_frame=base_frame,
        summary=summary,
        limit_check=check,
    )


# --------------------------------------------------------------------------- pieces


def _plan_run(
    path: CuttingPath,
    sol: PathSolution,
    run: NDArray[np.intp],
    follower: PathFollower,
    ik: TorchIk,
    cfg: MotionConfig,
    plan_limits: JointLimits,
    profile: MoveProfile,
    *,
    dwell_s: float,
    dwell_phase: str,
    run_out: bool,
) -> tuple[list[_Segment], dict[str, Any]]:
    """Approach, dwell, cut (+ run-out), retreat of one run of consecutive set-points."""
    first, last = int(run[0]), int(run[-1])
    q_first, q_last = sol.q[first], sol.q[last]
    run_out_q, run_out_s = np.zeros((0, 7)), np.zeros(0)
    if run_out and cfg.run_out_m > 0:
        tangent = _end_tangent(path.surface_points, sol.axis[last])
        if tangent is not None:
            run_out_q, run_out_s = _line_waypoints(
                follower,
                sol.tip[last],
                tangent,
                sol.axis[last],
                q_last,
                cfg.run_out_m,
                cfg.waypoint_spacing_m,
            )
    q_end = run_out_q[-1] if len(run_out_q) else q_last
    T_end = ik.tool_poses(q_end)[0]
    approach_q, approach_s = _line_waypoints(
        follower,
        sol.tip[first],
        -sol.axis[first],
        sol.axis[first],
        q_first,
        cfg.approach_m,
        cfg.waypoint_spacing_m,
    )
    retreat_q, retreat_s = _line_waypoints(
        follower,
        T_end[:3, 3],
        -T_end[:3, 2],
        T_end[:3, 2],
        q_end,
        cfg.retreat_m,
        cfg.waypoint_spacing_m,
    )
    parts: list[_Segment] = []
    scales: dict[str, float] = {}

    def travel(knots_q: FloatArray, knots_s: FloatArray, phase: str) -> _Segment:
        move = time_move(
            knots_q,
            knots_s,
            np.full(len(knots_s) - 1, cfg.travel_speed_m_s),
            plan_limits,
            profile=profile,
        )
        scales[phase] = move.time_scale
        return _sample(move, cfg.sample_period_s, phase)

    if len(approach_q):
        knots_s = np.concatenate([[0.0], approach_s[-1] - approach_s[::-1][1:], [approach_s[-1]]])
        seg = travel(np.vstack([approach_q[::-1], q_first]), knots_s, "approach")
        seg.setpoint[-1] = first
        seg.phase[-1] = dwell_phase  # arrived: the dwell starts
        parts.append(seg)
    n_dwell = 2 if dwell_s > 0 else 1
    parts.append(
        _Segment(
            np.array([0.0, dwell_s])[:n_dwell],
            np.tile(q_first, (n_dwell, 1)),
            np.zeros((n_dwell, 7)),
            np.zeros((n_dwell, 7)),
            np.full(n_dwell, first, dtype=np.int64),
            [dwell_phase] * n_dwell,
        )
    )
    cut_move = None
    cut_q = np.vstack([sol.q[run], run_out_q])
    if len(cut_q) >= 2:
        arc = path.arc_length[run] - path.arc_length[first]
        speeds = np.diff(arc) / np.maximum(np.diff(path.time[run]), 1e-9)
        cut_s = np.concatenate([arc, arc[-1] + run_out_s])
        cut_speeds = np.concatenate([speeds, np.full(len(run_out_s), float(path.speed[last]))])
        cut_move = time_move(cut_q, cut_s, cut_speeds, plan_limits, profile=profile)
        scales["cut"] = cut_move.time_scale
        seg = _sample(cut_move, cfg.sample_period_s, "cut")
        index = np.concatenate([run, np.full(len(run_out_s), -1)])
        phases = ["cut"] * len(run) + ["run_out"] * len(run_out_s)
        parts.append(_with_knots(seg, cut_move, cut_move.knot_times(), index, phases))
    if len(retreat_q):
        parts.append(
            travel(np.vstack([q_end, retreat_q]), np.concatenate([[0.0], retreat_s]), "retreat")
        )
    info = {
        "scales": scales,
        "cut_move": cut_move,
        "approach_m": float(approach_s[-1]) if len(approach_s) else 0.0,
        "retreat_m": float(retreat_s[-1]) if len(retreat_s) else 0.0,
        "run_out_m": float(run_out_s[-1]) if len(run_out_s) else 0.0,
    }
    return parts, info


#: Waypoint spacing (radians, largest joint) of a transit's joint path: the shape-preserving
#: spline through collinear waypoints is the straight segment, so the timed move leaves the
#: checked polyline only within one spacing of its corners (it is checked again, densely).
_TRANSIT_KNOT_RAD = 0.05


def _transit(
    q_from: FloatArray,
    q_to: FloatArray,
    checker: CollisionChecker,
    cfg: MotionConfig,
    plan_limits: JointLimits,
    profile: MoveProfile,
    seed: int,
) -> tuple[_Segment, int, bool]:
    """A joint-space move between two cuts around the observed scene (:mod:`~.transit`: the
    straight line when clear, else RRT-Connect seeded with ``seed``), the number of its
    densely checked configurations that still collide (with the observed surface, the unseen
    space or the floor), and whether a search was needed."""
    distance = float(np.max(np.abs(q_to - q_from)))
    if distance < 1e-9:
        return (
            _Segment(
                np.array([0.0]),
                q_from[None],
                np.zeros((1, 7)),
                np.zeros((1, 7)),
                np.full(1, -1, dtype=np.int64),
                ["transit"],
            ),
            0,
            False,
        )

    def collides(q: FloatArray) -> NDArray[np.bool_]:
        return np.array([h is not None for h in checker.check(q)], dtype=bool)

    settings = TransitSettings()
    polyline = plan_transit(
        q_from,
        q_to,
        collides,
        plan_limits.lower,
        plan_limits.upper,
        np.random.default_rng(seed),
        settings,
    )
    searched = polyline is not None and len(polyline) > 2
    if polyline is None:  # no clear path found: the straight line, its collisions counted
        polyline = np.vstack([q_from, q_to])
    knots = np.vstack(
        [polyline[0]]
        + [segment_samples(a, b, _TRANSIT_KNOT_RAD)[1:] for a, b in itertools.pairwise(polyline)]
    )
    s_knots = np.concatenate([[0.0], np.cumsum(np.max(np.abs(np.diff(knots, axis=0)), axis=1))])
    move = time_move(
        knots,
        s_knots,
        np.full(len(knots) - 1, cfg.transit_speed_rad_s),
        plan_limits,
        profile=profile,
    )
    fine = np.linspace(
        0.0, s_knots[-1], max(int(np.ceil(s_knots[-1] / settings.check_step_rad)), 1) + 1
    )
    hits = int(np.count_nonzero(collides(np.asarray(move.spline(fine)))))
    return _sample(move, cfg.sample_period_s, "transit"), hits, searched


def _end_tangent(surface_points: FloatArray, axis: FloatArray) -> FloatArray | None:
    """Unit direction (3,) of the path at its last set-point, across the torch axis."""
    if len(surface_points) < 2:
        return None
    d = surface_points[-1] - surface_points[max(len(surface_points) - 3, 0)]
    d = d - np.dot(d, axis) * axis
    n = float(np.linalg.norm(d))
    return None if n < 1e-9 else d / n


def _line_waypoints(
    follower: PathFollower,
    start_tip: FloatArray,
    direction: FloatArray,
    axis: FloatArray,
    q_start: FloatArray,
    length: float,
    spacing: float,
) -> tuple[FloatArray, FloatArray]:
    """Joints (K, 7) and distances (K,) of tips moving from ``start_tip`` along ``direction``
    with a fixed torch ``axis``; stops before the first unreachable or colliding waypoint."""
    n = max(int(np.ceil(length / spacing)), 1)
    distances = np.linspace(0.0, length, n + 1)[1:]
    qs, ds = [], []
    q = q_start
    for d in distances:
        r, _, _ = follower._try(
            start_tip + d * direction, axis, q, follower.settings.max_joint_step_rad
        )
        if r is None:
            break
        q = r.q
        qs.append(q)
        ds.append(d)
    return (np.array(qs).reshape(-1, 7), np.array(ds))


def _sample(move: TimedMove, period: float, phase: str) -> _Segment:
    times = np.union1d(np.arange(0.0, move.duration_s, period), [move.duration_s])
    q, qd, qdd = move.state(times)
    return _Segment(
        times, q, qd, qdd, np.full(len(times), -1, dtype=np.int64), [phase] * len(times)
    )


def _with_knots(
    seg: _Segment,
    move: TimedMove,
    knot_t: FloatArray,
    index: NDArray[np.int64],
    phases: list[str],
) -> _Segment:
    """Add a point at every waypoint (positions exactly the waypoint's joints)."""
    q, qd, qdd = move.state(knot_t)
    q = move.positions_at_knots()
    keep = ~np.isin(np.round(seg.t, 9), np.round(knot_t, 9))
    t = np.concatenate([seg.t[keep], knot_t])
    order = np.argsort(t, kind="stable")
    phase_all = [p for p, k in zip(seg.phase, keep, strict=True) if k] + phases
    # Samples after the last set-point belong to the run-out.
    last_cut = knot_t[len(phases) - phases[::-1].index("cut") - 1] if "cut" in phases else 0.0
    phase_all = [
        "run_out" if (p == "cut" and tt > last_cut + 1e-9) else p
        for p, tt in zip(phase_all, t, strict=True)
    ]
    return _Segment(
        t[order],
        np.vstack([seg.q[keep], q])[order],
        np.vstack([seg.qd[keep], qd])[order],
        np.vstack([seg.qdd[keep], qdd])[order],
        np.concatenate([seg.setpoint[keep], index])[order],
        [phase_all[i] for i in order],
    )


def _concatenate(
    segments: list[_Segment],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.int64], list[str]]:
    """One time line; each segment's first point is dropped where it repeats the previous
    segment's last (same state, at rest)."""
    ts, qs, qds, qdds, sps, phases = [], [], [], [], [], []
    offset = 0.0
    for k, seg in enumerate(segments):
        start = 1 if k > 0 and len(seg.t) > 1 else 0
        if k > 0 and len(seg.t) == 1:
            continue
        ts.append(seg.t[start:] + offset)
        qs.append(seg.q[start:])
        qds.append(seg.qd[start:])
        qdds.append(seg.qdd[start:])
        sps.append(seg.setpoint[start:])
        phases.extend(seg.phase[start:])
        offset += float(seg.t[-1])
    return (
        np.concatenate(ts),
        np.vstack(qs),
        np.vstack(qds),
        np.vstack(qdds),
        np.concatenate(sps),
        phases,
    )


def _summary(
    path: CuttingPath,
    sol: PathSolution,
    ik: TorchIk,
    check: LimitCheck,
    hits: list[str | None],
    t: FloatArray,
    phase: list[str],
    *,
    ends: CutEnds,
    dwell: float,
    scales: dict[str, float],
    cut_move: TimedMove | None,
    lengths: dict[str, float],
    checker: CollisionChecker,
    limits: JointLimits,
    limit_share: float,
    cut_segments: int,
    transit_hits: int,
    transits_searched: int = 0,
) -> dict[str, Any]:
    n = len(path)
    ok = sol.ok
    counts = Counter(sol.status)
    tip_err = axis_err = 0.0
    path_axis = quat_xyzw_to_matrix(path.orientations_xyzw)[:, :, 2]
    if ok.any():
        T = ik.tool_poses(sol.q[ok])
        tip_err = float(np.max(np.linalg.norm(T[:, :3, 3] - sol.tip[ok], axis=1)))
        cos = np.clip(np.einsum("ij,ij->i", T[:, :3, 2], sol.axis[ok]), -1.0, 1.0)
        axis_err = float(np.degrees(np.max(np.arccos(cos))))
        reached = np.array([s == REACHED for s in sol.status])
        if reached.any():
            Tr = ik.tool_poses(sol.q[reached])
            cos_r = np.einsum("ij,ij->i", Tr[:, :3, 2], path_axis[reached])
            axis_err = max(axis_err, float(np.degrees(np.max(np.arccos(np.clip(cos_r, -1, 1))))))
    margin = check.position_margin_rad
    worst = int(np.argmin(margin))
    colliding = [h for h in hits if h is not None]
    flagged = [
        {"setpoint": i, "status": sol.status[i], "reason": sol.reason[i]}
        for i in range(n)
        if sol.status[i] in (UNREACHABLE, COLLISION)
    ]
    cut_phases = {"cut", "run_out"}
    cut_times = [tt for tt, p in zip(t, phase, strict=True) if p in cut_phases]
    return {
        "setpoints": n,
        "reached": int(counts.get(REACHED, 0)),
        "tilted": int(counts.get(TILTED, 0)),
        "unreachable": int(counts.get(UNREACHABLE, 0)),
        "in_collision": int(counts.get(COLLISION, 0)),
        "executable_share": float(ok.mean()),
        "reasons": dict(Counter(r for r in sol.reason if r).most_common()),
        "flagged": flagged,
        "max_tilt_used_deg": float(np.degrees(sol.tilt_rad.max())) if n else 0.0,
        "flips_avoided": int(sol.flips_avoided),
        "posture_changes": list(sol.breaks),
        "start": ends.start,
        "finish": ends.finish,
        "dwell_s": dwell,
        **lengths,
        "duration_s": float(t[-1]),
        "cut_duration_s": float(cut_times[-1] - cut_times[0]) if cut_times else 0.0,
        "cut_speed_scale": 1.0 / scales.get("cut", 1.0),
        "time_scales": {k: float(v) for k, v in scales.items()},
        "points": len(t),
        "tip_error_max_mm": tip_err * 1000.0,
        "axis_error_max_deg": axis_err,
        "joint_limit_margin_min_rad": float(margin[worst]),
        "joint_limit_margin_joint": ARM_JOINTS[worst],
        "velocity_ratio_max": float(check.velocity_ratio.max()),
        "acceleration_ratio_max": float(check.acceleration_ratio.max()),
        "jerk_ratio_max": float(check.jerk_ratio.max()),
        "limits": "Franka datasheet (motion.limits)",
        "limit_share_planned": float(limit_share),
        "limits_ok": bool(check.ok),
        "cut_segments": cut_segments,
        "transits_around_obstacles": transits_searched,
        "transit_collision_samples": transit_hits,
        "trajectory_collisions": len(colliding) + transit_hits,
        "trajectory_collision_bodies": dict(Counter(colliding).most_common()),
        "observed_points": len(checker.points),
        "unseen_voxels": len(checker.unseen),
        "floor_z_m": float(checker.settings.floor_z_m),
        "executable": bool(ok.all() and check.ok and not colliding and not transit_hits),
        "planning_share_default": PLANNING_SHARE,
    }
