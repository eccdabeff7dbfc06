"""The contract between a next-view planner and whoever moves the camera (simulator or replay).

The simulator's recorder loop is::

    decision = planner.start()                 # first view (the worker's initial segment)
    while not decision.stop:
        frame = capture_at(decision.T_base_cam)  # move the robot, render, record
        decision = planner.observe(frame)

A planner never touches pybullet or files; it may ask ``reachable(T_base_cam)`` (given at
construction by the simulator, or answered from recorded views in replay) whether a camera pose
can be executed without collision.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.recording.frame import Frame

#: Answers whether the camera can be placed at ``T_base_cam`` (IK solution, no collision).
Reachability = Callable[[NDArray[np.float64]], bool]


@dataclass(frozen=True, eq=False)
class Decision:
    """What the planner wants next.

    ``T_base_cam`` is the next camera pose (optical frame, base frame) unless ``stop`` is set;
    ``reason`` is a short machine-friendly word: why this view (``initial``, ``extrapolate``,
    ``look_past``), why a direction ended (``endpoint``, ``revisit``, ``no_feasible_view``,
    ``paint_lost``, ``fit_failed``: on the return to the initial view, whose ``info["action"]``
    is ``return``, or on the stop) or why the run stopped (``done``, ``budget``); ``info``
    carries the step's log entry (written as JSON on /scrapcut/exploration).
    """

    T_base_cam: NDArray[np.float64] | None
    reason: str
    stop: bool = False
    info: dict[str, Any] = field(default_factory=dict)


class ViewPlanner(Protocol):
    """A deterministic next-view planner (Algorithm 1 or a pre-planned sequence)."""

    def start(self) -> Decision:
        """The first view."""
        ...

    def observe(self, frame: Frame) -> Decision:
        """Take the frame captured at the last decided pose; return the next decision."""
        ...
