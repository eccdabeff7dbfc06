"""Time parameterisation: rest-to-rest moves along joint paths, within the joint limits.

A move is a joint path through waypoints ``q_k`` (K, 7) at TCP arc lengths ``s_k`` with a
nominal TCP speed per interval (the cutting chart's speed for a cut, a fixed speed for the
approach and the retreat). Its timing is built the way FIR trajectory generators do
(Biagiotti & Melchiorri, "FIR filters for online trajectory planning with time- and
frequency-domain specifications", 2012): the nominal speed profile, a step up from rest and
down to rest again, is convolved with two box filters of ``accel_time_s`` and
``jerk_time_s``; the result starts and ends at rest with continuous acceleration and bounded
jerk, and covers the same distance. The joint path is a cubic spline through the waypoints
in arc length (scipy), so the TCP passes exactly through every waypoint; the timing only
decides when.

Every move is checked on a 1 kHz grid (Franka's control rate) against the planning share of
the joint velocity, acceleration and jerk limits; a move that exceeds them is slowed by
uniform time scaling (speeds ÷ k, accelerations ÷ k², jerks ÷ k³), and the factor is
reported (a cut slowed below the chart's speed says so).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline, PchipInterpolator

from scrapcut_cli.motion.limits import JointLimits

FloatArray = NDArray[np.float64]

#: Fine time step of the timing and of the checks: Franka's 1 kHz control rate.
DT_S = 0.001


@dataclass(frozen=True)
class MoveProfile:
    """Smoothing of a move's speed profile: box filter lengths (s)."""

    accel_time_s: float = 0.2
    jerk_time_s: float = 0.05


@dataclass(frozen=True, eq=False)
class TimedMove:
    """A move, timed from its own start.

    Attributes
    ----------
    spline : CubicSpline
        Joints (7,) as a function of TCP arc length, metres.
    s_knots : (K,) float64
        Arc length of the waypoints, metres.
    t : (F,) float64
        Fine time grid (``DT_S``), seconds from the move's start.
    s, s_dot, s_ddot : (F,) float64
        Arc length (m), speed (m/s) and acceleration (m/s²) along the move on that grid.
    time_scale : float
        Factor (≥ 1) the nominal timing was stretched by to stay within the limits.
    """

    spline: CubicSpline
    s_knots: FloatArray
    t: FloatArray
    s: FloatArray
    s_dot: FloatArray
    s_ddot: FloatArray
    time_scale: float

    @property
    def duration_s(self) -> float:
        return float(self.t[-1])

    def knot_times(self) -> FloatArray:
        """Time (K,) at which the TCP passes each waypoint, seconds from the move's start."""
        times = np.interp(self.s_knots, self.s, self.t)
        times[0], times[-1] = 0.0, self.duration_s
        return np.asarray(times)

    def state(self, times: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Joint positions, velocities and accelerations (T, 7) at ``times`` (T,)."""
        tt = np.clip(np.asarray(times, dtype=np.float64), 0.0, self.duration_s)
        s = np.interp(tt, self.t, self.s)
        sd = np.interp(tt, self.t, self.s_dot)
        sdd = np.interp(tt, self.t, self.s_ddot)
        d1, d2 = self.spline(s, 1), self.spline(s, 2)
        return self.spline(s), d1 * sd[:, None], d2 * (sd * sd)[:, None] + d1 * sdd[:, None]

    def positions_at_knots(self) -> FloatArray:
        """Joints (K, 7) at the waypoints (exactly the waypoints given)."""
        return np.asarray(self.spline(self.s_knots))


def time_move(
    q_knots: ArrayLike,
    s_knots: ArrayLike,
    speeds: ArrayLike,
    limits: JointLimits,
    *,
    profile: MoveProfile | None = None,
) -> TimedMove:
    """Time a rest-to-rest move through joint waypoints within ``limits``.

    Parameters
    ----------
    q_knots : (K, 7) float64, radians
        Waypoints, K ≥ 2.
    s_knots : (K,) float64, metres
        TCP arc length at each waypoint, strictly increasing from 0.
    speeds : (K - 1,) float64, m/s
        Nominal TCP speed on each interval.
    limits : JointLimits
        The velocity, acceleration and jerk limits to stay within (a planning share of the
        datasheet's).
    profile : MoveProfile
        Filter lengths of the speed profile.
    """
    q = np.asarray(q_knots, dtype=np.float64)
    s_k = np.asarray(s_knots, dtype=np.float64)
    v_k = np.asarray(speeds, dtype=np.float64)
    prof = profile or MoveProfile()
    spline = PchipInterpolator(s_k, q, axis=0)
    scale = 1.0
    for _ in range(6):
        t, s, sd, sdd = _speed_profile(s_k, v_k / scale, prof, scale)
        qd, qdd, qddd = _joint_derivatives(spline, s, sd, sdd)
        ratio = max(
            float(np.max(np.abs(qd) / limits.velocity)),
            float(np.sqrt(np.max(np.abs(qdd) / limits.acceleration))),
            float(np.cbrt(np.max(np.abs(qddd) / limits.jerk))),
        )
        if ratio <= 1.0:
            break
        scale *= ratio * 1.02
    return TimedMove(spline, s_k, t, s, sd, sdd, scale)


def _speed_profile(
    s_knots: FloatArray, speeds: FloatArray, profile: MoveProfile, scale: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Fine time grid, arc length, speed and acceleration of the smoothed profile."""
    seg_t = np.diff(s_knots) / speeds
    edges = np.concatenate([[0.0], np.cumsum(seg_t)])
    n = max(int(np.ceil(edges[-1] / DT_S)), 1)
    mids = (np.arange(n) + 0.5) * DT_S
    v = speeds[np.clip(np.searchsorted(edges, mids, side="right") - 1, 0, len(speeds) - 1)]
    for width in (profile.accel_time_s * scale, profile.jerk_time_s * scale):
        k = max(round(width / DT_S), 1)
        v = np.convolve(v, np.full(k, 1.0 / k))
    v = np.concatenate([[0.0], v, [0.0]])
    steps = 0.5 * (v[1:] + v[:-1]) * DT_S
    v = v * (s_knots[-1] / float(np.sum(steps)))  # the grid's rounding: land on the last knot
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * DT_S)])
    s[-1] = s_knots[-1]
    t = np.arange(len(s)) * DT_S
    a = np.gradient(v, DT_S)
    return (
        np.asarray(t, dtype=np.float64),
        np.asarray(s, dtype=np.float64),
        np.asarray(v, dtype=np.float64),
        np.asarray(a, dtype=np.float64),
    )


def quintic_hermite(
    t: ArrayLike,
    positions: ArrayLike,
    velocities: ArrayLike,
    accelerations: ArrayLike,
    at: ArrayLike,
) -> FloatArray:
    """Positions (F, J) at times ``at`` (F,) of the quintic through points at ``t`` (T,)
    matching positions, velocities and accelerations (T, J) at every point — what a
    joint-trajectory controller given all three executes (ros2_control's
    joint_trajectory_controller, MoveIt). Vectorised here; scipy's ``BPoly.from_derivatives``
    gives the same polynomials one joint at a time (a test checks they agree)."""
    tt = np.asarray(t, dtype=np.float64)
    P = np.asarray(positions, dtype=np.float64)
    V = np.asarray(velocities, dtype=np.float64)
    A = np.asarray(accelerations, dtype=np.float64)
    h = np.diff(tt)[:, None]
    dp = P[1:] - P[:-1]
    v0, v1, a0, a1 = V[:-1] * h, V[1:] * h, 0.5 * A[:-1] * h * h, 0.5 * A[1:] * h * h
    coeffs = np.stack(
        [
            P[:-1],
            v0,
            a0,
            10 * dp - 6 * v0 - 4 * v1 - 3 * a0 + a1,
            -15 * dp + 8 * v0 + 7 * v1 + 3 * a0 - 2 * a1,
            6 * dp - 3 * v0 - 3 * v1 - a0 + a1,
        ],
        axis=1,
    )  # (T-1, 6, J), in the normalised time of each interval
    x = np.asarray(at, dtype=np.float64)
    k = np.clip(np.searchsorted(tt, x, side="right") - 1, 0, len(tt) - 2)
    tau = ((x - tt[k]) / h[k, 0])[:, None]
    c = coeffs[k]
    out = c[:, 5]
    for i in range(4, -1, -1):
        out = out * tau + c[:, i]
    return np.asarray(out)


def _joint_derivatives(
    spline: CubicSpline, s: FloatArray, sd: FloatArray, sdd: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Joint velocity, acceleration and jerk (F, 7) by finite differences on the fine grid."""
    q = spline(s)
    qd = np.diff(q, axis=0) / DT_S
    qdd = np.diff(q, 2, axis=0) / DT_S**2
    qddd = np.diff(q, 3, axis=0) / DT_S**3
    return qd, qdd, qddd


@dataclass(frozen=True, eq=False)
class LimitCheck:
    """The sampled trajectory against the limits, as a controller interpolating its points
    (quintic through positions, velocities and accelerations) would execute it at 1 kHz.

    ``*_ratio`` (7,) are the largest |value| / limit per joint (≤ 1 is within);
    ``position_margin_rad`` (7,) the smallest distance to a position limit.
    """

    velocity_ratio: FloatArray
    acceleration_ratio: FloatArray
    jerk_ratio: FloatArray
    position_margin_rad: FloatArray

    @property
    def ok(self) -> bool:
        return bool(
            np.all(self.velocity_ratio <= 1.0)
            and np.all(self.acceleration_ratio <= 1.0)
            and np.all(self.jerk_ratio <= 1.0)
            and np.all(self.position_margin_rad >= 0.0)
        )


def check_sampled(
    t: ArrayLike,
    positions: ArrayLike,
    velocities: ArrayLike,
    accelerations: ArrayLike,
    limits: JointLimits,
) -> LimitCheck:
    """Check trajectory points (T,) / (T, 7) against ``limits`` by finite differences at 1 kHz
    of their quintic Hermite interpolation (:func:`quintic_hermite`)."""
    tt = np.asarray(t, dtype=np.float64)
    fine = np.arange(tt[0], tt[-1], DT_S)
    fine = np.append(fine, tt[-1]) if fine[-1] < tt[-1] else fine
    q = quintic_hermite(tt, positions, velocities, accelerations, fine)
    qd = np.diff(q, axis=0) / DT_S
    qdd = np.diff(q, 2, axis=0) / DT_S**2
    qddd = np.diff(q, 3, axis=0) / DT_S**3

    def ratio(x: FloatArray, lim: FloatArray) -> FloatArray:
        return np.asarray(np.max(np.abs(x), axis=0) / lim) if len(x) else np.zeros(len(lim))

    margin = np.min(limits.position_margin(q), axis=0)
    return LimitCheck(
        ratio(qd, limits.velocity),
        ratio(qdd, limits.acceleration),
        ratio(qddd, limits.jerk),
        np.asarray(margin),
    )
