"""Why a direction of the calibration is not observable, in words a user understands.

The solver finds the directions (combinations of the seven parameters) the scan cannot pin
down; :func:`describe` names each and says why, from how the scan moved: all views share one
orientation (a mount translation moves every frame alike), the views turn only about one axis
(translation along it is invisible), the camera slid along one line without turning (rotation
about that line is invisible), the arm never moved while images were taken (the clock offset is
invisible), or the surface is flat.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Direction:
    """A direction of the correction the scan cannot pin down.

    ``vector`` (7,) is unit in the analysis units (``observable_sigma_*``), in :data:`PARAMETERS`
    order; ``sigma`` its standard deviation in those units (> 1: unobservable); ``what`` and
    ``why`` describe it for a user.
    """

    vector: tuple[float, ...]
    sigma: float
    what: str
    why: str


@dataclass(frozen=True)
class ScanContext:
    """What the scan's motion looks like, to explain an unobservable direction."""

    max_angle_deg: float  # largest rotation between any two frames
    rotation_axis_cam: FloatArray | None  # (3,) when all rotations share one axis
    max_speed_m_s: float  # fastest moving-frame motion at a capture time
    flat: bool  # all surface normals within 10 degrees of one direction
    travel_line_cam: FloatArray | None  # (3,) when the camera only slid along one line

    @staticmethod
    def of(T_base_cam: FloatArray, velocities: FloatArray, normals_base: FloatArray) -> ScanContext:
        """From the frames' poses (F, 4, 4), the moving frame's velocities (F, 3) m/s at the
        capture times and the surface normals seen (N, 3), base frame."""
        R = T_base_cam[:, :3, :3]
        rotvecs = []
        for i in range(len(R)):
            rel = Rotation.from_matrix(np.einsum("ji,njk->nik", R[i], R))  # R_iᵀ R_k, camera i
            rotvecs.append(rel.as_rotvec())
        rv = np.vstack(rotvecs)
        angles = np.linalg.norm(rv, axis=1)
        max_angle = float(np.degrees(angles.max())) if angles.size else 0.0
        axis = None
        big = rv[angles > math.radians(1.0)]
        if len(big) >= 1:
            _, s, vt = np.linalg.svd(big, full_matrices=False)
            if len(s) == 1 or s[1] < 0.1 * s[0]:
                axis = vt[0]
        speeds = np.linalg.norm(velocities, axis=1)
        mean = normals_base.mean(axis=0)
        mean /= max(float(np.linalg.norm(mean)), 1e-12)
        flat = bool(np.quantile(normals_base @ mean, 0.05) > math.cos(math.radians(10.0)))
        line = None
        if max_angle < 2.0 and len(R) >= 2:
            shifts = (T_base_cam[:, :3, 3] - T_base_cam[0, :3, 3]) @ R[0]  # camera 0's axes
            _, s, vt = np.linalg.svd(shifts, full_matrices=False)
            if s[0] > 1e-3 and (len(s) < 2 or s[1] < 0.1 * s[0]):
                line = vt[0]
        return ScanContext(max_angle, axis, float(speeds.max()), flat, line)


_AXES = ("x (across the image)", "y (down the image)", "z (the optical axis)")


def describe(vector: FloatArray, sigma: object, context: ScanContext) -> Direction:
    """Words for an unobservable eigen-direction (analysis units) and why."""
    v = np.asarray(vector, dtype=np.float64)
    groups = {"translation": v[0:3], "rotation": v[3:6], "time": v[6:7]}
    weight = {k: float(np.sum(g * g)) for k, g in groups.items()}
    main = max(weight, key=lambda k: weight[k])
    if main == "time":
        what = "the clock offset between the camera and /tf"
        if context.max_speed_m_s < 0.005:
            why = "the arm never moved while images were taken: the time offset is not observable"
        else:
            why = (
                f"the arm moved slowly while images were taken (at most "
                f"{1000 * context.max_speed_m_s:.0f} mm/s): the time offset is weakly determined"
            )
    else:
        g = groups[main] / math.sqrt(weight[main])
        along = _axis_text(g)
        what = f"{main} {'along' if main == 'translation' else 'about'} {along}"
        if main == "translation" and context.max_angle_deg < 2.0:
            why = (
                "all views share one orientation: a mount translation moves every frame alike "
                "and is not observable"
            )
        elif main == "translation" and context.rotation_axis_cam is not None:
            why = (
                f"the views differ only by rotation about one axis "
                f"({_vector_text(context.rotation_axis_cam)} in the camera frame): translation "
                "along it is not observable"
            )
        elif (
            main == "rotation"
            and context.travel_line_cam is not None
            and abs(float(g @ context.travel_line_cam)) > 0.9
        ):
            why = (
                f"the camera only moved along one line ({_axis_text(context.travel_line_cam)}) "
                "without turning: rotation about that line is not observable"
            )
        elif context.flat:
            why = "the surface seen is flat and the paint's edges do not constrain this direction"
        else:
            why = "the views and the surface seen do not constrain this direction"
    return Direction(
        vector=tuple(round(float(c), 4) for c in v),
        sigma=float(sigma) if isinstance(sigma, float) else math.inf,
        what=what,
        why=why,
    )


def _axis_text(v: FloatArray) -> str:
    """``camera y (down the image)`` when ``v`` is close to an axis, else its components."""
    axis = int(np.argmax(np.abs(v)))
    return f"camera {_AXES[axis]}" if abs(v[axis]) > 0.9 else _vector_text(v)


def _vector_text(v: FloatArray) -> str:
    return "(" + ", ".join(f"{c:+.2f}" for c in v) + ")"
