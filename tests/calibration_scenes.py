"""Synthetic eye-in-hand scans with a known hand-eye error and clock offset (calibration tests).

A flange (``panda_link8``) rests at a few views of the painted cylinder of ``perception_scenes``
and moves between them with minimum-jerk profiles; the camera hangs from it by the TRUE mount,
and images are stamped ``stamp_offset_s`` late on the camera's clock. The published mount (what
/tf_static says) differs from the true one by a known error. Frames are rendered analytically
at 160x120 (numpy only), so a scan of a dozen frames takes well under a second.

``CalibrationScan.trajectory`` answers the solver's pose queries exactly (no /tf sampling);
``write_calibration_recording`` writes the same scan as an MCAP with /tf at 100 Hz and the
published mount on /tf_static, as a real recording holds it.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from perception_scenes import (
    CYLINDER_AXIS_YZ,
    CYLINDER_RADIUS_M,
    SceneNoise,
    render_cylinder,
    small_camera,
)
from perception_scenes import cylinder_top_line as _top_line
from scipy.spatial.transform import Rotation

from scrapcut_cli.geometry import invert_transform, look_at, make_transform
from scrapcut_cli.recording.frame import CameraModel, Frame
from scrapcut_cli.recording.mount import CameraMount

FloatArray = NDArray[np.float64]

MOVING_FRAME = "panda_link8"
CAMERA_FRAME = "camera_color_optical_frame"
T0_NS = 1_000_000_000_000
#: The published mount: camera 60 mm off the flange axis, 100 mm down it, looking along it.
PUBLISHED_MOUNT = make_transform(
    Rotation.from_euler("z", 90, degrees=True).as_matrix(), (0.06, 0.0, 0.10)
)


def mount_error(translation_mm: Sequence[float], rotation_deg: Sequence[float]) -> FloatArray:
    """A correction [Rot(r), t] (4, 4) in the camera frame: t in mm, r a rotation vector in deg."""
    return make_transform(
        Rotation.from_rotvec(np.radians(rotation_deg)).as_matrix(),
        np.asarray(translation_mm, dtype=np.float64) / 1000.0,
    )


def look_down(
    x_m: float, *, tilt_deg: float = 0.0, roll_deg: float = 0.0, height_m: float = 0.28
) -> FloatArray:
    """T_base_cam looking at the cylinder's top at ``x_m``: tilted about the pipe's axis by
    ``tilt_deg`` (the eye moves round it), rolled about the optical axis by ``roll_deg``."""
    y0, z0 = CYLINDER_AXIS_YZ
    top = np.array([x_m, y0, z0 + CYLINDER_RADIUS_M])
    a = np.radians(tilt_deg)
    eye = top + height_m * np.array([0.0, np.sin(a), np.cos(a)])
    T = look_at(eye, top, up_hint=(1.0, 0.0, 0.0))
    T[:3, :3] = T[:3, :3] @ Rotation.from_euler("z", roll_deg, degrees=True).as_matrix()
    return T


#: Six views with tilt and roll diversity, along 0.2 m of the line.
DIVERSE_VIEWS = (
    dict(x_m=-0.08, tilt_deg=-20.0, roll_deg=0.0),
    dict(x_m=-0.04, tilt_deg=15.0, roll_deg=35.0),
    dict(x_m=0.0, tilt_deg=0.0, roll_deg=-30.0),
    dict(x_m=0.04, tilt_deg=-15.0, roll_deg=60.0),
    dict(x_m=0.08, tilt_deg=20.0, roll_deg=-10.0),
    dict(x_m=0.02, tilt_deg=30.0, roll_deg=20.0),
)
#: Six views that all share one orientation (pure translations along the line).
PARALLEL_VIEWS = tuple(dict(x_m=x) for x in (-0.1, -0.06, -0.02, 0.02, 0.06, 0.1))


@dataclass
class CalibrationScan:
    """Rest views joined by minimum-jerk moves; frames at rest and (``moving_fps``) in motion."""

    views: Sequence[dict[str, float] | FloatArray] = DIVERSE_VIEWS  # look_down args or poses
    error: FloatArray = field(default_factory=lambda: np.eye(4))  # true = published @ error
    stamp_offset_s: float = 0.0  # header stamp = capture time + this
    moving_fps: float = 0.0  # images per second while moving (0: at rest only)
    move_s: float = 0.8
    rest_s: float = 0.4
    width: int = 160
    height: int = 120
    noise: SceneNoise = field(default_factory=SceneNoise)
    seed: int = 0
    camera: CameraModel = field(init=False)
    reference: FloatArray = field(init=False)
    flanges: list[FloatArray] = field(init=False)

    def __post_init__(self) -> None:
        self.camera = replace(small_camera(self.width, self.height), frame_id=CAMERA_FRAME)
        self.reference = _top_line(120, length_m=0.34)
        M_inv = invert_transform(PUBLISHED_MOUNT)
        # The robot goes where the published mount says the views are.
        self.flanges = [
            (look_down(**v) if isinstance(v, dict) else np.asarray(v)) @ M_inv for v in self.views
        ]

    @property
    def true_mount(self) -> FloatArray:
        return np.asarray(PUBLISHED_MOUNT @ self.error)

    @property
    def published(self) -> CameraMount:
        return CameraMount(MOVING_FRAME, CAMERA_FRAME, PUBLISHED_MOUNT, 0.0)

    @property
    def true_time_offset_s(self) -> float:
        """What the calibration should find: added to a stamp it gives the capture time."""
        return -self.stamp_offset_s

    @property
    def duration_s(self) -> float:
        return len(self.views) * self.rest_s + (len(self.views) - 1) * self.move_s

    def flange_at(self, t_s: NDArray[np.float64]) -> FloatArray:
        """T_base_link8 (N, 4, 4) at times ``t_s`` (N,) seconds since T0."""
        t = np.asarray(t_s, dtype=np.float64)
        period = self.rest_s + self.move_s
        seg = np.clip(np.floor(t / period).astype(int), 0, len(self.views) - 1)
        local = t - seg * period
        tau = np.clip((local - self.rest_s) / self.move_s, 0.0, 1.0)
        tau = np.where(seg >= len(self.views) - 1, 0.0, tau)
        s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
        nxt = np.minimum(seg + 1, len(self.flanges) - 1)
        F = np.array(self.flanges)
        r0 = Rotation.from_matrix(F[seg, :3, :3])
        delta = (r0.inv() * Rotation.from_matrix(F[nxt, :3, :3])).as_rotvec()
        out = np.tile(np.eye(4), (len(t), 1, 1))
        out[:, :3, :3] = (r0 * Rotation.from_rotvec(s[:, None] * delta)).as_matrix()
        out[:, :3, 3] = (1.0 - s[:, None]) * F[seg, :3, 3] + s[:, None] * F[nxt, :3, 3]
        return out

    def trajectory(self, stamps_ns: NDArray[np.int64]) -> tuple[FloatArray, NDArray[np.bool_]]:
        """The solver's pose query: T_base_link8 at TF-clock stamps, all valid in range."""
        t = (np.asarray(stamps_ns, dtype=np.int64) - T0_NS) / 1e9
        valid = (t >= 0.0) & (t <= self.duration_s)
        return self.flange_at(np.clip(t, 0.0, self.duration_s)), valid

    def capture_times(self) -> list[float]:
        """Capture times (s): the middle of each rest, and ``moving_fps`` frames per move."""
        times = []
        period = self.rest_s + self.move_s
        for k in range(len(self.views)):
            times.append(k * period + 0.5 * self.rest_s)
            if k + 1 < len(self.views) and self.moving_fps > 0:
                n = int(self.move_s * self.moving_fps)
                start = k * period + self.rest_s
                times += [start + (j + 0.5) * self.move_s / n for j in range(n)]
        return sorted(times)

    def rest_indices(self) -> set[int]:
        """Indices of the frames taken at rest (one per view)."""
        period = self.rest_s + self.move_s
        rests = {round(k * period + 0.5 * self.rest_s, 9) for k in range(len(self.views))}
        return {i for i, t in enumerate(self.capture_times()) if round(t, 9) in rests}

    def frames(self) -> list[Frame]:
        """Rendered frames, stamped on the camera's clock, posed as a reader would pose them
        with the published mount (the calibration must not see the truth)."""
        out = []
        times = self.capture_times()
        F_true = self.flange_at(np.array(times))
        for index, (t, F) in enumerate(zip(times, F_true, strict=True)):
            frame = render_cylinder(
                self.camera,
                F @ self.true_mount,
                self.reference,
                noise=self.noise,
                seed=self.seed * 1000 + index,
                index=index,
            )
            stamp = T0_NS + round((t + self.stamp_offset_s) * 1e9)
            F_stamp = self.flange_at(np.array([(stamp - T0_NS) / 1e9]))[0]
            out.append(
                replace(
                    frame,
                    stamp_ns=stamp,
                    T_base_cam=F_stamp @ PUBLISHED_MOUNT,
                    base_frame="panda_link0",
                    camera_frame=CAMERA_FRAME,
                )
            )
        return out


def write_calibration_recording(
    path: str | Path, scan: CalibrationScan, *, reasons: Sequence[str] = ()
) -> list[Frame]:
    """The scan as an MCAP: /tf link0 -> link8 at 100 Hz, the published mount on /tf_static
    (link8 -> camera_link -> optical frame), 16UC1 depth, orange paint. Returns the frames.

    ``reasons``: also an exploration log, one entry per view (its rest frame's stamp and the
    reason of the decision taken there), as the planner writes on /scrapcut/exploration.
    """
    from scrapcut_cli.recording.writer import McapWriter

    frames = scan.frames()
    camera_link = make_transform(np.eye(3), (0.0, 0.0, 0.0))
    # Split the published mount across two static links, as a real chain has.
    T_link8_camlink = PUBLISHED_MOUNT @ invert_transform(camera_link)
    with McapWriter(path) as writer:
        writer.add_metadata("scrapcut", {"paint": "orange", "object": "synthetic_cylinder"})
        writer.write_tf(
            T0_NS - 10**9,
            [
                (MOVING_FRAME, "camera_link", T_link8_camlink),
                ("camera_link", CAMERA_FRAME, camera_link),
            ],
            static=True,
        )
        stamps = np.arange(T0_NS, T0_NS + round(scan.duration_s * 1e9) + 1, 10_000_000)
        poses = scan.flange_at((stamps - T0_NS) / 1e9)
        events: list[tuple[int, int, object]] = [
            (int(s), 0, T) for s, T in zip(stamps, poses, strict=True)
        ]
        events += [(f.stamp_ns, 1, f) for f in frames]
        for stamp, kind, item in sorted(events, key=lambda e: (e[0], e[1])):
            if kind == 0:
                writer.write_tf(stamp, [("panda_link0", MOVING_FRAME, item)])
                continue
            assert isinstance(item, Frame)
            writer.write_camera_info("/camera/camera/color/camera_info", stamp, item.camera)
            writer.write_image("/camera/camera/color/image_raw", stamp, CAMERA_FRAME, item.color)
            depth_mm = np.nan_to_num(np.rint(item.depth * 1000.0), nan=0.0).astype(np.uint16)
            writer.write_image(
                "/camera/camera/aligned_depth_to_color/image_raw", stamp, CAMERA_FRAME, depth_mm
            )
        writer.write_path("/scrapcut/reference", T0_NS, "panda_link0", scan.reference)
        rest = [f for f in frames if f.index in scan.rest_indices()]
        for k, (frame, reason) in enumerate(zip(rest, reasons, strict=False)):
            entry = {"k": k, "frame_stamp_ns": frame.stamp_ns, "reason": reason}
            writer.write_string("/scrapcut/exploration", frame.stamp_ns + 1, json.dumps(entry))
    return frames
