"""The contract between a next-view planner and the robot cell that moves the camera.

Written for whoever drives a camera with a planner: scrapcut's simulator (``sim.recorder``), a
replay of a recorded run (``exploration.replay``), or a driver for a real arm (a ROS node
around MoveIt, say). Neither ``sim/`` nor ``exploration/`` owns this module; both import it,
neither imports the other, and the ``record`` command wires a planner into the simulator.

The loop a cell runs::

    planner = make_planner(PlannerContext(camera, start_view, reachable, paint))
    decision = planner.start()                     # the worker's start view
    while not decision.stop:
        move the camera to decision.T_base_cam     # or, if impossible: planner.skip(reason)
        frame = capture()                          # a recording.Frame, exactly as read back
        decision = planner.observe(frame)

What a planner is given, and nothing else:

* **Frames** as a reader of the recording returns them (:class:`~scrapcut_cli.recording.frame.
  Frame`): colour, depth, intrinsics, the camera pose from the robot's joint encoders and the
  calibrated hand-eye transform. Nothing a real cell cannot know — no true pose, no object
  name, no mesh, no reference curve.
* **A** :class:`PlannerContext`: the camera model, the start view (where the worker pointed
  the robot: near the painted line, not exactly on it), the paint the worker used, and
  ``reachable``.
* **Answers to reachability queries** (:class:`ReachQuery` → :class:`ReachAnswer`): can the
  camera be placed at this pose, from where the robot is now? A cell answers from what it
  knows: inverse kinematics within the joint limits, self-collision, the floor or table, and
  collision with what its camera has observed so far. A MoveIt-based driver would answer with
  its IK solver and its planning scene, whose octomap is built from the same depth stream (the
  occupancy map monitor): the cell observes the frames it captures itself, so a query does not
  carry the planner's own map. The cell must never answer from knowledge of the piece it could
  not have (the simulator keeps the true mesh only to count crashes afterwards).

Decisions and answers are deterministic functions of the frames and answers seen so far, so a
recorded run can be replayed by answering the logged queries (``scrapcut explore``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.recording.frame import CameraModel, Frame

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Decision:
    """What the planner wants next.

    Attributes
    ----------
    T_base_cam : (4, 4) float64 or None
        The next camera pose (optical frame, in the base frame), None when ``stop`` is set.
    reason : str
        A short machine-friendly word: why this view (``initial``, ``extrapolate``,
        ``look_past``), why a direction ended (``endpoint``, ``revisit``, ``no_feasible_view``,
        ``paint_lost``, ``fit_failed``) or why the run stopped (``done``, ``budget``).
    stop : bool
        The run is over.
    info : mapping
        The step's log entry, JSON-ready; its schema is the planner's (Algorithm 1 writes
        ``scrapcut.exploration/v1``). The cell records it and never interprets it.
    """

    T_base_cam: FloatArray | None
    reason: str
    stop: bool = False
    info: Mapping[str, Any] = field(default_factory=dict)


class ViewPlanner(Protocol):
    """A deterministic next-view planner (Algorithm 1, or a pre-planned list of views)."""

    def start(self) -> Decision:
        """The first view."""
        ...

    def observe(self, frame: Frame) -> Decision:
        """Take the frame captured at the last decided pose; return the next decision."""
        ...


@runtime_checkable
class SkippingPlanner(Protocol):
    """A planner that can be told its last view could not be executed (pre-planned sweeps).

    A cell that cannot execute a decision calls ``skip`` if the planner has it, and otherwise
    stops the run with the reason.
    """

    def skip(self, reason: str) -> Decision: ...


class Reach(Enum):
    """Why a camera pose can or cannot be executed."""

    OK = "ok"
    IK = "ik"  # inverse kinematics found no solution (out of reach)
    JOINT_LIMITS = "joint_limits"  # only solutions outside the joint limits
    COLLISION = "collision"  # the robot or camera would touch an obstacle at the pose
    MOTION = "motion"  # the pose is clear, but no collision-free move gets there
    NO_RECORD = "no_record"  # a replay has no recorded answer or frame for the pose

    @classmethod
    def parse(cls, text: str) -> tuple[Reach, str]:
        """(reason, detail) of an :meth:`ReachAnswer.describe` string; unknown reasons are
        ``NO_RECORD`` with the text as detail."""
        head, _, detail = text.partition(":")
        try:
            return cls(head), detail
        except ValueError:
            return cls.NO_RECORD, text


@dataclass(frozen=True, eq=False)
class ReachQuery:
    """Can the camera be placed at ``T_base_cam``, from the robot's current configuration?

    Attributes
    ----------
    T_base_cam : (4, 4) float64
        Requested camera pose (optical frame, base frame, metres).
    free_dofs : bool
        May the cell turn the camera about its optical axis and back it off along it (the
        paper's free degrees of freedom of a view)? False: exactly this pose or nothing.
    """

    T_base_cam: FloatArray
    free_dofs: bool = False


@dataclass(frozen=True, eq=False)
class ReachAnswer:
    """A cell's answer to a :class:`ReachQuery`.

    Attributes
    ----------
    feasible : bool
        The camera can be placed there and the robot can move there without collision.
    reason : Reach
        ``Reach.OK``, or why not (the last failure met while searching the free DOFs).
    detail : str
        What collided (``panda_link5/observed``, ``camera/floor``), or empty.
    T_base_cam : (4, 4) float64 or None
        Where the camera would be, as the robot's controller sees it (the requested pose, turned
        and backed off by ``roll_rad`` and ``backoff_m``); None when infeasible.
    roll_rad, backoff_m : float
        The free-DOF adjustment used: rotation about the optical axis (radians) and distance
        moved back along it (metres).
    attempts : int
        Poses tried (free-DOF search).
    """

    feasible: bool
    reason: Reach
    detail: str = ""
    T_base_cam: FloatArray | None = None
    roll_rad: float = 0.0
    backoff_m: float = 0.0
    attempts: int = 1

    def describe(self) -> str:
        """``ok``, ``ik``, ``collision:panda_hand/observed``... (for logs and messages)."""
        return self.reason.value if not self.detail else f"{self.reason.value}:{self.detail}"


#: Answers reachability queries (the cell's IK and collision model, or recorded answers).
Reachability = Callable[[ReachQuery], ReachAnswer]


@dataclass(frozen=True, eq=False)
class PlannerContext:
    """What a closed-loop planner is given by the cell at the start of a run.

    Attributes
    ----------
    camera : CameraModel
        The colour camera (depth is aligned to it).
    start_view : (4, 4) float64
        ``T_base_cam`` where the worker pointed the robot: the initial segment of the line is in
        view, but the pose is the worker's, not a view computed from the line.
    reachable : Reachability
        The cell's answer to "can the camera go there from here?".
    paint : str
        The paint preset the worker marked the line with (``perception.paint.PAINT_PRESETS``).
    base_frame : str
        TF frame of every pose (REP-105: the robot's base).
    """

    camera: CameraModel
    start_view: FloatArray
    reachable: Reachability
    paint: str
    base_frame: str = "panda_link0"


PlannerFactory = Callable[[PlannerContext], ViewPlanner]
