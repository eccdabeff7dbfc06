"""Tests of scrapcut_cli.sim.surface: seeded textures, rust colours, the paint stroke, shading."""

from __future__ import annotations

import colorsys

import numpy as np
import pytest
from helpers import arc

from scrapcut_cli.geometry import PolylineDistance, cumulative_length
from scrapcut_cli.perception.paint import PAINT_PRESETS
from scrapcut_cli.sim.surface import (
    OVERSPRAY_PRESETS,
    STEEL_GLINT,
    MetalFinish,
    PaintStroke,
    faded_rgb,
    hash01,
    lambert,
    metal_albedo,
    paint_can_rgb,
    shiny_steel,
    specular,
    value_noise,
)


def hsv(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) hue degrees, saturation, value of sRGB in 0-1."""
    return np.array([colorsys.rgb_to_hsv(*c) for c in rgb]) * [360.0, 1.0, 1.0]


def test_hash01_is_uniform_deterministic_and_independent_of_the_batch() -> None:
    keys = np.stack(np.meshgrid(np.arange(60), np.arange(60), np.arange(30)), -1).reshape(-1, 3)
    u = hash01(keys, seed=3)
    assert u.min() >= 0.0 and u.max() < 1.0
    assert u.mean() == pytest.approx(0.5, abs=0.005)
    assert u.std() == pytest.approx(np.sqrt(1 / 12), abs=0.005)
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.01
    assert np.array_equal(hash01(keys[1234:1235], seed=3), u[1234:1235])
    assert not np.allclose(hash01(keys, seed=4), u)


def test_value_noise_interpolates_lattice_values_smoothly() -> None:
    lattice = np.array([[1, 2, 3], [-4, 5, 0]])
    assert np.allclose(value_noise(lattice * 0.05, 0.05, 7), hash01(lattice, 7))
    rng = np.random.default_rng(0)
    p = rng.uniform(-1, 1, (2000, 3))
    v = value_noise(p, 0.05, 7, octaves=3)
    assert v.min() >= 0.0 and v.max() < 1.0
    # Continuous: 10 µm apart never differ by more than the steepest smoothstep slope allows.
    dv = np.abs(value_noise(p + 1e-5, 0.05, 7) - value_noise(p, 0.05, 7))
    assert dv.max() < 3 * 1.5 * 1e-5 / 0.05


def test_rust_is_orange_brown_at_iron_oxide_saturation_and_steel_is_grey() -> None:
    rng = np.random.default_rng(1)
    points = rng.uniform(-0.5, 0.5, (40000, 3))
    finish = MetalFinish(rust_fraction=0.35)
    albedo, rust = metal_albedo(points, finish, seed=2)
    assert rust.mean() == pytest.approx(0.35, abs=0.05)
    h = hsv(albedo[rust])
    assert h[:, 0].min() >= 10.0 and h[:, 0].max() <= 35.0  # the orange paint's hue range
    # Iron oxides reach S ~0.7: a good share of rust is as saturated as the orange filter
    # accepts (0.65), none as saturated as fresh fluorescent paint (S >= 0.85).
    assert 0.1 < np.mean(h[:, 1] >= 0.65) < 0.6
    assert h[:, 1].max() <= 0.8
    assert h[:, 2].max() <= 0.65
    steel = hsv(albedo[~rust])
    assert steel[:, 1].max() <= 0.08


@pytest.mark.parametrize("name", list(PAINT_PRESETS))
def test_every_can_sprays_near_its_preset_but_not_on_it(name: str) -> None:
    preset = PAINT_PRESETS[name]
    nominal = hsv(np.array([preset.rgb]) / 255.0)[0]
    cans = [paint_can_rgb(preset.rgb, np.random.default_rng(seed)) for seed in range(40)]
    h = hsv(np.array(cans) / 255.0)
    hue_gap = (h[:, 0] - nominal[0] + 180.0) % 360.0 - 180.0
    assert np.abs(hue_gap).max() <= 6.5 and hue_gap.std() > 2.0
    assert np.all(h[:, 1] <= nominal[1] + 0.01) and h[:, 1].min() >= 0.84 * nominal[1] - 0.01
    assert np.all(h[:, 2] < nominal[2]) and h[:, 2].min() >= 0.79 * nominal[2] - 0.01
    assert len(set(cans)) > 30
    assert tuple(preset.rgb) not in cans


def test_old_marks_keep_the_hue_family_and_fade() -> None:
    can = (236, 103, 8)
    faded = np.array([faded_rgb(can, np.random.default_rng(s)) for s in range(40)]) / 255.0
    h, h_can = hsv(faded), hsv(np.array([can]) / 255.0)[0]
    assert np.abs(h[:, 0] - h_can[0]).max() <= 10.5
    assert np.all(h[:, 1] <= 0.81 * h_can[1]) and np.all(h[:, 1] >= 0.54 * h_can[1])
    assert np.all(h[:, 2] <= 0.86 * h_can[2]) and np.all(h[:, 2] >= 0.54 * h_can[2])


def test_a_worn_stroke_keeps_the_rest_of_its_paint() -> None:
    fresh = PaintStroke(arc(600, radius=0.15, angle=2.0), width_m=0.025, rgb=(1, 2, 3), seed=9)
    worn = PaintStroke(
        arc(600, radius=0.15, angle=2.0), width_m=0.025, rgb=(1, 2, 3), seed=9, wear=0.4
    )
    p = points_around(fresh.reference, 40000, 0.01, seed=7)
    a, b = fresh.layer(p), worn.layer(p)
    assert not (b.stroke & ~a.stroke).any()  # wear only takes paint away
    assert b.stroke.sum() / a.stroke.sum() == pytest.approx(0.6, abs=0.08)
    # A full coat inside, thinner over the last 1.5 mm of the edge.
    dist = PolylineDistance(fresh.reference).distance(p)
    inner = a.stroke & (dist < fresh.min_half_width_m - 0.003)
    assert np.all(a.opacity[inner] == 1.0)
    assert a.opacity[a.stroke].min() >= fresh.EDGE_OPACITY - 1e-9
    assert np.all(a.opacity[~a.paint] == 0.0)


def test_glints_are_small_spots_facing_the_light() -> None:
    rng = np.random.default_rng(3)
    p = rng.uniform(-0.5, 0.5, (50000, 3))
    shiny = shiny_steel(p, seed=1)
    assert shiny.mean() == pytest.approx(0.12, abs=0.03)
    normals = np.tile([0.0, 0.0, 1.0], (3, 1))
    points = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.1, 0.0, 0.0]])
    light = eye = np.array([0.0, 0.0, 0.3])
    glow = specular(normals, points, light, eye, STEEL_GLINT)
    assert glow[0] == pytest.approx(STEEL_GLINT.strength)  # mirrored straight back
    assert glow[2] < 1e-3 * glow[0] and glow[0] > glow[1] > glow[2]


def make_stroke(overspray: str = "light", width: float = 0.025) -> PaintStroke:
    return PaintStroke(
        arc(600, radius=0.15, angle=2.0),
        width_m=width,
        rgb=(255, 110, 0),
        overspray=OVERSPRAY_PRESETS[overspray],
        seed=9,
    )


def points_around(reference: np.ndarray, n: int, spread: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = reference[rng.integers(0, len(reference), n)]
    return np.asarray(base + rng.normal(scale=spread, size=(n, 3)))


def test_stroke_matches_the_exact_polyline_distance() -> None:
    stroke = make_stroke("none")
    p = points_around(stroke.reference, 30000, 0.012, seed=3)
    painted, specks = stroke.coverage(p)
    assert not specks.any()
    dist, _, param = PolylineDistance(stroke.reference).query(p)
    s_ref = cumulative_length(stroke.reference)
    seg = np.minimum(param.astype(int), len(s_ref) - 2)
    arc_len = s_ref[seg] + (param - seg) * (s_ref[seg + 1] - s_ref[seg])
    edge = stroke.EDGE_ROUGHNESS_M * (2 * value_noise(p, stroke.EDGE_SCALE_M, 9 + 103) - 1)
    margin = dist - (stroke.half_width(arc_len) + edge)
    decided = np.abs(margin) > 2e-6  # the table and the exact search agree off the edge itself
    assert decided.mean() > 0.99
    assert np.array_equal(painted[decided], margin[decided] < 0)
    assert dist[painted].max() <= stroke.max_half_width_m
    assert painted[dist < stroke.min_half_width_m].all()


def test_stroke_width_is_ragged_along_the_line() -> None:
    stroke = make_stroke()
    half = stroke.half_width(np.linspace(0.0, 0.3, 3000))
    assert half.min() >= 0.5 * 0.025 * 0.85 - 1e-12 and half.max() <= 0.5 * 0.025 * 1.15
    assert half.max() - half.min() > 0.15 * 0.5 * 0.025


def test_overspray_specks_lie_beside_the_stroke_and_thin_out() -> None:
    light, heavy = make_stroke("light"), make_stroke("heavy")
    p = points_around(light.reference, 60000, 0.03, seed=4)
    dist = PolylineDistance(light.reference).distance(p)
    painted, specks = light.coverage(p)
    assert not (painted & specks).any()
    assert specks.any()
    assert dist[specks].min() >= light.min_half_width_m
    assert dist[specks].max() <= light.max_half_width_m + light.overspray.band_m
    near = (dist > light.max_half_width_m) & (dist < light.max_half_width_m + 0.005)
    far = (dist > light.max_half_width_m + 0.015) & (dist < light.max_half_width_m + 0.025)
    assert specks[near].mean() > 3 * specks[far].mean()
    assert heavy.coverage(p)[1].sum() > 1.5 * specks.sum()


def test_coverage_leaves_its_input_alone_and_is_deterministic() -> None:
    stroke = make_stroke()
    p = points_around(stroke.reference, 5000, 0.02, seed=5)
    before = p.copy()
    a = stroke.coverage(p)
    b = make_stroke().coverage(p)
    assert np.array_equal(p, before)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_lambert_head_on_is_full_light_and_grazing_is_ambient() -> None:
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    points = np.zeros((2, 3))
    shade = lambert(normals, points, (0.0, 0.0, 0.3), ambient=0.35)
    assert shade == pytest.approx([1.0, 0.35])
