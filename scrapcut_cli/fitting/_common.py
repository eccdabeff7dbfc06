"""What both fitters share: input checks, a canonical frame, orientation, the data's extent.

Rigid-motion invariance. Both fitters work in a *canonical frame* of the input cloud (origin at
the centroid, axes along the principal directions with signs fixed by the third moments), so
a rotated and translated cloud produces the same canonical coordinates up to round-off and the
same sequence of discrete decisions (voxel keys, knot insertions, iteration counts). Results are
mapped back to the base frame at the end. Without it, the skeleton's voxel grid would change
with the object's pose, and the NURBS fit could stop one iteration earlier or later.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.errors import FittingError
from scrapcut_cli.geometry import (
    cumulative_length,
    interpolate_polyline,
    resample_polyline,
)

FloatArray = NDArray[np.float64]


def as_points(points_base: ArrayLike, *, minimum: int, what: str) -> FloatArray:
    """The cloud as a fresh (N, 3) float64 array; one-line FittingError when unusable."""
    pts = np.array(points_base, dtype=np.float64, copy=True)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise FittingError(f"{what}: points must be an (N, 3) array, got shape {pts.shape}")
    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        raise FittingError(
            f"{what}: {int((~finite).sum())} of {len(pts)} points are NaN or infinite"
        )
    if len(pts) < minimum:
        raise FittingError(f"{what}: need at least {minimum} points, got {len(pts)}")
    if float(np.ptp(pts, axis=0).max()) <= 1e-9:
        raise FittingError(f"{what}: all {len(pts)} points coincide; nothing to fit")
    return pts


def check_numbers(
    config: object,
    where: str,
    *,
    positive: tuple[str, ...] = (),
    non_negative: tuple[str, ...] = (),
) -> None:
    """One-line FittingError naming the first option of config section ``where`` that is not a
    finite number > 0 (``positive``) or >= 0 (``non_negative``): NaN and infinity included."""
    for names, above, words in ((positive, False, "> 0"), (non_negative, True, ">= 0")):
        for name in names:
            value = getattr(config, name)
            if not (np.isfinite(value) and (value >= 0.0 if above else value > 0.0)):
                raise FittingError(f"{where}.{name} must be a finite number {words}, got {value}")


@dataclass(frozen=True)
class CanonicalFrame:
    """``local = (base - origin) @ axes``; ``axes`` (3, 3) columns are the principal directions
    (largest variance first), right-handed; ``origin`` (3,) is the centroid, metres."""

    origin: FloatArray
    axes: FloatArray

    @classmethod
    def of(cls, points_base: FloatArray) -> CanonicalFrame:
        origin = points_base.mean(axis=0)
        centred = points_base - origin
        _, vectors = np.linalg.eigh(centred.T @ centred)
        axes = vectors[:, ::-1].copy()
        # Eigenvector signs are arbitrary; fix them by the sign of the third moment (the side
        # the cloud is skewed to), which turns with the cloud.
        for k in range(2):
            third = float(np.sum((centred @ axes[:, k]) ** 3))
            if third < 0.0:
                axes[:, k] = -axes[:, k]
        axes[:, 2] = np.cross(axes[:, 0], axes[:, 1])
        return cls(origin=origin, axes=axes)

    def to_local(self, points_base: FloatArray) -> FloatArray:
        return np.asarray((points_base - self.origin) @ self.axes)

    def to_base(self, points_local: FloatArray) -> FloatArray:
        return np.asarray(points_local @ self.axes.T + self.origin)


def canonical_order(points_local: FloatArray) -> NDArray[np.int64]:
    """A permutation sorting points by canonical x (then y, z): the same points in any input
    order give the same array, so reversing the input order changes nothing but the direction."""
    return np.lexsort((points_local[:, 2], points_local[:, 1], points_local[:, 0]))


def follows_input_order(positions: FloatArray) -> bool:
    """Whether the curve runs with the input order: ``positions`` (N,) is each input point's
    position along the curve (parameter or arc length), in input order.

    A stitched cloud is accumulated frame by frame, so its order follows the scan; the curve is
    oriented along it (reversing the input reverses the curve).
    """
    index = np.arange(len(positions), dtype=np.float64)
    index -= index.mean()
    return float(np.dot(index, positions - positions.mean())) >= 0.0


def moving_average(points: FloatArray, window: int) -> FloatArray:
    """Centred moving average of an ordered polyline (K, 3); the window shrinks at the ends so
    the end points stay put. ``window`` is an odd number of vertices (1: unchanged)."""
    half = max(int(window) // 2, 0)
    k = len(points)
    if half == 0 or k < 3:
        return points.copy()
    idx = np.arange(k)
    reach = np.minimum(np.minimum(idx, k - 1 - idx), half)
    csum = np.vstack([np.zeros((1, 3)), np.cumsum(points, axis=0)])
    lo = idx - reach
    hi = idx + reach + 1
    mean = (csum[hi] - csum[lo]) / (hi - lo)[:, None]
    return np.asarray(np.where((reach == 0)[:, None], points, mean))


def arc_positions(
    polyline: FloatArray, points: FloatArray, *, step: float = 0.0005
) -> tuple[FloatArray, FloatArray]:
    """Distance (N,) from each point to an ordered polyline (K, 3) and the arc length (N,) of
    its nearest point, both to within ``step / 2`` metres.

    The polyline is resampled every ``step`` and the nearest sample found with a KD-tree:
    several times faster than the exact segment search of ``geometry.PolylineDistance`` on
    thousands of points, and exact enough for ordering points and placing ends.
    """
    dense = resample_polyline(polyline, step)
    s = cumulative_length(dense)
    dist, nearest = cKDTree(dense).query(points)
    return np.asarray(dist, dtype=np.float64), np.asarray(s[nearest])


def band_fill(polyline: FloatArray, points: FloatArray, *, cell_m: float = 0.004) -> float:
    """Share (0-1) of the painted band around an ordered polyline that holds paint.

    The band is measured in (arc length, distance from the curve) cells of ``cell_m``, out to
    the distance 90 % of the points lie within (the band's half width) and away from the ends
    by that much (round caps). A sprayed stroke fills it (about 0.9-1.0); paint that landed
    only on the wires of a mesh fills a fifth of it. A line thinner than a cell counts as full.
    """
    # Nearest vertex of the curve resampled every half millimetre: arc length within 0.25 mm
    # and distance within far less, at a tenth of the cost of exact point-to-segment queries.
    dense = resample_polyline(polyline, 0.0005)
    distance, nearest = cKDTree(dense).query(points)
    s = cumulative_length(dense)[nearest]
    half = float(np.quantile(distance, 0.9))
    if half < cell_m:
        return 1.0
    lo, hi = float(s.min()) + half, float(s.max()) - half
    if hi - lo < 2.0 * cell_m:
        lo, hi = float(s.min()), float(s.max())
    keep = (s >= lo) & (s <= hi) & (distance <= half)
    cells = np.unique(
        np.column_stack([np.floor((s[keep] - lo) / cell_m), np.floor(distance[keep] / cell_m)]),
        axis=0,
    )
    total = int(np.ceil((hi - lo) / cell_m)) * int(np.ceil(half / cell_m))
    return float(min(len(cells) / max(total, 1), 1.0))


def corner_indices(
    polyline: FloatArray, *, reach: float, angle: float, concentration: float = 0.75
) -> NDArray[np.int64]:
    """Vertices of an ordered polyline (K, 3) where it turns sharply: by at least ``angle``
    (radians) between the directions ``reach`` metres before and after, and by at least
    ``concentration`` times as much as within twice the reach (a corner; an arc keeps turning).
    Picked sharpest first, at least two reaches apart and one reach from either end; returned
    in order along the polyline.
    """
    s = cumulative_length(polyline)
    n = len(polyline)
    if n < 3 or s[-1] <= 2.0 * reach:
        return np.zeros(0, dtype=np.int64)

    def direction(at: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        # Chord over one reach centred on arc length ``at``: robust to vertex-level noise. A
        # chord cut short by the polyline's end is flagged.
        a = interpolate_polyline(polyline, at - 0.5 * reach, cumulative=s)
        b = interpolate_polyline(polyline, at + 0.5 * reach, cumulative=s)
        d = b - a
        n = np.linalg.norm(d, axis=1, keepdims=True)
        return np.asarray(d / np.maximum(n, 1e-12)), np.asarray(n[:, 0] < 0.25 * reach)

    def turning(gap: float) -> FloatArray:
        (before, short_b), (after, short_a) = direction(s - gap), direction(s + gap)
        cos = np.einsum("ij,ij->i", before, after)
        # Unknown beyond an end: assume the most turning, so nothing counts as concentrated.
        return np.asarray(np.where(short_b | short_a, np.pi, np.arccos(np.clip(cos, -1.0, 1.0))))

    near, far = turning(reach), turning(2.0 * reach)
    inside = (s >= reach) & (s <= s[-1] - reach)
    # A sharp corner turns fully over a plateau a reach wide; the turning at a quarter of the
    # reach breaks the tie towards its middle.
    score = near + 0.01 * turning(0.25 * reach)
    score = np.where(inside & (near >= angle) & (near >= concentration * far), score, 0.0)
    picked: list[int] = []
    order = np.argsort(-score, kind="stable")
    for i in order[score[order] > 0.0]:
        if all(abs(s[i] - s[j]) >= 2.0 * reach for j in picked):
            picked.append(int(i))
    return np.asarray(sorted(picked), dtype=np.int64)


def data_extent(
    polyline: FloatArray,
    points: FloatArray,
    *,
    quantile: float,
    radius: float,
    reach: float = 0.05,
    span: float = 0.01,
) -> tuple[float, float]:
    """Where the data starts and ends along an ordered polyline (K, 3), as arc lengths.

    The polyline is extended straight by ``reach`` metres along its end tangents, the points
    within ``radius`` of it are projected on it, and the ``quantile`` and ``1 - quantile``
    arc-length quantiles are returned relative to the original start (so the start may be
    negative and the end beyond the polyline's length). End tangents are chords over ``span``.
    A curve ending there neither stops short of the painted end nor overshoots it; the
    quantile ignores a few stray points.
    """
    length = float(cumulative_length(polyline)[-1])
    dist, arc = extended_positions(polyline, points, reach=reach, span=span)
    return extent_of(arc[dist <= radius], quantile=quantile, length=length)


def extent_of(positions: FloatArray, *, quantile: float, length: float) -> tuple[float, float]:
    """The ``quantile`` and ``1 - quantile`` arc positions (N,) of the points near a polyline
    of ``length`` metres (``(0, length)`` with fewer than two points): see
    :func:`data_extent`."""
    if len(positions) < 2:
        return 0.0, float(length)
    # The empirical quantile (no interpolation): a cloud given twice over ends at the same place.
    lo, hi = np.quantile(positions, [quantile, 1.0 - quantile], method="inverted_cdf")
    return float(lo), float(hi)


def extended_positions(
    polyline: FloatArray, points: FloatArray, *, reach: float = 0.05, span: float = 0.01
) -> tuple[FloatArray, FloatArray]:
    """Distance (N,) from each point to an ordered polyline (K, 3) extended straight by
    ``reach`` metres along its end directions (chords over ``span``), and the arc length (N,)
    of its nearest point relative to the polyline's own start (negative before it, beyond the
    length after it): a paint point beyond an end of the curve still gets its lateral offset
    and how far out it lies."""
    dist, arc = arc_positions(extended_polyline(polyline, reach=reach, span=span), points)
    return dist, np.asarray(arc - reach)


def extended_polyline(polyline: FloatArray, *, reach: float, span: float = 0.01) -> FloatArray:
    """The polyline (K, 3) with a straight piece of ``reach`` metres added at each end along
    its end direction (a chord over ``span``): (K + 2, 3)."""
    s = cumulative_length(polyline)
    t0 = _end_direction(polyline, s, start=True, span=span)
    t1 = _end_direction(polyline, s, start=False, span=span)
    return np.vstack([polyline[:1] + reach * t0, polyline, polyline[-1:] + reach * t1])


def clip_to_extent(
    polyline: FloatArray, start: float, end: float, *, span: float = 0.01
) -> FloatArray:
    """The polyline (K, 3) cut or extended straight along its end directions (chords over
    ``span``) so that it runs from arc length ``start`` to ``end`` (see :func:`data_extent`)."""
    s = cumulative_length(polyline)
    length = float(s[-1])
    keep = (s > max(start, 0.0)) & (s < min(end, length))
    head = (
        polyline[:1] - start * _end_direction(polyline, s, start=True, span=span)
        if start <= 0.0
        else interpolate_polyline(polyline, [start], cumulative=s)
    )
    tail = (
        polyline[-1:] + (end - length) * _end_direction(polyline, s, start=False, span=span)
        if end >= length
        else interpolate_polyline(polyline, [end], cumulative=s)
    )
    parts = [head, polyline[keep], tail]
    if start < 0.0:
        parts.insert(1, polyline[:1])
    if end > length:
        parts.insert(-1, polyline[-1:])
    out = np.vstack(parts)
    step = np.linalg.norm(np.diff(out, axis=0), axis=1)
    return np.asarray(out[np.concatenate([[True], step > 1e-12])])


def _end_direction(polyline: FloatArray, s: FloatArray, *, start: bool, span: float) -> FloatArray:
    """Unit direction pointing out of the polyline at one end, from a chord of ``span`` metres."""
    length = float(s[-1])
    reach = min(span, 0.5 * length)
    if start:
        inner = polyline[min(int(np.searchsorted(s, reach)), len(polyline) - 1)]
        d = polyline[0] - inner
    else:
        inner = polyline[max(int(np.searchsorted(s, length - reach)) - 1, 0)]
        d = polyline[-1] - inner
    n = float(np.linalg.norm(d))
    if n <= 0.0:
        d = polyline[0] - polyline[1] if start else polyline[-1] - polyline[-2]
        n = float(np.linalg.norm(d)) or 1.0
    return np.asarray(d / n)
