"""``--paint auto``: the marking paint's colour range, estimated from the recording's images.

A user should not have to know which preset their can is, nor tune a range by hand. Marking
paint is the most saturated thing on a piece of scrap and lies on it as a stroke; that is what
:func:`estimate_paint` looks for, in a few images sampled over the recording:

1. **Hue clusters.** The hues of the colourful pixels (S >= 0.35, V >= 0.15) form a circular
   histogram (5° bins, smoothed); each mode holding at least 0.5 % of them is a cluster, its
   hue interval where the density stays above a tenth of its peak (at most ±30°).
2. **The paint's own saturation.** Within a cluster's hues, the pixels' saturation may have
   several modes: fluorescent paint at S ≈ 0.85–1, rust, faded paint and primer duller. The
   most saturated mode holding a tenth of them is the paint; the range's lower saturation bound
   is where the histogram dips between it and the next duller mode, else that mode's core
   (four spreads below it) less a margin for the stroke's own thin edge.
3. **Stroke-like.** In each sampled image the cluster's mask is split into 8-connected blobs;
   a blob of area A whose distance transform's 90 % quantile is q is a band about
   w = 2q / 0.9 wide and A / w long: stroke-like when at least three times as long as wide
   (a crate's face or a cone is about 1-2). A cluster with no stroke-like blob is no paint.
4. **The pick.** Of the stroke-like clusters, the most saturated. Its range: the hues of its
   pixels (0.5-99.5 % quantiles, ±5°), the saturation bound of step 2, the value bound at 0.7
   of its pixels' 0.5 % quantile (shadowed paint is still paint), at least 0.12.

The result is described in preset terms (the nearest preset by hue). No stroke-like cluster:
a :class:`PerceptionError` listing the dominant saturated hues seen. Hand-written on numpy and
scipy.ndimage (labelling, distance transform).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt, gaussian_filter1d, label

from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.perception.paint import (
    PAINT_PRESETS,
    HsvRange,
    paint_core,
    rgb_to_hsv_deg,
    saturation_splits,
)

FloatArray = NDArray[np.float64]

#: Pixels this saturated and bright are colourful (their hue means something).
COLOURFUL_SAT = 0.35
COLOURFUL_VAL = 0.15
#: Hue histogram: bin width, smoothing (bins), least share of the colourful pixels in a mode,
#: the density (share of the peak) that bounds its interval, its widest half width.
_HUE_BIN = 5.0
_HUE_SMOOTH = 1.0
_MIN_CLUSTER_SHARE = 0.005
_HUE_EDGE = 0.1
_HUE_REACH = 30.0
#: Hue margin around the pixels' quantiles, and the quantiles.
_HUE_MARGIN = 5.0
_HUE_QUANTILE = 0.005
#: Without a dip below the paint's saturation mode: its core less this margin (thin edges).
_SAT_MARGIN = 0.05
#: Value bound: this share of the pixels' low quantile, at least the floor.
_VAL_SHARE = 0.7
_VAL_FLOOR = 0.12
#: Blobs: least area (share of the sampled image), elongation of a stroke.
_MIN_BLOB_SHARE = 0.002
STROKE_ELONGATION = 3.0
#: Images are examined at about this width (every k-th pixel).
_WIDTH = 320


@dataclass(frozen=True)
class HueCluster:
    """One colour the images show: its hue interval, the paint-like saturation bound found in
    it, its mode's hue, saturation and value, and how much of it lies in stroke-like blobs."""

    hue_min_deg: float
    hue_max_deg: float
    sat_min: float
    val_min: float
    hue_deg: float
    saturation: float
    value: float
    share: float  # of the colourful pixels
    stroke_share: float  # of its own masked pixels, in stroke-like blobs

    def to_dict(self) -> dict[str, Any]:
        return {k: round(float(v), 4) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class PaintEstimate:
    """The estimated paint: its range (``hsv``, named ``auto``), the nearest preset by hue,
    the cluster it came from, every cluster considered and how many images were examined."""

    hsv: HsvRange
    preset: str | None
    cluster: HueCluster
    clusters: tuple[HueCluster, ...] = field(default_factory=tuple)
    images: int = 0

    def describe(self) -> str:
        """``auto: hue 14-37 deg, S >= 0.80, V >= 0.21 (orange-like; paint at 25 deg, S 0.96)``."""
        like = f"{self.preset}-like" if self.preset else "no preset's hue"
        c = self.cluster
        return (
            f"auto: hue {self.hsv.hue_min_deg:.0f}-{self.hsv.hue_max_deg:.0f} deg, "
            f"S >= {self.hsv.sat_min:.2f}, V >= {self.hsv.val_min:.2f} ({like}; paint at "
            f"{c.hue_deg:.0f} deg, S {c.saturation:.2f}, V {c.value:.2f}; {self.images} images)"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "hsv": [
                self.hsv.hue_min_deg,
                self.hsv.hue_max_deg,
                round(self.hsv.sat_min, 4),
                round(self.hsv.val_min, 4),
            ],
            "preset": self.preset,
            "cluster": self.cluster.to_dict(),
            "clusters": [c.to_dict() for c in self.clusters],
            "images": self.images,
        }


def estimate_paint(images: Iterable[NDArray[np.uint8]]) -> PaintEstimate:
    """The marking paint's HSV range from a few colour images (H, W, 3) uint8 (module text).

    Raises
    ------
    PerceptionError
        No image, or no stroke-like saturated colour: one line with the dominant hues seen.
    """
    samples: list[FloatArray] = []  # per image: (h, w, 3) HSV of every k-th pixel
    for image in images:
        rgb = np.asarray(image)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise PerceptionError(f"colour image must be (H, W, 3), got shape {rgb.shape}")
        step = max(1, rgb.shape[1] // _WIDTH)
        small = rgb[::step, ::step]
        samples.append(rgb_to_hsv_deg(small.reshape(-1, 3)).reshape(*small.shape[:2], 3))
    if not samples:
        raise PerceptionError("no images to estimate the paint's colour from")
    flat = np.concatenate([s.reshape(-1, 3) for s in samples])
    colourful = (flat[:, 1] >= COLOURFUL_SAT) & (flat[:, 2] >= COLOURFUL_VAL)
    clusters = [
        _cluster(flat[colourful], lo, hi, samples, int(colourful.sum()))
        for lo, hi in _hue_modes(flat[colourful, 0])
    ]
    strokes = [c for c in clusters if c.stroke_share > 0.0]
    if not strokes:
        raise PerceptionError(_no_paint_message(samples, clusters))
    best = max(strokes, key=lambda c: (c.saturation, c.stroke_share))
    hsv = HsvRange(
        best.hue_min_deg % 360.0, best.hue_max_deg % 360.0, best.sat_min, best.val_min, "auto"
    )
    return PaintEstimate(hsv, _nearest_preset(best.hue_deg), best, tuple(clusters), len(samples))


def _hue_modes(hue: FloatArray) -> list[tuple[float, float]]:
    """(start, end) degrees of each hue mode (``end`` may exceed 360: the interval wraps)."""
    bins = round(360.0 / _HUE_BIN)
    counts = np.bincount(np.floor(hue / _HUE_BIN).astype(np.int64) % bins, minlength=bins)
    density = gaussian_filter1d(counts.astype(np.float64), _HUE_SMOOTH, mode="wrap")
    total = max(int(counts.sum()), 1)
    modes: list[tuple[float, float]] = []
    for k in range(bins):
        left, right = density[(k - 1) % bins], density[(k + 1) % bins]
        if not (density[k] >= left and density[k] > right and density[k] > 0):
            continue
        reach = int(_HUE_REACH / _HUE_BIN)
        lo = hi = 0
        while lo < reach and density[(k - lo - 1) % bins] >= _HUE_EDGE * density[k]:
            lo += 1
        while hi < reach and density[(k + hi + 1) % bins] >= _HUE_EDGE * density[k]:
            hi += 1
        mass = sum(counts[(k + j) % bins] for j in range(-lo, hi + 1))
        if mass >= _MIN_CLUSTER_SHARE * total:
            start = (k - lo) * _HUE_BIN
            modes.append((start, start + (lo + hi + 1) * _HUE_BIN))
    return modes


def _in_hue(hue: FloatArray, lo: float, hi: float) -> NDArray[np.bool_]:
    """Hues within [lo, hi) degrees, the interval possibly running past 360 or below 0."""
    return np.asarray((hue - lo) % 360.0 < (hi - lo))


def _cluster(
    hsv: FloatArray, lo: float, hi: float, samples: list[FloatArray], colourful: int
) -> HueCluster:
    """The paint-like part of the colourful pixels (N, 3) with hues in [lo, hi)."""
    mine = hsv[_in_hue(hsv[:, 0], lo, hi)]
    sat = mine[:, 1]
    splits = saturation_splits(sat)
    core = paint_core(sat[sat >= splits[-1]] if splits else sat)
    bound = splits[-1] if splits else core - _SAT_MARGIN
    bound = float(np.clip(bound, COLOURFUL_SAT, 0.95))
    paint = mine[sat >= bound]
    if len(paint) == 0:
        paint = mine
    centre = _circular_mean(paint[:, 0])
    offsets = (paint[:, 0] - centre + 180.0) % 360.0 - 180.0
    h_lo, h_hi = np.quantile(offsets, [_HUE_QUANTILE, 1.0 - _HUE_QUANTILE])
    val_min = max(_VAL_FLOOR, _VAL_SHARE * float(np.quantile(paint[:, 2], _HUE_QUANTILE)))
    span = (centre + h_lo - _HUE_MARGIN, centre + h_hi + _HUE_MARGIN)
    cluster = HueCluster(
        hue_min_deg=span[0],
        hue_max_deg=span[1],
        sat_min=bound,
        val_min=val_min,
        hue_deg=centre % 360.0,
        saturation=float(np.median(paint[:, 1])),
        value=float(np.median(paint[:, 2])),
        share=len(mine) / max(colourful, 1),
        stroke_share=0.0,
    )
    return HueCluster(**{**cluster.__dict__, "stroke_share": _stroke_share(cluster, samples)})


def _stroke_share(cluster: HueCluster, samples: list[FloatArray]) -> float:
    """Share of the cluster's masked pixels (over the images) in stroke-like blobs."""
    inside = stroke = 0
    eight = np.ones((3, 3), dtype=bool)
    for hsv in samples:
        mask = (
            _in_hue(hsv[..., 0], cluster.hue_min_deg, cluster.hue_max_deg)
            & (hsv[..., 1] >= cluster.sat_min)
            & (hsv[..., 2] >= cluster.val_min)
        )
        count = int(mask.sum())
        inside += count
        least = _MIN_BLOB_SHARE * mask.size
        if count < least:
            continue
        labels, n = label(mask, structure=eight)
        if n == 0:
            continue
        distance = distance_transform_edt(mask)
        flat = labels.reshape(-1)
        order = np.argsort(flat, kind="stable")
        bounds = np.searchsorted(flat[order], np.arange(1, n + 2))
        values = distance.reshape(-1)[order]
        for k in range(n):
            part = values[bounds[k] : bounds[k + 1]]
            if len(part) < least:
                continue
            width = 2.0 * float(np.quantile(part, 0.9)) / 0.9
            if len(part) >= STROKE_ELONGATION * width * width:
                stroke += len(part)
    return stroke / inside if inside else 0.0


def _circular_mean(hue: FloatArray) -> float:
    angle = np.radians(hue)
    return float(np.degrees(np.arctan2(np.sin(angle).mean(), np.cos(angle).mean())) % 360.0)


def _nearest_preset(hue_deg: float) -> str | None:
    """The preset whose range holds ``hue_deg``, nearest by its nominal colour's hue."""
    best, gap = None, np.inf
    for name, preset in PAINT_PRESETS.items():
        nominal = float(rgb_to_hsv_deg(np.array([preset.rgb], dtype=np.uint8))[0, 0])
        d = abs((hue_deg - nominal + 180.0) % 360.0 - 180.0)
        lo, hi = preset.hsv.hue_min_deg, preset.hsv.hue_max_deg
        inside = (lo <= hue_deg <= hi) if lo <= hi else (hue_deg >= lo or hue_deg <= hi)
        if inside and d < gap:
            best, gap = name, d
    return best


def _no_paint_message(samples: list[FloatArray], clusters: list[HueCluster]) -> str:
    seen = ", ".join(
        f"{c.hue_deg:.0f} deg (S {c.saturation:.2f}, {100 * c.share:.0f} %)"
        for c in sorted(clusters, key=lambda c: -c.share)[:4]
    )
    return (
        f"--paint auto found no stroke-like saturated colour in {len(samples)} images; "
        f"dominant saturated hues: {seen or 'none (the images are grey)'}; "
        "give --paint PRESET or --hsv H1,H2,S,V"
    )
