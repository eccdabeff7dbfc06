"""The cutting path: torch set-points along the fitted curve."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, eq=False)
class CuttingPath:
    """Torch set-points in the base frame, ordered along the curve.

    Attributes
    ----------
    positions : (N, 3) float64
        Torch tip positions, metres: the surface point plus ``standoff_m`` along the torch axis
        (the normal, or the normal tilted away from an obstacle where the flags say "tilted").
    orientations_xyzw : (N, 4) float64
        Torch orientation; its z axis points into the surface (along −normal unless tilted), x
        along the curve tangent.
    normals : (N, 3) float64
        Unit surface normals at the set-points, pointing out of the surface (towards the camera
        that observed it).
    surface_points : (N, 3) float64
        The points on the fitted curve the set-points stand off from.
    arc_length : (N,) float64
        Arc length along the curve, metres, from 0.
    speed : (N,) float64
        Torch travel speed, m/s.
    time : (N,) float64
        Time stamps, s, from the start of the pierce.
    flags : list of list of str
        Per set-point flags, e.g. ``["tilted"]``, ``["collision"]``, ``["bridged_gap"]``.
    segments : list of str
        Per set-point part of the cut: ``cut``, or on a loop ``lead_in`` (from the pierce onto
        the line) and ``overlap`` (past the start, closing the kerf). Empty: all ``cut``.
    support : (N,) float64 or None
        Share (0-1) of the stroke's band around each set-point that holds paint.
    frames : (N,) int64 or None
        How many frames saw paint there (0: none).
    sigma_m : (N,) float64 or None
        Estimated lateral uncertainty of each set-point, metres.

    The last three are None when the curve carried no confidence (``fitting.stroke``).
    """

    positions: NDArray[np.float64]
    orientations_xyzw: NDArray[np.float64]
    normals: NDArray[np.float64]
    surface_points: NDArray[np.float64]
    arc_length: NDArray[np.float64]
    speed: NDArray[np.float64]
    time: NDArray[np.float64]
    flags: list[list[str]]
    standoff_m: float
    spacing_m: float
    info: dict[str, object] = field(default_factory=dict)
    segments: list[str] = field(default_factory=list)
    support: NDArray[np.float64] | None = None
    frames: NDArray[np.int64] | None = None
    sigma_m: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def flagged(self) -> int:
        """Number of set-points carrying any flag."""
        return sum(1 for f in self.flags if f)
