"""Open NURBS fit by point-distance minimisation (PCL on_nurbs ``FittingCurve``, made open).

The recipe (:func:`fit_nurbs`):

1. Move the cloud to its canonical frame (``_common``) so the fit does not depend on its pose;
   a cloud of more than ``MAX_FIT_POINTS`` is fitted through count-weighted voxel centroids.
   With a stroke model (``fitting.stroke``: the stroke's centre from its two edges and width,
   holes not taken for edges) the paint is first moved across the line so that its centre is
   the stroke's (``StrokeModel.recentre``); its height and its ends stay the paint's.
2. Initial parameters: the paper's principal-axis projection, and arc lengths along a chain
   down the middle of the cloud built from geodesic distances (``ordering``), which also
   orders arcs, U shapes and helices. ``init="auto"`` runs a few iterations from both and
   goes on with the smaller objective.
3. Alternate (a) a regularised least-squares solve for the control points with the parameters
   fixed and (b) closest-point parameter updates (global nearest of dense samples, then a
   vectorised Newton step on ‖C(t) − x‖², clamped to the domain, never wrapped), until the
   objective stops improving (by ``tolerance_m``, or by 0.1 % of its root).
4. Broken paint: when the paint fills less than ``MIN_BAND_FILL`` of its band (``band_fill``:
   a wire mesh, where paint lands only on the wires) steps 5 and 6 are skipped: the smooth
   fit bridges the gaps instead of bending from wire to wire.
5. Knot refinement (``refine``): a knot span whose points' mean residual stays one-sided (the
   curve runs off the data) is split and the fit resumed, while the objective improves.
6. Corners (``corner_angle_deg``): where the curve turns sharply within a few smoothing
   lengths, a knot of multiplicity ``degree`` (a C0 kink, no bending penalty across it) is
   tried and kept when the fitted kink really turns and the objective improves. A smooth
   spline rounds a 90-degree joint (the paper's I-beam and T-piece NURBS errors); the kink's
   control point settles on the corner instead.
7. The curve is trimmed, or its end polynomials continued, to where the data begins and ends
   (``end_quantile``), then each end is moved back from the paint's tip to the centre of the
   stroke's round cap (``end_trim``, :mod:`~scrapcut_cli.fitting.ends`), re-expressed exactly
   on clamped knots over [0, 1] (``retarget_domain``): model and polyline end together.

Objective, per metre of curve so that neither point density nor the control-point count
changes what ``smoothness`` means::

    E = Σ wᵢ‖C(tᵢ) − xᵢ‖² / Σ wᵢ  +  w · (ℓ/L)⁴ · Σⱼ ‖Dⱼ‖² (ξⱼ₊₁ − ξⱼ₋₁)/2

with ``w`` = ``smoothness`` (the paper's 1.0), L the curve length, ξ the Greville abscissae of
the clamped knot vector on [0, 1] and Dⱼ the second divided difference of the control points
over ξ. For uniform knots Dⱼ ∝ Pⱼ₋₁ − 2Pⱼ + Pⱼ₊₁ (the cage regularisation of PCL), and the
second term approximates w·ℓ⁴/L ∫‖C''(s)‖² ds: a smoothing spline that damps wiggles of
wavelength below about 2πℓ. ℓ is ``smoothing_length_m`` or ``BAND_SMOOTHING`` times the RMS
residual of the initial fit, whichever is larger: a painted band's centre line cannot be
resolved below the band's own width, and with a smaller ℓ point-distance minimisation prefers
a curve zig-zagging across the band. The weights wᵢ are Huber weights (``robust``) against
stray points, times the point counts of aggregated voxels.

B-spline bases and evaluation come from scipy (``BSpline.design_matrix``); the
point-distance loop, the regulariser, the knot refinement and the kinks are written here
because no library does open-curve point-distance fitting in Python (geomdl's
``approximate_curve`` needs ordered points and fixed parameters and has no regulariser).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline
from scipy.linalg import solve
from scipy.spatial import cKDTree

from scrapcut_cli.config import NurbsConfig
from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting._common import (
    CanonicalFrame,
    as_points,
    band_fill,
    canonical_order,
    check_numbers,
    corner_indices,
    follows_input_order,
)
from scrapcut_cli.fitting.curve import Curve, NurbsModel
from scrapcut_cli.fitting.ends import StrokeEnds, check_end_trim, stroke_ends
from scrapcut_cli.fitting.ordering import geodesic_positions, voxel_centroids
from scrapcut_cli.fitting.stroke import StrokeModel
from scrapcut_cli.geometry import cumulative_length, resample_polyline

FloatArray = NDArray[np.float64]

INITS = ("auto", "principal", "chain")
#: Fits from each initialisation run this many iterations before the best one goes on.
SELECTION_ITERATIONS = 2
#: Iterations after a knot insertion or a kink, from the converged fit.
REFINE_ITERATIONS = 6
#: The loop runs on at most this many points (weighted voxel centroids of a denser cloud).
MAX_FIT_POINTS = 2000
#: The smoothing length is at least this many times the RMS residual of the initial fit.
BAND_SMOOTHING = 1.5
#: Smoothing length of that initial (probe) fit.
PROBE_SMOOTHING_M = 0.02
#: The loop also stops when sqrt(E) improves by less than this share in one iteration.
RELATIVE_TOLERANCE = 1e-3
#: Below this share of its band filled with paint (``band_fill``) the paint is broken (a wire
#: mesh: about 0.45; sprayed strokes on solid metal 0.75-1.0): no knot refinement, no corners.
MIN_BAND_FILL = 0.6


@dataclass(frozen=True, eq=False)
class _Fit:
    """One state of the loop, canonical frame: a clamped B-spline on [0, 1] and its data."""

    knots: FloatArray
    control_points: FloatArray
    degree: int
    t: FloatArray  # (N,) closest-point parameters
    residuals: FloatArray  # (N, 3) C(t) - x
    weights: FloatArray  # (N,) weights of the next solve: mass x robust weight
    mass: FloatArray  # (N,) points each fitted point stands for
    objective: float  # E, m^2
    length: float  # m
    iterations: int

    def spline(self) -> BSpline:
        return BSpline(self.knots, self.control_points, self.degree)


def fit_nurbs(
    points_base: ArrayLike,
    *,
    config: NurbsConfig | None = None,
    stroke: StrokeModel | None = None,
) -> Curve:
    """Fit an open NURBS curve through the centre of a painted band.

    Parameters
    ----------
    points_base : (N, 3) float64, metres, base frame
        The stitched paint cloud, any order. Not modified.
    config : NurbsConfig, optional
        Degree, control points, smoothness, iterations, refinement (see the module docstring);
        default: ``NurbsConfig()`` (the paper's smoothness 1.0).
    stroke : StrokeModel, optional
        The stroke's centre from its edges (:mod:`~scrapcut_cli.fitting.stroke`): the paint
        is moved across the line onto it first (its centre is off the line where a hole took
        part of the stroke); the unknown stretches are bridged by the curve's smoothness. The
        curve is fitted to the band collapsed onto the model's centre where the model knows it
        (``StrokeModel.collapse``): a line is then resolved along its length finer than the
        stroke is wide (a groove's V); the ends are still read off the whole band.

    Returns
    -------
    Curve
        ``method="nurbs"``; ``points`` the curve resampled every ``sample_spacing_m``;
        ``nurbs`` the model (degree, clamped knots on [0, 1], control points in the base frame,
        unit weights); ``info`` with ``rms_m``, ``max_residual_m``, ``iterations``,
        ``control_points``, ``knots_inserted``, ``init``, ``length_m``, the ends
        (``stroke_half_width_m``, ``end_trim_m`` [start, end], ``end_shape``) and more. The
        curve runs in the direction of the input order (a stitched cloud's scan direction) and
        ends at the centres of the stroke's round caps (``end_trim``).

    Raises
    ------
    FittingError
        Too few or non-finite points, or bad options.
    """
    config = config if config is not None else NurbsConfig()
    _check_config(config)
    pts = as_points(points_base, minimum=max(2 * (config.degree + 1), 8), what="NURBS fit")
    if stroke is not None:
        pts = stroke.recentre(pts)
    frame = CanonicalFrame.of(pts)
    order = canonical_order(frame.to_local(pts))
    x = frame.to_local(pts)[order]

    # A dense stitched cloud is fitted through the centroids of small voxels, each weighted by
    # its point count (the loop's cost grows with the points; the centre line does not
    # change); residuals, ends and orientation use every point.
    x_all = x
    if stroke is not None:  # the band's width taken out where the model knows the centre
        x = frame.to_local(stroke.collapse(pts)[0])[order]
    x, mass = _aggregate(x)

    candidates = []
    if config.init in ("auto", "principal"):
        candidates.append(("principal", *_principal_parameters(x)))
    if config.init in ("auto", "chain"):
        candidates.append(("chain", *_chain_parameters(x)))
    # The smallest feature a band's centre line can be resolved at is the band's own width:
    # below it a point-distance fit would rather zig-zag across the band than follow it. The
    # width is measured by the residuals of a stiff probe fit (a flexible one would already
    # zig-zag and understate it).
    probe = replace(config, smoothing_length_m=max(config.smoothing_length_m, PROBE_SMOOTHING_M))
    first = [_initial_fit(x, mass, t, length, probe) for _, t, length in candidates]
    spread = min(
        float(np.sqrt(np.sum(f.mass * np.sum(f.residuals**2, axis=1)) / np.sum(f.mass)))
        for f in first
    )
    ell = max(config.smoothing_length_m, BAND_SMOOTHING * spread)
    settings = replace(config, smoothing_length_m=ell)
    trials = {
        name: _iterate(
            x,
            _initial_fit(x, mass, t, length, settings),
            settings,
            min(SELECTION_ITERATIONS, settings.max_iterations),
        )
        for name, t, length in candidates
    }
    init = min(trials, key=lambda name: trials[name].objective)
    fit = _iterate(x, trials[init], settings, settings.max_iterations)
    # On broken paint (a wire mesh) the residuals are one-sided wherever a wire runs beside the
    # line: refinement and kinks would pull the curve from wire to wire, not along the stroke.
    fill = band_fill(fit.spline()(np.linspace(0.0, 1.0, 400)), x_all)
    solid = fill >= MIN_BAND_FILL
    inserted = 0
    if settings.refine and solid:
        fit, inserted = _refine(x, fit, settings)
    corners = 0
    if settings.corner_angle_deg > 0.0 and solid:
        fit, corners = _insert_corners(x, fit, settings)
    fit, ends = _to_data_extent(
        x_all, fit, settings, band_half_width=None if stroke is None else stroke.edge_half_width
    )

    dist = np.linalg.norm(fit.residuals, axis=1)
    model = NurbsModel(
        degree=fit.degree,
        knots=fit.knots.copy(),
        control_points=frame.to_base(fit.control_points),
        weights=np.ones(len(fit.control_points)),
    )
    polyline = _sample_polyline(model, fit.length, config.sample_spacing_m)
    t_input = np.empty_like(fit.t)
    t_input[order] = fit.t
    forward = follows_input_order(t_input)
    curve = Curve(
        points=polyline,
        method="nurbs",
        nurbs=model,
        spacing_m=config.sample_spacing_m,
        info={
            "rms_m": float(np.sqrt(np.mean(dist**2))),
            "max_residual_m": float(dist.max()),
            "median_residual_m": float(np.median(dist)),
            "objective_m2": float(fit.objective),
            "iterations": int(fit.iterations),
            "control_points": len(fit.control_points),
            "degree": fit.degree,
            "knots_inserted": inserted,
            "corners": corners,
            "band_fill": fill,
            "init": init,
            "init_objective_m2": {name: float(f.objective) for name, f in trials.items()},
            "length_m": float(fit.length),
            "points": len(pts),
            "smoothness": float(config.smoothness),
            "smoothing_length_m": float(ell),
            **ends.info(mode=config.end_trim),  # start to end: curve.reversed() turns them
        },
    )
    return curve if forward else curve.reversed()


# --------------------------------------------------------------------------- geomdl export


def nurbs_to_geomdl(model: NurbsModel) -> Any:
    """The model as a ``geomdl.NURBS.Curve`` (weighted control points, same knot vector)."""
    from geomdl import NURBS

    curve = NURBS.Curve()
    curve.degree = int(model.degree)
    w = np.asarray(model.weights, dtype=np.float64)
    weighted = np.column_stack([model.control_points * w[:, None], w])
    curve.ctrlptsw = [[float(c) for c in row] for row in weighted]
    curve.knotvector = [float(k) for k in model.knots]
    return curve


def nurbs_to_geomdl_json(model: NurbsModel) -> str:
    """geomdl's JSON exchange format for one rational curve (``geomdl.exchange.import_json``
    reads it back): ``{"shape": {"type": "curve", "count": 1, "data": [...]}}``."""
    data = {
        "type": "spline",
        "rational": True,
        "dimension": 3,
        "degree": int(model.degree),
        "knotvector": [float(k) for k in model.knots],
        "control_points": {
            "points": [[float(c) for c in p] for p in model.control_points],
            "weights": [float(w) for w in model.weights],
        },
    }
    return json.dumps({"shape": {"type": "curve", "count": 1, "data": [data]}}, indent=2)


# --------------------------------------------------------------------------- initialisation


def _check_config(config: NurbsConfig) -> None:
    if config.degree < 1 or config.degree > 5:
        raise FittingError(f"NURBS degree must be 1 to 5, got {config.degree}")
    if config.control_points is not None and config.control_points < config.degree + 1:
        raise FittingError(
            f"a degree-{config.degree} NURBS needs at least {config.degree + 1} control "
            f"points, got {config.control_points}"
        )
    if config.init not in INITS:
        raise FittingError(f"unknown NURBS init {config.init!r}; known: {', '.join(INITS)}")
    check_numbers(
        config,
        "nurbs",
        positive=("control_point_spacing_m", "sample_spacing_m", "min_knot_spacing_m"),
        non_negative=(
            "smoothness",
            "smoothing_length_m",
            "tolerance_m",
            "refine_bias_m",
            "corner_angle_deg",
        ),
    )
    if not 0.0 <= config.end_quantile < 0.5:
        raise FittingError(f"nurbs.end_quantile must be in [0, 0.5), got {config.end_quantile}")
    check_end_trim(config.end_trim, config.end_trim_m, "nurbs")


def _principal_parameters(x: FloatArray) -> tuple[FloatArray, float]:
    """The paper's start: parameters from the projection on the first principal axis (the
    canonical x axis)."""
    proj = x[:, 0]
    lo, hi = float(proj.min()), float(proj.max())
    return (proj - lo) / (hi - lo), hi - lo


def _chain_parameters(x: FloatArray) -> tuple[FloatArray, float]:
    """Parameters from geodesic distances along the cloud (orders arcs and U shapes too)."""
    position, length = geodesic_positions(x)
    return position / length, length


def _aggregate(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """At most ``MAX_FIT_POINTS`` (points, mass): the points themselves (mass 1) or the
    centroids of the occupied voxels of the smallest size from 1 mm up (x1.25) that leaves no
    more, with their point counts as mass."""
    if len(x) <= MAX_FIT_POINTS:
        return x, np.ones(len(x))
    size = 0.001
    while True:
        centroids, counts, _ = voxel_centroids(x, size)
        if len(centroids) <= MAX_FIT_POINTS:
            return centroids, counts.astype(np.float64)
        size *= 1.25


def _clamped_knots(n_control: int, degree: int) -> FloatArray:
    interior = np.linspace(0.0, 1.0, n_control - degree + 1)[1:-1]
    return np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])


def _control_count(length: float, config: NurbsConfig) -> int:
    if config.control_points is not None:
        return int(config.control_points)
    n = int(np.ceil(length / config.control_point_spacing_m)) + config.degree
    return int(np.clip(n, config.degree + 1, max(config.max_control_points, config.degree + 1)))


def _initial_fit(
    x: FloatArray, mass: FloatArray, t: FloatArray, length: float, config: NurbsConfig
) -> _Fit:
    degree = config.degree
    knots = _clamped_knots(_control_count(length, config), degree)
    ctrl = _solve_control_points(x, t, mass, knots, degree, length, config)
    return _evaluate(x, knots, ctrl, degree, config, iterations=0, mass=mass)


# --------------------------------------------------------------------------- the loop


def _iterate(x: FloatArray, fit: _Fit, config: NurbsConfig, max_iterations: int) -> _Fit:
    """Alternate control-point solves and parameter updates until E stops improving."""
    best = fit
    current = fit
    for _ in range(max_iterations):
        t = current.t
        lo, hi = float(t.min()), float(t.max())
        if hi - lo > 1e-9 and (lo > 0.0 or hi < 1.0):
            # The curve overshoots the data at an end: stretch the parameters over the
            # whole domain so the next solve pulls the end back onto the data.
            t = (t - lo) / (hi - lo)
        ctrl = _solve_control_points(
            x, t, current.weights, current.knots, current.degree, current.length, config
        )
        current = _evaluate(
            x,
            current.knots,
            ctrl,
            current.degree,
            config,
            iterations=current.iterations + 1,
            mass=current.mass,
        )
        improved = np.sqrt(best.objective) - np.sqrt(current.objective)
        if current.objective < best.objective:
            best = current
        if improved < max(config.tolerance_m, RELATIVE_TOLERANCE * np.sqrt(best.objective)):
            break
    return best


def _evaluate(
    x: FloatArray,
    knots: FloatArray,
    ctrl: FloatArray,
    degree: int,
    config: NurbsConfig,
    *,
    iterations: int,
    mass: FloatArray,
) -> _Fit:
    """The fit state of a spline: closest-point parameters, residuals, weights, objective."""
    spline = BSpline(knots, ctrl, degree)
    # Dense samples about a millimetre apart (the control polygon is at least as long as the
    # curve) give both the length and the start of the closest-point search.
    polygon = float(np.linalg.norm(np.diff(ctrl, axis=0), axis=1).sum())
    ts = np.linspace(0.0, 1.0, int(np.clip(polygon / 0.001, 200, 20000)))
    samples = spline(ts)
    length = float(np.linalg.norm(np.diff(samples, axis=0), axis=1).sum())
    t = _closest_parameters(spline, x, ts, samples)
    residuals = spline(t) - x
    dist = np.linalg.norm(residuals, axis=1)
    weights = mass * _huber_weights(dist) if config.robust else mass
    data = float(np.sum(weights * dist**2) / np.sum(weights))
    lam = _penalty_weight(config, length)
    # Pᵀ R P >= 0 (R is positive semi-definite); round-off can make it -1e-20 on exact data.
    bending = float(np.sum(_smoothing_cached(knots.tobytes(), degree) @ ctrl * ctrl))
    penalty = lam * max(bending, 0.0)
    return _Fit(
        knots, ctrl, degree, t, residuals, weights, mass, data + penalty, length, iterations
    )


def _huber_weights(dist: FloatArray) -> FloatArray:
    """Huber weights min(1, c/r) with c = 2.5 x the median residual (at least 1 mm)."""
    c = max(2.5 * float(np.median(dist)), 1e-3)
    return np.asarray(np.minimum(1.0, c / np.maximum(dist, 1e-12)))


def _penalty_weight(config: NurbsConfig, length: float) -> float:
    return float(config.smoothness * (config.smoothing_length_m / max(length, 1e-9)) ** 4)


def _solve_control_points(
    x: FloatArray,
    t: FloatArray,
    weights: FloatArray,
    knots: FloatArray,
    degree: int,
    length: float,
    config: NurbsConfig,
) -> FloatArray:
    """Minimise E over the control points with the parameters fixed (normal equations, M x M).

    Each row of the B-spline design matrix holds ``degree + 1`` basis values on consecutive
    columns, so BᵀWB and BᵀWx are accumulated with ``bincount`` over those few entries.
    """
    basis = BSpline.design_matrix(np.clip(t, 0.0, 1.0), knots, degree)
    m = len(knots) - degree - 1
    values = basis.data.reshape(len(t), degree + 1)
    cols = basis.indices.reshape(len(t), degree + 1)
    weighted = values * weights[:, None]
    pairs = (cols[:, :, None] * m + cols[:, None, :]).ravel()
    products = (weighted[:, :, None] * values[:, None, :]).ravel()
    total = float(weights.sum())
    normal = np.bincount(pairs, weights=products, minlength=m * m).reshape(m, m) / total
    normal += _penalty_weight(config, length) * _smoothing_cached(knots.tobytes(), degree)
    rhs = (
        np.column_stack(
            [
                np.bincount(cols.ravel(), weights=(weighted * x[:, k : k + 1]).ravel(), minlength=m)
                for k in range(3)
            ]
        )
        / total
    )
    # Tiny ridge: a span without data and no smoothing would leave the system singular.
    normal += 1e-12 * np.trace(normal) / len(normal) * np.eye(len(normal))
    return np.asarray(solve(normal, rhs, assume_a="pos"))


def _greville(knots: FloatArray, degree: int) -> FloatArray:
    n = len(knots) - degree - 1
    idx = np.arange(n)[:, None] + np.arange(1, degree + 1)[None, :]
    return np.asarray(knots[idx].mean(axis=1))


@functools.lru_cache(maxsize=64)
def _smoothing_cached(knots: bytes, degree: int) -> FloatArray:
    """:func:`_smoothing_matrix` for a knot vector given as bytes (the loop reuses a few)."""
    matrix = _smoothing_matrix(np.frombuffer(knots, dtype=np.float64), degree)
    matrix.flags.writeable = False
    return matrix


def _smoothing_matrix(knots: FloatArray, degree: int) -> FloatArray:
    """R (M, M) with Pᵀ R P = Σⱼ ‖Dⱼ‖² (ξⱼ₊₁ − ξⱼ₋₁)/2 (second divided differences over the
    Greville abscissae ξ; for uniform knots the paper's Pⱼ₋₁ − 2Pⱼ + Pⱼ₊₁ up to a constant)."""
    xi = _greville(knots, degree)
    m = len(xi)
    if m < 3:
        return np.zeros((m, m))
    h = np.diff(xi)
    h = np.where(h > 0, h, 1e-12)
    j = np.arange(1, m - 1)
    width = 0.5 * (h[j - 1] + h[j])
    d = np.zeros((m - 2, m))
    d[j - 1, j - 1] = 1.0 / (h[j - 1] * width)
    d[j - 1, j] = -(1.0 / h[j - 1] + 1.0 / h[j]) / width
    d[j - 1, j + 1] = 1.0 / (h[j] * width)
    # No bending penalty across a kink (a knot of multiplicity >= degree: a corner).
    weight = np.where(np.isin(j, _kink_indices(knots, degree)), 0.0, width)
    return np.asarray(d.T @ (d * weight[:, None]))


def _kink_indices(knots: FloatArray, degree: int) -> NDArray[np.int64]:
    """Indices of the control points sitting on interior knots of multiplicity >= degree."""
    inner = knots[degree + 1 : -degree - 1]
    if len(inner) == 0 or degree < 2:
        return np.zeros(0, dtype=np.int64)
    values, counts = np.unique(inner, return_counts=True)
    kinks = values[counts >= degree]
    if len(kinks) == 0:
        return np.zeros(0, dtype=np.int64)
    # The control point whose Greville abscissa equals the kink's knot value.
    xi = _greville(knots, degree)
    gap = np.abs(xi[:, None] - kinks[None, :]).min(axis=1)
    return np.asarray(np.flatnonzero(gap <= 1e-12), dtype=np.int64)


def _closest_parameters(
    spline: BSpline, x: FloatArray, ts: FloatArray, samples: FloatArray, *, newton_steps: int = 1
) -> FloatArray:
    """Parameters (N,) of the curve points nearest to ``x``: the nearest of the dense
    ``samples`` at ``ts``, then Newton steps on ‖C(t) − x‖², clamped to [0, 1] (the curve is
    open: parameters never wrap)."""
    _, nearest = cKDTree(samples).query(x)
    t = ts[nearest]
    step_limit = 2.0 * float(ts[1] - ts[0])
    for _ in range(newton_steps):
        r = spline(t) - x
        d1 = spline(t, 1)
        grad = np.einsum("ij,ij->i", r, d1)
        hess = np.einsum("ij,ij->i", d1, d1)
        if spline.k >= 2:
            full = hess + np.einsum("ij,ij->i", r, spline(t, 2))
            hess = np.where(full > 1e-12, full, hess)
        step = np.clip(grad / np.maximum(hess, 1e-12), -step_limit, step_limit)
        t = np.clip(t - step, 0.0, 1.0)
    return np.asarray(t)


# --------------------------------------------------------------------------- refinement


def _refine(x: FloatArray, fit: _Fit, config: NurbsConfig) -> tuple[_Fit, int]:
    """Split knot spans whose residuals stay one-sided; keep a round only if E improves."""
    inserted = 0
    for _ in range(config.refine_rounds):
        if len(fit.control_points) >= config.max_control_points:
            break
        new_knots = _knots_to_insert(fit, config)
        room = config.max_control_points - len(fit.control_points)
        new_knots = new_knots[:room]
        if len(new_knots) == 0:
            break
        knots = np.sort(np.concatenate([fit.knots, new_knots]))
        ctrl = _solve_control_points(x, fit.t, fit.weights, knots, fit.degree, fit.length, config)
        start = _evaluate(
            x, knots, ctrl, fit.degree, config, iterations=fit.iterations, mass=fit.mass
        )
        trial = _iterate(x, start, config, min(REFINE_ITERATIONS, config.max_iterations))
        if trial.objective >= fit.objective:
            break
        inserted += len(new_knots)
        fit = trial
    return fit, inserted


def _knots_to_insert(fit: _Fit, config: NurbsConfig) -> FloatArray:
    """Midpoints of the spans whose mean residual vector exceeds both ``refine_bias_m`` and
    three standard errors of the mean: the curve runs systematically off the data there."""
    breaks = np.unique(fit.knots)
    span = np.clip(np.searchsorted(breaks, fit.t, side="right") - 1, 0, len(breaks) - 2)
    n_spans = len(breaks) - 1
    count = np.bincount(span, weights=fit.mass, minlength=n_spans)
    mean = (
        np.column_stack(
            [
                np.bincount(span, weights=fit.mass * fit.residuals[:, k], minlength=n_spans)
                for k in range(3)
            ]
        )
        / np.maximum(count, 1.0)[:, None]
    )
    sq = np.bincount(span, weights=fit.mass * np.sum(fit.residuals**2, axis=1), minlength=n_spans)
    spread = np.sqrt(np.maximum(sq / np.maximum(count, 1.0) - np.sum(mean**2, axis=1), 0.0))
    bias = np.linalg.norm(mean, axis=1)
    span_length = np.diff(breaks) * fit.length
    split = (
        (count >= 2 * (fit.degree + 1))
        & (bias > config.refine_bias_m)
        & (bias > 3.0 * spread / np.sqrt(np.maximum(count, 1.0)))
        & (span_length >= 2.0 * config.min_knot_spacing_m)
    )
    # Worst spans first, so the control-point budget goes where the curve is furthest off.
    order = np.argsort(-bias[split], kind="stable")
    mids = 0.5 * (breaks[:-1] + breaks[1:])
    return np.asarray(np.sort(mids[split][order]))


# --------------------------------------------------------------------------- corners


def _insert_corners(x: FloatArray, fit: _Fit, config: NurbsConfig) -> tuple[_Fit, int]:
    """Turn sharp turns into kinks: a knot of multiplicity ``degree`` (C0) with no bending
    penalty across it, kept when the fitted kink turns by at least ``corner_angle_deg`` and the
    objective improves. A smooth spline rounds a 90-degree joint (the paper's I-beam and T-piece
    errors); with the kink, its control point settles on the corner.
    """
    kept = 0
    threshold = np.radians(config.corner_angle_deg)
    for t_corner in _corner_candidates(fit, config)[: config.max_corners]:
        span = config.min_knot_spacing_m / max(fit.length, 1e-9)
        inner = fit.knots[fit.degree + 1 : -fit.degree - 1]
        inner = inner[np.abs(inner - t_corner) > span]
        knots = np.concatenate(
            [
                np.zeros(fit.degree + 1),
                np.sort(np.concatenate([inner, np.full(fit.degree, t_corner)])),
                np.ones(fit.degree + 1),
            ]
        )
        ctrl = _solve_control_points(x, fit.t, fit.weights, knots, fit.degree, fit.length, config)
        start = _evaluate(
            x, knots, ctrl, fit.degree, config, iterations=fit.iterations, mass=fit.mass
        )
        trial = _iterate(x, start, config, min(REFINE_ITERATIONS, config.max_iterations))
        angles = _kink_angles(trial)
        if trial.objective < fit.objective and len(angles) > kept and angles.min() >= threshold:
            fit = trial
            kept += 1
    return fit, kept


def _corner_candidates(fit: _Fit, config: NurbsConfig) -> FloatArray:
    """Parameters where the fitted curve turns by more than the corner angle within two
    smoothing lengths (and hardly more within four)."""
    spline = fit.spline()
    ts = np.linspace(0.0, 1.0, max(int(fit.length / 0.001), 200))
    polyline = spline(ts)
    idx = corner_indices(
        polyline,
        reach=2.0 * config.smoothing_length_m,
        angle=float(np.radians(config.corner_angle_deg)),
    )
    return np.asarray(ts[idx])


def _kink_angles(fit: _Fit) -> FloatArray:
    """Turning angle (radians) of the control polygon at each kink control point."""
    idx = _kink_indices(fit.knots, fit.degree)
    if len(idx) == 0:
        return np.zeros(0)
    p = fit.control_points
    a = p[idx] - p[idx - 1]
    b = p[idx + 1] - p[idx]
    cos = np.einsum("ij,ij->i", a, b) / np.maximum(
        np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-18
    )
    return np.asarray(np.arccos(np.clip(cos, -1.0, 1.0)))


# --------------------------------------------------------------------------- ends


def _to_data_extent(
    x: FloatArray, fit: _Fit, config: NurbsConfig, *, band_half_width: float | None = None
) -> tuple[_Fit, StrokeEnds]:
    """Trim or extend the curve to where the points ``x`` (all of them) begin and end along it,
    each end then moved in to its round cap's centre (``end_trim``; ``band_half_width``: the
    stroke's from its edges, see ``ends.stroke_ends``); exactly: the end spans' polynomials
    are continued, then re-expressed on clamped knots over [0, 1]. The state returned is
    evaluated on ``x``."""
    spline = fit.spline()
    ts = np.linspace(0.0, 1.0, max(int(fit.length / 0.0005), 200))
    dense = spline(ts)
    s = cumulative_length(dense)
    # The band's own reach: the fit may have been made to its collapsed centre.
    dist, _ = cKDTree(dense).query(x)
    radius = max(2.0 * float(np.quantile(dist, 0.95)), 0.002)
    ends = stroke_ends(
        dense,
        x,
        quantile=config.end_quantile,
        radius=radius,
        mode=config.end_trim,
        trim_m=config.end_trim_m,
        band_half_width=band_half_width,
    )
    speed0 = float(np.linalg.norm(spline(0.0, 1)))
    speed1 = float(np.linalg.norm(spline(1.0, 1)))
    a = _arc_to_parameter(ends.start, ts, s, speed0, speed1)
    b = _arc_to_parameter(ends.end, ts, s, speed0, speed1)
    knots, ctrl = fit.knots, fit.control_points
    if b - a > 1e-9 and (abs(a) >= 1e-9 or abs(b - 1.0) >= 1e-9):
        knots, ctrl = retarget_domain(knots, ctrl, fit.degree, a, b)
    state = _evaluate(
        x, knots, ctrl, fit.degree, config, iterations=fit.iterations, mass=np.ones(len(x))
    )
    return state, ends


def _arc_to_parameter(
    s_query: float, ts: FloatArray, s: FloatArray, speed0: float, speed1: float
) -> float:
    if s_query < 0.0:
        return s_query / max(speed0, 1e-12)
    if s_query > s[-1]:
        return 1.0 + (s_query - float(s[-1])) / max(speed1, 1e-12)
    return float(np.interp(s_query, s, ts))


def retarget_domain(
    knots: FloatArray, control_points: FloatArray, degree: int, a: float, b: float
) -> tuple[FloatArray, FloatArray]:
    """The same curve restricted (or polynomially continued) to parameters [a, b], as clamped
    knots on [0, 1] and new control points. Exact up to round-off: the piecewise polynomial is
    unchanged, only re-expressed (interpolation at the new Greville abscissae)."""
    inner = knots[degree + 1 : -degree - 1]
    inner = inner[(inner > a + 1e-12) & (inner < b - 1e-12)]
    new = np.concatenate([np.full(degree + 1, a), inner, np.full(degree + 1, b)])
    xi = np.clip(_greville(new, degree), a, b)
    values = BSpline(knots, control_points, degree, extrapolate=True)(xi)
    collocation = BSpline.design_matrix(xi, new, degree).toarray()
    ctrl = np.asarray(solve(collocation, values))
    return (new - a) / (b - a), ctrl


def _sample_polyline(model: NurbsModel, length: float, spacing: float) -> FloatArray:
    n = max(int(np.ceil(length / min(spacing / 4.0, 0.00025))), 200)
    dense = model.evaluate(np.linspace(0.0, 1.0, n))
    return resample_polyline(dense, spacing)
