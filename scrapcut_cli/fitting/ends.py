"""Where a painted line really ends: the centre of a spray stroke's round cap, not its tip.

A spray stroke is a band of half width h around the intended line, and where the can starts
or stops it leaves a round cap: a half disc of radius about h centred on the line's end. The
paint therefore reaches about h beyond each intended end, and a curve clamped to the paint's
extent (``_common.data_extent``) overshoots by that much (12 mm for the usual 25 mm stroke);
a torch following it cuts past the mark. :func:`stroke_ends` moves each end back to where the
full-width band stops:

1. **Half width.** The distances of the paint points to the fitted curve, away from the ends
   (at least twice the half width in from either end of the paint), are matched to a uniform
   band: for |u| uniform on [0, h] the q-quantile is q·h, so h is the least-squares slope of
   the 0.3 … 0.8 quantiles over q. Quantiles (no mean, no maximum) ignore outliers, the
   blurred ragged edge and noise across the surface; paint on the wires of a basket has the
   same lateral distribution on each wire. Points scattered isotropically around a curve (10 %
   quantile above 0.37 of the median; a band's is 0.2) have no band edge: "no band", kept.
2. **The end window.** The points within three half widths of an end are placed by their
   position x along the curve extended straight past its end and their offset d across the
   line within the band's plane (its normal is the direction least spanned by the offsets and
   the tangents: paint that wrapped over an edge beside the end, onto the top of an I-beam
   flange, is off the plane and left out). The band's local half width h_b is the quantile
   fit over the window's inner half (the global h when they disagree by more than 25 %).
3. **A round cap.** The window's points are taken as uniform over a band of half width h_b
   that stops at E and is closed by a half disc of radius h_c centred at E, with a soft edge
   (a Gaussian of width σ, measured from the share of band points beyond h_b, so noise and
   ragged edges count) and a small share of outliers; (E, h_c) maximise the likelihood with
   the prior h_c = h_b ± 5 %. The point-process likelihood is what makes E definite: every
   unit of area the region claims without points costs, every point outside costs more. It
   is a mean over the points (the same cloud given twice ends at the same place) weighed as
   the points of a 2 mm stitching grid over the window's painted length.
4. **Or a square end.** Paint that runs off the edge of a piece (or out of the camera's view)
   stops square, at full width: the same likelihood with no cap. It is chosen only when it
   beats the round cap by ``SQUARE_EVIDENCE`` nats; the line then ends at the paint's edge
   (cutting short of an edge would leave the piece attached). On ragged, sparse paint a square
   end is recognised about half of the time and otherwise taken for a cap; ``end_trim="none"``
   keeps every end where the paint ends.
5. **Or gapped paint.** When the window's paint has gaps (an empty run over 4 mm: a basket's
   wires), a density has too little to go on; the end is the envelope instead: the last E
   that keeps the points inside the band and cap (a wire across the cap, narrowed to the
   cap's chord, places E; a full-width wire says the line goes at least that far). An end
   whose cap falls in a gap cannot be seen: the curve ends on the last wire.
6. **Limits.** An end never moves beyond the paint's extent, and each end moves in by at most
   ``MAX_TRIM_SHARE`` of the extent, so a stroke shorter than its own width keeps at least half
   of its length.

The grid search (E on a 1 mm then 0.2 mm grid, h_c over seven ratios) is vectorised numpy
written here: no library fits this region model. ``mode="cap"`` always assumes round caps,
``"none"`` keeps the extent, and a fixed ``trim_m`` (for a stroke width known beforehand)
replaces the estimate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr

from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting._common import arc_positions, extended_polyline, extent_of
from scrapcut_cli.geometry import cumulative_length, interpolate_polyline, polyline_length

FloatArray = NDArray[np.float64]

#: ``end_trim`` modes: estimate each end's shape; always a round cap; no trimming.
END_TRIM_MODES = ("auto", "cap", "none")
#: Quantiles of the lateral distance matched to a uniform band (robust to edges and outliers).
_QUANTILES = np.linspace(0.3, 0.8, 6)
#: A square end must beat the round cap by this log-likelihood (nats): spray caps are the rule.
SQUARE_EVIDENCE = 8.0
#: ... and its paint just inside the tip must be this wide (share of the band's half width).
_SQUARE_WIDTH = 0.85
#: Each end moves in by at most this share of the paint's extent.
MAX_TRIM_SHARE = 0.25
#: Windows at the ends, in half widths: the whole window, and its inner (band) part.
_WINDOW = 3.0
_BAND_PART = 1.5
#: Points counted at an end: within this many half widths of the curve, and at most this many
#: off the band's plane.
_NEAR = 2.5
_OFF_PLANE = 0.5
#: The curve is extended straight by this much past its ends to place the points beyond them.
_REACH = 0.05
#: Share of outliers in the end model, and the prior spread of the cap radius over h_b.
_OUTLIERS = 0.03
_CAP_PRIOR = 0.05
_CAP_RATIOS = np.linspace(0.85, 1.15, 7)  # three prior widths either way
#: Fewest points for a half-width fit, and for an end model.
_MIN_WIDTH_POINTS = 20
_MIN_END_POINTS = 15
#: Evidence is counted per (2 mm)^2 of painted window, the stitching voxel's share of a band.
_VOXEL_M = 0.002
#: A band: the 10 % quantile of the lateral distance is at most this share of the median
#: (a uniform band: 0.2; the distances of isotropic noise around a curve, Rayleigh: 0.39).
_BAND_SHAPE = 0.37
#: Slices along the window (metres), and the empty run between paint that makes it gapped.
_SLICE_M = 0.001
_GAP_M = 0.004
#: Share of the largest end bounds of gapped paint left out.
_ENVELOPE_SHARE = 0.05


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
    """
    extended = extended_polyline(polyline, reach=_REACH, span=span)
    dist, arc = arc_positions(extended, points)
    pos = arc - _REACH
    near = dist <= radius
    if extent is None:
        extent = extent_of(pos[near], quantile=quantile, length=polyline_length(polyline))
    lo, hi = float(extent[0]), float(extent[1])
    limit = MAX_TRIM_SHARE * max(hi - lo, 0.0)
    half = stroke_half_width(dist[near], pos[near], lo, hi)
    if trim_m is not None:
        trim = min(float(trim_m), limit)
        return StrokeEnds(lo + trim, hi - trim, half, (trim, trim), ("fixed", "fixed"))
    if mode == "none" or half is None:
        return StrokeEnds(lo, hi, half, (0.0, 0.0), ("none", "none"))
    if not _is_band(dist[near], pos[near], lo, hi, half):
        # Isotropic noise around a curve, or paint on wires running along it: no band edge
        # to read a cap from.
        return StrokeEnds(lo, hi, half, (0.0, 0.0), ("no band", "no band"))
    middle = 0.5 * (lo + hi)
    ends = []
    # The start is the end of the mirrored positions.
    for sign, tip in ((-1.0, -lo), (1.0, hi)):
        p = sign * pos
        window = np.flatnonzero((p >= max(tip - _WINDOW * half, sign * middle)) & near)
        lateral, off_plane = _in_band_plane(points[window], extended, arc[window])
        keep = (off_plane <= _OFF_PLANE * half) & (lateral <= _NEAR * half)
        ends.append(
            _line_end(
                p[window[keep]],
                lateral[keep],
                tip=tip,
                start=max(tip - _WINDOW * half, sign * middle),
                half=half,
                mode=mode,
            )
        )
    (e0, shape0), (e1, shape1) = ends
    trim0 = float(np.clip(-e0 - lo, 0.0, limit))
    trim1 = float(np.clip(hi - e1, 0.0, limit))
    return StrokeEnds(lo + trim0, hi - trim1, half, (trim0, trim1), (shape0, shape1))


def stroke_half_width(dist: FloatArray, pos: FloatArray, lo: float, hi: float) -> float | None:
    """Half width of a painted band from the lateral distances (N,) of its points and their
    arc positions (N,) along the centre line, metres: the points at least two half widths in
    from the ends of the paint's extent [lo, hi] (a first guess from the middle half; all the
    points of a short stroke). None with fewer than 10 points."""
    length = hi - lo
    middle = (pos >= lo + 0.25 * length) & (pos <= hi - 0.25 * length)
    guess = _uniform_half_width(dist[middle]) if middle.sum() >= 10 else None
    if guess is None:
        return _uniform_half_width(dist) if len(dist) >= 10 else None
    inner = (pos >= lo + 2.0 * guess) & (pos <= hi - 2.0 * guess)
    if inner.sum() >= _MIN_WIDTH_POINTS:
        return _uniform_half_width(dist[inner])
    return guess


def _is_band(dist: FloatArray, pos: FloatArray, lo: float, hi: float, half: float) -> bool:
    """Whether the lateral distances (N,) away from the ends look like a uniform band (a
    stroke too short to have points away from its ends is taken for one)."""
    inner = (pos >= lo + 2.0 * half) & (pos <= hi - 2.0 * half)
    if hi - lo < 6.0 * half or inner.sum() < _MIN_WIDTH_POINTS:
        return True
    q10, q50 = np.quantile(dist[inner], [0.1, 0.5], method="inverted_cdf")
    return bool(q10 <= _BAND_SHAPE * q50)


def _uniform_half_width(dist: FloatArray) -> float:
    """h of a uniform band: the slope of the 0.3 … 0.8 quantiles of |u| over q (least
    squares through the origin)."""
    # The empirical quantile (no interpolation): a cloud given twice over has the same width.
    q = np.quantile(dist, _QUANTILES, method="inverted_cdf")
    return float(_QUANTILES @ q / (_QUANTILES @ _QUANTILES))


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


def _line_end(
    p: FloatArray, d: FloatArray, *, tip: float, start: float, half: float, mode: str
) -> tuple[float, str]:
    """Where the full-width band ends, as a position: the window's points at positions
    ``p`` (M,) (from ``start``, the line running towards increasing positions, the paint's tip
    at ``tip``) and lateral offsets ``d`` (M,), metres. Returns (position, shape)."""
    if len(p) < _MIN_END_POINTS:
        return tip, "none"  # too little paint at this end to tell: kept
    band = p <= tip - _BAND_PART * half
    hb = _uniform_half_width(d[band]) if band.sum() >= _MIN_WIDTH_POINTS else half
    if not 0.75 * half <= hb <= 1.25 * half:
        hb = half  # not a uniform band there (a basket's wires): the stroke's width
    if _gapped(p, start=start, tip=tip, half=hb):
        return min(_envelope_end(p, d, band_half=hb), tip), "gapped"
    # The edge's blur: a uniform band blurred by a Gaussian of width s puts a share
    # s / (sqrt(2 pi) h) of its points beyond h.
    ref = d[band] if band.sum() >= _MIN_WIDTH_POINTS else d
    sigma = float(np.clip(np.sqrt(2.0 * np.pi) * hb * np.mean(ref > hb), 0.0003, 0.25 * hb))
    model = _EndModel(p, d, start=start, band_half=hb, sigma=sigma)
    e_round, ll_round = model.best(tip, round_cap=True)
    if mode == "auto" and _full_width_at_tip(p, d, tip=tip, band_half=hb):
        e_square, ll_square = model.best(tip, round_cap=False)
        if ll_square > ll_round + SQUARE_EVIDENCE:
            return min(e_square, tip), "square"
    return min(e_round, tip), "round"


def _full_width_at_tip(p: FloatArray, d: FloatArray, *, tip: float, band_half: float) -> bool:
    """Whether the paint just inside its tip (0.05-0.3 half widths in) is as wide as the band,
    as a square end's is (a round cap's chord there is at most 0.7 h_b): the uniform width
    estimate Q80/0.8 of the lateral offsets there reaches ``_SQUARE_WIDTH`` h_b. Paint heaped
    at the very tip (wrapped over an edge, stray points) does not count."""
    zone = (p >= tip - 0.3 * band_half) & (p <= tip - 0.05 * band_half)
    if zone.sum() < 5:
        return False
    width = float(np.quantile(d[zone], 0.8, method="inverted_cdf")) / 0.8
    return width >= _SQUARE_WIDTH * band_half


def _gapped(p: FloatArray, *, start: float, tip: float, half: float) -> bool:
    """Whether the window's paint (positions (M,) from ``start``) has gaps: an empty run
    longer than ``_GAP_M`` opening before the outer half of a cap (its sparse tip, and stray
    points past the paint's tip, leave empty runs too)."""
    slices = np.unique(np.floor((p - start) / _SLICE_M))
    edges = np.concatenate([[-1.0], slices])
    run = np.diff(edges) > _GAP_M / _SLICE_M
    opens = start + edges[:-1] * _SLICE_M < tip - 0.5 * half
    return bool(np.any(run & opens))


def _envelope_end(p: FloatArray, d: FloatArray, *, band_half: float) -> float:
    """The end of gapped paint (a basket's wires): the last position E that keeps the paint
    inside the stroke (band up to E, a cap of radius ``band_half`` beyond).

    With a wire patch or two in the window, a density model has too little to go on, but the
    envelope does: a point at (x, d) needs E >= x - sqrt(h^2 - d^2), so a full-width wire
    says the line reaches at least that far, and a wire across the cap, narrowed to the cap's
    chord, places E. The largest ``_ENVELOPE_SHARE`` of these bounds are left out (noise and
    stray points).
    """
    bound = np.sort(p - np.sqrt(np.maximum(band_half**2 - d**2, 0.0)))
    k = max(int(np.ceil(_ENVELOPE_SHARE * len(bound))), 2)
    return float(bound[-min(k, len(bound))])


class _EndModel:
    """Log-likelihood of the window's points (positions p, lateral offsets d) for a band of
    half width ``band_half`` from ``start`` to E, closed by a half disc of radius h_c at E (or
    square), with Gaussian-blurred edges and a uniform share of outliers."""

    def __init__(
        self, p: FloatArray, d: FloatArray, *, start: float, band_half: float, sigma: float
    ) -> None:
        self.p, self.d = p, d
        self.start, self.hb, self.sigma = start, band_half, sigma
        # Outliers spread over the window's box (its length plus a cap, 2 x the counted width).
        self.box = (float(p.max()) - start + band_half) * 2.0 * _NEAR * band_half
        # The evidence the window holds, in points of a stitched cloud's 2 mm voxel grid over
        # its painted 1 mm slices: the likelihood is a mean over the points (a cloud given
        # twice over ends at the same place) weighed by this.
        slices = len(np.unique(np.floor((p - start) / _SLICE_M)))
        self.weight = max(slices * _SLICE_M * 2.0 * band_half / _VOXEL_M**2, 1.0)

    def best(self, tip: float, *, round_cap: bool) -> tuple[float, float]:
        """(E, score) of the best end: a 1 mm grid over [tip - 2 h_b, tip], then 0.2 mm around
        its best."""
        low = self.start + 0.0005
        coarse = np.arange(tip - 2.0 * self.hb, tip + 0.0005, 0.001)
        coarse = coarse[coarse > low]
        if len(coarse) == 0:
            return tip, -np.inf
        e, _ = self._search(coarse, round_cap)
        fine = np.arange(e - 0.001, e + 0.001 + 1e-9, 0.0002)
        return self._search(fine[fine > low], round_cap)

    def _search(self, ends: FloatArray, round_cap: bool) -> tuple[float, float]:
        # Points short of every candidate end are in the band for all of them: their terms
        # differ between candidates only by the area, and those deep inside the band (edge
        # term above -1e-9) are counted rather than evaluated one by one.
        varying = self.p > ends.min()
        band_terms = log_ndtr((self.hb - self.d[~varying]) / self.sigma)
        deep = int(np.count_nonzero(band_terms > -1e-9))
        edge = band_terms[band_terms <= -1e-9]
        p, d = self.p[varying], self.d[varying]
        x = p[None, :] - ends[:, None]  # (E, M): how far beyond the end each point is
        beyond = x > 0.0
        across = (d - self.hb)[None, :]
        outlier = np.log(_OUTLIERS / self.box)
        best_score, best_e = -np.inf, float(ends[0])
        ratios = _CAP_RATIOS if round_cap else np.zeros(1)
        r = np.hypot(np.maximum(x, 0.0), d[None, :]) if round_cap else None
        for ratio in ratios:
            hc = ratio * self.hb
            if round_cap:
                assert r is not None
                out = np.where(beyond, r - hc, across)
                prior = -0.5 * ((ratio - 1.0) / _CAP_PRIOR) ** 2
            else:
                out = np.where(beyond, np.maximum(across, x), across)
                prior = 0.0
            area = 2.0 * self.hb * (ends - self.start) + 0.5 * np.pi * hc**2
            density = np.log((1.0 - _OUTLIERS) / area)  # (E,)
            total = (
                np.logaddexp(log_ndtr(-out / self.sigma) + density[:, None], outlier).sum(axis=1)
                + np.logaddexp(edge[None, :] + density[:, None], outlier).sum(axis=1)
                + deep * np.logaddexp(density, outlier)
            )
            score = total / len(self.p) * self.weight + prior
            k = int(np.argmax(score))
            if score[k] > best_score:
                best_score, best_e = float(score[k]), float(ends[k])
        return best_e, best_score
