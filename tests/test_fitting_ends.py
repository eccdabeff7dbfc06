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
    ],
)
def test_half_width_of_a_painted_band(options, tolerance_mm):
    # A 25 mm ragged band (+-15 % about 12.5 mm): plain; with 2 mm noise and 5 % outliers; only
    # on the wires of a basket.
    pts = painted_stroke(LINE, NORMALS, caps=True, seed=1, **options)
    dist, pos = extended_positions(LINE, pts)
    near = dist <= 0.03
    half = stroke_half_width(dist[near], pos[near], 0.0, 0.5)
    assert half is not None
    assert abs(half - 0.0125) < tolerance_mm * 1e-3


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


def test_a_wire_across_the_cap_places_the_end():
    line, normals = line_on_plane(BASKET_LENGTH)
    pts = painted_stroke(line, normals, caps=True, gaps=BASKET_GAPS, seed=0)
    ends = ends_on_line(pts, line)
    assert ends.shapes == ("gapped", "gapped")
    assert abs(ends.start) < 0.003
    assert abs(ends.end - BASKET_LENGTH) < 0.003


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
