"""The paint colour filter: presets on synthetic colours, hue wrap-around, exactness, hues."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import hsv_to_rgb, rgb_to_hsv

from scrapcut_cli.config import PaintConfig
from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.perception.paint import (
    PAINT_PRESETS,
    HsvRange,
    HueHistogram,
    dominant_hues,
    paint_mask,
    paint_pixel_indices,
    resolve_paint,
    resolve_recording_paint,
    rgb_to_hsv_deg,
)


def image_of(colors: list[tuple[int, int, int]] | np.ndarray) -> np.ndarray:
    """A (1, N, 3) uint8 image, one pixel per colour."""
    return np.asarray(colors, dtype=np.uint8).reshape(1, -1, 3)


def colour_with_hsv(hue_deg: float, sat: float, val: float) -> tuple[int, int, int]:
    rgb = np.rint(hsv_to_rgb([hue_deg / 360.0, sat, val]) * 255.0).astype(int)
    return int(rgb[0]), int(rgb[1]), int(rgb[2])


def reference_mask(colors: np.ndarray, hsv: HsvRange) -> tuple[np.ndarray, np.ndarray]:
    """matplotlib's HSV test, and which colours lie within 1e-6 of a threshold (ambiguous)."""
    h_s_v = rgb_to_hsv(colors.astype(np.float64) / 255.0)
    h, s, v = h_s_v[:, 0] * 360.0, h_s_v[:, 1], h_s_v[:, 2]
    if hsv.wraps:
        in_hue = (h >= hsv.hue_min_deg) | (h <= hsv.hue_max_deg)
    else:
        in_hue = (h >= hsv.hue_min_deg) & (h <= hsv.hue_max_deg)
    mask = in_hue & (s >= hsv.sat_min) & (v >= hsv.val_min)
    eps = 1e-6
    near = (
        (np.abs(h - hsv.hue_min_deg) < eps)
        | (np.abs(h - hsv.hue_max_deg) < eps)
        | (np.abs(s - hsv.sat_min) < eps)
        | (np.abs(v - hsv.val_min) < eps)
    )
    return mask, near


# --------------------------------------------------------------------------- presets


@pytest.mark.parametrize("name", list(PAINT_PRESETS))
def test_every_preset_finds_its_paint_in_light_and_shadow(name: str) -> None:
    rgb = np.array(PAINT_PRESETS[name].rgb, dtype=np.float64)
    # Shading from a light near the camera scales R, G and B together (0.45: deep shadow).
    shades = np.array([1.0, 0.8, 0.6, 0.45])
    colors = np.rint(rgb[None, :] * shades[:, None]).astype(np.uint8)
    assert paint_mask(image_of(colors), PAINT_PRESETS[name].hsv).all()


@pytest.mark.parametrize("name", list(PAINT_PRESETS))
def test_presets_do_not_claim_each_others_paint(name: str) -> None:
    others = [p.rgb for other, p in PAINT_PRESETS.items() if other != name]
    assert not paint_mask(image_of(others), PAINT_PRESETS[name].hsv).any()


@pytest.mark.parametrize("name", list(PAINT_PRESETS))
def test_no_preset_takes_steel_concrete_black_or_white(name: str) -> None:
    neutral = [(118, 121, 127), (90, 90, 92), (160, 158, 150), (0, 0, 0), (255, 255, 255)]
    assert not paint_mask(image_of(neutral), PAINT_PRESETS[name].hsv).any()


def test_orange_rejects_dull_rust_by_saturation_although_the_hue_matches() -> None:
    orange = PAINT_PRESETS["orange"].hsv
    # Dull rust (S <= 0.60) at every shade. Iron oxide can reach S ~0.75 and pass the range:
    # the frame's saturation clusters tell it apart (tests/test_perception_cloud.py).
    rust = [
        colour_with_hsv(h, s, v)
        for h in (14.0, 22.0, 30.0)
        for s in (0.30, 0.50, 0.60)
        for v in (0.22, 0.52, 0.9)
    ]
    hues = rgb_to_hsv_deg(np.asarray(rust, dtype=np.uint8))[:, 0]
    assert np.all((hues >= orange.hue_min_deg) & (hues <= orange.hue_max_deg))
    assert not paint_mask(image_of(rust), orange).any()


def test_value_floor_rejects_paint_in_darkness() -> None:
    orange = PAINT_PRESETS["orange"]
    dark = np.rint(np.array(orange.rgb) * 0.2).astype(np.uint8)  # V = 0.2 < 0.25
    assert not paint_mask(image_of([tuple(dark)]), orange.hsv).any()


# --------------------------------------------------------------------------- hue wrap-around


def test_custom_range_wraps_through_zero_degrees() -> None:
    reds = HsvRange(350.0, 10.0, 0.5, 0.2)
    assert reds.wraps
    inside = [colour_with_hsv(h, 0.9, 0.9) for h in (351.0, 355.0, 359.5, 0.0, 5.0, 9.5)]
    outside = [colour_with_hsv(h, 0.9, 0.9) for h in (12.0, 30.0, 180.0, 340.0, 348.0)]
    assert paint_mask(image_of(inside), reds).all()
    assert not paint_mask(image_of(outside), reds).any()


def test_pink_preset_wraps() -> None:
    pink = PAINT_PRESETS["pink"].hsv
    assert pink.wraps
    inside = [colour_with_hsv(h, 0.9, 0.9) for h in (315.0, 337.0, 359.0, 3.0, 9.0)]
    outside = [colour_with_hsv(h, 0.9, 0.9) for h in (15.0, 300.0)]
    assert paint_mask(image_of(inside), pink).all()
    assert not paint_mask(image_of(outside), pink).any()


def test_full_hue_circle_takes_every_saturated_colour() -> None:
    everything = HsvRange(0.0, 360.0, 0.5, 0.2)
    colors = [colour_with_hsv(h, 0.8, 0.8) for h in range(0, 360, 7)]
    assert paint_mask(image_of(colors), everything).all()


# --------------------------------------------------------------------------- exactness


RANGES = [
    *(p.hsv for p in PAINT_PRESETS.values()),
    HsvRange(350.0, 10.0, 0.5, 0.2),
    HsvRange(100.0, 100.5, 0.1, 0.1),
    HsvRange(0.0, 360.0, 0.0, 0.0),
    HsvRange(200.0, 20.0, 0.0, 0.5),  # wraps, and greys (hue 0) are inside
    HsvRange(20.0, 200.0, 0.0, 0.5),  # greys (hue 0) are outside
]


@pytest.mark.parametrize("hsv", RANGES, ids=lambda r: r.describe())
def test_mask_equals_the_hsv_definition_on_random_colours(hsv: HsvRange) -> None:
    rng = np.random.default_rng(7)
    colors = rng.integers(0, 256, size=(60_000, 3), dtype=np.uint8)
    colors[:500] = np.repeat(rng.integers(0, 256, size=(500, 1), dtype=np.uint8), 3, axis=1)
    expected, ambiguous = reference_mask(colors, hsv)
    got = paint_mask(colors.reshape(200, 300, 3), hsv).reshape(-1)
    assert np.array_equal(got[~ambiguous], expected[~ambiguous])
    assert ambiguous.mean() < 0.02  # the test keeps its teeth: few colours are excused


def test_rgb_to_hsv_deg_matches_matplotlib() -> None:
    rng = np.random.default_rng(3)
    colors = rng.integers(0, 256, size=(20_000, 3), dtype=np.uint8)
    ours = rgb_to_hsv_deg(colors)
    theirs = rgb_to_hsv(colors / 255.0) * np.array([360.0, 1.0, 1.0])
    np.testing.assert_allclose(ours, theirs, atol=1e-9)


def test_indices_are_flat_and_ascending_and_input_is_unchanged() -> None:
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, size=(30, 40, 3), dtype=np.uint8)
    image[5, 7] = PAINT_PRESETS["orange"].rgb
    before = image.copy()
    idx = paint_pixel_indices(image, PAINT_PRESETS["orange"].hsv)
    assert np.all(np.diff(idx) > 0)
    assert 5 * 40 + 7 in idx
    mask = paint_mask(image, PAINT_PRESETS["orange"].hsv)
    assert mask.shape == (30, 40) and mask.dtype == bool
    assert np.array_equal(np.flatnonzero(mask), idx)
    assert np.array_equal(image, before)


def test_bad_images_and_ranges_raise() -> None:
    with pytest.raises(PerceptionError, match="uint8"):
        paint_mask(np.zeros((4, 4, 3), dtype=np.float32), PAINT_PRESETS["orange"].hsv)
    with pytest.raises(PerceptionError, match=r"\(H, W, 3\)"):
        paint_mask(np.zeros((4, 4), dtype=np.uint8), PAINT_PRESETS["orange"].hsv)
    with pytest.raises(PerceptionError, match="hue_min_deg"):
        HsvRange(-5.0, 10.0, 0.5, 0.5)
    with pytest.raises(PerceptionError, match="sat_min"):
        HsvRange(5.0, 10.0, 1.5, 0.5)


# --------------------------------------------------------------------------- choosing the paint


def test_resolve_paint_preset_custom_and_unknown() -> None:
    assert resolve_paint(PaintConfig()) == PAINT_PRESETS["orange"].hsv
    assert resolve_paint(PaintConfig(preset="blue")) == PAINT_PRESETS["blue"].hsv
    custom = resolve_paint(PaintConfig(hsv=(350.0, 10.0, 0.5, 0.3)))
    assert (custom.hue_min_deg, custom.hue_max_deg, custom.name) == (350.0, 10.0, "custom")
    with pytest.raises(PerceptionError, match="unknown paint preset 'teal'"):
        resolve_paint(PaintConfig(preset="teal"))
    # From a TOML [paint] table, which the command line's --hsv parser never sees.
    for bad in ((10.0, 40.0), (10.0, 40.0, "x", 0.3), (10.0, 40.0, 0.5, 0.3, 1.0)):
        with pytest.raises(PerceptionError, match=r"paint\.hsv must be four numbers"):
            resolve_paint(PaintConfig(hsv=bad))  # type: ignore[arg-type]
    with pytest.raises(PerceptionError, match="hue_max_deg must be within 0-360"):
        resolve_paint(PaintConfig(hsv=(10.0, 400.0, 0.5, 0.3)))


def test_recording_paint_is_the_default_and_explicit_choices_win() -> None:
    meta = {"scrapcut": {"paint": "green", "object": "cylinder"}}
    assert resolve_recording_paint(PaintConfig(), meta) == PAINT_PRESETS["green"].hsv
    # No paint named by the user nor the recording: estimate it from the images (auto).
    assert resolve_recording_paint(PaintConfig(), {}) is None
    assert resolve_recording_paint(PaintConfig(), None) is None
    assert resolve_recording_paint(PaintConfig(preset="auto"), meta) is None
    assert resolve_recording_paint(PaintConfig(preset="pink"), meta) == PAINT_PRESETS["pink"].hsv
    explicit = PaintConfig(preset="orange")  # the default's name, but chosen: it wins
    assert resolve_recording_paint(explicit, meta) == PAINT_PRESETS["orange"].hsv
    custom = resolve_recording_paint(PaintConfig(hsv=(1.0, 2.0, 0.5, 0.5)), meta)
    assert custom is not None and custom.name == "custom"
    with pytest.raises(PerceptionError, match="auto estimates the colour from a recording"):
        resolve_paint(PaintConfig(preset="auto"))


# --------------------------------------------------------------------------- dominant hues


def test_dominant_hues_name_the_colours_shown() -> None:
    image = np.full((40, 40, 3), 110, dtype=np.uint8)  # grey: not counted
    image[:24, :] = (20, 90, 230)  # blue, hue 220 deg -> bin centred on 210
    image[24:36, :] = PAINT_PRESETS["orange"].rgb  # hue 26 deg -> bin centred on 30
    hues = dominant_hues([image, image])
    assert [h for h, _ in hues] == [210.0, 30.0]
    np.testing.assert_allclose([s for _, s in hues], [2 / 3, 1 / 3], atol=1e-12)


def test_red_hues_on_both_sides_of_zero_share_one_bin() -> None:
    image = image_of([colour_with_hsv(355.0, 0.9, 0.9), colour_with_hsv(5.0, 0.9, 0.9)] * 8)
    histogram = HueHistogram(stride=1)
    histogram.add(image)
    assert histogram.dominant() == [(0.0, 1.0)]
    assert histogram.describe() == "0 deg (100%)"


def test_grey_images_have_no_dominant_hue() -> None:
    histogram = HueHistogram()
    histogram.add(np.full((16, 16, 3), 128, dtype=np.uint8))
    assert histogram.dominant() == []
    assert histogram.colourful_share() == 0.0
    assert "no saturated colours" in histogram.describe()


def test_unit_histogram_counts_as_numpy() -> None:
    """The saturation histogram's lean path bins every value as np.histogram does: all byte
    saturations (float32), values on and one ulp either side of every edge (float32 and
    float64), random values; NaN, values outside 0-1 and other dtypes go to numpy itself."""
    from scrapcut_cli.perception.paint import _BINS, unit_histogram

    cmax = np.repeat(np.arange(256), 256)
    chroma = np.tile(np.arange(256), 256)
    keep = chroma <= cmax
    sat = chroma[keep].astype(np.float32) / np.maximum(cmax[keep].astype(np.float32), 1.0)
    rng = np.random.default_rng(0)
    cases: list[np.ndarray] = [sat, rng.random(50_000), rng.random(7).astype(np.float32)]
    for dtype in (np.float32, np.float64):
        edges = np.histogram(np.zeros(1, dtype=dtype), bins=_BINS, range=(0.0, 1.0))[1]
        near = np.concatenate(
            [edges, np.nextafter(edges, dtype(-1.0)), np.nextafter(edges, dtype(2.0))]
        ).astype(dtype)
        cases.append(near[(near >= 0) & (near <= 1)])
    cases += [np.array([0.5, np.nan]), np.array([-0.1, 0.5, 1.5]), np.array([0, 1, 1])]
    for values in cases:
        counts, edges = unit_histogram(values)
        expected, expected_edges = np.histogram(values, bins=_BINS, range=(0.0, 1.0))
        np.testing.assert_array_equal(counts, expected)
        np.testing.assert_array_equal(edges, expected_edges)
        assert edges.dtype == expected_edges.dtype
