"""Closed lines: closure detection, the periodic NURBS, the skeleton's cycle, unobserved arcs."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import painted_stroke, surface_patch

from scrapcut_cli.config import ClosureConfig, ScrapcutConfig
from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting import detect_closure, fit_line, nurbs_to_geomdl
from scrapcut_cli.fitting.closure import arc_mask, bridge_directions, hermite_bridge
from scrapcut_cli.fitting.ordering import paint_chain
from scrapcut_cli.geometry import PolylineDistance, closed_polyline, false_runs

RADIUS = 0.075


def circle(n: int = 900, radius: float = RADIUS) -> tuple[np.ndarray, np.ndarray]:
    """A circle (n + 1, 3) in z = 0 about the origin, first point repeated, from angle 0
    counter-clockwise; normals +z."""
    phi = np.linspace(0.0, 2.0 * np.pi, n + 1)
    pts = np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros_like(phi)])
    return pts, np.tile([0.0, 0.0, 1.0], (n + 1, 1))


def plate_around(paint: np.ndarray, *, band_m: float, reach_m: float = 0.04) -> np.ndarray:
    """Observed bare surface in z = 0 beside a paint band: grid points within ``reach_m`` of the
    paint but further than ``band_m`` from it."""
    from scipy.spatial import cKDTree

    grid = surface_patch((-0.15, -0.15, 0.0), (0.3, 0.0, 0.0), (0.0, 0.3, 0.0), spacing_m=0.004)
    d, _ = cKDTree(paint).query(grid)
    return np.asarray(grid[(d > band_m) & (d < reach_m)])


def ring_scan(
    gap_deg: tuple[float, float] | None = None, *, surface_seen_in_gap: bool = False, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Paint of a 150 mm ring on a plate and the bare plate seen around it; with ``gap_deg``
    neither paint nor plate was seen over that arc (degrees from angle 0, counter-clockwise)
    unless ``surface_seen_in_gap`` (then only the paint is missing)."""
    line, normals = circle()
    length = 2.0 * np.pi * RADIUS
    gaps = []
    if gap_deg is not None:
        gaps = [(np.radians(gap_deg[0]) * RADIUS, np.radians(gap_deg[1]) * RADIUS)]
    paint = painted_stroke(line, normals, gaps=gaps, seed=seed)
    surface = plate_around(paint, band_m=0.006)
    if gap_deg is not None and not surface_seen_in_gap:
        angle = np.degrees(np.mod(np.arctan2(surface[:, 1], surface[:, 0]), 2 * np.pi))
        surface = surface[(angle < gap_deg[0]) | (angle > gap_deg[1])]
    assert length > 0.4
    return paint, surface


def u_scan(gap_m: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A U of two 200 mm arms ``gap_m`` apart (tips side by side, facing the same way), on a
    plate seen around it."""
    r = gap_m / 2.0
    t = np.linspace(0.0, np.pi, 200)
    bend = np.column_stack([0.1 + r * np.sin(t), r - r * np.cos(t), np.zeros_like(t)])
    arm = np.linspace(-0.1, 0.1, 200)
    line = np.vstack(
        [
            np.column_stack([arm, np.zeros_like(arm), np.zeros_like(arm)]),
            bend[1:-1],
            np.column_stack([arm[::-1], np.full_like(arm, gap_m), np.zeros_like(arm)]),
        ]
    )
    normals = np.tile([0.0, 0.0, 1.0], (len(line), 1))
    paint = painted_stroke(line, normals, caps=True, seed=seed)
    return paint, plate_around(paint, band_m=0.006)


def mean_distance_to_circle(points: np.ndarray) -> float:
    r = np.hypot(points[:, 0], points[:, 1])
    return float(np.mean(np.hypot(r - RADIUS, points[:, 2])))


# --------------------------------------------------------------------------- detection


def test_paint_all_round_is_a_loop() -> None:
    paint, surface = ring_scan()
    closure = detect_closure(paint, surface)
    assert closure.closed and closure.reason == "loop"
    # The chain runs once round from next to its start: its length and the gap make the ring.
    info = closure.info()
    assert info["gap_m"] < 0.03
    length = info["chain_length_m"] + info["gap_m"]
    assert abs(length - 2 * np.pi * RADIUS) < 0.03 * 2 * np.pi * RADIUS


@pytest.mark.parametrize("gap_m", [0.03, 0.06])
def test_a_u_whose_tips_are_close_stays_open(gap_m: float) -> None:
    paint, surface = u_scan(gap_m)
    chain = paint_chain(paint, voxel_m=0.01)
    assert not chain.loop
    closure = detect_closure(paint, surface)
    assert not closure.closed, closure.reason


def test_a_ring_with_an_arc_no_frame_saw_is_closed_through_it() -> None:
    paint, surface = ring_scan((200.0, 290.0))
    closure = detect_closure(paint, surface)
    assert closure.closed and closure.reason == "unobserved_gap"
    # The bridge runs round the missing quarter, near the circle (not across the chord).
    assert mean_distance_to_circle(closure.bridge) < 0.006


def test_paint_missing_where_the_plate_was_seen_is_an_end() -> None:
    paint, surface = ring_scan((200.0, 290.0), surface_seen_in_gap=True)
    closure = detect_closure(paint, surface)
    assert not closure.closed
    assert closure.reason in ("end_observed", "gap_observed")


def test_forced_modes() -> None:
    paint, surface = ring_scan()
    assert not detect_closure(paint, surface, config=ClosureConfig(mode="open")).closed
    u_paint, u_surface = u_scan(0.05)
    forced = detect_closure(u_paint, u_surface, config=ClosureConfig(mode="closed"))
    assert forced.closed and forced.reason == "forced_closed"
    with pytest.raises(FittingError, match=r"unknown closure\.mode"):
        detect_closure(paint, surface, config=ClosureConfig(mode="maybe"))


def test_hermite_bridge_of_a_circle_gap_follows_the_circle() -> None:
    # Ends of a circle missing 90 degrees, with the circle's directions out of the line.
    a, b = np.radians(180.0), np.radians(270.0)
    start = RADIUS * np.array([np.cos(a), np.sin(a), 0.0])
    end = RADIUS * np.array([np.cos(b), np.sin(b), 0.0])
    out_start = np.array([-np.sin(a), np.cos(a), 0.0])  # counter-clockwise past a
    out_end = np.array([np.sin(b), -np.cos(b), 0.0])  # clockwise past b
    bridge = hermite_bridge(start, out_start, end, out_end)
    assert np.allclose(bridge[0], start) and np.allclose(bridge[-1], end)
    assert mean_distance_to_circle(bridge) < 0.002


def test_bridge_over_a_ring_gap_is_not_swung_by_one_hooked_end() -> None:
    # The centre of a ring's 270 degrees (a 25 mm band: 12 mm half width) whose last 25 mm,
    # about one stroke width, rise 5 mm out of the ring's plane (a hooked end, as paint misread
    # at a grazing view). The bridge must start at that tip; beyond the tip's own offset fading
    # across the gap it should stay within 2 mm of the circle. Directions read off the last
    # 3 cm (paint_end's) follow the hook: about 4 mm of swing.
    half, hook = 0.012, 0.005
    phi = np.radians(np.arange(0.0, 270.0 + 1e-9, 0.25))
    centre = np.column_stack([RADIUS * np.cos(phi), RADIUS * np.sin(phi), np.zeros_like(phi)])
    s = RADIUS * phi
    centre[:, 2] += hook * np.clip((s - (s[-1] - 0.025)) / 0.025, 0.0, None) ** 2

    def swing(bridge: np.ndarray) -> float:
        off = np.hypot(np.hypot(bridge[:, 0], bridge[:, 1]) - RADIUS, bridge[:, 2])
        u = np.linspace(0.0, 1.0, len(bridge))  # evenly resampled from the hooked tip
        return float(np.max(off - hook * (1.0 - u)))

    end_out, start_out = bridge_directions(centre, half_width_m=half)
    bridge = hermite_bridge(centre[-1], end_out, centre[0], start_out)
    assert np.allclose(bridge[0], centre[-1]) and np.allclose(bridge[-1], centre[0])
    assert swing(bridge) < 0.002
    # Unhooked, the bridge follows the circle.
    flat = centre * np.array([1.0, 1.0, 0.0])
    flat_end, flat_start = bridge_directions(flat, half_width_m=half)
    assert mean_distance_to_circle(hermite_bridge(flat[-1], flat_end, flat[0], flat_start)) < 0.001


def test_false_runs_wrap_round_a_loop() -> None:
    mask = np.array([False, True, True, False, False, True, False])
    assert false_runs(mask) == [(0, 1), (3, 5), (6, 7)]
    assert false_runs(mask, closed=True) == [(3, 5), (6, 1)]
    assert false_runs(np.ones(4, bool), closed=True) == []
    assert false_runs(np.zeros(4, bool), closed=True) == [(0, 4)]
    s = np.array([0.0, 0.1, 0.5, 0.9])
    assert arc_mask(s, [(0.8, 0.05)]).tolist() == [True, False, False, True]


# --------------------------------------------------------------------------- fits


@pytest.mark.parametrize("method", ["nurbs", "skeleton"])
def test_closed_fit_of_a_ring_seen_all_round(method: str) -> None:
    paint, surface = ring_scan(seed=3)
    curve = fit_line(paint, surface, method, ScrapcutConfig())
    assert curve.closed and curve.info["closure_reason"] == "loop"
    # points do not repeat the first one; the polyline does.
    assert np.linalg.norm(curve.points[-1] - curve.points[0]) > 0.5 * curve.spacing_m
    assert np.allclose(curve.polyline[-1], curve.polyline[0])
    assert mean_distance_to_circle(curve.points) < 0.001
    assert abs(curve.length - 2 * np.pi * RADIUS) < 0.005
    assert curve.info["unobserved_arcs_m"] == []
    # The closing segment is as short as any other: no seam.
    steps = np.linalg.norm(np.diff(curve.polyline, axis=0), axis=1)
    assert steps[-1] < 1.5 * np.median(steps)


@pytest.mark.parametrize("method", ["nurbs", "skeleton"])
def test_closed_fit_bridges_and_reports_an_unobserved_arc(method: str) -> None:
    gap = (200.0, 290.0)
    paint, surface = ring_scan(gap, seed=4)
    curve = fit_line(paint, surface, method, ScrapcutConfig())
    assert curve.closed and curve.info["closure_reason"] == "unobserved_gap"
    # Observed arcs within a millimetre; the bridge within a few.
    angle = np.degrees(np.mod(np.arctan2(curve.points[:, 1], curve.points[:, 0]), 2 * np.pi))
    seen = (angle < gap[0] - 5) | (angle > gap[1] + 5)
    assert mean_distance_to_circle(curve.points[seen]) < 0.001
    assert mean_distance_to_circle(curve.points[~seen]) < 0.006
    arcs = curve.info["unobserved_arcs_m"]
    assert len(arcs) == 1
    poly = curve.polyline
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poly, axis=0), axis=1))])
    ends = [poly[int(np.argmin(np.abs(s - v)))] for v in arcs[0]]
    end_angles = sorted(np.degrees(np.mod(np.arctan2(e[1], e[0]), 2 * np.pi)) for e in ends)
    # Reported within 10 mm of the true extent (7.6 degrees at 75 mm).
    tolerance = np.degrees(0.010 / RADIUS)
    assert abs(end_angles[0] - gap[0]) < tolerance
    assert abs(end_angles[1] - gap[1]) < tolerance


@pytest.mark.parametrize("seed", [4, 5])
def test_closed_nurbs_bridges_a_third_of_a_ring_round_not_towards_its_chord(seed: int) -> None:
    # 120 degrees of a 75 mm ring unseen. By its bending term alone the periodic fit flattened
    # the gap towards its chord, 6.5 and 12.3 mm inside the ring for these seeds; guided by the
    # bridge that continues both ends' turn it stays within 4 mm (3.9 and 2.4).
    gap = (150.0, 270.0)
    paint, surface = ring_scan(gap, seed=seed)
    curve = fit_line(paint, surface, "nurbs", ScrapcutConfig())
    assert curve.closed and curve.info["closure_reason"] == "unobserved_gap"
    angle = np.degrees(np.mod(np.arctan2(curve.points[:, 1], curve.points[:, 0]), 2 * np.pi))
    inside = (angle > gap[0]) & (angle < gap[1])
    r = np.hypot(curve.points[:, 0], curve.points[:, 1])
    assert np.max(np.hypot(r - RADIUS, curve.points[:, 2])[inside]) < 0.0045
    assert mean_distance_to_circle(curve.points[~inside]) < 0.001


def test_a_ring_seen_one_sided_before_its_gap_is_centred_by_the_stroke_model() -> None:
    # The last 40 degrees before an unobserved arc seen at a grazing angle: only the band's
    # inner half and its inner edge. The paint's centre lies 6 mm inside the line there; the
    # stroke model's (its one edge and the band's width) does not (NURBS 5.9 -> 2.7 mm mean).
    from scrapcut_cli.fitting.stroke import StrokeObservations, stroke_model

    gap = (200.0, 290.0)
    paint, surface = ring_scan(gap, seed=4)
    angle = np.degrees(np.mod(np.arctan2(paint[:, 1], paint[:, 0]), 2 * np.pi))
    outside = np.hypot(paint[:, 0], paint[:, 1]) > RADIUS
    paint = paint[~((angle > 160) & (angle < 200) & outside)]
    paint = paint[np.argsort(np.mod(np.degrees(np.arctan2(paint[:, 1], paint[:, 0])) - 290, 360))]
    seen = np.arange(0.0, 360.0, 0.5)
    seen = seen[(seen < gap[0]) | (seen > gap[1])]
    outer = seen[(seen < 160) | (seen > gap[1])]
    edges = np.vstack(
        [
            circle_points(np.radians(seen), RADIUS - 0.0125),
            circle_points(np.radians(outer), RADIUS + 0.0125),
        ]
    )
    model = stroke_model(paint, StrokeObservations(edges=edges, surface=surface, voxel_m=0.002))
    for stroke, worst in ((None, 0.005), (model, 0.0035)):
        curve = fit_line(paint, surface, "nurbs", ScrapcutConfig(), stroke=stroke)
        assert curve.closed and curve.info["closure_reason"] == "unobserved_gap"
        a = np.degrees(np.mod(np.arctan2(curve.points[:, 1], curve.points[:, 0]), 2 * np.pi))
        one_sided = curve.points[(a > 165) & (a < 200)]
        if stroke is None:  # the paint's centre: off the line
            assert mean_distance_to_circle(one_sided) > worst
        else:
            assert mean_distance_to_circle(one_sided) < worst


def circle_points(phi: np.ndarray, radius: float) -> np.ndarray:
    return np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros_like(phi)])


def test_periodic_nurbs_matches_geomdl_and_closes_smoothly() -> None:
    paint, surface = ring_scan(seed=5)
    curve = fit_line(paint, surface, "nurbs", ScrapcutConfig())
    model = curve.nurbs
    assert model is not None and model.periodic
    p = model.degree
    # Unclamped form: the first p control points repeated at the end.
    assert np.allclose(model.control_points[:p], model.control_points[-p:])
    lo, hi = model.domain
    t = np.linspace(lo, hi, 57)
    ours = model.evaluate(t)
    theirs = np.asarray([nurbs_to_geomdl(model).evaluate_single(float(v)) for v in t])
    assert np.max(np.linalg.norm(ours - theirs, axis=1)) < 1e-9
    # The curve returns to its start with matching tangent.
    assert np.linalg.norm(ours[0] - ours[-1]) < 1e-9
    eps = 1e-6 * (hi - lo)
    d_start = model.evaluate([lo + eps])[0] - ours[0]
    d_end = ours[-1] - model.evaluate([hi - eps])[0]
    cos = d_start @ d_end / (np.linalg.norm(d_start) * np.linalg.norm(d_end))
    assert cos > 0.9999
    # Wrapped evaluation past the domain.
    assert np.allclose(
        model.evaluate([lo + 0.25 * (hi - lo)]), model.evaluate([hi + 0.25 * (hi - lo)])
    )
    # Round-trips through a dict.
    again = type(model).from_dict(model.to_dict())
    assert again.periodic and np.allclose(again.evaluate(t), ours)


def test_reversed_loop_keeps_its_start_and_mirrors_its_arcs() -> None:
    paint, surface = ring_scan((200.0, 290.0), seed=6)
    curve = fit_line(paint, surface, "nurbs", ScrapcutConfig())
    back = curve.reversed()
    assert back.closed and np.allclose(back.points[0], curve.points[0])
    assert abs(back.length - curve.length) < 1e-9
    (a, b), (c, d) = curve.info["unobserved_arcs_m"][0], back.info["unobserved_arcs_m"][0]
    total = curve.length
    assert abs((b - a) % total - (d - c) % total) < 0.003
    mid = PolylineDistance(closed_polyline(curve.points))
    assert mid.distance(back.points).max() < 1e-6
