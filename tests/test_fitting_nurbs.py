"""Open NURBS fit: geomdl agreement, recovery of known curves, invariances, ends, errors."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    apply_se3,
    arc_on_cylinder,
    corner_on_beam,
    line_on_plane,
    noisy_arc,
    noisy_helix,
    on_wire_grid,
    painted_stroke,
    random_se3,
    s_curve_on_plane,
)

from scrapcut_cli.config import NurbsConfig
from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting.curve import NurbsModel
from scrapcut_cli.fitting.nurbs import (
    fit_nurbs,
    nurbs_to_geomdl,
    nurbs_to_geomdl_json,
    retarget_domain,
)
from scrapcut_cli.geometry import PolylineDistance


def errors_mm(curve_points: np.ndarray, reference: np.ndarray) -> tuple[float, float, float]:
    """(mean, max) distance reference -> curve and max curve -> reference, millimetres."""
    forward = PolylineDistance(curve_points).distance(reference)
    backward = PolylineDistance(reference).distance(curve_points)
    return 1e3 * forward.mean(), 1e3 * forward.max(), 1e3 * backward.max()


@pytest.fixture(scope="module")
def helix_fit():
    pts, ref = noisy_helix(seed=2)
    return pts, ref, fit_nurbs(pts)


# --------------------------------------------------------------------------- geomdl


def test_geomdl_evaluates_the_fitted_curve_identically(helix_fit):
    _, _, curve = helix_fit
    model = curve.nurbs
    t = np.linspace(*model.domain, 257)
    ours = model.evaluate(t)
    theirs = np.asarray(nurbs_to_geomdl(model).evaluate_list(t.tolist()))
    assert np.abs(ours - theirs).max() < 1e-9


def test_geomdl_agrees_on_a_rational_curve():
    rng = np.random.default_rng(7)
    knots = np.concatenate([np.zeros(4), np.sort(rng.uniform(0, 1, 5)), np.ones(4)])
    model = NurbsModel(
        degree=3,
        knots=knots,
        control_points=rng.normal(size=(9, 3)),
        weights=rng.uniform(0.5, 2.0, 9),
    )
    t = np.linspace(0.0, 1.0, 101)
    theirs = np.asarray(nurbs_to_geomdl(model).evaluate_list(t.tolist()))
    assert np.abs(model.evaluate(t) - theirs).max() < 1e-9


def test_geomdl_json_round_trip(helix_fit, tmp_path):
    from geomdl import exchange

    model = helix_fit[2].nurbs
    path = tmp_path / "curve.json"
    path.write_text(nurbs_to_geomdl_json(model), encoding="utf-8")
    (loaded,) = exchange.import_json(str(path))
    t = np.linspace(0.0, 1.0, 101)
    assert loaded.degree == model.degree
    assert np.abs(np.asarray(loaded.evaluate_list(t.tolist())) - model.evaluate(t)).max() < 1e-9


def test_curve_points_lie_on_the_model_and_are_evenly_spaced(helix_fit):
    _, _, curve = helix_fit
    on_model = curve.nurbs.evaluate(np.linspace(0.0, 1.0, 5000))
    assert PolylineDistance(on_model).distance(curve.points).max() < 1e-6
    step = np.linalg.norm(np.diff(curve.points, axis=0), axis=1)
    assert step.max() <= 0.001 + 1e-9
    assert step.min() > 0.0009
    np.testing.assert_allclose(curve.nurbs.knots[:4], 0.0)
    np.testing.assert_allclose(curve.nurbs.knots[-4:], 1.0)
    np.testing.assert_array_equal(curve.nurbs.weights, 1.0)


def test_retarget_domain_is_exact():
    rng = np.random.default_rng(3)
    knots = np.concatenate([np.zeros(4), [0.2, 0.45, 0.7], np.ones(4)])
    ctrl = rng.normal(size=(7, 3))
    new_knots, new_ctrl = retarget_domain(knots, ctrl, 3, 0.1, 0.8)
    trimmed = NurbsModel(3, new_knots, new_ctrl, np.ones(len(new_ctrl)))
    original = NurbsModel(3, knots, ctrl, np.ones(7))
    u = np.linspace(0.0, 1.0, 101)
    assert np.abs(trimmed.evaluate(u) - original.evaluate(0.1 + 0.7 * u)).max() < 1e-12


# --------------------------------------------------------------------------- recovery


def test_noisy_helix_is_recovered(helix_fit):
    # 1 mm Gaussian noise on a 1.5-turn helix (r 50 mm, pitch 40 mm): the fit lies within
    # 0.4 mm of the helix on average and 2.5 mm at worst (the worst is at the free ends).
    _, ref, curve = helix_fit
    mean, worst, back = errors_mm(curve.points, ref)
    assert mean < 0.4
    assert worst < 2.5
    assert back < 1.5
    assert curve.method == "nurbs"
    assert abs(curve.length - 0.4727) < 0.004
    assert curve.info["rms_m"] < 0.002


def test_noisy_arc_is_recovered_where_a_principal_axis_fails():
    # A 270-degree arc folds over its principal axis; the chain initialisation orders it.
    pts, ref = noisy_arc(seed=1)
    curve = fit_nurbs(pts)
    mean, worst, back = errors_mm(curve.points, ref)
    assert curve.info["init"] == "chain"
    assert mean < 0.4
    assert worst < 2.5
    assert back < 1.5
    principal = fit_nurbs(pts, config=NurbsConfig(init="principal", max_iterations=5))
    assert errors_mm(principal.points, ref)[1] > 10.0


def test_centre_of_a_painted_band_on_a_pipe():
    # A 25 mm wide ragged band around a pipe (r 80 mm, 270 degrees), 1 mm noise.
    line, normals = arc_on_cylinder()
    curve = fit_nurbs(painted_stroke(line, normals, seed=4))
    mean, worst, back = errors_mm(curve.points, line)
    assert mean < 1.0
    assert worst < 5.0
    assert back < 5.0
    assert abs(curve.length - 0.377) < 0.01


def test_a_sharp_joint_becomes_a_kink():
    # The I-beam's 90-degree joint: with the kink the fit follows the corner.
    line, normals = corner_on_beam()
    pts = painted_stroke(line, normals, seed=5, outlier_share=0.01)
    curve = fit_nurbs(pts)
    assert curve.info["corners"] == 1
    near_corner = line[np.abs(np.linalg.norm(line, axis=1)) < 0.03]
    at_corner = 1e3 * PolylineDistance(curve.points).distance(near_corner).max()
    assert at_corner < 2.5
    assert errors_mm(curve.points, line)[0] < 1.0
    smooth = fit_nurbs(pts, config=NurbsConfig(corner_angle_deg=0.0))
    assert smooth.info["corners"] == 0
    rounded = 1e3 * PolylineDistance(smooth.points).distance(near_corner).max()
    assert rounded > at_corner + 1.0


def test_gaps_are_bridged():
    # Round caps, as sprayed: the ends are then where the line ends (square ends of ragged
    # paint are told from caps only about half of the time; see test_fitting_ends).
    line, normals = line_on_plane(0.5)
    gaps = [(0.10, 0.14), (0.20, 0.25), (0.30, 0.34)]
    curve = fit_nurbs(painted_stroke(line, normals, seed=6, gaps=gaps, caps=True))
    _, worst, back = errors_mm(curve.points, line)
    assert worst < 3.0
    assert back < 3.0


def test_a_wire_basket_is_bridged():
    # Paint only on the wires: 5 mm patches of band every 35 mm along a 0.5 m arc (r 0.2 m).
    # The patches lie across the line; the fit must follow the line, not zig-zag over them.
    # The end cap falls in a gap (0.495-0.525 m): the last paint is a wire ending 5 mm before
    # the line's end, where the curve ends too; the line is compared up to that wire.
    line, normals = arc_on_cylinder(radius=0.2, angle=2.5)
    gaps = [(s + 0.005, s + 0.035) for s in np.arange(0.0, 0.5, 0.035)]
    pts = painted_stroke(line, normals, seed=21, gaps=gaps, outlier_share=0.01, caps=True)
    curve = fit_nurbs(pts)
    painted = line[: round(len(line) * 0.495 / 0.5)]
    mean, worst, back = errors_mm(curve.points, painted)
    assert mean < 2.0
    assert worst < 6.0
    assert back < 6.0
    assert abs(curve.length - 0.5) < 0.01
    assert curve.info["corners"] == 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_paint_on_a_wire_mesh_is_fitted_smoothly(seed: int):
    # A stroke sprayed across a 40 mm wire mesh: paint only on the wires, and wherever a wire
    # runs beside the line the residuals are one-sided. Knot refinement and kinks would pull
    # the curve from wire to wire (before they were skipped: up to 15 mm off, 20 mm back);
    # the smooth fit stays within 12 mm everywhere and near 3 mm on average.
    line, normals = s_curve_on_plane()
    stroke = painted_stroke(line, normals, seed=seed, caps=True)
    curve = fit_nurbs(on_wire_grid(stroke, angle_deg=10.0 + 15.0 * seed))
    assert curve.info["band_fill"] < 0.6
    assert curve.info["corners"] == 0 and curve.info["knots_inserted"] == 0
    mean, worst, back = errors_mm(curve.points, line)
    assert mean < 4.5
    assert worst < 12.0
    assert back < 12.0
    solid = fit_nurbs(stroke)
    assert solid.info["band_fill"] > 0.9


def test_ends_match_the_line_not_the_paint():
    # The paint's round caps reach ~12 mm past each end of the line; the curve ends at the
    # caps' centres (the line's ends), the model with it. Without the trim it ran to the tips.
    line, normals = line_on_plane(0.5)
    pts = painted_stroke(line, normals, seed=8, caps=True)
    pts = pts[np.argsort(pts[:, 0])]
    curve = fit_nurbs(pts)
    # Ordered input: the curve starts at x = 0 and stops neither short nor beyond x = 0.5.
    assert np.linalg.norm(curve.points[0] - line[0]) < 0.003
    assert np.linalg.norm(curve.points[-1] - line[-1]) < 0.003
    assert curve.info["end_shape"] == ["round", "round"]
    np.testing.assert_allclose(curve.nurbs.evaluate([0.0, 1.0]), curve.points[[0, -1]], atol=1e-9)
    to_the_tips = fit_nurbs(pts, config=NurbsConfig(end_trim="none"))
    assert to_the_tips.points[0, 0] < -0.008 and to_the_tips.points[-1, 0] > 0.508
    assert to_the_tips.info["end_trim_m"] == [0.0, 0.0]
    fixed = fit_nurbs(pts, config=NurbsConfig(end_trim_m=0.005))
    assert abs(fixed.length - (to_the_tips.length - 0.01)) < 0.001


# --------------------------------------------------------------------------- invariances


def test_rigid_motion_invariance():
    line, normals = arc_on_cylinder()
    pts = painted_stroke(line, normals, seed=9)
    T = random_se3(11)
    moved = fit_nurbs(apply_se3(T, pts))
    base = fit_nurbs(pts)
    assert moved.points.shape == base.points.shape
    assert np.abs(moved.points - apply_se3(T, base.points)).max() < 1e-6
    assert np.abs(moved.nurbs.control_points - apply_se3(T, base.nurbs.control_points)).max() < (
        1e-6
    )


def test_reversing_the_input_reverses_the_curve_only(helix_fit):
    pts, _, curve = helix_fit
    backwards = fit_nurbs(pts[::-1])
    assert np.abs(backwards.points - curve.points[::-1]).max() < 1e-6
    t = np.linspace(0.0, 1.0, 50)
    assert np.abs(backwards.nurbs.evaluate(t) - curve.nurbs.evaluate(1.0 - t)).max() < 1e-6


def test_curve_runs_with_the_input_order():
    line, normals = line_on_plane(0.4)
    pts = painted_stroke(line, normals, seed=12, caps=True)  # capped: ends at the line's
    ordered = pts[np.argsort(pts[:, 0])]
    assert fit_nurbs(ordered).points[0, 0] < 0.01
    assert fit_nurbs(ordered[::-1]).points[0, 0] > 0.39


def test_density_does_not_change_the_fit():
    # The objective is per point and per metre: the same cloud twice over fits the same curve.
    pts, _ = noisy_arc(n=800, seed=13)
    once = fit_nurbs(pts)
    twice = fit_nurbs(np.vstack([pts, pts]))
    assert np.abs(once.points - twice.points).max() < 1e-6


def test_exact_collinear_points_fit_without_warnings():
    # Noise-free points, each repeated: the bending energy is ~0 and round-off made it
    # negative (sqrt of a negative objective: RuntimeWarning, an error under pytest).
    line = np.column_stack([np.linspace(0.0, 0.3, 30), np.zeros(30), np.zeros(30)])
    curve = fit_nurbs(np.repeat(line, 50, axis=0))
    assert curve.info["objective_m2"] >= 0.0
    assert PolylineDistance(line).distance(curve.points).max() < 1e-6  # on the line
    assert abs(curve.length - 0.3) < 0.001


def test_input_is_not_modified(helix_fit):
    pts = helix_fit[0]
    before = pts.copy()
    fit_nurbs(pts, config=NurbsConfig(refine=False, corner_angle_deg=0.0))
    np.testing.assert_array_equal(pts, before)


def test_same_input_same_bytes():
    pts, _ = noisy_arc(n=600, seed=14)
    a, b = fit_nurbs(pts), fit_nurbs(pts)
    assert a.points.tobytes() == b.points.tobytes()
    assert a.nurbs.control_points.tobytes() == b.nurbs.control_points.tobytes()


# --------------------------------------------------------------------------- options, errors


def test_fixed_control_points_and_degree():
    pts, _ = noisy_arc(n=600, seed=15)
    curve = fit_nurbs(
        pts, config=NurbsConfig(degree=2, control_points=12, refine=False, corner_angle_deg=0.0)
    )
    assert curve.nurbs.degree == 2
    assert len(curve.nurbs.control_points) == 12
    assert len(curve.nurbs.knots) == 15


def test_more_smoothness_means_a_straighter_curve():
    pts, _ = noisy_helix(n=1500, seed=16, noise_m=0.002)
    loose = fit_nurbs(pts, config=NurbsConfig(smoothness=1.0))
    stiff = fit_nurbs(pts, config=NurbsConfig(smoothness=1e6))
    assert stiff.length < loose.length - 0.01


@pytest.mark.parametrize(
    ("points", "message"),
    [
        (np.zeros((5, 3)), "at least"),
        (np.zeros((50, 2)), "(N, 3)"),
        (np.full((50, 3), np.nan), "NaN"),
        (np.ones((50, 3)), "coincide"),
    ],
)
def test_bad_clouds_raise_one_line(points, message):
    with pytest.raises(FittingError, match=message.replace("(", r"\(").replace(")", r"\)")):
        fit_nurbs(points)


@pytest.mark.parametrize(
    ("config", "message"),
    [
        (NurbsConfig(degree=0), "degree"),
        (NurbsConfig(control_points=2), "control points"),
        (NurbsConfig(init="pca"), "unknown NURBS init"),
        (NurbsConfig(smoothness=-1.0), r"nurbs.smoothness must be a finite number >= 0"),
        # Before, NaN or infinite smoothness reached scipy's solver (a ValueError traceback).
        (NurbsConfig(smoothness=float("nan")), r"nurbs.smoothness must be a finite number >= 0"),
        (NurbsConfig(smoothness=float("inf")), r"nurbs.smoothness must be a finite number >= 0"),
        (NurbsConfig(sample_spacing_m=0.0), r"nurbs.sample_spacing_m must be a finite number > 0"),
    ],
)
def test_bad_options_raise(config, message):
    pts, _ = noisy_arc(n=100, seed=1)
    with pytest.raises(FittingError, match=message):
        fit_nurbs(pts, config=config)
