"""Estimate the camera mount and clock offset that make overlapping frames agree.

The problem (poses, residuals, weights, which frames are compared) is
:mod:`~scrapcut_cli.calibration.residuals`; here it is solved and judged:

1. Gauss-Newton over all seven parameters, weakly held by a prior at the published values;
   correspondences are found again for each gate of a schedule that shrinks from
   ``max_distance_m`` to ``min_distance_m`` (ICP's alternation), two steps per search;
2. observability: the normal equations ``JᵀWJ`` are analysed in units of the accuracy each
   parameter needs (``observable_sigma_*``: one unit is one "tolerance"); an eigen-direction is
   observable when its standard deviation — the larger of the formal one and a
   leave-one-frame-out jackknife, which sees errors shared by a frame's residuals — is below
   one unit;
3. the solve again with the unobservable directions held at the published values; those are
   described in words with the reason (:mod:`~scrapcut_cli.calibration.explain`);
4. a standard deviation per parameter, and the residual before and after.

Nothing here reads files or prints.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.calibration.explain import Direction, ScanContext, describe
from scrapcut_cli.calibration.observations import FrameObservation
from scrapcut_cli.calibration.residuals import (
    EDGE,
    PARAMETERS,
    SURFACE,
    Frames,
    Residuals,
    Trajectory,
    evaluate,
    huber_weights,
    match_points,
    normal_equations,
    partners_of,
    robust_scales,
    select_pairs,
)
from scrapcut_cli.config import CalibrationConfig
from scrapcut_cli.errors import CalibrationError
from scrapcut_cli.recording.mount import CameraMount

FloatArray = NDArray[np.float64]

#: Gauss-Newton steps taken with one set of correspondences.
STEPS_PER_MATCH = 2

__all__ = ["PARAMETERS", "Solution", "solve"]


@dataclass(frozen=True, eq=False)
class Solution:
    """The estimate and everything the report needs.

    Attributes
    ----------
    correction : (7,) float64
        ``x`` in :data:`PARAMETERS` units (mm, deg, ms), relative to the published mount.
    sigma : (7,) float64
        Standard deviations, same units; NaN where not observable.
    observable : (7,) bool
        Parameters the scan determines (less than a quarter of each in an unobservable
        direction).
    unobservable : tuple of Direction
        Eigen-directions held at the published values, with the reason.
    residual_before_mm, residual_after_mm : dict
        RMS of the gated residuals per kind (``surface``, ``edge``) and ``all``, millimetres.
    frames, pairs, residuals : int
        Frames used, frame pairs compared, residuals at the solution.
    iterations : int
    eigen : list of dict
        The eigen-analysis: per direction ``sigma`` (analysis units) and ``vector``.
    """

    correction: FloatArray
    sigma: FloatArray
    observable: NDArray[np.bool_]
    unobservable: tuple[Direction, ...]
    residual_before_mm: dict[str, float]
    residual_after_mm: dict[str, float]
    frames: int
    pairs: int
    residuals: int
    iterations: int
    eigen: list[dict[str, object]] = field(default_factory=list)


# --------------------------------------------------------------------------- the solve


def solve(
    observations: Sequence[FrameObservation],
    trajectory: Trajectory,
    published: CameraMount,
    config: CalibrationConfig,
) -> Solution:
    """The correction to ``published`` that makes the frames agree (see the module docstring).

    Parameters
    ----------
    observations : sequence of FrameObservation
        Camera-frame measurements of the frames to compare (at least 2).
    trajectory : callable
        ``trajectory(stamps_ns)`` -> (T_base_moving (N, 4, 4), valid (N,)) on the TF clock.
    published : CameraMount
        The mount and offset the recording publishes; the correction is relative to it.
    config : CalibrationConfig

    Raises
    ------
    CalibrationError
        Fewer than two frames, or no pair of frames that overlap.
    """
    obs = [o for o in observations if len(o.surface) > 0]
    if len(obs) < 2:
        raise CalibrationError(
            f"{len(obs)} frame(s) with valid depth: the calibration compares frames with each "
            "other and needs at least 2 that overlap"
        )
    stamps = np.array([o.stamp_ns for o in obs], dtype=np.int64)
    frames = Frames(obs, stamps, published, trajectory)
    zero = np.zeros(7)
    frames.pose(zero)
    if not frames.motion.valid.all():
        bad = int(np.count_nonzero(~frames.motion.valid))
        raise CalibrationError(f"{bad} frame(s) lie outside the /tf time range")
    pairs = select_pairs(
        obs,
        frames.motion.origin_velocity,
        partners=config.partners,
        min_overlap=config.min_overlap,
    )
    frames.partners = partners_of(pairs, len(obs))
    if not pairs:
        raise CalibrationError(
            f"none of the {len(obs)} frames overlap (less than {100 * config.min_overlap:g} % "
            "shared surface): the calibration compares overlapping views"
        )
    tau = _tolerances(config)
    prior = 1.0 / np.square(_prior_sigmas(config))  # information per PARAMETERS unit

    # 1. All seven parameters, weakly held by the prior.
    x, res, scales, gate, iterations = _iterate(frames, zero, None, prior, config)
    # 2. Observability at that solution; 3. again with the unobservable directions held.
    analysis = _analyse(frames, res, scales, x, prior, tau, config)
    basis = analysis.observable_basis  # (7, m) in PARAMETERS units (columns)
    if basis.shape[1] < 7:
        x0 = _project(x, basis, tau)
        x, res, scales, gate, more = _iterate(frames, x0, basis, prior, config, warm=True)
        iterations += more
    sigma = _sigmas(frames, res, scales, x, basis, prior)
    observable = _observable_parameters(analysis.unobservable_vectors, tau)
    sigma = np.where(observable, sigma, np.nan)

    after = _rms_of(res)
    before = _rms_of(_residuals_at(frames, zero, gate))
    return Solution(
        correction=x,
        sigma=sigma,
        observable=observable,
        unobservable=analysis.unobservable,
        residual_before_mm=before,
        residual_after_mm=after,
        frames=len(obs),
        pairs=len(pairs),
        residuals=len(res.r),
        iterations=iterations,
        eigen=analysis.eigen,
    )


def _tolerances(config: CalibrationConfig) -> FloatArray:
    """One analysis unit per parameter, in PARAMETERS units."""
    return np.array(
        [1000.0 * config.observable_sigma_m] * 3
        + [config.observable_sigma_deg] * 3
        + [1000.0 * config.observable_sigma_s]
    )


def _prior_sigmas(config: CalibrationConfig) -> FloatArray:
    return np.array(
        [1000.0 * config.prior_translation_m] * 3
        + [config.prior_rotation_deg] * 3
        + [1000.0 * config.prior_time_offset_s]
    )


def _iterate(
    frames: Frames,
    x0: FloatArray,
    basis: FloatArray | None,
    prior: FloatArray,
    config: CalibrationConfig,
    *,
    warm: bool = False,
) -> tuple[FloatArray, Residuals, FloatArray, float, int]:
    """Gauss-Newton with re-found correspondences; returns x, residuals, scales, gate, steps.

    Correspondences are found once per gate and kept for ``STEPS_PER_MATCH`` steps. ``basis``
    (7, m): move only within its columns (None: all parameters). ``warm``: start at the
    narrowest gate (the correspondences are already good).
    """
    x = np.array(x0, dtype=np.float64)
    gates = _gates(config)
    if warm:
        gates = gates[-2:]
    P = np.diag(prior)
    steps = 0
    tolerance = 1e-3 * _tolerances(config)
    for gate in gates:
        frames.pose(x)
        matches = match_points(frames, frames.partners, gate)
        small = False
        for _ in range(STEPS_PER_MATCH):
            res = evaluate(frames, matches)
            if len(res.r) < 7:
                raise CalibrationError(
                    f"only {len(res.r)} corresponding points between the overlapping frames"
                )
            H, g = normal_equations(res, huber_weights(res, robust_scales(res)))
            A = H + P
            b = -(g + P @ x)
            if basis is None:
                step = np.linalg.solve(A, b)
            else:
                step = basis @ np.linalg.solve(basis.T @ A @ basis, basis.T @ b)
            x = x + step
            steps += 1
            frames.pose(x)
            small = bool(np.all(np.abs(step) < tolerance))
            if small:
                break
        if small and gate == gates[-1]:
            break
    matches = match_points(frames, frames.partners, gates[-1])
    res = evaluate(frames, matches)
    return x, res, robust_scales(res), gates[-1], steps


def _gates(config: CalibrationConfig) -> list[float]:
    """Correspondence gates (m): from max_distance_m down to min_distance_m, then held."""
    n = max(config.iterations, 2)
    hi, lo = config.max_distance_m, config.min_distance_m
    shrink = max(2, n * 2 // 3)
    out = [hi * (lo / hi) ** (j / (shrink - 1)) for j in range(shrink)]
    return out + [lo] * (n - shrink)


def _project(x: FloatArray, basis: FloatArray, tau: FloatArray) -> FloatArray:
    """``x`` without its components outside ``basis`` (orthogonal in analysis units)."""
    u = x / tau
    B = basis / tau[:, None]
    Q, _ = np.linalg.qr(B)
    return np.asarray((Q @ (Q.T @ u)) * tau)


def _residuals_at(frames: Frames, x: FloatArray, gate: float) -> Residuals:
    """The residuals with correction ``x``, correspondences found again within ``gate``."""
    frames.pose(x)
    return evaluate(frames, match_points(frames, frames.partners, gate))


def _rms_of(res: Residuals) -> dict[str, float]:
    """RMS (mm) of residuals per kind (``surface``, ``edge``) and ``all``."""
    out = {}
    for name, sel in ((SURFACE, res.kind == 0), (EDGE, res.kind == 1), ("all", slice(None))):
        r = res.r[sel]
        out[name] = float(np.sqrt(np.mean(r * r))) if r.size else float("nan")
    return out


# --------------------------------------------------------------------------- uncertainty


def _jackknife(
    res: Residuals,
    w: FloatArray,
    A: FloatArray,
    n_frames: int,
) -> FloatArray:
    """Leave-one-frame-out covariance (k, k) of a linearised problem with matrix ``A``.

    ``res.J`` is in the problem's parameters (k columns); at the solution the gradient of the
    whole problem vanishes, so dropping frame f's residuals moves the estimate by
    ``(A − H_f)⁻¹ g_f``.
    """
    k = A.shape[0]
    deltas = []
    Jw = res.J * w[:, None]
    for f in range(n_frames):
        sel = (res.frames[:, 0] == f) | (res.frames[:, 1] == f)
        if not sel.any():
            continue
        H_f = Jw[sel].T @ res.J[sel]
        g_f = Jw[sel].T @ res.r[sel]
        try:
            deltas.append(np.linalg.solve(A - H_f, g_f))
        except np.linalg.LinAlgError:
            continue
    if len(deltas) < 3:
        return np.zeros((k, k))
    D = np.array(deltas)
    D -= D.mean(axis=0)
    m = len(deltas)
    return np.asarray((m - 1) / m * (D.T @ D))


def _formal_variance_factor(res: Residuals, w: FloatArray, k: int) -> float:
    """Σ w r² / (n − k): the whitened residuals' variance (1 when the scales are right)."""
    n = len(res.r)
    return float(np.sum(w * res.r * res.r) / max(n - k, 1))


def _sigmas(
    frames: Frames,
    res: Residuals,
    scales: FloatArray,
    x: FloatArray,
    basis: FloatArray,
    prior: FloatArray,
) -> FloatArray:
    """Standard deviation (7,) of each parameter within the observable ``basis``."""
    w = huber_weights(res, scales)
    Jb = res.J @ basis
    sub = Residuals(res.r, Jb, res.kind, res.frames)
    A = Jb.T @ (Jb * w[:, None]) + basis.T @ np.diag(prior) @ basis
    formal = np.linalg.inv(A) * _formal_variance_factor(res, w, basis.shape[1])
    jack = _jackknife(sub, w, A, len(frames.obs))
    cov = np.maximum(np.diag(basis @ formal @ basis.T), np.diag(basis @ jack @ basis.T))
    return np.sqrt(cov)


@dataclass(frozen=True)
class _Analysis:
    observable_basis: FloatArray  # (7, m)
    unobservable_vectors: FloatArray  # (7, 7 - m) unit in analysis units
    unobservable: tuple[Direction, ...]
    eigen: list[dict[str, object]]


def _analyse(
    frames: Frames,
    res: Residuals,
    scales: FloatArray,
    x: FloatArray,
    prior: FloatArray,
    tau: FloatArray,
    config: CalibrationConfig,
) -> _Analysis:
    """Eigen-analysis of the data's normal equations in analysis units (module docstring)."""
    w = huber_weights(res, scales)
    Ju = res.J * tau[None, :]  # d r / d u with x = tau * u
    H = Ju.T @ (Ju * w[:, None])
    H = 0.5 * (H + H.T)
    values, vectors = np.linalg.eigh(H)
    factor = max(_formal_variance_factor(res, w, 7), 1.0)
    # The jackknife of the weakly regularised problem, in analysis units.
    sub = Residuals(res.r, Ju, res.kind, res.frames)
    A = H + np.diag(prior * tau * tau)
    jack = _jackknife(sub, w, A, len(frames.obs))
    eigen: list[dict[str, object]] = []
    unobservable_idx = []
    for j in range(7):
        v = vectors[:, j]
        formal = factor / values[j] if values[j] > 0 else math.inf
        var = max(formal, float(v @ jack @ v))
        sigma = math.sqrt(var) if math.isfinite(var) else math.inf
        eigen.append(
            {
                "sigma": sigma if math.isfinite(sigma) else None,
                "vector": [round(float(c), 4) for c in v],
            }
        )
        if not sigma <= 1.0:
            unobservable_idx.append(j)
    U = vectors[:, unobservable_idx]
    kept = vectors[:, [j for j in range(7) if j not in unobservable_idx]]
    normals = np.vstack([o.normals @ frames.T[f, :3, :3].T for f, o in enumerate(frames.obs)])
    context = ScanContext.of(frames.T, frames.motion.origin_velocity, normals)
    directions = tuple(
        describe(vectors[:, j], eigen[j]["sigma"], context) for j in unobservable_idx
    )
    return _Analysis(
        observable_basis=kept * tau[:, None],
        unobservable_vectors=U,
        unobservable=directions,
        eigen=eigen,
    )


def _observable_parameters(unobservable: FloatArray, tau: FloatArray) -> NDArray[np.bool_]:
    """A parameter is observable when less than a quarter of it lies in unobservable
    directions (in analysis units)."""
    if unobservable.shape[1] == 0:
        return np.ones(7, dtype=bool)
    share = np.sum(unobservable * unobservable, axis=1)  # |projection of e_j|²
    return np.asarray(share < 0.25)
