"""The camera mount: what a recording publishes, and a reader posing frames with another one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import (
    SCAN_OPTICAL_FRAME,
    SyntheticScan,
    scan_static_transforms,
    scan_T_base_link8,
    synthetic_scan,
    write_scan,
)
from scipy.spatial.transform import Rotation

from scrapcut_cli.errors import RecordingError
from scrapcut_cli.geometry import make_transform
from scrapcut_cli.recording.mount import CameraMount
from scrapcut_cli.recording.reader import open_recording
from scrapcut_cli.recording.tf import TfBuffer


@pytest.fixture(scope="module")
def scan() -> SyntheticScan:
    return synthetic_scan(8)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory, scan: SyntheticScan) -> Path:
    path = tmp_path_factory.mktemp("mount") / "scan.mcap"
    write_scan(path, scan, "mcap")
    return path


def _static_chain() -> np.ndarray:
    T = np.eye(4)
    for _, _, link in scan_static_transforms():
        T = T @ link
    return T


def test_published_mount_is_the_static_chain_below_the_last_tf_link(recording: Path) -> None:
    with open_recording(recording) as rec:
        mount = rec.published_mount()
        plan = rec.plan()
        T_moving, valid = rec.moving_poses(plan.stamps_ns)
    assert (mount.moving_frame, mount.camera_frame) == ("panda_link8", SCAN_OPTICAL_FRAME)
    assert mount.time_offset_s == 0.0
    np.testing.assert_allclose(mount.T_moving_camera, _static_chain(), atol=1e-9)
    # The moving frame's poses at the frames' stamps compose with the mount to the frame poses.
    assert valid.all()
    np.testing.assert_allclose(T_moving @ mount.T_moving_camera, plan.T_base_cam, atol=1e-9)


def test_a_mount_poses_frames_with_its_transform_and_clock_offset(
    recording: Path, scan: SyntheticScan
) -> None:
    shift = make_transform(Rotation.from_rotvec([0.0, 0.01, 0.0]).as_matrix(), [0.002, 0, 0])
    mount = CameraMount("panda_link8", SCAN_OPTICAL_FRAME, _static_chain() @ shift, 0.004)
    with open_recording(recording) as rec:
        published = rec.plan()
    with open_recording(recording, mount=mount) as rec:
        plan = rec.plan()
        frames = list(rec.frames())
    # Header stamps stay the frames' stamps; poses come from /tf 4 ms later and the new mount.
    np.testing.assert_array_equal(plan.stamps_ns, published.stamps_ns)
    expected = scan_T_base_link8(scan.seconds(plan.stamps_ns + 4_000_000)) @ mount.T_moving_camera
    np.testing.assert_allclose(plan.T_base_cam, expected, atol=1e-7)
    assert [f.stamp_ns for f in frames] == plan.stamps_ns.tolist()
    np.testing.assert_allclose(frames[0].T_base_cam, expected[0], atol=1e-7)
    # A stamp the offset moves past the end of /tf is skipped, never extrapolated.
    late = CameraMount("panda_link8", SCAN_OPTICAL_FRAME, _static_chain(), 0.5)
    with open_recording(recording, mount=late) as rec:
        assert rec.plan().usable < published.usable
        assert rec.plan().skip_reasons["pose_out_of_range"] > 0


def test_a_mount_for_another_chain_is_refused(recording: Path) -> None:
    other_camera = CameraMount("panda_link8", "ir_optical_frame", np.eye(4))
    with (
        open_recording(recording, mount=other_camera) as rec,
        pytest.raises(RecordingError, match="camera frame 'ir_optical_frame'"),
    ):
        rec.plan()
    other_flange = CameraMount("panda_hand", SCAN_OPTICAL_FRAME, np.eye(4))
    with (
        open_recording(recording, mount=other_flange) as rec,
        pytest.raises(RecordingError, match=r"mounts the camera on 'panda_hand'.*'panda_link8'"),
    ):
        rec.plan()


def test_a_mount_must_be_a_rigid_transform() -> None:
    with pytest.raises(ValueError, match="rotation"):
        CameraMount("a", "b", np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="finite"):
        CameraMount("a", "b", np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="time offset"):
        CameraMount("a", "b", np.eye(4), float("inf"))


def test_moving_frame_is_the_child_of_the_last_dynamic_link() -> None:
    tf = TfBuffer()
    tf.add("base", "flange", 0, [0, 0, 0], [0, 0, 0, 1], static=False)
    tf.add("flange", "hand", 0, [0, 0, 0.1], [0, 0, 0, 1], static=True)
    tf.add("hand", "camera", 0, [0.05, 0, 0], [0, 0, 0, 1], static=True)
    tf.add("base", "fixed_camera", 0, [1, 0, 0], [0, 0, 0, 1], static=True)
    tf.add("base", "tracked", 0, [0, 1, 0], [0, 0, 0, 1], static=False)
    assert tf.moving_frame("base", "camera") == "flange"
    assert tf.moving_frame("base", "fixed_camera") == "base"  # nothing moves it
    assert tf.moving_frame("base", "tracked") == "tracked"  # its own link moves
    assert tf.path_down("flange", "camera") == ["flange", "hand", "camera"]
    with pytest.raises(RecordingError, match="not above"):
        tf.path_down("camera", "flange")
