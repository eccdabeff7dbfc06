"""The stroke model: the painted line's centre from the stroke's two edges and its width.

A spray stroke is a band of half width h around the line the worker meant. On solid metal the
centre of the paint is the centre of the stroke; where a hole (a perforated plate's slot, the
gap between a basket's wires) takes part of the stroke away, it is not: the paint left on one
side of a hole has its centre off the line. A missing paint pixel over a hole says nothing about
where the stroke's edge is; over metal it does. So the line is estimated from the *edges* of the
stroke, and paint absence counts as an edge only where the depth showed metal that could have
carried paint (``perception.cloud.stroke_edge_points``).

Where that is decided, and why. Hole or metal is decided per frame in the image, where a paint
pixel's neighbours and the pixels beyond them have a depth or none: a hole's background lies far
behind (or has no depth at all), the flying pixels at its rim jump, metal continues the paint's
surface. After stitching, the same test would have to be made on voxel clouds in which a rim's
flying pixels, views from different sides and missing depth at grazing angles are already mixed
(and the surface band is kept at 4 mm). The geometry, on the other hand, is done in 3-D on the
stitched edges: every view's edges add up, and cross sections are taken in the local tangent
plane of the surface along a provisional centre line, so a line that turns over an edge (an
I-beam's flange to its web) is handled the same as a flat one.

The recipe (:func:`stroke_model`):

1. **A provisional centre line** through the paint: its geodesic order (``ordering``), slab
   centroids every ``SLAB_M``, gaps bridged straight, smoothed over about a half width.
2. **Stations** every ``STATION_M`` along it, each with a frame: the tangent t (the line's
   direction over ± ``FRAME_SMOOTH_HALVES`` half widths), the lateral direction a (across the
   line in the surface: the direction in which the observed surface around the station,
   projected across t, spreads most) and b = t × a (the normal).
3. **Cross sections.** The stroke's edge points are placed by their station and their lateral
   offset u = (e − P)·a; the edge points within a window along the line are split by the sign
   of u, and each side's edge is the median of its offsets. The window grows from
   ``MIN_WINDOW_M`` until each side holds ``MIN_EDGE_POINTS``, up to the stroke's half width
   (a wire mesh's crossings are centimetres apart).
4. **Width.** The half widths (u₊ − u₋)/2 of the sections that see both edges, as a running
   median along the line (± ``WIDTH_WINDOW_M``; the whole line's median where there is none,
   or where those sections spread over less than ``WIDTH_SPAN_HALVES`` half widths: one
   crossing of a wire mesh, its few edge points seen by several neighbouring sections across
   a tangent its own paint tilts, is one narrow measurement).
5. **The centre.** Both edges seen: their midpoint. One: that edge moved in by the local half
   width. None (a hole wider than the stroke, a wire along the line, a stretch never seen):
   unknown — the fitters bridge it with the curve's smoothness. Within a half width of the
   paint's ends only two-edge sections count (a round cap's rim is no side edge). The centre's
   height over the surface comes from the edges and the paint near it (b offsets).
6. **Twice**: the centres found (straight across the unknown stretches, smoothed over a half
   width) are the next provisional line, so cross sections are taken across the line itself.
   Past the first and last known centre the stations are carried along by its offset, so the
   line keeps the paint's whole extent: cut back to the known centres, each pass lost the
   ends, and the paint there (a cap, a wire crossing it) was left as it lay for the fitters
   to follow off the line.
7. **The outer envelope** (:func:`_envelope`). On a layered mesh or grate the line is drawn on
   the piece's outer envelope, where the torch cuts, but where it runs between the outer wires
   the spray lands on the layer below. Where the stroke is perforated and the surface within
   the perception's surface band rises above its paint on both sides of the line (by at most
   a layer's depth) on the cameras' side, that outer surface is the envelope, and the paint
   (``recentre``) and the centres are moved along its normal onto it. Solid strokes (steps,
   flanges, grooves) and one-sided rises are left alone.

The fitters fit the paint moved onto the centre (:meth:`StrokeModel.recentre`), and, where
the model knows the centre, with the band's width taken out (:meth:`StrokeModel.collapse`): a
fit to the whole band cannot follow the line along its length any finer than the band is wide
(it would rather zig-zag across it), so a sharp groove's V would be cut across 6-8 mm above its
root; collapsed, the band is as thin as its noise and the V is followed.

Each section also gets its lateral uncertainty σ (metres): the spread of its edges' offsets
over the square root of how many independent pieces of edge the window held, the width's
variation along the line when one edge stands in for two, and a resolution floor of the
stitching voxel (a uniform quantisation error, voxel/√12). The fitters weigh the centres by
1/σ² (``StrokeModel.samples``); :func:`curve_confidence` turns σ, the paint's support and the
frames into each curve point's confidence.

Numpy and scipy (KD-tree, medians) only: no library models a stroke by its edges.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.fitting._common import arc_positions, follows_input_order, moving_average
from scrapcut_cli.fitting.curve import LOW_SUPPORT, Curve, CurveConfidence
from scrapcut_cli.fitting.ordering import geodesic_positions
from scrapcut_cli.geometry import (
    cumulative_length,
    interpolate_polyline,
    orient_over_edge,
    resample_polyline,
    sight_cosines,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Spacing of the cross sections along the line, metres.
STATION_M = 0.002
#: Slabs of the provisional line's centroids, metres.
SLAB_M = 0.005
#: A cross section's window along the line starts at this half length...
MIN_WINDOW_M = 0.003
#: ... and grows until each side holds this many edge points (2 mm voxels of edge).
MIN_EDGE_POINTS = 3
#: Half window of the running median of the half width along the line, metres; the two-edge
#: sections in it must spread over at least this many half widths along the line.
WIDTH_WINDOW_M = 0.05
WIDTH_SPAN_HALVES = 3.0
#: A station's tangent: the line's direction over ± this many half widths.
FRAME_SMOOTH_HALVES = 2.0
#: Radius of the surface that gives a station its lateral direction, metres.
FRAME_RADIUS_M = 0.02
#: Edge points farther than this many half widths across the line, or more than this many off
#: the surface, belong to no section.
MAX_ACROSS = 2.0
MAX_OFF_SURFACE = 0.5
#: Length along an edge over which its roughness and a frame's pixels are correlated: a
#: window's edge points count as (window length / this) independent ones at most.
EDGE_CORRELATION_M = 0.004
#: Provisional line, then the line through the centres found.
ITERATIONS = 2
#: Neighbouring stations' normals further apart than this (degrees) end a run of continuous
#: frames (a surface does not turn that much within ``STATION_M``).
FRAME_JUMP_DEG = 60.0

#: What a section saw: both edges, one, none (its centre is unknown).
BOTH, ONE, NONE = 2, 1, 0


class _Placement(NamedTuple):
    """Where points (N,) lie against a model's stations (K,), metres: the stations' arc
    lengths ``s`` (K,); each point's lateral and normal offsets ``u``, ``w`` (N,) in its
    nearest station's frame (:func:`_place`) and that ``station`` (N,); the median
    ``half`` width; each station's centre ``offset`` across the line (K,); and which points
    are ``near`` (N,): within ``MAX_ACROSS`` half widths and the line's extent."""

    s: FloatArray
    u: FloatArray
    w: FloatArray
    station: IntArray
    half: float
    offset: FloatArray
    near: NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class StrokeObservations:
    """What the stitched clouds say about a stroke besides its paint, base frame, metres.

    ``edges`` (E, 3): the stroke's edges (paint next to metal); ``surface`` (M, 3): the non-paint
    surface around the paint (for the stations' frames and the confidence); ``paint_frames``
    (N,) and ``surface_frames`` (M,): how many frames saw each voxel (empty: unknown);
    ``voxel_m``: the stitching voxel of the paint and edges; ``paint_viewpoints`` (N,): the
    camera centre that first saw each paint voxel (empty: unknown), which side is out;
    ``envelope_reach_m``: how far around the line the surface was kept (the perception's
    surface band), over which the piece's outer envelope is looked for on a layered mesh
    (0: not looked for; see :func:`_envelope`).
    """

    edges: FloatArray
    surface: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    paint_frames: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    surface_frames: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    voxel_m: float = 0.002
    paint_viewpoints: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    envelope_reach_m: float = 0.0


@dataclass(frozen=True, eq=False)
class StrokeModel:
    """The stroke's centre along its provisional line, one cross section per station.

    Attributes
    ----------
    stations : (K, 3) float64
        The provisional centre line the sections were taken across, every ``STATION_M``,
        ordered as the paint was scanned; metres, base frame.
    tangents, lateral, normals : (K, 3) float64
        Each station's frame: t, a (across the line in the surface), b = t × a; b points out
        of the surface (towards the cameras) when the viewpoints are known.
    centres : (K, 3) float64
        The stroke's centre at each station (NaN where unknown).
    kind : (K,) int64
        :data:`BOTH`, :data:`ONE` or :data:`NONE` edges seen.
    half_width : (K,) float64
        The local half width used, metres.
    sigma : (K,) float64
        Lateral uncertainty of each centre, metres (inf where unknown).
    info : dict
        Counts and the stroke's half width, for ``Curve.info``.
    voxel_m : float
        The stitching voxel of the paint and edges, metres.
    envelope, envelope_normals : (K,) and (K, 3) float64
        Where the paint lies on a layered mesh's lower layer: the outer envelope's height over
        the station along its local outward normal (metres; NaN elsewhere, and both empty when
        not looked for; :func:`_envelope`). ``recentre`` moves the paint onto it.
    """

    stations: FloatArray
    tangents: FloatArray
    lateral: FloatArray
    normals: FloatArray
    centres: FloatArray
    kind: IntArray
    half_width: FloatArray
    sigma: FloatArray
    info: dict[str, Any] = field(default_factory=dict)
    voxel_m: float = 0.002
    envelope: FloatArray = field(default_factory=lambda: np.zeros(0))
    envelope_normals: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def edge_half_width(self) -> float | None:
        """The stroke's half width measured from its two edges (the median over the sections
        that saw both), metres; None when no section saw both."""
        half = float(self.info.get("half_width_m", np.nan))
        return half if np.isfinite(half) else None

    @property
    def known(self) -> NDArray[np.bool_]:
        """(K,) sections whose centre is known."""
        return np.asarray(self.kind > NONE)

    def samples(self) -> tuple[FloatArray, FloatArray]:
        """The known centres (J, 3), in order along the line, and their weights (J,) ∝ 1/σ²
        (mean 1): what the fitters fit."""
        known = self.known
        w = 1.0 / np.maximum(self.sigma[known], 1e-6) ** 2
        return self.centres[known].copy(), np.asarray(w / max(float(w.mean()), 1e-300))

    def recentre(self, paint: ArrayLike) -> FloatArray:
        """``paint`` (N, 3) moved so that its centre is the stroke's: what the fitters fit.

        Each point moves by its nearest station's shift, in that station's frame: across the
        line, the model's centre minus the paint's mean offset there; along the normal, the
        mean height of the paint within a third of a half width of that centre minus the mean
        height of all of it (the centroid of a band on a pipe lies below the surface, its
        middle does not) — or, where the paint lies in layers (a wire mesh), its top. Paint
        within ± ``STATION_M`` along and ``MAX_ACROSS`` half widths
        across counts; the shifts are interpolated across the stations without a centre or
        without paint, and smoothed over about a half width. The paint's extent along the line
        (its ends) and its shape along it (a groove's dip) stay the paint's. Last, paint below
        a layered mesh's outer envelope is moved onto it (:meth:`onto_envelope`). A copy when
        the model knows no centre."""
        cloud = np.asarray(paint, dtype=np.float64).reshape(-1, 3)
        known = self.known
        if len(self.stations) < 2 or len(cloud) == 0 or not known.any():
            return cloud.copy()
        s, u, w, k, half, offset, near = self._placed(cloud)
        n = len(s)
        middle = near & (np.abs(u - offset[k]) <= half / 3.0)

        def slab_sums(mask: NDArray[np.bool_], values: FloatArray) -> tuple[FloatArray, FloatArray]:
            total, count = np.zeros(n), np.zeros(n)
            for step in (-1, 0, 1):  # each station sees its neighbours' slabs too
                kk = np.clip(k[mask] + step, 0, n - 1)
                total += np.bincount(kk, weights=values[mask], minlength=n)
                count += np.bincount(kk, minlength=n)
            return total, count

        u_sum, count = slab_sums(near, u)
        w_sum, _ = slab_sums(near, w)
        w_mid, count_mid = slab_sums(middle, w)
        # Within a half width of the line's ends lie the round caps, whose rims and partly seen
        # paint say little about the centre: no shift at the very ends, the full one a half
        # width in.
        taper = np.clip(np.minimum(s, s[-1] - s) / half, 0.0, 1.0)
        usable = known & (count >= 3) & (taper >= 1.0)
        if not usable.any():
            return cloud.copy()
        safe = np.maximum(count, 1.0)
        across = offset - u_sum / safe
        up = np.where(count_mid >= 3, w_mid / np.maximum(count_mid, 1.0) - w_sum / safe, 0.0)
        # Paint in layers (a wire mesh: the top wires, the wires under them, their sides) lies
        # on the piece's envelope and below it; the line runs on the envelope, so there the
        # paint's top (its 90 % height within a half width along the line) is the line's
        # height, not its middle. Layers: heights spread over more than two stitching voxels
        # (one surface's paint spreads over less: a voxel's quantisation and the sensor's
        # noise).
        reach = max(round(half / STATION_M), 1)
        low, high = _slab_quantiles(k[near], w[near], n, (0.1, 0.9), reach)
        # ... and only where the paint is sparse (under half of a full band's voxels in the
        # slabs): a groove or a ridge across the line spreads a solid band's heights too.
        full = (2.0 * half / self.voxel_m) * (3.0 * STATION_M / self.voxel_m)
        layered = np.isfinite(high) & (high - low > 2.0 * self.voxel_m) & (count < 0.5 * full)
        up = np.where(layered, high - w_sum / safe, up)
        idx = np.arange(n)
        window = 2 * max(round(0.5 * half / STATION_M), 1) + 1
        shifts = np.column_stack(
            [
                np.interp(idx, idx[usable], across[usable]),
                np.interp(idx, idx[usable], up[usable]),
                np.zeros(n),
            ]
        )
        shifts = moving_average(shifts, window) * taper[:, None]
        moved = cloud + shifts[k, 0, None] * self.lateral[k] + shifts[k, 1, None] * self.normals[k]
        return self.onto_envelope(moved, k)

    def collapse(self, points: ArrayLike) -> tuple[FloatArray, NDArray[np.bool_]]:
        """``points`` (N, 3) (recentred paint) moved across the line onto the stroke's centre
        wherever their nearest station's centre is known: the band's width taken out, its
        shape along the line and its height kept. Points off the line's ends, farther than
        ``MAX_ACROSS`` half widths across, or at stations without a centre stay as they are.
        Returns the points and which of them (N,) moved."""
        cloud = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(self.stations) < 2 or len(cloud) == 0 or not self.known.any():
            return cloud.copy(), np.zeros(len(cloud), dtype=bool)
        placed = self._placed(cloud)
        k = placed.station
        move = self.known[k] & placed.near
        du = np.where(move, placed.offset[k] - placed.u, 0.0)
        return np.asarray(cloud + du[:, None] * self.lateral[k]), np.asarray(move)

    def _placed(self, cloud: FloatArray) -> _Placement:
        """Where the points (N, 3) lie against the stations (see :class:`_Placement`)."""
        s = cumulative_length(self.stations)
        u, w, se = _place(self.stations, s, self.lateral, self.normals, cloud)
        k = np.clip(np.rint(se / STATION_M).astype(np.int64), 0, len(s) - 1)
        half = max(float(np.median(self.half_width)), 1e-3)
        offset = np.einsum("ij,ij->i", np.nan_to_num(self.centres) - self.stations, self.lateral)
        near = (np.abs(u) <= MAX_ACROSS * half) & (se >= 0.0) & (se <= s[-1])
        return _Placement(s, u, w, k, half, offset, near)

    def onto_envelope(self, points: ArrayLike, station: NDArray[np.int64]) -> FloatArray:
        """``points`` (N, 3) below the outer envelope of their ``station`` (N,) moved along its
        normal onto it (a layered mesh's lower-layer paint up to where the torch cuts); the
        others, and every point where no envelope was found, unchanged."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(self.envelope) != len(self.stations) or len(pts) == 0:
            return pts
        k = np.clip(np.asarray(station, dtype=np.int64), 0, len(self.stations) - 1)
        n = self.envelope_normals[k]
        below = np.nan_to_num(self.envelope[k], nan=-np.inf) - np.einsum(
            "ij,ij->i", pts - self.stations[k], n
        )
        lift = np.where(np.isfinite(below) & (below > 0.0), below, 0.0)
        return np.asarray(pts + lift[:, None] * n)

    def line(self) -> FloatArray:
        """The centre line (K, 3): known centres, straight across the unknown stretches (the
        stations themselves where nothing is known)."""
        return _bridged(self.stations, self.centres, self.known)


def stroke_model(
    paint_base: ArrayLike,
    observations: StrokeObservations,
    *,
    half_width_m: float | None = None,
) -> StrokeModel:
    """The stroke's centre from its edges (see the module text).

    Parameters
    ----------
    paint_base : (N, 3) float64, metres, base frame
        The stitched paint, in scan order (the model runs in that direction). Not modified.
    observations : StrokeObservations
        The stitched edges (and surface) of the same recording.
    half_width_m : float, optional
        The stroke's half width if known; default: from the two-edge sections, else from the
        paint's spread.

    Returns
    -------
    StrokeModel
    """
    paint = np.asarray(paint_base, dtype=np.float64).reshape(-1, 3)
    edges = np.asarray(observations.edges, dtype=np.float64).reshape(-1, 3)
    surface = np.asarray(observations.surface, dtype=np.float64).reshape(-1, 3)
    line = _provisional_line(paint)
    context = np.vstack([paint, edges, surface])
    guess = half_width_m if half_width_m is not None else _paint_half_width(line, paint)
    model = None
    for _ in range(ITERATIONS):
        model = replace(
            _sections(line, paint, edges, context, guess, observations.voxel_m),
            voxel_m=float(observations.voxel_m),
        )
        model = _outward(model, paint, observations.paint_viewpoints)
        if half_width_m is None and np.isfinite(model.info["half_width_m"]):
            guess = float(model.info["half_width_m"])
        if not model.known.any():
            break
        line = _smooth_line(_carried(model.stations, model.centres, model.known), guess)
    assert model is not None
    return _with_envelope(
        model, paint, surface, observations.envelope_reach_m, observations.paint_viewpoints
    )


# --------------------------------------------------------------------------- provisional line


def _provisional_line(paint: FloatArray) -> FloatArray:
    """A centre line (K, 3) through the paint every ``STATION_M``, in scan order: slab
    centroids of the geodesic order, straight across empty slabs, smoothed."""
    if len(paint) < 3:
        return resample_polyline(paint, STATION_M) if len(paint) >= 2 else paint.copy()
    position, _ = geodesic_positions(paint)
    slab = np.floor((position - position.min()) / SLAB_M).astype(np.int64)
    counts = np.bincount(slab)
    filled = counts > 0
    sums = np.column_stack([np.bincount(slab, weights=paint[:, k]) for k in range(3)])
    centroids = sums[filled] / counts[filled][:, None]
    line = moving_average(centroids, 5)
    if not follows_input_order(position):
        line = line[::-1]
    return resample_polyline(line, STATION_M)


def _smooth_line(line: FloatArray, half_width: float) -> FloatArray:
    """The line (K, 3) smoothed over about a half width and resampled every ``STATION_M``."""
    window = 2 * max(round(0.5 * half_width / STATION_M), 1) + 1
    return resample_polyline(moving_average(line, window), STATION_M)


def _paint_half_width(line: FloatArray, paint: FloatArray) -> float:
    """A first guess of the stroke's half width: the 90 % quantile of the paint's distance to
    the provisional line (a uniform band's is 0.9 h), at least a few millimetres."""
    dist, _ = arc_positions(line, paint)
    return max(float(np.quantile(dist, 0.9)) / 0.9, 0.003)


def _bridged(stations: FloatArray, centres: FloatArray, known: NDArray[np.bool_]) -> FloatArray:
    """Known centres, linearly interpolated in station index across unknown ones."""
    if not known.any():
        return stations.copy()
    idx = np.arange(len(stations))
    out = np.column_stack([np.interp(idx, idx[known], centres[known, k]) for k in range(3)])
    return np.asarray(out)


def _carried(stations: FloatArray, centres: FloatArray, known: NDArray[np.bool_]) -> FloatArray:
    """The next provisional line: known centres, straight across unknown stretches between
    them, and past the first and last known centre the stations moved by that centre's
    offset (the line keeps the paint's whole extent, its caps included)."""
    line = _bridged(stations, centres, known)
    if not known.any():
        return line
    idx = np.flatnonzero(known)
    first, last = int(idx[0]), int(idx[-1])
    line[:first] = stations[:first] + (centres[first] - stations[first])
    line[last + 1 :] = stations[last + 1 :] + (centres[last] - stations[last])
    return line


# --------------------------------------------------------------------------- sections


def _frames(
    line: FloatArray, context: FloatArray, half_width: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Unit tangent, lateral and normal (K, 3) of every station of ``line``.

    The tangent is the line's direction smoothed over ± ``FRAME_SMOOTH_HALVES`` half widths:
    on broken paint (a wire mesh) the line runs through centres a few millimetres apart across
    it and a centimetre along, and its own direction tilted the sections by 10-25 degrees (a
    band measured across such a tilt is narrower by its cosine, and a one-edge centre moves by
    the tilt times how far along the window its edge points lie). The lateral direction is
    the principal direction of the observed points within ``FRAME_RADIUS_M`` of the line and
    of the station along it, projected onto the plane across the tangent (a stroke and the
    surface around it spread across the line, not along its normal); signs are kept
    continuous along the line. Covariances come from cumulative sums over the points sorted
    along the line (no loop over points or stations)."""
    k = len(line)
    if k < 2:
        return np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), np.array([[0, 0, 1.0]])
    window = 2 * max(round(FRAME_SMOOTH_HALVES * half_width / STATION_M), 0) + 1
    tangent = np.gradient(moving_average(line, window), axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    helper = np.where(np.abs(tangent[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(tangent, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(tangent, e1)
    s = cumulative_length(line)
    dist, arc = arc_positions(line, context) if len(context) else (np.zeros(0), np.zeros(0))
    near = dist <= FRAME_RADIUS_M
    order = np.argsort(arc[near], kind="stable")
    pts, pos = context[near][order], arc[near][order]
    # Centre the points on the line's middle for round-off, then running sums of x and x xᵀ.
    origin = line[k // 2]
    x = pts - origin
    outer = (x[:, :, None] * x[:, None, :]).reshape(-1, 9)
    cx = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    cxx = np.vstack([np.zeros((1, 9)), np.cumsum(outer, axis=0)])
    lo = np.searchsorted(pos, s - FRAME_RADIUS_M, side="left")
    hi = np.searchsorted(pos, s + FRAME_RADIUS_M, side="right")
    count = (hi - lo).astype(np.float64)
    mean = (cx[hi] - cx[lo]) / np.maximum(count, 1.0)[:, None]
    second = ((cxx[hi] - cxx[lo]) / np.maximum(count, 1.0)[:, None]).reshape(k, 3, 3)
    cov = second - mean[:, :, None] * mean[:, None, :]
    # The 2 x 2 covariance across the tangent and its principal direction (closed form).
    a = np.einsum("ki,kij,kj->k", e1, cov, e1)
    c = np.einsum("ki,kij,kj->k", e2, cov, e2)
    b = np.einsum("ki,kij,kj->k", e1, cov, e2)
    angle = 0.5 * np.arctan2(2.0 * b, a - c)
    spread = np.sqrt((0.5 * (a - c)) ** 2 + b**2)
    big, small = 0.5 * (a + c) + spread, 0.5 * (a + c) - spread
    clear = (count >= 3) & (big > 1.5 * np.maximum(small, 1e-18))
    direction = np.cos(angle)[:, None] * e1 + np.sin(angle)[:, None] * e2
    lateral = np.empty_like(line)
    previous = None
    for i in range(k):  # signs and fallbacks carried along the line: one small step each
        d = direction[i]
        if not clear[i]:
            if previous is None:
                d = e1[i]
            else:
                d = previous - float(np.dot(previous, tangent[i])) * tangent[i]
                d = d / max(float(np.linalg.norm(d)), 1e-12)
        if previous is not None and float(np.dot(d, previous)) < 0.0:
            d = -d
        lateral[i] = d
        previous = d
    normal = np.cross(tangent, lateral)
    return tangent, lateral, normal


def _sections(
    line: FloatArray,
    paint: FloatArray,
    edges: FloatArray,
    context: FloatArray,
    half_guess: float,
    voxel_m: float,
) -> StrokeModel:
    """Cross sections of the edges across ``line`` (K, 3): steps 2-5 of the module text."""
    k = len(line)
    tangent, lateral, normal = _frames(line, context, half_guess)
    s = cumulative_length(line)
    length = float(s[-1]) if k else 0.0
    floor = voxel_m / np.sqrt(12.0)
    plus, minus, sigma_plus, sigma_minus, windows = _edge_sides(
        line, s, lateral, normal, edges, half_guess, voxel_m
    )
    near_end = np.minimum(s, length - s) < half_guess
    one_sided = ~(np.isfinite(plus) & np.isfinite(minus))
    plus[near_end & one_sided] = np.nan
    minus[near_end & one_sided] = np.nan
    both = np.isfinite(plus) & np.isfinite(minus) & (plus - minus > 2.0 * voxel_m)
    halves = 0.5 * (plus - minus)
    half_width, half_sd = _local_half_width(s, halves, both, half_guess)
    offset = np.full(k, np.nan)
    sigma = np.full(k, np.inf)
    kind = np.zeros(k, dtype=np.int64)
    offset[both] = 0.5 * (plus[both] + minus[both])
    sigma[both] = 0.5 * np.hypot(sigma_plus[both], sigma_minus[both])
    kind[both] = BOTH
    only_plus = ~both & np.isfinite(plus) & ~np.isfinite(minus)
    only_minus = ~both & np.isfinite(minus) & ~np.isfinite(plus)
    offset[only_plus] = plus[only_plus] - half_width[only_plus]
    offset[only_minus] = minus[only_minus] + half_width[only_minus]
    sigma[only_plus] = np.hypot(sigma_plus[only_plus], half_sd[only_plus])
    sigma[only_minus] = np.hypot(sigma_minus[only_minus], half_sd[only_minus])
    kind[only_plus | only_minus] = ONE
    sigma = np.where(kind > NONE, np.hypot(sigma, floor), np.inf)
    known = kind > NONE
    lift = _heights(line, s, lateral, normal, paint, edges, offset, half_width, windows, known)
    centres = np.full((k, 3), np.nan)
    centres[known] = (
        line[known] + offset[known, None] * lateral[known] + lift[known, None] * normal[known]
    )
    two = halves[both]
    info = {
        "sections": int(k),
        "sections_both_edges": int(both.sum()),
        "sections_one_edge": int((only_plus | only_minus).sum()),
        "sections_unknown": int(k - known.sum()),
        "edge_points": len(edges),
        "half_width_m": float(np.median(two)) if len(two) else float("nan"),
    }
    return StrokeModel(
        stations=line,
        tangents=tangent,
        lateral=lateral,
        normals=normal,
        centres=centres,
        kind=kind,
        half_width=half_width,
        sigma=sigma,
        info=info,
    )


def _edge_sides(
    line: FloatArray,
    s: FloatArray,
    lateral: FloatArray,
    normal: FloatArray,
    edges: FloatArray,
    half_guess: float,
    voxel_m: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per station (K,): the edge offsets on the + and - side (NaN: not seen), their σ, and
    the half window along the line the section used (step 3 of the module text).

    A section's edges are measured in its own station's frame, (x, u) = ((e − P)·t, (e − P)·a),
    and each side's edge is a straight line u = c₀ + c₁x fitted to them (an edge 10 mm away
    along a curving line is not where it is beside the station); its offset is c₀ and its σ the
    intercept's standard error, with the points counted as at most one per
    ``EDGE_CORRELATION_M`` of window (a ragged edge's neighbouring points are not independent).
    Points more than three robust deviations off a first fit are dropped before the second.
    Every station at once: the windows' points are gathered into a padded (K, M) table.
    """
    k = len(line)
    plus, minus = np.full(k, np.nan), np.full(k, np.nan)
    sigma_plus, sigma_minus = np.full(k, np.inf), np.full(k, np.inf)
    windows = np.full(k, MIN_WINDOW_M)
    if k < 2 or len(edges) == 0:
        return plus, minus, sigma_plus, sigma_minus, windows
    length = float(s[-1])
    u, w, se = _place(line, s, lateral, normal, edges)
    keep = (np.abs(u) <= MAX_ACROSS * half_guess) & (
        np.abs(w) <= max(MAX_OFF_SURFACE * half_guess, 2.0 * voxel_m)
    )
    # Edge points beyond the line's ends are a round cap's rim, not a side's edge.
    keep &= (se > 0.0) & (se < length)
    if not keep.any():
        return plus, minus, sigma_plus, sigma_minus, windows
    order = np.argsort(se[keep], kind="stable")
    points, u, se = edges[keep][order], u[keep][order], se[keep][order]
    # The smallest window (doubling from MIN_WINDOW_M up to the half width) with enough
    # points on both sides.
    positive = np.concatenate([[0], np.cumsum(u > 0.0)])
    chosen = np.full(k, -1.0)
    size = MIN_WINDOW_M
    while True:
        size = min(size, half_guess)
        lo = np.searchsorted(se, s - size, side="left")
        hi = np.searchsorted(se, s + size, side="right")
        n_plus = positive[hi] - positive[lo]
        enough = np.minimum(n_plus, (hi - lo) - n_plus) >= MIN_EDGE_POINTS
        chosen = np.where((chosen < 0.0) & (enough | (size >= half_guess)), size, chosen)
        if size >= half_guess or (chosen > 0.0).all():
            break
        size *= 2.0
    windows = chosen
    lo = np.searchsorted(se, s - windows, side="left")
    hi = np.searchsorted(se, s + windows, side="right")
    width = int(max((hi - lo).max(), 1))
    idx = lo[:, None] + np.arange(width)[None, :]
    valid = idx < hi[:, None]
    idx = np.minimum(idx, len(se) - 1)
    d = points[idx] - line[:, None, :]  # (K, M, 3)
    x = np.einsum(
        "kmj,kj->km",
        d,
        np.gradient(line, axis=0)
        / np.maximum(np.linalg.norm(np.gradient(line, axis=0), axis=1, keepdims=True), 1e-12),
    )
    across = np.einsum("kmj,kj->km", d, lateral)
    independent = np.maximum(2.0 * windows / EDGE_CORRELATION_M, 1.0)
    for side, where, spread in (
        (valid & (u[idx] > 0.0), plus, sigma_plus),
        (valid & (u[idx] < 0.0), minus, sigma_minus),
    ):
        c0, se0, n = _edge_lines(x, across, side, independent)
        ok = n >= MIN_EDGE_POINTS
        where[ok] = c0[ok]
        spread[ok] = se0[ok]
    return plus, minus, sigma_plus, sigma_minus, windows


def _edge_lines(
    x: FloatArray, u: FloatArray, mask: NDArray[np.bool_], independent: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per row of (K, M) tables of positions x and offsets u (``mask`` the entries in use): the
    intercept at x = 0 of the straight line u = c₀ + c₁x, its standard error (the points
    counted as at most ``independent`` (K,)), and the points kept; a constant where the points
    span too little along the line for a slope. Two passes: the second without the points
    more than three robust deviations off the first."""
    keep = mask.copy()
    for final in (False, True):
        n = keep.sum(axis=1).astype(np.float64)
        safe = np.maximum(n, 1.0)
        xm = np.where(keep, x, 0.0).sum(axis=1) / safe
        um = np.where(keep, u, 0.0).sum(axis=1) / safe
        dx = np.where(keep, x - xm[:, None], 0.0)
        du = np.where(keep, u - um[:, None], 0.0)
        sxx = (dx**2).sum(axis=1)
        sloped = (n >= 4) & (sxx > n * (0.5 * EDGE_CORRELATION_M) ** 2)
        slope = np.where(sloped, (dx * du).sum(axis=1) / np.maximum(sxx, 1e-18), 0.0)
        c0 = um - slope * xm
        residual = u - (c0[:, None] + slope[:, None] * x)
        if final:
            break
        mad = 1.4826 * _row_median(np.abs(residual), keep)
        limit = np.maximum(3.0 * mad, 1e-4)
        trimmed = keep & (np.abs(residual) <= limit[:, None])
        keep = np.where((trimmed.sum(axis=1) >= MIN_EDGE_POINTS)[:, None], trimmed, keep)
    dof = np.maximum(n - np.where(sloped, 2.0, 1.0), 1.0)
    sd = np.sqrt(np.where(keep, residual**2, 0.0).sum(axis=1) / dof)
    n_eff = np.minimum(n, independent)
    leverage = 1.0 / np.maximum(n_eff, 1.0) + np.where(
        sloped, xm**2 / np.maximum(sxx, 1e-18) * n / np.maximum(n_eff, 1.0), 0.0
    )
    return c0, sd * np.sqrt(leverage), n


def _heights(
    line: FloatArray,
    s: FloatArray,
    lateral: FloatArray,
    normal: FloatArray,
    paint: FloatArray,
    edges: FloatArray,
    offset: FloatArray,
    half_width: FloatArray,
    windows: FloatArray,
    known: NDArray[np.bool_],
) -> FloatArray:
    """The surface's offset along the normal (K,) at each known centre, in the station's
    frame: the median of the paint within a third of a half width of the centre (across) and
    the section's window (along); the edges' where no paint is there (a hole under the
    centre); 0 where neither is."""
    lift = np.zeros(len(line))
    if not known.any():
        return lift
    for cloud, paint_like in ((edges, False), (paint, True)):
        if len(cloud) == 0:
            continue
        _, _, se = _place(line, s, lateral, normal, cloud)
        order = np.argsort(se, kind="stable")
        pts, se = cloud[order], se[order]
        lo = np.searchsorted(se, s - windows, side="left")
        hi = np.searchsorted(se, s + windows, side="right")
        width = int(max((hi - lo).max(), 1))
        idx = lo[:, None] + np.arange(width)[None, :]
        valid = (idx < hi[:, None]) & known[:, None]
        d = pts[np.minimum(idx, len(se) - 1)] - line[:, None, :]
        across = np.einsum("kmj,kj->km", d, lateral)
        up = np.einsum("kmj,kj->km", d, normal)
        if paint_like:
            near = np.abs(across - np.nan_to_num(offset)[:, None]) <= half_width[:, None] / 3.0
        else:
            near = np.abs(across) <= 2.0 * half_width[:, None]
        mask = valid & near
        found = mask.any(axis=1)
        lift = np.where(found, _row_median(up, mask), lift)
    return lift


def _row_median(values: FloatArray, mask: NDArray[np.bool_]) -> FloatArray:
    """Median (K,) of each row's entries where ``mask`` (0 for an empty row)."""
    ordered = np.sort(np.where(mask, values, np.inf), axis=1)
    n = mask.sum(axis=1)
    rows = np.arange(len(values))
    lo = np.clip((n - 1) // 2, 0, values.shape[1] - 1)
    hi = np.clip(n // 2, 0, values.shape[1] - 1)
    median = 0.5 * (ordered[rows, lo] + ordered[rows, hi])
    return np.asarray(np.where(n > 0, median, 0.0))


def _place(
    line: FloatArray, s: FloatArray, lateral: FloatArray, normal: FloatArray, points: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each point's lateral offset u (N,), normal offset w (N,) and arc length (N,) along the
    line, in the frame of its nearest station (arc lengths beyond the ends mark points off
    either end: the line is extended by a ``FRAME_RADIUS_M`` straight piece for this)."""
    reach = FRAME_RADIUS_M
    head = line[0] - reach * _unit(line[1] - line[0])
    tail = line[-1] + reach * _unit(line[-1] - line[-2])
    extended = np.vstack([head, line, tail])
    _, arc = arc_positions(extended, points)
    se = arc - reach
    k = np.clip(np.rint(se / STATION_M).astype(np.int64), 0, len(line) - 1)
    foot = interpolate_polyline(line, se, cumulative=s)
    d = points - foot
    return (
        np.einsum("ij,ij->i", d, lateral[k]),
        np.einsum("ij,ij->i", d, normal[k]),
        np.asarray(se),
    )


def _outward(model: StrokeModel, paint: FloatArray, viewpoints: ArrayLike) -> StrokeModel:
    """``model`` with its normals (and laterals, keeping the frames right-handed) turned out of
    the surface: each run of continuous frames to the side from which most of its stations'
    nearest paint was seen.

    :func:`_frames` carries the frames' signs along the line, so within a run (no step between
    neighbouring stations' normals over ``FRAME_JUMP_DEG``: where the surface around the line
    gives no clear lateral direction the frame can jump) one sign serves every station.
    Turning each station by its own camera would flip single stations where a see-through
    piece (a basket's side wall, seen through its top) or a grazing view showed the paint from
    behind, and the shifts :meth:`StrokeModel.recentre` carries between neighbouring stations
    would then point every which way."""
    cameras = np.asarray(viewpoints, dtype=np.float64).reshape(-1, 3)
    if len(cameras) != len(paint) or len(paint) == 0 or len(model.stations) == 0:
        return model
    _, nearest = cKDTree(paint).query(model.stations)
    facing = np.sign(np.einsum("ij,ij->i", cameras[nearest] - model.stations, model.normals))
    step = np.einsum("ij,ij->i", model.normals[:-1], model.normals[1:])
    run = np.concatenate([[0], np.cumsum(step < np.cos(np.radians(FRAME_JUMP_DEG)))])
    votes = np.bincount(run, weights=facing)
    sign = np.where(votes[run] < 0.0, -1.0, 1.0)[:, None]
    return replace(model, lateral=model.lateral * sign, normals=model.normals * sign)


def _slab_quantiles(
    k: IntArray, values: FloatArray, n: int, quantiles: tuple[float, float], reach: int
) -> tuple[FloatArray, FloatArray]:
    """Two quantiles (n,) of ``values`` grouped by station ``k`` (each station with its
    neighbours' slabs, ± ``reach``), NaN where a station has fewer than 5 values."""
    steps = range(-reach, reach + 1)
    ks = np.concatenate([np.clip(k + step, 0, n - 1) for step in steps])
    vs = np.concatenate([values] * len(steps))
    order = np.lexsort((vs, ks))
    ks, vs = ks[order], vs[order]
    start = np.searchsorted(ks, np.arange(n), side="left")
    count = np.searchsorted(ks, np.arange(n), side="right") - start
    out = []
    for q in quantiles:
        at = start + np.floor(q * np.maximum(count - 1, 0)).astype(np.int64)
        picked = vs[np.clip(at, 0, max(len(vs) - 1, 0))] if len(vs) else np.zeros(n)
        out.append(np.where(count >= 5, picked, np.nan))
    return out[0], out[1]


# --------------------------------------------------------------------------- outer envelope


#: A perforated stroke: under this share of a full band's paint voxels within the reach along
#: the line (a mesh's wires or a grate's bars carry the paint, the openings between them do
#: not; on two layers and smeared by stitching they hold 0.3-0.7 of it on the simulator's
#: basket). A solid stroke — on a plate, a step, a groove, a flange — fills its band: 0.96 of
#: it and more on the simulator's solid pieces.
PERFORATED_SHARE = 0.8
#: The outer surface on each side of the line: this quantile of the heights of the points
#: there along the local normal (the outer wires' tops; a few stray points above them do not
#: count) ...
ENVELOPE_QUANTILE = 0.9
#: ... from at least this many points on each side (the line must be bracketed: a surface
#: higher on one side only is a step or a flange beside the line, not an envelope over it).
ENVELOPE_MIN_POINTS = 5
#: A mesh's or a grate's lower layer lies at most this far below its outer one (its top lies
#: one wire or bar below: crossed wires or bars up to 12 mm thick): a larger lift would move
#: the line onto another surface. Also
#: the thickest slab the points around a station may fill for one local plane to fit them
#: (twice its RMS thickness): past a piece's edge or in a corner they fill more.
MAX_LAYER_DEPTH_M = 0.012
#: Along the line the lift onto the envelope comes in over this length at either end of a
#: lifted stretch (twice the paper's 5 mm skeleton leaf: a layer-deep step within a leaf or
#: two would split a skeleton), and gaps up to this long between lifted stations are bridged.
ENVELOPE_RAMP_M = 0.01
#: The cameras must have seen the paint around a station from the same side of the surface
#: (this share of its voxels at least) and from in front (their median sight line within 45°
#: of the normal) for that side to be out.
FACING_SHARE = 0.9
FACING_COS = float(np.cos(np.radians(45.0)))


def _with_envelope(
    model: StrokeModel,
    paint: FloatArray,
    surface: FloatArray,
    reach_m: float,
    viewpoints: ArrayLike = (),
) -> StrokeModel:
    """``model`` with the outer envelope of a layered mesh (:func:`_envelope`) and its known
    centres moved onto it."""
    if reach_m <= 0.0 or len(model.stations) < 2:
        return model
    envelope, normals = _envelope(model, paint, surface, reach_m, viewpoints)
    found = np.isfinite(envelope)
    info = {**model.info, "envelope_sections": int(found.sum())}
    if found.any():
        lifted = np.nan_to_num(envelope[found]) - np.einsum(
            "ij,ij->i", np.nan_to_num(model.centres[found]) - model.stations[found], normals[found]
        )
        info["envelope_lift_median_m"] = float(np.median(lifted))
    model = replace(model, envelope=envelope, envelope_normals=normals, info=info)
    centres = model.centres.copy()
    known = model.known
    centres[known] = model.onto_envelope(centres[known], np.flatnonzero(known))
    return replace(model, centres=centres)


def _envelope(
    model: StrokeModel,
    paint: FloatArray,
    surface: FloatArray,
    reach_m: float,
    viewpoints: ArrayLike = (),
) -> tuple[FloatArray, FloatArray]:
    """The piece's outer envelope where the paint lies on a layered mesh's lower layer.

    A torch cuts a mesh or a grate along its outer envelope, which the worker drew the line
    on; the spray lands on whatever wire is under it, and where the line runs between the
    outer wires that is the layer below. At each station, the points within ``reach_m`` (the
    paint and the surface around it: every depth the perception kept) give a local plane
    (principal axes) and its outward normal (:func:`_outward_normals`). The envelope is the
    lower of the two sides' outer heights (``ENVELOPE_QUANTILE`` of the heights across the
    line on each side, each from ``ENVELOPE_MIN_POINTS`` at least) and it counts only where
    all of these hold:

    - the points fit one plane: their RMS thickness is at most half ``MAX_LAYER_DEPTH_M`` (no
      edge of the piece, no corner within the reach);
    - the stroke is perforated: its band within the reach holds under ``PERFORATED_SHARE`` of
      a full band's paint voxels over the line's length there (solid pieces — steps, flanges,
      grooves — are left alone);
    - both sides rise above the paint (the median height of the band's paint), by at most
      ``MAX_LAYER_DEPTH_M``; by more than a stitching voxel (a surface's own spread) here or
      at a station within the reach along the line (where the line crosses an outer wire,
      the band's paint lies on both layers and its median between them).

    Gaps of up to ``ENVELOPE_RAMP_M`` between such stations take the nearest one's plane, and
    the lift comes in linearly over ``ENVELOPE_RAMP_M`` at either end of a lifted stretch.

    Returns the envelope's height over each station along that normal (K,) (NaN where it does
    not count) and the normals (K, 3) (the station's own where it does not count).
    """
    stations = model.stations
    k_count = len(stations)
    heights = np.full(k_count, np.nan)
    lifts = np.full(k_count, np.nan)
    cloud = np.vstack([paint, surface]) if len(surface) else paint
    if len(paint) < ENVELOPE_MIN_POINTS or k_count < 2:
        return heights, model.normals.copy()
    voxel = float(model.voxel_m)
    half = max(float(np.median(model.half_width)), voxel)
    s = cumulative_length(stations)
    # Paint voxels of a full band (both sides of the line) over the line's length within the
    # reach (near its ends the reach runs past them).
    span = np.minimum(s + reach_m, s[-1]) - np.maximum(s - reach_m, 0.0)
    full = (2.0 * half / voxel) * (np.maximum(span, voxel) / voxel)
    # One tree: the cloud starts with the paint, so a station's paint is the head of its
    # (ascending) cloud indices, and each station's offsets are taken once.
    near_cloud = [
        np.asarray(i, dtype=np.intp)
        for i in cKDTree(cloud).query_ball_point(stations, reach_m, return_sorted=True)
    ]
    paint_count = [int(np.searchsorted(i, len(paint))) for i in near_cloud]
    near_paint = [i[:m] for i, m in zip(near_cloud, paint_count, strict=True)]
    planes = np.full((k_count, 3), np.nan)
    offsets: dict[int, FloatArray] = {}
    for k in range(k_count):
        if len(near_cloud[k]) < 3 * ENVELOPE_MIN_POINTS or paint_count[k] == 0:
            continue
        d = cloud[near_cloud[k]] - stations[k]
        values, vectors = np.linalg.eigh(np.cov(d.T))
        if np.sqrt(max(float(values[0]), 0.0)) <= 0.5 * MAX_LAYER_DEPTH_M:
            planes[k] = vectors[:, 0]
            offsets[k] = d
    normals = _outward_normals(model, planes, paint, near_paint, viewpoints)
    for k in np.flatnonzero(np.isfinite(normals[:, 0])).tolist():
        n = normals[k]
        # Across the line: the line's direction over the reach (a station's own tangent turns
        # with the line's wiggles and hooks at its ends), in the plane.
        run = stations[np.abs(s - s[k]) <= reach_m] - stations[k]
        _, _, axes = np.linalg.svd(run - run.mean(axis=0), full_matrices=False)
        t = axes[0] - float(np.dot(axes[0], n)) * n
        a = _cross(n, _unit(t))
        d = offsets[k]
        pd = d[: paint_count[k]]
        band = np.abs(pd @ a) <= half
        if band.sum() >= PERFORATED_SHARE * full[k] or not band.any():
            continue
        level = float(np.median(pd[band] @ n))
        h, u = d @ n, d @ a
        sides = [h[u < 0.0], h[u > 0.0]]
        if min(len(side) for side in sides) < ENVELOPE_MIN_POINTS:
            continue
        outer = min(float(np.quantile(side, ENVELOPE_QUANTILE)) for side in sides)
        if 0.0 < outer - level <= MAX_LAYER_DEPTH_M:
            heights[k], lifts[k] = outer, outer - level
    # A lift of a voxel or less counts only near a clear one: alone it is a surface's noise.
    clear = np.flatnonzero(lifts > voxel)
    if len(clear) == 0:
        return np.full(k_count, np.nan), model.normals.copy()
    keep = np.isfinite(lifts) & (_distance_to(s, clear) <= reach_m)
    # A station or two between lifted ones (a gate failed there) takes its nearest lifted
    # neighbour's plane, and the lift comes in gradually at either end of a lifted stretch:
    # a step a layer deep within a voxel or two would split the path (a skeleton's voxels).
    kept = np.flatnonzero(keep)
    pos = np.searchsorted(kept, np.arange(k_count))
    prev = kept[np.clip(pos - 1, 0, len(kept) - 1)]
    nxt = kept[np.clip(pos, 0, len(kept) - 1)]
    gap = ~keep & (pos > 0) & (pos < len(kept)) & (s[nxt] - s[prev] <= ENVELOPE_RAMP_M)
    for k in np.flatnonzero(gap).tolist():
        j = prev[k] if s[k] - s[prev[k]] <= s[nxt[k]] - s[k] else nxt[k]
        on_plane = stations[j] + heights[j] * normals[j] - stations[k]
        normals[k] = normals[j]
        heights[k] = float(np.dot(on_plane, normals[j]))
        lifts[k] = lifts[j]
    keep |= gap
    ramp = np.clip(_distance_to(s, np.flatnonzero(~keep)) / ENVELOPE_RAMP_M, 0.0, 1.0)
    heights = np.where(keep, heights - (1.0 - ramp) * lifts, np.nan)
    normals = np.where(keep[:, None], normals, model.normals)
    return heights, normals


def _distance_to(s: FloatArray, at: IntArray) -> FloatArray:
    """Distance (K,) along the line from each station (arc lengths ``s``) to the nearest of
    the stations ``at`` (ascending indices; inf when there are none)."""
    if len(at) == 0:
        return np.full(len(s), np.inf)
    pos = np.searchsorted(s[at], s)
    before = np.abs(s - s[at[np.clip(pos - 1, 0, len(at) - 1)]])
    after = np.abs(s[at[np.clip(pos, 0, len(at) - 1)]] - s)
    return np.asarray(np.minimum(before, after))


def _outward_normals(
    model: StrokeModel,
    planes: FloatArray,
    paint: FloatArray,
    near_paint: Any,
    viewpoints: ArrayLike,
) -> FloatArray:
    """Each station's plane normal (K, 3) turned out of the piece (NaN where no plane was fitted
    or its outside stays unknown).

    Out is the cameras' side where they looked at the surface from in front: the paint within
    the reach seen from one side (``FACING_SHARE`` of its voxels) and within 45° of the normal
    (median). A see-through piece is also seen from behind — a basket's side wall through its
    top — and at grazing angles; there the side comes from the nearest station along the line
    whose side is known (at j, normal n_j), as a closed surface has it: a face behind n_j's
    plane turns over a convex edge and faces away from j, one in front of it over a concave
    edge and faces towards j; a face in n_j's plane faces as n_j does. Without viewpoints,
    the stations' own normals decide."""
    cameras = np.asarray(viewpoints, dtype=np.float64).reshape(-1, 3)
    fitted = np.isfinite(planes[:, 0])
    out = np.full_like(planes, np.nan)
    if len(cameras) != len(paint):
        flip = np.einsum("ij,ij->i", np.nan_to_num(planes), model.normals) < 0.0
        out[fitted] = np.where(flip[:, None], -planes, planes)[fitted]
        return out
    known = np.zeros(len(planes), dtype=bool)
    for k in np.flatnonzero(fitted):
        n = planes[k]
        idx = near_paint[k]
        facing = sight_cosines(paint[idx], cameras[idx], n)
        if np.median(facing) < 0.0:
            n, facing = -n, -facing
        out[k] = n
        known[k] = np.mean(facing > 0.0) >= FACING_SHARE and np.median(facing) >= FACING_COS
    if not known.any():
        return np.full_like(planes, np.nan)
    s = cumulative_length(model.stations)
    ks = np.flatnonzero(known)
    for k in np.flatnonzero(fitted & ~known):
        j = int(ks[np.argmin(np.abs(s[ks] - s[k]))])
        oriented = orient_over_edge(
            out[k],
            model.stations[k],
            out[j],
            model.stations[j],
            margin_m=MAX_LAYER_DEPTH_M,
            same_plane_cos=FACING_COS,
        )
        out[k] = np.nan if oriented is None else oriented
    return out


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """np.cross of two 3-vectors, the same products and differences without its overhead
    (a tenth of a millisecond a call, a station's whole budget)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _unit(v: FloatArray) -> FloatArray:
    return np.asarray(v / max(float(np.linalg.norm(v)), 1e-12))


def _local_half_width(
    s: FloatArray, halves: FloatArray, both: NDArray[np.bool_], guess: float
) -> tuple[FloatArray, FloatArray]:
    """Local half width (K,) at every station — the running median of the two-edge sections'
    half widths within ± ``WIDTH_WINDOW_M`` (the whole line's where fewer than three are that
    near or they spread over less than ``WIDTH_SPAN_HALVES`` half widths ``guess`` along the
    line, the guess where there is none at all) — and its uncertainty (K,): the robust spread
    of those half widths (how much the width varies along the line), metres."""
    k = len(s)
    if not both.any():
        return np.full(k, guess), np.full(k, 0.25 * guess)
    hs, ss = halves[both], s[both]
    overall = float(np.median(hs))
    overall_sd = max(1.4826 * float(np.median(np.abs(hs - overall))), 1e-4)
    lo = np.searchsorted(ss, s - WIDTH_WINDOW_M, side="left")
    hi = np.searchsorted(ss, s + WIDTH_WINDOW_M, side="right")
    idx = lo[:, None] + np.arange(int(max((hi - lo).max(), 1)))[None, :]
    mask = idx < hi[:, None]
    table = hs[np.minimum(idx, len(hs) - 1)]
    local = _row_median(table, mask)
    local_sd = np.maximum(1.4826 * _row_median(np.abs(table - local[:, None]), mask), 1e-4)
    # A wire's crossing gives a few neighbouring sections from the same edge points, taken
    # across a tangent its own paint tilts: one measurement, however many sections.
    spread = ss[np.maximum(hi - 1, 0)] - ss[np.minimum(lo, len(ss) - 1)]
    enough = (mask.sum(axis=1) >= 3) & (spread >= WIDTH_SPAN_HALVES * guess)
    return np.where(enough, local, overall), np.where(enough, local_sd, overall_sd)


# --------------------------------------------------------------------------- confidence


#: A curve point with no paint nor surface within this many stitching voxels has nothing
#: under it: a bridged gap.
GAP_VOXELS = 1.5
#: Along the line, a curve point's support and frames are counted over ± this, metres.
SUPPORT_HALF_LENGTH_M = 0.003


def with_confidence(
    curve: Curve,
    paint_base: ArrayLike,
    observations: StrokeObservations,
    model: StrokeModel | None,
) -> Curve:
    """``curve`` with each point's confidence (:func:`curve_confidence`) and, in its ``info``,
    the stroke model's counts and the confidence's summary (``stroke_*`` keys)."""
    confidence = curve_confidence(curve.points, paint_base, observations, model)
    info = dict(curve.info)
    if model is not None:
        info.update({f"stroke_{k}": v for k, v in model.info.items()})
    info.update({f"stroke_{k}": v for k, v in confidence.summary().items()})
    return replace(curve, info=info, confidence=confidence)


def curve_confidence(
    curve_points: ArrayLike,
    paint_base: ArrayLike,
    observations: StrokeObservations,
    model: StrokeModel | None,
) -> CurveConfidence:
    """Each curve point's confidence (see :class:`CurveConfidence`).

    ``curve_points`` (K, 3) the fitted curve, ``paint_base`` (N, 3) the paint it was fitted to
    (``observations.paint_frames`` aligned with it, or empty), metres, base frame.

    σ² adds up: the stroke model's σ at the nearest section (where the centre was known); over
    an unknown stretch, the σ at its ends plus the bridge's own error growing with the distance
    d to the nearest known section, d·σ_θ + κ d²/2 (σ_θ the direction's uncertainty there, κ the
    curve's curvature: a smooth curve's chord error); the fit's departure from the centres it
    was given (lateral distance from the curve to the section's centre); and the stitching
    voxel's resolution floor (voxel/√12); and the band's thinness, (h/√3)(1 − support)² (h the
    half width: the whole band's RMS spread where none of it is painted); at most the half
    width (a long bridge is still held within the band). Without a model (no
    edges seen), σ comes from the paint's spread across the line over the square root of the
    points in a section.
    """
    curve = np.asarray(curve_points, dtype=np.float64).reshape(-1, 3)
    paint = np.asarray(paint_base, dtype=np.float64).reshape(-1, 3)
    voxel = float(observations.voxel_m)
    n = len(curve)
    s = cumulative_length(curve)
    floor = voxel / np.sqrt(12.0)
    half = _curve_half_width(curve, paint, model)
    dist, arc = arc_positions(curve, paint)
    band = dist <= half
    support = _support(s, arc[band], dist[band], half, voxel)
    frames = _frames_near(s, arc[band], observations.paint_frames, band)
    surface = np.asarray(observations.surface, dtype=np.float64).reshape(-1, 3)
    cloud = np.vstack([paint, surface]) if len(surface) else paint
    gap_distance, _ = cKDTree(cloud).query(curve, distance_upper_bound=GAP_VOXELS * voxel)
    bridged = ~np.isfinite(gap_distance)
    if model is None or not model.known.any():
        spread = float(np.sqrt(np.mean(dist[band] ** 2))) if band.any() else half
        per_section = max(len(paint) * (2.0 * SUPPORT_HALF_LENGTH_M) / max(s[-1], 1e-9), 1.0)
        sigma = np.full(n, np.hypot(spread / np.sqrt(per_section), floor))
    else:
        sigma = _model_sigma(curve, s, model, floor)
    # Thin paint says little about where the band's middle is: up to the band's RMS half
    # width (h/√3) where nothing of the band is painted, nothing where all of it is.
    sigma = np.sqrt(sigma**2 + (half / np.sqrt(3.0) * (1.0 - support) ** 2) ** 2)
    # A bridge's growth (d σ_θ + κ d²/2) is a bound for short gaps; over a long one the curve
    # is still held by the paint on both sides to within the band: at most a half width.
    sigma = np.minimum(sigma, max(half, floor))
    # Where the paint under a point is not one smooth sheet (a mesh's wires at two depths, a
    # groove the band spans), where the line lies across its depth is uncertain too: the
    # robust spread of the paint's heights about the curve there.
    if model is not None and model.known.any():
        sigma = np.hypot(sigma, _height_spread(curve, s, paint, dist, arc, band, model))
    low = support < LOW_SUPPORT
    return CurveConfidence(
        support=support,
        frames=frames,
        sigma_m=sigma,
        bridged_gap=bridged,
        low_support=low,
    )


def _curve_half_width(curve: FloatArray, paint: FloatArray, model: StrokeModel | None) -> float:
    half = None if model is None else model.edge_half_width
    return _paint_half_width(curve, paint) if half is None else half


def _height_spread(
    curve: FloatArray,
    s: FloatArray,
    paint: FloatArray,
    dist: FloatArray,
    arc: FloatArray,
    band: NDArray[np.bool_],
    model: StrokeModel,
) -> FloatArray:
    """The spread (K,) of the band's paint heights (along the nearest station's normal) within
    ± ``SUPPORT_HALF_LENGTH_M`` of each curve point — their interquartile range / 1.349, a
    Gaussian's σ, which a quarter of the paint on another level already widens — less the
    part a single noisy sheet has (the stitching voxel's quantisation): 0 on a smooth
    painted surface."""
    out = np.zeros(len(curve))
    if not band.any():
        return out
    _, station = cKDTree(model.stations).query(curve)
    order = np.argsort(arc[band], kind="stable")
    pts, pos = paint[band][order], arc[band][order]
    _, nearest = cKDTree(curve).query(pts)
    height = np.einsum("ij,ij->i", pts - curve[nearest], model.normals[station[nearest]])
    lo = np.searchsorted(pos, s - SUPPORT_HALF_LENGTH_M, side="left")
    hi = np.searchsorted(pos, s + SUPPORT_HALF_LENGTH_M, side="right")
    floor = model.voxel_m / np.sqrt(12.0)
    for i in np.flatnonzero(hi - lo >= 5):
        q25, q75 = np.percentile(height[lo[i] : hi[i]], (25.0, 75.0))
        spread = float(q75 - q25) / 1.349
        out[i] = np.sqrt(max(spread * spread - floor * floor, 0.0))
    return out


def _support(
    s: FloatArray, arc: FloatArray, dist: FloatArray, half: float, voxel: float
) -> FloatArray:
    """Share (K,) of the band cells (``voxel`` along × ``voxel`` across, both sides counted
    by distance) within ± ``SUPPORT_HALF_LENGTH_M`` of each curve point that hold paint."""
    n_across = max(int(np.ceil(half / voxel)), 1)
    rows = np.floor(arc / voxel).astype(np.int64)
    cols = np.minimum(np.floor(dist / voxel).astype(np.int64), n_across - 1)
    n_rows = int(np.ceil(s[-1] / voxel)) + 1 if len(s) else 1
    occupied = np.zeros((n_rows + 1, n_across), dtype=bool)
    inside = (rows >= 0) & (rows <= n_rows)
    occupied[rows[inside], cols[inside]] = True
    per_row = occupied.sum(axis=1).astype(np.float64)
    csum = np.concatenate([[0.0], np.cumsum(per_row)])
    reach = max(round(SUPPORT_HALF_LENGTH_M / voxel), 1)
    centre = np.clip(np.floor(s / voxel).astype(np.int64), 0, n_rows)
    lo = np.clip(centre - reach, 0, n_rows + 1)
    hi = np.clip(centre + reach + 1, 0, n_rows + 1)
    # Both sides share each distance cell: a full band fills every cell of its rows (twice over).
    filled = (csum[hi] - csum[lo]) / np.maximum((hi - lo) * n_across, 1)
    return np.asarray(np.clip(filled, 0.0, 1.0))


def _frames_near(
    s: FloatArray, arc: FloatArray, paint_frames: IntArray, band: NDArray[np.bool_]
) -> IntArray:
    """The most frames (K,) any paint voxel in the band within ± ``SUPPORT_HALF_LENGTH_M``
    of each curve point was seen by (1 per voxel when the counts are unknown)."""
    frames = np.asarray(paint_frames, dtype=np.int64)
    frames = frames[band] if len(frames) == len(band) else np.ones(int(band.sum()), np.int64)
    out = np.zeros(len(s), dtype=np.int64)
    if len(arc) == 0:
        return out
    order = np.argsort(arc, kind="stable")
    arc, frames = arc[order], frames[order]
    lo = np.searchsorted(arc, s - SUPPORT_HALF_LENGTH_M, side="left")
    hi = np.searchsorted(arc, s + SUPPORT_HALF_LENGTH_M, side="right")
    for i in np.flatnonzero(hi > lo):
        out[i] = int(frames[lo[i] : hi[i]].max())
    return out


def _model_sigma(curve: FloatArray, s: FloatArray, model: StrokeModel, floor: float) -> FloatArray:
    """σ (K,) at each curve point from the stroke model (see :func:`curve_confidence`)."""
    stations = model.stations
    _, nearest = cKDTree(stations).query(curve)
    known = model.known
    ks = np.arange(len(stations))
    # Nearest known section before and after every section, and the distance to it.
    before = np.maximum.accumulate(np.where(known, ks, -1))
    after = np.minimum.accumulate(np.where(known, ks, len(ks))[::-1])[::-1]
    d_before = np.where(before >= 0, (ks - before) * STATION_M, np.inf)
    d_after = np.where(after < len(ks), (after - ks) * STATION_M, np.inf)
    d = np.minimum(d_before, d_after)
    worst = float(np.max(model.sigma[known]))
    end_sigma = np.where(
        d_before <= d_after,
        model.sigma[np.clip(before, 0, len(ks) - 1)],
        model.sigma[np.clip(after, 0, len(ks) - 1)],
    )
    end_sigma = np.where(np.isfinite(end_sigma), end_sigma, worst)
    # The direction at a bridge's end is known to about σ over the known run behind it
    # (at most 5 cm of it counts: the line turns farther away).
    run = min(max(float(np.count_nonzero(known)) * STATION_M, 0.01), 0.05)
    sigma_theta = np.sqrt(2.0) * end_sigma / run
    kappa = _curvature(curve, s)
    dp = d[nearest]
    bridge = dp * sigma_theta[nearest] + 0.5 * kappa * dp * dp
    sigma = np.where(known[nearest], model.sigma[nearest], np.hypot(end_sigma[nearest], bridge))
    # How far the fit runs from the centre it was given (across the line).
    centre = np.where(known[nearest, None], model.centres[nearest], curve)
    departure = np.abs(np.einsum("ij,ij->i", curve - centre, model.lateral[nearest]))
    departure = moving_average(np.repeat(departure[:, None], 3, axis=1), 5)[:, 0]
    return np.asarray(np.sqrt(sigma**2 + departure**2 + floor**2))


def _curvature(curve: FloatArray, s: FloatArray) -> FloatArray:
    """|C''| (K,) of a polyline by differences over about 5 mm, 1/m."""
    if len(curve) < 5:
        return np.zeros(len(curve))
    step = max(round(0.005 / max(float(s[-1]) / (len(curve) - 1), 1e-9)), 1)
    idx = np.arange(len(curve))
    a, b = np.clip(idx - step, 0, len(curve) - 1), np.clip(idx + step, 0, len(curve) - 1)
    h1 = np.maximum(s[idx] - s[a], 1e-9)
    h2 = np.maximum(s[b] - s[idx], 1e-9)
    second = (
        2.0
        * ((curve[b] - curve[idx]) / h2[:, None] - (curve[idx] - curve[a]) / h1[:, None])
        / (h1 + h2)[:, None]
    )
    return np.asarray(np.linalg.norm(second, axis=1))
