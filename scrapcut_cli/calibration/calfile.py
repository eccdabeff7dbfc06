"""CAL.yaml: a calibration as a user pastes it, and as ``--calibration`` reads it back.

The file holds the corrected mount as YAML (``T_moving_camera``: translation in metres and a
quaternion x, y, z, w, mapping camera-frame points into the moving frame; ``time_offset_s``,
added to image header stamps), the figures behind it, and ``static_transform_publisher``
command lines:

- ROS 1 (tf2_ros): ``rosrun tf2_ros static_transform_publisher x y z qx qy qz qw frame child``;
- ROS 2 Humble and later: ``ros2 run tf2_ros static_transform_publisher --x X --y Y --z Z
  --qx QX --qy QY --qz QZ --qw QW --frame-id FRAME --child-frame-id CHILD``;
- ROS 2 Foxy / Galactic: the positional form of ROS 1 (deprecated in Humble).

A TF frame has one parent: publish the whole mount (moving frame -> camera frame) only in place
of the links it replaces, or the one corrected link (``links``) your hand-eye calibration
publishes. The clock offset has no TF equivalent; scrapcut applies it with ``--calibration``.
Written with JSON values (valid YAML), read with ruamel.yaml's safe loader.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from scrapcut_cli._io import write_text_atomic
from scrapcut_cli.calibration.result import SCHEMA, Calibration, transform_dict
from scrapcut_cli.errors import CalibrationError
from scrapcut_cli.geometry import transform_from_pose
from scrapcut_cli.recording.mount import CameraMount


def publisher_commands(parent: str, child: str, T: np.ndarray) -> dict[str, str]:
    """``static_transform_publisher`` lines (ros1, ros2, ros2_positional) for T_parent_child."""
    d = transform_dict(T)
    x, y, z = (_num(v) for v in d["translation_m"])
    qx, qy, qz, qw = (_num(v) for v in d["rotation_xyzw"])
    positional = f"{x} {y} {z} {qx} {qy} {qz} {qw} {parent} {child}"
    return {
        "ros1": f"rosrun tf2_ros static_transform_publisher {positional}",
        "ros2": (
            f"ros2 run tf2_ros static_transform_publisher --x {x} --y {y} --z {z} "
            f"--qx {qx} --qy {qy} --qz {qz} --qw {qw} --frame-id {parent} --child-frame-id {child}"
        ),
        "ros2_positional": f"ros2 run tf2_ros static_transform_publisher {positional}",
    }


def _num(value: float) -> str:
    """Enough digits for 1 µm / 1e-9 of a quaternion, no exponent."""
    text = f"{value:.9f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def calibration_yaml(calibration: Calibration) -> str:
    """The text of CAL.yaml (see the module docstring)."""
    data = calibration.to_dict()
    mount = calibration.mount
    lines = [
        f"# scrapcut calibration ({SCHEMA}): camera mount and clock offset estimated from",
        f"# the scan {data['source'].get('path', '')}.",
        "# Apply it: scrapcut fit|stitch|filter|explore REC --calibration THIS.yaml",
        f"# Verdict: {data['verdict']}",
        f"schema: {SCHEMA}",
        f"verdict: {json.dumps(data['verdict'])}",
        f"consistent: {json.dumps(data['consistent'])}",
        f"moving_frame: {json.dumps(mount.moving_frame)}",
        f"camera_frame: {json.dumps(mount.camera_frame)}",
        "# maps points in camera_frame into moving_frame (metres; quaternion x, y, z, w)",
        f"T_moving_camera: {json.dumps(data['T_moving_camera'])}",
        f"published_T_moving_camera: {json.dumps(data['published_T_moving_camera'])}",
        "# seconds to add to each image header stamp to get its capture time on the /tf clock",
        f"time_offset_s: {json.dumps(data['time_offset_s'])}",
        "# the estimate relative to the published mount, in the camera's optical frame",
        f"correction: {json.dumps(data['correction'])}",
        f"sigma: {json.dumps(data['sigma'])}",
        f"observable: {json.dumps(data['observable'])}",
        f"unobservable: {json.dumps(_reasons(data['unobservable']))}",
        f"residual_before_mm: {json.dumps(data['residual_before_mm'])}",
        f"residual_after_mm: {json.dumps(data['residual_after_mm'])}",
        f"source: {json.dumps(data['source'])}",
        "# One TF frame has one parent: publish the whole mount only instead of the links it",
        "# replaces, or publish the one corrected link (under links) your hand-eye calibration",
        "# publishes. ros2: Humble and later; ros2_positional: Foxy and Galactic.",
        "static_transform_publisher:",
    ]
    commands = publisher_commands(mount.moving_frame, mount.camera_frame, mount.T_moving_camera)
    lines += [f"  {k}: {json.dumps(v)}" for k, v in commands.items()]
    lines.append("links:")
    if not calibration.links:
        lines[-1] += " []"
    for link, corrected in calibration.link_corrections():
        lines += [
            f"  - parent: {json.dumps(link.parent)}",
            f"    child: {json.dumps(link.child)}",
            f"    published: {json.dumps(transform_dict(link.T))}",
            f"    corrected: {json.dumps(transform_dict(corrected))}",
        ]
        for k, v in publisher_commands(link.parent, link.child, corrected).items():
            lines.append(f"    {k}: {json.dumps(v)}")
    return "\n".join(lines) + "\n"


def _reasons(unobservable: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{"what": u["what"], "why": u["why"]} for u in unobservable]


def write_calibration_file(path: str | os.PathLike[str], calibration: Calibration) -> None:
    """Write CAL.yaml atomically."""
    write_text_atomic(path, calibration_yaml(calibration))


def read_calibration_file(path: str | os.PathLike[str]) -> CameraMount:
    """The mount and clock offset of a CAL.yaml (``scrapcut calibrate -o``).

    Raises CalibrationError with one line naming the problem.
    """
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CalibrationError(f"calibration file not found: {p}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"cannot read calibration {p}: {exc}") from None
    try:
        data = YAML(typ="safe", pure=True).load(text)
    except YAMLError as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CalibrationError(f"{p} is not valid YAML: {reason}") from None
    return mount_from_dict(data, where=str(p))


def mount_from_dict(data: Any, *, where: str) -> CameraMount:
    """A CameraMount from CAL.yaml's (or a path file's ``calibration``) keys."""
    if not isinstance(data, dict):
        raise CalibrationError(f"{where} is not a scrapcut calibration (expected a mapping)")
    if data.get("schema") != SCHEMA:
        raise CalibrationError(
            f"{where} is not a scrapcut calibration (schema {data.get('schema')!r}, "
            f"expected {SCHEMA}); make one with `scrapcut calibrate REC -o CAL.yaml`"
        )
    try:
        moving = str(data["moving_frame"])
        camera = str(data["camera_frame"])
        T = data["T_moving_camera"]
        t = np.asarray(T["translation_m"], dtype=np.float64).reshape(3)
        q = np.asarray(T["rotation_xyzw"], dtype=np.float64).reshape(4)
        offset = float(data["time_offset_s"])
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(
            f"{where}: missing or malformed {exc.args[0] if exc.args else 'value'} "
            "(needs moving_frame, camera_frame, T_moving_camera {translation_m, rotation_xyzw}, "
            "time_offset_s)"
        ) from None
    norm = float(np.linalg.norm(q))
    if not (np.all(np.isfinite(t)) and np.isfinite(norm) and abs(norm - 1.0) < 1e-3):
        raise CalibrationError(
            f"{where}: T_moving_camera must be a finite translation and a unit quaternion, got "
            f"{t.tolist()} and {q.tolist()}"
        )
    if not np.isfinite(offset) or abs(offset) > 1.0:
        raise CalibrationError(f"{where}: time_offset_s must be within ±1 s, got {offset}")
    return CameraMount(moving, camera, transform_from_pose(t, q / norm), offset)


def mount_record(mount: CameraMount, *, origin: str, **extra: Any) -> dict[str, Any]:
    """What a path file records of the mount its frames were posed with (``calibration``)."""
    return {
        "schema": SCHEMA,
        "origin": origin,
        "moving_frame": mount.moving_frame,
        "camera_frame": mount.camera_frame,
        "T_moving_camera": transform_dict(mount.T_moving_camera),
        "time_offset_s": mount.time_offset_s,
        **extra,
    }
