"""The review file: one MCAP that Foxglove (or RViz via ros2 bag) shows a cut with.

``scrapcut fit --mcap`` and ``scrapcut eval --mcap`` write it. Every message is stamped at the
recording's start, so opened beside the recording the review overlays its whole timeline (not
its last frame). Coordinates are metres in the path's base frame. Topics
(:data:`REVIEW_TOPICS`; ``docs/foxglove_layout.json`` shows them all in one 3-D panel):

- ``/scrapcut/curve`` (nav_msgs/Path) — the fitted curve (one path file: ``fit``);
- ``/scrapcut/curves`` (MarkerArray) — each path file's curve, a line strip (namespace = file);
- ``/scrapcut/curve_error`` (MarkerArray) — the same curves coloured by their distance to the
  reference: green at 0, yellow at half :data:`ERROR_SCALE_M`... red at or beyond it;
- ``/scrapcut/reference_path`` (nav_msgs/Path) — the painted reference, when known;
- ``/scrapcut/torch`` (MarkerArray) — one arrow per set-point along the torch's z axis (the
  torch frame: z into the surface, x along the travel), ending at the torch tip; grey, or
  orange when the set-point is flagged;
- ``/scrapcut/flagged`` (MarkerArray) — spheres on the flagged set-points, one namespace per
  flag (``tilted``, ``collision``, ``no_surface``...);
- ``/scrapcut/cloud/paint``, ``/scrapcut/cloud/surface`` (PointCloud2) — the stitched clouds
  (``fit`` only: ``eval`` has no recording frames to stitch).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.geometry import PolylineDistance, quat_xyzw_to_matrix

FloatArray = NDArray[np.float64]

REVIEW_TOPICS = {
    "curve": "/scrapcut/curve",
    "curves": "/scrapcut/curves",
    "curve_error": "/scrapcut/curve_error",
    "reference": "/scrapcut/reference_path",
    "torch": "/scrapcut/torch",
    "flagged": "/scrapcut/flagged",
    "paint": "/scrapcut/cloud/paint",
    "surface": "/scrapcut/cloud/surface",
}
PAINT_RGB = (255, 110, 0)
SURFACE_RGB = (150, 150, 150)
#: Distance to the reference drawn red (the evaluation's coverage threshold by default).
ERROR_SCALE_M = 0.010
#: Length of a torch arrow (metres): the torch's last few centimetres, down to its tip.
TORCH_ARROW_M = 0.04
_CURVE_RGBA = (0.12, 0.47, 0.71, 1.0)
_TORCH_RGBA = (0.6, 0.6, 0.6, 1.0)
_FLAGGED_RGBA = (1.0, 0.5, 0.0, 1.0)
_FLAG_RGBA = {"tilted": (1.0, 0.8, 0.0, 1.0), "collision": (0.9, 0.1, 0.1, 1.0)}


@dataclass(frozen=True, eq=False)
class ReviewPath:
    """One path file to show.

    ``curve_points`` (N, 3) metres; ``positions`` (K, 3) torch tips and ``orientations_xyzw``
    (K, 4) torch frames of the set-points; ``flags`` their flags (K lists); ``reference``
    (M, 3) the reference this path is coloured against (default: the file's reference).
    """

    label: str
    curve_points: FloatArray
    positions: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    orientations_xyzw: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    flags: Sequence[Sequence[str]] = ()
    reference: FloatArray | None = None


def error_colours(errors_m: FloatArray, scale_m: float = ERROR_SCALE_M) -> FloatArray:
    """(N, 4) RGBA in 0-1 for distances (N,) metres: green at 0, yellow at ``scale_m / 2``,
    red at ``scale_m`` and beyond."""
    t = np.clip(np.asarray(errors_m, dtype=np.float64) / scale_m, 0.0, 1.0)
    red = np.clip(2.0 * t, 0.0, 1.0)
    green = np.clip(2.0 * (1.0 - t), 0.0, 1.0)
    return np.column_stack([red, green, np.zeros_like(t), np.ones_like(t)])


def torch_arrows(
    positions: FloatArray, orientations_xyzw: FloatArray, length_m: float = TORCH_ARROW_M
) -> tuple[FloatArray, FloatArray]:
    """Tail and head (K, 3) of each torch arrow: along the torch z axis, ending at the tip."""
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    quats = np.asarray(orientations_xyzw, dtype=np.float64).reshape(-1, 4)
    if len(pos) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    z = np.stack([quat_xyzw_to_matrix(q)[:, 2] for q in quats])
    return pos - length_m * z, pos


def write_review_mcap(
    target: str | Path,
    paths: Sequence[ReviewPath],
    *,
    frame_id: str,
    stamp_ns: int,
    reference: FloatArray | None = None,
    paint_points: FloatArray | None = None,
    surface_points: FloatArray | None = None,
    error_scale_m: float = ERROR_SCALE_M,
) -> list[str]:
    """Write the review MCAP (atomically); returns the topics written.

    ``stamp_ns`` is the recording's start (every message's stamp and log time); ``reference``
    (M, 3) metres, when known, adds the reference and the error colouring.
    """
    from scrapcut_cli.recording.messages import MarkerSpec
    from scrapcut_cli.recording.writer import McapWriter

    topics: list[str] = []
    ref = None if reference is None else np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    with McapWriter(target) as writer:
        if len(paths) == 1:
            writer.write_path(REVIEW_TOPICS["curve"], stamp_ns, frame_id, paths[0].curve_points)
            topics.append(REVIEW_TOPICS["curve"])
        curves = [
            MarkerSpec(p.label, i, "LINE_STRIP", p.curve_points, (0.002, 0.0, 0.0), _CURVE_RGBA)
            for i, p in enumerate(paths)
        ]
        writer.write_marker_array(REVIEW_TOPICS["curves"], stamp_ns, frame_id, curves)
        topics.append(REVIEW_TOPICS["curves"])
        if ref is not None and len(ref) >= 2:
            writer.write_path(REVIEW_TOPICS["reference"], stamp_ns, frame_id, ref)
            topics.append(REVIEW_TOPICS["reference"])
        coloured = []
        for i, p in enumerate(paths):
            against = ref if p.reference is None else np.asarray(p.reference).reshape(-1, 3)
            if against is None or len(against) < 2:
                continue
            errors = PolylineDistance(against).distance(p.curve_points)
            coloured.append(
                MarkerSpec(
                    p.label,
                    i,
                    "LINE_STRIP",
                    p.curve_points,
                    (0.003, 0.0, 0.0),
                    colors=error_colours(errors, error_scale_m),
                )
            )
        if coloured:
            writer.write_marker_array(REVIEW_TOPICS["curve_error"], stamp_ns, frame_id, coloured)
            topics.append(REVIEW_TOPICS["curve_error"])
        arrows: list[MarkerSpec] = []
        flagged: list[MarkerSpec] = []
        for p in paths:
            tails, heads = torch_arrows(p.positions, p.orientations_xyzw)
            for k, (tail, head) in enumerate(zip(tails, heads, strict=True)):
                rgba = _FLAGGED_RGBA if k < len(p.flags) and p.flags[k] else _TORCH_RGBA
                points = np.stack([tail, head])
                arrows.append(MarkerSpec(p.label, k, "ARROW", points, (0.002, 0.005, 0.008), rgba))
            kinds = sorted({f for names in p.flags for f in names})
            for i, kind in enumerate(kinds):
                where = [k for k, names in enumerate(p.flags) if kind in names]
                flagged.append(
                    MarkerSpec(
                        f"{p.label}/{kind}",
                        i,
                        "SPHERE_LIST",
                        np.asarray(p.positions, dtype=np.float64).reshape(-1, 3)[where],
                        (0.008, 0.008, 0.008),
                        _FLAG_RGBA.get(kind, _FLAGGED_RGBA),
                    )
                )
        writer.write_marker_array(REVIEW_TOPICS["torch"], stamp_ns, frame_id, arrows)
        writer.write_marker_array(REVIEW_TOPICS["flagged"], stamp_ns, frame_id, flagged)
        topics += [REVIEW_TOPICS["torch"], REVIEW_TOPICS["flagged"]]
        clouds = (("paint", paint_points, PAINT_RGB), ("surface", surface_points, SURFACE_RGB))
        for key, cloud, rgb in clouds:
            if cloud is None:
                continue
            pts = np.asarray(cloud, dtype=np.float64).reshape(-1, 3)
            colours = np.tile(np.array(rgb, dtype=np.uint8), (len(pts), 1))
            writer.write_pointcloud(REVIEW_TOPICS[key], stamp_ns, frame_id, pts, colours)
            topics.append(REVIEW_TOPICS[key])
    return topics
