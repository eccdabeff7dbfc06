"""The torch on the flange: ``T_flange_tool`` (flange ``panda_link8`` → torch tip) and its body.

Default mount (:data:`DEFAULT_TOOL_OFFSET_M`): a straight machine gas torch held coaxially on
the flange, its nozzle tip 250 mm out along the flange's z axis, the tool frame parallel to
the flange's. A 250 mm reach is the body of a typical straight machine torch (about 150 mm
from the toolpath's collision model, ``toolpath.torch_length_m``) plus a holder; the tool z
axis points out of the nozzle, along the jet, as the path file's torch orientations do (their
z axis points into the surface). A round torch makes the rotation about that axis free.

Give your own mount with ``--tool-offset``: ``x,y,z[,roll,pitch,yaw]`` in millimetres and
degrees (URDF convention: fixed-axis roll about x, then pitch about y, then yaw about z), or a
YAML/JSON file holding ``translation_m`` [x, y, z] and ``rotation_xyzw`` [x, y, z, w] — at the
top level or under a ``T_flange_tool`` key, so a ``TRAJ.json`` can be reused.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from scrapcut_cli.errors import MotionError
from scrapcut_cli.geometry import make_transform, matrix_to_quat_xyzw, quat_xyzw_to_matrix

FloatArray = NDArray[np.float64]

#: Tip of the default torch along the flange z axis, metres.
DEFAULT_TOOL_OFFSET_M = (0.0, 0.0, 0.25)
#: Radius of the torch holder between the flange and the torch body, metres.
HOLDER_RADIUS_M = 0.025


@dataclass(frozen=True, eq=False)
class TorchMount:
    """The torch's pose on the flange and the size of its body (for collisions).

    Attributes
    ----------
    T_flange_tool : (4, 4) float64
        Flange (``panda_link8``) → torch tip; the tool z axis runs along the jet.
    body_length_m, body_radius_m : float
        The torch body checked against the observed surface: a cylinder from the tip back
        along −z (the toolpath's ``torch_length_m``, ``torch_radius_m``). Behind it the holder
        (radius :data:`HOLDER_RADIUS_M`) runs on to the flange.
    source : str
        "default", "option" or the file it was read from.
    """

    T_flange_tool: FloatArray
    body_length_m: float = 0.15
    body_radius_m: float = 0.012
    source: str = "default"

    def to_dict(self) -> dict[str, Any]:
        """``{"translation_m": [3], "rotation_xyzw": [4]}`` (TRAJ.json ``T_flange_tool``)."""
        return {
            "translation_m": [float(v) for v in self.T_flange_tool[:3, 3]],
            "rotation_xyzw": [float(v) for v in matrix_to_quat_xyzw(self.T_flange_tool[:3, :3])],
        }

    def with_body(self, length_m: float, radius_m: float) -> TorchMount:
        """The same mount with another torch body size."""
        return TorchMount(self.T_flange_tool, float(length_m), float(radius_m), self.source)


def default_mount() -> TorchMount:
    """The documented default: a straight torch, tip 250 mm out along the flange z axis."""
    return TorchMount(make_transform(np.eye(3), DEFAULT_TOOL_OFFSET_M))


def parse_tool_offset(text: str) -> TorchMount:
    """A mount from ``x,y,z[,roll,pitch,yaw]`` (mm, degrees) or a YAML/JSON file name."""
    text = text.strip()
    parts = [p.strip() for p in text.split(",")]
    if len(parts) in (3, 6):
        try:
            values = [float(p) for p in parts]
        except ValueError:
            values = []
        if values:
            if not all(math.isfinite(v) for v in values):
                raise MotionError(f"--tool-offset {text!r}: values must be finite")
            rpy = np.radians(values[3:]) if len(values) == 6 else np.zeros(3)
            T = make_transform(
                Rotation.from_euler("xyz", rpy).as_matrix(), np.array(values[:3]) / 1000.0
            )
            return _checked(TorchMount(T, source="option"), text)
    path = Path(text)
    if path.suffix.lower() in (".yaml", ".yml", ".json") or path.exists():
        return read_mount_file(path)
    raise MotionError(
        f"--tool-offset {text!r}: expected x,y,z[,roll,pitch,yaw] in mm/deg or a YAML/JSON file"
    )


def read_mount_file(path: str | Path) -> TorchMount:
    """Read ``translation_m`` and ``rotation_xyzw`` (optionally under ``T_flange_tool``)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MotionError(f"tool mount file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MotionError(f"cannot read tool mount file {path}: {exc}") from None
    data: Any
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            from ruamel.yaml import YAML, YAMLError

            try:
                data = YAML(typ="safe", pure=True).load(text)
            except YAMLError as exc:
                raise ValueError(str(exc).splitlines()[0]) from None
    except ValueError as exc:
        raise MotionError(f"tool mount file {path}: not valid {path.suffix[1:]}: {exc}") from None
    if isinstance(data, dict) and isinstance(data.get("T_flange_tool"), dict):
        data = data["T_flange_tool"]
    if not isinstance(data, dict):
        raise MotionError(f"tool mount file {path}: expected translation_m and rotation_xyzw")
    translation = _vector(data.get("translation_m"), 3, "translation_m", path)
    quat = _vector(data.get("rotation_xyzw", [0.0, 0.0, 0.0, 1.0]), 4, "rotation_xyzw", path)
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > 1e-3:
        raise MotionError(f"tool mount file {path}: rotation_xyzw is not a unit quaternion")
    T = make_transform(quat_xyzw_to_matrix(quat / norm), translation)
    return _checked(TorchMount(T, source=str(path)), str(path))


def _vector(value: Any, n: int, name: str, path: Path) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise MotionError(f"tool mount file {path}: {name} must be {n} finite numbers")
    return arr


def _checked(mount: TorchMount, what: str) -> TorchMount:
    reach = float(np.linalg.norm(mount.T_flange_tool[:3, 3]))
    if reach > 1.0:
        raise MotionError(f"tool mount {what}: the tip is {reach:.2f} m from the flange (> 1 m)")
    return mount
