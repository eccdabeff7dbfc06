"""The calibration's result: the mount to use, the estimate behind it, and how sure it is.

:class:`Calibration` turns a solver :class:`~scrapcut_cli.calibration.solver.Solution` into the
decision a user acts on: when every determined parameter's correction is within three standard
deviations (or within ``consistent_*``, below what moves a path measurably) of zero, the
published calibration is consistent and stays as it is; otherwise the corrected mount replaces
it. :meth:`Calibration.to_dict` is ``scrapcut calibrate --json`` (fixed keys, docs/design.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.calibration.residuals import PARAMETERS, corrected_mount
from scrapcut_cli.calibration.solver import Solution
from scrapcut_cli.config import CalibrationConfig
from scrapcut_cli.geometry import matrix_to_quat_xyzw
from scrapcut_cli.recording.mount import CameraMount

FloatArray = NDArray[np.float64]

SCHEMA = "scrapcut.calibration/v1"
CONSISTENT = "published calibration is consistent"
NOT_DETERMINED = (
    "this scan cannot check the calibration (see unobservable); the published one is kept"
)


@dataclass(frozen=True)
class Link:
    """One static TF link between the moving frame and the camera: T_parent_child."""

    parent: str
    child: str
    T: FloatArray


@dataclass(frozen=True, eq=False)
class Calibration:
    """The outcome of a self-calibration.

    Attributes
    ----------
    published : CameraMount
        What the recording publishes.
    estimated : CameraMount
        The published mount with the whole estimated correction.
    consistent : bool
        True when the correction is not significant: ``mount`` is then ``published``.
    solution : Solution
        The solver's figures (correction, sigma, observability, residuals).
    links : tuple of Link
        The static links from the moving frame to the camera, as published.
    source : dict
        ``path`` and frame counts of the recording it came from.
    time_s : float
        Wall time of the whole calibration.
    without_views : Solution, optional
        The same solve without an exploration's calibration views (what they narrowed).
    """

    published: CameraMount
    estimated: CameraMount
    consistent: bool
    solution: Solution
    links: tuple[Link, ...] = ()
    source: dict[str, Any] = field(default_factory=dict)
    time_s: float = 0.0
    without_views: Solution | None = None

    @staticmethod
    def decide(
        solution: Solution,
        published: CameraMount,
        config: CalibrationConfig,
        *,
        links: tuple[Link, ...] = (),
        source: dict[str, Any] | None = None,
        time_s: float = 0.0,
        without_views: Solution | None = None,
    ) -> Calibration:
        """Apply the consistency rule of the module docstring to ``solution``."""
        floor = np.array(
            [1000.0 * config.consistent_translation_m] * 3
            + [config.consistent_rotation_deg] * 3
            + [1000.0 * config.consistent_time_offset_s]
        )
        x = solution.correction
        sigma = np.nan_to_num(solution.sigma, nan=0.0)
        significant = solution.observable & (np.abs(x) > np.maximum(3.0 * sigma, floor))
        return Calibration(
            published=published,
            estimated=corrected_mount(published, x),
            consistent=not bool(significant.any()),
            solution=solution,
            links=links,
            source=dict(source or {}),
            time_s=time_s,
            without_views=without_views,
        )

    @property
    def mount(self) -> CameraMount:
        """The mount to pose frames with: the estimate, or the published one if consistent."""
        return self.published if self.consistent else self.estimated

    @property
    def verdict(self) -> str:
        """One line for the user."""
        if not self.solution.observable.any():
            return NOT_DETERMINED
        if self.consistent:
            if self.solution.observable.all():
                return CONSISTENT
            return f"{CONSISTENT} in the directions this scan determines"
        x = self.solution.correction
        t = float(np.linalg.norm(x[:3]))
        r = float(np.linalg.norm(x[3:6]))
        return (
            f"published calibration is off by {t:.2f} mm and {r:.3f} deg, clock by "
            f"{x[6]:+.1f} ms: corrected"
        )

    def link_corrections(self) -> list[tuple[Link, FloatArray]]:
        """Each static link with the value it would need to carry the whole correction alone.

        The mount is A @ L @ B around a link L; the corrected mount M' = M @ C needs
        L' = L @ B @ C @ B⁻¹ (the other links unchanged).
        """
        C = np.linalg.inv(self.published.T_moving_camera) @ self.mount.T_moving_camera
        out = []
        below = np.eye(4)
        for link in reversed(self.links):
            B = below
            out.append((link, link.T @ B @ C @ np.linalg.inv(B)))
            below = link.T @ below
        return out[::-1]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the keys of ``scrapcut calibrate --json`` (docs/design.md) and more."""
        s = self.solution
        x = s.correction
        sigma = [None if not math.isfinite(v) else float(v) for v in s.sigma]
        mount = self.mount
        return {
            "schema": SCHEMA,
            "source": dict(self.source),
            "moving_frame": mount.moving_frame,
            "camera_frame": mount.camera_frame,
            "T_moving_camera": transform_dict(mount.T_moving_camera),
            "published_T_moving_camera": transform_dict(self.published.T_moving_camera),
            "time_offset_s": mount.time_offset_s,
            "published_time_offset_s": self.published.time_offset_s,
            "consistent": self.consistent,
            "verdict": self.verdict,
            "correction": {
                "frame": "camera optical frame (x right, y down, z along the optical axis)",
                "translation_m": [float(v) / 1000.0 for v in x[:3]],
                "rotation_deg": [float(v) for v in x[3:6]],
                "time_offset_s": float(x[6]) / 1000.0,
            },
            "sigma": {
                "translation_m": [None if v is None else v / 1000.0 for v in sigma[:3]],
                "rotation_deg": sigma[3:6],
                "time_offset_s": None if sigma[6] is None else sigma[6] / 1000.0,
            },
            "observable": {
                "translation": [bool(v) for v in s.observable[:3]],
                "rotation": [bool(v) for v in s.observable[3:6]],
                "time_offset": bool(s.observable[6]),
            },
            "unobservable": [
                {
                    "what": d.what,
                    "why": d.why,
                    "sigma": d.sigma if d.sigma < 1e6 else None,
                    "direction": dict(zip(PARAMETERS, d.vector, strict=True)),
                }
                for d in s.unobservable
            ],
            "residual_before_mm": _finite(s.residual_before_mm["all"]),
            "residual_after_mm": _finite(s.residual_after_mm["all"]),
            "residuals_mm": {
                kind: {
                    "before": _finite(s.residual_before_mm[kind]),
                    "after": _finite(s.residual_after_mm[kind]),
                }
                for kind in ("surface", "edge")
            },
            "frames_used": s.frames,
            "pairs": s.pairs,
            "residuals": s.residuals,
            "iterations": s.iterations,
            "eigen": s.eigen,
            "time_s": self.time_s,
            "calibration_views": self.views_effect(),
        }

    def views_effect(self) -> dict[str, Any] | None:
        """What an exploration's calibration views changed: sigma without them, its ratio to
        sigma with them per parameter (> 1: narrowed), parameters they made observable."""
        w = self.without_views
        if w is None:
            return None
        s = self.solution
        ratio = [
            None if not (math.isfinite(a) and math.isfinite(b) and b > 0) else float(a / b)
            for a, b in zip(w.sigma, s.sigma, strict=True)
        ]
        return {
            "frames": self.source.get("calibration_view_frames"),
            "sigma_without": [None if not math.isfinite(v) else float(v) for v in w.sigma],
            "sigma_ratio": ratio,
            "observable_without": [bool(v) for v in w.observable],
            "became_observable": [
                p
                for p, a, b in zip(PARAMETERS, w.observable, s.observable, strict=True)
                if b and not a
            ],
            "units": list(PARAMETERS),
        }


def calibration_record(calibration: Calibration) -> dict[str, Any]:
    """What a path file keeps of a self-calibration (``calibration`` key)."""
    data = calibration.to_dict()
    keep = (
        "schema",
        "moving_frame",
        "camera_frame",
        "T_moving_camera",
        "published_T_moving_camera",
        "time_offset_s",
        "consistent",
        "verdict",
        "correction",
        "sigma",
        "observable",
        "residual_before_mm",
        "residual_after_mm",
        "frames_used",
    )
    record = {"origin": "self-calibrate", **{k: data[k] for k in keep}}
    record["unobservable"] = [{"what": u["what"], "why": u["why"]} for u in data["unobservable"]]
    return record


def transform_dict(T: FloatArray) -> dict[str, list[float]]:
    """``{"translation_m": [3], "rotation_xyzw": [4]}`` of a (4, 4) transform."""
    M = np.asarray(T, dtype=np.float64)
    return {
        "translation_m": [float(v) for v in M[:3, 3]],
        "rotation_xyzw": [float(v) for v in matrix_to_quat_xyzw(M[:3, :3])],
    }


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None
