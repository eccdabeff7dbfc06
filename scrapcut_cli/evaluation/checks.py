"""What ``scrapcut eval`` checks before and after it measures: units, overlap, set-points.

A figure computed from the wrong inputs is worse than none. The frame check lives in
:func:`~scrapcut_cli.evaluation.sources.evaluate_path_file` (paths and references in different
frames are refused); here:

- :func:`check_scale` refuses a reference (or path) that is about 1000× the other's size: a CSV
  in millimetres read as metres (a mean error of 534,406 mm is no result);
- :func:`row_warnings` names what makes a computed row suspect: almost no coverage (the wrong
  reference, frame or piece), a length ratio far from 1 (a path that stopped early or
  wandered), no set-points, flagged set-points, set-points that cover less of the line than
  the curve does.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.evaluation.metrics import PathError, SetpointError
from scrapcut_cli.geometry import PolylineDistance

#: Sizes this many times apart (either way) are a unit mistake of 1000×: millimetres read as
#: metres. A factor 250–4000 brackets 1000 by a factor 4, more than two real curves of one piece
#: ever differ (a path stopping after 1/250 of its line is a failed fit, caught by coverage).
UNIT_RATIO = (250.0, 4000.0)
#: Coverage below this share: path and reference hardly overlap.
LOW_COVERAGE = 0.1
#: A length ratio (curve / reference) outside this range: the path stopped early or wandered.
LENGTH_RATIO_RANGE = (2.0 / 3.0, 1.5)
#: Set-point coverage this much below the curve's: set-points are missing along the line.
SETPOINT_COVERAGE_GAP = 0.1


def _extent(points: NDArray[np.float64]) -> float:
    """Diagonal of the axis-aligned bounding box, metres."""
    return float(np.linalg.norm(np.ptp(points, axis=0)))


def check_scale(
    curve_points: NDArray[np.float64],
    reference_points: NDArray[np.float64],
    *,
    path_name: str,
    reference_name: str,
) -> None:
    """Refuse a path and a reference whose sizes differ by about 1000× (one is in mm).

    Both are (N, 3) float64 in what claims to be metres. The message says which one looks like
    millimetres and, as evidence, how close it lands to the other once divided by 1000.
    """
    curve_extent, ref_extent = _extent(curve_points), _extent(reference_points)
    if curve_extent <= 0.0 or ref_extent <= 0.0:
        return
    ratio = ref_extent / curve_extent
    lo, hi = UNIT_RATIO
    if lo <= ratio <= hi:
        big, small, name = reference_points, curve_points, f"reference {reference_name}"
    elif lo <= 1.0 / ratio <= hi:
        big, small, name, ratio = curve_points, reference_points, f"path {path_name}", 1.0 / ratio
    else:
        return
    evidence = ""
    scaled = big / 1000.0
    d_scaled = float(np.median(PolylineDistance(small).distance(scaled)))
    d_raw = float(np.median(PolylineDistance(small).distance(big)))
    if d_scaled < 0.1 * d_raw:
        evidence = f", and divided by 1000 it lies {1000.0 * d_scaled:.1f} mm from the other"
    raise EvaluationError(
        f"{name} looks like millimetres: it is {ratio:.0f}× the size of the other{evidence}; "
        "scrapcut reads metres (divide its coordinates by 1000)"
    )


def row_warnings(error: PathError, setpoints: SetpointError | None) -> list[str]:
    """Short sentences naming what makes a computed row suspect (empty: nothing)."""
    warnings = []
    if error.coverage < LOW_COVERAGE:
        warnings.append(
            f"coverage {100.0 * error.coverage:.0f} %: the path hardly meets the reference "
            "(wrong reference, frame or piece?)"
        )
    lo, hi = LENGTH_RATIO_RANGE
    if not lo <= error.length_ratio <= hi:
        what = "shorter" if error.length_ratio < lo else "longer"
        warnings.append(
            f"length ratio {error.length_ratio:.2f}: the path is much {what} than the reference"
        )
    if setpoints is None:
        return warnings
    if setpoints.count == 0:
        warnings.append("no set-points: the path file has a curve but nothing to cut")
        return warnings
    if setpoints.flagged_total:
        kinds = ", ".join(f"{k} {v}" for k, v in sorted(setpoints.flagged.items()))
        warnings.append(
            f"{setpoints.flagged_total} of {setpoints.count} set-points flagged ({kinds})"
        )
    if setpoints.coverage < error.coverage - SETPOINT_COVERAGE_GAP:
        warnings.append(
            f"set-points cover {100.0 * setpoints.coverage:.0f} % of the reference, the curve "
            f"{100.0 * error.coverage:.0f} %: set-points are missing along the line"
        )
    return warnings
