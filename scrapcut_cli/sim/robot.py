"""A Franka Panda in pybullet carrying the D435i: inverse kinematics, limits, collisions.

The arm is ``franka_panda/panda.urdf`` from ``pybullet_data`` with a fixed base at the origin
of ``panda_link0``. pybullet (DIRECT mode, no GUI) answers inverse kinematics and collision
queries; forward kinematics for /tf is evaluated in numpy from the same URDF by
:class:`scrapcut_cli.motion.panda.PandaKinematics` (vectorised over hundreds of samples per
motion, where pybullet would need a call per sample), and a test checks both agree.

Collisions are checked against one of two worlds (:class:`World`): the TRUE piece mesh, which
the oracle modes (sweep, survey) plan with and against which crashes are counted, or what the
camera has OBSERVED (``sim.observed``), all a real cell knows and all explore mode plans with.
Both include the floor, the camera housing and self-collision of the arm (the link pairs that
can touch within the joint limits, :data:`SELF_COLLISION_PAIRS`).

A requested camera pose is executed as the paper's Section IV-B describes: the optical axis is
kept, the rotation about it and the distance to the surface are the free degrees of freedom.
:meth:`PandaSim.plan_view` tries rotations about the optical axis (0, ±30°, ... 180°) at the
requested distance, then — if some of those were blocked by a collision — backs the camera off
along its axis in 25 mm steps, until inverse kinematics converges inside the joint limits with
no collision at the view nor on the way there (the straight joint-space move, or a detour
through the ready pose), or gives up with the reason of the last failure (backing off cannot
cure a pose out of reach or beyond the joint limits, so those give up at once). Its answer is
the planner contract's (``cell.ReachAnswer``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from types import TracebackType
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.cell import Reach, ReachAnswer, ReachQuery
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
#: Link pairs checked for self-collision: those that touched in at least one of 20 000 random
#: configurations within the joint limits (MoveIt Setup Assistant's sampling; seed 0). The
#: other non-adjacent pairs never did: the shoulder against the upper arm, the forearm links
#: against the hand.
SELF_COLLISION_PAIRS = tuple(
    [
        (base, tip)
        for base in ("panda_link0", "panda_link1", "panda_link2")
        for tip in (
            "panda_link5",
            "panda_link6",
            "panda_link7",
            "panda_hand",
            "panda_leftfinger",
            "panda_rightfinger",
        )
    ]
    + [
        ("panda_link5", tip)
        for tip in ("panda_link7", "panda_hand", "panda_leftfinger", "panda_rightfinger")
    ]
)
#: Joint-space step of the collision checks along a planned move (the largest joint's motion,
#: radians), about what MoveIt's default segment check uses; the margins cover the gaps.
PLAN_STEP_RAD = 0.05
#: A finer step for counting crashes against the true piece, with no margin (a link 0.8 m from
#: the joint moves 8 mm between two samples).
CRASH_STEP_RAD = 0.01
#: Clearances to the true piece are measured up to this distance (metres).
CLEARANCE_CAP_M = 0.1


class World(Enum):
    """What a collision check sees besides the robot itself and the floor."""

    #: The piece's true mesh: the oracle modes (sweep, survey) plan with it, and crashes are
    #: counted against it.
    TRUTH = "truth"
    #: The voxels the camera has observed so far (``sim.observed``): what a real cell knows,
    #: and all that explore mode plans with.
    OBSERVED = "observed"


class Contact(NamedTuple):
    """What the robot or the camera touches (``link/obstacle``, or None) and the clearance to
    the true piece, metres, at most :data:`CLEARANCE_CAP_M` (negative: into it)."""

    hit: str | None
    clearance_m: float


@dataclass(frozen=True, eq=False)
class ViewSolution:
    """How (or whether) a requested camera pose can be executed from the current joints.

    ``answer`` is the contract's answer (pose reached as the controller sees it, with the
    nominal hand-eye; free-DOF adjustment; reason); ``q`` the joint angles (7,) at the view;
    ``route`` the joint waypoints to move through, ending at ``q``: the straight joint-space
    move, or a detour through the ready pose when the straight one would hit an obstacle.
    """

    answer: ReachAnswer
    q: FloatArray | None = None
    route: tuple[FloatArray, ...] = ()

    @property
    def feasible(self) -> bool:
        return self.answer.feasible


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

    Collision checks take a :class:`World`: ``TRUTH`` (the piece's true mesh; the oracle modes
    plan with it) or ``OBSERVED`` (the voxels given to :meth:`set_observed`; the camera's
    view of the piece, all a real cell plans with). Both include the floor, self-collision and
    the camera housing, with :class:`RobotLimits`' margins. :meth:`crash` and
    :meth:`motion_crash` check the TRUE piece and floor with no margin, the housing where the
    camera really is: they count failures, they never plan.

    Parameters
    ----------
    obstacle : TriMesh
        The piece's true mesh, base frame.
    T_hand_camlink_nominal : (4, 4)
        The calibrated hand-eye transform the controller uses (and /tf_static publishes).
    T_hand_camlink_true : (4, 4), optional
        Where the camera really is (``yard``: perturbed); default the nominal one. The housing
        is placed there for ``TRUTH`` checks and crashes, at the nominal one for ``OBSERVED``.
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
        T_camlink_housing = make_transform(np.eye(3), HOUSING_CENTRE_CAMLINK)
        # The housing's pose relative to the flange, as (position, xyzw) for pybullet.
        self._link8_housing = {
            True: _pose_pair(self._T_link8_camlink_true @ T_camlink_housing),
            False: _pose_pair(self.kin.T_link8_hand @ self.T_hand_camlink @ T_camlink_housing),
        }

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
        self._joints = [*self._arm, *self._fingers]
        self._link_names = {-1: "panda_link0"}
        for j in range(c.getNumJoints(self._robot)):
            self._link_names[j] = c.getJointInfo(self._robot, j)[12].decode()
        index = {name: j for j, name in self._link_names.items()}
        self._self_pairs = [(index[a], index[b]) for a, b in SELF_COLLISION_PAIRS]
        floor_shape = c.createCollisionShape(p.GEOM_PLANE)
        self._floor = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=floor_shape)
        self._object = self._mesh_body(*_weld(obstacle))
        if self._object is None:
            raise SimError("pybullet could not build the piece's collision mesh")
        self._observed: int | None = None
        housing_shape = c.createCollisionShape(p.GEOM_BOX, halfExtents=list(HOUSING_HALF_EXTENTS))
        self._housing = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=housing_shape)
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

    def _mesh_body(self, vertices: FloatArray, faces: NDArray[np.int64]) -> int | None:
        """A static concave triangle-mesh body (None if pybullet refuses the mesh)."""
        c, p = self._client, self._p
        shape = c.createCollisionShape(
            p.GEOM_MESH,
            vertices=vertices.tolist(),
            indices=faces.reshape(-1).tolist(),
            flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
        )
        if shape < 0:
            return None
        return int(c.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape))

    def set_observed(self, vertices: ArrayLike, faces: ArrayLike) -> None:
        """Replace the observed obstacles (``World.OBSERVED``) by a triangle mesh: vertices
        (V, 3) metres, base frame, triangles (F, 3) (``ObservedScene.mesh``). Empty: none."""
        if self._observed is not None:
            self._client.removeBody(self._observed)
            self._observed = None
        V = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        if len(F) == 0:
            return
        self._observed = self._mesh_body(V, F)
        if self._observed is None:
            raise SimError("pybullet could not build the observed obstacles' collision mesh")

    # ------------------------------------------------------------------ kinematics

    def camera_pose(self, q: ArrayLike, *, true: bool = False) -> FloatArray:
        """T_base_cam (4, 4) of the optical frame at joints (7,): nominal or true hand-eye."""
        T = self.kin.flange(np.asarray(q, dtype=np.float64))
        return np.asarray(T @ (self._T_link8_cam_true if true else self._T_link8_cam))

    def camera_poses(self, q: ArrayLike, *, true: bool = False) -> FloatArray:
        """T_base_cam (S, 4, 4) at joint samples (S, 7)."""
        T = self.kin.flange(np.atleast_2d(np.asarray(q, dtype=np.float64)))
        return np.asarray(T @ (self._T_link8_cam_true if true else self._T_link8_cam))

    def set_joints(self, q: ArrayLike, *, true_camera: bool = True) -> None:
        """Place the arm at joints (7,) (fingers at their fixed opening) and the camera housing
        on the hand where it really is (``true_camera``) or where the calibration says."""
        c = self._client
        values = [[float(v)] for v in np.asarray(q, dtype=np.float64)]
        c.resetJointStatesMultiDof(
            self._robot, self._joints, [*values, [FINGER_OPENING_M], [FINGER_OPENING_M]]
        )
        state = c.getLinkState(self._robot, _FLANGE_LINK, computeForwardKinematics=True)
        position, orientation = c.multiplyTransforms(
            state[4], state[5], *self._link8_housing[true_camera]
        )
        c.resetBasePositionAndOrientation(self._housing, position, orientation)

    def solve_ik(self, T_base_cam: ArrayLike, q_seed: ArrayLike) -> tuple[FloatArray | None, Reach]:
        """Joints (7,) placing the camera at ``T_base_cam`` (and ``Reach.OK``), or (None, why).

        pybullet's damped-least-squares IK with the joint limits in its null space, restarted
        from its own answer until the flange pose is within tolerance; then from Q_READY if the
        seed led nowhere. Deterministic: every attempt starts from a reset state.
        """
        target = np.asarray(T_base_cam, dtype=np.float64) @ self._T_cam_link8
        position = target[:3, 3].tolist()
        orientation = matrix_to_quat_xyzw(target[:3, :3]).tolist()
        lim = self.limits
        reason = Reach.IK
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
                return q, Reach.OK
            reason = Reach.JOINT_LIMITS
        return None, reason

    # ------------------------------------------------------------------ collisions

    def collision(self, q: ArrayLike, *, world: World = World.TRUTH) -> str | None:
        """The first colliding pair at joints (7,), as ``link/obstacle``, or None if clear.

        With the limits' margins: the piece (``TRUTH``: ``object``) or what was observed
        (``OBSERVED``: ``observed``), the floor, the camera housing against both and the arm,
        and the arm against itself.
        """
        truth = world is World.TRUTH
        obstacle = self._object if truth else self._observed
        lim = self.limits
        return self._contact(
            q,
            obstacle=obstacle,
            name="object" if truth else "observed",
            true_camera=truth,
            object_margin_m=lim.object_margin_m,
            floor_margin_m=lim.floor_margin_m,
        )

    def crash(self, q: ArrayLike) -> Contact:
        """What the robot or the camera (where it really is) touches at joints (7,), with no
        margin: the TRUE piece or the floor; and the clearance to the true piece. Counts
        failures, never plans (self-collision is the robot's own model: planning checks it)."""
        self.set_joints(q)
        c = self._client
        cap = CLEARANCE_CAP_M
        hit: str | None = None
        clearance = cap
        for body, name in ((self._robot, None), (self._housing, "camera")):
            for point in c.getClosestPoints(body, self._object, cap):
                distance = float(point[8])
                if distance <= 0.0 and hit is None:
                    hit = f"{name or self._link_names[point[3]]}/object"
                clearance = min(clearance, distance)
        if hit is None:
            for point in c.getClosestPoints(self._robot, self._floor, 0.0):
                if point[3] not in _NO_FLOOR_CHECK:
                    hit = f"{self._link_names[point[3]]}/floor"
                    break
        if hit is None and c.getClosestPoints(self._housing, self._floor, 0.0):
            hit = "camera/floor"
        return Contact(hit, clearance)

    def _contact(
        self,
        q: ArrayLike,
        *,
        obstacle: int | None,
        name: str,
        true_camera: bool,
        object_margin_m: float,
        floor_margin_m: float,
    ) -> str | None:
        self.set_joints(q, true_camera=true_camera)
        c = self._client
        if obstacle is not None:
            for point in c.getClosestPoints(self._robot, obstacle, object_margin_m):
                return f"{self._link_names[point[3]]}/{name}"
        for point in c.getClosestPoints(self._robot, self._floor, floor_margin_m):
            if point[3] not in _NO_FLOOR_CHECK:
                return f"{self._link_names[point[3]]}/floor"
        if obstacle is not None and c.getClosestPoints(self._housing, obstacle, object_margin_m):
            return f"camera/{name}"
        if c.getClosestPoints(self._housing, self._floor, floor_margin_m):
            return "camera/floor"
        for point in c.getClosestPoints(self._housing, self._robot, 0.0):
            if point[4] in _HOUSING_VS_ARM:
                return f"camera/{self._link_names[point[4]]}"
        for a, b in self._self_pairs:
            if c.getClosestPoints(self._robot, self._robot, 0.0, a, b):
                return f"{self._link_names[a]}/{self._link_names[b]}"
        return None

    def path_collision(
        self,
        q_from: ArrayLike,
        q_to: ArrayLike,
        *,
        world: World = World.TRUTH,
        step_rad: float = PLAN_STEP_RAD,
    ) -> str | None:
        """First collision (with margins, in ``world``) along the straight joint-space path,
        checked every ``step_rad`` of the largest joint's motion (the ends excluded)."""
        for q in _joint_samples(q_from, q_to, step_rad)[1:-1]:
            hit = self.collision(q, world=world)
            if hit is not None:
                return hit
        return None

    def motion_crash(
        self, q_from: ArrayLike, q_to: ArrayLike, *, step_rad: float = CRASH_STEP_RAD
    ) -> Contact:
        """:meth:`crash` along the straight joint-space path, sampled every ``step_rad``, both
        ends included: the first contact, and the smallest clearance on the way."""
        hit: str | None = None
        clearance = CLEARANCE_CAP_M
        for q in _joint_samples(q_from, q_to, step_rad):
            contact = self.crash(q)
            hit = hit or contact.hit
            clearance = min(clearance, contact.clearance_m)
        return Contact(hit, clearance)

    # ------------------------------------------------------------------ views

    def route(
        self, q_from: ArrayLike, q_to: ArrayLike, *, world: World = World.TRUTH
    ) -> tuple[tuple[FloatArray, ...] | None, str | None]:
        """(joint waypoints from ``q_from`` to ``q_to``, None) or (None, what blocks them).

        The straight joint-space move, or, when it would sweep the arm through an obstacle (a
        jump to the line's other end over a ridge), a detour through the ready pose above it:
        no motion planner, but the two moves an operator would teach.
        """
        target = np.asarray(q_to, dtype=np.float64)
        blocked = self.path_collision(q_from, target, world=world)
        if blocked is None:
            return (target,), None
        ready = np.asarray(Q_READY, dtype=np.float64)
        clear = (
            self.collision(ready, world=world) is None
            and self.path_collision(q_from, ready, world=world) is None
            and self.path_collision(ready, target, world=world) is None
        )
        return ((ready, target), None) if clear else (None, blocked)

    def reachable(
        self, query: ReachQuery, q_seed: ArrayLike, *, world: World = World.TRUTH
    ) -> ReachAnswer:
        """The contract's answer to ``query`` from joints ``q_seed`` (7,), in ``world``."""
        return self.plan_view(
            query.T_base_cam, q_seed, free_dofs=query.free_dofs, world=world
        ).answer

    def plan_view(
        self,
        T_base_cam: ArrayLike,
        q_seed: ArrayLike,
        *,
        free_dofs: bool = True,
        world: World = World.TRUTH,
        check_motion: bool = True,
    ) -> ViewSolution:
        """Execute a requested view from joints ``q_seed``, using the free DOFs (roll, back-off)
        if it is infeasible as asked; collisions (and, with ``check_motion``, the move there)
        checked in ``world``."""
        requested = np.asarray(T_base_cam, dtype=np.float64)
        lim = self.limits
        rolls = lim.roll_steps_deg if free_dofs else (0.0,)
        n_back = int(np.floor(lim.max_backoff_m / lim.backoff_step_m + 1e-9)) if free_dofs else 0
        attempts = 0
        reason, detail = Reach.IK, ""
        for k in range(n_back + 1):
            backoff = k * lim.backoff_step_m
            blocked = False
            for roll_deg in rolls:
                attempts += 1
                candidate = requested @ _roll_and_back_off(np.radians(roll_deg), backoff)
                q, why = self.solve_ik(candidate, q_seed)
                if q is None:
                    reason, detail = why, ""
                    continue
                hit = self.collision(q, world=world)
                if hit is not None:
                    reason, detail = Reach.COLLISION, hit
                    blocked = True
                    continue
                route: tuple[FloatArray, ...] = (q,)
                if check_motion:
                    waypoints, stop = self.route(q_seed, q, world=world)
                    if waypoints is None:
                        reason, detail = Reach.MOTION, stop or ""
                        blocked = True
                        continue
                    route = waypoints
                answer = ReachAnswer(
                    True,
                    Reach.OK,
                    T_base_cam=self.camera_pose(q),
                    roll_rad=float(np.radians(roll_deg)),
                    backoff_m=backoff,
                    attempts=attempts,
                )
                return ViewSolution(answer, q, route)
            if not blocked:
                # Backing off helps against collisions, not against reach or joint limits.
                break
        return ViewSolution(ReachAnswer(False, reason, detail, attempts=attempts))


def _joint_samples(q_from: ArrayLike, q_to: ArrayLike, step_rad: float) -> FloatArray:
    """Joint samples (n + 1, 7) along the straight path, ends included, no joint moving more
    than ``step_rad`` between two."""
    a = np.asarray(q_from, dtype=np.float64)
    b = np.asarray(q_to, dtype=np.float64)
    n = max(int(np.ceil(np.max(np.abs(b - a)) / step_rad)), 1)
    return np.asarray(a + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a))


def _pose_pair(T: FloatArray) -> tuple[list[float], list[float]]:
    """(position, quaternion xyzw) lists of a (4, 4) transform, as pybullet takes poses."""
    return T[:3, 3].tolist(), matrix_to_quat_xyzw(T[:3, :3]).tolist()


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
