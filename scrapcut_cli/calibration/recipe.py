"""What ``scrapcut calibrate`` does, as one function: recording → frames → observations → solve.

:func:`calibrate_recording` plans the recording's frames from headers and /tf, picks up to
``max_frames`` with diverse poses and speeds (:func:`choose_frames`), reads only those, turns
each into camera-frame observations (:mod:`~scrapcut_cli.calibration.observations`) and solves
for the mount and clock offset (:mod:`~scrapcut_cli.calibration.solver`) against the
recording's own /tf. It returns a :class:`~scrapcut_cli.calibration.result.Calibration`;
nothing here prints.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.calibration.observations import FrameObservation, observe_frame
from scrapcut_cli.calibration.residuals import TYPICAL_ERROR, VELOCITY_STEP_NS
from scrapcut_cli.calibration.result import Calibration, Link
from scrapcut_cli.calibration.solver import solve
from scrapcut_cli.config import CalibrationConfig, ScrapcutConfig
from scrapcut_cli.errors import CalibrationError
from scrapcut_cli.exploration.calibration_views import CALIBRATION_REASON

if TYPE_CHECKING:
    from scrapcut_cli.recording.mount import CameraMount
    from scrapcut_cli.recording.reader import Recording

FloatArray = NDArray[np.float64]


def choose_frames(T_base_cam: FloatArray, velocities: FloatArray, count: int) -> NDArray[np.int64]:
    """Indices (ascending) of up to ``count`` frames with the most diverse poses and speeds.

    Farthest-point sampling from frame 0 in the distance of :func:`select_pairs`' score: how
    far a typical calibration error would throw two frames' points apart (orientation,
    position and velocity differences). Frames at the same pose count once.

    Parameters
    ----------
    T_base_cam : (N, 4, 4) float64
        Camera poses (published mount), base frame.
    velocities : (N, 3) float64
        The moving frame's velocity at each frame, m/s.
    count : int
    """
    n = len(T_base_cam)
    if n <= count:
        return np.arange(n, dtype=np.int64)
    t_err, r_err, dt_err = TYPICAL_ERROR
    R = T_base_cam[:, :3, :3]
    position = T_base_cam[:, :3, 3] * 1000.0
    chosen = [0]
    best = np.full(n, np.inf)
    for _ in range(count - 1):
        last = chosen[-1]
        cos = (np.einsum("ab,nab->n", R[last], R) - 1.0) / 2.0
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        shift = np.linalg.norm(position - position[last], axis=1)
        speed = np.linalg.norm(velocities - velocities[last], axis=1) * 1000.0
        best = np.minimum(best, t_err * angle + r_err * shift + dt_err * speed)
        pick = int(np.argmax(best))
        if best[pick] <= 0.0:
            break
        chosen.append(pick)
    return np.array(sorted(chosen), dtype=np.int64)


def calibrate_recording(
    recording: str | os.PathLike[str],
    *,
    config: ScrapcutConfig,
    progress: Callable[[int, int], None] | None = None,
) -> Calibration:
    """Estimate the camera mount and clock offset of a recording from its own frames.

    Parameters
    ----------
    recording : path
        An ``.mcap`` file, a ROS 1 ``.bag`` or a ROS 2 bag directory.
    config : ScrapcutConfig
        ``recording`` (topics), ``paint``, ``perception`` (depth gate, paint clean-up) and
        ``calibration`` are used.
    progress : callable, optional
        ``progress(frames_done, frames_total)`` while frames are read.

    Raises
    ------
    ScrapcutError
        RecordingError (unreadable, no TF chain), CalibrationError (too few overlapping frames).
    """
    from scrapcut_cli.pipeline.fit import paint_for_recording
    from scrapcut_cli.recording.reader import open_recording

    t0 = time.perf_counter()
    path = Path(recording)
    cal = config.calibration
    _check(cal)
    with open_recording(path, config.recording) as rec:
        plan = rec.plan()
        if plan.usable < 2:
            raise CalibrationError(
                f"{path} has {plan.usable} usable frame(s); the calibration compares frames "
                "with each other"
            )
        published = rec.published_mount()
        hsv, _ = paint_for_recording(rec, config)  # --paint auto: estimated from the images
        velocities = _velocities(rec.moving_poses, plan.stamps_ns)
        chosen = choose_frames(plan.T_base_cam, velocities, cal.max_frames)
        # An exploration with calibration views: also solve without them, to say what they gave.
        split = calibration_views_start(rec.exploration_log())
        before: NDArray[np.int64] | None = None
        if split is not None:
            early = np.flatnonzero(plan.stamps_ns <= split)
            before = early[choose_frames(plan.T_base_cam[early], velocities[early], cal.max_frames)]
        wanted = set(chosen.tolist()) | set(() if before is None else before.tolist())
        observed: dict[int, FrameObservation] = {}
        for frame in rec.frames():
            if frame.index not in wanted:
                continue
            observed[frame.index] = observe_frame(
                frame, hsv, config=cal, perception=config.perception
            )
            if progress is not None:
                progress(len(observed), len(wanted))
        solution = solve([observed[i] for i in chosen], rec.moving_poses, published, cal)
        without = None
        if before is not None:
            try:
                without = solve([observed[i] for i in before], rec.moving_poses, published, cal)
            except CalibrationError:
                without = None  # too little before the calibration views to compare
        links = _links(rec, published.moving_frame, published.camera_frame)
    source = {
        "path": str(path),
        "frames": int(plan.usable),
        "frames_read": len(observed),
    }
    if split is not None:
        source["calibration_view_frames"] = int(np.count_nonzero(plan.stamps_ns > split))
    return Calibration.decide(
        solution,
        published,
        cal,
        links=links,
        source=source,
        time_s=time.perf_counter() - t0,
        without_views=without,
    )


def calibration_views_start(log: list[dict[str, Any]]) -> int | None:
    """Header stamp (ns) of the frame after which an exploration went for calibration views:
    the frame of the first step that decided ``calibration``; None if none did."""
    for entry in log:
        if entry.get("reason") == CALIBRATION_REASON and "frame_stamp_ns" in entry:
            return int(entry["frame_stamp_ns"])
    return None


def _check(cal: CalibrationConfig) -> None:
    """CalibrationError naming the first parameter out of its range."""
    if cal.max_frames < 2:
        raise CalibrationError(f"calibration.max_frames must be at least 2, got {cal.max_frames}")
    if not 0.0 < cal.min_distance_m <= cal.max_distance_m:
        raise CalibrationError(
            "calibration gates must satisfy 0 < min_distance_m <= max_distance_m, got "
            f"{cal.min_distance_m} and {cal.max_distance_m}"
        )
    positive = {
        "surface_samples": cal.surface_samples,
        "edge_spacing_m": cal.edge_spacing_m,
        "partners": cal.partners,
        "observable_sigma_m": cal.observable_sigma_m,
        "observable_sigma_deg": cal.observable_sigma_deg,
        "observable_sigma_s": cal.observable_sigma_s,
        "prior_translation_m": cal.prior_translation_m,
        "prior_rotation_deg": cal.prior_rotation_deg,
        "prior_time_offset_s": cal.prior_time_offset_s,
    }
    for name, value in positive.items():
        if not value > 0:
            raise CalibrationError(f"calibration.{name} must be positive, got {value}")


def _velocities(
    moving_poses: Callable[[NDArray[np.int64]], tuple[FloatArray, NDArray[np.bool_]]],
    stamps_ns: NDArray[np.int64],
) -> FloatArray:
    """The moving frame's linear velocity (N, 3) m/s at each stamp (0 where /tf ends)."""
    h = VELOCITY_STEP_NS
    lo, ok_lo = moving_poses(stamps_ns - h)
    hi, ok_hi = moving_poses(stamps_ns + h)
    v = (hi[:, :3, 3] - lo[:, :3, 3]) / (2 * h * 1e-9)
    return np.where((ok_lo & ok_hi)[:, None], v, 0.0)


def _links(rec: Recording, moving: str, camera: str) -> tuple[Link, ...]:
    """The static links from ``moving`` down to ``camera``, as the recording publishes them."""
    frames = rec.tf.path_down(moving, camera)
    return tuple(
        Link(parent, child, rec.tf.lookup_one(parent, child, 0))
        for parent, child in itertools.pairwise(frames)
    )


def camera_mount_for(
    recording: str | os.PathLike[str],
    config: ScrapcutConfig,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[CameraMount | None, dict[str, Any] | None]:
    """The mount to pose ``recording``'s frames with, as ``config.calibration`` asks, and what
    a path file records of it (``calibration``); (None, None): the recording's own.

    ``file`` is read (a CAL.yaml); ``self_calibrate`` runs :func:`calibrate_recording` first.
    """
    from scrapcut_cli.calibration.calfile import mount_record, read_calibration_file
    from scrapcut_cli.calibration.result import calibration_record

    cal = config.calibration
    if cal.file is not None and cal.self_calibrate:
        raise CalibrationError(
            "a calibration file and self-calibration exclude each other: use one"
        )
    if cal.file is not None:
        mount = read_calibration_file(cal.file)
        return mount, mount_record(mount, origin=cal.file)
    if cal.self_calibrate:
        calibration = calibrate_recording(recording, config=config, progress=progress)
        return calibration.mount, calibration_record(calibration)
    return None, None
