"""A Franka Panda in pybullet carrying the D435i: inverse kinematics, limits, collisions.

The arm is ``franka_panda/panda.urdf`` from ``pybullet_data`` with a fixed base at the origin
of ``panda_link0``. pybullet (DIRECT mode, no GUI) answers inverse kinematics and collision
queries against the TRUE piece mesh and the floor; forward kinematics for /tf is evaluated in
numpy from the same URDF by :class:`scrapcut_cli.motion.panda.PandaKinematics` (vectorised over
hundreds of samples per motion, where pybullet would need a call per sample), and a test checks
both agree.

A requested camera pose is executed as the paper's Section IV-B describes: the optical axis is
kept, the rotation about it and the distance to the surface are the free degrees of freedom.
:meth:`PandaSim.plan_view` tries rotations about the optical axis (0, ±30°, ... 180°) at the
requested distance, then — if some of those were blocked by a collision — backs the camera off
along its axis in 25 mm steps, until inverse kinematics converges inside the joint limits with
no collision, or gives up with the reason of the last failure (backing off cannot cure a pose
out of reach or beyond the joint limits, so those give up at once).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import (
    invert_transform,
    make_transform,
    matrix_to_quat_xyzw,
    rotation_angle,
)

# The chain lives in motion/ (planning never imports the simulator); the names the recorder
# uses are re-exported here.
from scrapcut_cli.motion.panda import (
    ARM_JOINTS,
    PandaKinematics,
    default_urdf_path,
)
from scrapcut_cli.motion.panda import LINK_NAMES as LINK_NAMES
from scrapcut_cli.motion.panda import Q_READY as Q_READY
from scrapcut_cli.sim._pybullet import pybullet, quiet_stdout
from scrapcut_cli.sim.camera import (
    HOUSING_CENTRE_CAMLINK,
    HOUSING_HALF_EXTENTS,
    T_CAMLINK_OPTICAL,
)
from scrapcut_cli.sim.mesh import TriMesh

FloatArray = NDArray[np.float64]

FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
FINGER_OPENING_M = 0.02

#: pybullet link indices (joint index = child link index; the base is -1)
_FLANGE_LINK = 7
_NO_FLOOR_CHECK = (-1, 0)  # panda_link0 stands on the floor; link1 is the column above it
_HOUSING_VS_ARM = (-1, 0, 1, 2, 3, 4)  # the camera may hit the arm up to panda_link5


@dataclass(frozen=True, eq=False)
class ViewSolution:
    """How (or whether) a requested camera pose can be executed.

    ``T_base_cam`` is the pose the robot reaches as the controller sees it (nominal hand-eye);
    ``q`` the joint angles (7,); ``roll_rad`` and ``backoff_m`` the free-DOF adjustment used;
    ``reason`` is ``ok`` or why the last attempt failed (``ik``, ``joint_limits``,
    ``collision:<link>/<obstacle>``).
    """

    feasible: bool
    T_base_cam_requested: FloatArray
    T_base_cam: FloatArray | None
    q: FloatArray | None
    roll_rad: float
    backoff_m: float
    attempts: int
    reason: str


@dataclass(frozen=True)
class RobotLimits:
    """Safety margins and solver tolerances (metres, radians).

    Margins are assumed clearances for a scanning motion: 10 mm to the piece, 20 mm to the
    floor (the arm's collision meshes are convex hulls, already a little fat), 0.02 rad inside
    the URDF joint limits. The IK tolerance (0.2 mm, 0.11°) is far below the D435i's noise.
    """

    object_margin_m: float = 0.010
    floor_margin_m: float = 0.020
    joint_margin_rad: float = 0.02
    ik_position_tol_m: float = 2e-4
    ik_rotation_tol_rad: float = 2e-3
    ik_rounds: int = 12
    roll_steps_deg: tuple[float, ...] = (
        0.0,
        30.0,
        -30.0,
        60.0,
        -60.0,
        90.0,
        -90.0,
        120.0,
        -120.0,
        150.0,
        -150.0,
        180.0,
    )
    backoff_step_m: float = 0.025
    max_backoff_m: float = 0.15


class PandaSim:
    """The Panda, the piece and the floor in a pybullet DIRECT world (close it, or use ``with``).

    Parameters
    ----------
    obstacle : TriMesh
        The piece's true mesh, base frame.
    T_hand_camlink_nominal : (4, 4)
        The calibrated hand-eye transform the controller uses (and /tf_static publishes).
    T_hand_camlink_true : (4, 4), optional
        Where the camera really is (``yard``: perturbed); default the nominal one. Collisions
        of the camera housing use it.
    limits : RobotLimits
        Margins and solver settings.
    """

    def __init__(
        self,
        obstacle: TriMesh,
        *,
        T_hand_camlink_nominal: ArrayLike,
        T_hand_camlink_true: ArrayLike | None = None,
        limits: RobotLimits | None = None,
    ) -> None:
        self.kin = PandaKinematics()
        self.limits = limits or RobotLimits()
        self.T_hand_camlink = np.asarray(T_hand_camlink_nominal, dtype=np.float64)
        self.T_hand_camlink_true = (
            self.T_hand_camlink
            if T_hand_camlink_true is None
            else np.asarray(T_hand_camlink_true, dtype=np.float64)
        )
        self._T_link8_cam = self.kin.T_link8_hand @ self.T_hand_camlink @ T_CAMLINK_OPTICAL
        self._T_cam_link8 = invert_transform(self._T_link8_cam)
        self._T_link8_camlink_true = self.kin.T_link8_hand @ self.T_hand_camlink_true
        self._T_link8_cam_true = self._T_link8_camlink_true @ T_CAMLINK_OPTICAL

        p = pybullet()
        from pybullet_utils.bullet_client import BulletClient  # type: ignore[import-untyped]

        with quiet_stdout():
            self._client: Any = BulletClient(connection_mode=p.DIRECT)
            self._robot = self._client.loadURDF(
                str(default_urdf_path()), useFixedBase=True, flags=p.URDF_USE_INERTIA_FROM_FILE
            )
        c = self._client
        self._p = p
        self._arm = [self._joint_index(n) for n in ARM_JOINTS]
        self._fingers = [self._joint_index(n) for n in FINGER_JOINTS]
        self._movable = [
            j for j in range(c.getNumJoints(self._robot)) if c.getJointInfo(self._robot, j)[2] != 4
        ]
        self._link_names = {-1: "panda_link0"}
        for j in range(c.getNumJoints(self._robot)):
            self._link_names[j] = c.getJointInfo(self._robot, j)[12].decode()
        floor_shape = c.createCollisionShape(p.GEOM_PLANE)
        self._floor = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=floor_shape)
        vertices, faces = _weld(obstacle)
        mesh_shape = c.createCollisionShape(
            p.GEOM_MESH,
            vertices=vertices.tolist(),
            indices=faces.reshape(-1).tolist(),
            flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
        )
        if mesh_shape < 0:
            raise SimError("pybullet could not build the piece's collision mesh")
        self._object = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=mesh_shape)
        housing_shape = c.createCollisionShape(p.GEOM_BOX, halfExtents=list(HOUSING_HALF_EXTENTS))
        self._housing = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=housing_shape)
        self._T_camlink_housing = make_transform(np.eye(3), HOUSING_CENTRE_CAMLINK)
        lower = [*self.kin.lower, 0.0, 0.0]
        upper = [*self.kin.upper, 0.04, 0.04]
        self._ik_limits = {
            "lowerLimits": lower,
            "upperLimits": upper,
            "jointRanges": [u - lo for lo, u in zip(lower, upper, strict=True)],
            "restPoses": [*Q_READY, FINGER_OPENING_M, FINGER_OPENING_M],
        }
        self._closed = False
        self.set_joints(Q_READY)

    # ------------------------------------------------------------------ lifecycle

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._client.disconnect()

    def __enter__(self) -> PandaSim:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _joint_index(self, name: str) -> int:
        c = self._client
        for j in range(c.getNumJoints(self._robot)):
            if c.getJointInfo(self._robot, j)[1].decode() == name:
                return j
        raise SimError(f"panda.urdf in pybullet has no joint {name}")

    # ------------------------------------------------------------------ kinematics

    def camera_pose(self, q: ArrayLike, *, true: bool = False) -> FloatArray:
        """T_base_cam (4, 4) of the optical frame at joints (7,): nominal or true hand-eye."""
        T = self.kin.flange(np.asarray(q, dtype=np.float64))
        return np.asarray(T @ (self._T_link8_cam_true if true else self._T_link8_cam))

    def camera_poses(self, q: ArrayLike, *, true: bool = False) -> FloatArray:
        """T_base_cam (S, 4, 4) at joint samples (S, 7)."""
        T = self.kin.flange(np.atleast_2d(np.asarray(q, dtype=np.float64)))
        return np.asarray(T @ (self._T_link8_cam_true if true else self._T_link8_cam))

    def set_joints(self, q: ArrayLike) -> None:
        """Place the arm at joints (7,) (fingers at their fixed opening) and the housing."""
        c = self._client
        for j, v in zip(self._arm, np.asarray(q, dtype=np.float64), strict=True):
            c.resetJointState(self._robot, j, float(v))
        for j in self._fingers:
            c.resetJointState(self._robot, j, FINGER_OPENING_M)
        T = self.kin.flange(q) @ self._T_link8_camlink_true @ self._T_camlink_housing
        c.resetBasePositionAndOrientation(
            self._housing, T[:3, 3].tolist(), matrix_to_quat_xyzw(T[:3, :3]).tolist()
        )

    def solve_ik(self, T_base_cam: ArrayLike, q_seed: ArrayLike) -> tuple[FloatArray | None, str]:
        """Joints (7,) placing the camera at ``T_base_cam``, or (None, reason).

        pybullet's damped-least-squares IK with the joint limits in its null space, restarted
        from its own answer until the flange pose is within tolerance; then from Q_READY if the
        seed led nowhere. Deterministic: every attempt starts from a reset state.
        """
        target = np.asarray(T_base_cam, dtype=np.float64) @ self._T_cam_link8
        position = target[:3, 3].tolist()
        orientation = matrix_to_quat_xyzw(target[:3, :3]).tolist()
        lim = self.limits
        reason = "ik"
        for seed in (np.asarray(q_seed, dtype=np.float64), np.asarray(Q_READY)):
            q = seed.copy()
            previous = np.inf
            converged = False
            # The null-space pull towards the rest pose keeps a natural elbow but leaves a few
            # millimetres of error; plain damped least squares from there converges exactly.
            # A pose out of reach stalls at the nearest reachable one: stop when no round gains.
            for k in range(lim.ik_rounds):
                self.set_joints(q)
                extra = self._ik_limits if k == 0 else {}
                sol = self._client.calculateInverseKinematics(
                    self._robot,
                    _FLANGE_LINK,
                    position,
                    orientation,
                    maxNumIterations=100,
                    residualThreshold=1e-7,
                    **extra,
                )
                q = np.asarray(sol[:7], dtype=np.float64)
                T = self.kin.flange(q)
                dp = float(np.linalg.norm(T[:3, 3] - target[:3, 3]))
                dr = rotation_angle(T[:3, :3], target[:3, :3])
                converged = dp < lim.ik_position_tol_m and dr < lim.ik_rotation_tol_rad
                if converged:
                    break
                error = dp + 0.1 * dr  # metres; 0.1 m lever for the rotation
                if k >= 2 and error > 0.9 * previous:
                    break  # stalled: out of reach from this seed
                previous = error
            if not converged:
                continue
            if self.kin.within_limits(q, lim.joint_margin_rad):
                return q, "ok"
            reason = "joint_limits"
        return None, reason

    # ------------------------------------------------------------------ collisions

    def collision(self, q: ArrayLike) -> str | None:
        """The first colliding pair at joints (7,), as ``link/obstacle``, or None if clear."""
        self.set_joints(q)
        c = self._client
        lim = self.limits
        for point in c.getClosestPoints(self._robot, self._object, lim.object_margin_m):
            return f"{self._link_names[point[3]]}/object"
        for point in c.getClosestPoints(self._robot, self._floor, lim.floor_margin_m):
            if point[3] not in _NO_FLOOR_CHECK:
                return f"{self._link_names[point[3]]}/floor"
        if c.getClosestPoints(self._housing, self._object, lim.object_margin_m):
            return "camera/object"
        if c.getClosestPoints(self._housing, self._floor, lim.floor_margin_m):
            return "camera/floor"
        for point in c.getClosestPoints(self._housing, self._robot, 0.0):
            if point[4] in _HOUSING_VS_ARM:
                return f"camera/{self._link_names[point[4]]}"
        return None

    def path_collision(
        self, q_from: ArrayLike, q_to: ArrayLike, *, step_rad: float = 0.05
    ) -> str | None:
        """First collision along the straight joint-space path, checked every ``step_rad``."""
        a = np.asarray(q_from, dtype=np.float64)
        b = np.asarray(q_to, dtype=np.float64)
        n = max(int(np.ceil(np.max(np.abs(b - a)) / step_rad)), 1)
        for t in np.linspace(0.0, 1.0, n + 1)[1:-1]:
            hit = self.collision(a + t * (b - a))
            if hit is not None:
                return hit
        return None

    # ------------------------------------------------------------------ views

    def reachable(self, T_base_cam: ArrayLike, q_seed: ArrayLike | None = None) -> bool:
        """True if the camera can be placed exactly at ``T_base_cam`` without collision."""
        q, _ = self.solve_ik(T_base_cam, Q_READY if q_seed is None else q_seed)
        return q is not None and self.collision(q) is None

    def plan_view(
        self, T_base_cam: ArrayLike, q_seed: ArrayLike, *, free_dofs: bool = True
    ) -> ViewSolution:
        """Execute a requested view, using the free DOFs (roll, back-off) if it is infeasible."""
        requested = np.asarray(T_base_cam, dtype=np.float64)
        lim = self.limits
        rolls = lim.roll_steps_deg if free_dofs else (0.0,)
        n_back = int(np.floor(lim.max_backoff_m / lim.backoff_step_m + 1e-9)) if free_dofs else 0
        attempts = 0
        reason = "ik"
        for k in range(n_back + 1):
            backoff = k * lim.backoff_step_m
            blocked = False
            for roll_deg in rolls:
                attempts += 1
                candidate = requested @ _roll_and_back_off(np.radians(roll_deg), backoff)
                q, why = self.solve_ik(candidate, q_seed)
                if q is None:
                    reason = why
                    continue
                hit = self.collision(q)
                if hit is not None:
                    reason = f"collision:{hit}"
                    blocked = True
                    continue
                return ViewSolution(
                    True,
                    requested,
                    self.camera_pose(q),
                    q,
                    float(np.radians(roll_deg)),
                    backoff,
                    attempts,
                    "ok",
                )
            if not blocked:
                # Backing off helps against collisions, not against reach or joint limits.
                break
        return ViewSolution(False, requested, None, None, 0.0, 0.0, attempts, reason)


def _roll_and_back_off(roll_rad: float, backoff_m: float) -> FloatArray:
    """Camera-frame motion: turn about the optical axis, then step back along it."""
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    return make_transform([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], (0.0, 0.0, -backoff_m))


def _weld(mesh: TriMesh) -> tuple[FloatArray, NDArray[np.int64]]:
    """Shared vertices for collision (the render mesh duplicates them along creases)."""
    keys = np.round(mesh.vertices / 1e-7).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return mesh.vertices[first], inverse.reshape(-1)[mesh.faces]


def joint_names() -> Sequence[str]:
    """Names in /joint_states: the seven arm joints, then the two fingers."""
    return (*ARM_JOINTS, *FINGER_JOINTS)
