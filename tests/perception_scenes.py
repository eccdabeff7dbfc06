"""Synthetic RGB-D frames for the perception tests: a painted cylinder on a floor.

Rendered analytically for a CameraModel: exact depth, a paint stroke decided by the distance of
each surface point to a reference polyline, rust patches (the orange paint's hue but dull),
grey steel, Lambert shading from a light at the camera, and optional noise, NaN holes and
flying pixels. Small images (160x120) keep the tests fast. Seeded: same seed, same frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.geometry import PolylineDistance, look_at
from scrapcut_cli.recording.frame import CameraModel, Frame

FloatArray = NDArray[np.float64]

#: Cylinder lying along the base x axis on the floor (z = 0): axis at y = 0.5 m, z = radius.
CYLINDER_RADIUS_M = 0.1
CYLINDER_AXIS_YZ = (0.5, 0.1)
PAINT_RGB = (255, 110, 0)  # the orange preset's nominal colour
RUST_RGB = (150, 92, 62)  # hue ~20 deg like orange paint, S ~0.59 (dull): must be rejected
STEEL_RGB = (118, 121, 127)
FLOOR_RGB = (70, 72, 70)


def small_camera(width: int = 160, height: int = 120) -> CameraModel:
    """A D435i-like colour camera (fx = fy = 615 at 640x480) scaled to ``width`` x ``height``."""
    full = CameraModel(640, 480, 615.0, 615.0, 319.5, 239.5, frame_id="camera_optical")
    return full.scaled(width, height)


def cylinder_top_line(n: int = 300, *, length_m: float = 0.3) -> FloatArray:
    """(n, 3) reference polyline ON the cylinder, wavy along its top, metres, base frame."""
    x = np.linspace(-length_m / 2, length_m / 2, n)
    phi = 0.35 * np.sin(2 * np.pi * x / 0.2)
    y0, z0 = CYLINDER_AXIS_YZ
    r = CYLINDER_RADIUS_M
    return np.column_stack([x, y0 + r * np.sin(phi), z0 + r * np.cos(phi)])


def cylinder_ring_line(
    n: int = 300, *, x_m: float = 0.0, half_angle_deg: float = 110.0
) -> FloatArray:
    """(n, 3) reference polyline ON the cylinder, around it at ``x_m``, past its silhouettes."""
    phi = np.radians(np.linspace(-half_angle_deg, half_angle_deg, n))
    y0, z0 = CYLINDER_AXIS_YZ
    r = CYLINDER_RADIUS_M
    return np.column_stack([np.full(n, x_m), y0 + r * np.sin(phi), z0 + r * np.cos(phi)])


def top_view(x_m: float, *, height_m: float = 0.3, tilt_m: float = 0.0) -> FloatArray:
    """``T_base_cam`` looking down at the cylinder's top at ``x_m`` from ``height_m`` above it."""
    y0, z0 = CYLINDER_AXIS_YZ
    top = np.array([x_m, y0, z0 + CYLINDER_RADIUS_M])
    eye = top + np.array([0.0, tilt_m, height_m])
    return look_at(eye, top, up_hint=(1.0, 0.0, 0.0))


@dataclass(frozen=True)
class SceneNoise:
    """Imperfections of a rendered frame (all zero: exact)."""

    depth_sigma_m: float = 0.0
    hole_fraction: float = 0.0  # share of pixels set to NaN at random
    flying_pixels: bool = False  # the near pixel of a horizontal depth edge: the mid depth
    color_sigma: float = 0.0  # Gaussian noise on colour bytes


#: D435i-like imperfections at half a millimetre of depth noise, for the perception tests.
NOISY = SceneNoise(depth_sigma_m=0.0005, hole_fraction=0.02, flying_pixels=True, color_sigma=3.0)
#: A little lighter, for the command tests (fewer holes, less colour noise).
NOISY_LIGHT = SceneNoise(
    depth_sigma_m=0.0005, hole_fraction=0.01, flying_pixels=True, color_sigma=2.0
)


def render_cylinder(
    camera: CameraModel,
    T_base_cam: FloatArray,
    reference: FloatArray,
    *,
    stroke_width_m: float = 0.025,
    rust: bool = True,
    noise: SceneNoise | None = None,
    seed: int = 0,
    index: int = 0,
) -> Frame:
    """A Frame of the painted cylinder on the floor seen from ``T_base_cam`` (base frame)."""
    noise = noise or SceneNoise()
    rng = np.random.default_rng(seed)
    h, w = camera.height, camera.width
    rays = camera.ray_grid().reshape(-1, 2).astype(np.float64)
    d_cam = np.column_stack([rays, np.ones(len(rays))])
    R, c = T_base_cam[:3, :3], T_base_cam[:3, 3]
    d = d_cam @ R.T  # base-frame ray directions scaled so that the ray parameter is the depth
    y0, z0 = CYLINDER_AXIS_YZ
    r = CYLINDER_RADIUS_M
    oy, oz = c[1] - y0, c[2] - z0
    a = d[:, 1] ** 2 + d[:, 2] ** 2
    b = 2 * (d[:, 1] * oy + d[:, 2] * oz)
    disc = b * b - 4 * a * (oy**2 + oz**2 - r**2)
    with np.errstate(invalid="ignore", divide="ignore"):
        t_cyl = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), np.inf)
        t_cyl = np.where(t_cyl > 0, t_cyl, np.inf)
        t_floor = np.where(d[:, 2] < 0, -c[2] / d[:, 2], np.inf)
    on_cyl = t_cyl < t_floor
    depth = np.minimum(t_cyl, t_floor)
    hit = np.isfinite(depth)
    p = c + np.where(hit, depth, 0.0)[:, None] * d
    normal = np.zeros_like(p)
    normal[on_cyl, 1] = (p[on_cyl, 1] - y0) / r
    normal[on_cyl, 2] = (p[on_cyl, 2] - z0) / r
    normal[~on_cyl, 2] = 1.0
    color = np.empty((len(p), 3))
    color[:] = FLOOR_RGB
    color[on_cyl] = STEEL_RGB
    if rust:
        phi = np.arctan2(p[:, 1] - y0, p[:, 2] - z0)
        patch = np.sin(p[:, 0] * 70.0) * np.cos(phi * 9.0) > 0.3
        color[on_cyl & patch] = RUST_RGB
    paint = np.zeros(len(p), dtype=bool)
    if on_cyl.any():
        dist = PolylineDistance(reference).distance(p[on_cyl])
        paint[np.flatnonzero(on_cyl)[dist < stroke_width_m / 2]] = True
    color[paint] = PAINT_RGB
    view = p - c
    view /= np.linalg.norm(view, axis=1, keepdims=True) + 1e-12
    shade = 0.25 + 0.75 * np.clip(-np.einsum("ij,ij->i", view, normal), 0, 1)
    color *= shade[:, None]
    if noise.color_sigma > 0:
        color += rng.normal(0, noise.color_sigma, color.shape)
    depth = np.where(hit, depth, np.nan).reshape(h, w)
    if noise.depth_sigma_m > 0:
        depth = depth + rng.normal(0, noise.depth_sigma_m, depth.shape)
    if noise.flying_pixels:
        edge = np.abs(np.diff(depth, axis=1)) > 0.02
        near = np.where(depth[:, 1:] < depth[:, :-1], 1, 0)  # which side of the edge is near
        mid = 0.5 * (depth[:, 1:] + depth[:, :-1])
        rows, cols = np.nonzero(edge)
        depth[rows, cols + near[rows, cols]] = mid[rows, cols]
    if noise.hole_fraction > 0:
        depth[rng.random(depth.shape) < noise.hole_fraction] = np.nan
    return Frame(
        index=index,
        stamp_ns=1_000_000_000 + index * 33_333_333,
        color=np.clip(np.rint(color), 0, 255).astype(np.uint8).reshape(h, w, 3),
        depth=depth.astype(np.float32),
        camera=camera,
        T_base_cam=np.asarray(T_base_cam, dtype=np.float64),
    )


def write_scene_recording(
    path: object,
    frames: list[Frame],
    *,
    paint: str | None = "orange",
    reference: FloatArray | None = None,
) -> None:
    """Write frames as a small ROS 2 MCAP (realsense-ros 4.x topics, 16UC1 depth, /tf).

    The camera pose goes on /tf as base -> camera_link (three samples around each image stamp)
    and /tf_static camera_link -> optical frame (identity), like a real hand-eye chain.
    """
    from scrapcut_cli.recording.writer import McapWriter

    base, link = "panda_link0", "camera_link"
    optical = frames[0].camera.frame_id or "camera_color_optical_frame"
    with McapWriter(path) as writer:  # type: ignore[arg-type]
        if paint is not None:
            writer.add_metadata("scrapcut", {"paint": paint, "object": "synthetic_cylinder"})
        writer.write_tf(frames[0].stamp_ns - 10**8, [(link, optical, np.eye(4))], static=True)
        for frame in frames:
            for dt in (-5_000_000, 0, 5_000_000):
                writer.write_tf(frame.stamp_ns + dt, [(base, link, frame.T_base_cam)])
            t = frame.stamp_ns
            writer.write_camera_info("/camera/camera/color/camera_info", t, frame.camera)
            writer.write_image("/camera/camera/color/image_raw", t, optical, frame.color)
            depth_mm = np.nan_to_num(np.rint(frame.depth * 1000.0), nan=0.0).astype(np.uint16)
            writer.write_image(
                "/camera/camera/aligned_depth_to_color/image_raw", t, optical, depth_mm
            )
        if reference is not None:
            writer.write_path("/scrapcut/reference", frames[0].stamp_ns, base, reference)
