"""The cut of a loop: pierce, lead-in, once round, overlap past the start.

A ring round a pipe or a cut-out in a plate has no ends to start from. :func:`make_loop_path`
cuts it as a burner does:

1. set-points every ``spacing_m`` round the closed curve (the spacing adjusted to divide the
   loop evenly); normals, their gaps filled and smoothed *round* the loop (no seam), and torch
   axes as on an open path (:mod:`~scrapcut_cli.toolpath.setpoints`);
2. the start on the loop (``toolpath.start``): ``top``, the highest set-point (molten metal
   runs away from the cut below it); ``reachable``, the set-point nearest the robot's base
   (the origin of the base frame); or ``X,Y,Z`` (metres, base frame), the set-point nearest to
   it. ``top`` and ``reachable`` choose among set-points observed, with surface support and a
   free torch when there are any;
3. the pierce ``lead_in_m`` off the line, across it in the surface's tangent plane, on the
   side of the loop's inside when the loop encloses a region there (a cut-out's drop: the
   pierce mark falls in the scrap) and to the left of the cutting direction otherwise (round
   a pipe); a straight lead-in from the pierce to the start;
4. once round the loop back to the start, and ``overlap_m`` past it (rounded up to whole
   set-point spacings), so the kerf closes and the ring is severed.

Every set-point says which part it belongs to (``segments``: ``lead_in``, ``cut``,
``overlap``). Set-points on an arc no camera saw (``curve.info["unobserved_arcs_m"]``, from
:func:`~scrapcut_cli.fitting.closure.unobserved_arcs`) carry the flag ``unobserved``: their
positions come from the fitted model alone. The summary lists each such arc with its start and
end (positions on the curve and arc lengths along the path) and its length, and ``loop`` the
start, pierce point, lead-in and overlap.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.config import ToolpathConfig
from scrapcut_cli.errors import ToolpathError
from scrapcut_cli.fitting.closure import arc_mask
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.geometry import (
    closed_polyline,
    cumulative_length,
    interpolate_polyline,
    matrix_to_quat_xyzw,
)
from scrapcut_cli.toolpath.normals import (
    estimate_path_normals,
    fill_unsupported,
    smooth_along_path,
)
from scrapcut_cli.toolpath.path import CuttingPath
from scrapcut_cli.toolpath.setpoints import (
    FLAG_COLLISION,
    FLAG_NO_SURFACE,
    FLAG_TILTED,
    check_toolpath_config,
    cutting_times,
    perpendicular_to,
    points_array,
    torch_axes,
    torch_rotations,
)
from scrapcut_cli.toolpath.speeds import SpeedTable, load_speed_table

FloatArray = NDArray[np.float64]

FLAG_UNOBSERVED = "unobserved"  # on an arc no frame saw: the fitted model's guess
#: Parts of a loop's cut (``CuttingPath.segments``).
LEAD_IN, CUT, OVERLAP = "lead_in", "cut", "overlap"
#: ``toolpath.start`` words (anything else must be "X,Y,Z" in metres).
START_WORDS = ("top", "reachable")
#: A loop encloses a region on the surface when its centroid lies this far across the line at
#: the start (a share of the distance to it): a cut-out's drop, not a ring round a pipe.
INSIDE_SHARE = 0.3


def parse_start(text: str) -> str | FloatArray:
    """``"top"``, ``"reachable"``, or the (3,) point of ``"X,Y,Z"`` (metres, base frame)."""
    word = text.strip().lower()
    if word in START_WORDS:
        return word
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not np.all(np.isfinite(values)):
        raise ToolpathError(
            f"toolpath.start must be 'top', 'reachable' or X,Y,Z in metres, got {text!r}"
        )
    return np.asarray(values, dtype=np.float64)


def make_loop_path(
    curve: Curve,
    surface_base: ArrayLike,
    surface_viewpoints: ArrayLike,
    *,
    config: ToolpathConfig,
    speeds: SpeedTable | None = None,
) -> CuttingPath:
    """Torch set-points for a closed ``curve`` (see the module docstring).

    Parameters as :func:`~scrapcut_cli.toolpath.setpoints.make_cutting_path`; ``curve.closed``
    must be set.

    Returns
    -------
    CuttingPath
        From the pierce along the lead-in, once round and past the start by the overlap;
        ``segments`` names each set-point's part; ``info`` as an open path's plus ``loop``,
        ``unobserved`` and ``unobserved_arcs``.
    """
    if not curve.closed:
        raise ToolpathError("make_loop_path needs a closed curve")
    check_toolpath_config(config)
    start = parse_start(config.start)
    surface = points_array(surface_base, "surface_base")
    viewpoints = points_array(surface_viewpoints, "surface_viewpoints")
    if len(surface) != len(viewpoints) or len(surface) == 0:
        raise ToolpathError(
            f"{len(surface)} surface points and {len(viewpoints)} viewpoints: one per point, "
            "and at least one, needed"
        )
    speeds = speeds if speeds is not None else load_speed_table(config.speed_table)
    speed_m_s, pierce_s = speeds.lookup(config.material, config.thickness_mm)

    arc, points, tangents, total = sample_loop(curve.points, config.spacing_m)
    estimate = estimate_path_normals(
        points,
        surface,
        viewpoints,
        radius_m=config.normal_radius_m,
        coarse_radius_m=config.coarse_normal_radius_m,
        min_points=config.min_surface_points,
    )
    if not estimate.supported.any():
        raise ToolpathError(
            f"too few surface points for normals: no set-point of the loop has "
            f"{config.min_surface_points} within {config.normal_radius_m * 1000:g} mm; are "
            "curve and surface in the same frame? try a larger --normal-radius-mm"
        )
    normals = _round_the_loop(arc, total, estimate.normals, estimate.supported, config)
    normals = perpendicular_to(normals, tangents)
    torch = torch_axes(points, normals, tangents, surface, config)
    unobserved = arc_mask(arc, [tuple(a) for a in curve.info.get("unobserved_arcs_m", [])])

    good = ~unobserved & estimate.supported & ~torch.colliding
    i0 = start_index(start, points, good if good.any() else ~unobserved)
    n = len(arc)
    # At least the overlap asked for: whole set-point spacings, rounded up.
    overlap = (
        int(np.ceil(config.overlap_m / (total / len(arc)) - 1e-9)) if config.overlap_m > 0 else 0
    )
    order = (i0 + np.arange(n + 1 + overlap)) % n
    side = lead_in_side(points, i0, normals[i0], tangents[i0])
    pierce = points[i0] + config.lead_in_m * side
    lead = int(np.ceil(config.lead_in_m / config.spacing_m)) if config.lead_in_m > 0 else 0
    f = np.arange(lead, dtype=np.float64)[:, None] / max(lead, 1)
    lead_points = pierce + f * (points[i0] - pierce)
    lead_dir = -side if lead else tangents[i0]
    lead_tangents = np.tile(lead_dir, (lead, 1))
    lead_normals = np.tile(normals[i0], (lead, 1))
    lead_torch = torch_axes(lead_points, lead_normals, lead_tangents, surface, config)

    surface_points = np.vstack([lead_points, points[order]])
    all_normals = np.vstack([lead_normals, normals[order]])
    all_tangents = np.vstack([lead_tangents, tangents[order]])
    axes = np.vstack([lead_torch.axes, torch.axes[order]])
    tilt = np.concatenate([lead_torch.tilt_rad, torch.tilt_rad[order]])
    s = cumulative_length(surface_points)
    positions = surface_points + config.standoff_m * axes
    orientations = matrix_to_quat_xyzw(torch_rotations(axes, all_tangents))
    speed, time = cutting_times(
        s, tilt, speeds, material=config.material, thickness_mm=config.thickness_mm
    )
    segments = [LEAD_IN] * lead + [CUT] * (n + 1) + [OVERLAP] * overlap
    flags: list[list[str]] = [[] for _ in range(len(s))]
    masks = (
        (np.concatenate([np.zeros(lead, bool), ~estimate.supported[order]]), FLAG_NO_SURFACE),
        (np.concatenate([lead_torch.tilted, torch.tilted[order]]), FLAG_TILTED),
        (np.concatenate([lead_torch.colliding, torch.colliding[order]]), FLAG_COLLISION),
        (np.concatenate([np.zeros(lead, bool), unobserved[order]]), FLAG_UNOBSERVED),
    )
    for mask, name in masks:
        for i in np.flatnonzero(mask):
            flags[i].append(name)
    arcs = _arcs_along_path(curve, arc, i0, s[lead] if lead else 0.0, total)
    chart = speeds.chart(config.material)
    info: dict[str, object] = {
        "setpoints": len(s),
        "length_m": float(s[-1]),
        "spacing_actual_m": float(total / n),
        "tilted": int(sum(FLAG_TILTED in f for f in flags)),
        "collision": int(sum(FLAG_COLLISION in f for f in flags)),
        "no_surface": int(sum(FLAG_NO_SURFACE in f for f in flags)),
        "unobserved": int(sum(FLAG_UNOBSERVED in f for f in flags)),
        "unobserved_arcs": arcs,
        "line_normals": int(estimate.line_like.sum()),
        "coarse_normals": int(estimate.coarse.sum()),
        "max_tilt_used_deg": float(np.degrees(tilt.max())),
        "material": config.material,
        "fuel": chart.fuel,
        "thickness_mm": float(config.thickness_mm),
        "speed_m_s": speed_m_s,
        "pierce_s": pierce_s,
        "cut_time_s": float(time[-1]),
        "speed_table": speeds.source,
        "loop": {
            "closed": True,
            "loop_length_m": float(total),
            "start": config.start,
            "start_point": [float(v) for v in points[i0]],
            "start_on_curve_m": float(arc[i0]),
            "pierce_point": [float(v) for v in pierce],
            "lead_in_m": float(s[lead]) if lead else 0.0,
            "overlap_m": float(overlap * total / n),
        },
    }
    return CuttingPath(
        positions=positions,
        orientations_xyzw=orientations,
        normals=all_normals,
        surface_points=surface_points,
        arc_length=s,
        speed=speed,
        time=time,
        flags=flags,
        standoff_m=float(config.standoff_m),
        spacing_m=float(config.spacing_m),
        info=info,
        segments=segments,
    )


def sample_loop(
    curve_points: ArrayLike, spacing_m: float
) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """Arc lengths (N,), points (N, 3) and unit tangents (N, 3) every ~``spacing_m`` round a
    loop given by its vertices (K, 3) (the first not repeated), and the loop's length: N
    intervals of length / N (N = length / spacing rounded, at least 3); tangents are central
    differences round the loop."""
    loop = closed_polyline(points_array(curve_points, "curve points"))
    s = cumulative_length(loop)
    total = float(s[-1])
    if len(loop) < 4 or total <= 0:
        raise ToolpathError("the fitted loop has no length: nothing to cut")
    n = max(round(total / spacing_m), 3)
    arc = np.arange(n) * (total / n)
    points = interpolate_polyline(loop, arc, cumulative=s)
    d = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    tangents = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    return np.asarray(arc, dtype=np.float64), points, np.asarray(tangents), total


def start_index(start: str | FloatArray, points: FloatArray, candidates: NDArray[np.bool_]) -> int:
    """Index of the start among the loop's set-points (see the module docstring)."""
    if isinstance(start, np.ndarray):
        return int(np.argmin(np.linalg.norm(points - start, axis=1)))
    pool = np.flatnonzero(candidates) if candidates.any() else np.arange(len(points))
    if start == "top":
        return int(pool[np.argmax(points[pool, 2])])
    return int(pool[np.argmin(np.linalg.norm(points[pool], axis=1))])


def lead_in_side(
    points: FloatArray, i0: int, normal: FloatArray, tangent: FloatArray
) -> FloatArray:
    """Unit direction (3,) from the start to the pierce: across the line in the surface's
    tangent plane, towards the loop's inside when the loop encloses a region on the surface
    (its centroid lies well to one side), else to the left of the cutting direction."""
    left = np.cross(normal, tangent)
    norm = float(np.linalg.norm(left))
    if norm < 1e-9:
        return np.zeros(3)
    left /= norm
    towards = points.mean(axis=0) - points[i0]
    across = float(np.dot(towards, left))
    if abs(across) >= INSIDE_SHARE * float(np.linalg.norm(towards)) and across < 0.0:
        return np.asarray(-left)
    return np.asarray(left)


# --------------------------------------------------------------------------- helpers


def _round_the_loop(
    arc: FloatArray,
    total: float,
    normals: FloatArray,
    supported: NDArray[np.bool_],
    config: ToolpathConfig,
) -> FloatArray:
    """Gaps filled and normals smoothed along the loop as if it had no seam: the loop is laid
    out three times end to end and the middle turn kept."""
    n = len(arc)
    arc3 = np.concatenate([arc - total, arc, arc + total])
    filled = fill_unsupported(arc3, np.vstack([normals] * 3), np.concatenate([supported] * 3))
    smooth = smooth_along_path(
        arc3, filled, sigma_m=config.normal_smoothing_m, edge_angle_deg=config.edge_angle_deg
    )
    return np.asarray(smooth[n : 2 * n])


def _arcs_along_path(
    curve: Curve, arc: FloatArray, i0: int, offset: float, total: float
) -> list[dict[str, Any]]:
    """The curve's unobserved arcs as the path meets them: start and end on the curve, arc
    lengths along the path (from the pierce), length."""
    out = []
    loop = closed_polyline(curve.points)
    s = cumulative_length(loop)
    for a, b in curve.info.get("unobserved_arcs_m", []):
        length = (b - a) % total if b != a else total
        start_s = offset + (a - arc[i0]) % total
        out.append(
            {
                "start": [float(v) for v in interpolate_polyline(loop, [a], cumulative=s)[0]],
                "end": [float(v) for v in interpolate_polyline(loop, [b], cumulative=s)[0]],
                "start_s_m": float(start_s),
                "end_s_m": float(start_s + length),
                "length_m": float(length),
                "on_curve_m": [float(a), float(b)],
            }
        )
    return sorted(out, key=lambda d: d["start_s_m"])
