"""Closed NURBS fit: a periodic B-spline by the same point-distance minimisation as the open fit.

PCL's on_nurbs ``FittingCurve`` fits closed curves only (its ``initNurbsCurve2D`` makes a
periodic curve and its assembly wraps the basis); the paper opened it. This is the closed case
again, written for our objective (:mod:`~scrapcut_cli.fitting.nurbs`)::

    E = Σ wᵢ‖C(tᵢ) − xᵢ‖² / Σ wᵢ  +  w · (ℓ/L)⁴ · Σⱼ ‖Dⱼ‖² / n

over n control points P₀..Pₙ₋₁ of a uniform periodic B-spline on t ∈ [0, 1): the basis of
control point j is the clamped one shifted by j/n and wrapped round, so the design matrix's
columns are folded modulo n, and Dⱼ = n² (Pⱼ₋₁ − 2Pⱼ + Pⱼ₊₁) runs round the loop (the open fit's
second divided differences over the Greville abscissae, which are evenly spaced 1/n here).
Closest-point parameters wrap round the loop instead of clamping. The initial parameters are
arc lengths along the closure's loop (:mod:`~scrapcut_cli.fitting.closure`: the paint's chain
closed by its bridge), so an arc no camera saw starts as a parameter span without data. The
bending term alone would carry the curve across it as the curve that bends least, which
flattens a ring's gap towards its chord (12 mm inside a 75 mm ring over a third of it); so
the gap holds guide points on the bridge that continues both ends' turn
(:func:`~scrapcut_cli.fitting.closure.bridge_directions`, read over a few stroke widths, and
:func:`~scrapcut_cli.fitting.closure.hermite_bridge`, scaled as a circular arc), each as
heavy as the paint along as much of the line. The arc stays flagged ``unobserved``
downstream.

A closed curve has no ends to trim. Knot refinement and kinks are not tried (the knots stay
uniform): a loop with sharp corners (a square cut-out) is rounded at the smoothing length.

The model is written in the unclamped form every NURBS reader takes (geomdl included): knots
``(i - p) / n`` for i = 0..n+2p rescaled to [0, 1], and the first p control points repeated at
the end; its domain is the middle part of the knot vector.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline
from scipy.linalg import solve
from scipy.spatial import cKDTree

from scrapcut_cli.config import NurbsConfig
from scrapcut_cli.fitting._common import CanonicalFrame, as_points, canonical_order
from scrapcut_cli.fitting.closure import (
    UNOBSERVED_GAP,
    Closure,
    bridge_directions,
    hermite_bridge,
)
from scrapcut_cli.fitting.curve import Curve, NurbsModel
from scrapcut_cli.fitting.nurbs import (
    BAND_SMOOTHING,
    PROBE_SMOOTHING_M,
    RELATIVE_TOLERANCE,
    _aggregate,
    _check_config,
    _huber_weights,
    _penalty_weight,
)
from scrapcut_cli.geometry import closed_polyline, cumulative_length, resample_loop

FloatArray = NDArray[np.float64]

#: Fewest control points of a closed curve per degree (a loop needs room to turn round).
MIN_CONTROL_PER_DEGREE = 2
#: Spacing of the guide points on the bridge over an unobserved gap, metres; each weighs as
#: much as the paint along that length of the line.
GUIDE_SPACING_M = 0.002


@dataclass(frozen=True, eq=False)
class _Loop:
    """One state of the loop, canonical frame: n control points of a periodic B-spline."""

    control_points: FloatArray  # (n, 3), not wrapped
    degree: int
    t: FloatArray  # (N,) closest-point parameters in [0, 1)
    residuals: FloatArray  # (N, 3)
    weights: FloatArray  # (N,)
    mass: FloatArray  # (N,)
    objective: float
    length: float
    iterations: int

    def spline(self) -> BSpline:
        return periodic_spline(self.control_points, self.degree)


def periodic_knots(n: int, degree: int) -> FloatArray:
    """Uniform knots (n + 2p + 1,) of a periodic B-spline with n control points on [0, 1)."""
    return np.arange(-degree, n + degree + 1, dtype=np.float64) / n


def periodic_spline(control_points: FloatArray, degree: int) -> BSpline:
    """scipy BSpline of the periodic curve (evaluate at t in [0, 1]; t = 1 is t = 0)."""
    n = len(control_points)
    wrapped = np.vstack([control_points, control_points[:degree]])
    return BSpline(periodic_knots(n, degree), wrapped, degree)


def fit_closed_nurbs(
    points_base: ArrayLike, *, closure: Closure, config: NurbsConfig | None = None
) -> Curve:
    """Fit a closed (periodic) NURBS through the centre of a painted loop.

    Parameters
    ----------
    points_base : (N, 3) float64, metres, base frame
        The stitched paint cloud, any order. Not modified.
    closure : Closure
        A closed :func:`~scrapcut_cli.fitting.closure.detect_closure` result for these points:
        its loop orders the points and bridges an unobserved gap.
    config : NurbsConfig, optional
        Degree, control-point spacing, smoothness, iterations, robust weights, sample spacing.

    Returns
    -------
    Curve
        ``closed=True``, ``method="nurbs"``; ``points`` the loop resampled every
        ``sample_spacing_m`` from the closure chain's first end (not repeating it), in the
        closure's direction; ``nurbs`` the periodic model (``periodic=True``, unit weights,
        base frame); ``info`` as the open fit's where it applies.
    """
    config = config if config is not None else NurbsConfig()
    _check_config(config)
    pts = as_points(points_base, minimum=max(2 * (config.degree + 1), 8), what="NURBS fit")
    frame = CanonicalFrame.of(pts)
    x_all = frame.to_local(pts)[canonical_order(frame.to_local(pts))]
    x, mass = _aggregate(x_all)
    # Across an arc no camera saw, the curve follows the bridge that continues both ends'
    # turn (``closure.bridge_directions``, ``hermite_bridge``) as though it were paint: the
    # bending term alone would pull it towards the gap's chord (a ring's 120-degree gap: 12 mm
    # inside a 75 mm ring).
    chain = frame.to_local(closure.chain)
    guide = _gap_guide(chain, closure)
    if len(guide):
        density = float(mass.sum()) / max(float(cumulative_length(chain)[-1]), 1e-9)
        x = np.vstack([x, guide])
        mass = np.concatenate([mass, np.full(len(guide), density * GUIDE_SPACING_M)])
    loop = frame.to_local(closure.loop)
    loop_length = float(cumulative_length(closed_polyline(loop))[-1])
    t0 = loop_parameters(loop, x)
    n = _control_count(loop_length, config)

    probe = replace(config, smoothing_length_m=max(config.smoothing_length_m, PROBE_SMOOTHING_M))
    first = _initial(x, mass, t0, n, loop_length, probe)
    data = slice(0, len(x) - len(guide))  # the band's spread, not the guide's
    spread = float(
        np.sqrt(
            np.sum(mass[data] * np.sum(first.residuals[data] ** 2, axis=1)) / np.sum(mass[data])
        )
    )
    ell = max(config.smoothing_length_m, BAND_SMOOTHING * spread)
    settings = replace(config, smoothing_length_m=ell)
    fit = _iterate(x, _initial(x, mass, t0, n, loop_length, settings), settings)
    final = _evaluate(x_all, fit.control_points, fit.degree, settings, iterations=fit.iterations)

    dist = np.linalg.norm(final.residuals, axis=1)
    ctrl_base = frame.to_base(fit.control_points)
    model = periodic_model(ctrl_base, fit.degree)
    polyline = frame.to_base(_sample_loop(fit, config.sample_spacing_m))
    return Curve(
        points=polyline,
        method="nurbs",
        nurbs=model,
        spacing_m=config.sample_spacing_m,
        closed=True,
        info={
            "rms_m": float(np.sqrt(np.mean(dist**2))),
            "max_residual_m": float(dist.max()),
            "median_residual_m": float(np.median(dist)),
            "objective_m2": float(fit.objective),
            "iterations": int(fit.iterations),
            "control_points": n,
            "degree": fit.degree,
            "knots_inserted": 0,
            "corners": 0,
            "init": "closure",
            "length_m": float(final.length),
            "points": len(pts),
            "smoothness": float(config.smoothness),
            "smoothing_length_m": float(ell),
        },
    )


def _gap_guide(chain: FloatArray, closure: Closure) -> FloatArray:
    """Points (G, 3) every ``GUIDE_SPACING_M`` on the bridge over an unobserved gap, the
    chain's frame, without its two ends; none when the loop was seen all round."""
    if closure.reason != UNOBSERVED_GAP or len(chain) < 4 or closure.half_width_m <= 0.0:
        return np.zeros((0, 3))
    out_last, out_first = bridge_directions(chain, half_width_m=closure.half_width_m)
    bridge = hermite_bridge(chain[-1], out_last, chain[0], out_first, spacing=GUIDE_SPACING_M)
    return np.asarray(bridge[1:-1])


def periodic_model(control_points: FloatArray, degree: int) -> NurbsModel:
    """The periodic curve of ``control_points`` (n, 3) as a :class:`NurbsModel` in unclamped
    form: knots rescaled to [0, 1] and the first ``degree`` control points repeated."""
    n = len(control_points)
    knots = periodic_knots(n, degree)
    knots = (knots - knots[0]) / (knots[-1] - knots[0])
    wrapped = np.vstack([control_points, control_points[:degree]])
    return NurbsModel(
        degree=degree,
        knots=knots,
        control_points=wrapped,
        weights=np.ones(len(wrapped)),
        periodic=True,
    )


def loop_parameters(loop: FloatArray, x: FloatArray) -> FloatArray:
    """Each point's position (N,) round a loop given by its vertices (K, 3), as a share of the
    loop's length in [0, 1), from the loop's first vertex (nearest vertex of a 1 mm
    resampling)."""
    dense = resample_loop(loop, 0.001)
    s = cumulative_length(closed_polyline(dense))
    _, nearest = cKDTree(dense).query(x)
    return np.asarray(s[nearest] / s[-1])


# --------------------------------------------------------------------------- the loop


def _control_count(length: float, config: NurbsConfig) -> int:
    if config.control_points is not None:
        n = int(config.control_points)
    else:
        n = int(np.ceil(length / config.control_point_spacing_m))
    lo = MIN_CONTROL_PER_DEGREE * (config.degree + 1)
    return int(np.clip(n, lo, max(config.max_control_points, lo)))


def _initial(
    x: FloatArray, mass: FloatArray, t: FloatArray, n: int, length: float, config: NurbsConfig
) -> _Loop:
    ctrl = _solve(x, t, mass, n, config.degree, length, config)
    return _evaluate(x, ctrl, config.degree, config, iterations=0, mass=mass)


def _iterate(x: FloatArray, fit: _Loop, config: NurbsConfig) -> _Loop:
    """Alternate control-point solves and parameter updates until E stops improving."""
    best = current = fit
    n = len(fit.control_points)
    for _ in range(config.max_iterations):
        ctrl = _solve(x, current.t, current.weights, n, current.degree, current.length, config)
        current = _evaluate(
            x, ctrl, current.degree, config, iterations=current.iterations + 1, mass=current.mass
        )
        improved = np.sqrt(best.objective) - np.sqrt(current.objective)
        if current.objective < best.objective:
            best = current
        if improved < max(config.tolerance_m, RELATIVE_TOLERANCE * np.sqrt(best.objective)):
            break
    return best


def _evaluate(
    x: FloatArray,
    ctrl: FloatArray,
    degree: int,
    config: NurbsConfig,
    *,
    iterations: int,
    mass: FloatArray | None = None,
) -> _Loop:
    """Closest-point parameters, residuals, weights and the objective of a periodic spline."""
    mass = np.ones(len(x)) if mass is None else mass
    spline = periodic_spline(ctrl, degree)
    polygon = float(np.linalg.norm(np.diff(closed_polyline(ctrl), axis=0), axis=1).sum())
    ts = np.linspace(0.0, 1.0, int(np.clip(polygon / 0.001, 200, 20000)), endpoint=False)
    samples = spline(ts)
    length = float(np.linalg.norm(np.diff(closed_polyline(samples), axis=0), axis=1).sum())
    t = _closest(spline, x, ts, samples)
    residuals = spline(t) - x
    dist = np.linalg.norm(residuals, axis=1)
    weights = mass * _huber_weights(dist) if config.robust else mass
    data = float(np.sum(weights * dist**2) / np.sum(weights))
    bending = float(np.sum(_cyclic_smoothing(len(ctrl)) @ ctrl * ctrl))
    objective = data + _penalty_weight(config, length) * max(bending, 0.0)
    return _Loop(ctrl, degree, t, residuals, weights, mass, objective, length, iterations)


def _solve(
    x: FloatArray,
    t: FloatArray,
    weights: FloatArray,
    n: int,
    degree: int,
    length: float,
    config: NurbsConfig,
) -> FloatArray:
    """Minimise E over the n control points with the parameters fixed (normal equations); the
    wrapped basis columns fold onto the first ``degree`` control points."""
    basis = BSpline.design_matrix(np.mod(t, 1.0), periodic_knots(n, degree), degree)
    values = basis.data.reshape(len(t), degree + 1)
    cols = basis.indices.reshape(len(t), degree + 1) % n
    weighted = values * weights[:, None]
    pairs = (cols[:, :, None] * n + cols[:, None, :]).ravel()
    products = (weighted[:, :, None] * values[:, None, :]).ravel()
    total = float(weights.sum())
    normal = np.bincount(pairs, weights=products, minlength=n * n).reshape(n, n) / total
    normal += _penalty_weight(config, length) * _cyclic_smoothing(n)
    rhs = (
        np.column_stack(
            [
                np.bincount(cols.ravel(), weights=(weighted * x[:, k : k + 1]).ravel(), minlength=n)
                for k in range(3)
            ]
        )
        / total
    )
    normal += 1e-12 * np.trace(normal) / n * np.eye(n)
    return np.asarray(solve(normal, rhs, assume_a="pos"))


def _cyclic_smoothing(n: int) -> FloatArray:
    """R (n, n) with Pᵀ R P = Σⱼ ‖n² (Pⱼ₋₁ − 2Pⱼ + Pⱼ₊₁)‖² / n, indices modulo n."""
    d = np.zeros((n, n))
    j = np.arange(n)
    d[j, (j - 1) % n] += 1.0
    d[j, j] -= 2.0
    d[j, (j + 1) % n] += 1.0
    d *= float(n) ** 2
    return np.asarray(d.T @ d / n)


def _closest(spline: BSpline, x: FloatArray, ts: FloatArray, samples: FloatArray) -> FloatArray:
    """Parameters (N,) of the curve points nearest to ``x``: the nearest dense sample, then one
    Newton step on ‖C(t) − x‖², wrapped round [0, 1)."""
    _, nearest = cKDTree(samples).query(x)
    t = ts[nearest]
    limit = 2.0 * float(ts[1] - ts[0])
    r = spline(t) - x
    d1 = spline(t, 1)
    grad = np.einsum("ij,ij->i", r, d1)
    hess = np.einsum("ij,ij->i", d1, d1)
    if spline.k >= 2:
        full = hess + np.einsum("ij,ij->i", r, spline(t, 2))
        hess = np.where(full > 1e-12, full, hess)
    step = np.clip(grad / np.maximum(hess, 1e-12), -limit, limit)
    return np.asarray(np.mod(t - step, 1.0))


def _sample_loop(fit: _Loop, spacing: float) -> FloatArray:
    n = max(int(np.ceil(fit.length / min(spacing / 4.0, 0.00025))), 400)
    dense = fit.spline()(np.linspace(0.0, 1.0, n, endpoint=False))
    return resample_loop(dense, spacing)
