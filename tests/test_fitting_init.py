"""The fitting package's entry points: method dispatch and end extrapolation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import arc_on_cylinder, corner_on_beam, line_on_plane, painted_stroke

from scrapcut_cli.config import ScrapcutConfig, SkeletonConfig, config_from_dict
from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting import METHODS, extrapolate_end, fit_curve
from scrapcut_cli.fitting.curve import Curve


@pytest.fixture(scope="module")
def ordered_line() -> np.ndarray:
    line, normals = line_on_plane(0.4)
    pts = painted_stroke(line, normals, seed=31, caps=True)
    return pts[np.argsort(pts[:, 0])]


@pytest.mark.parametrize("method", METHODS)
def test_fit_curve_dispatches_with_the_method_section(ordered_line, method):
    curve = fit_curve(ordered_line, method, ScrapcutConfig())
    assert curve.method == method
    assert abs(curve.length - 0.4) < 0.01
    assert (curve.nurbs is not None) == (method == "nurbs")


def test_fit_curve_uses_the_config():
    line, normals = line_on_plane(0.4)
    pts = painted_stroke(line, normals, seed=32)
    config = config_from_dict({"nurbs": {"control_points": 9, "refine": False}})
    assert len(fit_curve(pts, "nurbs", config).nurbs.control_points) == 9
    config = config_from_dict({"skeleton": {"leaf_size_m": 0.02}})
    assert fit_curve(pts, "skeleton", config).info["leaf_size_m"] == 0.02


def test_unknown_method():
    with pytest.raises(FittingError, match="unknown fitting method 'spline'; known: nurbs"):
        fit_curve(np.zeros((10, 3)), "spline", ScrapcutConfig())


@pytest.mark.parametrize("method", METHODS)
def test_extrapolate_along_a_straight_line(ordered_line, method):
    curve = fit_curve(ordered_line, method, ScrapcutConfig())
    point, direction = extrapolate_end(curve, "end", step_m=0.06)
    assert abs(np.linalg.norm(direction) - 1.0) < 1e-12
    assert direction[0] > 0.99  # the line runs along +x
    np.testing.assert_allclose(point, curve.points[-1] + 0.06 * direction, atol=1e-12)
    point, direction = extrapolate_end(curve, "start", step_m=0.06)
    assert direction[0] < -0.99
    assert point[0] < -0.05


def test_extrapolate_follows_the_turn_of_an_arc():
    # On a pipe the end direction is close to the tangent at the end (the chord of the whole
    # arc would be 45 degrees off); a fitted end straightens a little over the last centimetres.
    line, normals = arc_on_cylinder(angle=np.pi / 2)
    pts = painted_stroke(line, normals, seed=33, caps=True)
    pts = pts[np.argsort(np.arctan2(pts[:, 1], pts[:, 0]))]
    tangent_at_end = np.array([-1.0, 0.0, 0.0])  # at angle 90 degrees, going anticlockwise
    for method in METHODS:
        curve = fit_curve(pts, method, ScrapcutConfig())
        _, direction = extrapolate_end(curve, "end", step_m=0.05)
        assert np.degrees(np.arccos(np.clip(direction @ tangent_at_end, -1, 1))) < 15.0, method


def test_extrapolate_a_plain_polyline():
    curve = Curve(points=np.array([[0.0, 0.0, 0.0], [0.0, 0.1, 0.0]]), method="other")
    point, direction = extrapolate_end(curve, "end", step_m=0.02)
    np.testing.assert_allclose(direction, [0.0, 1.0, 0.0])
    np.testing.assert_allclose(point, [0.0, 0.12, 0.0])


@pytest.mark.parametrize("method", METHODS)
def test_a_reversed_curve_extrapolates_from_its_own_ends(ordered_line, method):
    # reversed() turns the ordered info with the curve: the skeleton's vertices (its end
    # directions) and the per-end trims. Before, a reversed skeleton kept the vertices in the
    # old order and its "start" direction came from the other end of the line.
    curve = fit_curve(ordered_line, method, ScrapcutConfig())
    back = curve.reversed()
    for ours, theirs in (("start", "end"), ("end", "start")):
        point, direction = extrapolate_end(back, ours, step_m=0.05)
        expected_point, expected_direction = extrapolate_end(curve, theirs, step_m=0.05)
        np.testing.assert_allclose(direction, expected_direction, atol=1e-9)
        np.testing.assert_allclose(point, expected_point, atol=1e-9)
    assert back.info["end_trim_m"] == curve.info["end_trim_m"][::-1]
    assert back.info["end_trim_start_m"] == curve.info["end_trim_end_m"]
    assert back.info["end_shape"] == curve.info["end_shape"][::-1]
    assert back.reversed().info == curve.info


@pytest.mark.parametrize(("end", "step"), [("middle", 0.1), ("end", -0.1)])
def test_extrapolate_rejects_bad_arguments(end, step):
    curve = Curve(points=np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]), method="other")
    with pytest.raises(ValueError):
        extrapolate_end(curve, end, step_m=step)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- ends

#: Painted strokes with round caps (the paint reaches ~12 mm past each end) and the tolerance
#: on each end of the fitted curve, mm. Over 8 strokes per case the ends lie 1.0-1.5 mm from
#: the line's ends on average and at most 3.1 mm (continuous paint); on basket wires 2.4 mm
#: (NURBS) and 3.2 mm (skeleton at 20 mm, whose centre wanders ~3 mm over the wire patches)
#: on average and at most 9.3 mm (a wire at the rim of a cap, where the envelope is steep).
CAPPED_STROKES = {
    "straight": (line_on_plane(0.5), {}, 3.5),
    "pipe": (arc_on_cylinder(), {}, 3.5),
    "joint": (corner_on_beam(), {"outlier_share": 0.01}, 3.5),
    "gaps": (line_on_plane(0.5), {"gaps": [(0.10, 0.14), (0.20, 0.25), (0.30, 0.34)]}, 3.5),
    "short": (line_on_plane(0.03, 31), {}, 3.5),
    # Wires 5 mm wide every 35 mm; one crosses each cap 6-11 mm beyond the line's end.
    "basket": (
        line_on_plane(0.473),
        {"gaps": [(s + 0.005, s + 0.035) for s in np.arange(-0.046, 0.55, 0.035)]},
        8.0,
    ),
}


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("case", sorted(CAPPED_STROKES))
def test_capped_strokes_end_at_the_line_ends(case, method):
    (line, normals), options, tolerance_mm = CAPPED_STROKES[case]
    pts = painted_stroke(line, normals, caps=True, seed=7, **options)
    pts = pts[np.argsort(pts @ (line[-1] - line[0]))]  # scanned from start to end
    config = ScrapcutConfig()
    if method == "skeleton" and case in ("gaps", "basket"):  # 5 mm leaves break over gaps
        config = replace(config, skeleton=SkeletonConfig(leaf_size_m=0.02))
    curve = fit_curve(pts, method, config)
    start_mm = 1e3 * np.linalg.norm(curve.points[0] - line[0])
    end_mm = 1e3 * np.linalg.norm(curve.points[-1] - line[-1])
    assert start_mm < tolerance_mm and end_mm < tolerance_mm, (start_mm, end_mm)
    trims = curve.info["end_trim_m"]
    assert all(0.004 < t < 0.02 for t in trims), trims
    if case != "short":  # a short stroke's width comes partly from its caps
        assert abs(curve.info["stroke_half_width_m"] - 0.0125) < 0.0015
    if curve.nurbs is not None:
        # The exported model ends where the polyline does.
        ends = curve.nurbs.evaluate(np.array(curve.nurbs.domain))
        np.testing.assert_allclose(ends, curve.points[[0, -1]], atol=1e-9)
