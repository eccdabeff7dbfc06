"""Curve types shared by the fitters, the tool path, exploration and evaluation."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline

from scrapcut_cli.geometry import (
    closed_polyline,
    polyline_length,
    resample_loop,
    resample_polyline,
)


@dataclass(frozen=True, eq=False)
class NurbsModel:
    """A NURBS curve: degree p, knot vector (M + p + 1,), control points (M, 3), weights (M,).

    Parameter domain is ``[knots[p], knots[-p-1]]`` (``[0, 1]`` for the fitter's clamped knots).

    ``periodic``: a closed curve in the unclamped (wrapped) form that exchange formats such as
    geomdl read as an ordinary NURBS: uniform knots over [0, 1] whose domain is the middle
    part, and the first p control points (and weights) repeated at the end, so the curve
    returns to its start with matching derivatives. Evaluation wraps the parameter round the
    domain.
    """

    degree: int
    knots: NDArray[np.float64]
    control_points: NDArray[np.float64]
    weights: NDArray[np.float64]
    periodic: bool = False

    def __post_init__(self) -> None:
        m = len(self.control_points)
        if len(self.knots) != m + self.degree + 1:
            raise ValueError(
                f"a degree-{self.degree} NURBS with {m} control points needs "
                f"{m + self.degree + 1} knots, got {len(self.knots)}"
            )
        if len(self.weights) != m:
            raise ValueError(f"{m} control points but {len(self.weights)} weights")

    @property
    def domain(self) -> tuple[float, float]:
        return float(self.knots[self.degree]), float(self.knots[-self.degree - 1])

    def evaluate(self, t: ArrayLike) -> NDArray[np.float64]:
        """Points (N, 3) at parameters ``t`` (N,), clamped to the domain (wrapped round it when
        ``periodic``)."""
        lo, hi = self.domain
        tt = np.asarray(t, dtype=np.float64)
        tt = lo + np.mod(tt - lo, hi - lo) if self.periodic else np.clip(tt, lo, hi)
        w = np.asarray(self.weights, dtype=np.float64)
        homogeneous = np.column_stack([self.control_points * w[:, None], w])
        spline = BSpline(self.knots, homogeneous, self.degree, extrapolate=False)
        h = np.atleast_2d(spline(tt))
        return np.asarray(h[:, :3] / h[:, 3:4])

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "degree": int(self.degree),
            "knots": [float(k) for k in self.knots],
            "control_points": [[float(c) for c in p] for p in self.control_points],
            "weights": [float(w) for w in self.weights],
        }
        if self.periodic:
            out["periodic"] = True
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> NurbsModel:
        return cls(
            degree=int(data["degree"]),
            knots=np.asarray(data["knots"], dtype=np.float64),
            control_points=np.asarray(data["control_points"], dtype=np.float64).reshape(-1, 3),
            weights=np.asarray(data["weights"], dtype=np.float64),
            periodic=bool(data.get("periodic", False)),
        )


#: Below this share of its band painted a curve point has low support.
LOW_SUPPORT = 0.5


@dataclass(frozen=True, eq=False)
class CurveConfidence:
    """How sure each point of a fitted curve is (one value per ``Curve.points`` row).

    ``support`` (K,) share 0-1 of the stroke's band around the point that holds paint;
    ``frames`` (K,) the most frames that saw a paint voxel there (0: none); ``sigma_m`` (K,)
    lateral uncertainty, metres; ``bridged_gap`` (K,) no surface under the point (a hole,
    a gap in a mesh: the curve bridges it); ``low_support`` (K,) support below
    :data:`LOW_SUPPORT`.
    """

    support: NDArray[np.float64]
    frames: NDArray[np.int64]
    sigma_m: NDArray[np.float64]
    bridged_gap: NDArray[np.bool_]
    low_support: NDArray[np.bool_]

    def reversed(self) -> CurveConfidence:
        return CurveConfidence(
            self.support[::-1].copy(),
            self.frames[::-1].copy(),
            self.sigma_m[::-1].copy(),
            self.bridged_gap[::-1].copy(),
            self.low_support[::-1].copy(),
        )

    def at(self, index: ArrayLike) -> CurveConfidence:
        """The confidence of the curve points ``index`` (M,)."""
        i = np.asarray(index, dtype=np.int64)
        return CurveConfidence(
            self.support[i], self.frames[i], self.sigma_m[i], self.bridged_gap[i],
            self.low_support[i],
        )  # fmt: skip

    def summary(self) -> dict[str, Any]:
        """Counts and σ figures for ``Curve.info`` and reports."""
        n = max(len(self.sigma_m), 1)
        return {
            "sigma_median_m": float(np.median(self.sigma_m)) if len(self.sigma_m) else 0.0,
            "sigma_max_m": float(np.max(self.sigma_m)) if len(self.sigma_m) else 0.0,
            "bridged_gap_share": float(np.count_nonzero(self.bridged_gap) / n),
            "low_support_share": float(np.count_nonzero(self.low_support) / n),
            "support_mean": float(np.mean(self.support)) if len(self.support) else 0.0,
        }


#: ``Curve.info`` entries listed from the curve's start to its end (skeleton vertices, the
#: per-end trims and shapes): :meth:`Curve.reversed` reverses them.
ORDERED_INFO = ("skeleton_points", "end_trim_m", "end_shape")


@dataclass(frozen=True, eq=False)
class Curve:
    """An ordered polyline (N, 3) in the base frame plus the fitting method's own model.

    ``points`` are evenly resampled along the curve (spacing ``spacing_m``). ``nurbs`` is set by
    the NURBS fitter; ``info`` carries method diagnostics (residuals, iterations, pieces...).
    ``closed``: the curve is a loop; its last point joins its first, which ``points`` does not
    repeat (:attr:`polyline` does). ``confidence`` says how sure each point is (None when not
    estimated).
    """

    points: NDArray[np.float64]
    method: str
    nurbs: NurbsModel | None = None
    spacing_m: float = 0.001
    info: dict[str, Any] = field(default_factory=dict)
    closed: bool = False
    confidence: CurveConfidence | None = None

    @property
    def polyline(self) -> NDArray[np.float64]:
        """The curve as a polyline from its start to its end: ``points``, with the first point
        repeated at the end when ``closed`` (N + 1, 3)."""
        return closed_polyline(self.points) if self.closed else self.points

    @property
    def length(self) -> float:
        """Arc length in metres (a loop's closing segment included)."""
        return polyline_length(self.polyline)

    def sample(self, spacing: float) -> NDArray[np.float64]:
        """Evenly spaced points (K, 3), ``spacing`` metres apart, both ends included (a loop's
        start is not repeated)."""
        if self.closed:
            return resample_loop(self.points, spacing)
        return resample_polyline(self.points, spacing)

    def reversed(self) -> Curve:
        """The same curve traversed the other way: the model, and the ``info`` entries listed
        from the start to the end (:data:`ORDERED_INFO`, the per-end trims) turn with it."""
        nurbs = None
        if self.nurbs is not None:
            n = self.nurbs
            lo, hi = n.domain
            nurbs = NurbsModel(
                degree=n.degree,
                knots=(lo + hi) - n.knots[::-1],
                control_points=n.control_points[::-1].copy(),
                weights=n.weights[::-1].copy(),
                periodic=n.periodic,
            )
        info = dict(self.info)
        for key in ORDERED_INFO:
            if isinstance(info.get(key), list | tuple):
                info[key] = list(info[key])[::-1]
        if self.closed and isinstance(info.get("unobserved_arcs_m"), list):
            # Arc lengths from the start (kept) run the other way round the loop.
            total = self.length
            info["unobserved_arcs_m"] = sorted(
                [(total - b) % total, (total - a) % total] for a, b in info["unobserved_arcs_m"]
            )
        if "end_trim_start_m" in info and "end_trim_end_m" in info:
            info["end_trim_start_m"], info["end_trim_end_m"] = (
                info["end_trim_end_m"],
                info["end_trim_start_m"],
            )
        # A loop reversed keeps its start point.
        points = np.roll(self.points[::-1], 1, axis=0) if self.closed else self.points[::-1]
        return Curve(
            points=points.copy(),
            method=self.method,
            nurbs=nurbs,
            spacing_m=self.spacing_m,
            info=info,
            closed=self.closed,
            confidence=None if self.confidence is None else self.confidence.reversed(),
        )
