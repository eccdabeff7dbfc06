"""The Franka Panda's kinematic chain from its URDF, evaluated in numpy.

The default URDF is ``franka_panda/panda.urdf`` from ``pybullet_data`` (pybullet is a
dependency anyway; it is only read as a file here, never imported as a simulator); any URDF
with the same joint names (``panda_joint1`` … ``panda_joint8``, ``panda_hand_joint``) can be
given instead. Forward kinematics is vectorised over joint samples, because trajectories and
recorded /tf need hundreds of poses at a time.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from scrapcut_cli.errors import MotionError
from scrapcut_cli.geometry import make_transform

FloatArray = NDArray[np.float64]

ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
LINK_NAMES = tuple(f"panda_link{i}" for i in range(9))  # link0 (base) ... link8 (flange)
#: Franka's "ready" pose: elbow up, hand pointing down.
Q_READY = (0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4)


def default_urdf_path() -> Path:
    """``franka_panda/panda.urdf`` inside the installed ``pybullet_data`` package."""
    import pybullet_data

    return Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"


def _origin(element: ET.Element | None) -> FloatArray:
    if element is None:
        return np.eye(4)
    xyz = [float(v) for v in element.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in element.get("rpy", "0 0 0").split()]
    # URDF rpy: fixed-axis roll, pitch, yaw = R_z(yaw) R_y(pitch) R_x(roll).
    return make_transform(Rotation.from_euler("xyz", rpy).as_matrix(), xyz)


class PandaKinematics:
    """Forward kinematics of the Panda arm from its URDF, vectorised over joint samples.

    Attributes
    ----------
    origins : (8, 4, 4) float64
        Joint origins (parent link → joint frame at q = 0) of joint1 … joint7 and the fixed
        joint8 (link7 → link8, the flange).
    lower, upper, velocity : (7,) float64
        The URDF's joint limits (rad, rad/s).
    T_link8_hand : (4, 4) float64
        Flange → hand (the fixed ``panda_hand_joint``).
    urdf : Path
        The file read.
    """

    def __init__(self, urdf: str | Path | None = None) -> None:
        self.urdf = Path(urdf) if urdf is not None else default_urdf_path()
        try:
            root = ET.parse(str(self.urdf)).getroot()
        except (OSError, ET.ParseError) as exc:
            raise MotionError(f"cannot read URDF {self.urdf}: {exc}") from None
        joints = {j.get("name"): j for j in root.findall("joint")}
        origins, lower, upper, velocity = [], [], [], []
        for name in (*ARM_JOINTS, "panda_joint8"):
            joint = joints.get(name)
            if joint is None:
                raise MotionError(f"{self.urdf.name} has no joint {name}")
            origins.append(_origin(joint.find("origin")))
            if name in ARM_JOINTS:
                axis = joint.find("axis")
                if axis is None or [float(v) for v in axis.get("xyz", "").split()] != [0, 0, 1]:
                    raise MotionError(f"{self.urdf.name} joint {name} does not turn about z")
                limit = joint.find("limit")
                if limit is None:
                    raise MotionError(f"{self.urdf.name} joint {name} has no <limit>")
                lower.append(float(limit.get("lower", "0")))
                upper.append(float(limit.get("upper", "0")))
                velocity.append(float(limit.get("velocity", "1")))
        hand = joints.get("panda_hand_joint")
        if hand is None:
            raise MotionError(f"{self.urdf.name} has no panda_hand_joint")
        self.origins = np.stack(origins)  # (8, 4, 4): joint1..7 and the fixed joint8
        self.lower = np.array(lower)
        self.upper = np.array(upper)
        self.velocity = np.array(velocity)
        self.T_link8_hand = _origin(hand.find("origin"))

    def chain(self, q: ArrayLike) -> FloatArray:
        """T_parent_child (S, 8, 4, 4) for link0->link1 ... link7->link8 at joint samples (S, 7)."""
        qs = np.atleast_2d(np.asarray(q, dtype=np.float64))
        n = len(qs)
        c, s = np.cos(qs), np.sin(qs)
        rz = np.zeros((n, 7, 4, 4))
        rz[:, :, 0, 0] = c
        rz[:, :, 0, 1] = -s
        rz[:, :, 1, 0] = s
        rz[:, :, 1, 1] = c
        rz[:, :, 2, 2] = 1.0
        rz[:, :, 3, 3] = 1.0
        out = np.empty((n, 8, 4, 4))
        out[:, :7] = self.origins[None, :7] @ rz
        out[:, 7] = self.origins[7]
        return out

    def flange(self, q: ArrayLike) -> FloatArray:
        """T_base_link8 (S, 4, 4) at joint samples (S, 7) (or (4, 4) for one (7,) sample)."""
        chain = self.chain(q)
        T = chain[:, 0]
        for k in range(1, 8):
            T = T @ chain[:, k]
        return T if np.asarray(q).ndim > 1 else T[0]

    def link_frames(self, q: ArrayLike) -> FloatArray:
        """T_base_link (S, 9, 4, 4) of panda_link0 … panda_link8 at joint samples (S, 7).

        The z axis of link k (1–7) is joint k's axis: the URDF joints turn about their own z.
        """
        chain = self.chain(q)
        out = np.empty((len(chain), 9, 4, 4))
        out[:, 0] = np.eye(4)
        for k in range(8):
            out[:, k + 1] = out[:, k] @ chain[:, k]
        return out

    def tool_jacobian(
        self, q: ArrayLike, T_flange_tool: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Tool poses T_base_tool (S, 4, 4) and geometric Jacobians (S, 6, 7) at (S, 7) joints.

        Rows 0–2 map joint rates to the tool origin's linear velocity, rows 3–5 to the angular
        velocity, both in the base frame: column k is (z_k × (p − o_k), z_k) for joint axis
        z_k through o_k (the analytic Jacobian of a revolute chain).
        """
        frames = self.link_frames(q)
        T = frames[:, 8] @ np.asarray(T_flange_tool, dtype=np.float64)
        z = frames[:, 1:8, :3, 2]  # (S, 7, 3)
        o = frames[:, 1:8, :3, 3]
        p = T[:, None, :3, 3]
        r = p - o
        J = np.empty((len(frames), 6, 7))
        # z × r written out: np.cross costs more than the whole chain for a handful of rows.
        J[:, 0] = z[..., 1] * r[..., 2] - z[..., 2] * r[..., 1]
        J[:, 1] = z[..., 2] * r[..., 0] - z[..., 0] * r[..., 2]
        J[:, 2] = z[..., 0] * r[..., 1] - z[..., 1] * r[..., 0]
        J[:, 3:] = np.swapaxes(z, 1, 2)
        return T, J

    def within_limits(self, q: ArrayLike, margin: float = 0.0) -> bool:
        qq = np.asarray(q, dtype=np.float64)
        return bool(np.all(qq >= self.lower + margin) and np.all(qq <= self.upper - margin))
