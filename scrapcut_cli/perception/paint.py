"""Marking-paint colours and the colour filter.

The one table of presets below is shared by the filter and the simulator; :func:`paint_mask`
(and :func:`paint_pixel_indices`, its hot path) select the pixels of a colour image that lie in
an :class:`HsvRange`; :func:`dominant_hues` says what colours a recording shows instead.

Hue in degrees (0–360, a range with ``hue_min_deg > hue_max_deg`` wraps through 0 — reds and
pinks), saturation and value in 0–1 (HSV of sRGB bytes / 255, as OpenCV / matplotlib define
them).

Why saturation matters: rusty steel is orange-brown, within the hue range of orange marking
paint. Fluorescent marking paints are strongly saturated (S > 0.85 when lit); mill scale and
bare steel are dull, and most rust too (S about 0.25–0.6), but iron oxide reaches S ~0.75 (V
below about 0.6). Shading from a light near the camera scales R, G and B together, which lowers
V but keeps S, so the thresholds below are low on value (shadowed paint is still paint) and
high on saturation (most rust is not; the rest is another saturation cluster, see below).

| preset | nominal sRGB | hue range (deg) | S min | V min |
|--------|--------------|-----------------|-------|-------|
| orange | 255, 110, 0  | 8 – 42          | 0.65  | 0.25  |
| pink   | 255, 40, 120 | 310 – 10 (wraps)| 0.55  | 0.25  |
| yellow | 255, 220, 0  | 45 – 70         | 0.60  | 0.35  |
| green  | 40, 200, 60  | 85 – 165        | 0.45  | 0.20  |
| blue   | 20, 90, 230  | 190 – 250       | 0.50  | 0.20  |

The nominal sRGB is the colour of the paint under full white light; the simulator's cans spray
near it. Numbers chosen from typical fluorescent marking-paint swatches. A range cannot tell
fresh paint from iron-oxide rust or a faded old mark of the same hue at S 0.65-0.8: the frame's
saturation clusters (:func:`saturation_splits`, used by ``perception.cloud``) and line selection
(``perception.candidates``) do; ``--paint auto`` (``perception.auto``) estimates a range that
fits the paint's own cluster.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter1d

from scrapcut_cli.config import PaintConfig
from scrapcut_cli.errors import PerceptionError

FloatArray = NDArray[np.float64]


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


#: The paint a recording-free configuration means when it names none (``resolve_paint``).
DEFAULT_PAINT = "orange"
#: ``--paint auto``: estimate the range from the recording's images (``perception.auto``), the
#: default for a recording that names no paint.
AUTO = "auto"

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
    """The HSV range for a paint configuration: explicit ``hsv`` wins over the preset name.

    No preset chosen (``None``) means orange, the default of docs/design.md.
    """
    if config.hsv is not None:
        try:  # a [paint] table in a TOML file is not checked by the command line's parser
            h1, h2, s, v = (float(x) for x in config.hsv)
        except (TypeError, ValueError):
            raise PerceptionError(
                f"paint.hsv must be four numbers H1, H2, S, V, got {config.hsv!r}"
            ) from None
        return HsvRange(h1, h2, s, v, "custom")
    name = DEFAULT_PAINT if config.preset is None else config.preset
    if name == AUTO:
        raise PerceptionError(
            "--paint auto estimates the colour from a recording's images; here give a preset "
            f"({', '.join(PAINT_PRESETS)}) or --hsv H1,H2,S,V"
        )
    preset = PAINT_PRESETS.get(name)
    if preset is None:
        raise PerceptionError(
            f"unknown paint preset {name!r}; presets: {', '.join(PAINT_PRESETS)}, auto "
            "(or give --hsv H1,H2,S,V)"
        )
    return preset.hsv


def resolve_recording_paint(
    config: PaintConfig, metadata: Mapping[str, Mapping[str, str]] | None = None
) -> HsvRange | None:
    """The paint to look for in a recording; None: estimate it from its images (``auto``).

    An explicit choice (``--paint``/``--hsv`` or a ``[paint]`` table) wins; otherwise a
    simulator recording's own paint (``metadata["scrapcut"]["paint"]``), else ``auto``.
    """
    if config.hsv is None and config.preset is None:
        recorded = (metadata or {}).get("scrapcut", {}).get("paint")
        if recorded in PAINT_PRESETS:
            return PAINT_PRESETS[str(recorded)].hsv
        return None
    if config.hsv is None and config.preset == AUTO:
        return None
    return resolve_paint(config)


# --------------------------------------------------------------------------- the colour filter

#: Pixels at least this saturated and bright count as "colourful" in :func:`dominant_hues`.
COLOURFUL_SAT_MIN = 0.3
COLOURFUL_VAL_MIN = 0.2


@functools.lru_cache(maxsize=16)
def _min_chroma_table(sat_min: float, val_min: float) -> NDArray[np.uint8]:
    """Per max-channel byte M, the smallest chroma (max − min byte) that passes S and V (256,).

    S = chroma / M grows with chroma, so ``chroma >= table[M]`` is exactly ``S >= sat_min and
    V >= val_min`` (evaluated in float64 as :func:`rgb_to_hsv_deg` does). Where V fails the
    entry is 255, which no chroma of such a pixel reaches (chroma <= M < 255).
    """
    m = np.arange(256, dtype=np.float64)[:, None]
    d = np.arange(256, dtype=np.float64)[None, :]
    sat = np.where(m > 0, d / np.where(m > 0, m, 1.0), 0.0)
    passes = (d <= m) & (sat >= sat_min) & (m / 255.0 >= val_min)
    table = np.where(passes.any(axis=1), passes.argmax(axis=1), 255).astype(np.uint8)
    table.setflags(write=False)
    return table


def _hue_deg(
    r: NDArray[np.float64],
    g: NDArray[np.float64],
    b: NDArray[np.float64],
    cmax: NDArray[np.float64],
    chroma: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Hue in degrees [0, 360) from channel values and their max and chroma (0 for greys)."""
    # Sextant numerators; where two channels tie for the max, the formulas agree.
    num = np.where(
        cmax == r, g - b, np.where(cmax == g, b - r + 2.0 * chroma, r - g + 4.0 * chroma)
    )
    hue = 60.0 * num / np.where(chroma > 0, chroma, 1.0)
    hue[hue < 0.0] += 360.0
    return np.asarray(hue)


def rgb_to_hsv_deg(rgb: ArrayLike) -> NDArray[np.float64]:
    """HSV of sRGB bytes (N, 3) uint8 → (N, 3) float64: hue in degrees [0, 360), S and V in 0–1.

    The definition of matplotlib's ``rgb_to_hsv`` (hue 0 for greys), on byte values.
    """
    c = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
    cmax = c.max(axis=1)
    chroma = cmax - c.min(axis=1)
    hue = _hue_deg(c[:, 0], c[:, 1], c[:, 2], cmax, chroma)
    sat = np.where(cmax > 0, chroma / np.where(cmax > 0, cmax, 1.0), 0.0)
    return np.column_stack([hue, sat, cmax / 255.0])


def hue_in_range(hue_deg: ArrayLike, hsv: HsvRange) -> NDArray[np.bool_]:
    """Whether hues (degrees) lie in ``hsv``'s interval, wrapping through 0 when it wraps."""
    h = np.asarray(hue_deg, dtype=np.float64)
    if hsv.wraps:
        return np.asarray((h >= hsv.hue_min_deg) | (h <= hsv.hue_max_deg))
    return np.asarray((h >= hsv.hue_min_deg) & (h <= hsv.hue_max_deg))


def paint_pixels_with_saturation(
    rgb: NDArray[np.uint8], hsv: HsvRange
) -> tuple[NDArray[np.intp], NDArray[np.float32]]:
    """Flat indices (K,) into ``H * W`` of the pixels whose colour lies in ``hsv``, ascending,
    and their saturation (K,) float32 (chroma over the max channel, as the test saw it).

    The hot path of the filter, written by hand because a full-image HSV conversion in numpy
    (or OpenCV-style per-pixel code) costs ~15 ms at 640×480. Saturation and value are tested
    exactly on bytes as a comparison of the chroma (max − min channel) against a 256-entry
    table indexed by the max channel, after a scalar pre-gate on the chroma alone; that
    discards the dull pixels (grey steel, rust, shadows) in ~1 ms. The hue is tested on the
    survivors only, in integers without a division:
    ``hue = 60 · num / chroma`` with ``num`` the sextant's numerator, so
    ``h1 <= hue <= h2  ⇔  h1 · chroma <= 60 · num <= h2 · chroma``.
    """
    flat = np.asarray(rgb).reshape(-1, 3)
    if flat.dtype != np.uint8:
        raise PerceptionError(f"colour image must be uint8 RGB, got {flat.dtype}")
    # The channels as contiguous planes first: numpy's SIMD loops skip strided views, so the
    # copy (one pass) makes the four full-image passes below several times faster.
    r, g, b = np.ascontiguousarray(flat.T)
    cmax = np.maximum(r, g)
    np.maximum(cmax, b, out=cmax)
    chroma = np.minimum(r, g)
    np.minimum(chroma, b, out=chroma)
    np.subtract(cmax, chroma, out=chroma)
    table = _min_chroma_table(hsv.sat_min, hsv.val_min)
    # The table's smallest entry is a necessary bound: one scalar comparison drops most pixels
    # before the exact per-pixel table test runs on the rest.
    candidates = np.flatnonzero(chroma >= table.min())
    cm = np.take(cmax, candidates)
    ch8 = np.take(chroma, candidates)
    exact = ch8 >= table.take(cm)
    candidates, cm, ch8 = candidates[exact], cm[exact], ch8[exact]
    if candidates.size == 0 or (hsv.hue_min_deg == 0.0 and hsv.hue_max_deg == 360.0):
        return candidates, _saturation(ch8, cm)
    # np.take is several times faster than fancy indexing for these gathers; from the planes,
    # so that the arithmetic below runs on contiguous arrays too.
    cr = np.take(r, candidates).astype(np.int32)
    cg = np.take(g, candidates).astype(np.int32)
    cb = np.take(b, candidates).astype(np.int32)
    ch = ch8.astype(np.int32)
    # 60 · hue / 360 · 6 · chroma: the sextant numerator, in [0, 6 · chroma).
    num = np.where(cm == cr, cg - cb, np.where(cm == cg, cb - cr + 2 * ch, cr - cg + 4 * ch))
    num += (6 * ch) * (num < 0)
    num *= 60
    above = num >= hsv.hue_min_deg * ch
    below = num <= hsv.hue_max_deg * ch
    keep = (above | below) if hsv.wraps else (above & below)
    if hsv.sat_min == 0.0:  # greys can pass S; their hue is 0 by definition
        keep = np.where(ch > 0, keep, bool(hue_in_range(0.0, hsv)))
    return candidates[keep], _saturation(ch[keep], cm[keep])


def _saturation(chroma: NDArray[Any], cmax: NDArray[Any]) -> NDArray[np.float32]:
    return np.asarray(
        chroma.astype(np.float32) / np.maximum(cmax.astype(np.float32), np.float32(1.0))
    )


def paint_pixel_indices(rgb: NDArray[np.uint8], hsv: HsvRange) -> NDArray[np.intp]:
    """Flat indices (K,) into ``H * W`` of the pixels whose colour lies in ``hsv``, ascending
    (:func:`paint_pixels_with_saturation` without the saturations)."""
    return paint_pixels_with_saturation(rgb, hsv)[0]


def paint_mask(rgb: NDArray[np.uint8], hsv: HsvRange) -> NDArray[np.bool_]:
    """Paint pixels of an image.

    Parameters
    ----------
    rgb : (H, W, 3) uint8
        sRGB colour image.
    hsv : HsvRange
        The paint's colour range (a preset's ``hsv`` or a custom range).

    Returns
    -------
    (H, W) bool
        True where hue, saturation and value all lie in the range.
    """
    image = np.asarray(rgb)
    if image.ndim != 3 or image.shape[2] != 3:
        raise PerceptionError(f"colour image must be (H, W, 3), got shape {image.shape}")
    mask = np.zeros(image.shape[0] * image.shape[1], dtype=bool)
    mask[paint_pixel_indices(image, hsv)] = True
    return mask.reshape(image.shape[:2])


# --------------------------------------------------------------------------- colour clusters

#: Saturation histogram: bins, smoothing (bins), least distance between two modes it splits,
#: least share of the voxels a mode holds, how deep the dip must be (share of the lower mode).
_BINS = 100
_SMOOTH_BINS = 1.5
_MIN_MODE_GAP = 0.08
_MIN_MODE_SHARE = 0.01
_MIN_MODE_VOXELS = 30
_DIP = 0.5


def unit_histogram(values: NDArray[Any]) -> tuple[NDArray[np.intp], NDArray[Any]]:
    """``np.histogram(values, bins=_BINS, range=(0.0, 1.0))``: counts and edges.

    For float values within 0-1, numpy's own steps without its range mask and blocks (a
    third of its time on a frame's 20 000 saturations): the bin estimated by scaling, then
    moved by one where the value lies below its bin's lower edge or at or above the next
    (the last bin holds 1.0), against numpy's edges for the dtype. The bins follow from
    those comparisons alone, so the counts are numpy's. Anything else goes to numpy.
    """
    v = np.asarray(values)
    if v.dtype not in (np.float32, np.float64) or v.ndim != 1 or v.size == 0:
        return np.histogram(v, bins=_BINS, range=(0.0, 1.0))
    if not (v.min() >= 0.0 and v.max() <= 1.0):  # NaN fails too
        return np.histogram(v, bins=_BINS, range=(0.0, 1.0))
    edges = _unit_edges(v.dtype.str)
    index = (v * _BINS).astype(np.intp)
    np.minimum(index, _BINS - 1, out=index)
    index -= v < edges[index]
    index += (v >= edges[index + 1]) & (index != _BINS - 1)
    return np.bincount(index, minlength=_BINS), edges


@functools.cache
def _unit_edges(dtype: str) -> NDArray[Any]:
    """numpy's bin edges of :func:`unit_histogram` for values of ``dtype``."""
    edges = np.histogram(np.zeros(1, dtype=dtype), bins=_BINS, range=(0.0, 1.0))[1]
    edges.setflags(write=False)
    return edges


def saturation_splits(sat: FloatArray) -> list[float]:
    """Saturations (ascending) where the voxels' saturation histogram dips between two modes
    (each with ``_MIN_MODE_SHARE`` of the voxels, ``_MIN_MODE_GAP`` apart, the dip below
    ``_DIP`` of the lower mode's height); empty when it has one mode."""
    s = sat[np.isfinite(sat)]
    if len(s) < 2 * _MIN_MODE_VOXELS:
        return []
    counts, edges = unit_histogram(s)
    density = gaussian_filter1d(counts.astype(np.float64), _SMOOTH_BINS, mode="constant")
    centres = 0.5 * (edges[:-1] + edges[1:])
    peaks = _peaks(density)
    least = max(_MIN_MODE_SHARE * len(s), _MIN_MODE_VOXELS)
    # From the top mode down: a lower mode is split off only when both sides hold enough
    # voxels, the modes lie far enough apart and a deep enough dip separates them; otherwise
    # the two are one, represented by the stronger.
    splits: list[int] = []
    upper = peaks[-1] if peaks else 0
    for k in reversed(peaks[:-1]):
        dip = k + int(np.argmin(density[k : upper + 1]))
        ceiling = splits[0] if splits else _BINS
        if (
            centres[upper] - centres[k] >= _MIN_MODE_GAP
            and density[dip] <= _DIP * min(density[k], density[upper])
            and counts[:dip].sum() >= least
            and counts[dip:ceiling].sum() >= least
        ):
            splits.insert(0, dip)
            upper = k
        elif density[k] > density[upper]:
            upper = k
    return [float(edges[k]) for k in splits]


def _peaks(density: FloatArray) -> list[int]:
    """Bins (ascending) of the local maxima of a histogram's density, its ends included
    (saturation 1 is a mode's place when a channel is 0: fluorescent orange, yellow)."""
    padded = np.concatenate([[-1.0], density, [-1.0]])
    centre = padded[1:-1]
    peak = (centre > 0) & (centre >= padded[:-2]) & (centre > padded[2:])
    return [int(k) for k in np.flatnonzero(peak)]


def paint_core(sat: FloatArray) -> float:
    """Where the paint's own colour cluster begins among a line candidate's voxel
    saturations (N,): below its most saturated mode holding ``_CORE_SHARE`` of them (fresh
    marking paint is the most saturated thing on a piece) by ``_CORE_SPREAD`` times the
    spread above that mode (at least ``_CORE_GAP``); NaN when the colours are unknown."""
    s = sat[np.isfinite(sat)]
    if len(s) < _MIN_MODE_VOXELS:
        return float("nan")
    counts, edges = unit_histogram(s)
    density = gaussian_filter1d(counts.astype(np.float64), _SMOOTH_BINS, mode="constant")
    peaks = _peaks(density)
    # A mode's mass: the voxels within the half-height span around it.
    least = max(_CORE_SHARE * len(s), _MIN_MODE_VOXELS)
    top = int(np.argmax(density))
    for k in reversed(peaks):
        lo = hi = k
        while lo > 0 and density[lo - 1] >= 0.5 * density[k]:
            lo -= 1
        while hi < _BINS - 1 and density[hi + 1] >= 0.5 * density[k]:
            hi += 1
        if counts[lo : hi + 1].sum() >= least:
            top = k
            break
    mode = 0.5 * (edges[top] + edges[top + 1])
    above = s[s >= mode]
    spread = float(np.sqrt(np.mean((above - mode) ** 2))) if len(above) else 0.0
    return float(mode - max(_CORE_SPREAD * spread, _CORE_GAP))


#: The paint's core: within this many spreads (at least this much) below its mode, the most
#: saturated mode with at least this share of the line candidate's voxels.
_CORE_SPREAD = 4.0
_CORE_GAP = 0.03
_CORE_SHARE = 0.1


class HueHistogram:
    """Running histogram of the hues of colourful pixels, for the "no paint found" message.

    Only every ``stride``-th pixel in each direction is counted (the share of a hue does not
    need every pixel), and only pixels with S >= ``COLOURFUL_SAT_MIN`` and
    V >= ``COLOURFUL_VAL_MIN``: the hue of grey steel is noise.
    """

    def __init__(self, *, bins: int = 12, stride: int = 4) -> None:
        if bins < 1:
            raise PerceptionError(f"bins must be at least 1, got {bins}")
        if stride < 1:
            raise PerceptionError(f"stride must be at least 1, got {stride}")
        self.bins = bins
        self.stride = stride
        self.counts = np.zeros(bins, dtype=np.int64)
        self.pixels = 0

    def add(self, rgb: NDArray[np.uint8]) -> None:
        """Count the colourful pixels of one (H, W, 3) uint8 image."""
        sample = np.asarray(rgb)[:: self.stride, :: self.stride].reshape(-1, 3)
        self.pixels += len(sample)
        h_s_v = rgb_to_hsv_deg(sample)
        colourful = (h_s_v[:, 1] >= COLOURFUL_SAT_MIN) & (h_s_v[:, 2] >= COLOURFUL_VAL_MIN)
        width = 360.0 / self.bins
        # Bins centred on multiples of the bin width, so red sits in one bin around 0 deg.
        index = np.floor((h_s_v[colourful, 0] + width / 2.0) / width).astype(np.int64) % self.bins
        self.counts += np.bincount(index, minlength=self.bins)

    def dominant(self, *, top: int | None = None) -> list[tuple[float, float]]:
        """(hue centre in degrees, share of colourful pixels), largest share first."""
        total = int(self.counts.sum())
        if total == 0:
            return []
        order = np.argsort(-self.counts, kind="stable")
        order = order[self.counts[order] > 0][:top]
        width = 360.0 / self.bins
        return [(float(i * width), float(self.counts[i] / total)) for i in order]

    def colourful_share(self) -> float:
        """Share of the sampled pixels that were colourful at all."""
        return float(self.counts.sum() / self.pixels) if self.pixels else 0.0

    def describe(self, *, top: int = 3) -> str:
        """``210 deg (40%), 30 deg (25%)`` or a note that the images are grey."""
        hues = self.dominant(top=top)
        if not hues:
            return "none (no saturated colours in the images)"
        return ", ".join(f"{h:.0f} deg ({100.0 * share:.0f}%)" for h, share in hues)


def dominant_hues(
    rgb_images: Iterable[NDArray[np.uint8]], *, bins: int = 12
) -> list[tuple[float, float]]:
    """The hues of the colourful pixels of some images, largest share first.

    Parameters
    ----------
    rgb_images : iterable of (H, W, 3) uint8
    bins : int
        Number of hue bins over 360 degrees; bins are centred on multiples of 360 / bins.

    Returns
    -------
    list of (hue_deg, share)
        Bin centre in degrees and its share (0–1) of the colourful pixels (S >= 0.3, V >= 0.2).
    """
    histogram = HueHistogram(bins=bins)
    for image in rgb_images:
        histogram.add(image)
    return histogram.dominant()
