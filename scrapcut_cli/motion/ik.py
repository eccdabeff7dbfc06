"""Numerical inverse kinematics of the torch: damped least squares with redundancy resolution.

The task has five dimensions: the torch tip's position (3) and the direction of its axis (2).
The rotation about the axis is free (a round torch), so with the Panda's seven joints two
degrees of freedom are left for the null space. Each iteration solves

    dq = J⁺_λ e + (I − J⁺J) (−k ∇C)

where ``e`` stacks the tip's position error and the axis error (the rotation vector that
turns the current axis onto the target's, expressed in the two directions across the axis,
scaled by :data:`ROTATION_LENGTH_M` so metres and radians weigh alike), ``J`` is the matching
5 × 7 rows of the analytic Jacobian of the URDF chain, ``J⁺_λ`` its damped pseudo-inverse
(the damping grows only when the smallest singular value falls below a threshold:
Nakamura & Hanafusa's singularity-robust inverse), and ``C`` the redundancy cost: a quadratic
pull to the middle of each joint's range plus −log of the task manipulability
sqrt(det(J Jᵀ)) (Yoshikawa), its gradient by finite differences over the seven joints in one
vectorised forward-kinematics call. Steps are capped in size and joints clipped inside their
limits (minus a margin), so a solution seeded from its neighbour's stays on the same branch:
the path follower below relies on that for continuity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.motion.limits import JointLimits
from scrapcut_cli.motion.panda import PandaKinematics

FloatArray = NDArray[np.float64]

#: Lever that converts the axis error (rad) into metres in the task error and Jacobian.
ROTATION_LENGTH_M = 0.1
#: Finite-difference step of the manipulability gradient, radians.
_GRADIENT_STEP = 1e-5


@dataclass(frozen=True)
class IkSettings:
    """Solver tolerances and gains (metres, radians).

    The tolerances (0.05 mm, 0.03°) are an order below the accuracy a trajectory is judged by
    (0.5 mm, 1°), so interpolation between set-points has room. ``limit_gain`` and
    ``manipulability_gain`` weigh the two redundancy costs; ``null_step_rad`` caps the
    null-space motion per iteration, which keeps the posture drift between neighbouring
    set-points small.
    """

    position_tol_m: float = 5e-5
    axis_tol_rad: float = 5e-4
    max_iterations: int = 100
    max_step_rad: float = 0.2
    joint_margin_rad: float = 0.01
    singular_threshold: float = 0.02
    max_damping: float = 0.02
    limit_gain: float = 0.02
    manipulability_gain: float = 0.02
    null_step_rad: float = 0.01
    stall_iterations: int = 6  # iterations without progress that end a solve


@dataclass(frozen=True, eq=False)
class IkResult:
    """One solve: joints (7,), whether the task tolerances were met, the remaining position
    (m) and axis (rad) errors, iterations used, and ``reason`` (``ok``, ``joint_limits``: a
    joint ended on its limit, ``out_of_reach``: otherwise not converged)."""

    q: FloatArray
    converged: bool
    position_error_m: float
    axis_error_rad: float
    iterations: int
    reason: str


class TorchIk:
    """Inverse kinematics of the tool frame ``T_flange_tool`` on the Panda.

    Parameters
    ----------
    kin : PandaKinematics
        The URDF chain.
    T_flange_tool : (4, 4) float64
        Flange → torch tip; the tool z axis is the torch axis (along the jet).
    limits : JointLimits
        Position limits used (the solver stays ``joint_margin_rad`` inside them).
    settings : IkSettings
        Tolerances and gains.
    """

    def __init__(
        self,
        kin: PandaKinematics,
        T_flange_tool: ArrayLike,
        limits: JointLimits,
        settings: IkSettings | None = None,
    ) -> None:
        self.kin = kin
        self.T_flange_tool = np.asarray(T_flange_tool, dtype=np.float64)
        self.settings = settings or IkSettings()
        m = self.settings.joint_margin_rad
        self.lower = limits.lower + m
        self.upper = limits.upper - m
        self._mid = 0.5 * (limits.lower + limits.upper)
        self._half = 0.5 * (limits.upper - limits.lower)
        # Reach bound: the flange's distance from the shoulder (joint 2's origin, on joint 1's
        # axis) is at most the wrist centre's (joint 5's origin; on a Panda it depends on the
        # elbow, joint 4, alone) plus the wrist centre's distance to the flange (constant).
        # Sampled over joint 4's range with a few postures of the others, plus 1 cm.
        q = np.tile(np.asarray(self._mid), (4 * 201, 1))
        q[:, 3] = np.tile(np.linspace(limits.lower[3], limits.upper[3], 201), 4)
        rng = np.random.default_rng(0)
        others = [0, 1, 2, 4, 5, 6]
        q[201:, others] = rng.uniform(limits.lower[others], limits.upper[others], (3 * 201, 6))
        F = kin.link_frames(q)
        shoulder, wrist, flange = F[:, 2, :3, 3], F[:, 5, :3, 3], F[:, 8, :3, 3]
        self._shoulder = np.asarray(shoulder[0], dtype=np.float64)
        off_axis = float(np.max(np.linalg.norm(shoulder - self._shoulder, axis=1)))
        self._reach = (
            float(np.max(np.linalg.norm(wrist - shoulder, axis=1)))
            + float(np.max(np.linalg.norm(flange - wrist, axis=1)))
            + off_axis
            + 0.01
        )
        u = self.T_flange_tool[:3, :3].T @ self.T_flange_tool[:3, 3]  # flange→tip, tool frame
        self._tip_axial = float(u[2])
        self._tip_lateral = float(np.hypot(u[0], u[1]))

    # ------------------------------------------------------------------ pieces

    def tool_poses(self, q: ArrayLike) -> FloatArray:
        """T_base_tool (S, 4, 4) at joint samples (S, 7)."""
        return np.asarray(self.kin.flange(np.atleast_2d(q)) @ self.T_flange_tool)

    def _task(
        self, q: FloatArray, target_p: FloatArray, target_a: FloatArray, *, gradient: bool
    ) -> tuple[FloatArray, FloatArray, float, float, FloatArray | None]:
        """Task error (5,), Jacobian (5, 7), errors (m, rad), and −∇ log manipulability (7,)."""
        samples = (
            q[None] if not gradient else q + np.vstack([np.zeros(7), np.eye(7)]) * (_GRADIENT_STEP)
        )
        T, J6 = self.kin.tool_jacobian(samples, self.T_flange_tool)
        p, a = T[0, :3, 3], T[0, :3, 2]
        u, v = _across(a)
        basis = np.stack([u, v])  # (2, 3)
        rows = np.concatenate(
            [J6[:, :3], ROTATION_LENGTH_M * np.einsum("kj,sjn->skn", basis, J6[:, 3:])], axis=1
        )  # (S, 5, 7)
        dp = target_p - p
        cross = _cross3(a, target_a)
        sin, cos = float(np.linalg.norm(cross)), float(np.dot(a, target_a))
        angle = float(np.arctan2(sin, cos))
        w = cross * (angle / sin) if sin > 1e-12 else (np.zeros(3) if cos > 0 else np.pi * u)
        e = np.concatenate([dp, ROTATION_LENGTH_M * (basis @ w)])
        grad = None
        if gradient:
            gram = rows @ np.swapaxes(rows, 1, 2)
            sign, logdet = np.linalg.slogdet(gram)
            logdet = np.where(sign > 0, logdet, -1e3)
            grad = -0.5 * (logdet[1:] - logdet[0]) / _GRADIENT_STEP
        return e, rows[0], float(np.linalg.norm(dp)), abs(angle), grad

    def beyond_reach(self, target_position: ArrayLike, target_axis: ArrayLike) -> bool:
        """True when no joint values can place the tip there (a conservative bound: False
        does not promise a solution)."""
        a = np.asarray(target_axis, dtype=np.float64)
        c = np.asarray(target_position, dtype=np.float64) - self._tip_axial * a / np.linalg.norm(a)
        return bool(np.linalg.norm(c - self._shoulder) - self._tip_lateral > self._reach + 1e-3)

    # ------------------------------------------------------------------ solve

    def solve(
        self,
        target_position: ArrayLike,
        target_axis: ArrayLike,
        q_seed: ArrayLike,
        *,
        max_iterations: int | None = None,
        posture_iterations: int = 0,
    ) -> IkResult:
        """Joints placing the tip at ``target_position`` (3,) with the torch axis along
        ``target_axis`` (3,), both base frame, starting from ``q_seed`` (7,).

        ``posture_iterations`` extra iterations keep improving the redundancy cost after the
        task is met (used for a path's first set-point, where no neighbour fixes the posture).
        """
        s = self.settings
        p_star = np.asarray(target_position, dtype=np.float64)
        a_star = np.asarray(target_axis, dtype=np.float64)
        a_star = a_star / np.linalg.norm(a_star)
        q = np.clip(np.asarray(q_seed, dtype=np.float64), self.lower, self.upper)
        if self.beyond_reach(p_star, a_star):
            return IkResult(q, False, np.inf, np.inf, 0, "out_of_reach")
        limit = s.max_iterations if max_iterations is None else max_iterations
        best = (np.inf, q.copy(), np.inf, np.inf)
        extra = posture_iterations
        stall = 0
        it = 0
        dp = da = np.inf
        evaluated = False  # dp, da belong to the current q
        grad: FloatArray | None = None
        for it in range(1, limit + posture_iterations + 1):
            # The manipulability gradient costs as much as the rest of an iteration; within one
            # solve's small steps it changes little, so it is refreshed every few iterations.
            fresh = grad is None or it % 4 == 0 or extra < posture_iterations
            e, J, dp, da, g = self._task(q, p_star, a_star, gradient=fresh)
            grad = g if g is not None else grad
            evaluated = True
            score = dp + ROTATION_LENGTH_M * da
            if score < best[0] - 1e-9:
                best, stall = (score, q.copy(), dp, da), 0
            else:
                stall += 1
            if dp < s.position_tol_m and da < s.axis_tol_rad:
                if extra <= 0:
                    break
                extra -= 1
            elif stall >= s.stall_iterations or it > limit:
                break
            dq_task, null = _damped_step(J, e, s.singular_threshold, s.max_damping)
            assert grad is not None
            cost = s.limit_gain * (q - self._mid) / self._half**2 + s.manipulability_gain * grad
            dq_null = -(null @ cost)
            n = float(np.max(np.abs(dq_null)))
            if n > s.null_step_rad:
                dq_null *= s.null_step_rad / n
            dq = dq_task + dq_null
            n = float(np.max(np.abs(dq)))
            if n > s.max_step_rad:
                dq *= s.max_step_rad / n
            q = np.clip(q + dq, self.lower, self.upper)
            evaluated = False
        if not evaluated:
            _, _, dp, da, _ = self._task(q, p_star, a_star, gradient=False)
        met = dp < s.position_tol_m and da < s.axis_tol_rad
        if not met and best[0] < dp + ROTATION_LENGTH_M * da:
            q, dp, da = best[1], best[2], best[3]
        converged = dp < s.position_tol_m and da < s.axis_tol_rad
        if converged:
            reason = "ok"
        elif np.any(np.isclose(q, self.lower, atol=1e-6) | np.isclose(q, self.upper, atol=1e-6)):
            reason = "joint_limits"
        else:
            reason = "out_of_reach"
        return IkResult(q, bool(converged), float(dp), float(da), it, reason)


def _across(axis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Two unit vectors (3,) completing ``axis`` (3,) to a right-handed orthonormal frame."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = _cross3(axis, helper)
    u /= np.linalg.norm(u)
    return u, _cross3(axis, u)


def _cross3(a: FloatArray, b: FloatArray) -> FloatArray:
    """a × b of two (3,) vectors (np.cross's generality costs ~20 µs a call here)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _damped_step(
    J: FloatArray, e: FloatArray, threshold: float, max_damping: float
) -> tuple[FloatArray, FloatArray]:
    """Singularity-robust step J⁺_λ e (7,) and the null-space projector (7, 7) of J (5, 7)."""
    U, S, Vt = np.linalg.svd(J, full_matrices=True)
    smallest = float(S[-1])
    lam2 = 0.0 if smallest >= threshold else (1.0 - (smallest / threshold) ** 2) * max_damping**2
    gains = S / (S * S + lam2)
    dq = Vt[: len(S)].T @ (gains * (U.T @ e))
    V_null = Vt[len(S) :]
    return dq, V_null.T @ V_null
