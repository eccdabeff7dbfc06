"""Which stretches of the painted line some captured image really showed: the simulator's truth
of unobserved arcs (a ring's underside, paint against the floor).

Every captured image is checked with the renderer's exact knowledge: the pixels showing the
stroke itself (no overspray) whose depth survived the sensor model (grazing angles, range,
dropout) are mapped to the arc length of their foot point on the line. A stretch of line counts
as seen when one image put at least ``min_pixels`` such pixels on it per ``bin_m`` of length;
the arcs never seen, longer than ``min_arc_m``, are the truth that ``scrapcut eval`` compares
with the arcs a fit reports unobserved. Nothing here reaches a recording's frames or a planner.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.geometry import false_runs
from scrapcut_cli.sim.render import RenderedView
from scrapcut_cli.sim.surface import PaintStroke

FloatArray = NDArray[np.float64]

#: Length of a bin along the line (the pixel footprint at a wrist camera's range is 1-2 mm).
BIN_M = 0.002
#: Stroke pixels with depth an image must put in a bin for it to count as seen there (a band
#: seen at all covers a bin with several; a stray pixel at a grazing silhouette does not count).
MIN_PIXELS = 3
#: Unseen runs shorter than this are holes between pixels, not arcs.
MIN_ARC_M = 0.01


class LineVisibility:
    """Accumulates, image by image, which bins of a painted line were seen.

    Parameters
    ----------
    stroke : PaintStroke
        The stroke as painted (its ``reference`` is the painted polyline; a loop repeats its
        first point at the end).
    closed : bool
        The line is a loop: a run may wrap from its end to its start.
    """

    def __init__(
        self,
        stroke: PaintStroke,
        *,
        closed: bool,
        bin_m: float = BIN_M,
        min_pixels: int = MIN_PIXELS,
    ) -> None:
        self.stroke = stroke
        self.closed = bool(closed)
        self.bin_m = float(bin_m)
        self.min_pixels = int(min_pixels)
        self.length_m = float(np.linalg.norm(np.diff(stroke.reference, axis=0), axis=1).sum())
        self.seen = np.zeros(max(int(np.ceil(self.length_m / self.bin_m)), 1), dtype=bool)

    def add(self, rendered: RenderedView, depth_m: ArrayLike) -> None:
        """Count one image: ``rendered`` (exact) and its simulated depth (H, W), NaN invalid."""
        depth = np.asarray(depth_m).reshape(-1)
        valid = rendered.hit_stroke & np.isfinite(depth[rendered.hit_index])
        if not valid.any():
            return
        _, s = self.stroke.distance_and_arc_length(rendered.hit_points[valid])
        bins = np.clip((s / self.bin_m).astype(np.int64), 0, len(self.seen) - 1)
        counts = np.bincount(bins, minlength=len(self.seen))
        self.seen |= counts >= self.min_pixels

    def unseen_arcs(self, *, min_arc_m: float = MIN_ARC_M) -> list[tuple[float, float]]:
        """(start, end) arc lengths in metres along the line of every run of unseen bins at
        least ``min_arc_m`` long, in order; a run across a loop's start has end < start."""
        return unseen_runs(
            self.seen, self.bin_m, self.length_m, closed=self.closed, min_m=min_arc_m
        )


def unseen_runs(
    seen: NDArray[np.bool_], bin_m: float, length_m: float, *, closed: bool, min_m: float
) -> list[tuple[float, float]]:
    """Runs of False in ``seen`` (bins of ``bin_m`` along a line of ``length_m``) at least
    ``min_m`` long, as (start, end) metres; on a loop a run may wrap (end < start)."""
    n = len(seen)
    runs = []
    for a, b in false_runs(seen, closed=closed):
        if ((b - a) % n or n) * bin_m < min_m:
            continue
        runs.append((float(a * bin_m), float(min(b * bin_m, length_m))))
    return runs
