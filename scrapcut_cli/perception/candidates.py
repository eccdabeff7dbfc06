"""The marked line among the stitched paint: candidates, what each one is, which one to cut.

A stitched paint cloud of a real scene holds more than the marked line: the paint filter also
takes a crate or a traffic cone of the paint's colour lying beside the piece, an old faded mark
of a previous job, and rust as saturated as pale paint. :func:`select_line` splits the cloud
into candidates and keeps the line:

1. **Colour layers.** The voxels' saturation (their pixels' mean sRGB) is split where its
   histogram has a clear dip between two modes at least ``_MIN_MODE_GAP`` apart (fresh
   marking paint S ≈ 0.85–1 against rust or faded paint at 0.5–0.8), so a rust patch
   touching the line is not part of its candidate. Without such a dip there is one layer.
   The paint's core (within four spreads of its mode) is then set apart from voxels that mix
   the paint with a duller colour (a sprayed edge, an overspray speck on rust): those are
   never a line of their own, only the line's rim (step 5). The mode is the one of the most
   saturated candidate the scan follows, whatever its shape: heavy overspray widens the line
   past a stroke's width until its core is set apart.
2. **Candidates.** Within each layer, paint closer than ``link_m`` (measured between the
   centroids of a ``cell_m`` grid) is one candidate: a wire mesh's gaps are bridged, a crate
   beside the piece is not.
3. **Shape.** Each candidate's length is the geodesic diameter of its cell graph; its width
   twice the 90 % quantile of its points' distance to that path, and how much the width
   varies along it (per window of two widths). A closed line (a cut-out drawn round on a
   plate, a ring round a pipe seen all round) is measured along its loop instead: its
   diameter runs half way round and the other half lies far from it. Whether the paint closes
   on itself is decided as ``fit --closure`` decides it (``fitting.ordering.paint_chain``),
   only for candidates too wide for their diameter. A stroke is at least ``min_elongation``
   times as long as wide and at most ``max_width_m`` wide; boxes, cones, gloves and rusty
   areas are not.
4. **The scan.** Each frame looked along its optical axis, from the camera to the surface it
   met (its view centre; through a wire mesh that is the floor behind, so the whole sight line
   counts, not its end); a candidate's ``follow`` is the share of these sight lines passing
   within ``follow_m`` of it. The marked line is the one the scan follows. Paint farther than
   ``off_surface_m`` from every sight line was never looked at: off the scanned surface.
5. **The line's own paint.** Of the line-like candidates the scan follows (at least half as
   much as the most followed one), the most saturated sets the paint's colour; candidates
   duller than it by ``dull_margin`` of its saturation are another paint: a faded old mark if
   stroke-like, else dull paint (rust, primer). Duller voxels within ``rim_m`` of the line are
   its own thin edge (sprayed edges and JPEG's chroma subsampling desaturate it) and join
   it.
6. **The pick.** Among the line-like candidates of the paint's colour near the scan:
   ``scan`` (default) the one the scan follows, ``longest``, ``nearest-start`` (nearest to the
   first sight line, where the worker pointed the robot) or ``all``. When more than one was
   possible, a warning says so. When the scan follows paint of the line's colour that is not
   shaped like a stroke more than twice as much as every stroke, no line is picked: the
   stroke left is not what the scan followed.

Every other candidate is reported with its kind (``faded``, ``dull``, ``mixed``, ``blob``,
``off_surface``, ``other_line``, ``speck``), size, colour and position, so a user sees what was
ignored. Hand-written (numpy and scipy's KD-tree and sparse graphs): no library classifies paint
this way.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from scrapcut_cli.config import SelectionConfig, validate_section
from scrapcut_cli.errors import ConfigError, PerceptionError
from scrapcut_cli.fitting.ordering import paint_chain
from scrapcut_cli.geometry import (
    cumulative_length,
    pack_voxel_keys,
    resample_polyline,
    voxel_keys,
)
from scrapcut_cli.perception.paint import paint_core, rgb_to_hsv_deg, saturation_splits

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.intp]

PICKS = ("scan", "longest", "nearest-start", "all")
#: Kinds of candidates: the picked line(s), then the rejected ones.
KIND_LINE = "line"
KIND_OTHER_LINE = "other_line"
KIND_FADED = "faded"
KIND_DULL = "dull"
KIND_BLOB = "blob"
KIND_OFF_SURFACE = "off_surface"
KIND_MIXED = "mixed"
KIND_SPECK = "speck"
KIND_TEXT = {
    KIND_LINE: "the marked line",
    KIND_OTHER_LINE: "another stroke of the paint",
    KIND_FADED: "a stroke of duller paint (an old mark)",
    KIND_DULL: "duller paint (rust, primer, an old mark's rest)",
    KIND_BLOB: "a compact blob of the paint's colour (a crate, a cone)",
    KIND_OFF_SURFACE: "paint the scan never looked at",
    KIND_MIXED: "paint mixed with a duller colour (a thin edge, overspray on rust)",
    KIND_SPECK: "a few voxels",
}


@dataclass(frozen=True, eq=False)
class Candidate:
    """One connected piece of paint of one colour layer.

    ``points`` indexes the stitched paint cloud; lengths in metres, base frame. ``follow`` is
    the share of the scan's sight lines within ``follow_m``; ``scan_distance_m`` the distance
    to the nearest one (inf without any), ``start_distance_m`` to the first; ``hsv`` the
    median hue (degrees), saturation and value of its voxels' colours (NaN unknown).
    """

    kind: str
    points: IndexArray
    centroid: FloatArray
    length_m: float
    width_m: float
    width_variation: float
    area_m2: float
    hsv: tuple[float, float, float]
    follow: float
    scan_distance_m: float
    start_distance_m: float
    reason: str = ""

    @property
    def elongation(self) -> float:
        """Length over width (inf for a one-cell-wide line)."""
        return self.length_m / self.width_m if self.width_m > 0 else float("inf")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: kind, size, position, colour and why (millimetres for sizes)."""

        def finite(x: float, digits: int) -> float | None:
            return round(float(x), digits) if np.isfinite(x) else None

        return {
            "kind": self.kind,
            "what": KIND_TEXT[self.kind],
            "reason": self.reason,
            "points": len(self.points),
            "length_mm": round(1000.0 * self.length_m, 1),
            "width_mm": round(1000.0 * self.width_m, 1),
            "width_variation": finite(self.width_variation, 3),
            "area_cm2": round(1e4 * self.area_m2, 1),
            "position_m": [round(float(c), 4) for c in self.centroid],
            "hue_deg": finite(self.hsv[0], 1),
            "saturation": finite(self.hsv[1], 3),
            "value": finite(self.hsv[2], 3),
            "follow": round(self.follow, 3),
            "scan_distance_mm": finite(1000.0 * self.scan_distance_m, 1),
        }

    def describe(self) -> str:
        """``blob 412 pts, 310x160 mm at (0.55, -0.36, 0.08) m`` for messages."""
        x, y, z = self.centroid
        return (
            f"{self.kind} {len(self.points)} pts, {1000 * self.length_m:.0f}x"
            f"{1000 * self.width_m:.0f} mm at ({x:.2f}, {y:.2f}, {z:.2f}) m"
        )


@dataclass(frozen=True, eq=False)
class LineSelection:
    """The picked line(s) among the candidates and everything rejected.

    ``lines`` are the picked candidates (one, or every line-like one with ``pick="all"``),
    their ``points`` including the rim voxels they absorbed; ``rejected`` the rest;
    ``warnings`` one line each; ``paint_saturation`` the line's median saturation (the paint's
    own colour cluster).
    """

    lines: tuple[Candidate, ...]
    rejected: tuple[Candidate, ...]
    warnings: tuple[str, ...] = ()
    pick: str = "scan"
    layers: tuple[float, ...] = field(default_factory=tuple)
    paint_saturation: float = float("nan")

    @property
    def line(self) -> Candidate:
        """The first picked line."""
        return self.lines[0]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready report (path file ``selection``, fit's ``--json``)."""
        return {
            "pick": self.pick,
            "lines": [c.to_dict() for c in self.lines],
            "rejected": [c.to_dict() for c in self.rejected],
            "warnings": list(self.warnings),
            "saturation_splits": [round(t, 3) for t in self.layers],
            "paint_saturation": (
                round(self.paint_saturation, 3) if np.isfinite(self.paint_saturation) else None
            ),
        }


def check_selection_config(config: SelectionConfig) -> None:
    """PerceptionError naming the first selection parameter out of its range (the ranges
    declared in ``config.SelectionConfig``) or an unknown pick."""
    if config.pick not in PICKS:
        raise PerceptionError(f"unknown selection.pick {config.pick!r}; known: {', '.join(PICKS)}")
    try:
        validate_section(config, "selection")
    except ConfigError as exc:
        raise PerceptionError(str(exc)) from None


def select_line(
    points: ArrayLike,
    rgb: ArrayLike | None,
    views: ArrayLike | None,
    *,
    voxel_m: float,
    config: SelectionConfig | None = None,
) -> LineSelection:
    """Split the stitched paint into candidates and pick the marked line (module text).

    Parameters
    ----------
    points : (N, 3) float64
        Stitched paint, metres, base frame (one point per ``voxel_m`` voxel).
    rgb : (N, 3) float64 or None
        Mean sRGB in 0-1 of each point (NaN or None: unknown, one colour layer).
    views : (K, 2, 3) float64 or None
        Each frame's sight line, in scan order, base frame: (camera centre, view centre where
        its optical axis met the surface). (K, 3) view centres alone are sight lines of length
        zero.
    voxel_m : float
        The stitching voxel (the area of a point).
    config : SelectionConfig

    Raises
    ------
    PerceptionError
        No paint, or no candidate shaped like a stroke (listing what was found instead).
    """
    config = config or SelectionConfig()
    check_selection_config(config)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        raise PerceptionError("no paint to find the line in")
    colour = _hsv(rgb, len(pts))
    centres = _sight_lines(views)
    splits = saturation_splits(colour[:, 1])
    layer = np.searchsorted(np.asarray(splits), np.nan_to_num(colour[:, 1], nan=1.0))

    def describe(idx: IndexArray, *, mixed: bool = False) -> _Shape:
        return _describe(pts, colour, centres, idx, voxel_m, config, mixed=mixed)

    shapes = [
        describe(np.flatnonzero(layer == k)[part])
        for k in range(len(splits) + 1)
        for part in _components(pts[layer == k], config.link_m, config.cell_m)
    ]
    # The line's own paint: the core of its colour cluster. What of a paint-coloured candidate
    # lies below it mixes the paint with something duller (rust touching it, a blurred edge).
    reference = _colour_reference(shapes, bool(len(centres)), config)
    core = paint_core(colour[reference.points, 1])
    if np.isfinite(core):
        ref_sat = colour[reference.points, 1]
        paint_sat = float(np.median(ref_sat[ref_sat >= core]))
        dull_below = paint_sat * (1.0 - config.dull_margin)
        refined: list[_Shape] = []
        for shape in shapes:
            sat = colour[shape.points, 1]
            keep = ~(sat < core)  # NaN (unknown colour) stays
            dull = shape is not reference and not _sat(shape) >= dull_below
            if shape.mixed or dull or keep.all():
                refined.append(shape)
                continue
            for part, mixed in ((shape.points[keep], False), (shape.points[~keep], True)):
                for piece in _components(pts[part], config.link_m, config.cell_m):
                    refined.append(describe(part[piece], mixed=mixed))
        shapes = refined
    return _classify(pts, shapes, centres, config, tuple(splits), voxel_m)


# --------------------------------------------------------------------------- colour


def _hsv(rgb: ArrayLike | None, n: int) -> FloatArray:
    """(N, 3) hue in degrees, saturation and value of sRGB (N, 3) in 0-1; NaN where unknown."""
    if rgb is None:
        return np.full((n, 3), np.nan)
    c = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
    if len(c) != n:
        return np.full((n, 3), np.nan)
    known = np.isfinite(c).all(axis=1)
    out = np.full((n, 3), np.nan)
    out[known] = rgb_to_hsv_deg(255.0 * c[known])
    return out


# --------------------------------------------------------------------------- shape


def _cells(points: FloatArray, cell_m: float) -> tuple[IndexArray, FloatArray]:
    """Cell of each point (N,) and the centroid (M, 3) of each occupied ``cell_m`` cell."""
    keys = pack_voxel_keys(voxel_keys(points, cell_m))
    _, cell, counts = np.unique(keys, return_inverse=True, return_counts=True)
    cell = cell.reshape(-1)
    centroids = np.column_stack(
        [np.bincount(cell, weights=points[:, i]) / counts for i in range(3)]
    )
    return cell.astype(np.intp), centroids


def _components(points: FloatArray, link_m: float, cell_m: float) -> list[IndexArray]:
    """Indices into ``points`` of each group whose cells' centroids link within ``link_m``."""
    if len(points) == 0:
        return []
    cell, centroids = _cells(points, cell_m)
    graph = cKDTree(centroids).sparse_distance_matrix(
        cKDTree(centroids), link_m, output_type="coo_matrix"
    )
    n, label = connected_components(graph.tocsr(), directed=False)
    point_label = label[cell]
    order = np.argsort(point_label, kind="stable")
    bounds = np.searchsorted(point_label[order], np.arange(n + 1))
    return [order[bounds[k] : bounds[k + 1]] for k in range(n)]


@dataclass(frozen=True, eq=False)
class _Shape:
    points: IndexArray
    centroid: FloatArray
    length_m: float
    width_m: float
    width_variation: float
    area_m2: float
    hsv: tuple[float, float, float]
    follow: float
    scan_distance_m: float
    start_distance_m: float
    path: FloatArray
    mixed: bool = False  # of the layer mixing the paint with a duller colour


def _describe(
    pts: FloatArray,
    colour: FloatArray,
    centres: FloatArray,
    idx: IndexArray,
    voxel_m: float,
    config: SelectionConfig,
    *,
    mixed: bool = False,
) -> _Shape:
    """Size, shape, colour and relation to the scan of the candidate ``idx``."""
    p = pts[idx]
    path, length = _diameter_path(p, config.cell_m, config.link_m)
    if len(path) >= 2:
        offsets, width = _offsets(path, p)
        if length < config.min_elongation * width:
            loop = _loop_path(p, config.cell_m)
            if loop is not None:
                path, length = loop
                offsets, width = _offsets(path, p)
        variation = _width_variation(path, p, offsets, width)
    else:
        width = float(np.ptp(p, axis=0).max()) if len(p) > 1 else voxel_m
        variation = float("nan")
    width = max(width, voxel_m)
    hsv = colour[idx]
    known = np.isfinite(hsv[:, 1])
    if known.any():
        sat = float(np.median(hsv[known, 1]))
        val = float(np.median(hsv[known, 2]))
        angle = np.radians(hsv[known, 0])
        hue = float(np.degrees(np.arctan2(np.sin(angle).mean(), np.cos(angle).mean())) % 360.0)
    else:
        sat = val = hue = float("nan")
    if len(centres):
        distance = _segment_distances(centres, _cells(p, config.cell_m)[1])
        follow = float(np.mean(distance <= config.follow_m))
        scan = float(distance.min())
        start = float(distance[0])
    else:
        follow, scan, start = 0.0, float("inf"), float("inf")
    return _Shape(
        points=idx,
        centroid=p.mean(axis=0),
        length_m=length,
        width_m=width,
        width_variation=variation,
        area_m2=len(idx) * voxel_m**2,
        hsv=(hue, sat, val),
        follow=follow,
        scan_distance_m=scan,
        start_distance_m=start,
        path=path,
        mixed=mixed,
    )


def _sight_lines(views: ArrayLike | None) -> FloatArray:
    """(K, 2, 3) sight-line segments from (K, 2, 3) segments or (K, 3) points."""
    if views is None:
        return np.zeros((0, 2, 3))
    v = np.asarray(views, dtype=np.float64)
    if v.ndim == 2:
        v = np.repeat(v.reshape(-1, 1, 3), 2, axis=1)
    return v.reshape(-1, 2, 3)


def _segment_distances(segments: FloatArray, points: FloatArray) -> FloatArray:
    """For each segment (K, 2, 3), its distance to the nearest of ``points`` (M, 3)."""
    out = np.empty(len(segments))
    for k, (a, b) in enumerate(segments):
        d = b - a
        t = np.clip((points - a) @ d / max(float(d @ d), 1e-18), 0.0, 1.0)
        out[k] = float(np.sqrt(np.min(np.sum((points - a - t[:, None] * d) ** 2, axis=1))))
    return out


def _diameter_path(points: FloatArray, cell_m: float, link_m: float) -> tuple[FloatArray, float]:
    """The geodesic diameter of the candidate's cell graph (edges up to ``link_m``): its
    path through the cell centroids (K, 3) and length, metres (double sweep)."""
    _, centroids = _cells(points, cell_m)
    if len(centroids) < 2:
        return centroids, 0.0
    tree = cKDTree(centroids)
    # Neighbouring cells only, unless a gap needs the long link (a wire mesh): the path then
    # follows the shape instead of cutting across it.
    graph = tree.sparse_distance_matrix(tree, 1.8 * cell_m, output_type="coo_matrix").tocsr()
    n, _ = connected_components(graph, directed=False)
    if n > 1:
        graph = tree.sparse_distance_matrix(tree, link_m, output_type="coo_matrix").tocsr()
    first = dijkstra(graph, directed=False, indices=0)
    a = int(np.argmax(np.where(np.isfinite(first), first, -1.0)))
    dist, previous = dijkstra(graph, directed=False, indices=a, return_predecessors=True)
    b = int(np.argmax(np.where(np.isfinite(dist), dist, -1.0)))
    order = [b]
    while order[-1] != a:
        order.append(int(previous[order[-1]]))
    return centroids[order[::-1]], float(dist[b])


def _offsets(path: FloatArray, p: FloatArray) -> tuple[FloatArray, float]:
    """Each point's distance (N,) to the path (K, 3) and the width they make (twice their 90 %
    quantile), metres. The nearest point of the path resampled every millimetre: within 0.5 mm
    of the exact distance, at a fraction of an exact segment search's cost on tens of
    thousands."""
    offsets, _ = cKDTree(resample_polyline(path, 0.001)).query(p)
    return offsets, 2.0 * float(np.quantile(offsets, 0.9))


def _loop_path(points: FloatArray, cell_m: float) -> tuple[FloatArray, float] | None:
    """The closed chain (K + 1, 3; its first point repeated last) round a candidate whose paint
    closes on itself, and its length, metres; None for paint that does not (a line, a blob)."""
    chain = paint_chain(points, voxel_m=cell_m, chain_lines=False)
    if not chain.loop or len(chain.points) < 3:
        return None
    loop = np.vstack([chain.points, chain.points[:1]])
    return loop, float(cumulative_length(loop)[-1])


def _width_variation(path: FloatArray, p: FloatArray, offsets: FloatArray, width: float) -> float:
    """Coefficient of variation of the width along the path (windows of two widths, ends
    left out); NaN when fewer than three windows hold enough points."""
    s = cumulative_length(path)
    _, foot = cKDTree(path).query(p)
    arc = s[foot]
    window = max(2.0 * width, 1e-3)
    lo, hi = float(s[0]) + window, float(s[-1]) - window
    if hi - lo < 3 * window:
        return float("nan")
    index = np.floor((arc - lo) / window).astype(np.int64)
    inside = (arc >= lo) & (arc < hi)
    widths = []
    for k in np.unique(index[inside]):
        sel = inside & (index == k)
        if sel.sum() >= 10:
            widths.append(2.0 * float(np.quantile(offsets[sel], 0.9)))
    if len(widths) < 3:
        return float("nan")
    w = np.asarray(widths)
    return float(w.std() / max(w.mean(), 1e-9))


# --------------------------------------------------------------------------- the pick


def _classify(
    pts: FloatArray,
    shapes: list[_Shape],
    centres: FloatArray,
    config: SelectionConfig,
    splits: tuple[float, ...],
    voxel_m: float,
) -> LineSelection:
    """Kinds, the paint's colour, the pick (module text, steps 4-6)."""
    scanned = len(centres) > 0
    near = _line_like(shapes, scanned, config)
    reference = _reference(shapes, scanned, config)
    paint_sat = _sat(reference)
    dull_below = paint_sat * (1.0 - config.dull_margin) if np.isfinite(paint_sat) else -np.inf
    if scanned:
        _check_followed(shapes, reference, dull_below, config)
    lines = [s for s in near if not _sat(s) < dull_below]
    picked = _pick(lines, reference, config.pick)
    kinds: dict[int, tuple[str, str]] = {}
    for s in shapes:
        kinds[id(s)] = _kind(s, picked, lines, dull_below, scanned, config)
    warnings: list[str] = []
    others = [s for s in lines if s not in picked]
    if others and config.pick != "all":
        chosen = picked[0]
        warnings.append(
            f"{len(lines)} line-like candidates of the paint; picked the "
            f"{_why(config.pick)} ({1000 * chosen.length_m:.0f} mm, scan follows "
            f"{100 * chosen.follow:.0f} %), others at "
            + "; ".join(_where(s) for s in others[:3])
            + "; --pick longest|nearest-start|all to choose"
        )
    rim = _rim(pts, picked, shapes, kinds, config.rim_m, voxel_m)
    line_candidates = tuple(
        _candidate(s, KIND_LINE, f"picked: {_why(config.pick)}", extra=rim.get(id(s)))
        for s in picked
    )
    absorbed = np.concatenate(list(rim.values())) if rim else np.zeros(0, np.intp)
    rejected = tuple(
        _candidate(s, *kinds[id(s)], drop=absorbed)
        for s in sorted(shapes, key=lambda s: -len(s.points))
        if s not in picked
    )
    rejected = tuple(c for c in rejected if len(c.points))
    return LineSelection(
        lines=line_candidates,
        rejected=rejected,
        warnings=tuple(warnings),
        pick=config.pick,
        layers=splits,
        paint_saturation=paint_sat,
    )


def _line_like(shapes: list[_Shape], scanned: bool, config: SelectionConfig) -> list[_Shape]:
    """Candidates shaped like a stroke, big enough, near the scan, not mixed colour."""
    return [s for s in _near_scan(shapes, scanned, config) if _is_stroke(s, config)]


def _near_scan(shapes: list[_Shape], scanned: bool, config: SelectionConfig) -> list[_Shape]:
    """Candidates big enough, not mixed colour and (with a scan) near a sight line."""
    return [
        s
        for s in shapes
        if len(s.points) >= config.min_points
        and not s.mixed
        and (not scanned or s.scan_distance_m <= config.off_surface_m)
    ]


def _most_saturated(shapes: list[_Shape]) -> _Shape:
    """The most saturated candidate (then the most followed, the longest)."""
    return max(shapes, key=lambda s: (np.nan_to_num(_sat(s)), s.follow, s.length_m))


def _is_stroke(s: _Shape, config: SelectionConfig) -> bool:
    """Shaped like a stroke: long for its width, and no wider than a stroke."""
    return s.length_m >= config.min_elongation * s.width_m and s.width_m <= config.max_width_m


def _reference(shapes: list[_Shape], scanned: bool, config: SelectionConfig) -> _Shape:
    """The line-like candidate that sets the paint's colour: of those the scan follows at
    least half as much as the most followed one, the most saturated (fresh marking paint is
    the most saturated thing on a piece; rust around a line is followed as much as the line);
    without a scan, the most saturated one. Raises when there is none."""
    near = _line_like(shapes, scanned, config)
    if not near:
        raise PerceptionError(_no_line_message(shapes, scanned, config))
    if scanned:
        most = max(s.follow for s in near)
        near = [s for s in near if s.follow >= _FOLLOWED * most]
    return _most_saturated(near)


#: A candidate the scan follows this share as much as the most followed one is followed too.
_FOLLOWED = 0.5


def _check_followed(
    shapes: list[_Shape], reference: _Shape, dull_below: float, config: SelectionConfig
) -> None:
    """PerceptionError when paint of the line's colour that is not shaped like a stroke is
    followed by the scan more than twice as much as the line: the scan followed that paint, so
    a stroke the scan hardly looked at is not the marked line (a line the filter merged with
    overspray or another paint past a stroke's width; cutting the small stroke would cut
    elsewhere)."""
    rivals = [
        s
        for s in _near_scan(shapes, True, config)
        if not _sat(s) < dull_below and not _is_stroke(s, config)
    ]
    if not rivals:
        return
    rival = max(rivals, key=lambda s: s.follow)
    if reference.follow >= _FOLLOWED * rival.follow:
        return
    raise PerceptionError(
        f"the scan follows paint that is not shaped like a stroke (at {_where(rival)} long, "
        f"{1000 * rival.width_m:.0f} mm wide, {100 * rival.follow:.0f} % of the sight lines) "
        f"more than the most stroke-like candidate (at {_where(reference)} long, "
        f"{100 * reference.follow:.0f} %); a stroke is {config.min_elongation:g}x as long as "
        f"wide and at most {1000 * config.max_width_m:.0f} mm wide (selection.min_elongation, "
        "selection.max_width_m in --config); look at the mask with scrapcut filter --overlay"
    )


def _colour_reference(shapes: list[_Shape], scanned: bool, config: SelectionConfig) -> _Shape:
    """The candidate whose colour is the line's paint, before the paint's core is set apart:
    of the candidates the scan follows (at least half as much as the most followed one, any
    shape), the most saturated; a line-like one among them instead when it is not duller than
    that by ``dull_margin``. Heavy overspray or a sprayed edge widens the line past a stroke's
    width until its core is set apart, so its shape cannot decide yet; without a scan, or
    when nothing near the scan is big enough, as :func:`_reference`."""
    near = _near_scan(shapes, True, config)
    most = max((s.follow for s in near), default=0.0)
    if not scanned or most <= 0.0:
        return _reference(shapes, scanned, config)
    followed = [s for s in near if s.follow >= _FOLLOWED * most]
    top = _most_saturated(followed)
    strokes = [s for s in followed if _is_stroke(s, config)]
    if strokes:
        best = _most_saturated(strokes)
        if not _sat(best) < _sat(top) * (1.0 - config.dull_margin):
            return best
    return top


def _sat(s: _Shape) -> float:
    return s.hsv[1]


def _why(pick: str) -> str:
    return {
        "scan": "one the scan follows",
        "longest": "longest",
        "nearest-start": "one nearest to where the scan started",
        "all": "every line-like candidate",
    }[pick]


def _where(s: _Shape) -> str:
    x, y, z = s.centroid
    return f"({x:.2f}, {y:.2f}, {z:.2f}) m, {1000 * s.length_m:.0f} mm"


def _pick(lines: list[_Shape], reference: _Shape, pick: str) -> list[_Shape]:
    if pick == "all":
        return sorted(lines, key=lambda s: (-s.follow, -s.length_m))
    if pick == "longest":
        return [max(lines, key=lambda s: s.length_m)]
    if pick == "nearest-start":
        return [min(lines, key=lambda s: (s.start_distance_m, -s.length_m))]
    return [reference]


def _kind(
    s: _Shape,
    picked: list[_Shape],
    lines: list[_Shape],
    dull_below: float,
    scanned: bool,
    config: SelectionConfig,
) -> tuple[str, str]:
    """(kind, reason) of a candidate that was not picked."""
    if s in picked:
        return KIND_LINE, ""
    if len(s.points) < config.min_points:
        return KIND_SPECK, f"fewer than {config.min_points} voxels"
    if s.mixed:
        return KIND_MIXED, (
            f"saturation {_sat(s):.2f} between the paint's and a duller colour's: paint on "
            "rust, a thin edge, overspray"
        )
    is_stroke = _is_stroke(s, config)
    if _sat(s) < dull_below:
        kind = KIND_FADED if is_stroke else KIND_DULL
        return kind, f"saturation {_sat(s):.2f} below the line's paint ({dull_below:.2f})"
    if not is_stroke:
        return KIND_BLOB, (
            f"not a stroke: {1000 * s.length_m:.0f} mm long, {1000 * s.width_m:.0f} mm wide "
            f"(a stroke is {config.min_elongation:g}x as long as wide, at most "
            f"{1000 * config.max_width_m:.0f} mm)"
        )
    if scanned and s.scan_distance_m > config.off_surface_m:
        return KIND_OFF_SURFACE, (
            f"{1000 * s.scan_distance_m:.0f} mm from every sight line of the scan "
            f"(> {1000 * config.off_surface_m:.0f})"
        )
    return KIND_OTHER_LINE, f"not picked (--pick {config.pick})"


def _rim(
    pts: FloatArray,
    picked: list[_Shape],
    shapes: list[_Shape],
    kinds: dict[int, tuple[str, str]],
    rim_m: float,
    voxel_m: float,
) -> dict[int, IndexArray]:
    """For each picked line, the duller voxels within ``rim_m`` of its solid paint (its own
    thin edge). Solid: a voxel with at least ``_SOLID`` line voxels within ``_SOLID_RADIUS``
    voxels' reach, so overspray specks beside the line do not pull in the rust around them."""
    if rim_m <= 0:
        return {}
    donors = [
        s for s in shapes if kinds[id(s)][0] in (KIND_FADED, KIND_DULL, KIND_MIXED, KIND_SPECK)
    ]
    if not donors:
        return {}
    pool = np.concatenate([s.points for s in donors])
    out: dict[int, IndexArray] = {}
    taken = np.zeros(len(pool), dtype=bool)
    for s in picked:
        line = pts[s.points]
        tree = cKDTree(line)
        solid = tree.query_ball_point(line, _SOLID_RADIUS * voxel_m, return_length=True) >= _SOLID
        if not solid.any():
            continue
        distance, _ = cKDTree(line[solid]).query(pts[pool], distance_upper_bound=rim_m)
        near = np.isfinite(distance) & ~taken
        taken |= near
        out[id(s)] = pool[near]
    return out


#: A line voxel is solid paint with this many line voxels within this many voxel sizes (the
#: inside of a band has ~19 within 2.5, its edge ~10, a speck a few).
_SOLID = 8
_SOLID_RADIUS = 2.5


def _candidate(
    s: _Shape,
    kind: str,
    reason: str,
    *,
    extra: IndexArray | None = None,
    drop: IndexArray | None = None,
) -> Candidate:
    points = s.points
    if extra is not None and len(extra):
        points = np.union1d(points, extra)
    if drop is not None and len(drop):
        points = np.setdiff1d(points, drop, assume_unique=False)
    return Candidate(
        kind=kind,
        points=np.asarray(points, dtype=np.intp),
        centroid=s.centroid,
        length_m=s.length_m,
        width_m=s.width_m,
        width_variation=s.width_variation,
        area_m2=s.area_m2,
        hsv=s.hsv,
        follow=s.follow,
        scan_distance_m=s.scan_distance_m,
        start_distance_m=s.start_distance_m,
        reason=reason,
    )


def _no_line_message(shapes: list[_Shape], scanned: bool, config: SelectionConfig) -> str:
    big = sorted(shapes, key=lambda s: -len(s.points))[:3]
    found = "; ".join(
        f"{len(s.points)} voxels, {1000 * s.length_m:.0f}x{1000 * s.width_m:.0f} mm, "
        f"{1000 * s.scan_distance_m:.0f} mm from the scan"
        if scanned
        else f"{len(s.points)} voxels, {1000 * s.length_m:.0f}x{1000 * s.width_m:.0f} mm"
        for s in big
    )
    return (
        f"no stroke-like paint near the scan among {len(shapes)} candidate(s) (largest: "
        f"{found}); a stroke is {config.min_elongation:g}x as long as wide and within "
        f"{1000 * config.off_surface_m:.0f} mm of a sight line (selection.min_elongation, "
        "selection.off_surface_m in --config)"
    )
