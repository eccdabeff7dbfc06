"""Camera poses for the planner: look at a target along a direction, at a distance, with a roll.

A view is fixed by the paper's four constraints: the optical axis along the inverse surface
normal at the target (three DOF with the target), the distance to the target (searched from the
camera's minimum upward) and the rotation about the optical axis (free, searched too). Here the
image x axis starts along the line's direction (the line runs across the wide image axis) and
turns by ``roll``. Base frame z is up (REP-103); a view is raised to a minimum elevation above
its target, as an operator keeps the arm above the piece.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.geometry import make_transform, orthonormal_frame

FloatArray = NDArray[np.float64]

UP = np.array([0.0, 0.0, 1.0])


def unit(vector: ArrayLike) -> FloatArray:
    """``vector`` (3,) scaled to unit length (raises ValueError on a zero vector)."""
    v = np.asarray(vector, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(v))
    if not n > 1e-12:
        raise ValueError("cannot normalise a zero vector")
    return np.asarray(v / n)


def tilt_up(direction: ArrayLike, min_elevation_deg: float) -> FloatArray:
    """``direction`` (3,) unit, raised in its vertical plane to at least ``min_elevation_deg``.

    A direction already high enough is returned unchanged; a horizontal or downward one keeps
    its azimuth (straight down: +x is used) and gets exactly the minimum elevation.
    """
    n = unit(direction)
    min_el = np.radians(min_elevation_deg)
    if np.arcsin(np.clip(n[2], -1.0, 1.0)) >= min_el:
        return n
    horizontal = np.array([n[0], n[1], 0.0])
    h = float(np.linalg.norm(horizontal))
    horizontal = horizontal / h if h > 1e-9 else np.array([1.0, 0.0, 0.0])
    return np.asarray(np.cos(min_el) * horizontal + np.sin(min_el) * UP)


def view_pose(
    target: ArrayLike,
    outward: ArrayLike,
    x_hint: ArrayLike,
    *,
    distance_m: float,
    roll_rad: float = 0.0,
) -> FloatArray:
    """``T_base_cam`` (4, 4) at ``distance_m`` from ``target`` along ``outward``, looking back.

    The optical axis (+z) is ``-outward``; the image x axis is ``x_hint`` made perpendicular to
    it, then turned by ``roll_rad`` about the optical axis.
    """
    out = unit(outward)
    R = orthonormal_frame(-out, x_hint)
    if roll_rad != 0.0:
        c, s = np.cos(roll_rad), np.sin(roll_rad)
        R = R @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return make_transform(R, np.asarray(target, dtype=np.float64) + distance_m * out)


def search_distances(min_m: float, max_m: float, step_m: float) -> FloatArray:
    """Camera distances (K,) from ``min_m`` up to ``max_m`` (inclusive) in ``step_m`` steps."""
    if not (0 < min_m <= max_m and step_m > 0):
        raise ValueError(
            f"distance search needs 0 < min <= max and step > 0, got {min_m}, {max_m}, {step_m}"
        )
    n = int(np.floor((max_m - min_m) / step_m + 1e-9)) + 1
    return np.asarray(min_m + step_m * np.arange(n))


def search_rolls(step_deg: float) -> FloatArray:
    """Rolls (K,) in radians, nearest to zero first: 0, +s, -s, +2s, -2s, ... up to 180°."""
    if not 0 < step_deg <= 180:
        raise ValueError(f"roll step must be within (0, 180] degrees, got {step_deg}")
    n = int(np.floor(180.0 / step_deg + 1e-9))
    rolls = [0.0]
    for k in range(1, n + 1):
        angle = k * step_deg
        rolls.append(angle)
        if angle < 180.0 - 1e-9:
            rolls.append(-angle)
    return np.radians(np.asarray(rolls))


def tilt_about_edge(normal: ArrayLike, direction: ArrayLike, angle_deg: float) -> FloatArray:
    """``normal`` (3,) turned by ``angle_deg`` towards ``direction`` (unit (3,)).

    The rotation axis is ``normal × direction`` — the edge where the surface ends, when
    ``direction`` points out of the surface along the line: a camera on the turned normal looks
    over that edge at what lies past it.
    """
    n = unit(normal)
    d = np.asarray(direction, dtype=np.float64).reshape(3)
    d = d - np.dot(d, n) * n
    if np.linalg.norm(d) < 1e-9:
        return n
    d = unit(d)
    a = np.radians(angle_deg)
    return np.asarray(np.cos(a) * n + np.sin(a) * d)
