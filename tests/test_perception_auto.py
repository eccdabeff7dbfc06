"""Tests of scrapcut_cli.perception.auto: the paint's range estimated from the images.

Small synthetic images (240 x 320): a grey steel background with shading and noise, rust
patches (orange-brown, S ~0.7), a crate of the paint's colour (compact) and the painted stroke
(a curved band) in a can's colour near a preset's.
"""

from __future__ import annotations

import colorsys

import numpy as np
import pytest

from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.perception.auto import estimate_paint
from scrapcut_cli.perception.paint import PAINT_PRESETS, paint_mask

H, W = 240, 320
RUST = (140, 76, 44)  # S 0.69


def can(preset: str) -> tuple[int, int, int]:
    """A can near the preset: hue +3 deg, saturation and value a little lower."""
    r, g, b = (c / 255.0 for c in PAINT_PRESETS[preset].rgb)
    h, s, v = colorsys.rgb_to_hsv(r, g, b)
    rgb = colorsys.hsv_to_rgb((h + 3.0 / 360.0) % 1.0, 0.93 * s, 0.9 * v)
    return (round(255 * rgb[0]), round(255 * rgb[1]), round(255 * rgb[2]))


def image(
    paint: tuple[int, int, int] | None, *, seed: int, crate: bool = True, rust: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(image, stroke mask, rust mask) of one synthetic frame."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:H, 0:W]
    rgb = np.empty((H, W, 3))
    rgb[:] = (118, 121, 127)
    rust_mask = np.zeros((H, W), dtype=bool)
    if rust:
        for _ in range(5):
            cu, cv, r = rng.uniform(0, W), rng.uniform(0, H), rng.uniform(15, 35)
            rust_mask |= (u - cu) ** 2 + (v - cv) ** 2 < r * r
        rgb[rust_mask] = RUST
    stroke = np.zeros((H, W), dtype=bool)
    if paint is not None:
        centre = H / 2 + 40 * np.sin(2 * np.pi * u / W + rng.uniform(0, 6))
        stroke = np.abs(v - centre) < 12
        rgb[stroke] = paint
        if crate:
            box = (u > W - 70) & (v < 60)
            rgb[box] = paint
            stroke &= ~box
            rust_mask &= ~box
    shade = 0.55 + 0.45 * (u / W)  # lit from one side
    rgb = rgb * shade[:, :, None] + rng.normal(0, 2.0, rgb.shape)
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8), stroke, rust_mask & ~stroke


@pytest.mark.parametrize("preset", list(PAINT_PRESETS))
def test_auto_finds_every_paint_and_leaves_rust_out(preset: str) -> None:
    frames = [image(can(preset), seed=s) for s in range(4)]
    estimate = estimate_paint(f[0] for f in frames)
    assert estimate.preset == preset
    assert estimate.images == 4
    assert "auto:" in estimate.describe() and f"{preset}-like" in estimate.describe()
    stroke = np.mean([paint_mask(f[0], estimate.hsv)[f[1]].mean() for f in frames])
    rust = np.mean([paint_mask(f[0], estimate.hsv)[f[2]].mean() for f in frames])
    assert stroke > 0.97
    assert rust < 0.01
    # The preset's own range takes orange-brown rust too: the estimate is the paint's cluster.
    if preset == "orange":
        preset_rust = np.mean(
            [paint_mask(f[0], PAINT_PRESETS[preset].hsv)[f[2]].mean() for f in frames]
        )
        assert preset_rust > 0.5


def test_compact_blobs_are_no_paint() -> None:
    crate_only = [image(None, seed=s)[0] for s in range(2)]
    for frame in crate_only:
        frame[:60, W - 70 :] = PAINT_PRESETS["blue"].rgb
    with pytest.raises(PerceptionError) as info:
        estimate_paint(crate_only)
    message = str(info.value)
    assert "no stroke-like saturated colour" in message and "\n" not in message
    assert "220 deg" in message or "215 deg" in message or "225 deg" in message


def test_grey_images_name_no_hue() -> None:
    with pytest.raises(PerceptionError, match="the images are grey"):
        estimate_paint([image(None, seed=0, rust=False)[0]])
    with pytest.raises(PerceptionError, match="no images"):
        estimate_paint([])
