"""Start and finish the way a cutter does: at an edge where the line reaches one.

Oxy-fuel cutters start at an edge whenever they can: piercing takes the chart's pierce time
and wears the nozzle, while at an edge the torch preheats the corner and cuts straight in.
At the far end a line that reaches an edge is cut out past it (run-out), so the piece is
severed; a line that stops on the surface starts with a pierce and stops where it ends.

:func:`cut_ends` decides each end from the observed surface cloud (the stitched surface band
and paint, what the camera saw). In a corridor along the line's tangent past the curve's end
(``corridor_m`` to either side, within ``corridor_m`` of the tangent plane), the cloud is
binned every ``BIN_M`` outwards; the surface ends at the first run of two empty bins. The
paint itself reaches ``paint_past_m`` past the curve's end (the fitter's end trim: the curve
ends at the centre of a spray stroke's round cap, or at a square end's edge). Then:

- the surface ends within ``gap_m`` of where the paint ends: the line reaches an **edge**;
- the surface goes on at least ``probe_m`` past the paint: the line ends **on the surface**;
- the surface ends between the two: on the surface, short of an edge (reported);
- fewer than ``MIN_INSIDE_POINTS`` points in the corridor just inside the end: **not
  observed**, so no edge is assumed (a pierce is always possible; an edge start on solid
  plate is not).

An edge is recognised only where the camera looked past the end (explore mode's look-past
views do; a sweep's last view normally does): where it did not, the cloud ends there too and
the end would look like an edge. The summary reports the distances so this can be checked.

If only the far end reaches an edge, the cut is reversed (start at the edge, no pierce at
all); if both do, it starts at one and runs out past the other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: Bin length of the corridor along the tangent: the stitched surface band's voxel (4 mm).
BIN_M = 0.004
#: Points needed in the corridor's last 12 mm inside the end for the end to count as observed.
MIN_INSIDE_POINTS = 3
_INSIDE_M = 0.012

EDGE = "edge"
PIERCE = "pierce"
RUN_OUT = "run_out"
STOP = "stop"


@dataclass(frozen=True)
class EndEvidence:
    """What the cloud shows past one end of the curve.

    ``kind`` is ``edge``, ``surface`` or ``not_observed``; distances in metres from the curve's
    end along its tangent: ``paint_past_m`` (where the paint ends), ``surface_past_m`` (where
    the observed surface ends; None if it goes on beyond the probe); ``inside_points`` counts
    the corridor's points just inside the end.
    """

    kind: str
    paint_past_m: float
    surface_past_m: float | None
    inside_points: int

    def reason(self) -> str:
        paint = f"{1000 * self.paint_past_m:.0f} mm"
        if self.kind == "not_observed":
            return f"surface at the end not observed ({self.inside_points} points): no edge assumed"
        if self.surface_past_m is None:
            return f"surface seen beyond the paint end (which is {paint} past the curve)"
        surface = f"{1000 * self.surface_past_m:.0f} mm"
        if self.kind == EDGE:
            return f"edge: the surface ends {surface} past the curve end, the paint {paint}"
        return f"surface ends {surface} past the curve end, the paint already {paint}: no edge"


@dataclass(frozen=True)
class CutEndsDecision:
    """How the cut starts (``edge`` | ``pierce``) and finishes (``run_out`` | ``stop``), whether
    the curve is cut backwards, and the evidence at the curve's first and last point."""

    start: str
    finish: str
    reversed: bool
    first: EndEvidence
    last: EndEvidence

    def to_info(self) -> dict[str, Any]:
        """The path summary's ``ends`` entry (in cutting order)."""
        start, finish = (self.last, self.first) if self.reversed else (self.first, self.last)
        return {
            "start": {"kind": self.start, "reason": start.reason(), **_numbers(start)},
            "finish": {"kind": self.finish, "reason": finish.reason(), **_numbers(finish)},
            "reversed": self.reversed,
        }


def _numbers(e: EndEvidence) -> dict[str, Any]:
    return {
        "evidence": e.kind,
        "paint_past_m": e.paint_past_m,
        "surface_past_m": e.surface_past_m,
        "inside_points": e.inside_points,
    }


def end_evidence(
    end_point: ArrayLike,
    outward: ArrayLike,
    normal: ArrayLike,
    cloud_base: ArrayLike,
    *,
    paint_past_m: float,
    gap_m: float,
    probe_m: float,
    corridor_m: float,
) -> EndEvidence:
    """Evidence past one end: ``end_point`` (3,) on the surface, ``outward`` (3,) unit tangent
    pointing away from the curve, ``normal`` (3,) unit surface normal, ``cloud_base`` (M, 3)
    the observed cloud; metres, base frame."""
    e = np.asarray(end_point, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    d = np.asarray(outward, dtype=np.float64)
    d = d - np.dot(d, n) * n
    d /= max(float(np.linalg.norm(d)), 1e-12)
    w = np.cross(n, d)
    rel = np.asarray(cloud_base, dtype=np.float64).reshape(-1, 3) - e
    along, across, height = rel @ d, rel @ w, rel @ n
    corridor = (np.abs(across) <= corridor_m) & (np.abs(height) <= corridor_m)
    paint = max(float(paint_past_m), 0.0)
    inside = int(np.count_nonzero(corridor & (along <= 0.0) & (along > -_INSIDE_M)))
    if inside < MIN_INSIDE_POINTS:
        return EndEvidence("not_observed", paint, None, inside)
    reach = paint + probe_m
    nbins = int(np.ceil(reach / BIN_M))
    a = along[corridor & (along > 0.0) & (along <= nbins * BIN_M)]
    counts = np.bincount((a / BIN_M).astype(np.intp), minlength=nbins)[:nbins]
    empty = counts == 0
    runs = np.flatnonzero(empty[:-1] & empty[1:]) if nbins > 1 else np.zeros(0, dtype=np.intp)
    if len(runs) == 0:
        return EndEvidence("surface", paint, None, inside)
    surface_past = float(runs[0] * BIN_M)
    kind = EDGE if surface_past <= paint + gap_m else "surface"
    return EndEvidence(kind, paint, surface_past, inside)


def cut_ends(
    curve_points: ArrayLike,
    normals_at_ends: tuple[ArrayLike, ArrayLike],
    cloud_base: ArrayLike,
    *,
    paint_past_m: tuple[float, float],
    gap_m: float,
    probe_m: float,
    corridor_m: float,
) -> CutEndsDecision:
    """Decide how the cut of the curve ``curve_points`` (K, 3) starts and finishes.

    ``normals_at_ends``: unit surface normals (3,) at the first and last point;
    ``paint_past_m``: how far the paint reaches past the first and last point (the fitter's
    end trims). See the module docstring.
    """
    pts = np.asarray(curve_points, dtype=np.float64)
    chord = BIN_M * 2

    def outward(at_end: bool) -> FloatArray:
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        if at_end:
            k = int(np.searchsorted(s, s[-1] - chord))
            return np.asarray(pts[-1] - pts[min(k, len(pts) - 2)])
        k = int(np.searchsorted(s, chord))
        return np.asarray(pts[0] - pts[max(k, 1)])

    args = dict(gap_m=gap_m, probe_m=probe_m, corridor_m=corridor_m)
    first = end_evidence(
        pts[0], outward(False), normals_at_ends[0], cloud_base, paint_past_m=paint_past_m[0], **args
    )
    last = end_evidence(
        pts[-1], outward(True), normals_at_ends[1], cloud_base, paint_past_m=paint_past_m[1], **args
    )
    a, b = first.kind == EDGE, last.kind == EDGE
    if b and not a:
        return CutEndsDecision(EDGE, STOP, True, first, last)
    return CutEndsDecision(
        EDGE if a else PIERCE, RUN_OUT if (a and b) else STOP, False, first, last
    )
