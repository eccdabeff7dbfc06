"""Marking-paint colours: the one table of presets, shared by the filter and the simulator.

Hue in degrees (0–360, a range with ``hue_min_deg > hue_max_deg`` wraps through 0 — reds and
pinks), saturation and value in 0–1 (HSV of sRGB bytes / 255, as OpenCV / matplotlib define
them).

Why saturation matters: rusty steel is orange-brown, within the hue range of orange marking
paint. Fluorescent marking paints are strongly saturated (S > 0.8 when lit); rust, mill scale
and bare steel are dull (S about 0.25–0.6, V below about 0.6). Shading from a light near the
camera scales R, G and B together, which lowers V but keeps S, so the thresholds below are low
on value (shadowed paint is still paint) and high on saturation (rust is not).

| preset | nominal sRGB | hue range (deg) | S min | V min |
|--------|--------------|-----------------|-------|-------|
| orange | 255, 110, 0  | 8 – 42          | 0.65  | 0.25  |
| pink   | 255, 40, 120 | 310 – 10 (wraps)| 0.55  | 0.25  |
| yellow | 255, 220, 0  | 45 – 70         | 0.60  | 0.35  |
| green  | 40, 200, 60  | 85 – 165        | 0.45  | 0.20  |
| blue   | 20, 90, 230  | 190 – 250       | 0.50  | 0.20  |

The nominal sRGB is the colour of the paint under full white light; the simulator paints with
it. Numbers chosen from typical fluorescent marking-paint swatches and checked against the
simulator's rust palette (``sim`` keeps rust at S <= 0.60), see ``tests/test_perception_paint.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

from scrapcut_cli.config import PaintConfig
from scrapcut_cli.errors import PerceptionError


@dataclass(frozen=True)
class HsvRange:
    """An HSV box: hue interval in degrees (wrapping when min > max), lower bounds on S and V."""

    hue_min_deg: float
    hue_max_deg: float
    sat_min: float
    val_min: float
    name: str = "custom"

    def __post_init__(self) -> None:
        for label, h in (("hue_min_deg", self.hue_min_deg), ("hue_max_deg", self.hue_max_deg)):
            if not 0.0 <= h <= 360.0:
                raise PerceptionError(f"{label} must be within 0-360 degrees, got {h}")
        for label, x in (("sat_min", self.sat_min), ("val_min", self.val_min)):
            if not 0.0 <= x <= 1.0:
                raise PerceptionError(f"{label} must be within 0-1, got {x}")

    @property
    def wraps(self) -> bool:
        """True when the hue interval passes through 0/360 degrees."""
        return self.hue_min_deg > self.hue_max_deg

    def describe(self) -> str:
        """``orange (hue 8-42 deg, S >= 0.65, V >= 0.25)`` for messages."""
        return (
            f"{self.name} (hue {self.hue_min_deg:g}-{self.hue_max_deg:g} deg, "
            f"S >= {self.sat_min:g}, V >= {self.val_min:g})"
        )


@dataclass(frozen=True)
class PaintPreset:
    """A named paint: its filter range and the nominal colour the simulator paints with."""

    name: str
    rgb: tuple[int, int, int]
    hsv: HsvRange


PAINT_PRESETS: dict[str, PaintPreset] = {
    p.name: p
    for p in (
        PaintPreset("orange", (255, 110, 0), HsvRange(8.0, 42.0, 0.65, 0.25, "orange")),
        PaintPreset("pink", (255, 40, 120), HsvRange(310.0, 10.0, 0.55, 0.25, "pink")),
        PaintPreset("yellow", (255, 220, 0), HsvRange(45.0, 70.0, 0.60, 0.35, "yellow")),
        PaintPreset("green", (40, 200, 60), HsvRange(85.0, 165.0, 0.45, 0.20, "green")),
        PaintPreset("blue", (20, 90, 230), HsvRange(190.0, 250.0, 0.50, 0.20, "blue")),
    )
}


def resolve_paint(config: PaintConfig) -> HsvRange:
    """The HSV range for a paint configuration: explicit ``hsv`` wins over the preset name."""
    if config.hsv is not None:
        h1, h2, s, v = config.hsv
        return HsvRange(float(h1), float(h2), float(s), float(v), "custom")
    preset = PAINT_PRESETS.get(config.preset)
    if preset is None:
        raise PerceptionError(
            f"unknown paint preset {config.preset!r}; presets: {', '.join(PAINT_PRESETS)} "
            "(or give --hsv H1,H2,S,V)"
        )
    return preset.hsv
