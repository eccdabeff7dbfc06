"""Stroke ends: half width, round caps, square and gapped ends, modes and limits."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import line_on_plane, noisy_arc, painted_stroke

from scrapcut_cli.config import NurbsConfig, SkeletonConfig
from scrapcut_cli.errors import FittingError
from scrapcut_cli.fitting._common import data_extent, extended_positions
from scrapcut_cli.fitting.ends import (
    MAX_TRIM_SHARE,
    StrokeEnds,
    edge_profile,
    stroke_ends,
    stroke_half_width,
)
from scrapcut_cli.fitting.nurbs import fit_nurbs
from scrapcut_cli.fitting.skeleton import fit_skeleton

LINE, NORMALS = line_on_plane(0.5)
#: Wires 5 mm wide every 35 mm, placed so that one crosses each cap 6-11 mm beyond the line's
#: ends (0 and 0.473 m), where the cap's chord has narrowed to 5-11 mm half width.
BASKET_LENGTH = 0.473
BASKET_GAPS = [(s + 0.005, s + 0.035) for s in np.arange(-0.046, 0.55, 0.035)]
#: The simulator's heavy (``yard``) overspray: specks in 20 % of the 1.5 mm cells at the
#: stroke's edge, e times fewer every 10 mm out to 40 mm, around the caps too. Stitched, they
#: add a third of the band's density just outside its edge, and the paint's extent lies
#: 10-35 mm past the caps.
OVERSPRAY = 0.2


def ends_on_line(points: np.ndarray, line: np.ndarray = LINE, **options) -> StrokeEnds:
    """The estimate made on the true centre line, from the paint's extent along it."""
    extent = data_extent(line, points, quantile=0.002, radius=0.03)
    return stroke_ends(line, points, extent=extent, radius=0.03, **options)


# --------------------------------------------------------------------------- half width


@pytest.mark.parametrize(
    ("options", "tolerance_mm"),
    [
        ({}, 0.5),
        ({"noise_m": 0.002, "outlier_share": 0.05}, 1.0),
        ({"gaps": BASKET_GAPS}, 1.0),
        ({"overspray": OVERSPRAY}, 1.5),
    ],
)
def test_half_width_of_a_painted_band(options, tolerance_mm):
    # A 25 mm ragged band (+-15 % about 12.5 mm): plain; with 2 mm noise and 5 % outliers; only
    # on the wires of a basket; in a halo of overspray (which alone read as ~16.5 mm).
    pts = painted_stroke(LINE, NORMALS, caps=True, seed=1, **options)
    dist, pos = extended_positions(LINE, pts)
    near = dist <= 0.03
    half = stroke_half_width(dist[near], pos[near], 0.0, 0.5)
    assert half is not None
    assert abs(half - 0.0125) < tolerance_mm * 1e-3


def test_edge_profile_of_a_band_in_a_halo():
    # |u| of a 12.5 mm band (3000 points) and of a halo beside it (900 specks, 10 mm decay).
    rng = np.random.default_rng(0)
    band = np.abs(rng.uniform(-0.0125, 0.0125, 3000))
    halo = 0.0125 + rng.exponential(0.01, 900)
    profile = edge_profile(np.concatenate([band, halo[halo < 0.05]]))
    assert profile is not None
    assert abs(profile.half_width - 0.0125) < 0.0005
    assert np.all(np.diff(profile.density) <= 1e-12)  # non-increasing
    assert profile.density.min() >= 0.01 and profile.density.max() <= 1.0
    inside, beside, far = profile(np.array([-0.005, 0.002, 0.06]))
    assert inside == 1.0 and 0.2 < beside < 0.45 and far == 0.01
    assert 0.01 < profile.reach < 0.03  # the halo reaches out
    clean = edge_profile(band)
    assert clean is not None and clean.reach < 0.001
    assert abs(clean.half_width - 0.0125) < 0.0002
    # Evenly spaced distances (collinear steps of the distribution) still give a profile.
    even = edge_profile(np.linspace(0.0, 0.0125, 200))
    assert even is not None and abs(even.half_width - 0.0125) < 0.0002
    assert edge_profile(np.full(50, 0.003)) is None  # no spread, no band


# --------------------------------------------------------------------------- shapes


def test_round_caps_end_at_their_centres():
    # The paint reaches ~12 mm (the ragged local half width) past each end. Over ten strokes
    # the estimate ends 1 mm from the line's end on average (1.0 mm over 40 strokes, 95 % of
    # the ends within 2.2 mm) and never beyond 3.5 mm.
    errors, trims = [], []
    for seed in range(10):
        ends = ends_on_line(painted_stroke(LINE, NORMALS, caps=True, seed=seed))
        assert ends.shapes == ("round", "round"), seed
        errors += [ends.start - 0.0, ends.end - 0.5]
        trims += list(ends.trims)
    errors_mm = 1e3 * np.abs(errors)
    assert errors_mm.mean() < 1.5
    assert errors_mm.max() < 3.5
    assert min(trims) > 0.008 and max(trims) < 0.017


def test_a_sparse_last_stretch_of_line_is_not_taken_for_a_halo():
    # The line's last 150 mm hold a quarter of the band's paint (a steep face seen at a
    # grazing angle, few frames): below half the band's density, but line, not halo. Over
    # eight strokes the end stays within 2.6 mm of the line's end, trimmed by a cap's 2-9 mm
    # (measured against the whole line's density, ends fell up to 48 mm short).
    errors, trims = [], []
    for seed in range(8):
        band = painted_stroke(LINE, NORMALS, caps=True, seed=seed)
        sparse = np.random.default_rng(seed).random(len(band)) < 0.25
        found = ends_on_line(band[(band[:, 0] < 0.35) | sparse])  # the line runs along x
        errors.append(found.end - 0.5)
        trims.append(found.trims[1])
    assert 1e3 * np.abs(errors).max() < 4.0
    assert max(trims) < 0.015


def test_a_curve_between_a_meshs_wires_is_not_cut_back_within_its_paint() -> None:
    from scrapcut_cli.fitting.ends import past_paint

    # A 25 mm stroke on a mesh: paint only on 4 mm wires across it every 40 mm (the first
    # across the start's cap, 9 mm before the line begins, narrowed to its chord) and on one
    # wire along the line at the band's edge, 11 mm aside. The curve follows the stroke's
    # centre from x = 0: its first 25 mm lie more than 4 mm from any paint, but within the
    # paint's extent along it, and stay; its 30 mm past the last wire are cut back.
    rng = np.random.default_rng(5)
    wires = []
    for x0 in np.arange(-0.009, 0.30, 0.04):
        half = np.sqrt(0.0125**2 - x0**2) if x0 < 0 else 0.0125
        x = x0 + rng.uniform(-0.002, 0.002, 150)
        wires.append(np.column_stack([x, rng.uniform(-half, half, 150), np.zeros(150)]))
    x = rng.uniform(-0.004, 0.30, 600)
    wires.append(np.column_stack([x, -0.011 + rng.uniform(-0.002, 0.002, 600), np.zeros(600)]))
    paint = np.vstack(wires)
    xs = np.linspace(0.0, 0.321, 322)
    curve = np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs)])
    check = past_paint(curve, paint, tolerance_m=0.004)
    assert check.trims[0] == 0.0
    assert check.trims[1] == pytest.approx(0.321 - 0.293 - 0.004, abs=0.003)
    assert 0.006 < check.reverse_max_m < 0.012  # measured over the gaps all the same


def test_a_square_end_is_kept():
    # Paint that runs off an edge stops square at full width: the line ends at the paint's edge
    # (clean, dense paint: on ragged sparse paint a square end is told from a cap only about
    # half of the time, and then taken for a cap).
    pts = painted_stroke(LINE, NORMALS, seed=0, ragged=0.05, spacing_m=0.0015)
    ends = ends_on_line(pts)
    assert ends.shapes == ("square", "square")
    assert max(ends.trims) < 0.0015
    assert abs(ends.start) < 0.002 and abs(ends.end - 0.5) < 0.002
    capped = ends_on_line(pts, mode="cap")
    assert capped.shapes == ("round", "round")
    assert min(capped.trims) > 0.005


def test_overspray_does_not_carry_the_ends_past_the_caps():
    # The halo reaches past the caps, where the paint's extent now lies. Over six strokes the
    # ends are round caps within 4.5 mm of the line's ends, 1.9 mm on average (over 40
    # strokes 1.8 mm, 95 % within 4.4 mm, at most 6.7 mm). Taking the halo for paint, ends
    # came out square and up to 20 mm beyond the line.
    errors, overshoot = [], []
    for seed in range(6):
        pts = painted_stroke(LINE, NORMALS, caps=True, overspray=OVERSPRAY, seed=seed)
        extent = data_extent(LINE, pts, quantile=0.002, radius=0.03)
        overshoot += [-extent[0], extent[1] - 0.5]
        ends = ends_on_line(pts)
        assert ends.shapes == ("round", "round"), seed
        errors += [0.0 - ends.start, ends.end - 0.5]  # > 0: beyond the line's end
    assert min(overshoot) > 0.018  # the halo does reach far past the caps' 12 mm
    errors_mm = 1e3 * np.array(errors)
    assert np.abs(errors_mm).mean() < 2.5
    assert errors_mm.max() < 5.0
    assert errors_mm.min() > -5.0


@pytest.mark.parametrize("fit", [fit_nurbs, fit_skeleton])
def test_fits_in_overspray_end_at_the_line(fit):
    # Both fitters, from the halo-ridden cloud alone (their own extents and centre lines):
    # neither runs on past the line's end by more than 4 mm (3.1 mm at most here). NURBS ends
    # stop at most 4.4 mm short, the skeleton's 8.5 mm (its voxel path can branch into a
    # dense halo at an end, and the curve then stops short of it).
    errors = []
    for seed in range(4):
        pts = painted_stroke(LINE, NORMALS, caps=True, overspray=OVERSPRAY, seed=seed)
        curve = fit(pts)
        assert curve.info["end_shape"] == ["round", "round"], seed
        x = curve.points[:, 0]
        errors += [-x.min(), x.max() - 0.5]  # > 0: beyond the line's end
    errors_mm = 1e3 * np.array(errors)
    assert errors_mm.max() < 4.0
    assert np.abs(errors_mm).mean() < 3.5
    assert errors_mm.min() > (-5.5 if fit is fit_nurbs else -10.0)


def test_a_wire_across_the_cap_places_the_end():
    line, normals = line_on_plane(BASKET_LENGTH)
    pts = painted_stroke(line, normals, caps=True, gaps=BASKET_GAPS, seed=0)
    ends = ends_on_line(pts, line)
    assert ends.shapes == ("gapped", "gapped")
    assert abs(ends.start) < 0.003
    assert abs(ends.end - BASKET_LENGTH) < 0.003


def test_paint_on_a_wire_along_the_line_ends_by_the_strokes_own_width():
    # A mesh with a 4 mm wire along the middle of the stroke and wires across it every 40 mm:
    # the paint's profile is the wire's (3 mm half width), and a cap read off it put the ends
    # 6-11 mm past the line's (the cap's paint along the wire reaches a whole half width
    # beyond). With the stroke's half width from its edges the envelope places them: never
    # past the line's end by more than a millimetre, 3.5 mm short on average (a ragged
    # stroke's cap is up to 15 % narrower than the stroke; the wire's last sample lies up to
    # a sample's spacing inside it).
    before, after = [], []
    for seed in range(6):
        pts = painted_stroke(LINE, NORMALS, caps=True, seed=seed)
        x, y = pts[:, 0], pts[:, 1]
        across = np.abs((x + 0.027) - 0.04 * np.round((x + 0.027) / 0.04)) <= 0.002
        mesh = pts[(np.abs(y - 0.001) <= 0.002) | across]
        old = ends_on_line(mesh)
        new = ends_on_line(mesh, band_half_width=0.0125)
        assert old.half_width is not None and old.half_width < 0.005
        assert new.shapes == ("gapped", "gapped") and new.half_width == 0.0125
        before += [-old.start, old.end - 0.5]  # how far past the line's ends
        after += [-new.start, new.end - 0.5]
    assert min(before) > 0.006
    assert max(after) < 0.001
    assert -np.mean(after) < 0.0045 and min(after) > -0.0075


def test_a_solid_band_ignores_the_strokes_width():
    # On solid paint the band's own profile is the stroke's: a width from the edges (even a
    # narrower one) changes nothing.
    pts = painted_stroke(LINE, NORMALS, caps=True, seed=1)
    assert ends_on_line(pts, band_half_width=0.0115) == ends_on_line(pts)


def test_isotropic_noise_is_not_a_band():
    # Points scattered around a curve have no band edge to read a cap from: kept as they are.
    pts, ref = noisy_arc(seed=3)
    ends = ends_on_line(pts, ref)
    assert ends.shapes == ("no band", "no band")
    assert ends.trims == (0.0, 0.0)


# --------------------------------------------------------------------------- options, limits


def test_modes_and_fixed_trim():
    pts = painted_stroke(LINE, NORMALS, caps=True, seed=4)
    extent = data_extent(LINE, pts, quantile=0.002, radius=0.03)
    none = stroke_ends(LINE, pts, extent=extent, radius=0.03, mode="none")
    assert (none.start, none.end) == extent
    assert none.shapes == ("none", "none")
    fixed = stroke_ends(LINE, pts, extent=extent, radius=0.03, trim_m=0.01)
    assert fixed.start == pytest.approx(extent[0] + 0.01)
    assert fixed.end == pytest.approx(extent[1] - 0.01)
    assert fixed.shapes == ("fixed", "fixed")
    huge = stroke_ends(LINE, pts, extent=extent, radius=0.03, trim_m=1.0)
    assert huge.end - huge.start == pytest.approx(
        (1.0 - 2.0 * MAX_TRIM_SHARE) * (extent[1] - extent[0])
    )


@pytest.mark.parametrize("fit", [fit_nurbs, fit_skeleton])
def test_a_dab_keeps_half_its_length(fit):
    # A stroke no longer than it is wide (a dab 2 mm long, 25 mm wide): trimming by the caps
    # would leave nothing; each end moves in by at most a quarter of the paint's extent.
    line, normals = line_on_plane(0.002, 3)
    pts = painted_stroke(line, normals, caps=True, spacing_m=0.001, seed=5)
    curve = fit(pts)
    trims = curve.info["end_trim_m"]
    assert curve.length > 0.45 * (curve.length + sum(trims))
    assert curve.length < 0.03


def test_the_same_cloud_twice_ends_at_the_same_place():
    pts = painted_stroke(LINE, NORMALS, caps=True, seed=6)
    once, twice = ends_on_line(pts), ends_on_line(np.vstack([pts, pts]))
    assert once.start == twice.start and once.end == twice.end


def test_info_follows_the_curve_direction():
    ends = StrokeEnds(0.01, 0.4, 0.0125, (0.01, 0.012), ("round", "square"))
    info = ends.info(mode="auto", forward=False)
    assert info["end_trim_m"] == [0.012, 0.01]
    assert info["end_trim_start_m"] == 0.012 and info["end_trim_end_m"] == 0.01
    assert info["end_shape"] == ["square", "round"]
    assert info["stroke_half_width_m"] == 0.0125 and info["end_trim"] == "auto"


@pytest.mark.parametrize(
    ("fit", "config", "message"),
    [
        (fit_nurbs, NurbsConfig(end_trim="cut"), "unknown nurbs.end_trim 'cut'; known: auto"),
        (fit_nurbs, NurbsConfig(end_trim_m=-0.01), "nurbs.end_trim_m must be a length >= 0"),
        (fit_skeleton, SkeletonConfig(end_trim="cut"), "unknown skeleton.end_trim 'cut'"),
    ],
)
def test_bad_end_options_raise_one_line(fit, config, message):
    pts = painted_stroke(*line_on_plane(0.2), seed=1)
    with pytest.raises(FittingError, match=message.replace("(", r"\(")):
        fit(pts, config=config)


# --------------------------------------------------------------------------- past the paint


def test_what_runs_past_the_paint_is_cut_back_and_measured() -> None:
    from scrapcut_cli.fitting import trim_to_paint
    from scrapcut_cli.fitting.curve import Curve, NurbsModel
    from scrapcut_cli.fitting.ends import past_paint

    paint = painted_stroke(LINE, NORMALS, caps=True, seed=3)  # the line runs 0-0.5 m along x
    # A curve 27 mm too long at the end (an extrapolated spline), straight on past the cap.
    x = np.linspace(0.0, 0.527, 528)
    long = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    check = past_paint(long, paint, tolerance_m=0.004)
    assert check.trims[0] == pytest.approx(0.0)
    # The cap reaches ~12.5 mm past 0.5 m: the curve may go as far as its rim, not further.
    assert check.trims[1] == pytest.approx(0.527 - 0.5125 - 0.004, abs=0.003)
    assert check.reverse_max_m <= 0.004 + 1e-9
    # A clamped cubic through the same line, its domain cut back with it.
    ctrl = np.column_stack([np.linspace(0.0, 0.527, 6), np.zeros(6), np.zeros(6)])
    knots = np.array([0, 0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1, 1], dtype=float)
    curve = Curve(long, "nurbs", NurbsModel(3, knots, ctrl, np.ones(6)), 0.001)
    trimmed = trim_to_paint(curve, paint, tolerance_m=0.004)
    end = trimmed.points[-1, 0]
    assert end == pytest.approx(0.527 - check.trims[1], abs=0.001)
    assert trimmed.nurbs is not None
    assert trimmed.nurbs.evaluate([1.0])[0, 0] == pytest.approx(end, abs=0.001)
    assert trimmed.info["paint_trim_m"][1] == pytest.approx(check.trims[1])
    assert trimmed.info["reverse_max_m"] <= 0.004 + 1e-9
    # A curve within its paint is left alone (only measured).
    inside = Curve(long[:480], "skeleton", None, 0.001)
    same = trim_to_paint(inside, paint, tolerance_m=0.004)
    assert np.array_equal(same.points, inside.points)
    assert same.info["paint_trim_m"] == [0.0, 0.0]
