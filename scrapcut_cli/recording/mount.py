"""How the camera hangs on the robot and keeps time: the mount a reader poses frames with.

A frame's pose is ``T_base_cam = T_base_moving(stamp + time_offset_s) @ T_moving_camera``:
``moving_frame`` is the last frame of the TF chain that /tf moves (the child of the last dynamic
transform between the base and the image's frame, e.g. ``panda_link8``), ``T_moving_camera``
composes the static transforms below it down to the image's optical frame (the hand-eye
calibration and the camera driver's own links), and ``time_offset_s`` is added to an image's
header stamp to get its capture time on the TF clock.

A recording publishes one mount (its /tf_static, offset 0); ``scrapcut calibrate`` estimates a
corrected one, and a reader given a mount poses every frame with it. numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, eq=False)
class CameraMount:
    """The camera mount and clock offset a reader poses frames with.

    Attributes
    ----------
    moving_frame : str
        TF frame the camera is rigidly attached to (the last one /tf moves).
    camera_frame : str
        The images' optical frame.
    T_moving_camera : (4, 4) float64
        Maps points in the optical frame into ``moving_frame``, metres.
    time_offset_s : float
        Seconds added to each image header stamp to get its capture time on the TF clock.
    """

    moving_frame: str
    camera_frame: str
    T_moving_camera: NDArray[np.float64]
    time_offset_s: float = 0.0

    def __post_init__(self) -> None:
        T = np.asarray(self.T_moving_camera, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError("T_moving_camera must be a finite (4, 4) matrix")
        R = T[:3, :3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("T_moving_camera's rotation is not a rotation matrix")
        if not math.isfinite(self.time_offset_s):
            raise ValueError(f"time offset must be finite, got {self.time_offset_s}")
        object.__setattr__(self, "T_moving_camera", T.copy())

    @property
    def time_offset_ns(self) -> int:
        """``time_offset_s`` in whole nanoseconds."""
        return round(self.time_offset_s * 1e9)
