"""From a fitted curve and the observed surface to torch set-points: the tool-path recipe.

The paper: "collision free set-points at a desired cutting distance, where the cutting torch is
always perpendicular to the object surface", converted to a trajectory by speed limits from a
look-up table of the scrap's properties. :func:`make_cutting_path` does it in this order:

1. set-points every ``spacing_m`` of arc length along the curve (the spacing is adjusted to
   divide the length evenly, within half a spacing over the whole curve);
2. surface normals from the observed surface around each set-point
   (:mod:`~scrapcut_cli.toolpath.normals`: face-aware local planes, a coarser radius where the
   surface is rough such as a wire mesh), gaps filled along the path, edge-aware smoothing,
   then made perpendicular to the curve's tangent (the curve lies on the surface);
3. torch axes: the normal, tilted within ``max_tilt_deg`` where the torch body would hit the
   observed cloud (:mod:`~scrapcut_cli.toolpath.collision`);
4. torch poses: z into the surface (−axis), x along the curve tangent, tip at
   surface point + standoff · axis;
5. speeds and time stamps from the cutting chart (:mod:`~scrapcut_cli.toolpath.speeds`), with
   the pierce dwell at the start;
6. how the cut starts and finishes (:mod:`~scrapcut_cli.toolpath.ends`): at an edge the line
   reaches (preheat there, no pierce; the path is cut backwards when only its far end reaches
   one) and with a run-out past a far edge; the summary's ``ends`` says what and why;
7. each set-point's confidence from the curve's (``Curve.confidence``): support, frames, σ,
   and the flags ``bridged_gap`` (no surface under it) and ``low_support``.

A closed curve (a ring, a cut-out) is cut by :mod:`~scrapcut_cli.toolpath.loop` instead: a
pierce and lead-in, once round, an overlap past the start (no edge start, no run-out).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.config import ToolpathConfig
from scrapcut_cli.errors import ToolpathError
from scrapcut_cli.fitting.curve import Curve, CurveConfidence
from scrapcut_cli.geometry import cumulative_length, interpolate_polyline, matrix_to_quat_xyzw
from scrapcut_cli.toolpath.collision import TorchAxes, choose_torch_axes
from scrapcut_cli.toolpath.ends import CutEndsDecision, cut_ends
from scrapcut_cli.toolpath.normals import (
    estimate_path_normals,
    fill_unsupported,
    smooth_along_path,
)
from scrapcut_cli.toolpath.path import CuttingPath
from scrapcut_cli.toolpath.speeds import SpeedTable, load_speed_table

FloatArray = NDArray[np.float64]

#: Flags a set-point can carry (path file ``flags``).
FLAG_TILTED = "tilted"  # the perpendicular torch collided; a tilted one is free
FLAG_COLLISION = "collision"  # no torch axis within the tilt bound is free
FLAG_NO_SURFACE = "no_surface"  # too few surface points around it; normal interpolated
FLAG_BRIDGED_GAP = "bridged_gap"  # no surface under it: the curve bridges a hole or a gap
FLAG_LOW_SUPPORT = "low_support"  # little paint around it (fitting.curve.LOW_SUPPORT)


def make_cutting_path(
    curve: Curve,
    surface_base: ArrayLike,
    surface_viewpoints: ArrayLike,
    *,
    config: ToolpathConfig,
    speeds: SpeedTable | None = None,
) -> CuttingPath:
    """Torch set-points along ``curve``, perpendicular to the observed surface.

    Parameters
    ----------
    curve : Curve
        The fitted curve; ``curve.points`` (K, 3) float64, metres, base frame, on the surface.
    surface_base : (M, 3) float64, metres, base frame
        The observed surface for normals and collisions: the stitched surface band plus the
        stitched paint (paint lies on the surface too).
    surface_viewpoints : (M, 3) float64, metres, base frame
        Camera centre that observed each surface point; normals are oriented towards it.
    config : ToolpathConfig
        Spacing, standoff, normal radius, torch body, tilt bound, material and thickness.
    speeds : SpeedTable, optional
        Cutting chart; default ``config.speed_table`` or the bundled oxy-fuel table.

    Returns
    -------
    CuttingPath
        Set-points in cutting order (along the curve, or against it when only its far end
        reaches an edge); ``info`` counts flags, holds the timing figures and the ``ends``.
    """
    if curve.closed:
        from scrapcut_cli.toolpath.loop import make_loop_path

        return make_loop_path(curve, surface_base, surface_viewpoints, config=config, speeds=speeds)
    return _cutting_path(curve, surface_base, surface_viewpoints, config=config, speeds=speeds)


def _cutting_path(
    curve: Curve,
    surface_base: ArrayLike,
    surface_viewpoints: ArrayLike,
    *,
    config: ToolpathConfig,
    speeds: SpeedTable | None,
    ends: CutEndsDecision | None = None,
) -> CuttingPath:
    check_toolpath_config(config)
    surface = _points(surface_base, "surface_base")
    viewpoints = _points(surface_viewpoints, "surface_viewpoints")
    if len(surface) != len(viewpoints):
        raise ToolpathError(
            f"{len(surface)} surface points but {len(viewpoints)} viewpoints; one per point needed"
        )
    if len(surface) == 0:
        raise ToolpathError("the surface cloud is empty: no normals or collisions can be computed")
    if speeds is None:
        speeds = load_speed_table(config.speed_table)
    # Look the material up first: a typo should fail before any geometry is computed.
    speed_m_s, pierce_s = speeds.lookup(config.material, config.thickness_mm)

    arc, surface_points, tangents = sample_setpoints(curve.points, config.spacing_m)

    estimate = estimate_path_normals(
        surface_points,
        surface,
        viewpoints,
        radius_m=config.normal_radius_m,
        coarse_radius_m=config.coarse_normal_radius_m,
        min_points=config.min_surface_points,
    )
    if not estimate.supported.any():
        nearest = float(np.min(np.linalg.norm(surface[:, None] - surface_points[None, :1], axis=2)))
        raise ToolpathError(
            f"too few surface points for normals: no set-point has {config.min_surface_points} "
            f"within {config.normal_radius_m * 1000:g} mm (nearest point {nearest * 1000:.0f} mm "
            "from the curve's start); are curve and surface in the same frame? try a larger "
            "--normal-radius-mm"
        )
    normals = fill_unsupported(arc, estimate.normals, estimate.supported)
    normals = smooth_along_path(
        arc, normals, sigma_m=config.normal_smoothing_m, edge_angle_deg=config.edge_angle_deg
    )
    normals = perpendicular_to(normals, tangents)
    if config.edge_start and ends is None:
        trims = (
            float(curve.info.get("end_trim_start_m") or 0.0),
            float(curve.info.get("end_trim_end_m") or 0.0),
        )
        ends = cut_ends(
            curve.points,
            (normals[0], normals[-1]),
            surface,
            paint_past_m=trims,
            gap_m=config.edge_gap_m,
            probe_m=config.edge_probe_m,
            corridor_m=config.edge_corridor_m,
        )
        if ends.reversed:
            return _cutting_path(
                curve.reversed(),
                surface,
                viewpoints,
                config=config,
                speeds=speeds,
                ends=ends,
            )

    torch = torch_axes(surface_points, normals, tangents, surface, config)
    positions = surface_points + config.standoff_m * torch.axes
    orientations = matrix_to_quat_xyzw(torch_rotations(torch.axes, tangents))

    speed, time = cutting_times(
        arc, torch.tilt_rad, speeds, material=config.material, thickness_mm=config.thickness_mm
    )

    confidence = setpoint_confidence(curve, arc)
    flags: list[list[str]] = [[] for _ in range(len(arc))]
    for mask, name in (
        (~estimate.supported, FLAG_NO_SURFACE),
        (torch.tilted, FLAG_TILTED),
        (torch.colliding, FLAG_COLLISION),
        (confidence.bridged_gap if confidence else np.zeros(len(arc), bool), FLAG_BRIDGED_GAP),
        (confidence.low_support if confidence else np.zeros(len(arc), bool), FLAG_LOW_SUPPORT),
    ):
        for i in np.flatnonzero(mask):
            flags[i].append(name)

    chart = speeds.chart(config.material)
    info: dict[str, object] = {
        "setpoints": len(arc),
        "length_m": float(arc[-1]),
        "spacing_actual_m": float(arc[1] - arc[0]) if len(arc) > 1 else 0.0,
        "tilted": int(torch.tilted.sum()),
        "collision": int(torch.colliding.sum()),
        "no_surface": int((~estimate.supported).sum()),
        "line_normals": int(estimate.line_like.sum()),
        "coarse_normals": int(estimate.coarse.sum()),
        "max_tilt_used_deg": float(np.degrees(torch.tilt_rad.max())),
        **_confidence_summary(confidence),
        "material": config.material,
        "fuel": chart.fuel,
        "thickness_mm": float(config.thickness_mm),
        "speed_m_s": speed_m_s,
        "pierce_s": pierce_s,
        "cut_time_s": float(time[-1]),
        "speed_table": speeds.source,
    }
    if ends is not None:
        # The chart's pierce time is also the edge preheat (the bundled chart says so for thick
        # plate; it lists no separate preheat), so the dwell is the same either way.
        info["ends"] = ends.to_info()
        info["dwell_s"] = float(time[0])
    return CuttingPath(
        positions=positions,
        orientations_xyzw=orientations,
        normals=normals,
        surface_points=surface_points,
        arc_length=arc,
        speed=speed,
        time=time,
        flags=flags,
        standoff_m=float(config.standoff_m),
        spacing_m=float(config.spacing_m),
        info=info,
        support=None if confidence is None else confidence.support,
        frames=None if confidence is None else confidence.frames,
        sigma_m=None if confidence is None else confidence.sigma_m,
    )


def setpoint_confidence(curve: Curve, arc_length: ArrayLike) -> CurveConfidence | None:
    """The curve's confidence at set-points (arc lengths (N,) along ``curve.points``, metres):
    support and σ interpolated, frames and flags of the nearest curve point; None when the
    curve has none."""
    conf = curve.confidence
    if conf is None or len(conf.sigma_m) != len(curve.points):
        return None
    s = cumulative_length(curve.points)
    arc = np.asarray(arc_length, dtype=np.float64)
    nearest = np.clip(np.searchsorted(s, arc), 1, len(s) - 1)
    nearest = np.where(arc - s[nearest - 1] < s[nearest] - arc, nearest - 1, nearest)
    picked = conf.at(nearest)
    return CurveConfidence(
        support=np.interp(arc, s, conf.support),
        frames=picked.frames,
        sigma_m=np.interp(arc, s, conf.sigma_m),
        bridged_gap=picked.bridged_gap,
        low_support=picked.low_support,
    )


def _confidence_summary(confidence: CurveConfidence | None) -> dict[str, object]:
    """Set-point counts of the confidence flags and σ figures for the path's summary."""
    if confidence is None:
        return {}
    return {
        "bridged_gap": int(np.count_nonzero(confidence.bridged_gap)),
        "low_support": int(np.count_nonzero(confidence.low_support)),
        "sigma_median_m": float(np.median(confidence.sigma_m)),
        "sigma_max_m": float(np.max(confidence.sigma_m)),
    }


def sample_setpoints(
    curve_points: ArrayLike, spacing_m: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Set-point arc lengths (N,), points (N, 3) and unit tangents (N, 3) along a polyline.

    ``curve_points`` : (K, 3) float64, metres, ordered. The number of intervals is the length
    divided by ``spacing_m``, rounded, so the actual spacing is within half a spacing spread
    over the whole curve (within 5 % once the curve is 10 spacings long). Tangents are
    differences over ± one spacing, so the fitted polyline's small kinks do not jitter them.
    """
    pts = _points(curve_points, "curve points")
    s = cumulative_length(pts)
    if len(pts) < 2 or s[-1] <= 0:
        raise ToolpathError("the fitted curve has no length: nothing to cut")
    total = float(s[-1])
    intervals = max(round(total / spacing_m), 1)
    arc = np.linspace(0.0, total, intervals + 1)
    points = interpolate_polyline(pts, arc, cumulative=s)
    # Second-order differences: central inside, one-sided (3 points) at the ends, so the end
    # tangents of a turning curve are not a chord's half-step behind.
    derivative = np.gradient(points, arc, axis=0, edge_order=2 if len(arc) > 2 else 1)
    tangents = derivative / np.maximum(np.linalg.norm(derivative, axis=1, keepdims=True), 1e-12)
    return arc, points, tangents


def perpendicular_to(normals: FloatArray, tangents: FloatArray) -> FloatArray:
    """Unit normals (N, 3) with their component along the unit tangents (N, 3) removed.

    The curve lies on the surface, so the true normal is perpendicular to its tangent; what
    the estimate has along the tangent is error (a slope of the neighbourhood's plane), and
    removing it makes the torch exactly perpendicular to the cut direction. Rows where the
    normal is (nearly) parallel to the tangent are kept as they are.
    """
    along = np.einsum("ij,ij->i", normals, tangents)
    out = normals - along[:, None] * tangents
    norm = np.linalg.norm(out, axis=1)
    ok = norm > 0.1
    out[ok] /= norm[ok, None]
    out[~ok] = normals[~ok]
    return out


def torch_rotations(axes: FloatArray, tangents: FloatArray) -> FloatArray:
    """Torch orientations (N, 3, 3), columns x, y, z: z = −axis, x = tangent made orthogonal.

    ``axes`` (N, 3) point from the surface to the torch; ``tangents`` (N, 3) along the cut.
    Where the tangent is parallel to the axis, x falls back to a fixed perpendicular direction.
    """
    z = -np.asarray(axes, dtype=np.float64)
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = tangents - np.einsum("ij,ij->i", tangents, z)[:, None] * z
    norm = np.linalg.norm(x, axis=1)
    degenerate = norm < 1e-9
    if degenerate.any():
        helper = np.where(np.abs(z[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        alt = helper - np.einsum("ij,ij->i", helper, z)[:, None] * z
        x[degenerate] = alt[degenerate]
        norm = np.linalg.norm(x, axis=1)
    x /= norm[:, None]
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2)


def cutting_times(
    arc_length: FloatArray,
    tilt_rad: FloatArray,
    speeds: SpeedTable,
    *,
    material: str,
    thickness_mm: float,
) -> tuple[FloatArray, FloatArray]:
    """Travel speed (N,) in m/s and time stamps (N,) in s along the path.

    A torch tilted by θ cuts through thickness / cos θ of plate (as bevel charts do), so its
    speed is the chart's at that thickness (capped at the chart's thickest row). Each segment
    runs at the slower of its two ends. ``time[0]`` is the pierce time: the torch dwells at
    the first set-point from 0 to ``time[0]`` while preheating and piercing.
    """
    speed0, pierce = speeds.lookup(material, thickness_mm)
    _, hi = speeds.thickness_range_mm(material)
    effective = np.minimum(thickness_mm / np.cos(np.asarray(tilt_rad, dtype=np.float64)), hi)
    speed, _ = speeds.speeds(material, np.maximum(effective, thickness_mm))
    speed = np.where(np.asarray(tilt_rad) > 0, speed, speed0)
    seg = np.diff(arc_length)
    seg_speed = np.minimum(speed[1:], speed[:-1])
    time = pierce + np.concatenate([[0.0], np.cumsum(seg / seg_speed)])
    return np.asarray(speed, dtype=np.float64), time


def points_array(values: ArrayLike, name: str) -> FloatArray:
    """``values`` as a finite (N, 3) float64 array; ToolpathError naming ``name`` otherwise."""
    return _points(values, name)


def _points(values: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ToolpathError(f"{name} must be an (N, 3) array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ToolpathError(f"{name} contains NaN or infinite values")
    return arr


def check_toolpath_config(config: ToolpathConfig) -> None:
    """Raise :class:`ToolpathError` naming the first parameter out of its range."""
    positive = (
        "spacing_m",
        # At zero standoff the torch body starts on the surface and every set-point collides.
        "standoff_m",
        "normal_radius_m",
        "coarse_normal_radius_m",
        "torch_length_m",
        "torch_radius_m",
        "thickness_mm",
        "collision_min_points",
    )
    for name in positive:
        value = getattr(config, name)
        if not value > 0:
            raise ToolpathError(f"toolpath.{name} must be positive, got {value}")
    for name in ("normal_smoothing_m", "tilt_steps", "tilt_directions", "min_surface_points"):
        if getattr(config, name) < 0:
            raise ToolpathError(f"toolpath.{name} must be >= 0, got {getattr(config, name)}")
    if not 0 <= config.max_tilt_deg < 90:
        raise ToolpathError(f"toolpath.max_tilt_deg must be in [0, 90), got {config.max_tilt_deg}")
    if not 0 < config.edge_angle_deg <= 180:
        raise ToolpathError(
            f"toolpath.edge_angle_deg must be in (0, 180], got {config.edge_angle_deg}"
        )


def torch_axes(
    surface_points: FloatArray,
    normals: FloatArray,
    tangents: FloatArray,
    surface: FloatArray,
    config: ToolpathConfig,
) -> TorchAxes:
    """:func:`~scrapcut_cli.toolpath.collision.choose_torch_axes` with the torch, standoff and
    tilt search of ``config``: the one place the toolpath's settings reach the collision check
    (open cuts and loops alike)."""
    return choose_torch_axes(
        surface_points,
        normals,
        tangents,
        surface,
        standoff_m=config.standoff_m,
        length_m=config.torch_length_m,
        radius_m=config.torch_radius_m,
        max_tilt_deg=config.max_tilt_deg,
        tilt_steps=config.tilt_steps,
        directions=config.tilt_directions,
        min_points=config.collision_min_points,
    )
