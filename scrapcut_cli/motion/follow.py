"""Following the set-points: inverse kinematics along the path, continuously, with tilts.

Each set-point's solve is seeded from the previous set-point's joints, so the arm stays on one
branch of the inverse kinematics and the redundancy resolution of :mod:`~.ik` moves the
posture only a little per set-point. A joint step between neighbours larger than
``max_joint_step_rad`` is a flip (typically the wrist turning over near a singularity): the
follower then walks to the set-point through intermediate targets; if the step stays large,
the set-point is refused as ``flip``.

A set-point the torch cannot reach as given (out of reach, beyond the joint limits, the arm
or torch colliding, a flip) is tried with the torch tilted: pivoting about the surface point
(the jet still hits it at the standoff), by ``max_tilt_deg`` in ``tilt_steps`` steps, in
``tilt_directions`` directions around the path's axis, smallest tilt first; among the
candidates of one tilt the one with the smallest joint step wins. The rotation about the torch
axis is free in every solve, so that freedom is always used before any tilt.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.motion.collision import CollisionChecker
from scrapcut_cli.motion.ik import IkResult, TorchIk
from scrapcut_cli.motion.panda import Q_READY

FloatArray = NDArray[np.float64]

#: IK iterations per tilt candidate (seeded from the neighbour, a reachable one needs few).
TILT_ITERATIONS = 15
#: Set-point outcomes.
REACHED = "reached"
TILTED = "tilted"
UNREACHABLE = "unreachable"
COLLISION = "collision"


@dataclass(frozen=True)
class FollowSettings:
    """Tilt search and continuity bound (radians, degrees as named)."""

    max_tilt_deg: float = 20.0
    tilt_steps: int = 4
    tilt_directions: int = 8
    max_joint_step_rad: float = 0.25
    posture_iterations: int = 40


@dataclass(eq=False)
class PathSolution:
    """Joint solutions along the set-points.

    Attributes
    ----------
    q : (N, 7) float64
        Joints per set-point, radians (NaN where none was found).
    status : list of str
        ``reached``, ``tilted``, ``unreachable`` or ``collision``.
    reason : list of str
        Why a set-point is not reached: ``out_of_reach``, ``joint_limits``, ``flip`` or
        ``<body>/surface`` / ``<body>/floor``; empty otherwise.
    tip, axis : (N, 3) float64
        The tip position and torch axis (along the jet) solved for (tilted where tilted).
    tilt_rad : (N,) float64
        Tilt away from the path's torch axis.
    flips_avoided : int
        Set-points reached by walking through intermediate targets instead of jumping.
    breaks : list of int
        Set-points reached only in another posture of the arm (a flip from the previous one):
        the cut must stop before them and start again there.
    """

    q: FloatArray
    status: list[str]
    reason: list[str]
    tip: FloatArray
    axis: FloatArray
    tilt_rad: FloatArray
    flips_avoided: int = 0
    score: tuple[float, ...] = field(default_factory=tuple)
    breaks: list[int] = field(default_factory=list)

    @property
    def ok(self) -> NDArray[np.bool_]:
        """(N,) set-points the trajectory passes through."""
        return np.array([s in (REACHED, TILTED) for s in self.status], dtype=bool)


def _posture_dependent(reason: str) -> bool:
    """Could another arm posture (another start) avoid this failure? Reach and the torch's own
    collisions do not depend on it; joint limits, flips and the arm's collisions do."""
    return reason in ("joint_limits", "flip") or (
        reason.endswith(("/surface", "/unseen", "/floor")) and not reason.startswith("torch/")
    )


class PathFollower:
    """Solves a path's set-points in order (see the module docstring)."""

    def __init__(
        self,
        ik: TorchIk,
        checker: CollisionChecker,
        settings: FollowSettings | None = None,
    ) -> None:
        self.ik = ik
        self.checker = checker
        self.settings = settings or FollowSettings()

    # ------------------------------------------------------------------ one target

    def _try(
        self,
        tip: FloatArray,
        axis: FloatArray,
        q_prev: FloatArray,
        allowed: float,
        *,
        max_iterations: int | None = None,
        walk: bool = True,
    ) -> tuple[IkResult | None, str, int]:
        """Solve one target from ``q_prev``; (result or None, reason, flips avoided).

        ``walk``: when the step is too large, try reaching the target through intermediate
        targets before calling it a flip (not for tilt candidates: another tilt is cheaper).
        """
        r = self.ik.solve(tip, axis, q_prev, max_iterations=max_iterations)
        if not r.converged:
            return None, r.reason, 0
        avoided = 0
        if float(np.max(np.abs(r.q - q_prev))) > allowed:
            if not walk:
                return None, "flip", 0
            walked = self._walk(tip, axis, q_prev, allowed)
            if walked is None:
                return None, "flip", 0
            r, avoided = walked, 1
        # The motion from the neighbour must be clear too (on the way from one lean of the
        # torch to another the holder or wrist can swing through the piece): checked at thirds
        # of the joint step when the two belong to one cut.
        samples = r.q[None]
        if np.isfinite(allowed):
            samples = q_prev + np.array([[1 / 3], [2 / 3], [1.0]]) * (r.q - q_prev)
        hits = [h for h in self.checker.check(samples) if h is not None]
        if hits:
            return None, hits[0], avoided
        return r, "", avoided

    def _walk(
        self, tip: FloatArray, axis: FloatArray, q_prev: FloatArray, allowed: float
    ) -> IkResult | None:
        """Reach the target through intermediate targets from the pose at ``q_prev``."""
        T0 = self.ik.tool_poses(q_prev)[0]
        p0, a0 = T0[:3, 3], T0[:3, 2]
        q = q_prev
        steps = 8
        r: IkResult | None = None
        for k in range(1, steps + 1):
            f = k / steps
            a = (1 - f) * a0 + f * axis
            r = self.ik.solve((1 - f) * p0 + f * tip, a / np.linalg.norm(a), q)
            if not r.converged or float(np.max(np.abs(r.q - q))) > allowed:
                return None
            q = r.q
        return r

    # ------------------------------------------------------------------ the path

    def follow(
        self,
        tips: ArrayLike,
        axes: ArrayLike,
        surface_points: ArrayLike,
        q_start: ArrayLike,
        *,
        max_failures: int | None = None,
    ) -> PathSolution | None:
        """Solve every set-point in order, starting from joints ``q_start`` (7,).

        ``tips`` (N, 3) torch tip positions, ``axes`` (N, 3) unit torch axes along the jet
        (into the surface), ``surface_points`` (N, 3) where the jet meets the surface; all
        metres, base frame. None when more than ``max_failures`` set-points fail (a start that
        cannot beat another's).
        """
        P = np.asarray(tips, dtype=np.float64)
        A = np.asarray(axes, dtype=np.float64)
        S = np.asarray(surface_points, dtype=np.float64)
        n = len(P)
        st = self.settings
        q_out = np.full((n, 7), np.nan)
        status = [UNREACHABLE] * n
        reason = [""] * n
        tip_out, axis_out = P.copy(), A.copy()
        tilt = np.zeros(n)
        q_prev = np.asarray(q_start, dtype=np.float64)
        gap = 1
        avoided = 0
        # Continuity is asked of neighbours in one cut only: before the first solution, and
        # after a set-point that failed (the cut stops there), any posture will do.
        started = False
        failures = 0
        breaks: list[int] = []
        for i in range(n):
            allowed = st.max_joint_step_rad if started and gap == 1 else np.inf
            r, why, av = self._try(P[i], A[i], q_prev, allowed)
            avoided += av
            if r is not None:
                q_out[i], status[i] = r.q, REACHED
            else:
                prefer = axis_out[i - 1] if i > 0 and status[i - 1] == TILTED else None
                found = self._tilted(P[i], A[i], S[i], q_prev, allowed, prefer=prefer)
                if found is None and why == "flip":
                    # Reachable, but only in another posture: no flip mid-cut; the cut stops
                    # before this set-point and starts again here.
                    r, why, _ = self._try(P[i], A[i], q_prev, np.inf, walk=False)
                if found is not None:
                    r, tip_out[i], axis_out[i], tilt[i] = found
                    q_out[i], status[i] = r.q, TILTED
                elif r is not None:
                    q_out[i], status[i] = r.q, REACHED
                    breaks.append(i)
                else:
                    collision = why.endswith(("/surface", "/unseen", "/floor"))
                    status[i] = COLLISION if collision else UNREACHABLE
                    reason[i] = why
                    failures += 1
                    if max_failures is not None and failures > max_failures:
                        return None
            if r is not None:
                q_prev, gap, started = r.q, 1, True
            else:
                gap += 1
        sol = PathSolution(q_out, status, reason, tip_out, axis_out, tilt, avoided, breaks=breaks)
        sol.score = self._score(sol)
        return sol

    def _tilted(
        self,
        tip: FloatArray,
        axis: FloatArray,
        surface: FloatArray,
        q_prev: FloatArray,
        allowed: float,
        *,
        prefer: FloatArray | None = None,
    ) -> tuple[IkResult, FloatArray, FloatArray, float] | None:
        """The smallest tilt that works; among one tilt's directions the smallest joint step.

        ``prefer``: the previous set-point's tilted axis. Its direction is tried first at each
        tilt and taken when it works (a run of tilted set-points keeps its lean, and costs one
        solve per set-point); only if it never does are all directions searched.
        """
        st = self.settings
        if st.max_tilt_deg <= 0 or st.tilt_steps <= 0 or st.tilt_directions <= 0:
            return None
        standoff = float(np.dot(surface - tip, axis))
        u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(axis, u)
        thetas = np.radians(st.max_tilt_deg) * np.arange(1, st.tilt_steps + 1) / st.tilt_steps
        phis = 2 * np.pi * np.arange(st.tilt_directions) / st.tilt_directions

        def candidate(theta: float, phi: float) -> tuple[IkResult | None, FloatArray, FloatArray]:
            a = np.cos(theta) * axis + np.sin(theta) * (np.cos(phi) * u + np.sin(phi) * w)
            t = surface - standoff * a
            r, _, _ = self._try(t, a, q_prev, allowed, max_iterations=TILT_ITERATIONS, walk=False)
            return r, t, a

        if prefer is not None:
            lean = prefer - np.dot(prefer, axis) * axis
            if float(np.linalg.norm(lean)) > 1e-9:
                phi0 = float(np.arctan2(np.dot(lean, w), np.dot(lean, u)))
                for theta in thetas:
                    r, t, a = candidate(float(theta), phi0)
                    if r is not None:
                        return r, t, a, float(theta)
        for theta in thetas:
            best: tuple[float, IkResult, FloatArray, FloatArray] | None = None
            for phi in phis:
                r, t, a = candidate(float(theta), float(phi))
                if r is None:
                    continue
                step = float(np.max(np.abs(r.q - q_prev)))
                if best is None or step < best[0]:
                    best = (step, r, t, a)
            if best is not None:
                return best[1], best[2], best[3], float(theta)
        return None

    def _score(self, sol: PathSolution) -> tuple[float, ...]:
        """Larger is better: set-points passed, fewer cuts (breaks), fewer tilts, then the worst
        joint margin."""
        ok = sol.ok
        margin = 0.0
        if ok.any():
            q = sol.q[ok]
            margin = float(np.min(np.minimum(q - self.ik.lower, self.ik.upper - q)))
        tilts = float(sum(s == TILTED for s in sol.status))
        return (float(ok.sum()), -float(len(sol.breaks)), -tilts, margin)

    # ------------------------------------------------------------------ the start

    def start_candidates(self, tip: ArrayLike, axis: ArrayLike) -> Iterator[FloatArray]:
        """Distinct joint solutions of the first set-point (computed as they are asked for)
        from a few postures: Franka's
        ready pose turned towards the target, with joint 7 at three angles (the free roll
        about the torch axis decides how much of joint 7's range is left for the path)."""
        p = np.asarray(tip, dtype=np.float64)
        base = np.array(Q_READY, dtype=np.float64)
        base[0] = float(np.arctan2(p[1], p[0]))
        seeds = []
        for offset in (0.0, np.pi / 2, -np.pi / 2):
            s = base.copy()
            s[6] = base[6] + offset
            seeds.append(s)
        out: list[FloatArray] = []
        for seed in seeds:
            r = self.ik.solve(
                p,
                np.asarray(axis, dtype=np.float64),
                seed,
                max_iterations=100,
                posture_iterations=self.settings.posture_iterations,
            )
            if r.converged and all(np.max(np.abs(r.q - o)) > 0.05 for o in out):
                out.append(r.q)
                yield r.q

    def follow_best(
        self, tips: ArrayLike, axes: ArrayLike, surface_points: ArrayLike
    ) -> PathSolution:
        """:meth:`follow` from the start candidates in turn (and, if none converges, the ready
        pose turned towards the path) until one reaches every set-point as given; else the
        solution with the best score."""
        P = np.asarray(tips, dtype=np.float64)
        A = np.asarray(axes, dtype=np.float64)
        base = np.array(Q_READY, dtype=np.float64)
        base[0] = float(np.arctan2(P[0, 1], P[0, 0]))
        best: PathSolution | None = None
        for q0 in itertools.chain(self.start_candidates(P[0], A[0]), [base]):
            if best is not None and q0 is base:
                break  # the fallback only when no start converged
            # A start that fails as often as the best so far cannot pass more set-points.
            limit = None if best is None else int(len(P) - best.score[0]) - 1
            sol = self.follow(P, A, surface_points, q0, max_failures=limit)
            if sol is None:
                continue  # more failures than the best so far: it cannot win
            if best is None or sol.score > best.score:
                best = sol
            if not any(_posture_dependent(r) for r in best.reason):
                break  # what is left fails whatever the posture
        assert best is not None
        return best
