"""Path error against the painted reference: the paper's Table I metric, and what it misses.

The paper samples the drawn reference curve and averages the distance to the resulting path
(Section V-A). We do the same, exactly: the reference is resampled every
``EvaluationConfig.sample_spacing_m`` (1 mm) and each sample's distance is taken to the nearest
point of the fitted curve's *polyline* (point-to-segment, :class:`~scrapcut_cli.geometry.
PolylineDistance`), not to its vertices, so the vertex spacing of the curve does not inflate the
error.

That one-sided distance cannot see a path that wanders off the line (the reference never comes
near the detour) and is only weakly hurt by one that stops early (the missing end's samples are
far from the path, but only a few). So every result also carries:

- ``coverage``: the share of reference samples within ``coverage_threshold_m`` (10 mm) of the
  path;
- the reverse distance, path → reference (mean and max over the curve resampled at the same
  spacing);
- the length ratio, curve length / reference length;
- RMSE, median and 95th percentile of the same per-sample distances (evo's habit).

The set-points are scored too (:func:`setpoint_error`): the surface point of each set-point
(where the jet meets the piece) against the reference, and how much of the reference they
cover, so a path file with a good curve but missing or wandering set-points cannot hide.

A closed reference (a ring, a cut-out) is scored as a loop: its samples run round it, closing
segment included, and distances are taken to the curve's polyline closed too when the curve is
closed. What a closed line's scan could not see is scored apart (:class:`LoopError`): the
error and coverage over the *observed* arcs (outside the arcs no camera saw: the simulator's
truth when the reference carries it, else the arcs the path reports unobserved), the reported
unobserved arcs against the true ones (extent error of their ends, in arc length along the
reference), and the share of set-points on the true arcs flagged ``unobserved`` (and
elsewhere).

When the path file says how sure each set-point is (``sigma_m``, docs/path-file.md), each reference
sample's error is also set against σ at its nearest point of the curve (σ interpolated along
the curve's arc length): ``within_2sigma`` is the share of samples within 2σ of the path — about
95 % for a calibrated Gaussian σ; far less means σ is overconfident — and ``sigma_median_m`` the
typical σ the path claimed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.config import EvaluationConfig
from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.geometry import (
    MAX_COORDINATE_M,
    PolylineDistance,
    closed_polyline,
    cumulative_length,
    interpolate_polyline,
    resample_polyline,
)

FloatArray = NDArray[np.float64]

#: Millimetres per metre, for reports.
MM = 1000.0


@dataclass(frozen=True, eq=False)
class PathError:
    """Error of one fitted curve against its reference. Lengths in metres, base frame.

    Attributes
    ----------
    mean_m, sd_m, min_m, max_m : float
        Statistics of the distance from each reference sample to the curve polyline (the
        paper's Table I); ``sd_m`` is the population standard deviation.
    coverage : float
        Share (0–1) of reference samples within ``coverage_threshold_m`` of the curve.
    reverse_mean_m, reverse_max_m : float
        Mean and max distance from the curve (resampled every ``sample_spacing_m``) to the
        reference polyline.
    length_ratio : float
        Curve length / reference length.
    reference_length_m, curve_length_m : float
        Arc lengths of the two polylines.
    sample_s : (M,) float64
        Normalised arc length (0 at the reference's first point, 1 at its last) of each sample.
    sample_errors_m : (M,) float64
        Distance of each reference sample to the curve (the paper's Fig. 5 along ``sample_s``).
    coverage_threshold_m, sample_spacing_m : float
        The configuration the numbers were computed with.
    rmse_m, median_m, p95_m : float
        Root mean square, median and 95th percentile of the same distances.
    sample_points : (M, 3) float64, metres, base frame
        The reference samples themselves (``--save-results`` writes them beside the errors).
    sample_sigma_m : (M,) float64 or None
        σ the path claims at each sample's nearest curve point (None: the path has no σ).
    """

    mean_m: float
    sd_m: float
    min_m: float
    max_m: float
    coverage: float
    reverse_mean_m: float
    reverse_max_m: float
    length_ratio: float
    reference_length_m: float
    curve_length_m: float
    sample_s: FloatArray
    sample_errors_m: FloatArray
    coverage_threshold_m: float
    sample_spacing_m: float
    rmse_m: float = float("nan")
    median_m: float = float("nan")
    p95_m: float = float("nan")
    sample_points: FloatArray | None = None
    closed: bool = False
    loop: LoopError | None = None
    sample_sigma_m: FloatArray | None = None

    @property
    def samples(self) -> int:
        """Number of reference samples."""
        return len(self.sample_errors_m)

    @property
    def within_2sigma(self) -> float | None:
        """Share (0–1) of reference samples within 2σ of the path (None without σ)."""
        if self.sample_sigma_m is None:
            return None
        return float(np.mean(self.sample_errors_m <= 2.0 * self.sample_sigma_m))

    def summary_mm(self) -> dict[str, Any]:
        """Scalar figures for reports: millimetres, coverage as a share (0–1), plain floats."""
        return {
            "mean_mm": self.mean_m * MM,
            "sd_mm": self.sd_m * MM,
            "min_mm": self.min_m * MM,
            "max_mm": self.max_m * MM,
            "rmse_mm": self.rmse_m * MM,
            "median_mm": self.median_m * MM,
            "p95_mm": self.p95_m * MM,
            "coverage": self.coverage,
            "reverse_mean_mm": self.reverse_mean_m * MM,
            "reverse_max_mm": self.reverse_max_m * MM,
            "length_ratio": self.length_ratio,
            "reference_length_mm": self.reference_length_m * MM,
            "curve_length_mm": self.curve_length_m * MM,
            "samples": self.samples,
            "coverage_threshold_mm": self.coverage_threshold_m * MM,
            "sigma_median_mm": None
            if self.sample_sigma_m is None
            else float(np.median(self.sample_sigma_m)) * MM,
            "within_2sigma": self.within_2sigma,
            **({"closed": True} if self.closed else {}),
            **({} if self.loop is None else self.loop.summary_mm()),
        }


@dataclass(frozen=True, eq=False)
class LoopError:
    """What a closed line's scan saw and what it reports it did not. Metres.

    Attributes
    ----------
    observed_mean_m, observed_sd_m, observed_min_m, observed_max_m : float or None
        The Table I statistics over the reference samples on observed arcs (None: none).
    observed_coverage : float or None
        Share of those samples within the coverage threshold.
    observed_share : float
        Share of the reference's samples on observed arcs.
    observed_from : str
        ``truth`` (the reference's own unseen arcs), ``path`` (the arcs the path reports) or
        ``all`` (neither: every sample counts as observed).
    true_arcs_m, reported_arcs_m : list of (float, float)
        Unobserved arcs as (start, end) arc lengths along the reference from its first point
        (end < start wraps): the truth (empty when unknown) and the path's, projected.
    extent_error_m : float or None
        Largest distance along the reference between the ends of a true arc and of the
        reported arc overlapping it most; None when no truth, or a true arc has no reported
        counterpart (``arcs_missed``).
    arcs_missed : int
        True arcs no reported arc overlaps.
    flagged_on_arcs, flagged_elsewhere : float or None
        Share of set-points flagged ``unobserved`` among those on the true arcs, and among the
        others (None without truth or set-points).
    reference_length_m : float
        The loop's length.
    """

    observed_mean_m: float | None
    observed_sd_m: float | None
    observed_min_m: float | None
    observed_max_m: float | None
    observed_coverage: float | None
    observed_share: float
    observed_from: str
    true_arcs_m: list[tuple[float, float]]
    reported_arcs_m: list[tuple[float, float]]
    extent_error_m: float | None
    arcs_missed: int
    flagged_on_arcs: float | None
    flagged_elsewhere: float | None
    reference_length_m: float

    def summary_mm(self) -> dict[str, Any]:
        def mm(value: float | None) -> float | None:
            return None if value is None else value * MM

        return {
            "observed_mean_mm": mm(self.observed_mean_m),
            "observed_sd_mm": mm(self.observed_sd_m),
            "observed_min_mm": mm(self.observed_min_m),
            "observed_max_mm": mm(self.observed_max_m),
            "observed_coverage": self.observed_coverage,
            "observed_share": self.observed_share,
            "observed_from": self.observed_from,
            "unobserved_true_mm": sum(
                _span(a, b, self.reference_length_m) for a, b in self.true_arcs_m
            )
            * MM,
            "unobserved_reported_mm": sum(
                _span(a, b, self.reference_length_m) for a, b in self.reported_arcs_m
            )
            * MM,
            "unobserved_arcs": len(self.reported_arcs_m),
            "unobserved_true_arcs": len(self.true_arcs_m),
            "unobserved_extent_error_mm": mm(self.extent_error_m),
            "unobserved_arcs_missed": self.arcs_missed,
            "unobserved_flagged_on_arcs": self.flagged_on_arcs,
            "unobserved_flagged_elsewhere": self.flagged_elsewhere,
        }


def path_error(
    curve_points: ArrayLike,
    reference: ArrayLike,
    *,
    config: EvaluationConfig | None = None,
    curve_closed: bool = False,
    reference_closed: bool = False,
    true_unseen_arcs_m: Sequence[tuple[float, float]] | None = None,
    reported_unobserved_m: Sequence[tuple[float, float]] = (),
    setpoints: ArrayLike | None = None,
    setpoint_unobserved: ArrayLike | None = None,
    sigma_m: ArrayLike | None = None,
) -> PathError:
    """Measure a fitted curve against the painted reference curve.

    Parameters
    ----------
    curve_points : (N, 3) float64, metres, base frame
        The fitted curve as an ordered polyline (a path file's ``curve.points``, on the
        surface). Its direction does not matter.
    reference : (M, 3) float64, metres, base frame
        The painted reference curve, an ordered polyline.
    config : EvaluationConfig
        Sample spacing (default 1 mm) and coverage threshold (default 10 mm).
    curve_closed, reference_closed : bool
        The curve (its last point joins its first) and the reference are loops.
    true_unseen_arcs_m : list of (start, end), optional
        A closed reference's arcs no camera saw, metres along it from its first point (end <
        start wraps): the simulator's truth. Scored as :class:`LoopError`.
    reported_unobserved_m : list of (start, end)
        The arcs the path reports unobserved, metres along ``curve_points`` from its first
        point (end < start wraps).
    setpoints, setpoint_unobserved : (K, 3) float64 and (K,) bool, optional
        The set-points' surface points on the loop and which carry ``unobserved``.
    sigma_m : (N,) float64, optional
        The path's lateral uncertainty at each curve point, metres (from its set-points):
        each sample's error is then set against σ at its nearest curve point.

    Raises
    ------
    EvaluationError
        If either polyline has fewer than two distinct points or non-finite coordinates, σ
        does not match the curve or is negative, or the configuration is not positive.
    """
    config = EvaluationConfig() if config is None else config
    for name in ("sample_spacing_m", "coverage_threshold_m"):
        value = getattr(config, name)
        if not (np.isfinite(value) and value > 0):
            raise EvaluationError(f"evaluation.{name} must be a finite number > 0, got {value}")
    curve = _polyline(curve_points, "fitted curve")
    ref = _polyline(reference, "reference")
    curve_vertices = curve
    if curve_closed:
        curve = closed_polyline(curve)
    if reference_closed:
        ref = closed_polyline(ref)

    ref_samples = resample_polyline(ref, config.sample_spacing_m)
    s = cumulative_length(ref_samples)
    errors, _, parameter = PolylineDistance(curve).query(ref_samples)
    sample_sigma = None
    if sigma_m is not None:
        sigma = np.asarray(sigma_m, dtype=np.float64).reshape(-1)
        if len(sigma) != len(curve) or not (np.isfinite(sigma).all() and (sigma >= 0).all()):
            raise EvaluationError(
                f"sigma_m must hold one finite value >= 0 per curve point ({len(curve)}), "
                f"got {len(sigma)}"
            )
        sample_sigma = np.interp(parameter, np.arange(len(curve), dtype=np.float64), sigma)

    curve_samples = resample_polyline(curve, config.sample_spacing_m)
    reverse = PolylineDistance(ref).distance(curve_samples)

    ref_length = float(s[-1])
    curve_length = float(cumulative_length(curve)[-1])
    return PathError(
        mean_m=float(errors.mean()),
        sd_m=float(errors.std()),
        min_m=float(errors.min()),
        max_m=float(errors.max()),
        coverage=float(np.mean(errors <= config.coverage_threshold_m)),
        reverse_mean_m=float(reverse.mean()),
        reverse_max_m=float(reverse.max()),
        length_ratio=curve_length / ref_length,
        reference_length_m=ref_length,
        curve_length_m=curve_length,
        sample_s=s / ref_length,
        sample_errors_m=errors,
        coverage_threshold_m=float(config.coverage_threshold_m),
        sample_spacing_m=float(config.sample_spacing_m),
        rmse_m=float(np.sqrt(np.mean(errors * errors))),
        median_m=float(np.median(errors)),
        p95_m=float(np.percentile(errors, 95.0)),
        sample_points=ref_samples,
        closed=reference_closed,
        loop=None
        if not reference_closed
        else loop_error(
            ref_samples,
            s,
            errors,
            curve_vertices,
            curve_closed=curve_closed,
            threshold_m=float(config.coverage_threshold_m),
            true_arcs=list(true_unseen_arcs_m) if true_unseen_arcs_m is not None else None,
            reported=list(reported_unobserved_m),
            setpoints=setpoints,
            setpoint_unobserved=setpoint_unobserved,
        ),
        sample_sigma_m=sample_sigma,
    )


@dataclass(frozen=True, eq=False)
class SetpointError:
    """The set-points of a path against the reference. Lengths in metres, base frame.

    Attributes
    ----------
    count : int
        Set-points in the path (0: the path cannot be cut, whatever its curve scores).
    flagged : dict[str, int]
        Set-points per flag (``tilted``, ``collision``, ``no_surface``...); a set-point with
        two flags counts in both.
    flagged_total : int
        Set-points with at least one flag.
    mean_m, max_m : float or None
        Distance of each set-point's surface point (where the torch axis meets the piece) to
        the reference polyline; None without set-points.
    coverage : float
        Share of the reference samples within the coverage threshold of the polyline through
        the surface points (0 without set-points): set-points missing along part of the line
        lower it even when the curve is complete.
    """

    count: int
    flagged: dict[str, int]
    flagged_total: int
    mean_m: float | None
    max_m: float | None
    coverage: float

    def summary_mm(self) -> dict[str, Any]:
        """Figures for reports (millimetres, plain numbers)."""
        return {
            "setpoints": self.count,
            "setpoints_flagged": self.flagged_total,
            "setpoint_flags": dict(sorted(self.flagged.items())),
            "setpoint_mean_mm": None if self.mean_m is None else self.mean_m * MM,
            "setpoint_max_mm": None if self.max_m is None else self.max_m * MM,
            "setpoint_coverage": self.coverage,
        }


def setpoint_error(
    surface_points: ArrayLike,
    flags: list[list[str]],
    reference: ArrayLike,
    *,
    config: EvaluationConfig | None = None,
) -> SetpointError:
    """Score a path's set-points against the painted reference.

    Parameters
    ----------
    surface_points : (N, 3) float64, metres, base frame
        Each set-point's surface point, in path order (N may be 0).
    flags : list of N lists of str
        Each set-point's flags.
    reference : (M, 3) float64, metres, base frame
        The painted reference polyline.
    """
    config = EvaluationConfig() if config is None else config
    pts = np.asarray(surface_points, dtype=np.float64).reshape(-1, 3)
    if len(flags) != len(pts):
        raise EvaluationError(f"{len(pts)} set-points but {len(flags)} flag lists")
    ref = _polyline(reference, "reference")
    counts: dict[str, int] = {}
    for names in flags:
        for name in set(names):
            counts[name] = counts.get(name, 0) + 1
    flagged_total = sum(1 for names in flags if names)
    if len(pts) == 0:
        return SetpointError(0, counts, flagged_total, None, None, 0.0)
    if not np.isfinite(pts).all():
        raise EvaluationError("set-point surface points hold NaN or infinite coordinates")
    d = PolylineDistance(ref).distance(pts)
    samples = resample_polyline(ref, config.sample_spacing_m)
    covered = PolylineDistance(pts).distance(samples) <= config.coverage_threshold_m
    return SetpointError(
        count=len(pts),
        flagged=counts,
        flagged_total=flagged_total,
        mean_m=float(d.mean()),
        max_m=float(d.max()),
        coverage=float(np.mean(covered)),
    )


def loop_error(
    ref_samples: FloatArray,
    s: FloatArray,
    errors: FloatArray,
    curve: FloatArray,
    *,
    curve_closed: bool,
    threshold_m: float,
    true_arcs: list[tuple[float, float]] | None,
    reported: list[tuple[float, float]],
    setpoints: ArrayLike | None,
    setpoint_unobserved: ArrayLike | None,
) -> LoopError:
    """:class:`LoopError` of a closed reference sampled at ``ref_samples`` (M, 3) (arc lengths
    ``s`` (M,), the last sample closing the loop) with sample errors (M,), for a fitted
    ``curve`` (N, 3) whose reported unobserved arcs are ``reported`` (metres along it)."""
    length = float(s[-1])
    ref_line = PolylineDistance(ref_samples)
    projected = []
    if reported:
        c_poly = closed_polyline(curve) if curve_closed else curve
        c_s = cumulative_length(c_poly)
        # Does the curve run the reference's way round? (median step of its vertices' places)
        places = np.interp(ref_line.query(c_poly)[2], np.arange(len(s)), s)
        steps = (np.diff(places) + 0.5 * length) % length - 0.5 * length
        same_way = float(np.median(steps)) >= 0.0
        for a, b in reported:
            ends = interpolate_polyline(c_poly, [a, b], cumulative=c_s)
            u = ref_line.query(ends)[2]
            sa, sb = np.interp(u, np.arange(len(s)), s)
            if not same_way:
                sa, sb = sb, sa
            projected.append((float(sa) % length, float(sb) % length))
    if true_arcs is not None:
        unseen, origin = _in_arcs(s, true_arcs, length), "truth"
    elif projected:
        unseen, origin = _in_arcs(s, projected, length), "path"
    else:
        unseen, origin = np.zeros(len(s), dtype=bool), "all"
    seen = ~unseen
    e = errors[seen]
    extent, missed = None, 0
    if true_arcs is not None:
        gaps = []
        for a, b in true_arcs:
            best = max(projected, key=lambda r: _overlap((a, b), r, length), default=None)
            if best is None or _overlap((a, b), best, length) <= 0.0:
                missed += 1
                continue
            gaps += [_circular(a - best[0], length), _circular(b - best[1], length)]
        extent = None if missed or not gaps else float(max(gaps))
    on_arcs = elsewhere = None
    if true_arcs is not None and setpoints is not None and setpoint_unobserved is not None:
        sp = np.asarray(setpoints, dtype=np.float64).reshape(-1, 3)
        flagged = np.asarray(setpoint_unobserved, dtype=bool).reshape(-1)
        if len(sp):
            u = ref_line.query(sp)[2]
            where = _in_arcs(np.interp(u, np.arange(len(s)), s), true_arcs, length)
            on_arcs = float(flagged[where].mean()) if where.any() else None
            elsewhere = float(flagged[~where].mean()) if (~where).any() else None
    result = LoopError(
        observed_mean_m=float(e.mean()) if len(e) else None,
        observed_sd_m=float(e.std()) if len(e) else None,
        observed_min_m=float(e.min()) if len(e) else None,
        observed_max_m=float(e.max()) if len(e) else None,
        observed_coverage=float(np.mean(e <= threshold_m)) if len(e) else None,
        observed_share=float(seen.mean()),
        observed_from=origin,
        true_arcs_m=list(true_arcs or []),
        reported_arcs_m=projected,
        extent_error_m=extent,
        arcs_missed=missed,
        flagged_on_arcs=on_arcs,
        flagged_elsewhere=elsewhere,
        reference_length_m=length,
    )
    return result


def _span(a: float, b: float, length: float) -> float:
    return (b - a) % length if length > 0 and b != a else (length if b == a else b - a)


def _in_arcs(
    s: FloatArray, arcs: Sequence[tuple[float, float]], length: float
) -> NDArray[np.bool_]:
    inside = np.zeros(len(s), dtype=bool)
    for a, b in arcs:
        if b >= a:
            inside |= (s >= a) & (s <= b)
        else:
            inside |= (s >= a) | (s <= b)
    return inside


def _overlap(x: tuple[float, float], y: tuple[float, float], length: float) -> float:
    """Length of the overlap of two arcs on a loop (sampled every millimetre)."""
    grid = np.arange(0.0, length, 0.001)
    return float(np.sum(_in_arcs(grid, [x], length) & _in_arcs(grid, [y], length)) * 0.001)


def _circular(d: float, length: float) -> float:
    d = d % length
    return min(d, length - d)


def _polyline(points: ArrayLike, what: str) -> FloatArray:
    """Validated (N, 3) float64 copy with at least two distinct points."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise EvaluationError(f"{what} must be an (N, 3) array of points, got shape {pts.shape}")
    if not (np.abs(pts) <= MAX_COORDINATE_M).all():  # also NaN
        raise EvaluationError(
            f"{what} has non-finite or implausible coordinates (beyond {MAX_COORDINATE_M:g} m)"
        )
    if len(pts) < 2 or cumulative_length(pts)[-1] <= 0.0:
        raise EvaluationError(f"{what} needs at least two distinct points, got {len(pts)}")
    return pts
