"""Seeded synthetic geometry shared by the tests: curves, rigid motions, painted strokes.

Every function takes a seed (or is deterministic), so the same call gives the same bytes.
Units are metres. A "reference" here is the true centre line a fitter should recover.
"""

from __future__ import annotations

import os
import resource
import signal
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from scrapcut_cli.recording.frame import CameraModel

FloatArray = NDArray[np.float64]


def helix(
    n: int = 400, *, radius: float = 0.05, pitch: float = 0.04, turns: float = 1.5
) -> FloatArray:
    """Points (n, 3) on a helix about +z, starting at (radius, 0, 0), evenly spaced in angle."""
    phi = np.linspace(0.0, 2.0 * np.pi * turns, n)
    return np.column_stack(
        [radius * np.cos(phi), radius * np.sin(phi), pitch * phi / (2.0 * np.pi)]
    )


def noisy_helix(
    n: int = 2000,
    *,
    radius: float = 0.05,
    pitch: float = 0.04,
    turns: float = 1.5,
    noise_m: float = 0.001,
    seed: int = 0,
) -> tuple[FloatArray, FloatArray]:
    """(points (n, 3) with isotropic Gaussian noise, reference helix (1000, 3)).

    The noisy points are drawn at random angles (not ordered along the curve).
    """
    rng = np.random.default_rng(seed)
    phi = np.sort(rng.uniform(0.0, 2.0 * np.pi * turns, n))
    rng.shuffle(phi)
    pts = np.column_stack([radius * np.cos(phi), radius * np.sin(phi), pitch * phi / (2.0 * np.pi)])
    pts += rng.normal(scale=noise_m, size=pts.shape)
    return pts, helix(1000, radius=radius, pitch=pitch, turns=turns)


def arc(n: int = 400, *, radius: float = 0.1, angle: float = np.pi) -> FloatArray:
    """Points (n, 3) on a planar arc in z = 0, centred at the origin, from angle 0 to ``angle``."""
    phi = np.linspace(0.0, angle, n)
    return np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(n)])


def noisy_arc(
    n: int = 2000,
    *,
    radius: float = 0.1,
    angle: float = 1.5 * np.pi,
    noise_m: float = 0.001,
    seed: int = 0,
) -> tuple[FloatArray, FloatArray]:
    """(points (n, 3) on an arc with Gaussian noise, in random order; reference arc (1000, 3))."""
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0.0, angle, n)
    pts = np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(n)])
    pts += rng.normal(scale=noise_m, size=pts.shape)
    return pts, arc(1000, radius=radius, angle=angle)


def random_se3(seed: int = 0, *, max_translation: float = 1.0) -> FloatArray:
    """A random rigid transform (4, 4): uniform rotation, translation up to ``max_translation``."""
    rng = np.random.default_rng(seed)
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.uniform(-max_translation, max_translation, 3)
    return T


def apply_se3(T: FloatArray, points: FloatArray) -> FloatArray:
    """Points (N, 3) mapped by the rigid transform ``T`` (4, 4)."""
    return np.asarray(points @ T[:3, :3].T + T[:3, 3])


# --------------------------------------------------------------------------- painted strokes
# A painted line is a centre curve on a surface; the paint is a band of the stroke width in the
# surface's tangent plane, across the curve (along n x tangent).


def line_on_plane(length: float = 0.5, n: int = 500) -> tuple[FloatArray, FloatArray]:
    """(centre line (n, 3) along +x in z = 0 from the origin, normals (n, 3) = +z)."""
    x = np.linspace(0.0, length, n)
    curve = np.column_stack([x, np.zeros(n), np.zeros(n)])
    return curve, np.tile([0.0, 0.0, 1.0], (n, 1))


def arc_on_cylinder(
    radius: float = 0.08, angle: float = 1.5 * np.pi, n: int = 600
) -> tuple[FloatArray, FloatArray]:
    """(circumferential line (n, 3) on a cylinder about +z at z = 0, outward normals (n, 3))."""
    phi = np.linspace(0.0, angle, n)
    normals = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(n)])
    return radius * normals, normals


def corner_on_beam(arm: float = 0.25, n: int = 501) -> tuple[FloatArray, FloatArray]:
    """An I-beam-like 90-degree joint: a line along +x on the top face z = 0 (x <= 0) that turns
    down the side face x = 0 (z <= 0); normals +z then +x. Returns (curve (n, 3), normals (n, 3)).
    """
    s = np.linspace(-arm, arm, n)
    curve = np.column_stack([np.minimum(s, 0.0), np.zeros(n), -np.maximum(s, 0.0)])
    normals = np.where((s <= 0.0)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    return curve, normals


def painted_stroke(
    curve: FloatArray,
    normals: FloatArray,
    *,
    width_m: float = 0.025,
    spacing_m: float = 0.002,
    noise_m: float = 0.001,
    ragged: float = 0.15,
    gaps: Sequence[tuple[float, float]] = (),
    outlier_share: float = 0.0,
    caps: bool = False,
    overspray: float = 0.0,
    overspray_decay_m: float = 0.010,
    overspray_band_m: float = 0.040,
    seed: int = 0,
) -> FloatArray:
    """A stitched-like paint cloud (N, 3) around ``curve`` (K, 3) lying on a surface.

    Points are drawn uniformly over the band (about one per ``spacing_m`` squared, as a
    stitched cloud after a voxel filter), a ragged width ``width_m * (1 ± ragged)`` varying
    along the curve, isotropic Gaussian noise ``noise_m``, no paint in the arc-length
    intervals ``gaps`` [(s0, s1), ...] (metres from the curve's start), and ``outlier_share``
    of the points replaced by uniform outliers within 5 cm of the band. Returned in random
    order.

    ``caps``: the stroke also has round caps, as a real spray stroke (and the simulator's
    paint) has: a half disc at each end, centred on the curve's end point, of the band's half
    width there, in the plane of the end segment (its tangent and ``n x tangent``). Cap
    points count as arc lengths below 0 and beyond the curve's length for ``gaps``. Without
    caps the band stops square at the curve's ends (as paint running off an edge).

    ``overspray``: sparse specks around the stroke, as the simulator's spray paint has (its
    ``heavy`` preset: 0.2 of the 1.5 mm cells at the edge, 10 mm decay, 40 mm band): one
    point per speck, with the chance ``overspray * exp(-gap / overspray_decay_m)`` per 1.5 mm
    cell at a ``gap`` (up to ``overspray_band_m``) outside the ragged edge, around the caps
    too (``caps``; beyond square ends none, as paint running off an edge). They are drawn from
    a generator of their own, so ``overspray=0`` gives the same points as before. For straight
    or gently curving lines (the band's frame is carried across, not bent around corners).
    """
    rng = np.random.default_rng(seed)
    seg = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    s_vertex = np.concatenate([[0.0], np.cumsum(seg)])
    length = float(s_vertex[-1])
    n = round(length * width_m / spacing_m**2)
    s = rng.uniform(0.0, length, n)
    for s0, s1 in gaps:
        s = s[(s < s0) | (s > s1)]
    n = len(s)
    # Ragged edges: the local width wanders smoothly along the curve.
    phase = rng.uniform(0.0, 2.0 * np.pi, 2)
    half = _stroke_half_width(s, width_m, ragged, phase)
    u = rng.uniform(-1.0, 1.0, n) * half
    idx = np.clip(np.searchsorted(s_vertex, s) - 1, 0, len(curve) - 2)
    frac = (s - s_vertex[idx]) / np.where(seg[idx] > 0, seg[idx], 1.0)
    centre = curve[idx] + frac[:, None] * (curve[idx + 1] - curve[idx])
    tangent = (curve[idx + 1] - curve[idx]) / np.where(seg[idx] > 0, seg[idx], 1.0)[:, None]
    normal = normals[idx] + normals[idx + 1]  # the segment's normal (a corner: the bisector)
    across = np.cross(normal, tangent)
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    pts = centre + u[:, None] * across
    if caps:
        pts = np.vstack(
            [
                pts,
                _stroke_caps(
                    curve, normals, s_vertex, width_m, spacing_m, ragged, phase, gaps, rng
                ),
            ]
        )
        n = len(pts)
    if overspray > 0.0:
        pts = np.vstack(
            [
                pts,
                _overspray_specks(
                    curve,
                    normals,
                    s_vertex,
                    width_m,
                    ragged,
                    phase,
                    caps,
                    (overspray, overspray_decay_m, overspray_band_m),
                    np.random.default_rng([seed, 1]),
                ),
            ]
        )
        n = len(pts)
    pts = pts + rng.normal(scale=noise_m, size=(n, 3))
    n_out = round(outlier_share * n)
    if n_out:
        pick = rng.choice(n, n_out, replace=False)
        pts[pick] = pts[pick] + rng.uniform(-0.05, 0.05, (n_out, 3))
    return np.asarray(pts[rng.permutation(n)])


def on_wire_grid(
    points: FloatArray,
    *,
    pitch_m: float = 0.04,
    wire_radius_m: float = 0.002,
    angle_deg: float = 20.0,
) -> FloatArray:
    """The points (N, 3) of paint sprayed on z = 0 that land on a square wire mesh (M, 3).

    Two families of wires in the x-y plane, at ``angle_deg`` and ``angle_deg + 90``, every
    ``pitch_m``; a point is kept within ``wire_radius_m`` of a wire's axis (a wire basket).
    """
    keep = np.zeros(len(points), dtype=bool)
    for angle in np.radians([angle_deg, angle_deg + 90.0]):
        across = points[:, 0] * -np.sin(angle) + points[:, 1] * np.cos(angle)
        keep |= np.abs((across + 0.5 * pitch_m) % pitch_m - 0.5 * pitch_m) <= wire_radius_m
    return np.asarray(points[keep])


def s_curve_on_plane(length: float = 0.5, n: int = 1001) -> tuple[FloatArray, FloatArray]:
    """An S along x on the plane z = 0 (amplitude 30 mm, one period) and its normals (+z)."""
    x = np.linspace(0.0, length, n)
    curve = np.column_stack([x, 0.03 * np.sin(2.0 * np.pi * x / length), np.zeros(n)])
    return curve, np.tile([0.0, 0.0, 1.0], (n, 1))


def _stroke_half_width(
    s: FloatArray, width_m: float, ragged: float, phase: FloatArray
) -> FloatArray:
    """Half width (N,) of :func:`painted_stroke`'s band at arc lengths ``s`` (N,): it wanders
    smoothly along the curve (ragged edges)."""
    wobble = 0.5 * (np.sin(s / 0.03 + phase[0]) + np.sin(s / 0.011 + phase[1]))
    return np.asarray(0.5 * width_m * (1.0 + ragged * wobble))


def _stroke_caps(
    curve: FloatArray,
    normals: FloatArray,
    s_vertex: FloatArray,
    width_m: float,
    spacing_m: float,
    ragged: float,
    phase: FloatArray,
    gaps: Sequence[tuple[float, float]],
    rng: np.random.Generator,
) -> FloatArray:
    """Points (M, 3) uniformly in the two round caps of :func:`painted_stroke` (same density)."""
    length = float(s_vertex[-1])
    out = []
    for at_end in (False, True):
        a, b = (curve[-2], curve[-1]) if at_end else (curve[1], curve[0])
        outward = (b - a) / np.linalg.norm(b - a)
        nrm = normals[-1] if at_end else normals[0]
        across = np.cross(nrm, outward)
        across /= np.linalg.norm(across)
        h = float(
            _stroke_half_width(np.array([length if at_end else 0.0]), width_m, ragged, phase)[0]
        )
        m = round(0.5 * np.pi * h**2 / spacing_m**2)
        r = h * np.sqrt(rng.uniform(0.0, 1.0, m))
        theta = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, m)
        along, lateral = r * np.cos(theta), r * np.sin(theta)
        s = length + along if at_end else -along
        keep = np.ones(m, dtype=bool)
        for s0, s1 in gaps:
            keep &= (s < s0) | (s > s1)
        out.append(b + along[keep, None] * outward + lateral[keep, None] * across)
    return np.vstack(out)


def _overspray_specks(
    curve: FloatArray,
    normals: FloatArray,
    s_vertex: FloatArray,
    width_m: float,
    ragged: float,
    phase: FloatArray,
    caps: bool,
    spray: tuple[float, float, float],
    rng: np.random.Generator,
    cell_m: float = 0.0015,
) -> FloatArray:
    """Speck points (M, 3) around :func:`painted_stroke`'s band: candidate cells (one per
    ``cell_m`` squared, uniform over the stroke's surroundings in its arc-length / across
    frame) kept with the chance ``density * exp(-gap / decay)`` at a gap outside the edge."""
    density, decay, band = spray
    length = float(s_vertex[-1])
    reach = 0.5 * width_m * (1.0 + ragged) + band
    lo = -reach if caps else 0.0
    hi = length + reach if caps else length
    n = rng.poisson((hi - lo) * 2.0 * reach / cell_m**2)
    s = rng.uniform(lo, hi, n)
    u = rng.uniform(-reach, reach, n)
    inside = np.clip(s, 0.0, length)
    half = _stroke_half_width(inside, width_m, ragged, phase)
    gap = np.hypot(s - inside, u) - half  # beyond an end: from the round cap's edge
    keep = (gap > 0.0) & (gap < band) & (rng.uniform(size=n) < density * np.exp(-gap / decay))
    s, u, inside = s[keep], u[keep], inside[keep]
    seg = np.diff(s_vertex)
    idx = np.clip(np.searchsorted(s_vertex, inside) - 1, 0, len(curve) - 2)
    frac = (inside - s_vertex[idx]) / np.where(seg[idx] > 0, seg[idx], 1.0)
    centre = curve[idx] + frac[:, None] * (curve[idx + 1] - curve[idx])
    tangent = (curve[idx + 1] - curve[idx]) / np.where(seg[idx] > 0, seg[idx], 1.0)[:, None]
    across = np.cross(normals[idx] + normals[idx + 1], tangent)
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    return np.asarray(centre + (s - inside)[:, None] * tangent + u[:, None] * across)


# --------------------------------------------------------------------------- observed surfaces
# The tool path needs the observed surface around the paint and, per point, the camera centre
# that saw it (normals are oriented towards it).


def surface_patch(
    corner: Sequence[float],
    edge_u: Sequence[float],
    edge_v: Sequence[float],
    *,
    spacing_m: float = 0.003,
    noise_m: float = 0.0,
    seed: int = 0,
) -> FloatArray:
    """Grid points (N, 3) on the parallelogram ``corner + a * edge_u + b * edge_v``, a, b in
    [0, 1], about ``spacing_m`` apart, with isotropic Gaussian noise ``noise_m``."""
    c = np.asarray(corner, dtype=np.float64)
    u = np.asarray(edge_u, dtype=np.float64)
    v = np.asarray(edge_v, dtype=np.float64)
    nu = max(round(float(np.linalg.norm(u)) / spacing_m), 1) + 1
    nv = max(round(float(np.linalg.norm(v)) / spacing_m), 1) + 1
    a, b = np.meshgrid(np.linspace(0.0, 1.0, nu), np.linspace(0.0, 1.0, nv), indexing="ij")
    pts = c + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    rng = np.random.default_rng(seed)
    return np.asarray(pts + rng.normal(scale=noise_m, size=pts.shape))


def cylinder_surface(
    radius: float = 0.08,
    *,
    angle: float = 1.5 * np.pi,
    margin_angle: float = 0.5,
    half_height: float = 0.05,
    spacing_m: float = 0.003,
    noise_m: float = 0.0,
    camera_distance: float = 0.3,
    seed: int = 0,
) -> tuple[FloatArray, FloatArray]:
    """The outside of a cylinder about +z (matching :func:`arc_on_cylinder`) between angles
    ``-margin_angle`` and ``angle + margin_angle``, |z| <= ``half_height``.

    Returns (points (N, 3), viewpoints (N, 3)): each point was seen by a camera
    ``camera_distance`` out along its radial direction, as a sweep around the pipe would.
    """
    rng = np.random.default_rng(seed)
    span = angle + 2.0 * margin_angle
    n_phi = round(span * radius / spacing_m) + 1
    n_z = round(2.0 * half_height / spacing_m) + 1
    phi, z = np.meshgrid(
        np.linspace(-margin_angle, angle + margin_angle, n_phi),
        np.linspace(-half_height, half_height, n_z),
        indexing="ij",
    )
    phi, z = phi.ravel(), z.ravel()
    radial = np.column_stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)])
    pts = radius * radial + np.column_stack([np.zeros((len(z), 2)), z])
    viewpoints = pts + camera_distance * radial
    pts = pts + rng.normal(scale=noise_m, size=pts.shape)
    return np.asarray(pts), np.asarray(viewpoints)


# --------------------------------------------------------------------------- synthetic recordings
# A tiny eye-in-hand scan written as MCAP (scrapcut's writer), ROS 1 bag or ROS 2 bag (rosbags'
# writers, with their own ROS 1 / ROS 2 messages), so readers can be checked against the truth.

SCAN_COLOR_TOPIC = "/camera/camera/color/image_raw"
SCAN_DEPTH_TOPIC = "/camera/camera/aligned_depth_to_color/image_raw"
SCAN_INFO_TOPIC = "/camera/camera/color/camera_info"
SCAN_OPTICAL_FRAME = "camera_color_optical_frame"
SCAN_OMEGA = 0.7  # rad/s about base z
SCAN_VELOCITY = (0.05, -0.02, 0.01)  # m/s
SCAN_LOG_LAG_NS = 20_000_000  # recorders log tens of ms after the header stamp


def scan_T_base_link8(t_s: ArrayLike) -> FloatArray:
    """Flange poses (N, 4, 4) of the synthetic scan at times ``t_s`` (N,) seconds: a
    constant-rate rotation about base z and a constant velocity, so TF slerp/lerp between
    samples is exact."""
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    T = np.tile(np.eye(4), (len(t), 1, 1))
    tilt = Rotation.from_euler("x", np.pi)  # flange looking down
    T[:, :3, :3] = (Rotation.from_euler("z", SCAN_OMEGA * t[:, None]) * tilt).as_matrix()
    T[:, :3, 3] = np.array([0.4, 0.1, 0.5]) + t[:, None] * np.array(SCAN_VELOCITY)
    return T


def scan_static_transforms() -> list[tuple[str, str, FloatArray]]:
    """(parent, child, T_parent_child): link8 -> hand -> camera_link -> optical frame."""
    links = [
        ("panda_link8", "panda_hand", [0.0, 0.0, 0.107], "z", [-np.pi / 4]),
        ("panda_hand", "camera_link", [0.05, 0.0, 0.03], "y", [-np.pi / 2]),
        ("camera_link", SCAN_OPTICAL_FRAME, [0.0, 0.015, 0.0], "zx", [-np.pi / 2, -np.pi / 2]),
    ]
    out = []
    for parent, child, t, axes, angles in links:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler(axes, angles).as_matrix()
        T[:3, 3] = t
        out.append((parent, child, T))
    return out


def scan_T_base_cam(t_s: ArrayLike) -> FloatArray:
    """True optical-frame poses (N, 4, 4) of the synthetic scan at ``t_s`` (N,) seconds."""
    T = scan_T_base_link8(t_s)
    for _, _, T_static in scan_static_transforms():
        T = T @ T_static
    return T


@dataclass
class SyntheticScan:
    """A tiny scan: images, stamps (int ns), TF sample stamps and a reference path.

    Depth is stamped 3 ms after colour; colour frame 2 has no depth and one extra depth image
    pairs with nothing. TF is sampled at 100 Hz from 20 ms before the first frame until about
    27 ms before the last, so the last frame is out of the pose range.
    """

    camera: CameraModel
    t0_ns: int
    color_stamps: list[int]
    depth_stamps: list[int]
    colors: list[NDArray[np.uint8]]
    depths_mm: list[NDArray[np.uint16]]
    tf_stamps: list[int]
    reference: FloatArray

    def seconds(self, stamps_ns: ArrayLike) -> FloatArray:
        """Seconds since ``t0_ns``."""
        return (np.asarray(stamps_ns, dtype=np.int64) - self.t0_ns) / 1e9


def synthetic_scan(
    n_frames: int = 6, *, width: int = 32, height: int = 24, seed: int = 0
) -> SyntheticScan:
    """The :class:`SyntheticScan` with ``n_frames`` colour images of ``width`` x ``height``."""
    rng = np.random.default_rng(seed)
    camera = CameraModel(
        width=width,
        height=height,
        fx=0.9 * width,
        fy=0.9 * width,
        cx=(width - 1) / 2,
        cy=(height - 1) / 2,
        distortion_model="plumb_bob",
        distortion=(0.05, -0.01, 0.0, 0.0, 0.0),
        frame_id=SCAN_OPTICAL_FRAME,
    )
    t0 = 1_700_000_000_000_000_000
    color_stamps = [t0 + k * 33_333_333 for k in range(n_frames)]
    depth_stamps = [s + 3_000_000 for k, s in enumerate(color_stamps) if k != 2]
    depth_stamps.append(color_stamps[-1] + 500_000_000)
    colors = [rng.integers(0, 256, (height, width, 3), dtype=np.uint8) for _ in color_stamps]
    depths = []
    for _ in depth_stamps:
        d = rng.integers(200, 900, (height, width)).astype(np.uint16)
        d[rng.random((height, width)) < 0.1] = 0
        depths.append(d)
    tf_stamps = list(range(t0 - 20_000_000, color_stamps[-1] - 20_000_000, 10_000_000))
    s = np.linspace(0.0, 1.0, 25)
    reference = np.column_stack([0.4 + 0.2 * s, 0.1 * np.sin(3 * s), np.zeros_like(s)])
    return SyntheticScan(
        camera, t0, color_stamps, depth_stamps, colors, depths, tf_stamps, reference
    )


@dataclass
class _ScanItem:
    log_time: int
    topic: str
    kind: str  # tf | info | image | path | string
    stamp: int
    payload: Any = None


def _scan_items(scan: SyntheticScan) -> list[_ScanItem]:
    """The scan's messages in log order, independent of the file format."""
    t0 = scan.t0_ns
    statics = scan_static_transforms()
    items = [
        # Two /tf_static publishers, stamps long before the recording.
        _ScanItem(t0 - 50_000_000, "/tf_static", "tf", 0, statics[:1]),
        _ScanItem(t0 - 40_000_000, "/tf_static", "tf", 12_345, statics[1:]),
        _ScanItem(t0 - 30_000_000, SCAN_INFO_TOPIC, "info", t0),
        _ScanItem(t0 + 1, "/scrapcut/reference", "path", t0, scan.reference),
        _ScanItem(t0 + 2, "/scrapcut/exploration", "string", t0 + 2, '{"step": 0, "grow": 12}'),
        _ScanItem(t0 + 3, "/scrapcut/exploration", "string", t0 + 3, '{"step": 1, "grow": 3}'),
    ]
    poses = scan_T_base_link8(scan.seconds(scan.tf_stamps))
    for stamp, T in zip(scan.tf_stamps, poses, strict=True):
        items.append(
            _ScanItem(stamp + 2_000_000, "/tf", "tf", stamp, [("panda_link0", "panda_link8", T)])
        )
    for stamp, rgb in zip(scan.color_stamps, scan.colors, strict=True):
        items.append(_ScanItem(stamp + SCAN_LOG_LAG_NS, SCAN_COLOR_TOPIC, "image", stamp, rgb))
    for stamp, mm in zip(scan.depth_stamps, scan.depths_mm, strict=True):
        items.append(_ScanItem(stamp + SCAN_LOG_LAG_NS, SCAN_DEPTH_TOPIC, "image", stamp, mm))
    items.sort(key=lambda item: item.log_time)
    return items


def write_scan(path: str | Path, scan: SyntheticScan, fmt: str, *, storage: str = "mcap") -> None:
    """Write ``scan`` as ``mcap`` (scrapcut's McapWriter), ``ros1`` (rosbags Writer1, ROS 1
    messages with K/D and header.seq) or ``ros2`` (rosbags Writer2, ``storage`` mcap|sqlite3)."""
    path = Path(path)
    if fmt == "mcap":
        _write_scan_mcap(path, scan)
    elif fmt == "ros2":
        _write_scan_ros2(path, scan, storage)
    elif fmt == "ros1":
        _write_scan_ros1(path, scan)
    else:
        raise ValueError(f"unknown format {fmt!r}")


def tiny_recording(
    path: str | Path, *, image_frame: str = "cam", depth_shape: tuple[int, int] = (4, 6)
) -> Path:
    """A one-frame 6 x 4 MCAP on the default topics, TF base -> flange -> cam (static).

    ``image_frame`` names the images' frame (not "cam": no TF path); ``depth_shape`` other
    than (4, 6) gives a colour/depth size mismatch.
    """
    from scrapcut_cli.recording.writer import McapWriter

    path = Path(path)
    camera = CameraModel(6, 4, 5.0, 5.0, 2.5, 1.5, frame_id=image_frame)
    with McapWriter(path) as writer:
        writer.write_tf(
            0, [("base", "flange", np.eye(4)), ("flange", "cam", np.eye(4))], static=True
        )
        writer.write_camera_info(SCAN_INFO_TOPIC, 5, camera)
        writer.write_image(SCAN_COLOR_TOPIC, 5, image_frame, np.zeros((4, 6, 3), np.uint8))
        writer.write_image(SCAN_DEPTH_TOPIC, 5, image_frame, np.ones(depth_shape, np.uint16))
    return path


def assert_same_frames(a: Sequence[Any], b: Sequence[Any], *, atol_m: float = 0.0) -> None:
    """Two non-empty lists of Frames are equal: index, stamp, camera, frames, pixels, extras,
    and poses (within ``atol_m``; 0 = bit for bit)."""
    assert len(a) == len(b) > 0
    for x, y in zip(a, b, strict=True):
        assert (x.index, x.stamp_ns, x.camera, x.base_frame, x.camera_frame) == (
            y.index,
            y.stamp_ns,
            y.camera,
            y.base_frame,
            y.camera_frame,
        )
        np.testing.assert_array_equal(x.color, y.color)
        np.testing.assert_array_equal(x.depth, y.depth)
        np.testing.assert_allclose(x.T_base_cam, y.T_base_cam, rtol=0, atol=atol_m)
        assert x.extras == y.extras


def _write_scan_mcap(path: Path, scan: SyntheticScan) -> None:
    from scrapcut_cli.recording.writer import McapWriter

    with McapWriter(path) as writer:
        writer.add_metadata("scrapcut", {"object": "synthetic", "paint": "orange"})
        for item in _scan_items(scan):
            log = item.log_time
            if item.kind == "tf":
                static = item.topic == "/tf_static"
                writer.write_tf(item.stamp, item.payload, static=static, log_time_ns=log)
            elif item.kind == "info":
                writer.write_camera_info(item.topic, item.stamp, scan.camera, log_time_ns=log)
            elif item.kind == "image":
                writer.write_image(
                    item.topic, item.stamp, SCAN_OPTICAL_FRAME, item.payload, log_time_ns=log
                )
            elif item.kind == "path":
                writer.write_path(item.topic, item.stamp, "panda_link0", item.payload)
            else:
                writer.write_string(item.topic, item.stamp, item.payload)


def _write_scan_ros2(path: Path, scan: SyntheticScan, storage: str) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    from scrapcut_cli.recording import messages as m

    store = m.typestore()
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections: dict[str, Any] = {}
        for item in _scan_items(scan):
            if item.kind == "tf":
                msgtype, msg = m.TF_MESSAGE, m.tf_msg(item.stamp, item.payload)
            elif item.kind == "info":
                msgtype, msg = m.CAMERA_INFO, m.camera_info_msg(item.stamp, scan.camera)
            elif item.kind == "image":
                msgtype = m.IMAGE
                msg = m.image_msg(item.stamp, SCAN_OPTICAL_FRAME, item.payload)
            elif item.kind == "path":
                msgtype, msg = m.PATH, m.path_msg(item.stamp, "panda_link0", item.payload)
            else:
                msgtype, msg = m.STRING, m.string_msg(item.payload)
            if item.topic not in connections:
                connections[item.topic] = writer.add_connection(
                    item.topic, msgtype, typestore=store
                )
            writer.write(connections[item.topic], item.log_time, store.serialize_cdr(msg, msgtype))


def _write_scan_ros1(path: Path, scan: SyntheticScan) -> None:
    """ROS 1 messages built with rosbags' Noetic typestore (K/D, header.seq; tf2_msgs added)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(
        get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    )
    types = store.types
    seq: dict[str, int] = {}

    def header(topic: str, stamp: int, frame_id: str) -> Any:
        seq[topic] = seq.get(topic, 0) + 1
        sec, nsec = divmod(stamp, 1_000_000_000)
        time = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        return types["std_msgs/msg/Header"](seq=seq[topic], stamp=time, frame_id=frame_id)

    def quaternion(q: ArrayLike) -> Any:
        x, y, z, w = np.asarray(q, dtype=np.float64)
        return types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)

    def message(item: _ScanItem) -> tuple[str, Any]:
        if item.kind == "tf":
            transforms = [
                types["geometry_msgs/msg/TransformStamped"](
                    header=header(item.topic, item.stamp, parent),
                    child_frame_id=child,
                    transform=types["geometry_msgs/msg/Transform"](
                        translation=types["geometry_msgs/msg/Vector3"](
                            x=M[0, 3], y=M[1, 3], z=M[2, 3]
                        ),
                        rotation=quaternion(Rotation.from_matrix(M[:3, :3]).as_quat()),
                    ),
                )
                for parent, child, M in item.payload
            ]
            return "tf2_msgs/msg/TFMessage", types["tf2_msgs/msg/TFMessage"](transforms=transforms)
        if item.kind == "info":
            cam = scan.camera
            P = np.zeros((3, 4))
            P[:, :3] = cam.K
            roi = types["sensor_msgs/msg/RegionOfInterest"](
                x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
            )
            return "sensor_msgs/msg/CameraInfo", types["sensor_msgs/msg/CameraInfo"](
                header=header(item.topic, item.stamp, cam.frame_id),
                height=cam.height,
                width=cam.width,
                distortion_model=cam.distortion_model,
                D=np.asarray(cam.distortion, dtype=np.float64),
                K=cam.K.ravel(),
                R=np.eye(3).ravel(),
                P=P.ravel(),
                binning_x=0,
                binning_y=0,
                roi=roi,
            )
        if item.kind == "image":
            img = np.ascontiguousarray(item.payload)
            return "sensor_msgs/msg/Image", types["sensor_msgs/msg/Image"](
                header=header(item.topic, item.stamp, SCAN_OPTICAL_FRAME),
                height=img.shape[0],
                width=img.shape[1],
                encoding="rgb8" if img.ndim == 3 else "16UC1",
                is_bigendian=0,
                step=img.shape[1] * (3 if img.ndim == 3 else 2),
                data=img.reshape(-1).view(np.uint8),
            )
        if item.kind == "path":
            poses = [
                types["geometry_msgs/msg/PoseStamped"](
                    header=header(item.topic, item.stamp, "panda_link0"),
                    pose=types["geometry_msgs/msg/Pose"](
                        position=types["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                        orientation=quaternion([0.0, 0.0, 0.0, 1.0]),
                    ),
                )
                for p in item.payload
            ]
            return "nav_msgs/msg/Path", types["nav_msgs/msg/Path"](
                header=header(item.topic, item.stamp, "panda_link0"), poses=poses
            )
        return "std_msgs/msg/String", types["std_msgs/msg/String"](data=item.payload)

    with Writer(path) as writer:
        connections: dict[tuple[str, str], Any] = {}
        static_publishers = 0
        for item in _scan_items(scan):
            msgtype, msg = message(item)
            callerid = "/recorder"
            if item.topic == "/tf_static":  # each static publisher is its own ROS 1 connection
                static_publishers += 1
                callerid = f"/static_publisher_{static_publishers}"
            key = (item.topic, callerid)
            if key not in connections:
                connections[key] = writer.add_connection(
                    item.topic,
                    msgtype,
                    typestore=store,
                    callerid=callerid,
                    latching=int(item.topic == "/tf_static"),
                )
            writer.write(connections[key], item.log_time, store.serialize_ros1(msg, msgtype))


# --------------------------------------------------------------------------- CLI results


def one_line_error(result: Any) -> str:
    """The one stderr line of a ``CliRunner`` result that failed with a known error: exit code
    1, a single ``scrapcut: error: ...`` line, no traceback. Returns that line."""
    assert result.exit_code == 1, result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("scrapcut: error: "), result.stderr
    assert "Traceback" not in result.output
    return str(lines[0])


def under_file_size_limit(size: int, check: Callable[[], None]) -> None:
    """Run ``check`` (which asserts) in a forked child whose writes past ``size`` bytes fail
    with EFBIG, as on a full disk, without root or a small tmpfs.

    The limit (RLIMIT_FSIZE, SIGXFSZ ignored) is a process's: set in the test process it would
    also cut pytest's own writes to a log file already larger than ``size`` (CI's), so it is
    only ever set in the child. A failed assertion in the child fails the test with its
    traceback.
    """
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: never returns into pytest
        status = 0
        try:
            os.close(read_end)
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            hard = resource.getrlimit(resource.RLIMIT_FSIZE)[1]
            resource.setrlimit(resource.RLIMIT_FSIZE, (size, hard))
            check()
            message = b""
        except BaseException:
            message = traceback.format_exc().encode()
            status = 1
        try:
            os.write(write_end, message)
        finally:
            os._exit(status)
    os.close(write_end)
    chunks = []
    while chunk := os.read(read_end, 65536):
        chunks.append(chunk)
    os.close(read_end)
    _, wait_status = os.waitpid(pid, 0)
    if os.waitstatus_to_exitcode(wait_status) != 0:
        pytest.fail("in the child with a file size limit:\n" + b"".join(chunks).decode(), False)


# --------------------------------------------------------------------------- Panda kinematics

#: Franka's published modified (Craig) DH parameters of the Panda, joint by joint: (a_{i-1} m,
#: d_i m, alpha_{i-1} rad); the flange adds d = 0.107 m (FCI documentation, "Robot and
#: interface specifications", "Denavit–Hartenberg parameters"). An oracle independent of the
#: URDF chain the planner uses.
PANDA_DH = (
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -np.pi / 2),
    (0.0, 0.316, np.pi / 2),
    (0.0825, 0.0, np.pi / 2),
    (-0.0825, 0.384, -np.pi / 2),
    (0.0, 0.0, np.pi / 2),
    (0.088, 0.0, np.pi / 2),
)
PANDA_DH_FLANGE_D = 0.107


def panda_dh_flange(q: ArrayLike) -> FloatArray:
    """T_base_flange (4, 4) of joints (7,) from :data:`PANDA_DH`:
    T_{i-1,i} = Rot_x(alpha_{i-1}) Trans_x(a_{i-1}) Rot_z(theta_i) Trans_z(d_i)."""

    def link(a: float, d: float, alpha: float, theta: float) -> FloatArray:
        ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
        return np.array(
            [
                [ct, -st, 0.0, a],
                [st * ca, ct * ca, -sa, -d * sa],
                [st * sa, ct * sa, ca, d * ca],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )

    T = np.eye(4)
    for (a, d, alpha), theta in zip(PANDA_DH, np.asarray(q, dtype=np.float64), strict=True):
        T = T @ link(a, d, alpha, float(theta))
    return T @ link(0.0, PANDA_DH_FLANGE_D, 0.0, 0.0)
