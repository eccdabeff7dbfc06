"""What ``scrapcut trajectory`` does, as one function: path file (+ recording) → trajectory.

:func:`trajectory_from_files` reads the path file, finds the recording it was fitted from
(``--recording``, else the path's ``source.path`` when that file exists, relative to the path
file when it is relative), builds the observed surface from the recording's depth images
(:func:`observed_surface`: every valid depth pixel on a grid, back-projected with the frame's
pose, thinned to a voxel grid — what the camera saw, the piece and whatever stands around it;
not any simulator truth), and plans the trajectory (:func:`~.plan.plan_trajectory`). It
returns a :class:`TrajectoryResult` that knows how to become a trajectory file. Nothing here
prints.

The robot's base is the URDF's ``panda_link0``. A path in another frame is moved into it
with the recording's TF when the recording has ``panda_link0``; otherwise the path's frame
(the recording's TF root) is taken as the robot's base, and the summary says so.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.config import MotionConfig, ScrapcutConfig
from scrapcut_cli.errors import MotionError
from scrapcut_cli.geometry import (
    matrix_to_quat_xyzw,
    quat_xyzw_to_matrix,
    rotate_vectors,
    transform_points,
)
from scrapcut_cli.motion.limits import panda_limits
from scrapcut_cli.motion.observed import ObservedScene, observe
from scrapcut_cli.motion.panda import PandaKinematics
from scrapcut_cli.motion.plan import Trajectory, plan_trajectory
from scrapcut_cli.motion.tool import TorchMount, default_mount, parse_tool_offset
from scrapcut_cli.motion.trajfile import trajectory_to_dict
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.toolpath.path import CuttingPath

FloatArray = NDArray[np.float64]

#: The URDF's base link: the frame joint trajectories are planned in.
ROBOT_BASE = "panda_link0"


@dataclass(frozen=True, eq=False)
class TrajectoryResult:
    """A planned trajectory with what it was made from (see :func:`trajectory_from_files`)."""

    trajectory: Trajectory
    path: CuttingPath
    source: dict[str, Any]
    config: MotionConfig
    urdf: str
    kin: PandaKinematics
    timings_s: dict[str, float] = field(default_factory=dict)

    def to_dict(self, *, created: str | None = None) -> dict[str, Any]:
        """The ``scrapcut.trajectory/v1`` dictionary."""
        return trajectory_to_dict(
            self.trajectory,
            source=self.source,
            limits=panda_limits(self.kin.lower, self.kin.upper),
            config=dataclasses.asdict(self.config),
            urdf=self.urdf,
            created=created,
        )


def plan_for_scene(
    path: CuttingPath,
    *,
    frame_id: str,
    scene: ObservedScene,
    config: ScrapcutConfig,
    path_config: dict[str, Any] | None = None,
) -> Trajectory:
    """Plan ``path`` against an observed scene already built (``reproduce`` builds one per
    scan for both methods): the torch body is ``path_config``'s (default ``config``'s)."""
    settings = path_config if path_config is not None else config.to_dict()
    return plan_trajectory(
        path,
        base_frame=frame_id,
        surface_base=scene.surface,
        unseen_base=scene.unseen if config.motion.avoid_unseen else None,
        mount=resolve_mount(config.motion, settings),
        config=config.motion,
        kin=PandaKinematics(config.motion.urdf),
        collision_min_points=config.toolpath.collision_min_points,
    )


def execution_figures(traj: Trajectory) -> dict[str, Any]:
    """The report columns of what the Panda can execute (``reproduce``'s rows)."""
    s = traj.summary
    return {
        "panda_executable": s["executable_share"],
        "panda_setpoints": s["setpoints"],
        "panda_tilted": s["tilted"],
        "panda_unreachable": s["unreachable"],
        "panda_in_collision": s["in_collision"],
        "panda_cuts": s["cut_segments"],
        "panda_limits_ok": s["limits_ok"],
    }


def resolve_mount(config: MotionConfig, path_config: dict[str, Any]) -> TorchMount:
    """The torch mount of ``config.tool_offset`` (or the default), with the torch body of the
    path's toolpath configuration (so the trajectory checks the torch the path was made for)."""
    mount = default_mount() if config.tool_offset is None else parse_tool_offset(config.tool_offset)
    tp = path_config.get("toolpath") if isinstance(path_config, dict) else None
    defaults = ScrapcutConfig().toolpath
    length = defaults.torch_length_m
    radius = defaults.torch_radius_m
    if isinstance(tp, dict):
        length = float(tp.get("torch_length_m", length))
        radius = float(tp.get("torch_radius_m", radius))
    return mount.with_body(length, radius)


def trajectory_from_files(
    path_file: str | Path,
    *,
    recording: str | Path | None = None,
    config: ScrapcutConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> TrajectoryResult:
    """Plan the joint trajectory of a path file (see the module docstring).

    ``recording`` None: the path's source recording if it exists, else no observed surface
    (the floor only; the summary's ``observed_surface`` says ``none``). ``config.motion``
    holds the trajectory parameters, ``config.recording`` / ``config.perception`` how the
    recording is read.
    """
    from scrapcut_cli.recording.reader import open_recording, sha256_first_mib
    from scrapcut_cli.toolpath.pathfile import read_path_file

    cfg = config or ScrapcutConfig()
    t0 = time.perf_counter()
    path_file = Path(path_file)
    _, path, meta = read_path_file(path_file)
    frame_id = str(meta["frame_id"])
    # The robot and the torch first: a bad URDF or mount fails before the recording is read.
    kin = PandaKinematics(cfg.motion.urdf)
    mount = resolve_mount(cfg.motion, meta.get("config", {}))
    rec_path, rec_how = _find_recording(path_file, meta, recording)

    surface: FloatArray | None = None
    unseen: FloatArray | None = None
    T_base_path = np.eye(4)
    base_note = "path frame is the URDF base"
    source: dict[str, Any] = {
        "path_file": str(path_file),
        "path_sha256_first_mib": sha256_first_mib(path_file),
        "path_frame": frame_id,
    }
    if rec_path is not None:
        with open_recording(rec_path, cfg.recording) as rec:
            base = rec.base_frame
            if base != frame_id:
                raise MotionError(
                    f"the path is in frame {frame_id!r} but the recording's base frame is "
                    f"{base!r}; give the recording the path was fitted from (or --base-frame)"
                )
            total = rec.plan().usable if progress is not None else 0

            def frames() -> Iterable[Frame]:
                for k, frame in enumerate(rec.frames(), start=1):
                    if progress is not None:
                        progress(k, total)
                    yield frame

            scene = observe(
                frames(),
                surface_voxel_m=cfg.motion.collision_voxel_m,
                free_voxel_m=cfg.motion.unseen_voxel_m,
                perception=cfg.perception,
                floor_z_m=cfg.motion.floor_z_m,
            )
            surface = scene.surface
            unseen = scene.unseen if cfg.motion.avoid_unseen else None
            if frame_id != ROBOT_BASE and rec.tf.has_frame(ROBOT_BASE):
                T_base_path = rec.tf.lookup_one(ROBOT_BASE, frame_id, rec.start_ns)
                base_note = f"path frame moved into {ROBOT_BASE} with the recording's TF"
        source.update(
            {"recording": str(rec_path), "recording_sha256_first_mib": sha256_first_mib(rec_path)}
        )
    if frame_id != ROBOT_BASE and base_note.startswith("path frame is"):
        base_note = f"{frame_id!r} taken as the robot base ({ROBOT_BASE} not in any TF)"
    t_read = time.perf_counter()

    if not np.allclose(T_base_path, np.eye(4)):
        path = _moved(path, T_base_path)
        if surface is not None:
            surface = transform_points(T_base_path, surface)
        if unseen is not None:
            unseen = transform_points(T_base_path, unseen)
    tp = meta.get("config", {}).get("toolpath", {}) if isinstance(meta.get("config"), dict) else {}
    min_points = int(tp.get("collision_min_points", 3)) if isinstance(tp, dict) else 3
    traj = plan_trajectory(
        path,
        base_frame=ROBOT_BASE if base_note.startswith("path frame moved") else frame_id,
        surface_base=surface,
        mount=mount,
        config=cfg.motion,
        kin=kin,
        collision_min_points=min_points,
        unseen_base=unseen,
    )
    traj.summary["observed_surface"] = rec_how if surface is not None else "none"
    traj.summary["robot_base"] = base_note
    t_plan = time.perf_counter()
    return TrajectoryResult(
        trajectory=traj,
        path=path,
        source=source,
        config=cfg.motion,
        urdf=str(kin.urdf),
        kin=kin,
        timings_s={
            "read": t_read - t0,
            "plan": t_plan - t_read,
            "total": t_plan - t0,
        },
    )


def _find_recording(
    path_file: Path, meta: dict[str, Any], given: str | Path | None
) -> tuple[Path | None, str]:
    if given is not None:
        rec = Path(given)
        if not rec.exists():
            raise MotionError(f"recording not found: {rec}")
        return rec, "recording depth (--recording)"
    src = meta.get("source", {})
    name = src.get("path") if isinstance(src, dict) else None
    if isinstance(name, str) and name:
        candidate = Path(name)
        for rec in (candidate, path_file.parent / candidate):
            if rec.exists():
                return rec, "recording depth (the path's source)"
    return None, "none"


def _moved(path: CuttingPath, T: FloatArray) -> CuttingPath:
    """The path's set-points expressed in another frame (T_new_old)."""
    R = quat_xyzw_to_matrix(path.orientations_xyzw)
    return dataclasses.replace(
        path,
        positions=transform_points(T, path.positions),
        orientations_xyzw=matrix_to_quat_xyzw(T[:3, :3] @ R),
        normals=rotate_vectors(T, path.normals),
        surface_points=transform_points(T, path.surface_points),
    )
