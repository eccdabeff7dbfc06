"""The Panda's published joint limits (Franka Emika datasheet) and the share of them we plan to.

Values from Franka Control Interface documentation, "Robot and interface specifications",
section "Limits for Panda" (frankaemika.github.io/docs/control_parameters.html), the same as
libfranka's ``rate_limiting.h`` (kMaxJointVelocity, kMaxJointAcceleration, kMaxJointJerk):

===========  ======  ======  ======  ======  ======  ======  ======  =======
joint          1       2       3       4       5       6       7      unit
===========  ======  ======  ======  ======  ======  ======  ======  =======
q max        2.8973  1.7628  2.8973 -0.0698  2.8973  3.7525  2.8973  rad
q min       -2.8973 -1.7628 -2.8973 -3.0718 -2.8973 -0.0175 -2.8973  rad
dq max       2.1750  2.1750  2.1750  2.1750  2.6100  2.6100  2.6100  rad/s
ddq max      15      7.5     10      12.5    15      20      20      rad/s²
dddq max     7500    3750    5000    6250    7500    10000   10000   rad/s³
===========  ======  ======  ======  ======  ======  ======  ======  =======

The URDF carries the same position and velocity limits; acceleration and jerk are only here.
A trajectory is planned to ``PLANNING_SHARE`` of the velocity, acceleration and jerk limits
(the controller needs headroom to correct tracking errors) and checked against the full ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

Q_MAX = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)
Q_MIN = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
DQ_MAX = (2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100)
DDQ_MAX = (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
DDDQ_MAX = (7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0)
#: Plan to this share of the velocity, acceleration and jerk limits.
PLANNING_SHARE = 0.5


@dataclass(frozen=True, eq=False)
class JointLimits:
    """Per-joint limits, each (7,) float64: position (rad), velocity (rad/s), acceleration
    (rad/s²), jerk (rad/s³)."""

    lower: FloatArray
    upper: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    jerk: FloatArray

    def scaled(self, share: float) -> JointLimits:
        """The same position limits with velocity, acceleration and jerk times ``share``."""
        return JointLimits(
            self.lower,
            self.upper,
            self.velocity * share,
            self.acceleration * share,
            self.jerk * share,
        )

    def position_margin(self, q: NDArray[np.float64]) -> FloatArray:
        """Distance (..., 7) in radians of joint positions ``q`` (..., 7) to the nearer limit
        (negative outside)."""
        return np.minimum(q - self.lower, self.upper - q)


def panda_limits(
    lower: NDArray[np.float64] | None = None, upper: NDArray[np.float64] | None = None
) -> JointLimits:
    """Franka's datasheet limits; ``lower``/``upper`` (7,) replace the position limits (e.g.
    a user URDF's), intersected with the datasheet's."""
    lo = np.array(Q_MIN) if lower is None else np.maximum(np.asarray(lower, float), Q_MIN)
    hi = np.array(Q_MAX) if upper is None else np.minimum(np.asarray(upper, float), Q_MAX)
    return JointLimits(
        lower=lo,
        upper=hi,
        velocity=np.array(DQ_MAX),
        acceleration=np.array(DDQ_MAX),
        jerk=np.array(DDDQ_MAX),
    )
