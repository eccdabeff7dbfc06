"""``simulate-cut`` as one function: trajectory file + recording → the simulated cut's report."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from scrapcut_cli.config import ScrapcutConfig, SimConfig, update_dataclass
from scrapcut_cli.errors import ScrapcutError, SimError
from scrapcut_cli.motion.panda import ARM_JOINTS
from scrapcut_cli.motion.trajfile import read_trajectory_file
from scrapcut_cli.sim.cut import CutSimSettings, simulate_cut
from scrapcut_cli.sim.objects import ScrapObject


def piece_from_metadata(metadata: dict[str, dict[str, str]]) -> ScrapObject | None:
    """The simulated piece of a recording, rebuilt from its ``scrapcut`` metadata (object,
    seed, placement), or None for a recording that did not come from the simulator."""
    from scrapcut_cli.sim.recorder import place_object

    meta = metadata.get("scrapcut", {})
    if "object" not in meta or "params" not in meta:
        return None
    try:
        params = json.loads(meta["params"])
        sim = params["sim"]
        known = {f.name for f in dataclasses.fields(SimConfig)}
        config = update_dataclass(SimConfig(), {k: v for k, v in sim.items() if k in known}, "sim")
        return place_object(config)
    except (ValueError, KeyError, TypeError, ScrapcutError) as exc:
        raise SimError(f"the recording's simulator metadata is unreadable: {exc}") from None


def simulate_cut_files(
    traj_file: str | Path,
    recording: str | Path,
    *,
    config: ScrapcutConfig | None = None,
    settings: CutSimSettings | None = None,
    floor_z_m: float = 0.0,
) -> dict[str, Any]:
    """Read the trajectory and the recording, simulate the cut, return the JSON-ready report."""
    from scrapcut_cli.recording.reader import open_recording

    cfg = config or ScrapcutConfig()
    traj = read_trajectory_file(traj_file)
    if traj.joint_names != ARM_JOINTS:
        raise SimError(f"{traj_file}: joint_names are not the Panda's {', '.join(ARM_JOINTS)}")
    if len(traj.setpoint_tips) == 0:
        raise SimError(f"{traj_file}: no set-points listed")
    with open_recording(recording, cfg.recording) as rec:
        base = rec.base_frame
        metadata = rec.metadata
    if base != traj.base_frame:
        raise SimError(
            f"the trajectory is in frame {traj.base_frame!r} but the recording's base frame is "
            f"{base!r}"
        )
    piece = piece_from_metadata(metadata)
    points = traj.data["points"]

    def column(key: str) -> np.ndarray | None:
        if not all(key in p for p in points):
            return None
        try:
            arr = np.asarray([p[key] for p in points], dtype=np.float64)
        except (TypeError, ValueError):
            return None
        return arr if arr.shape == traj.positions.shape and np.all(np.isfinite(arr)) else None

    raw_tool = traj.data.get("tool")
    tool: dict[str, Any] = raw_tool if isinstance(raw_tool, dict) else {}
    radius = float(tool.get("body_radius_m", 0.012))
    length = float(tool.get("body_length_m", 0.15))
    result = simulate_cut(
        traj.t,
        traj.positions,
        column("velocities"),
        column("accelerations"),
        setpoint=traj.setpoint,
        setpoint_tips=traj.setpoint_tips,
        setpoint_axes=traj.setpoint_axes,
        T_flange_tool=traj.T_flange_tool,
        torch_radius_m=radius,
        torch_length_m=length,
        piece=None if piece is None else piece.mesh,
        piece_name=None if piece is None else piece.name,
        floor_z_m=floor_z_m,
        settings=settings,
    )
    report = result.summary()
    report["joint_margin_joint"] = ARM_JOINTS[int(np.argmin(result.joint_margin_rad))]
    report["trajectory"] = str(traj_file)
    report["recording"] = str(recording)
    return report
