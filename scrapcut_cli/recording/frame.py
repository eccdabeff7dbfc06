"""The data model every stage reads: a camera model and one synchronised RGB-D frame with pose.

This module imports only numpy, so perception, fitting and the simulator can use it freely.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

DISTORTION_MODELS = ("none", "plumb_bob", "rational_polynomial", "equidistant")
#: No RGB-D camera has an image side over 16384 px (8K colour is 7680); a larger size is a
#: damaged CameraInfo, and per-pixel arrays of it would not fit in memory.
MAX_IMAGE_SIDE = 16384


@dataclass(frozen=True)
class CameraModel:
    """Pinhole camera with optional lens distortion, as in sensor_msgs/CameraInfo.

    ``distortion_model`` is ``none``, ``plumb_bob`` / ``rational_polynomial`` (D = k1, k2, p1,
    p2, k3[, k4, k5, k6]) or ``equidistant`` (D = k1, k2, k3, k4, the fisheye model). Pixel
    coordinates follow ROS: the centre of the top-left pixel is (0, 0).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion_model: str = "none"
    distortion: tuple[float, ...] = ()
    frame_id: str = ""

    def __post_init__(self) -> None:
        if not (0 < self.width <= MAX_IMAGE_SIDE and 0 < self.height <= MAX_IMAGE_SIDE):
            raise ValueError(
                f"camera size must be 1-{MAX_IMAGE_SIDE} px a side, got {self.width}x{self.height}"
            )
        numbers = (self.fx, self.fy, self.cx, self.cy, *self.distortion)
        if not all(math.isfinite(v) and abs(v) < 1e9 for v in numbers):
            raise ValueError(
                f"intrinsics must be finite, got fx={self.fx} fy={self.fy} cx={self.cx} "
                f"cy={self.cy} distortion={self.distortion}"
            )
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={self.fx} fy={self.fy}")
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(
                f"unknown distortion model {self.distortion_model!r}; "
                f"known: {', '.join(DISTORTION_MODELS)}"
            )

    @property
    def K(self) -> NDArray[np.float64]:
        """(3, 3) intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def is_distorted(self) -> bool:
        return self.distortion_model != "none" and any(abs(d) > 0 for d in self.distortion)

    # ------------------------------------------------------------------ distortion

    def _distort(
        self, x: NDArray[np.float64], y: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Apply the lens model to normalised undistorted coordinates."""
        d = np.zeros(8)
        d[: len(self.distortion)] = self.distortion[:8]
        if self.distortion_model == "equidistant":
            k1, k2, k3, k4 = d[:4]
            r = np.hypot(x, y)
            theta = np.arctan(r)
            t2 = theta * theta
            theta_d = theta * (1 + k1 * t2 + k2 * t2**2 + k3 * t2**3 + k4 * t2**4)
            scale = np.where(r > 1e-12, theta_d / np.where(r > 1e-12, r, 1.0), 1.0)
            return x * scale, y * scale
        k1, k2, p1, p2, k3, k4, k5, k6 = d
        r2 = x * x + y * y
        radial = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return xd, yd

    def _undistort(
        self, xd: NDArray[np.float64], yd: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Invert the lens model by fixed-point iteration (as OpenCV's undistortPoints)."""
        x, y = xd.copy(), yd.copy()
        for _ in range(20):
            ex, ey = self._distort(x, y)
            x = x - (ex - xd)
            y = y - (ey - yd)
        return x, y

    # ------------------------------------------------------------------ rays

    def normalized_rays(self, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Normalised image coordinates (N, 2): the ray through pixel (u, v) is (x, y, 1)."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        x = (u - self.cx) / self.fx
        y = (v - self.cy) / self.fy
        if self.is_distorted:
            x, y = self._undistort(x, y)
        return np.stack([x, y], axis=-1)

    def ray_grid(self) -> NDArray[np.float32]:
        """(H, W, 2) float32 normalised ray coordinates of every pixel, cached per camera.

        Back-projection of any pixel subset is then a gather and a multiply by depth.
        """
        return _ray_grid(self)

    def unproject(self, u: ArrayLike, v: ArrayLike, depth_m: ArrayLike) -> NDArray[np.float64]:
        """Points (N, 3) in the camera optical frame for pixels (u, v) at z = ``depth_m``."""
        xy = self.normalized_rays(u, v).reshape(-1, 2)
        z = np.asarray(depth_m, dtype=np.float64).reshape(-1)
        return np.column_stack([xy[:, 0] * z, xy[:, 1] * z, z])

    def project(self, points_cam: ArrayLike) -> NDArray[np.float64]:
        """Pixel coordinates (N, 2) of points (N, 3) in the camera optical frame (z > 0)."""
        p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        x = p[:, 0] / p[:, 2]
        y = p[:, 1] / p[:, 2]
        if self.is_distorted:
            x, y = self._distort(x, y)
        return np.column_stack([self.fx * x + self.cx, self.fy * y + self.cy])

    def scaled(self, width: int, height: int) -> CameraModel:
        """The same lens at another resolution (intrinsics scaled, distortion unchanged)."""
        sx = width / self.width
        sy = height / self.height
        return replace(
            self,
            width=width,
            height=height,
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
        )

    def decimated(self, step: int) -> CameraModel:
        """The camera of every ``step``-th pixel each way (rows and columns 0, step, ...):
        pixel (u, v) of it is pixel (step·u, step·v) of this one, so the principal point and
        focal lengths divide by ``step`` exactly (not :meth:`scaled`'s area mapping)."""
        if step == 1:
            return self
        return replace(
            self,
            width=-(-self.width // step),
            height=-(-self.height // step),
            fx=self.fx / step,
            fy=self.fy / step,
            cx=self.cx / step,
            cy=self.cy / step,
        )


@functools.lru_cache(maxsize=8)
def _ray_grid(camera: CameraModel) -> NDArray[np.float32]:
    v, u = np.mgrid[0 : camera.height, 0 : camera.width]
    grid = camera.normalized_rays(u.ravel(), v.ravel()).astype(np.float32)
    grid = grid.reshape(camera.height, camera.width, 2)
    grid.setflags(write=False)
    return grid


def _every_pixel_of_rgb(rgb: NDArray[np.uint8], step: int) -> NDArray[np.uint8]:
    """``rgb[::step, ::step]`` (H, W, 3), contiguous: gathered row by row from the kept rows'
    bytes, a quarter faster than numpy's strided copy of 3-byte pixels."""
    height, width = rgb.shape[:2]
    rows = np.ascontiguousarray(rgb).reshape(height, 3 * width)[::step]
    out = np.take(rows, _rgb_columns(width, step), axis=1)
    return out.reshape(rows.shape[0], -1, 3)


@functools.lru_cache(maxsize=8)
def _rgb_columns(width: int, step: int) -> NDArray[np.intp]:
    """The byte columns of every ``step``-th pixel of an RGB row ``width`` pixels long."""
    pixels = np.arange(0, width, step, dtype=np.intp)
    return (3 * pixels[:, None] + np.arange(3, dtype=np.intp)).reshape(-1)


@dataclass(frozen=True, eq=False)
class Frame:
    """One colour image with aligned depth and the camera pose at the image stamp.

    Attributes
    ----------
    index : int
        Position of the frame in the recording's usable frames, from 0.
    stamp_ns : int
        Colour image header stamp, nanoseconds.
    color : (H, W, 3) uint8
        RGB.
    depth : (H, W) float32
        Metres, aligned to the colour image; NaN where invalid.
    camera : CameraModel
        Intrinsics of the colour camera (depth is aligned to it).
    T_base_cam : (4, 4) float64
        Maps points in the camera optical frame into the base frame, at ``stamp_ns``.
    base_frame, camera_frame : str
        TF frame ids.
    """

    index: int
    stamp_ns: int
    color: NDArray[np.uint8]
    depth: NDArray[np.float32]
    camera: CameraModel
    T_base_cam: NDArray[np.float64]
    base_frame: str = "panda_link0"
    camera_frame: str = "camera_color_optical_frame"
    extras: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        h, w = self.camera.height, self.camera.width
        if self.color.shape != (h, w, 3) or self.color.dtype != np.uint8:
            raise ValueError(
                f"colour image must be ({h}, {w}, 3) uint8, got {self.color.shape} "
                f"{self.color.dtype}"
            )
        if self.depth.shape != (h, w) or self.depth.dtype != np.float32:
            raise ValueError(
                f"depth image must be ({h}, {w}) float32, got {self.depth.shape} {self.depth.dtype}"
            )
        if np.asarray(self.T_base_cam).shape != (4, 4):
            raise ValueError("T_base_cam must be a (4, 4) matrix")

    def decimated(self, step: int) -> Frame:
        """This frame's every ``step``-th pixel each way, colour and depth alike (rows and
        columns 0, step, ...: a depth is never averaged across an edge into a flying pixel),
        with :meth:`CameraModel.decimated`; ``extras["decimation"]`` says by how much and
        ``extras["full_depth"]`` keeps this frame's depth image (not copied), for the tests
        that look at a pixel's neighbours one camera pixel away."""
        if step == 1:
            return self
        return replace(
            self,
            color=_every_pixel_of_rgb(self.color, step),
            depth=np.ascontiguousarray(self.depth[::step, ::step]),
            camera=self.camera.decimated(step),
            extras={**self.extras, "decimation": step, "full_depth": self.depth},
        )

    @property
    def camera_position(self) -> NDArray[np.float64]:
        """Optical centre (3,) in the base frame, metres."""
        return np.asarray(self.T_base_cam[:3, 3], dtype=np.float64)

    @property
    def optical_axis(self) -> NDArray[np.float64]:
        """Viewing direction (3,), unit, in the base frame."""
        return np.asarray(self.T_base_cam[:3, 2], dtype=np.float64)
