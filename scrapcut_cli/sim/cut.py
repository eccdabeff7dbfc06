"""Playing a joint trajectory on the simulated Panda: tracking, limits, true collisions.

:func:`simulate_cut` runs the trajectory the way a joint-trajectory controller would execute
it: the points are interpolated by quintics through their positions, velocities and
accelerations (``motion.timing.quintic_hermite``) and commanded every ``time_step_s`` to
pybullet's joint position controller (with Franka's joint torque limits, 87 / 12 Nm, as the
motor forces) on the URDF's Panda under gravity. What the arm actually did is measured:

- the torch tip's deviation from every set-point it passes (position and axis angle), from
  the simulated joint angles through the torch mount ``T_flange_tool``;
- how close each joint came to its limits;
- collisions (``check_period_s``) of the arm's links and the torch (the planner's model: a
  capsule of the trajectory's torch radius and length ending at the nozzle tip, then a holder
  to the flange) with the piece's TRUE mesh and the floor,
  in a second, kinematic pybullet world, when the recording came from the simulator (the piece
  is rebuilt from the recording's metadata). The planner never saw that mesh: it planned
  against the observed surface; this is the check of that plan against the truth.

The hand and fingers of pybullet's Panda stay on the flange (the torch replaces them in a
cutting cell): their mass is part of the dynamics, their shapes are not checked.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.geometry import matrix_to_quat_xyzw
from scrapcut_cli.motion.panda import PandaKinematics, default_urdf_path
from scrapcut_cli.motion.timing import quintic_hermite
from scrapcut_cli.motion.tool import HOLDER_RADIUS_M
from scrapcut_cli.sim._pybullet import pybullet, quiet_stdout
from scrapcut_cli.sim.mesh import TriMesh

FloatArray = NDArray[np.float64]

#: Franka's joint torque limits (datasheet, "Limits for Panda"), N·m: the motor forces.
TAU_MAX = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
#: Links of pybullet's panda.urdf not checked: the base and column (they stand on the floor)
#: for the floor; the hand, fingers and grasp frame (the torch replaces them) for everything.
_NOT_VS_FLOOR = ("panda_link0", "panda_link1")
_REPLACED = ("panda_hand", "panda_leftfinger", "panda_rightfinger", "panda_grasptarget")
#: The torch's clearance to the piece is measured up to this distance, metres (farther costs
#: much more on a concave mesh, and the torch works 8 mm off the surface).
_CLEARANCE_M = 0.015


@dataclass(frozen=True)
class CutSimSettings:
    """Simulation step and collision-check period (s), position-controller gains."""

    time_step_s: float = 0.001
    check_period_s: float = 0.05
    position_gain: float = 0.3
    velocity_gain: float = 1.0


@dataclass(frozen=True, eq=False)
class CutSimResult:
    """What the simulated arm did.

    Attributes
    ----------
    tip_error_m, axis_error_rad : (K,) float64
        At each trajectory point that is a set-point: the simulated torch tip's distance from
        the set-point's target tip, and the angle between the torch axes.
    planned_tip_error_m : (K,) float64
        The same for the commanded joints (the plan's own accuracy).
    tracking_error_rad : (7,) float64
        Largest |commanded − simulated| joint angle.
    joint_margin_rad : (7,) float64
        Smallest distance of the simulated joints to their limits.
    collisions : list of dict
        ``{"body", "obstacle", "first_t_s", "checks"}`` per colliding pair, obstacle
        ``piece`` or ``floor`` (without a true piece only the floor is checked).
    clearance_m : dict
        ``torch``: the torch's smallest distance to the true piece, up to 15 mm (None:
        farther, or no piece); ``arm``: 0.0 when a link touched the piece, else None (the
        arm's distances are not measured, only its contacts).
    """

    tip_error_m: FloatArray
    axis_error_rad: FloatArray
    planned_tip_error_m: FloatArray
    tracking_error_rad: FloatArray
    joint_margin_rad: FloatArray
    collisions: list[dict[str, Any]]
    clearance_m: dict[str, float | None]
    checks: int
    steps: int
    piece: str | None
    info: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures."""

        def stats(values: FloatArray, scale: float) -> dict[str, float | None]:
            if len(values) == 0:
                return {"max": None, "mean": None}
            return {"max": float(values.max() * scale), "mean": float(values.mean() * scale)}

        return {
            "piece": self.piece,
            "setpoints_checked": int(self.info.get("setpoints", len(self.tip_error_m))),
            "tip_error_mm": stats(self.tip_error_m, 1000.0),
            "axis_error_deg": stats(self.axis_error_rad, 180.0 / np.pi),
            "planned_tip_error_mm": stats(self.planned_tip_error_m, 1000.0),
            "tracking_error_max_rad": float(self.tracking_error_rad.max()),
            "joint_margin_min_rad": float(self.joint_margin_rad.min()),
            "joint_margin_rad": [float(v) for v in self.joint_margin_rad],
            "collisions": self.collisions,
            "collision_count": len(self.collisions),
            "clearance_mm": {
                k: (None if v is None else 1000.0 * v) for k, v in self.clearance_m.items()
            },
            "collision_checks": self.checks,
            "steps": self.steps,
            **self.info,
        }


def simulate_cut(
    t: NDArray[np.float64],
    positions: NDArray[np.float64],
    velocities: NDArray[np.float64] | None,
    accelerations: NDArray[np.float64] | None,
    *,
    setpoint: NDArray[np.int64],
    setpoint_tips: NDArray[np.float64],
    setpoint_axes: NDArray[np.float64],
    T_flange_tool: NDArray[np.float64],
    torch_radius_m: float,
    torch_length_m: float = 0.15,
    piece: TriMesh | None = None,
    piece_name: str | None = None,
    floor_z_m: float = 0.0,
    settings: CutSimSettings | None = None,
) -> CutSimResult:
    """Play trajectory points (``t`` (T,), joints (T, 7), optional velocities and
    accelerations) on pybullet's Panda and measure it (see the module docstring).

    ``setpoint`` (T,) marks points at set-points (−1 elsewhere); ``setpoint_tips`` and
    ``setpoint_axes`` (N, 3) are the targets, base frame; ``piece`` the true mesh (base frame)
    or None.
    """
    st = settings or CutSimSettings()
    q_pts = np.asarray(positions, dtype=np.float64)
    tt = np.asarray(t, dtype=np.float64)
    v_pts = _derivative(tt, q_pts) if velocities is None else np.asarray(velocities, float)
    a_pts = _derivative(tt, v_pts) if accelerations is None else np.asarray(accelerations, float)
    fine = np.arange(tt[0], tt[-1] + 0.5 * st.time_step_s, st.time_step_s)
    q_cmd = quintic_hermite(tt, q_pts, v_pts, a_pts, fine)
    qd_cmd = np.gradient(q_cmd, st.time_step_s, axis=0)

    kin = PandaKinematics()
    p = pybullet()
    from pybullet_utils.bullet_client import BulletClient  # type: ignore[import-untyped]

    with quiet_stdout():
        dyn: Any = BulletClient(connection_mode=p.DIRECT)
        check: Any = BulletClient(connection_mode=p.DIRECT)
    try:
        q_sim = _run_dynamics(dyn, p, q_cmd, qd_cmd, st)
        k_check = np.unique(
            np.concatenate(
                [
                    np.arange(0, len(fine), max(round(st.check_period_s / st.time_step_s), 1)),
                    [len(fine) - 1],
                ]
            )
        )
        collisions, clearance = _check_collisions(
            check,
            p,
            q_sim[k_check],
            fine[k_check],
            T_flange_tool,
            torch_radius_m,
            torch_length_m,
            piece,
            floor_z_m,
        )
    finally:
        dyn.disconnect()
        check.disconnect()

    # Tracking at the set-points.
    at = np.flatnonzero(np.asarray(setpoint) >= 0)
    k_at = np.clip(np.round((tt[at] - tt[0]) / st.time_step_s).astype(int), 0, len(fine) - 1)
    idx = np.asarray(setpoint)[at]
    T_sim = kin.flange(q_sim[k_at].reshape(-1, 7)) @ T_flange_tool
    T_cmd = kin.flange(q_pts[at].reshape(-1, 7)) @ T_flange_tool
    tips = np.asarray(setpoint_tips, dtype=np.float64)[idx]
    axes = np.asarray(setpoint_axes, dtype=np.float64)[idx]
    tip_err = np.linalg.norm(T_sim[:, :3, 3] - tips, axis=1)
    cos = np.clip(np.einsum("ij,ij->i", T_sim[:, :3, 2], axes), -1.0, 1.0)
    planned = np.linalg.norm(T_cmd[:, :3, 3] - tips, axis=1)
    margin = np.min(np.minimum(q_sim - kin.lower, kin.upper - q_sim), axis=0)
    return CutSimResult(
        tip_error_m=tip_err,
        axis_error_rad=np.arccos(cos),
        planned_tip_error_m=planned,
        tracking_error_rad=np.max(np.abs(q_sim - q_cmd), axis=0),
        joint_margin_rad=margin,
        collisions=collisions,
        clearance_m=clearance,
        checks=len(k_check),
        steps=len(fine),
        piece=piece_name,
        info={
            "setpoints": len(np.unique(idx)),
            "time_step_s": st.time_step_s,
            "check_period_s": st.check_period_s,
            "duration_s": float(tt[-1] - tt[0]),
        },
    )


def _derivative(t: FloatArray, values: FloatArray) -> FloatArray:
    return np.asarray(np.gradient(values, t, axis=0))


def _run_dynamics(
    c: Any, p: Any, q_cmd: FloatArray, qd_cmd: FloatArray, st: CutSimSettings
) -> FloatArray:
    """Simulated joint angles (F, 7) under position control of the commands."""
    with quiet_stdout():
        robot = c.loadURDF(
            str(default_urdf_path()), useFixedBase=True, flags=p.URDF_USE_INERTIA_FROM_FILE
        )
    c.setGravity(0.0, 0.0, -9.81)
    c.setTimeStep(st.time_step_s)
    arm = list(range(7))
    for j, q in zip(arm, q_cmd[0], strict=True):
        c.resetJointState(robot, j, float(q), 0.0)
    # The URDF's joint damping and the default velocity motors would fight the controller.
    for j in range(c.getNumJoints(robot)):
        c.changeDynamics(robot, j, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0)
    kp = [st.position_gain] * 7
    kd = [st.velocity_gain] * 7
    out = np.empty_like(q_cmd)
    for k in range(len(q_cmd)):
        c.setJointMotorControlArray(
            robot,
            arm,
            p.POSITION_CONTROL,
            targetPositions=q_cmd[k].tolist(),
            targetVelocities=qd_cmd[k].tolist(),
            forces=list(TAU_MAX),
            positionGains=kp,
            velocityGains=kd,
        )
        c.stepSimulation()
        out[k] = [s[0] for s in c.getJointStates(robot, arm)]
    return out


def _check_collisions(
    c: Any,
    p: Any,
    q: FloatArray,
    times: FloatArray,
    T_flange_tool: FloatArray,
    torch_radius_m: float,
    torch_length_m: float,
    piece: TriMesh | None,
    floor_z_m: float,
) -> tuple[list[dict[str, Any]], dict[str, float | None]]:
    """Colliding pairs and the clearances along the simulated joint samples."""
    with quiet_stdout():
        robot = c.loadURDF(str(default_urdf_path()), useFixedBase=True)
    names = {-1: "panda_link0"}
    for j in range(c.getNumJoints(robot)):
        names[j] = c.getJointInfo(robot, j)[12].decode()
    checked = [j for j in names if names[j] not in _REPLACED]
    floor = c.createMultiBody(
        baseMass=0,
        baseCollisionShapeIndex=c.createCollisionShape(p.GEOM_PLANE),
        basePosition=[0.0, 0.0, floor_z_m],
    )
    obstacles = {"floor": floor}
    if piece is not None:
        vertices, faces = _weld(piece)
        shape = c.createCollisionShape(
            p.GEOM_MESH,
            vertices=vertices.tolist(),
            indices=faces.reshape(-1).tolist(),
            flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
        )
        obstacles["piece"] = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape)
    tools = _torch_bodies(c, p, T_flange_tool, torch_radius_m, torch_length_m)
    kin = PandaKinematics()
    flanges = kin.flange(q)
    hits: dict[tuple[str, str], dict[str, Any]] = {}
    clearance: dict[str, float | None] = {"arm": None, "torch": None}
    for k in range(len(q)):
        for j, v in enumerate(q[k]):
            c.resetJointState(robot, j, float(v))
        for body_id, _, T_flange_body in tools:
            T = flanges[k] @ T_flange_body
            c.resetBasePositionAndOrientation(
                body_id, T[:3, 3].tolist(), matrix_to_quat_xyzw(T[:3, :3]).tolist()
            )
        for what, body in obstacles.items():
            for pt in c.getClosestPoints(robot, body, 0.0):
                link = int(pt[3])
                if link not in checked or (what == "floor" and names[link] in _NOT_VS_FLOOR):
                    continue
                _record(hits, clearance, "arm", names[link], what, float(pt[8]), times[k])
            for body_id, name, _ in tools:
                for pt in c.getClosestPoints(body_id, body, _CLEARANCE_M):
                    _record(hits, clearance, "torch", name, what, float(pt[8]), times[k])
    return list(hits.values()), clearance


def _torch_bodies(
    c: Any, p: Any, T_flange_tool: FloatArray, radius: float, length: float
) -> list[tuple[int, str, FloatArray]]:
    """The torch as the planner models it (``motion.collision``): a capsule of the body's
    radius whose rounded end is the nozzle tip (nozzles taper), ``length`` long, then the
    holder (a cylinder) back to the flange. (body id, name, T_flange_body) each."""
    tip = T_flange_tool[:3, 3]
    z = T_flange_tool[:3, 2]
    out: list[tuple[int, str, FloatArray]] = []

    def place(centre: FloatArray) -> FloatArray:
        T = np.eye(4)
        T[:3, :3] = _z_to(z)
        T[:3, 3] = centre
        return T

    straight = max(length - radius, 1e-4)  # the capsule's cylinder, between its sphere centres
    capsule = c.createCollisionShape(p.GEOM_CAPSULE, radius=radius, height=straight)
    centre = tip - z * (radius + 0.5 * straight)
    out.append(
        (c.createMultiBody(baseMass=0, baseCollisionShapeIndex=capsule), "torch", place(centre))
    )
    back = tip - z * length
    rest = float(np.dot(back, z))  # how far the holder runs on towards the flange
    if rest > 1e-3:
        holder = c.createCollisionShape(p.GEOM_CYLINDER, radius=HOLDER_RADIUS_M, height=rest)
        out.append(
            (
                c.createMultiBody(baseMass=0, baseCollisionShapeIndex=holder),
                "holder",
                place(back - 0.5 * rest * z),
            )
        )
    return out


def _record(
    hits: dict[tuple[str, str], dict[str, Any]],
    clearance: dict[str, float | None],
    group: str,
    body: str,
    obstacle: str,
    distance: float,
    t: float,
) -> None:
    if obstacle == "piece":
        old = clearance[group]
        clearance[group] = distance if old is None else min(old, distance)
    if distance > 0.0:
        return
    key = (body, obstacle)
    if key not in hits:
        hits[key] = {"body": body, "obstacle": obstacle, "first_t_s": float(t), "checks": 0}
    hits[key]["checks"] += 1


def _z_to(direction: FloatArray) -> FloatArray:
    """A rotation (3, 3) whose z axis is the unit ``direction``."""
    z = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _weld(mesh: TriMesh) -> tuple[FloatArray, NDArray[np.int64]]:
    """Shared vertices for a concave collision mesh (the render mesh duplicates them)."""
    keys = np.round(mesh.vertices / 1e-7).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return mesh.vertices[first], inverse.reshape(-1)[mesh.faces]
