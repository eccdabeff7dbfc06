"""CAL.yaml: values and static_transform_publisher lines a user pastes, read back by scrapcut."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import pytest
from ruamel.yaml import YAML
from scipy.spatial.transform import Rotation

from scrapcut_cli.calibration.calfile import (
    publisher_commands,
    read_calibration_file,
    write_calibration_file,
)
from scrapcut_cli.calibration.result import Calibration, Link
from scrapcut_cli.calibration.solver import Solution
from scrapcut_cli.config import CalibrationConfig
from scrapcut_cli.errors import CalibrationError
from scrapcut_cli.geometry import make_transform, transform_from_pose
from scrapcut_cli.recording.mount import CameraMount


def _link(rotvec: tuple[float, float, float], t: tuple[float, float, float]) -> np.ndarray:
    return make_transform(Rotation.from_rotvec(rotvec).as_matrix(), t)


LINKS = (
    Link("panda_link8", "panda_hand", _link((0.0, 0.0, -0.785), (0.0, 0.0, 0.107))),
    Link("panda_hand", "camera_link", _link((0.0, -1.571, 0.0), (0.065, 0.0, 0.04))),
    Link("camera_link", "camera_color_optical_frame", _link((-1.2, 1.2, -1.2), (0.0, 0.015, 0))),
)


def _calibration(correction: tuple[float, ...], observable: bool = True) -> Calibration:
    published_T = LINKS[0].T @ LINKS[1].T @ LINKS[2].T
    published = CameraMount("panda_link8", "camera_color_optical_frame", published_T)
    solution = Solution(
        correction=np.array(correction, dtype=np.float64),
        sigma=np.full(7, 0.01),
        observable=np.full(7, observable),
        unobservable=(),
        residual_before_mm={"surface": 2.0, "edge": 3.0, "all": 2.5},
        residual_after_mm={"surface": 0.6, "edge": 0.5, "all": 0.55},
        frames=40,
        pairs=120,
        residuals=50_000,
        iterations=12,
    )
    return Calibration.decide(
        solution, published, CalibrationConfig(), links=LINKS, source={"path": "scan.mcap"}
    )


def test_round_trip_gives_the_corrected_mount_and_offset(tmp_path: Path) -> None:
    calibration = _calibration((1.2, -0.8, 0.5, 0.2, -0.3, 0.1, -14.0))
    assert not calibration.consistent
    path = tmp_path / "cal.yaml"
    write_calibration_file(path, calibration)
    mount = read_calibration_file(path)
    np.testing.assert_allclose(mount.T_moving_camera, calibration.mount.T_moving_camera, atol=1e-12)
    assert mount.time_offset_s == pytest.approx(-0.014, abs=1e-12)
    assert (mount.moving_frame, mount.camera_frame) == ("panda_link8", "camera_color_optical_frame")
    data = YAML(typ="safe", pure=True).load(path.read_text())
    for key in ("T_moving_camera", "published_T_moving_camera", "sigma", "observable"):
        assert key in data
    assert data["residual_before_mm"] == 2.5 and data["residual_after_mm"] == 0.55


def test_publisher_lines_carry_the_transform_in_each_ros_argument_order() -> None:
    T = _link((0.1, -0.2, 0.3), (0.01, -0.02, 0.03))
    lines = publisher_commands("panda_hand", "camera_link", T)
    ros1 = shlex.split(lines["ros1"])
    assert ros1[:3] == ["rosrun", "tf2_ros", "static_transform_publisher"]
    x, y, z, qx, qy, qz, qw = map(float, ros1[3:10])
    assert ros1[10:] == ["panda_hand", "camera_link"]
    np.testing.assert_allclose(transform_from_pose([x, y, z], [qx, qy, qz, qw]), T, atol=1e-8)
    ros2 = shlex.split(lines["ros2"])
    assert ros2[:3] == ["ros2", "run", "tf2_ros"]
    named = dict(zip(ros2[4::2], ros2[5::2], strict=True))
    assert named["--frame-id"] == "panda_hand" and named["--child-frame-id"] == "camera_link"
    values = [float(named[k]) for k in ("--x", "--y", "--z", "--qx", "--qy", "--qz", "--qw")]
    np.testing.assert_allclose(values, [x, y, z, qx, qy, qz, qw])
    assert lines["ros2_positional"].split()[4:] == ros1[3:]


def test_each_corrected_link_alone_gives_the_corrected_mount() -> None:
    calibration = _calibration((1.2, -0.8, 0.5, 0.2, -0.3, 0.1, 0.0))
    corrected = calibration.link_corrections()
    for i, (link, T_new) in enumerate(corrected):
        chain = [L.T for L in LINKS]
        chain[i] = T_new
        assert link is LINKS[i]
        np.testing.assert_allclose(
            chain[0] @ chain[1] @ chain[2], calibration.mount.T_moving_camera, atol=1e-12
        )


def test_a_consistent_calibration_keeps_the_published_mount(tmp_path: Path) -> None:
    calibration = _calibration((0.01, 0.02, -0.01, 0.001, 0.0, 0.002, 0.1))
    assert calibration.consistent
    path = tmp_path / "cal.yaml"
    write_calibration_file(path, calibration)
    mount = read_calibration_file(path)
    np.testing.assert_allclose(mount.T_moving_camera, calibration.published.T_moving_camera)
    assert mount.time_offset_s == 0.0
    assert "published calibration is consistent" in path.read_text()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("schema: other/v1\n", "not a scrapcut calibration"),
        ("[1, 2\n", "not valid YAML"),
        ("- a\n- b\n", "expected a mapping"),
        (
            "schema: scrapcut.calibration/v1\nmoving_frame: a\ncamera_frame: b\n",
            "missing or malformed",
        ),
        (
            "schema: scrapcut.calibration/v1\nmoving_frame: a\ncamera_frame: b\n"
            "T_moving_camera: {translation_m: [0, 0, 0], rotation_xyzw: [0, 0, 0, 2]}\n"
            "time_offset_s: 0\n",
            "unit quaternion",
        ),
        (
            "schema: scrapcut.calibration/v1\nmoving_frame: a\ncamera_frame: b\n"
            "T_moving_camera: {translation_m: [0, 0, 0], rotation_xyzw: [0, 0, 0, 1]}\n"
            "time_offset_s: 5\n",
            "within ±1 s",
        ),
    ],
)
def test_bad_calibration_files_are_one_clear_error(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "cal.yaml"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=message) as info:
        read_calibration_file(path)
    assert "\n" not in str(info.value)
    with pytest.raises(CalibrationError, match="not found"):
        read_calibration_file(tmp_path / "missing.yaml")
