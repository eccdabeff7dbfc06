"""Does the painted line close on itself? A ring round a pipe, a cut-out drawn on a plate.

:func:`detect_closure` decides from the stitched paint and the observed surface around it:

1. **The chain.** The paint is reduced to a chain down the middle of its band
   (:func:`~scrapcut_cli.fitting.ordering.paint_chain`): voxel centroids linked along the band,
   the two nodes farthest apart found, and the graph asked whether two separate arcs join
   them (a loop) or one piece does (a line). A U whose tips lie side by side stays a line
   while its two bands do not run into each other (the tests: tips 30 and 60 mm apart, 25 mm
   bands); paint whose bands merge is one band, and its shape decides.
2. **Paint all round** (``loop``): the chain's graph is a loop; the chain runs once round it.
   Otherwise each end's tip and outward direction are measured on the paint
   (:func:`paint_end`).
3. **A loop through an arc no camera saw** (``unobserved_gap``): otherwise the ends are joined
   by a *bridge*, the cubic that leaves one tip along its direction and arrives at the other
   along its (tangents scaled as for a circular arc through both tips). The line is closed
   only if all of these hold:

   * **neither end was observed to end**: along the bridge past each tip (beyond the band's
     half width, for ``end_probe_m``) the observed surface shows no bare metal — paint ending
     on surface a camera saw is a real end (a U, an open C drawn on a plate), while paint
     running into what no frame saw (under a pipe, against the floor) may go on;
   * the bridge leaves each tip within ``max_end_angle_deg`` of the chord between the tips
     (a circular gap of up to 2 x that angle) and turns alike at both ends (the ends of one arc,
     not two lines pointing past each other);
   * the gap is at most ``max_gap_share`` of the loop (at least half of a ring must be seen);
   * and the bridge crosses no observed bare surface anywhere along it.

4. Otherwise the line is open, and :class:`Closure` says why.

:func:`unobserved_arcs` then finds, on a fitted closed curve, the stretches where neither paint
nor surface was observed: the arcs the fitted model bridged, which the tool path flags
``unobserved``. A gap where the surface was seen but paint is missing (a faded stretch, a hole
in the plate) is not one of them.

Everything is vectorised numpy and scipy (KD-trees, a minimum spanning tree); the decision rules
are written here because no library decides whether a painted stroke closes.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.config import ClosureConfig
from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting._common import as_points
from scrapcut_cli.fitting.ordering import paint_chain
from scrapcut_cli.geometry import (
    PolylineDistance,
    closed_polyline,
    cumulative_length,
    false_runs,
    interpolate_polyline,
    resample_loop,
    resample_polyline,
)

FloatArray = NDArray[np.float64]

#: ``closure.mode``: decide from the data, or force the answer.
CLOSURE_MODES = ("auto", "open", "closed")
#: Why a line was closed, or left open.
LOOP, UNOBSERVED_GAP, FORCED_CLOSED = "loop", "unobserved_gap", "forced_closed"
FORCED_OPEN = "forced_open"
#: Chord over which an end's outward direction is measured (or a quarter of a short chain).
END_SPAN_M = 0.03
#: Stretch, in stroke widths (two half widths each), over which a bridge's end directions are
#: measured when a closed fit joins its centre across the gap (:func:`bridge_directions`).
BRIDGE_SPAN_WIDTHS = 3.0
#: Spacing of the probes along a bridge, and the distance within which an observed surface
#: point counts as bare metal at a probe (one and a half 4 mm surface voxels).
PROBE_STEP_M = 0.002
PROBE_RADIUS_M = 0.006
#: A probe stretch with more than this share of its probes on observed bare surface was seen.
OBSERVED_SHARE = 0.3
#: Bins along a fitted loop when looking for unobserved arcs.
ARC_BIN_M = 0.002


@dataclass(frozen=True, eq=False)
class LineEnd:
    """One end of the paint's chain: ``tip`` (3,) metres, base frame; ``direction`` (3,) the
    unit direction out of the line there; ``observed_share`` (0-1) of the probes past the tip
    lying on observed bare surface (None when not probed)."""

    tip: FloatArray
    direction: FloatArray
    observed_share: float | None = None

    @property
    def observed(self) -> bool:
        return self.observed_share is not None and self.observed_share > OBSERVED_SHARE

    def to_dict(self) -> dict[str, Any]:
        return {
            "tip": [float(v) for v in self.tip],
            "direction": [float(v) for v in self.direction],
            "observed_share": None if self.observed_share is None else float(self.observed_share),
        }


@dataclass(frozen=True, eq=False)
class Closure:
    """Whether the stitched paint closes on itself, and what the decision rests on.

    Attributes
    ----------
    closed : bool
        The line is a loop.
    reason : str
        ``loop`` (paint all round), ``unobserved_gap`` (closed through an arc no frame saw),
        ``forced_closed``; or why it stays open: ``ends_apart`` (no gap rule applies),
        ``end_observed`` (paint ends on observed surface), ``ends_diverge`` (the ends do not
        point along one arc), ``gap_too_long``, ``gap_observed`` (the bridge crosses observed
        bare surface), ``forced_open``, ``too_short``.
    chain : (K, 3) float64
        The paint's centre chain from its first end to its second, metres, base frame (empty
        when not computed).
    bridge : (B, 3) float64
        A closed line's first guess across its gap, from the chain's last point to its first
        (both included; two points for paint all round).
    half_width_m : float
        The band's half width (twice the median distance of the paint to the chain).
    ends : tuple of LineEnd
        The chain's first and last end.
    gap_m : float
        Distance between the chain's ends.
    """

    closed: bool
    reason: str
    chain: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    bridge: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    half_width_m: float = 0.0
    ends: tuple[LineEnd, ...] = ()
    gap_m: float = 0.0

    @property
    def loop(self) -> FloatArray:
        """The chain closed by its bridge: a loop's vertices (M, 3) (the last joins the first)."""
        if len(self.bridge) <= 2:
            return self.chain.copy()
        return np.asarray(np.vstack([self.chain, self.bridge[1:-1]]))

    @property
    def bridge_length_m(self) -> float:
        return float(cumulative_length(self.bridge)[-1]) if len(self.bridge) > 1 else 0.0

    def info(self) -> dict[str, Any]:
        """JSON-ready diagnostics (``Curve.info["closure"]``)."""
        return {
            "closed": self.closed,
            "reason": self.reason,
            "gap_m": float(self.gap_m),
            "bridge_length_m": self.bridge_length_m,
            "chain_length_m": float(cumulative_length(self.chain)[-1])
            if len(self.chain) > 1
            else 0.0,
            "half_width_m": float(self.half_width_m),
            "ends": [e.to_dict() for e in self.ends],
        }


def detect_closure(
    paint_base: ArrayLike,
    surface_base: ArrayLike | None,
    *,
    config: ClosureConfig | None = None,
) -> Closure:
    """Decide whether the stitched paint closes on itself (see the module docstring).

    Parameters
    ----------
    paint_base : (N, 3) float64, metres, base frame
        The stitched paint cloud (of one line). Not modified.
    surface_base : (M, 3) float64, metres, base frame, or None
        Observed bare surface around the paint (the stitched surface band, no paint). None or
        empty: nothing was observed beside the paint, so no end counts as observed.
    config : ClosureConfig, optional
        Mode and thresholds; default ``ClosureConfig()``.
    """
    config = config if config is not None else ClosureConfig()
    check_closure_config(config)
    if config.mode == "open":
        return Closure(False, FORCED_OPEN)
    pts = as_points(paint_base, minimum=8, what="closure")
    surface = np.zeros((0, 3)) if surface_base is None else np.asarray(surface_base, dtype=float)
    surface = surface.reshape(-1, 3)
    found = paint_chain(pts, voxel_m=config.chain_voxel_m)
    chain, used = found.points, found.used
    if len(chain) < 4 or cumulative_length(chain)[-1] < 4.0 * config.chain_voxel_m:
        reason = FORCED_CLOSED if config.mode == "closed" else "too_short"
        if config.mode == "closed":
            raise FittingError("closure.mode is 'closed' but the paint is too short to close")
        return Closure(False, reason, chain=chain)
    dist, _ = cKDTree(resample_polyline(chain, 0.0005)).query(pts[used])
    half = max(2.0 * float(np.median(dist)), config.chain_voxel_m / 2.0)
    length = float(cumulative_length(chain)[-1])
    member = pts[used]
    first = _end(chain, at_start=True, paint=member, half_width_m=half)
    last = _end(chain, at_start=False, paint=member, half_width_m=half)
    gap = float(np.linalg.norm(first.tip - last.tip))
    base = Closure(False, "", chain=chain, half_width_m=half, gap_m=gap, ends=(first, last))

    # Paint all round: the chain's graph is a loop (its ends lie side by side).
    if found.loop:
        return replace(base, closed=True, reason=LOOP, bridge=np.vstack([last.tip, first.tip]))

    bridge = hermite_bridge(last.tip, last.direction, first.tip, first.direction)
    probes = _Probes(surface)
    reach = (half + 0.003, half + config.end_probe_m)
    first = LineEnd(first.tip, first.direction, probes.share(bridge[::-1], *reach))
    last = LineEnd(last.tip, last.direction, probes.share(bridge, *reach))
    base = replace(base, ends=(first, last))
    if config.mode == "closed":
        return replace(base, closed=True, reason=FORCED_CLOSED, bridge=bridge)
    if first.observed or last.observed:
        return replace(base, reason="end_observed")
    chord = (first.tip - last.tip) / max(gap, 1e-12)
    angle_last = float(np.degrees(np.arccos(np.clip(last.direction @ chord, -1.0, 1.0))))
    angle_first = float(np.degrees(np.arccos(np.clip(first.direction @ -chord, -1.0, 1.0))))
    if (
        max(angle_first, angle_last) > config.max_end_angle_deg
        or abs(angle_first - angle_last) > 0.5 * config.max_end_angle_deg
    ):
        return replace(base, reason="ends_diverge")
    bridge_length = float(cumulative_length(bridge)[-1])
    if bridge_length > config.max_gap_share * (bridge_length + length):
        return replace(base, reason="gap_too_long")
    if probes.share(bridge, reach[0], bridge_length - reach[0]) > OBSERVED_SHARE:
        return replace(base, reason="gap_observed")
    return replace(base, closed=True, reason=UNOBSERVED_GAP, bridge=bridge)


def check_closure_config(config: ClosureConfig) -> None:
    """One-line FittingError for an unknown closure mode."""
    if config.mode not in CLOSURE_MODES:
        raise FittingError(
            f"unknown closure.mode {config.mode!r}; known: {', '.join(CLOSURE_MODES)}"
        )


def hermite_bridge(
    start: FloatArray,
    start_direction: FloatArray,
    end: FloatArray,
    end_outward: FloatArray,
    *,
    spacing: float = 0.001,
) -> FloatArray:
    """A cubic (B, 3) from ``start`` leaving along ``start_direction`` to ``end``, arriving
    against ``end_outward`` (the unit direction out of the line at its other end), both ends
    included, about ``spacing`` metres between points.

    The tangents are scaled as a circular arc's through both points with those end directions
    would be (its length, chord x angle / sin angle), so a gap in a ring is bridged by nearly
    the ring's own arc.
    """
    chord = end - start
    c = float(np.linalg.norm(chord))
    if c <= 0.0:
        return np.vstack([start, end])
    u = chord / c
    angle = 0.5 * (
        np.arccos(np.clip(start_direction @ u, -1.0, 1.0))
        + np.arccos(np.clip(-end_outward @ u, -1.0, 1.0))
    )
    scale = c * (angle / np.sin(angle) if 1e-6 < angle < np.pi - 1e-3 else 1.0)
    scale = min(scale, 4.0 * c)
    n = max(int(np.ceil(2.0 * scale / spacing)), 8)
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    h00, h10 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t
    h01, h11 = -2 * t**3 + 3 * t**2, t**3 - t**2
    curve = h00 * start + h10 * scale * start_direction + h01 * end - h11 * scale * end_outward
    return resample_polyline(curve, spacing)


def unobserved_arcs(
    loop: ArrayLike,
    paint_base: ArrayLike,
    surface_base: ArrayLike | None,
    *,
    half_width_m: float,
    min_arc_m: float,
) -> list[tuple[float, float]]:
    """Stretches of a closed curve where neither paint nor bare surface was observed.

    ``loop`` (K, 3) are a closed curve's vertices (not repeating the first), metres, base
    frame. A bin (``ARC_BIN_M`` of arc) is observed when a paint point within 1.5 half widths
    of the curve, or a surface point within 2.5 (beside the band), has its nearest curve point
    in it or next to it. Returns (start, end) arc lengths in metres from the loop's first
    vertex of every unobserved run at least ``min_arc_m`` long, in order; a run across the
    first vertex has end < start.
    """
    pts = np.asarray(loop, dtype=np.float64).reshape(-1, 3)
    dense = resample_loop(pts, ARC_BIN_M)
    s = cumulative_length(closed_polyline(dense))
    total = float(s[-1])
    n = len(dense)
    tree = cKDTree(dense)
    covered = np.zeros(n, dtype=bool)
    for cloud, reach in ((paint_base, 1.5), (surface_base, 2.5)):
        if cloud is None:
            continue
        c = np.asarray(cloud, dtype=np.float64).reshape(-1, 3)
        if len(c) == 0:
            continue
        d, nearest = tree.query(c, distance_upper_bound=reach * half_width_m + ARC_BIN_M)
        covered[nearest[np.isfinite(d)]] = True
    covered |= np.roll(covered, 1) | np.roll(covered, -1)
    arcs = []
    for a, b in false_runs(covered, closed=True):
        span = float(s[b] - s[a]) if b > a else float(total - s[a] + s[b])
        if span >= min_arc_m:
            arcs.append((float(s[a]), float(s[b % n]) if b < n else total))
    return arcs


def arc_mask(arc_length: ArrayLike, arcs: list[tuple[float, float]]) -> NDArray[np.bool_]:
    """Which arc lengths (N,) fall in any of ``arcs`` ((start, end) metres; end < start wraps)."""
    s = np.asarray(arc_length, dtype=np.float64)
    inside = np.zeros(s.shape, dtype=bool)
    for a, b in arcs:
        inside |= (s >= a) & (s <= b) if b >= a else (s >= a) | (s <= b)
    return inside


# --------------------------------------------------------------------------- helpers


def _end(chain: FloatArray, *, at_start: bool, paint: FloatArray, half_width_m: float) -> LineEnd:
    pts = chain[::-1] if at_start else chain
    tip, direction = paint_end(pts, paint, half_width_m=half_width_m)
    return LineEnd(tip, direction)


def paint_end(
    polyline: ArrayLike,
    paint: ArrayLike | None,
    *,
    half_width_m: float,
    span_m: float = END_SPAN_M,
) -> tuple[FloatArray, FloatArray]:
    """Where a painted line ends, and the unit direction (3,) out of it there, at the last
    point of its ordered centre ``polyline`` (K, 3), from the ``paint`` (N, 3) of a band of
    half width ``half_width_m``. Metres, the points' frame.

    A centre line's last half width is unreliable (slices of a band at a square end lean to
    the band's outer side on a bend), and a chord over a span points inward by half the angle
    the span turns. So a quadratic in arc length is fitted to the centre line over ``span_m``
    short of its last half width (at most a quarter of the line) and continued to the line's
    end: its tangent there is the direction; the tip lies along it where the paint near the
    end stops (its 99th percentile along the direction). Without paint, the quadratic's end.
    """
    pts = np.asarray(polyline, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 2:
        return pts[-1].copy() if len(pts) else np.zeros(3), np.zeros(3)
    s = cumulative_length(pts)
    total = float(s[-1])
    half = min(max(float(half_width_m), 0.0), 0.1 * total)
    window = min(span_m, 0.25 * total)
    u = np.linspace(-half - window, -half, 16)
    at = interpolate_polyline(pts, total + u, cumulative=s)
    coef = np.polynomial.polynomial.polyfit(u, at, 2)  # (3, 3): constant, slope, curvature
    end, d = coef[0], coef[1]
    n = float(np.linalg.norm(d))
    if n <= 0.0:
        return np.asarray(pts[-1], dtype=np.float64).copy(), np.zeros(3)
    d = d / n
    if paint is None:
        return np.asarray(end), np.asarray(d)
    cloud = np.asarray(paint, dtype=np.float64).reshape(-1, 3)
    _, _, where = PolylineDistance(pts).query(cloud)
    near = cloud[np.interp(where, np.arange(len(pts)), s) >= total - half - window]
    if len(near) < 12:
        return np.asarray(end), np.asarray(d)
    t_tip = float(np.percentile((near - end) @ d, 99.0))
    return np.asarray(end + t_tip * d), np.asarray(d)


def bridge_directions(polyline: ArrayLike, *, half_width_m: float) -> tuple[FloatArray, FloatArray]:
    """The unit directions (3,) out of an open centre ``polyline`` (K, 3) at its last and at
    its first point, for the bridge (:func:`hermite_bridge`) that closes it into a loop.
    Metres, the points' frame.

    :func:`paint_end`'s quadratic, fitted over ``BRIDGE_SPAN_WIDTHS`` stroke widths
    (``2 * half_width_m`` each) short of the last half width instead of ``END_SPAN_M``, and
    at most a quarter of the line, as there. A bridge carries an end's direction across the
    whole gap, so an error of angle a there swings it by about a x gap / 4 (a ring's 12 cm
    gap: 5 mm for 10 degrees), and the last stroke width or two of a band are where it is
    least sure: slices of its square end, paint misread at the grazing view under a pipe,
    a centre pulled off line by either. Over a few centimetres such a hook is most of the
    span and the quadratic follows it; over three stroke widths it is a third of it at most,
    and the quadratic's curvature still follows a ring's bend (on a 160 mm ring and a 25 mm
    band the span is a sixth of the circumference, which a quadratic fits to a fraction of a
    millimetre). Much longer spans stop following the line's own turns out of its plane (a
    ring drawn by hand wanders along the pipe).
    """
    pts = np.asarray(polyline, dtype=np.float64).reshape(-1, 3)
    span = BRIDGE_SPAN_WIDTHS * 2.0 * float(half_width_m)
    _, out_last = paint_end(pts, None, half_width_m=half_width_m, span_m=span)
    _, out_first = paint_end(pts[::-1], None, half_width_m=half_width_m, span_m=span)
    return out_last, out_first


class _Probes:
    """Observed bare surface near points along a path."""

    def __init__(self, surface: FloatArray) -> None:
        self._tree = cKDTree(surface) if len(surface) else None

    def share(self, path: FloatArray, start: float, stop: float) -> float:
        """Share (0-1) of probes every ``PROBE_STEP_M`` along ``path`` from arc length
        ``start`` to ``stop`` with an observed surface point within ``PROBE_RADIUS_M``."""
        s = cumulative_length(path)
        stop = min(stop, float(s[-1]))
        if self._tree is None or stop <= start:
            return 0.0
        at = interpolate_polyline(path, np.arange(start, stop + 1e-12, PROBE_STEP_M), cumulative=s)
        d, _ = self._tree.query(at, distance_upper_bound=PROBE_RADIUS_M)
        return float(np.mean(np.isfinite(d)))
