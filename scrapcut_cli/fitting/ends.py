"""Where a painted line really ends: the centre of a spray stroke's round cap, not its tip.

A spray stroke is a band of half width h around the intended line, and where the can starts
or stops it leaves a round cap: a half disc of radius about h centred on the line's end. The
paint therefore reaches about h beyond each intended end, and a curve clamped to the paint's
extent (``_common.data_extent``) overshoots by that much (12 mm for the usual 25 mm stroke);
a torch following it cuts past the mark. Around the stroke lies a halo of overspray specks
(denser near the edge, out to a few centimetres), which stitching smears further; it reaches
past the cap too, so the paint's extent lies in the halo. :func:`stroke_ends` moves each end
back to where the full-width band stops:

1. **The edge profile.** The distances |u| of the paint points to the fitted curve, away from
   the ends (at least twice the half width in from either end of the paint), have a density
   that is flat across the band, falls across its edge (blur, ragged edge, misregistered
   views) and then tails off (the halo). Its most likely non-increasing estimate (Grenander:
   the slopes of the least concave majorant of their empirical distribution, from a convex
   hull) over the band's own density (between the 0.2 and 0.6 quantiles: the inner half of a
   band is never halo, and 3-D noise thins its first millimetres) is the **edge profile**
   P(t), the paint density at a signed distance t from the edge (negative inside), relative
   to the band's. The **half width** h is the area under P's levels 0.3-0.7 stretched to 0-1:
   the middle of a blurred or ragged edge (its half-density point), also when a slightly
   off-centre curve sees the edge at h - e on one side and h + e on the other; a halo
   sparser than 0.3 of the band counts for nothing. Points scattered isotropically around a
   curve (10 % quantile above 0.37 of the median; a band's is 0.2) have no band edge:
   "no band", kept.
2. **The end window.** The dense paint ends where a run of h/2 along the line holds less than
   half the band's points within the band's width (a halo is sparser; the band's density is
   the line's, or the one over four half widths before the end's window where that is
   lower: a steep face seen at a grazing angle holds less paint, and its last stretch is
   line, not halo); the window runs from
   three half widths (plus the profile's reach, where P falls below 5 %) before it, half a
   half width beyond that end or at the paint's tip if sooner. Its points are placed by their
   position x along the curve extended straight past its end and their offset d across the
   line within the band's plane (its normal is the direction least spanned by the offsets and
   the tangents: paint that wrapped over an edge beside the end, onto the top of an I-beam
   flange, is off the plane and left out). The band's local half width h_b is the most likely
   shift of the profile for the offsets of the window's inner part (prior h ± 10 %).
3. **A round cap.** The window's points are taken as drawn with density P(δ), δ the signed
   distance from a region made of the band of half width h_b up to E and a half disc of radius
   h_c centred at E, normalised over the window (the paint's own spill, halo included, is
   expected around the cap as it is beside the band); (E, h_c) maximise the likelihood with
   the prior h_c = h_b ± 7.5 %. The point-process likelihood is what makes E definite: every
   unit of area the region claims without points costs, every point outside costs by how
   much sparser the paint is at its distance from the edge. It is a mean over the points (the
   same cloud given twice ends at the same place) weighed as the points of a 2 mm stitching
   grid over the window's painted length.
4. **Or a square end.** Paint that runs off the edge of a piece (or out of the camera's view)
   stops square, at full width: the same likelihood with a rectangle. It is chosen only when
   it beats the round cap by ``SQUARE_EVIDENCE`` nats and the paint just inside the tip is as
   wide as the band (specks beside it do not count); the line then ends at the paint's edge
   (cutting short of an edge would leave the piece attached). On ragged, sparse paint a
   square end is recognised about half of the time and otherwise taken for a cap;
   ``end_trim="none"`` keeps every end where the paint ends.
5. **Or gapped paint.** When the window's paint has gaps (an empty run over 4 mm: a basket's
   wires), a density has too little to go on; the end is the envelope instead (with the
   stroke's half width h: a wire patch or two tell the local one poorly): the last E
   that keeps the points inside the band and cap (a wire across the cap, narrowed to the
   cap's chord, places E; a full-width wire says the line goes at least that far). An end
   whose cap falls in a gap cannot be seen: the curve ends on the last wire. When the stroke's
   half width is known from its edges (``band_half_width``: ``fitting.stroke``) and the
   paint's profile is much narrower (under ``_FILLED`` of it: on a mesh whose wires run
   along the line the paint's profile is the wires', 4 mm on the simulator's basket against
   10 mm from the edges), the paint does not fill its band: both ends are the envelope's, with
   the edges' half width, over the last ``_WINDOW`` of them within the extent.
6. **Limits.** An end never moves beyond the paint's extent, and each end moves in by at most
   ``MAX_TRIM_SHARE`` of the extent, so a stroke shorter than its own width keeps at least half
   of its length.

The grid search (E on a 2 mm then 0.25 mm grid, h_c over seven ratios, the normalisation
integrated on a 1 mm grid) is vectorised numpy written here: no library fits this region
model; the hull is scipy's (Qhull). ``mode="cap"`` always assumes round caps, ``"none"``
keeps the extent, and a fixed ``trim_m`` (for a stroke width known beforehand) replaces the
estimate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, QhullError, cKDTree

from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting._common import (
    arc_positions,
    extended_polyline,
    extended_positions,
    extent_of,
)
from scrapcut_cli.geometry import (
    cumulative_length,
    interpolate_polyline,
    polyline_length,
    resample_polyline,
)

FloatArray = NDArray[np.float64]

#: ``end_trim`` modes: estimate each end's shape; always a round cap; no trimming.
END_TRIM_MODES = ("auto", "cap", "none")
#: A square end must beat the round cap by this log-likelihood (nats): spray caps are the rule.
#: (Over 40 simulated strokes each: no capped end, with or without a heavy overspray halo,
#: reaches it; clean square ends do 80 % of the time, ragged ones about half.)
SQUARE_EVIDENCE = 5.0
#: ... and its paint just inside the tip must be this wide (share of the band's half width).
_SQUARE_WIDTH = 0.85
#: Each end moves in by at most this share of the paint's extent.
MAX_TRIM_SHARE = 0.25
#: Windows at the ends, in half widths (plus the profile's reach): the whole window, and how
#: far from its outer end its inner (band) part stops.
_WINDOW = 3.0
_BAND_PART = 1.5
#: Points counted at an end: within this many half widths of the curve (and the radius the
#: profile was measured in), and at most this many off the band's plane.
_NEAR = 2.5
_OFF_PLANE = 0.5
#: The curve is extended straight by this much past its ends to place the points beyond them.
_REACH = 0.05
#: Prior spread of the cap radius over h_b (a ragged stroke's width changes by that much within
#: a cap's length), and the ratios tried (two spreads either way).
_CAP_PRIOR = 0.075
_CAP_RATIOS = np.linspace(0.85, 1.15, 7)
#: Local half widths tried, as shares of the stroke's, and their prior spread (a hand-held
#: can's stroke varies by about 10 % along the line).
_LOCAL_WIDTHS = np.linspace(0.75, 1.25, 51)
_WIDTH_PRIOR = 0.1
#: Fewest points for a half-width fit, and for an end model.
_MIN_WIDTH_POINTS = 20
_MIN_END_POINTS = 15
#: Evidence is counted per (2 mm)^2 of painted window, the stitching voxel's share of a band.
_VOXEL_M = 0.002
#: A band: the 10 % quantile of the lateral distance is at most this share of the median
#: (a uniform band: 0.2; the distances of isotropic noise around a curve, Rayleigh: 0.39).
_BAND_SHAPE = 0.37
#: Relative paint density of the profile's floor (stray points anywhere), and the density
#: whose distance beyond the edge is the profile's reach.
_FLOOR = 0.01
_REACH_DENSITY = 0.05
#: Quantiles of |u| between which the band's own density is measured.
_INSIDE = (0.2, 0.6)
#: Density levels (share of the band's) below which the paint is no band, above which all
#: band, when the edge is placed.
_EDGE_LEVEL = 0.3
#: The dense paint ends where a run of this many half widths holds less than half the band's
#: density: the whole line's, or the one over ``_LOCAL_SPAN`` half widths just before the end's
#: window when it is sparser there.
_DENSE_RUN = 0.5
_LOCAL_SPAN = 4.0
#: Integration step of the end model's normalisation, metres.
_STEP_M = 0.001
#: The end's grid search: a coarse step over the whole range, then a fine one around its best.
_COARSE_M = 0.002
_FINE_M = 0.00025
#: Slices along the window (metres), and the empty run between paint that makes it gapped.
_SLICE_M = 0.001
_GAP_M = 0.004
#: Share of the paint left beyond each end of its extent along a curve when checking that the
#: curve does not run past it (stray specks).
_EXTENT_QUANTILE = 0.002
#: Share of the largest end bounds of gapped paint left out.
_ENVELOPE_SHARE = 0.05
#: Paint whose profile's half width is under this share of the stroke's (from its edges) does
#: not fill its band (a wire mesh: the paint on the wires along the line makes its profile);
#: a solid stroke's reads 1.0-1.15 of it.
_FILLED = 0.75


@dataclass(frozen=True)
class StrokeEnds:
    """Where a painted line starts and ends along a polyline, and why.

    ``start`` and ``end`` are arc lengths (metres) along the polyline the estimate was made on
    (``start`` may be negative, ``end`` beyond its length: see ``_common.clip_to_extent``).
    ``trims`` is how far each end was moved in from the paint's extent, ``shapes`` what each
    end looked like ("round" cap, "square", "gapped" paint, "no band" (isotropic scatter),
    "fixed" trim, "none": kept at the extent), ``half_width`` the stroke's half width (None
    when there were too few points to tell), metres.
    """

    start: float
    end: float
    half_width: float | None
    trims: tuple[float, float]
    shapes: tuple[str, str]

    def info(self, *, mode: str, forward: bool = True) -> dict[str, Any]:
        """``curve.info`` entries; ``forward=False`` lists the ends the other way round (the
        curve was reversed after the estimate)."""
        trims, shapes = self.trims, self.shapes
        if not forward:
            trims, shapes = trims[::-1], shapes[::-1]
        return {
            "end_trim": mode,
            "stroke_half_width_m": None if self.half_width is None else float(self.half_width),
            "end_trim_m": [float(trims[0]), float(trims[1])],
            "end_trim_start_m": float(trims[0]),
            "end_trim_end_m": float(trims[1]),
            "end_shape": [shapes[0], shapes[1]],
        }


@dataclass(frozen=True, eq=False)
class EdgeProfile:
    """The paint density across a band's edge, relative to the band's inside.

    ``density`` (K,) at signed distances ``t`` (K,) from the edge (metres, increasing;
    negative inside the band) is non-increasing, 1 deep inside, and never below ``_FLOOR``
    (stray points); ``half_width`` (metres) is where it crosses one half.
    """

    half_width: float
    t: FloatArray
    density: FloatArray

    def __call__(self, t: FloatArray) -> FloatArray:
        """P at signed distances ``t`` (any shape), metres: 1 before the table, the floor
        after it."""
        return np.asarray(np.interp(t, self.t, self.density, left=1.0, right=_FLOOR))

    @property
    def reach(self) -> float:
        """How far beyond the edge the paint (its blur and halo) stays denser than
        ``_REACH_DENSITY`` of the band, metres (at most two half widths)."""
        sparse = (self.t >= 0.0) & (self.density <= _REACH_DENSITY)
        t = float(self.t[int(np.argmax(sparse))]) if sparse.any() else float(self.t[-1])
        return float(np.clip(t, 0.0, 2.0 * self.half_width))

    def integral(self, a: FloatArray, b: FloatArray) -> FloatArray:
        """∫ P(t) dt from ``a`` to ``b`` (arrays of one shape), metres."""
        return self._antiderivative(b) - self._antiderivative(a)

    def _antiderivative(self, x: FloatArray) -> FloatArray:
        t, p = self.t, self.density
        table = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(t))])
        x = np.asarray(x, dtype=np.float64)
        return np.asarray(
            np.where(
                x < t[0],
                x - t[0],  # density 1 before the table
                np.where(x > t[-1], table[-1] + _FLOOR * (x - t[-1]), np.interp(x, t, table)),
            )
        )


def check_end_trim(mode: str, trim_m: float | None, where: str) -> None:
    """One-line FittingError for a bad ``end_trim`` / ``end_trim_m`` of config section
    ``where``."""
    if mode not in END_TRIM_MODES:
        raise FittingError(f"unknown {where}.end_trim {mode!r}; known: {', '.join(END_TRIM_MODES)}")
    if trim_m is not None and not (np.isfinite(trim_m) and trim_m >= 0.0):
        raise FittingError(f"{where}.end_trim_m must be a length >= 0, got {trim_m}")


def stroke_ends(
    polyline: FloatArray,
    points: FloatArray,
    *,
    extent: tuple[float, float] | None = None,
    quantile: float = 0.002,
    radius: float,
    mode: str = "auto",
    trim_m: float | None = None,
    span: float = 0.01,
    band_half_width: float | None = None,
) -> StrokeEnds:
    """Where the painted line starts and ends along an ordered polyline (see the module text).

    Parameters
    ----------
    polyline : (K, 3) float64, metres
        The fitted centre line, ordered, any frame (the same as ``points``).
    points : (N, 3) float64, metres
        The paint points. Not modified.
    extent : (start, end), optional
        Arc lengths where the paint begins and ends along ``polyline``; by default found as
        ``_common.data_extent`` does, from the ``quantile`` and ``1 - quantile`` positions of
        the points within ``radius`` (one projection serves both).
    quantile : float
        Share of the near points left beyond each end of the extent when it is not given.
    radius : float
        Points farther than this from the polyline do not count, metres.
    mode : "auto" | "cap" | "none"
        See :data:`END_TRIM_MODES`.
    trim_m : float, optional
        Move each end in by exactly this much instead of estimating it (metres).
    span : float
        Chord length of the end directions the polyline is extended along, metres.
    band_half_width : float, optional
        The stroke's half width measured from its edges (``fitting.stroke``), metres: when the
        paint's own profile is much narrower (under ``_FILLED`` of it: the paint does not
        fill its band), both ends are read off the envelope with this width (step 5).
    """
    extended = extended_polyline(polyline, reach=_REACH, span=span)
    dist, arc = arc_positions(extended, points)
    pos = arc - _REACH
    near = dist <= radius
    if extent is None:
        extent = extent_of(pos[near], quantile=quantile, length=polyline_length(polyline))
    lo, hi = float(extent[0]), float(extent[1])
    limit = MAX_TRIM_SHARE * max(hi - lo, 0.0)
    profile = band_profile(dist[near], pos[near], lo, hi)
    half = None if profile is None else profile.half_width
    if trim_m is not None:
        trim = min(float(trim_m), limit)
        return StrokeEnds(lo + trim, hi - trim, half, (trim, trim), ("fixed", "fixed"))
    if mode == "none" or profile is None:
        return StrokeEnds(lo, hi, half, (0.0, 0.0), ("none", "none"))
    half = profile.half_width
    if band_half_width is not None and half < _FILLED * band_half_width:
        # Paint on a mesh's wires: its profile is the wires', not the stroke's.
        return _envelope_ends(
            extended, arc[near], points[near], pos[near], (lo, hi), band_half_width
        )
    if not _is_band(dist[near], pos[near], lo, hi, half):
        # Isotropic noise around a curve, or paint on wires running along it: no band edge
        # to read a cap from.
        return StrokeEnds(lo, hi, half, (0.0, 0.0), ("no band", "no band"))
    middle = 0.5 * (lo + hi)
    reach = profile.reach
    depth = min(_NEAR * half, radius)  # across: no farther than the profile was measured
    strip = near & (dist <= half)
    inner = (pos >= lo + 2.0 * half) & (pos <= hi - 2.0 * half)
    per_metre = np.count_nonzero(strip & inner) / max(hi - lo - 4.0 * half, 1e-9)
    ends = []
    # The start is the end of the mirrored positions.
    for sign, paint_tip in ((-1.0, -lo), (1.0, hi)):
        p = sign * pos
        # The band just before where a cap and its halo can reach sets the density the end's
        # paint is measured against when it is sparser there than on average (a steep face
        # seen at a grazing angle, an end few frames saw): the line's sparse last stretch is
        # no halo.
        before = paint_tip - _WINDOW * half - reach
        local = _density(p[strip], before - _LOCAL_SPAN * half, before, floor=sign * middle)
        dense = _dense_end(p[strip], min(per_metre, local), half=half)
        tip = min(paint_tip, dense + _DENSE_RUN * half)
        start = max(tip - _WINDOW * half - reach, sign * middle)
        window = np.flatnonzero((p >= start) & near)
        lateral, off_plane = _in_band_plane(points[window], extended, arc[window])
        keep = (off_plane <= _OFF_PLANE * half) & (lateral <= depth)
        ends.append(
            _line_end(
                p[window[keep]],
                lateral[keep],
                tip=tip,
                start=start,
                profile=profile,
                depth=depth,
                mode=mode,
            )
        )
    return _moved_in(ends, (lo, hi), half)


def _moved_in(
    ends: list[tuple[float, str]], extent: tuple[float, float], half: float
) -> StrokeEnds:
    """The :class:`StrokeEnds` of the ends found, (position, shape) each, the start's
    position mirrored (negated): each moved in from the ``extent`` [lo, hi] by at least 0 and at
    most ``MAX_TRIM_SHARE`` of it (step 6)."""
    lo, hi = extent
    limit = MAX_TRIM_SHARE * max(hi - lo, 0.0)
    (e0, shape0), (e1, shape1) = ends
    trim0 = float(np.clip(-e0 - lo, 0.0, limit))
    trim1 = float(np.clip(hi - e1, 0.0, limit))
    return StrokeEnds(lo + trim0, hi - trim1, half, (trim0, trim1), (shape0, shape1))


def _envelope_ends(
    extended: FloatArray,
    arc: FloatArray,
    points: FloatArray,
    pos: FloatArray,
    extent: tuple[float, float],
    half: float,
) -> StrokeEnds:
    """Both ends of paint that does not fill its band (step 5 with the stroke's half width
    ``half`` from its edges): the envelope of the points (N, 3) within ``_WINDOW`` half
    widths of each end of the ``extent`` (their positions ``pos`` (N,) along the line, arc
    lengths ``arc`` (N,) along the ``extended`` polyline), within the band's plane."""
    lo, hi = extent
    middle = 0.5 * (lo + hi)
    ends = []
    for sign, paint_tip in ((-1.0, -lo), (1.0, hi)):
        p = sign * pos
        window = np.flatnonzero(p >= max(paint_tip - _WINDOW * half, sign * middle))
        lateral, off_plane = _in_band_plane(points[window], extended, arc[window])
        keep = (off_plane <= _OFF_PLANE * half) & (lateral <= half) & (p[window] <= paint_tip)
        if keep.sum() < _MIN_END_POINTS:  # too little paint at this end to tell: kept
            ends.append((paint_tip, "none"))
            continue
        # Only points within the extent (its quantile left the stray ones out): the sparse
        # paint at a mesh's tip is the end's evidence, not noise.
        bound = _envelope_end(p[window[keep]], lateral[keep], band_half=half, share=0.0)
        ends.append((min(bound, paint_tip), "gapped"))
    return _moved_in(ends, extent, half)


def band_profile(dist: FloatArray, pos: FloatArray, lo: float, hi: float) -> EdgeProfile | None:
    """The edge profile of a painted band (:func:`edge_profile`) from the lateral distances
    (N,) of its points and their arc positions (N,) along the centre line, metres: the points
    at least two half widths in from the ends of the paint's extent [lo, hi] (a first guess
    from the middle half; all the points of a short stroke). None with fewer than 10 points."""
    length = hi - lo
    middle = (pos >= lo + 0.25 * length) & (pos <= hi - 0.25 * length)
    guess = edge_profile(dist[middle]) if middle.sum() >= 10 else None
    if guess is None:
        return edge_profile(dist)
    inner = (pos >= lo + 2.0 * guess.half_width) & (pos <= hi - 2.0 * guess.half_width)
    if inner.sum() >= _MIN_WIDTH_POINTS:
        return edge_profile(dist[inner]) or guess
    return guess


def stroke_half_width(dist: FloatArray, pos: FloatArray, lo: float, hi: float) -> float | None:
    """Half width of a painted band (metres) from the lateral distances (N,) of its points and
    their arc positions (N,) along the centre line: see :func:`band_profile`."""
    profile = band_profile(dist, pos, lo, hi)
    return None if profile is None else profile.half_width


def edge_profile(dist: FloatArray) -> EdgeProfile | None:
    """The edge profile and half width of a band from the lateral distances (N,) of its points
    (metres; see the module text, step 1). None with fewer than 10 points or no spread.

    The least concave majorant of the empirical distribution of |u| is the upper hull of its
    steps: its slopes are the most likely non-increasing density (Grenander's estimator).
    """
    if len(dist) < 10:
        return None
    qa, qb = np.quantile(dist, _INSIDE, method="inverted_cdf")
    if qb - qa <= 1e-9:
        return None
    inside = (_INSIDE[1] - _INSIDE[0]) / float(qb - qa)  # the band's share per metre of |u|
    # Distinct values and their cumulative shares: the same cloud given twice has the same.
    values, counts = np.unique(dist, return_counts=True)
    x = np.concatenate([[0.0], values, [values[-1]]])
    y = np.concatenate([[0.0], np.cumsum(counts) / len(dist), [0.0]])
    # The last point (x_max, 0) closes the hull below, so collinear steps (evenly spaced
    # distances) still make a polygon; the upper chain runs counter-clockwise from
    # (x_max, 1) back to the origin.
    try:
        vertices = ConvexHull(np.column_stack([x, y])).vertices
    except QhullError:
        return None
    top = len(x) - 2
    if top not in vertices or 0 not in vertices:
        return None
    turn = np.roll(vertices, -int(np.flatnonzero(vertices == top)[0]))
    chain = turn[: int(np.flatnonzero(turn == 0)[0]) + 1][::-1]  # origin ... (x_max, 1)
    width = np.diff(x[chain])
    wide = width > 0.0
    slopes = np.diff(y[chain])[wide] / width[wide]
    mids = (0.5 * (x[chain][:-1] + x[chain][1:]))[wide]
    rel = np.minimum(slopes / inside, 1.0)
    # The edge: the area under the density, levels between _EDGE_LEVEL and 1 - _EDGE_LEVEL
    # stretched to 0-1 (a halo below that level counts for nothing). A symmetric blur or
    # ragged edge ends up at its middle (its half-density point), and so does an edge made
    # of two (a curve slightly off the band's centre sees it at h - e on one side, h + e on
    # the other, at half the density in between).
    level = np.clip((rel - _EDGE_LEVEL) / (1.0 - 2.0 * _EDGE_LEVEL), 0.0, 1.0)
    half = float(np.sum(level * width[wide]))
    return EdgeProfile(half_width=half, t=mids - half, density=np.maximum(rel, _FLOOR))


def _is_band(dist: FloatArray, pos: FloatArray, lo: float, hi: float, half: float) -> bool:
    """Whether the lateral distances (N,) away from the ends look like a uniform band (a
    stroke too short to have points away from its ends is taken for one)."""
    inner = (pos >= lo + 2.0 * half) & (pos <= hi - 2.0 * half)
    if hi - lo < 6.0 * half or inner.sum() < _MIN_WIDTH_POINTS:
        return True
    q10, q50 = np.quantile(dist[inner], [0.1, 0.5], method="inverted_cdf")
    return bool(q10 <= _BAND_SHAPE * q50)


def _density(p: FloatArray, lo: float, hi: float, *, floor: float) -> float:
    """Points per metre of the positions ``p`` (M,) in [lo, hi]; +inf when the stretch
    reaches below ``floor`` (the line's middle: a short line has no band before its end)."""
    if lo < floor or hi <= lo:
        return float(np.inf)
    return float(np.count_nonzero((p >= lo) & (p <= hi)) / (hi - lo))


def _dense_end(p: FloatArray, per_metre: float, *, half: float) -> float:
    """The last position (of the positions p (M,) of the points within the band's width)
    ending a run of ``_DENSE_RUN`` half widths that holds at least half the band's points per
    metre (``per_metre``): where the dense paint ends (a halo beyond is sparser). +inf when no
    run is that dense."""
    if len(p) == 0 or per_metre <= 0.0:
        return float(np.inf)
    run = _DENSE_RUN * half
    order = np.sort(p)
    count = np.arange(1, len(order) + 1) - np.searchsorted(order, order - run, side="right")
    dense = count >= 0.5 * per_metre * run
    return float(order[dense].max()) if dense.any() else float(np.inf)


def _in_band_plane(
    points: FloatArray, extended: FloatArray, arc: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Each point's offset (M,) from its nearest point on the polyline within the band's plane
    (across the line) and out of it (along the band's normal), metres.

    The normal is the direction least spanned by the unit offsets and the local tangents (a
    band is flat across the line): paint that wrapped over an edge beside the end (the top of
    an I-beam flange) lies off the plane and is not taken for the band's width.
    """
    if len(points) == 0:
        return np.zeros(0), np.zeros(0)
    s = cumulative_length(extended)
    foot = interpolate_polyline(extended, arc, cumulative=s)
    tangent = interpolate_polyline(extended, arc + 0.001, cumulative=s) - interpolate_polyline(
        extended, arc - 0.001, cumulative=s
    )
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    offset = points - foot
    length = np.linalg.norm(offset, axis=1)
    unit = offset / np.maximum(length, 1e-12)[:, None]
    _, vectors = np.linalg.eigh(unit.T @ unit + tangent.T @ tangent)
    off_plane = np.abs(offset @ vectors[:, 0])
    return np.sqrt(np.maximum(length**2 - off_plane**2, 0.0)), off_plane


def _local_half_width(
    p: FloatArray, d: FloatArray, profile: EdgeProfile, *, start: float, depth: float
) -> float:
    """The band's half width in a window: the shift of the edge profile that makes the
    lateral offsets d (M,) (up to ``depth``; positions p (M,) from ``start``, metres) most
    likely, with the prior h_b = h ± ``_WIDTH_PRIOR`` (a few wire patches say little)."""
    widths = profile.half_width * _LOCAL_WIDTHS
    log_p = np.log(profile(d[None, :] - widths[:, None])).mean(axis=1)
    norm = profile.integral(-widths, depth - widths)
    prior = -0.5 * ((_LOCAL_WIDTHS - 1.0) / _WIDTH_PRIOR) ** 2
    score = (log_p - np.log(norm)) * _evidence(p, start, profile.half_width) + prior
    return float(widths[int(np.argmax(score))])


def _evidence(p: FloatArray, start: float, half: float) -> float:
    """How many points a window's paint at positions p (M,) from ``start`` is worth: the
    points of a stitched cloud's 2 mm voxel grid over its painted 1 mm slices, across a band
    of half width ``half`` (at least 1). Likelihoods are means over the points (a cloud given
    twice over ends at the same place) weighed by this."""
    slices = len(np.unique(np.floor((p - start) / _SLICE_M)))
    return max(slices * _SLICE_M * 2.0 * half / _VOXEL_M**2, 1.0)


def _line_end(
    p: FloatArray,
    d: FloatArray,
    *,
    tip: float,
    start: float,
    profile: EdgeProfile,
    depth: float,
    mode: str,
) -> tuple[float, str]:
    """Where the full-width band ends, as a position: the window's points at positions
    ``p`` (M,) (from ``start``, the line running towards increasing positions, the dense
    paint's tip at ``tip``) and lateral offsets ``d`` (M,) up to ``depth``, metres. Returns
    (position, shape)."""
    if len(p) < _MIN_END_POINTS:
        return tip, "none"  # too little paint at this end to tell: kept
    half, reach = profile.half_width, profile.reach
    if _gapped(p, start=start, tip=tip - reach, half=half):
        # A wire patch or two tell the local width poorly: the stroke's.
        return min(_envelope_end(p, d, band_half=half), tip), "gapped"
    band = p <= tip - _BAND_PART * half - reach
    hb = (
        _local_half_width(p[band], d[band], profile, start=start, depth=depth)
        if band.sum() >= _MIN_WIDTH_POINTS
        else half
    )
    model = _EndModel(p, d, start=start, band_half=hb, depth=depth, profile=profile)
    low = tip - 2.0 * hb - reach
    e_round, ll_round = model.best(low, tip, round_cap=True)
    if mode == "auto" and _full_width_at_tip(p, d, tip=tip, band_half=hb):
        e_square, ll_square = model.best(low, tip, round_cap=False)
        if ll_square > ll_round + SQUARE_EVIDENCE:
            return min(e_square, tip), "square"
    return min(e_round, tip), "round"


def _full_width_at_tip(p: FloatArray, d: FloatArray, *, tip: float, band_half: float) -> bool:
    """Whether the paint just inside its tip (0.05-0.3 half widths in) is as wide as the band,
    as a square end's is (a round cap's chord there is at most 0.7 h_b): the uniform width
    estimate Q80/0.8 of the lateral offsets there within the band's width reaches
    ``_SQUARE_WIDTH`` h_b. Paint heaped at the very tip (wrapped over an edge, stray points)
    and overspray beside the cap (beyond the band's width) do not count."""
    zone = (p >= tip - 0.3 * band_half) & (p <= tip - 0.05 * band_half) & (d <= band_half)
    if zone.sum() < 5:
        return False
    width = float(np.quantile(d[zone], 0.8, method="inverted_cdf")) / 0.8
    return width >= _SQUARE_WIDTH * band_half


def _gapped(p: FloatArray, *, start: float, tip: float, half: float) -> bool:
    """Whether the window's paint (positions (M,) from ``start``) has gaps: an empty run
    longer than ``_GAP_M`` opening before the outer half of a cap (its sparse tip, a halo,
    and stray points past the paint's tip leave empty runs too)."""
    slices = np.unique(np.floor((p - start) / _SLICE_M))
    edges = np.concatenate([[-1.0], slices])
    run = np.diff(edges) > _GAP_M / _SLICE_M
    opens = start + edges[:-1] * _SLICE_M < tip - 0.5 * half
    return bool(np.any(run & opens))


def _envelope_end(
    p: FloatArray, d: FloatArray, *, band_half: float, share: float = _ENVELOPE_SHARE
) -> float:
    """The end of gapped paint (a basket's wires): the last position E that keeps the paint
    inside the stroke (band up to E, a cap of radius ``band_half`` beyond).

    With a wire patch or two in the window, a density model has too little to go on, but the
    envelope does: a point at (x, d) needs E >= x - sqrt(h^2 - d^2), so a full-width wire
    says the line reaches at least that far, and a wire across the cap, narrowed to the cap's
    chord, places E. The largest ``share`` of these bounds are left out (noise and stray
    points), and at least the largest.
    """
    bound = np.sort(p - np.sqrt(np.maximum(band_half**2 - d**2, 0.0)))
    k = max(int(np.ceil(share * len(bound))), 2)
    return float(bound[-min(k, len(bound))])


class _EndModel:
    """Log-likelihood of the window's points (positions p, lateral offsets d up to ``depth``)
    for a region made of a band of half width ``band_half`` from ``start`` to E and a half
    disc of radius h_c at E (or a square end): each point's density is the edge profile at its
    signed distance from the region, normalised over the window's box (from ``start`` to one
    depth past the last point, ``depth`` either side)."""

    def __init__(
        self,
        p: FloatArray,
        d: FloatArray,
        *,
        start: float,
        band_half: float,
        depth: float,
        profile: EdgeProfile,
    ) -> None:
        self.p, self.d = p, d
        self.start, self.hb, self.profile = start, band_half, profile
        # The box runs a depth past the last point, so every candidate region and its spill
        # lie inside it: a cap claiming empty area beyond the paint pays for it.
        self.stop = float(p.max()) + depth
        # Lateral samples (cell centres) for the normalisation: the region is symmetric.
        cells = np.arange(int(np.ceil(depth / _STEP_M)), dtype=np.float64)
        self.across: FloatArray = (cells + 0.5) * _STEP_M
        # ∫ P across the box where only the band's sides are near: the same for every E.
        self.band_row = 2.0 * _STEP_M * float(profile(self.across - band_half).sum())
        self.weight = _evidence(p, start, band_half)

    def best(self, low: float, tip: float, *, round_cap: bool) -> tuple[float, float]:
        """(E, score) of the best end: a 2 mm grid over [low, tip], then 0.25 mm around its
        best."""
        first = self.start + 0.0005
        coarse = np.arange(low, tip + 0.5 * _COARSE_M, _COARSE_M)
        coarse = coarse[coarse > first]
        if len(coarse) == 0:
            return tip, -np.inf
        reach = _COARSE_M + _FINE_M
        search = _Search(self, coarse[0] - reach, coarse[-1] + reach, round_cap=round_cap)
        e, _ = search.run(coarse)
        fine = np.arange(e - _COARSE_M, e + _COARSE_M + 1e-9, _FINE_M)
        return search.run(fine[fine > first])

    def distance(
        self, x: FloatArray, d: FloatArray, hc: FloatArray | float, round_cap: bool
    ) -> FloatArray:
        """Signed distance (negative inside) from the region of points x along the line
        (from E) and d across it, for cap radii ``hc`` (all broadcast), metres."""
        across = d - self.hb
        if round_cap:
            # Up to E the band's sides; beyond, the cap's rim (as the cap ends the band).
            return np.asarray(np.where(x > 0.0, np.hypot(np.maximum(x, 0.0), d) - hc, across))
        inside = np.maximum(across, x)  # depth under the nearer of side and end face
        outside = np.hypot(np.maximum(x, 0.0), np.maximum(across, 0.0))
        return np.asarray(np.where((across <= 0.0) & (x <= 0.0), inside, outside))


class _Search:
    """The end model's scores for candidate ends within [lowest, highest], one shape, all cap
    radii at once (arrays: radius x candidate x point).

    Points more than a half width short of every candidate are inside the band whatever E is
    (and far from a square end's face): their terms are summed once. The normalisation is
    tabulated once per cap radius as a cumulative integral over positions u = x - E along the
    box (the band's constant row up to where the end's shape begins).
    """

    def __init__(self, model: _EndModel, lowest: float, highest: float, *, round_cap: bool) -> None:
        self.model, self.round_cap = model, round_cap
        varying = model.p > lowest - model.hb
        self.fixed = float(np.log(model.profile(model.d[~varying] - model.hb)).sum())
        self.p, self.d = model.p[varying], model.d[varying]
        self.count = len(model.p)
        ratios = _CAP_RATIOS if round_cap else np.ones(1)
        self.radii = (ratios * model.hb)[:, None, None]  # (R, 1, 1)
        self.prior = -0.5 * ((ratios - 1.0) / _CAP_PRIOR) ** 2 if round_cap else np.zeros(1)
        self.u = np.arange(
            model.start - highest - _STEP_M, model.stop - lowest + 2.0 * _STEP_M, _STEP_M
        )
        # Where the row differs from the band's: beyond E (a cap), or a half width before it
        # (a square end's face).
        shaped = self.u > (0.0 if round_cap else -model.hb - _STEP_M)
        rows = np.full((len(ratios), len(self.u)), model.band_row)
        delta = model.distance(
            self.u[None, shaped, None], model.across[None, None, :], self.radii, round_cap
        )
        rows[:, shaped] = 2.0 * _STEP_M * model.profile(delta).sum(axis=2)
        zero = np.zeros((len(ratios), 1))
        self.tables = np.hstack([zero, np.cumsum(rows * _STEP_M, axis=1)])  # (R, U + 1)

    def _integral(self, at: FloatArray) -> FloatArray:
        """The tables' cumulative integrals (R, K) at positions ``at`` (K,) from E."""
        first = self.u[0] - 0.5 * _STEP_M
        where = np.clip((at - first) / _STEP_M, 0.0, len(self.u) - 1e-9)
        k = where.astype(np.int64)
        share = where - k
        return np.asarray(self.tables[:, k] * (1.0 - share) + self.tables[:, k + 1] * share)

    def run(self, ends: FloatArray) -> tuple[float, float]:
        """(E, score) of the best of ``ends`` (their cap radius profiled out)."""
        m = self.model
        x = (self.p[None, :] - ends[:, None])[None, :, :]  # how far beyond each end, (1, E, M)
        delta = m.distance(x, self.d[None, None, :], self.radii, self.round_cap)
        log_p = np.log(m.profile(delta)).sum(axis=2)  # (R, E)
        area = self._integral(m.stop - ends) - self._integral(m.start - ends)
        mean = (log_p + self.fixed) / self.count
        score = (mean - np.log(area)) * m.weight + self.prior[:, None]
        r, k = np.unravel_index(int(np.argmax(score)), score.shape)
        return float(ends[k]), float(score[r, k])


# --------------------------------------------------------------------------- past the paint


@dataclass(frozen=True)
class PaintCheck:
    """How a fitted curve sits on the paint it was fitted to (the reverse distance).

    ``start`` and ``end`` are the arc lengths (metres) between which the curve stays within
    ``tolerance_m`` of the paint at its ends (0 and the length when nothing runs past it);
    ``trims`` how far each end ran past the paint; ``reverse_mean_m`` and ``reverse_max_m``
    the distance from the curve (every ~1 mm) to its nearest paint point, over the part kept.
    """

    start: float
    end: float
    trims: tuple[float, float]
    reverse_mean_m: float
    reverse_max_m: float
    tolerance_m: float

    def info(self) -> dict[str, Any]:
        """``curve.info`` entries (``paint_trim_m`` lists the start's trim first)."""
        return {
            "paint_trim_m": [float(self.trims[0]), float(self.trims[1])],
            "paint_tolerance_m": float(self.tolerance_m),
            "reverse_mean_m": float(self.reverse_mean_m),
            "reverse_max_m": float(self.reverse_max_m),
        }


def past_paint(polyline: FloatArray, paint: FloatArray, *, tolerance_m: float) -> PaintCheck:
    """Where an ordered polyline (K, 3) runs past the paint (N, 3) at its ends.

    The stroke-end model ends a line within its paint's extent along it (at a round cap's
    centre, a square end's edge, within the cap of gapped paint). Walking in from each end,
    everything beyond that extent (its 0.2 % and 99.8 % positions along the curve extended
    straight past its ends: a few stray specks do not stretch it) and farther than
    ``tolerance_m`` from the paint ran past it (an extrapolated spline, a skeleton spur into
    nothing); the crossing is interpolated between the samples. Stretches within the extent
    farther from the paint (a wire mesh's gaps, also the one before a mesh's last wire, where
    the curve follows the stroke's centre between the wires) are the fit's business and only
    count in the reverse distance.
    """
    pts = np.asarray(polyline, dtype=np.float64)
    paint = np.asarray(paint, dtype=np.float64).reshape(-1, 3)
    dense = resample_polyline(pts, 0.001) if polyline_length(pts) > 0 else pts
    s = cumulative_length(dense)
    length = float(s[-1])
    distance, _ = cKDTree(paint).query(dense)
    lo, hi = 0.0, length
    if len(dense) >= 2 and length > 0.0:
        _, along = extended_positions(dense, paint, reach=_REACH)
        lo, hi = extent_of(along, quantile=_EXTENT_QUANTILE, length=length)
    ok = np.flatnonzero((distance <= tolerance_m) | ((s >= lo) & (s <= hi)))
    if ok.size == 0:  # nowhere near its paint: nothing to measure against, keep it whole
        return PaintCheck(
            0.0, length, (0.0, 0.0), float(distance.mean()), float(distance.max()), tolerance_m
        )
    first, last = int(ok[0]), int(ok[-1])
    start = _leaves(s, distance, first, first - 1, tolerance_m, lo) if first > 0 else 0.0
    end = _leaves(s, distance, last, last + 1, tolerance_m, hi) if last < len(s) - 1 else length
    kept = distance[first : last + 1]
    return PaintCheck(
        start, end, (start, length - end), float(kept.mean()), float(kept.max()), tolerance_m
    )


def _leaves(
    s: FloatArray, d: FloatArray, inside: int, outside: int, level: float, extent: float
) -> float:
    """Where the curve leaves its paint between the kept sample ``inside`` and the sample
    ``outside`` past it: the farther out of the crossing of the distance ``level`` (when the
    kept sample is that near the paint) and the paint extent's end at arc length ``extent``."""
    out = extent
    if d[inside] <= level:
        crossing = _crossing(s, d, inside, outside, level)
        out = min(crossing, extent) if outside < inside else max(crossing, extent)
    return float(np.clip(out, min(s[inside], s[outside]), max(s[inside], s[outside])))


def _crossing(s: FloatArray, d: FloatArray, inside: int, outside: int, level: float) -> float:
    """Arc length between samples ``inside`` (d <= level) and ``outside`` where d = level."""
    span = d[outside] - d[inside]
    t = 0.0 if span <= 0 else float(np.clip((level - d[inside]) / span, 0.0, 1.0))
    return float(s[inside] + t * (s[outside] - s[inside]))
