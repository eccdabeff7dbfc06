"""Views that make the hand-eye and clock calibration observable (``--calibration-views``).

A scan along a line on a pipe or a plate turns the camera mostly about one axis, and some
mount directions then stay unobservable (``scrapcut calibrate`` says which). A few extra views
of a painted stretch already seen fix that: each looks at the same target from a direction
tilted ``tilt_deg`` away from the surface normal, the tilts spread evenly round the normal, and
each is rolled about its optical axis by a different angle (golden-angle steps), so that the
rotations between any two views have axes in the surface and along the normal. The arm's moves
between them also give the clock offset speed to show in. Pure geometry; the planner checks
reachability and picks among the alternatives.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.exploration.views import tilt_up, unit, view_pose

FloatArray = NDArray[np.float64]

#: The planner's reason for a calibration view (its log entries; ``calibrate`` looks for it).
CALIBRATION_REASON = "calibration"
#: Roll step between successive views: the golden angle spreads any number of rolls evenly.
GOLDEN_ANGLE_DEG = 180.0 * (3.0 - math.sqrt(5.0))


def calibration_view_poses(
    target: ArrayLike,
    normal: ArrayLike,
    along: ArrayLike,
    *,
    count: int,
    distance_m: float,
    tilt_deg: float = 30.0,
    min_elevation_deg: float = 0.0,
) -> list[FloatArray]:
    """``count`` camera poses ``T_base_cam`` (4, 4) looking at ``target`` (3,), metres.

    Parameters
    ----------
    target : (3,)
        A point of paint already seen, base frame.
    normal : (3,)
        The surface normal there, pointing towards where the camera may be.
    along : (3,)
        The line's direction there (the first view's image x axis, before its roll).
    count : int
        Views wanted.
    distance_m : float
        Camera distance to the target.
    tilt_deg : float
        Angle between each optical axis and ``-normal``.
    min_elevation_deg : float
        Views stay at least this high above the target (the planner's own rule).
    """
    if count <= 0:
        return []
    n = unit(normal)
    a = np.asarray(along, dtype=np.float64) - float(np.dot(along, n)) * n
    a = unit(a) if np.linalg.norm(a) > 1e-9 else unit(np.cross(n, [1.0, 0.0, 0.0]))
    b = np.cross(n, a)
    tilt = math.radians(tilt_deg)
    poses = []
    for i in range(count):
        azimuth = 2.0 * math.pi * i / count
        side = math.cos(azimuth) * a + math.sin(azimuth) * b
        outward = tilt_up(math.cos(tilt) * n + math.sin(tilt) * side, min_elevation_deg)
        roll = math.radians((GOLDEN_ANGLE_DEG * i) % 360.0)
        poses.append(view_pose(target, outward, a, distance_m=distance_m, roll_rad=roll))
    return poses
