"""What a surface point looks like: steel and rust, concrete floor, spray paint, shading.

Everything here is a function of the 3-D surface point (base frame), never of the pixel, so the
same spot of rust or overspray looks the same from every view — a stitched cloud of paint must
line up across frames, as it does on a real piece. Randomness is a seeded hash of integer
lattice coordinates (3-D value noise), so renders are reproducible byte for byte and independent
of the order in which views are rendered.

Colours are sRGB in 0–1. The numbers and where they come from:

* Paint: the preset's nominal sRGB (``perception.paint.PAINT_PRESETS``) is a catalogue colour;
  a real can sprays near it, not on it (brands, batches, how well it was shaken, the primer
  under a thin coat). :func:`paint_can_rgb` moves it per can: hue ±6°, saturation and value
  down by up to 15 % and 20 % (assumed: the spread of "fluorescent orange" across marking-paint
  brands' sRGB swatches is about that). Within a stroke the coat's thickness mottles the value
  by ±4 % at 5 mm, and the last 1.5 mm of the edge is a thinner coat that lets the substrate
  show through (opacity falling to 0.55 at the edge), so edge pixels are duller than the band.
* Old marks (a previous job's paint, ``faded``): the same hue family as the can (±10°), sun- and
  weather-faded to 55–80 % of its saturation and 55–85 % of its value, worn through in
  centimetre patches (20–50 % of the stroke gone), no overspray left.
* Rust: hue 12–30°, saturation 0.50–0.78, value 0.26–0.62 before shading (``MetalFinish``).
  Iron oxides are orange-brown to dark brown: red oxide (haematite, pigment PR101) is about
  sRGB (125, 50, 35), S 0.72, V 0.49; yellow oxide (goethite, PY42) about (180, 130, 60),
  S 0.67, V 0.71; fresh flash rust (lepidocrocite) is more orange still. So rust reaches the
  saturation of faded or pale paint and partly passes the orange preset's filter (S >= 0.65):
  what separates it from fresh fluorescent paint (S >= 0.85) is a distinct saturation cluster
  and a darker value, which perception has to find, not a threshold set below rust.
* Steel (mill scale, ground patches): hue 210°, S 0.04, V 0.40–0.60. Galvanised wire (the
  basket): S 0.03, V 0.52–0.72.
* Concrete floor: hue 35°, S 0.07, V 0.45–0.60.
* Spray stroke: width from the configuration (25 mm default, the issue); its half width varies
  along the line by ±10 % over ~40 mm and ±5 % over ~6 mm (a hand-held can's speed and
  distance change), and the edge is ragged by ±0.6 mm at 1.5 mm scale (droplet edge).
  Overspray: sparse specks (1.5 mm cells) within a band beside the stroke whose density decays
  exponentially away from the edge — d435i preset 8 % of cells at the edge, 6 mm decay, 25 mm
  band; yard 20 %, 10 mm, 40 mm (assumed values that look like real marking-paint photos).
* Shading: Lambert from a light 3 cm above the lens (the LED ring / lamp on the wrist) plus
  ambient 0.35 (a diffuse yard or hall light); intensity = ambient + (1 - ambient)·cos θ.
* Glints (``glints``): ground or scratched steel is mirror-like in spots. 12 % of the bare steel
  (patches at 8 mm scale) is shiny and reflects the wrist light as a Blinn-Phong highlight
  (exponent 300, strength 1.5: a few pixels go white when the spot faces the lens); the D435i's
  projected pattern is mirrored away there, so the depth has holes (``camera.simulate_depth``).
  Plastic distractors have a broad, weak sheen (exponent 40, strength 0.25).
"""

from __future__ import annotations

import colorsys
import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.geometry import cumulative_length, resample_polyline

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# --------------------------------------------------------------------------- seeded value noise


def hash01(keys: NDArray[np.int64], seed: int) -> FloatArray:
    """Uniform numbers in [0, 1) (N,) from integer lattice keys (N, K) and a seed.

    Spatial hashing (Teschner et al. 2003: coordinates times large odd primes, XORed) followed
    by a murmur-style finaliser picks an entry of a fixed table of uniform numbers. The same key
    always gives the same number whatever else is hashed — numpy's generators cannot do that —
    and it costs a few integer operations per key, which matters at 300 k pixels per frame.
    """
    k = np.asarray(keys, dtype=np.int64)
    if k.ndim == 1:
        k = k[:, None]
    h = np.full(len(k), _seed_mix(seed), dtype=np.int64)
    for j in range(k.shape[1]):
        h ^= k[:, j] * _PRIMES[j % len(_PRIMES)]
    return _lookup(h)


_PRIMES = (73856093, 19349663, 83492791, 2654435761)
_TABLE_SIZE = 1 << 20


def _seed_mix(seed: int) -> int:
    return (int(seed) * 0x2545F4914F6CDD1D) & 0x7FFFFFFFFFFFFFFF


def _lookup(h: NDArray[np.int64]) -> FloatArray:
    """Finalise hashes (N,) and read the uniform table (consumes ``h``)."""
    u = h.view(np.uint64)
    u ^= u >> np.uint64(29)
    u *= np.uint64(0xBF58476D1CE4E5B9)
    u ^= u >> np.uint64(32)
    u &= np.uint64(_TABLE_SIZE - 1)
    return np.asarray(_uniform_table()[u.view(np.int64)])


@functools.cache
def _uniform_table() -> FloatArray:
    """2^20 uniform numbers in [0, 1), the same on every run (fixed generator seed)."""
    table = np.random.default_rng(20240531).random(_TABLE_SIZE)
    table.setflags(write=False)
    return table


def value_noise(points: ArrayLike, scale_m: float, seed: int, *, octaves: int = 1) -> FloatArray:
    """Smooth value noise in [0, 1) (N,) at ``points`` (N, D) metres, D = 1, 2 or 3.

    Lattice spacing ``scale_m``; each further octave halves the spacing and the amplitude
    (fractal sum, renormalised to [0, 1)). Lattice values are :func:`hash01` of the lattice
    corner, interpolated with smoothstep weights (2^D corners per octave).
    """
    p = np.asarray(points, dtype=np.float64)
    p = np.ascontiguousarray((p[:, None] if p.ndim == 1 else p).T)
    dims = p.shape[0]
    total = np.zeros(p.shape[1])
    weight = 0.0
    amplitude = 1.0
    for octave in range(octaves):
        q = p * (2**octave / scale_m)
        base = np.floor(q)
        f = q - base
        f = f * f * (3.0 - 2.0 * f)  # smoothstep: continuous gradient at lattice faces
        b = base.astype(np.int64)
        g = 1.0 - f
        lo = [b[j] * _PRIMES[j] for j in range(dims)]
        # (b + 1)·P = b·P + P, also under int64 wrap-around, so corners share the products.
        hi = [lo[j] + _PRIMES[j] for j in range(dims)]
        corners: list[tuple[NDArray[np.int64], FloatArray]] = [
            (lo[0] ^ _seed_mix(seed + 7919 * octave), g[0]),
            (hi[0] ^ _seed_mix(seed + 7919 * octave), f[0]),
        ]
        for j in range(1, dims):
            corners = [
                (h ^ hi[j], w * f[j]) if up else (h ^ lo[j], w * g[j])
                for h, w in corners
                for up in (0, 1)
            ]
        acc = np.zeros(p.shape[1])
        for h, w in corners:
            acc += w * _lookup(h)
        total += amplitude * acc
        weight += amplitude
        amplitude *= 0.5
    return total / weight


def value_noise_1d(s: ArrayLike, scale: float, seed: int) -> FloatArray:
    """Smooth 1-D value noise in [-1, 1) (N,) along ``s`` (lattice spacing ``scale``)."""
    x = np.asarray(s, dtype=np.float64) / scale
    base = np.floor(x)
    f = x - base
    f = f * f * (3.0 - 2.0 * f)
    b = base.astype(np.int64)
    v0 = hash01(b, seed)
    v1 = hash01(b + 1, seed)
    return np.asarray(2.0 * (v0 + f * (v1 - v0)) - 1.0)


def hsv_to_rgb(h_deg: float, s: float, v: float) -> FloatArray:
    """(3,) sRGB in 0–1 from hue in degrees, saturation and value in 0–1."""
    return np.array(colorsys.hsv_to_rgb((h_deg % 360.0) / 360.0, s, v))


# --------------------------------------------------------------------------- metal and floor


@dataclass(frozen=True)
class MetalFinish:
    """The look of a piece's metal: base steel tone and how much of it is rusted.

    ``rust_fraction`` is the share of the surface covered by rust (0–1), in patches about
    ``rust_scale_m`` across. Colours as (hue deg, saturation, value), see the module docstring.
    """

    steel_hsv: tuple[float, float, float] = (210.0, 0.04, 0.50)
    steel_value_range: float = 0.10  # ± around the steel value (mill scale, grinding marks)
    rust_fraction: float = 0.35
    rust_scale_m: float = 0.05
    rust_dark_hsv: tuple[float, float, float] = (12.0, 0.78, 0.26)
    rust_light_hsv: tuple[float, float, float] = (30.0, 0.50, 0.62)

    def __post_init__(self) -> None:
        if not 0.0 <= self.rust_fraction <= 1.0:
            raise ValueError(f"rust_fraction must be within 0-1, got {self.rust_fraction}")
        if self.rust_scale_m <= 0:
            raise ValueError(f"rust_scale_m must be positive, got {self.rust_scale_m}")


def metal_albedo(points: ArrayLike, finish: MetalFinish, seed: int) -> tuple[FloatArray, BoolArray]:
    """sRGB albedo (N, 3) in 0–1 and a rust mask (N,) at surface points (N, 3), base frame."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(p)
    # Rust patches: two octaves of value noise (patch size and ragged patch edges), thresholded
    # at the quantile that gives rust_fraction; the finer octave also mixes dark and light oxide
    # and mottles the steel. Two octaves keep texturing at ~2 × 40 ms per 300 k pixels.
    coarse = value_noise(p, finish.rust_scale_m, seed)
    fine = value_noise(p, finish.rust_scale_m / 4.0, seed + 1)
    patch = 0.7 * coarse + 0.3 * fine
    rust = patch > 0.5 + _PATCH_SD * _normal_quantile(1.0 - finish.rust_fraction)
    albedo = np.empty((n, 3))
    h0, s0, v0 = finish.steel_hsv
    steel_rgb = hsv_to_rgb(h0, s0, 1.0)
    steel_v = v0 + finish.steel_value_range * (2.0 * fine - 1.0)
    albedo[:] = steel_rgb[None, :] * steel_v[:, None]
    if rust.any():
        t = np.clip((fine[rust] - 0.2) / 0.6, 0.0, 1.0)
        dark = np.array(finish.rust_dark_hsv)
        light = np.array(finish.rust_light_hsv)
        hsv = dark[None, :] + t[:, None] * (light - dark)[None, :]
        albedo[rust] = _hsv_array_to_rgb(hsv)
    return albedo, rust


#: SD of 0.7·n1 + 0.3·n2 for independent one-octave value noises (SD 0.185 each), measured.
_PATCH_SD = 0.140


def floor_albedo(points: ArrayLike, seed: int) -> FloatArray:
    """sRGB albedo (N, 3) of a concrete floor: warm grey, mottled at 3 cm."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    # The floor is a plane: 2-D noise over (x, y) costs half of 3-D noise.
    value = 0.45 + 0.15 * value_noise(p[:, :2], 0.03, seed + 11)
    return np.asarray(hsv_to_rgb(35.0, 0.07, 1.0)[None, :] * value[:, None])


def _hsv_array_to_rgb(hsv: FloatArray) -> FloatArray:
    """Vectorised HSV (N, 3) (hue in degrees) to sRGB (N, 3) in 0–1."""
    h = (hsv[:, 0] % 360.0) / 60.0
    s, v = hsv[:, 1], hsv[:, 2]
    c = v * s
    x = c * (1.0 - np.abs(h % 2.0 - 1.0))
    m = v - c
    sector = np.floor(h).astype(np.int64) % 6
    zero = np.zeros_like(c)
    table = np.stack(
        [
            np.stack([c, x, zero], -1),
            np.stack([x, c, zero], -1),
            np.stack([zero, c, x], -1),
            np.stack([zero, x, c], -1),
            np.stack([x, zero, c], -1),
            np.stack([c, zero, x], -1),
        ]
    )
    rgb = table[sector, np.arange(len(h))]
    return np.asarray(rgb + m[:, None])


def _normal_quantile(p: float) -> float:
    """Standard normal quantile of ``p`` (clipped away from 0 and 1)."""
    from scipy.special import ndtri

    return float(ndtri(min(max(p, 1e-6), 1.0 - 1e-6)))


# --------------------------------------------------------------------------- spray paint

#: Per-can spread around a preset's nominal colour (see the module docstring): hue ± degrees,
#: largest relative loss of saturation and of value.
CAN_HUE_DEG = 6.0
CAN_SAT_LOSS = 0.15
CAN_VAL_LOSS = 0.20
#: An old mark's colour relative to the can: hue ± degrees, saturation and value factors.
FADED_HUE_DEG = 10.0
FADED_SAT = (0.55, 0.80)
FADED_VAL = (0.55, 0.85)


def _rgb_to_hsv(rgb: ArrayLike) -> tuple[float, float, float]:
    r, g, b = (float(c) for c in np.asarray(rgb, dtype=np.float64).reshape(3))
    h, s, v = colorsys.rgb_to_hsv(r, g, b)
    return 360.0 * h, s, v


def _to_bytes(rgb: FloatArray) -> tuple[int, int, int]:
    r, g, b = (int(c) for c in np.clip(np.rint(255.0 * rgb), 0, 255))
    return r, g, b


def paint_can_rgb(nominal: tuple[int, int, int], rng: np.random.Generator) -> tuple[int, int, int]:
    """The colour one can really sprays (sRGB bytes): ``nominal`` (a preset's sRGB bytes) moved
    in hue by up to ±``CAN_HUE_DEG``, saturation and value lowered by up to ``CAN_SAT_LOSS`` and
    ``CAN_VAL_LOSS`` (relative), uniformly; never the nominal colour exactly."""
    h, s, v = _rgb_to_hsv(np.asarray(nominal, dtype=np.float64) / 255.0)
    h += rng.uniform(-CAN_HUE_DEG, CAN_HUE_DEG)
    s *= 1.0 - rng.uniform(0.02, CAN_SAT_LOSS)
    v *= 1.0 - rng.uniform(0.02, CAN_VAL_LOSS)
    return _to_bytes(hsv_to_rgb(h, s, v))


def faded_rgb(can: tuple[int, int, int], rng: np.random.Generator) -> tuple[int, int, int]:
    """An old, weathered mark of the same hue family as ``can`` (sRGB bytes): hue ±
    ``FADED_HUE_DEG``, saturation and value scaled by factors drawn from ``FADED_SAT`` and
    ``FADED_VAL``."""
    h, s, v = _rgb_to_hsv(np.asarray(can, dtype=np.float64) / 255.0)
    h += rng.uniform(-FADED_HUE_DEG, FADED_HUE_DEG)
    s *= rng.uniform(*FADED_SAT)
    v *= rng.uniform(*FADED_VAL)
    return _to_bytes(hsv_to_rgb(h, s, v))


@dataclass(frozen=True)
class OversprayModel:
    """Sparse paint specks beside a stroke: cell probability ``density·exp(-gap/decay)``."""

    density: float = 0.08
    decay_m: float = 0.006
    band_m: float = 0.025
    cell_m: float = 0.0015


OVERSPRAY_PRESETS: dict[str, OversprayModel] = {
    "none": OversprayModel(density=0.0),
    "light": OversprayModel(),
    "heavy": OversprayModel(density=0.20, decay_m=0.010, band_m=0.040),
}


class PaintStroke:
    """A spray-painted stroke along a reference polyline, decided per surface point.

    Parameters
    ----------
    reference : (N, 3) float64
        The stroke's centre line, metres, base frame, ordered.
    width_m : float
        Nominal stroke width (25 mm default in the simulator configuration).
    rgb : (3,) sRGB bytes
        Paint colour under full white light.
    overspray : OversprayModel
        Specks beside the stroke.
    seed : int
        Seeds the ragged edge and the specks.
    wear : float
        Share (0-1) of the stroke worn away, in patches about ``WEAR_SCALE_M`` across (an old
        mark); 0 for fresh paint.
    """

    #: Along-line width variation (fractions of the half width) and the edge roughness.
    SLOW_VARIATION = 0.10
    SLOW_SCALE_M = 0.040
    FAST_VARIATION = 0.05
    FAST_SCALE_M = 0.006
    EDGE_ROUGHNESS_M = 0.0006
    EDGE_SCALE_M = 0.0015
    RESAMPLE_M = 0.0005
    GRID_M = 0.003
    #: The coat thins over the last EDGE_SOFT_M of the edge, down to EDGE_OPACITY; specks are
    #: thin drops; the coat's value mottles by ±TONE_VARIATION at TONE_SCALE_M.
    EDGE_SOFT_M = 0.0015
    EDGE_OPACITY = 0.55
    SPECK_OPACITY = 0.8
    TONE_VARIATION = 0.04
    TONE_SCALE_M = 0.005
    #: Worn patches of an old mark are about this big.
    WEAR_SCALE_M = 0.008

    def __init__(
        self,
        reference: ArrayLike,
        *,
        width_m: float,
        rgb: tuple[int, int, int],
        overspray: OversprayModel | None = None,
        seed: int = 0,
        wear: float = 0.0,
    ) -> None:
        ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
        if len(ref) < 2:
            raise ValueError("a paint stroke needs a reference polyline of at least two points")
        if width_m <= 0:
            raise ValueError(f"stroke width must be positive, got {width_m}")
        self.reference = ref
        self.width_m = float(width_m)
        self.rgb = np.asarray(rgb, dtype=np.float64) / 255.0
        self.overspray = overspray if overspray is not None else OversprayModel()
        self.seed = int(seed)
        if not 0.0 <= wear < 1.0:
            raise ValueError(f"wear must be within [0, 1), got {wear}")
        self.wear = float(wear)
        # Distances come from a 0.5 mm resampling: the nearest vertex (KD-tree) and the exact
        # foot point on its two segments. That distance D' satisfies D <= D' <= sqrt(D² + h²/4)
        # for the true distance D and spacing h, i.e. within 3 µm at the 12 mm stroke edge.
        # geometry.PolylineDistance is exact but its candidate search costs ~10× more when tens
        # of thousands of pixels per frame lie beside the stroke.
        self._dense = resample_polyline(ref, self.RESAMPLE_M)
        self._dense_arc = cumulative_length(self._dense)
        self._tree = cKDTree(self._dense)
        # A lookup table of distances on a voxel grid around the line sorts points cheaply:
        # far away, surely inside the stroke, or in the ring around its edge that needs the
        # exact distance (about a third of the points beside the stroke).
        reach = self.max_half_width_m + self.overspray.band_m + self.RESAMPLE_M
        self._grid = _DistanceGrid(self._tree, self._dense, reach, self.GRID_M)

    @property
    def max_half_width_m(self) -> float:
        """Largest distance from the reference at which the stroke itself (not overspray) lies."""
        variation = self.SLOW_VARIATION + self.FAST_VARIATION
        return 0.5 * self.width_m * (1.0 + variation) + self.EDGE_ROUGHNESS_M

    @property
    def min_half_width_m(self) -> float:
        """Smallest half width anywhere along the stroke."""
        variation = self.SLOW_VARIATION + self.FAST_VARIATION
        return 0.5 * self.width_m * (1.0 - variation) - self.EDGE_ROUGHNESS_M

    def half_width(self, arc_length_m: ArrayLike) -> FloatArray:
        """Half width (N,) in metres at arc lengths (N,) along the reference (edge excluded)."""
        s = np.asarray(arc_length_m, dtype=np.float64)
        slow = value_noise_1d(s, self.SLOW_SCALE_M, self.seed + 101)
        fast = value_noise_1d(s, self.FAST_SCALE_M, self.seed + 102)
        return np.asarray(
            0.5 * self.width_m * (1.0 + self.SLOW_VARIATION * slow + self.FAST_VARIATION * fast)
        )

    def distance_and_arc_length(
        self, points: ArrayLike, nearest_vertex: NDArray[np.int64] | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """Distance (N,) to the reference and arc length (N,) of the foot point, metres."""
        q = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if nearest_vertex is None:
            _, nearest_vertex = self._tree.query(q)
        k = np.asarray(nearest_vertex, dtype=np.int64)
        last = len(self._dense) - 2
        best_d = np.full(len(q), np.inf)
        best_s = np.zeros(len(q))
        for seg in (np.clip(k - 1, 0, last), np.clip(k, 0, last)):
            a = self._dense[seg]
            d = self._dense[seg + 1] - a
            length2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-24)
            t = np.clip(np.einsum("ij,ij->i", q - a, d) / length2, 0.0, 1.0)
            dist = np.linalg.norm(q - (a + t[:, None] * d), axis=1)
            arc = self._dense_arc[seg] + t * np.sqrt(length2)
            better = dist < best_d
            best_d = np.where(better, dist, best_d)
            best_s = np.where(better, arc, best_s)
        return best_d, best_s

    def coverage(self, points: ArrayLike) -> tuple[BoolArray, BoolArray]:
        """(stroke, speck) masks (N,) for surface points (N, 3), base frame."""
        layer = self.layer(points)
        return layer.stroke, layer.speck

    def layer(self, points: ArrayLike) -> PaintLayer:
        """Where the paint lies on surface points (N, 3), base frame, and how thick it is."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        n = len(p)
        stroke = np.zeros(n, dtype=bool)
        speck = np.zeros(n, dtype=bool)
        opacity = np.zeros(n)
        reach = self.max_half_width_m + self.overspray.band_m + self.RESAMPLE_M
        approx = self._grid.lookup(p)
        # Table error plus the sampled line's own (a vertex is at most 0.25 mm farther than the
        # line): the exact distance lies within ±err of ``approx``.
        err = self._grid.error_m + 0.5 * self.RESAMPLE_M
        near = np.flatnonzero(approx <= reach + err)
        if near.size == 0:
            return PaintLayer(stroke, speck, opacity)
        q = p[near]
        dist = approx[near]
        inside = dist + err < self.min_half_width_m
        ring = np.flatnonzero(~inside & (dist - err <= self.max_half_width_m))
        half = np.full(near.size, self.max_half_width_m)
        alpha = np.ones(near.size)
        if ring.size:
            _, nearest = self._tree.query(q[ring])
            dist[ring], s = self.distance_and_arc_length(q[ring], nearest)
            edge = self.EDGE_ROUGHNESS_M * (
                2.0 * value_noise(q[ring], self.EDGE_SCALE_M, self.seed + 103) - 1.0
            )
            half[ring] = self.half_width(s) + edge
            inside[ring] = dist[ring] < half[ring]
            # Points off the ring are more than the table's error inside the narrowest edge
            # (> EDGE_SOFT_M): full coat.
            gap = np.clip((half[ring] - dist[ring]) / self.EDGE_SOFT_M, 0.0, 1.0)
            alpha[ring] = self.EDGE_OPACITY + (1.0 - self.EDGE_OPACITY) * gap
        if self.wear > 0.0:
            worn = value_noise(q, self.WEAR_SCALE_M, self.seed + 105) < _noise_level(self.wear)
            inside &= ~worn
        stroke[near] = inside
        opacity[near] = np.where(inside, alpha, 0.0)
        model = self.overspray
        if model.density > 0:
            # Outside the ring ``dist`` is the table's estimate: good enough for a probability.
            gap = np.maximum(dist - half, 0.0)
            cells = np.floor(q / model.cell_m).astype(np.int64)
            chance = model.density * np.exp(-gap / model.decay_m)
            hit = (~inside) & (gap < model.band_m) & (hash01(cells, self.seed + 104) < chance)
            speck[near] = hit
            opacity[near[hit]] = self.SPECK_OPACITY
        return PaintLayer(stroke, speck, opacity)

    def tone(self, points: ArrayLike) -> FloatArray:
        """Value factor (N,) of the coat at surface points (N, 3): 1 ± ``TONE_VARIATION``."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        noise = value_noise(p, self.TONE_SCALE_M, self.seed + 106)
        return np.asarray(1.0 + self.TONE_VARIATION * (2.0 * noise - 1.0))


def _noise_level(share: float) -> float:
    """The one-octave value-noise level below which ``share`` of the surface lies (its
    distribution is close to normal, mean 0.5, SD ``_NOISE_SD``)."""
    return 0.5 + _NOISE_SD * _normal_quantile(share)


#: SD of one octave of value noise (smoothstep-interpolated uniform lattice values), measured.
_NOISE_SD = 0.185


@dataclass(frozen=True, eq=False)
class PaintLayer:
    """Paint on surface points (N,): ``stroke`` and ``speck`` masks and the coat's
    ``opacity`` (0 where unpainted; the substrate shows through the rest)."""

    stroke: BoolArray
    speck: BoolArray
    opacity: FloatArray

    @property
    def paint(self) -> BoolArray:
        return np.asarray(self.stroke | self.speck)


class _DistanceGrid:
    """Distance to a densely sampled line, tabulated at voxel centres around it.

    ``lookup`` returns the value of the voxel a point falls in: within ``error_m`` (half the
    voxel diagonal) of the distance to the samples, or inf beyond ``reach_m`` and outside the
    table.
    """

    MAX_VOXELS = 4_000_000

    def __init__(self, tree: cKDTree, samples: FloatArray, reach_m: float, voxel_m: float) -> None:
        lo = samples.min(axis=0) - reach_m - voxel_m
        hi = samples.max(axis=0) + reach_m + voxel_m
        voxel = max(voxel_m, float(np.prod(hi - lo) / self.MAX_VOXELS) ** (1.0 / 3.0))
        shape = np.ceil((hi - lo) / voxel).astype(np.int64) + 1
        axes = [lo[k] + (np.arange(shape[k]) + 0.5) * voxel for k in range(3)]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        distance, _ = tree.query(centres, distance_upper_bound=reach_m + voxel)
        self.table = distance.astype(np.float32).reshape(tuple(shape))
        self.origin = lo
        self.voxel_m = voxel
        self.error_m = 0.5 * np.sqrt(3.0) * voxel
        self._shape = shape

    def lookup(self, points: FloatArray) -> FloatArray:
        """Approximate distances (N,) for points (N, 3); inf outside the table."""
        cell = np.floor((points - self.origin) / self.voxel_m).astype(np.int64)
        inside = np.all((cell >= 0) & (cell < self._shape), axis=1)
        out = np.full(len(points), np.inf)
        c = cell[inside]
        out[inside] = self.table[c[:, 0], c[:, 1], c[:, 2]]
        return out


# --------------------------------------------------------------------------- shading

#: Light 3 cm above the lens (towards -y of the optical frame), ambient share of the light.
LIGHT_OFFSET_CAM = (0.0, -0.03, 0.0)
AMBIENT = 0.35


def lambert(
    normals: ArrayLike,
    points: ArrayLike,
    light_position: ArrayLike,
    *,
    ambient: float = AMBIENT,
) -> FloatArray:
    """Shading intensity (N,) in [ambient, 1]: ambient + (1 - ambient)·max(0, n·l).

    ``normals`` (N, 3) must face the viewer; ``light_position`` (3,) in the same frame as
    ``points`` (N, 3).
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    to_light = np.asarray(light_position, dtype=np.float64) - p
    distance = np.sqrt(np.einsum("ij,ij->i", to_light, to_light))
    cos = np.einsum("ij,ij->i", n, to_light) / np.maximum(distance, 1e-12)
    np.clip(cos, 0.0, 1.0, out=cos)
    return np.asarray(ambient + (1.0 - ambient) * cos)


# --------------------------------------------------------------------------- glints


@dataclass(frozen=True)
class Gloss:
    """A Blinn-Phong highlight: ``strength`` · (n·h)^``exponent`` added to every channel."""

    exponent: float
    strength: float


#: Ground or scratched steel (mirror-like spots) and a plastic crate's or cone's sheen.
STEEL_GLINT = Gloss(exponent=300.0, strength=1.5)
PLASTIC_SHEEN = Gloss(exponent=40.0, strength=0.25)
#: Share of the bare steel that is shiny, in patches this big.
SHINY_SHARE = 0.12
SHINY_SCALE_M = 0.008


def shiny_steel(points: ArrayLike, seed: int, *, share: float = SHINY_SHARE) -> BoolArray:
    """Mask (N,) of surface points (N, 3) on mirror-like (ground, scratched) steel spots."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.asarray(value_noise(p, SHINY_SCALE_M, seed + 21) > _noise_level(1.0 - share))


def specular(
    normals: ArrayLike,
    points: ArrayLike,
    light_position: ArrayLike,
    eye_position: ArrayLike,
    gloss: Gloss,
) -> FloatArray:
    """Highlight intensity (N,) >= 0 of a Blinn-Phong lobe at surface points (N, 3) with unit
    ``normals`` (N, 3) facing the viewer, lit from ``light_position`` and seen from
    ``eye_position`` (3,), all in one frame."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    to_light = np.asarray(light_position, dtype=np.float64) - p
    to_eye = np.asarray(eye_position, dtype=np.float64) - p
    to_light /= np.maximum(np.linalg.norm(to_light, axis=1, keepdims=True), 1e-12)
    to_eye /= np.maximum(np.linalg.norm(to_eye, axis=1, keepdims=True), 1e-12)
    h = to_light + to_eye
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
    cos = np.clip(np.einsum("ij,ij->i", n, h), 0.0, 1.0)
    return np.asarray(gloss.strength * cos**gloss.exponent)
