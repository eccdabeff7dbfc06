"""The trajectory file (``scrapcut.trajectory/v1`` JSON) and its CSV and MCAP exports.

Fixed keys (docs/design.md; add keys freely, never rename these): ``schema``, ``robot``,
``base_frame``, ``joint_names`` (7), ``T_flange_tool`` {``translation_m``,
``rotation_xyzw``}, ``points`` [{``t_s``, ``positions`` [7 rad], ``setpoint`` (index into
the path's set-points, or null)}] and ``summary``. Each point also carries ``velocities``,
``accelerations`` and its ``phase`` (approach, pierce or preheat, cut, run_out, retreat);
``setpoints`` lists every path set-point's outcome (status, reason, tilt, the tip and axis
solved for); ``limits`` the joint limits checked; ``config`` the motion parameters used.
Floats are written with Python's shortest round-trip repr.
"""

from __future__ import annotations

import csv
import datetime
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli import __version__
from scrapcut_cli._io import atomic_path, write_text_atomic
from scrapcut_cli.errors import MotionError
from scrapcut_cli.geometry import make_transform, matrix_to_quat_xyzw, quat_xyzw_to_matrix
from scrapcut_cli.motion.limits import JointLimits
from scrapcut_cli.motion.plan import PHASES, Trajectory

FloatArray = NDArray[np.float64]

SCHEMA = "scrapcut.trajectory/v1"
#: MCAP topics (base frame), for Foxglove next to the recording and the path.
MCAP_TOPICS = {
    "trajectory": "/scrapcut/joint_trajectory",  # trajectory_msgs/JointTrajectory, one message
    "tcp": "/scrapcut/tcp_path",  # nav_msgs/Path: the torch tip at every point
    "joint_states": "/joint_states",  # sensor_msgs/JointState at every point's time
}


def trajectory_to_dict(
    traj: Trajectory,
    *,
    source: Mapping[str, Any],
    limits: JointLimits,
    config: Mapping[str, Any],
    urdf: str,
    created: str | None = None,
) -> dict[str, Any]:
    """The trajectory file as a JSON-ready dictionary (``created``: ISO-8601, default now)."""
    if created is None:
        created = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    sol = traj.solution
    points = [
        {
            "t_s": float(traj.t[k]),
            "positions": _floats(traj.positions[k]),
            "velocities": _floats(traj.velocities[k]),
            "accelerations": _floats(traj.accelerations[k]),
            "setpoint": None if traj.setpoint[k] < 0 else int(traj.setpoint[k]),
            "phase": traj.phase[k],
        }
        for k in range(len(traj))
    ]
    setpoints = [
        {
            "index": i,
            "status": sol.status[i],
            "reason": sol.reason[i],
            "tilt_deg": float(np.degrees(sol.tilt_rad[i])),
            "tip": _floats(sol.tip[i]),
            "axis": _floats(sol.axis[i]),
        }
        for i in range(len(sol.status))
    ]
    return {
        "schema": SCHEMA,
        "tool_version": __version__,
        "created": created,
        "source": dict(source),
        "robot": traj.robot,
        "urdf": urdf,
        "base_frame": traj.base_frame,
        "units": "m, rad, s",
        "joint_names": list(traj.joint_names),
        "T_flange_tool": traj.mount.to_dict(),
        "tool": {
            "body_length_m": traj.mount.body_length_m,
            "body_radius_m": traj.mount.body_radius_m,
            "source": traj.mount.source,
        },
        "limits": {
            "lower_rad": _floats(limits.lower),
            "upper_rad": _floats(limits.upper),
            "velocity_rad_s": _floats(limits.velocity),
            "acceleration_rad_s2": _floats(limits.acceleration),
            "jerk_rad_s3": _floats(limits.jerk),
        },
        "points": points,
        "setpoints": setpoints,
        "summary": _clean(traj.summary),
        "config": _clean(dict(config)),
    }


def write_trajectory_file(target: str | Path, data: Mapping[str, Any]) -> None:
    """Write a trajectory dictionary as JSON, atomically (NaN/inf refused)."""
    try:
        text = json.dumps(data, indent=1, allow_nan=False)
    except ValueError as exc:
        raise MotionError(f"trajectory file: {exc}") from None
    write_text_atomic(target, text + "\n")


CSV_COLUMNS = (
    "t_s",
    "setpoint",
    "phase",
    *(f"q{j}" for j in range(1, 8)),
    *(f"dq{j}" for j in range(1, 8)),
    *(f"ddq{j}" for j in range(1, 8)),
    "x",
    "y",
    "z",
    "qx",
    "qy",
    "qz",
    "qw",
)


def write_trajectory_csv(traj: Trajectory, out: str | Path) -> None:
    """One row per point: time, set-point (empty for none), phase, joints q1-q7 (rad),
    velocities dq1-dq7, accelerations ddq1-ddq7, and the torch tip pose (m, xyzw)."""
    quats = matrix_to_quat_xyzw(traj.tool_poses[:, :3, :3])
    with atomic_path(out) as tmp, tmp.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(CSV_COLUMNS)
        for k in range(len(traj)):
            numbers = [
                *traj.positions[k],
                *traj.velocities[k],
                *traj.accelerations[k],
                *traj.tool_poses[k, :3, 3],
                *quats[k],
            ]
            writer.writerow(
                [
                    repr(float(traj.t[k])),
                    "" if traj.setpoint[k] < 0 else str(int(traj.setpoint[k])),
                    traj.phase[k],
                    *(repr(float(v)) for v in numbers),
                ]
            )


def write_trajectory_mcap(target: str | Path, traj: Trajectory, *, stamp_ns: int = 0) -> None:
    """The trajectory for Foxglove (atomic): one JointTrajectory, the torch tip as a Path, and
    /joint_states at every point's time from ``stamp_ns``."""
    from scrapcut_cli.recording.writer import McapWriter

    quats = matrix_to_quat_xyzw(traj.tool_poses[:, :3, :3])
    names = list(traj.joint_names)
    with McapWriter(target) as writer:
        writer.write_joint_trajectory(
            MCAP_TOPICS["trajectory"],
            stamp_ns,
            traj.base_frame,
            names,
            traj.t,
            traj.positions,
            traj.velocities,
            traj.accelerations,
        )
        writer.write_path(
            MCAP_TOPICS["tcp"], stamp_ns, traj.base_frame, traj.tool_poses[:, :3, 3], quats
        )
        for k in range(len(traj)):
            writer.write_joint_state(
                MCAP_TOPICS["joint_states"],
                stamp_ns + round(float(traj.t[k]) * 1e9),
                names,
                traj.positions[k],
            )


# --------------------------------------------------------------------------- reading


@dataclass(frozen=True, eq=False)
class TrajectoryFile:
    """What a trajectory file holds, validated.

    Attributes
    ----------
    t : (T,) float64, seconds, strictly increasing
    positions : (T, 7) float64, radians
    setpoint : (T,) int64, −1 for none
    phase : list of str
    base_frame : str
    joint_names : tuple of 7 str
    T_flange_tool : (4, 4) float64
    setpoint_tips, setpoint_axes : (N, 3) float64, the solved targets, base frame
    setpoint_status : list of str
    data : dict, the whole file
    """

    t: FloatArray
    positions: FloatArray
    setpoint: NDArray[np.int64]
    phase: list[str]
    base_frame: str
    joint_names: tuple[str, ...]
    T_flange_tool: FloatArray
    setpoint_tips: FloatArray
    setpoint_axes: FloatArray
    setpoint_status: list[str]
    data: dict[str, Any]


def read_trajectory_file(source: str | Path) -> TrajectoryFile:
    """Read and validate a ``scrapcut.trajectory/v1`` file; MotionError names the first
    problem."""
    source = Path(source)
    try:
        data = json.loads(source.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MotionError(f"trajectory file not found: {source}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MotionError(f"cannot read trajectory file {source}: {exc}") from None
    try:
        return _from_dict(data)
    except MotionError as exc:
        raise MotionError(f"{source}: {exc}") from None


def _from_dict(data: Any) -> TrajectoryFile:
    if not isinstance(data, dict):
        raise MotionError("expected a JSON object at the top level")
    if data.get("schema") != SCHEMA:
        raise MotionError(f"schema is {data.get('schema')!r}, this scrapcut reads {SCHEMA!r}")
    for key in ("robot", "base_frame", "joint_names", "T_flange_tool", "points"):
        if key not in data:
            raise MotionError(f"missing key {key!r}")
    names = data["joint_names"]
    if not (isinstance(names, list) and len(names) == 7 and all(isinstance(n, str) for n in names)):
        raise MotionError("joint_names must be 7 strings")
    if not isinstance(data["base_frame"], str):
        raise MotionError("base_frame must be a string")
    mount = data["T_flange_tool"]
    if not isinstance(mount, dict):
        raise MotionError("T_flange_tool must be an object")
    translation = _array([mount.get("translation_m")], 3, "T_flange_tool.translation_m")[0]
    quat = _array([mount.get("rotation_xyzw")], 4, "T_flange_tool.rotation_xyzw")[0]
    if abs(float(np.linalg.norm(quat)) - 1.0) > 1e-6:
        raise MotionError("T_flange_tool.rotation_xyzw is not a unit quaternion")
    points = data["points"]
    if not isinstance(points, list) or len(points) < 2:
        raise MotionError("points must be a list of at least 2 points")
    for i, p in enumerate(points):
        if not isinstance(p, dict) or "t_s" not in p or "positions" not in p:
            raise MotionError(f"points[{i}] must have t_s and positions")
        sp = p.get("setpoint")
        if sp is not None and (isinstance(sp, bool) or not isinstance(sp, int) or sp < 0):
            raise MotionError(f"points[{i}].setpoint must be a non-negative integer or null")
    t = _array([[p["t_s"]] for p in points], 1, "points[*].t_s")[:, 0]
    if np.any(np.diff(t) <= 0):
        i = int(np.argmax(np.diff(t) <= 0)) + 1
        raise MotionError(f"points[{i}].t_s does not increase")
    q = _array([p["positions"] for p in points], 7, "points[*].positions")
    sp_idx = np.array([-1 if p.get("setpoint") is None else p["setpoint"] for p in points])
    phase = [str(p.get("phase", "")) for p in points]
    unknown = sorted({ph for ph in phase if ph and ph not in PHASES})
    if unknown:
        raise MotionError(f"unknown point phase(s): {', '.join(unknown)}")
    sps = data.get("setpoints") or []
    if not isinstance(sps, list) or not all(isinstance(s, dict) for s in sps):
        raise MotionError("setpoints must be a list of objects")
    tips = _array([s.get("tip") for s in sps], 3, "setpoints[*].tip") if sps else np.zeros((0, 3))
    axes = _array([s.get("axis") for s in sps], 3, "setpoints[*].axis") if sps else np.zeros((0, 3))
    if len(sps) and sp_idx.max() >= len(sps):
        raise MotionError(f"a point refers to set-point {sp_idx.max()} of {len(sps)}")
    return TrajectoryFile(
        t=t,
        positions=q,
        setpoint=sp_idx.astype(np.int64),
        phase=phase,
        base_frame=data["base_frame"],
        joint_names=tuple(names),
        T_flange_tool=make_transform(quat_xyzw_to_matrix(quat), translation),
        setpoint_tips=tips,
        setpoint_axes=axes,
        setpoint_status=[str(s.get("status", "")) for s in sps],
        data=data,
    )


# --------------------------------------------------------------------------- helpers


def _floats(values: Any) -> list[float]:
    return [float(v) for v in values]


def _clean(value: Any) -> Any:
    """JSON-safe copy: numpy scalars to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _array(values: Any, width: int, name: str) -> FloatArray:
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise MotionError(f"{name} must be rows of {width} numbers") from None
    if arr.ndim != 2 or arr.shape[1] != width:
        raise MotionError(f"{name} must be rows of {width} numbers")
    if not np.all(np.isfinite(arr)):
        raise MotionError(f"{name} contains NaN or infinite values")
    return arr
