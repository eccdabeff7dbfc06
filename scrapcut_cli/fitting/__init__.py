"""Curve fitters: open NURBS and 3-D skeletonisation.

``fit_curve(points_base, method, config)`` runs the fitter named by ``method`` on a stitched
paint cloud and returns a :class:`~scrapcut_cli.fitting.curve.Curve` running along the centre
of the painted band; given a stroke model (:func:`~scrapcut_cli.fitting.stroke.stroke_model`:
the centre from the stroke's edges, holes not taken for edges) both fitters follow it.
:func:`~scrapcut_cli.fitting.stroke.with_confidence` adds each curve point's confidence.
``trim_to_paint`` cuts back whatever of a curve runs past its paint at the ends and measures the
reverse distance (curve to paint). ``extrapolate_end`` gives the exploration planner the
direction in which the line continues beyond one end of a fitted curve (the paper's
Algorithm 1).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.config import FitMethod, ScrapcutConfig, choice_names
from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting._common import clip_to_extent
from scrapcut_cli.fitting.closure import UNOBSERVED_GAP, Closure, detect_closure, unobserved_arcs
from scrapcut_cli.fitting.curve import Curve, NurbsModel
from scrapcut_cli.fitting.ends import past_paint
from scrapcut_cli.fitting.nurbs import (
    fit_nurbs,
    nurbs_to_geomdl,
    nurbs_to_geomdl_json,
    retarget_domain,
)
from scrapcut_cli.fitting.nurbs_closed import fit_closed_nurbs
from scrapcut_cli.fitting.skeleton import fit_skeleton
from scrapcut_cli.fitting.stroke import StrokeModel
from scrapcut_cli.geometry import cumulative_length, resample_polyline

__all__ = [
    "METHODS",
    "Closure",
    "Curve",
    "NurbsModel",
    "detect_closure",
    "extrapolate_end",
    "fit_curve",
    "fit_line",
    "fit_nurbs",
    "fit_skeleton",
    "nurbs_to_geomdl",
    "nurbs_to_geomdl_json",
    "trim_to_paint",
]

METHODS = choice_names(FitMethod)

#: Length of the chord that gives a NURBS curve's end direction.
END_CHORD_M = 0.01


def fit_curve(
    points_base: ArrayLike,
    method: str,
    config: ScrapcutConfig,
    *,
    closure: Closure | None = None,
    stroke: StrokeModel | None = None,
) -> Curve:
    """Fit the curve of ``method`` ("nurbs" or "skeleton") to ``points_base`` (N, 3) float64,
    metres, base frame, with that method's section of ``config``; with ``stroke`` (the stroke
    model of the same paint, :mod:`~scrapcut_cli.fitting.stroke`) an open fit follows the
    stroke's centre from its edges.

    ``closure``: :func:`~scrapcut_cli.fitting.closure.detect_closure` of these points (and the
    surface around them); when it is closed the fit is a loop (a periodic NURBS, the
    skeleton's cycle) and ``info`` holds the closure. None: an open fit. A loop through an arc
    no camera saw is an open band until then: with ``stroke`` the NURBS fit takes its paint
    moved onto the stroke's centre (``StrokeModel.recentre``), the skeleton the model itself,
    centring its open band on the collapsed paint as an open line's fit does.
    """
    if method not in METHODS:
        raise FittingError(f"unknown fitting method {method!r}; known: {', '.join(METHODS)}")
    if closure is not None and closure.closed:
        # An arc no camera saw leaves an open band: its centre from its edges too (a band
        # seen at a grazing angle near the gap shows one side of the stroke).
        open_band = stroke if closure.reason == UNOBSERVED_GAP else None
        if method == "nurbs":
            if open_band is not None:
                points_base = open_band.recentre(points_base)
            curve = fit_closed_nurbs(points_base, closure=closure, config=config.nurbs)
        else:
            curve = fit_skeleton(
                points_base, config=config.skeleton, closure=closure, stroke=open_band
            )
        curve.info["closure"] = closure.info()
        curve.info["closure_reason"] = closure.reason
        return curve
    if method == "nurbs":
        curve = fit_nurbs(points_base, config=config.nurbs, stroke=stroke)
    else:
        curve = fit_skeleton(points_base, config=config.skeleton, stroke=stroke)
    if closure is not None:
        curve.info["closure"] = closure.info()
        curve.info["closure_reason"] = closure.reason
    return curve


def fit_line(
    paint_base: ArrayLike,
    surface_base: ArrayLike | None,
    method: str,
    config: ScrapcutConfig,
    *,
    stroke: StrokeModel | None = None,
) -> Curve:
    """A stitched line's curve, open or closed: the global fit of a scan.

    Decides whether the paint ``paint_base`` (N, 3) closes on itself, with the observed bare
    surface ``surface_base`` (M, 3) around it (metres, base frame; :func:`detect_closure`),
    fits ``method`` open or closed, and on a closed curve finds the arcs where neither paint
    nor surface was observed (``info["unobserved_arcs_m"]``: [start, end] metres along
    ``points`` from its first point, end < start when an arc runs across it). ``stroke``:
    the stroke model an open fit follows (see :func:`fit_curve`).
    """
    closure = detect_closure(paint_base, surface_base, config=config.closure)
    curve = fit_curve(paint_base, method, config, closure=closure, stroke=stroke)
    if curve.closed:
        arcs = unobserved_arcs(
            curve.points,
            paint_base,
            surface_base,
            half_width_m=closure.half_width_m,
            min_arc_m=config.closure.min_unobserved_arc_m,
        )
        curve.info["unobserved_arcs_m"] = [[a, b] for a, b in arcs]
    return curve


def trim_to_paint(curve: Curve, paint_base: ArrayLike, *, tolerance_m: float) -> Curve:
    """``curve`` without what runs past the paint ``paint_base`` (N, 3) at its ends: beyond the
    paint's extent along it and by more than ``tolerance_m`` (``fitting.ends.past_paint``),
    NURBS model included; ``info`` gains
    ``paint_trim_m`` (per end), ``reverse_mean_m`` and ``reverse_max_m`` (curve to paint).
    A closed curve is not trimmed (it has no ends); its reverse distance is reported."""
    paint = np.asarray(paint_base, dtype=np.float64).reshape(-1, 3)
    if curve.closed:  # a loop has no ends to run past: only the reverse distance is reported
        whole = replace(past_paint(curve.polyline, paint, tolerance_m=np.inf), tolerance_m=0.0)
        return replace(curve, info={**curve.info, **whole.info()})
    check = past_paint(curve.points, paint, tolerance_m=tolerance_m)
    info = {**curve.info, **check.info()}
    if check.trims == (0.0, 0.0) or check.end - check.start <= curve.spacing_m:
        return Curve(curve.points, curve.method, curve.nurbs, curve.spacing_m, info)
    points = resample_polyline(
        clip_to_extent(curve.points, check.start, check.end), curve.spacing_m
    )
    nurbs = curve.nurbs
    if nurbs is not None and np.allclose(nurbs.weights, 1.0):
        lo, hi = nurbs.domain
        t = np.linspace(lo, hi, max(int(curve.length / 0.0002), 200))
        s = cumulative_length(nurbs.evaluate(t))
        a, b = np.interp([check.start, check.end], s, t)
        knots, ctrl = retarget_domain(nurbs.knots, nurbs.control_points, nurbs.degree, a, b)
        nurbs = NurbsModel(nurbs.degree, knots, ctrl, np.ones(len(ctrl)))
    return Curve(points, curve.method, nurbs, curve.spacing_m, info)


def extrapolate_end(
    curve: Curve, end: Literal["start", "end"], *, step_m: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Where the line goes on beyond one end of ``curve``, as the paper's planner samples it.

    The direction comes from two points near the end: for a NURBS curve, the model evaluated at
    its end parameter and at the parameter ``END_CHORD_M`` (1 cm) of arc length inwards; for a
    skeleton, its last two ordered skeleton vertices (``curve.info["skeleton_points"]``);
    otherwise (or with fewer than two vertices) the polyline's own end chord.

    Returns
    -------
    point : (3,) float64, metres, base frame
        The curve's end moved ``step_m`` along ``direction``.
    direction : (3,) float64
        Unit vector pointing out of the curve at that end.
    """
    if end not in ("start", "end"):
        raise ValueError(f"end must be 'start' or 'end', got {end!r}")
    if step_m < 0:
        raise ValueError(f"step_m must not be negative, got {step_m}")
    if len(curve.points) < 2:
        raise FittingError("cannot extrapolate a curve of fewer than two points")
    at_start = end == "start"
    tip = np.asarray(curve.points[0] if at_start else curve.points[-1], dtype=np.float64)
    direction = _end_direction(curve, at_start)
    return tip + step_m * direction, direction


def _end_direction(curve: Curve, at_start: bool) -> NDArray[np.float64]:
    if curve.nurbs is not None:
        pair = _nurbs_end_pair(curve.nurbs, at_start)
    else:
        vertices = np.asarray(curve.info.get("skeleton_points", []), dtype=np.float64)
        if vertices.ndim == 2 and len(vertices) >= 2:
            pair = vertices[:2][::-1] if at_start else vertices[-2:]
        else:
            pair = _polyline_end_pair(curve.points, at_start)
    d = pair[1] - pair[0]
    n = float(np.linalg.norm(d))
    if n <= 0.0:
        pair = _polyline_end_pair(curve.points, at_start)
        d = pair[1] - pair[0]
        n = float(np.linalg.norm(d))
    if n <= 0.0:
        raise FittingError("cannot extrapolate a curve whose end points coincide")
    return np.asarray(d / n)


def _nurbs_end_pair(model: NurbsModel, at_start: bool) -> NDArray[np.float64]:
    """(inner point, end point) of a NURBS, ``END_CHORD_M`` apart along the curve (or a
    quarter of the curve if it is shorter)."""
    lo, hi = model.domain
    t = np.linspace(lo, hi, 2001)
    if at_start:
        t = t[::-1]
    pts = model.evaluate(t)
    s = cumulative_length(pts)
    s = s[-1] - s  # arc length back from the end
    reach = min(END_CHORD_M, 0.25 * float(s[0]))
    inner = pts[int(np.clip(np.searchsorted(-s, -reach), 0, len(pts) - 1))]
    return np.vstack([inner, pts[-1]])


def _polyline_end_pair(points: NDArray[np.float64], at_start: bool) -> NDArray[np.float64]:
    pts = points[::-1] if at_start else points
    s = cumulative_length(pts)
    reach = min(END_CHORD_M, 0.25 * float(s[-1]))
    inner = pts[int(np.clip(np.searchsorted(s, s[-1] - reach) - 1, 0, len(pts) - 1))]
    return np.vstack([inner, pts[-1]])
