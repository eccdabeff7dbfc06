"""TfBuffer: static links are timeless, /tf is interpolated (lerp + slerp), never extrapolated."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import (
    random_se3,
    scan_static_transforms,
    scan_T_base_cam,
    scan_T_base_link8,
)
from scipy.spatial.transform import Rotation

from scrapcut_cli.errors import RecordingError
from scrapcut_cli.geometry import invert_transform, pose_from_transform, rotation_angle
from scrapcut_cli.recording.tf import TfBuffer

SECOND = 1_000_000_000


def _add(
    buffer: TfBuffer, parent: str, child: str, stamp: int, T: np.ndarray, static: bool
) -> None:
    t, q = pose_from_transform(T)
    buffer.add(parent, child, stamp, t, q, static=static)


def _scan_buffer(sample_stamps: np.ndarray) -> TfBuffer:
    """The synthetic scan's TF: a sampled flange pose and a three-link static chain."""
    buffer = TfBuffer()
    for parent, child, T in scan_static_transforms():
        _add(buffer, parent, child, 123, T, static=True)  # old stamp: static is timeless
    for stamp, T in zip(sample_stamps, scan_T_base_link8(sample_stamps / SECOND), strict=True):
        _add(buffer, "panda_link0", "panda_link8", int(stamp), T, static=False)
    return buffer


def test_interpolation_matches_an_analytic_rotating_translating_camera() -> None:
    # 20 Hz samples of a camera turning at 0.7 rad/s and moving at ~5 cm/s, queried at random
    # stamps between samples through a four-link chain: slerp and lerp are exact for this
    # motion, so the error is rounding only (required: 1e-6 m, 1e-6 rad).
    samples = np.arange(0, 2 * SECOND + 1, 50_000_000, dtype=np.int64)
    buffer = _scan_buffer(samples)
    rng = np.random.default_rng(3)
    queries = np.sort(rng.integers(0, 2 * SECOND, 200))
    T, valid = buffer.lookup("panda_link0", "camera_color_optical_frame", queries)
    assert valid.all()
    truth = scan_T_base_cam(queries / SECOND)
    position_error = np.linalg.norm(T[:, :3, 3] - truth[:, :3, 3], axis=1).max()
    angle_error = max(rotation_angle(a[:3, :3], b[:3, :3]) for a, b in zip(T, truth, strict=True))
    assert position_error < 1e-6
    assert angle_error < 1e-6


def test_interpolation_is_between_samples_not_at_the_nearest_one() -> None:
    buffer = TfBuffer()
    buffer.add("a", "b", 0, [0, 0, 0], [0, 0, 0, 1], static=False)
    rot = Rotation.from_rotvec([0, 0, 1.0]).as_quat()
    buffer.add("a", "b", 10, [1, 2, 3], rot, static=False)
    T, valid = buffer.lookup("a", "b", [0, 3, 10])
    assert valid.all()
    np.testing.assert_allclose(T[1, :3, 3], [0.3, 0.6, 0.9], atol=1e-12)
    np.testing.assert_allclose(Rotation.from_matrix(T[1, :3, :3]).as_rotvec(), [0, 0, 0.3])
    np.testing.assert_allclose(T[2, :3, 3], [1, 2, 3])


def test_slerp_takes_the_short_way_when_the_quaternion_sign_flips() -> None:
    buffer = TfBuffer()
    q0 = Rotation.from_rotvec([0, 0, 0.2]).as_quat()
    q1 = -Rotation.from_rotvec([0, 0, 0.4]).as_quat()  # same rotation, opposite sign
    buffer.add("a", "b", 0, [0, 0, 0], q0, static=False)
    buffer.add("a", "b", 2, [0, 0, 0], q1, static=False)
    T, _ = buffer.lookup("a", "b", [1])
    np.testing.assert_allclose(Rotation.from_matrix(T[0, :3, :3]).as_rotvec(), [0, 0, 0.3])


def test_out_of_range_is_invalid_never_extrapolated() -> None:
    samples = np.array([100, 200, 300], dtype=np.int64)
    buffer = _scan_buffer(samples)
    T, valid = buffer.lookup("panda_link0", "camera_color_optical_frame", [99, 100, 300, 301])
    assert valid.tolist() == [False, True, True, False]
    np.testing.assert_array_equal(T[0], np.eye(4))
    assert buffer.time_range("panda_link0", "camera_color_optical_frame") == (100, 300)
    with pytest.raises(RecordingError, match="known from 100 to 300 ns"):
        buffer.lookup_one("panda_link0", "camera_color_optical_frame", 301)


def test_static_links_hold_at_any_time_and_the_latest_wins() -> None:
    buffer = TfBuffer()
    first, second = random_se3(1), random_se3(2)
    _add(buffer, "a", "b", 5, first, static=True)
    _add(buffer, "a", "b", 1, second, static=True)  # a later message, even with an older stamp
    T, valid = buffer.lookup("a", "b", [-(10**18), 0, 10**18])
    assert valid.all()
    np.testing.assert_allclose(T, np.broadcast_to(second, (3, 4, 4)), atol=1e-12)
    assert buffer.is_static("a", "b")
    assert buffer.time_range("a", "b") is None


def test_lookup_between_branches_goes_through_the_common_ancestor() -> None:
    buffer = TfBuffer()
    T_root_a, T_a_b, T_a_c = random_se3(4), random_se3(5), random_se3(6)
    _add(buffer, "root", "a", 0, T_root_a, static=True)
    _add(buffer, "a", "b", 0, T_a_b, static=True)
    _add(buffer, "a", "c", 0, T_a_c, static=True)
    T, valid = buffer.lookup("b", "c", [0])
    assert valid.all()
    np.testing.assert_allclose(T[0], invert_transform(T_a_b) @ T_a_c, atol=1e-12)
    T_inverse, _ = buffer.lookup("c", "root", [0])
    np.testing.assert_allclose(T_inverse[0], invert_transform(T_root_a @ T_a_c), atol=1e-12)
    assert buffer.root("c") == "root"
    assert buffer.parent("c") == "a"
    assert buffer.frames == ["a", "b", "c", "root"]


def test_samples_may_arrive_out_of_order_and_duplicates_keep_the_last() -> None:
    buffer = TfBuffer()
    buffer.add("a", "b", 10, [1, 0, 0], [0, 0, 0, 1], static=False)
    buffer.add("a", "b", 0, [0, 0, 0], [0, 0, 0, 1], static=False)
    buffer.add("a", "b", 10, [2, 0, 0], [0, 0, 0, 1], static=False)
    T, _ = buffer.lookup("a", "b", [5])
    np.testing.assert_allclose(T[0, :3, 3], [1, 0, 0])


def test_two_parents_is_an_error_naming_the_frames() -> None:
    buffer = TfBuffer()
    buffer.add("world", "camera", 0, [0, 0, 0], [0, 0, 0, 1], static=True)
    with pytest.raises(RecordingError, match="'camera' has two parents, 'world' and 'hand'"):
        buffer.add("hand", "camera", 0, [0, 0, 0], [0, 0, 0, 1], static=False)


def test_static_and_dynamic_for_one_link_is_an_error() -> None:
    buffer = TfBuffer()
    buffer.add("a", "b", 0, [0, 0, 0], [0, 0, 0, 1], static=True)
    with pytest.raises(RecordingError, match="both /tf and /tf_static"):
        buffer.add("a", "b", 0, [0, 0, 0], [0, 0, 0, 1], static=False)


def test_missing_link_names_the_frames_and_lists_those_that_exist() -> None:
    buffer = TfBuffer()
    buffer.add("base", "link8", 0, [0, 0, 0], [0, 0, 0, 1], static=True)
    buffer.add("camera_link", "optical", 0, [0, 0, 0], [0, 0, 0, 1], static=True)
    with pytest.raises(
        RecordingError,
        match=r"no TF path from 'optical' to 'base'.*TF frames: base, camera_link, link8, optical",
    ):
        buffer.lookup("base", "optical", [0])
    with pytest.raises(RecordingError, match="'nowhere' does not exist; TF frames: base"):
        buffer.lookup("base", "nowhere", [0])


def test_invalid_poses_are_rejected() -> None:
    buffer = TfBuffer()
    with pytest.raises(RecordingError, match="not a valid pose"):
        buffer.add("a", "b", 0, [0, 0, 0], [0, 0, 0, 0], static=False)
    with pytest.raises(RecordingError, match="to itself"):
        buffer.add("a", "a", 0, [0, 0, 0], [0, 0, 0, 1], static=False)


def test_unnormalised_quaternions_are_normalised() -> None:
    buffer = TfBuffer()
    buffer.add("a", "b", 0, [0, 0, 0], [0, 0, 0, 2.0], static=True)
    T, _ = buffer.lookup("a", "b", [0])
    np.testing.assert_allclose(T[0], np.eye(4), atol=1e-15)


def test_empty_query() -> None:
    buffer = _scan_buffer(np.array([0, 10], dtype=np.int64))
    T, valid = buffer.lookup("panda_link0", "camera_color_optical_frame", [])
    assert T.shape == (0, 4, 4)
    assert valid.shape == (0,)


def test_add_transforms_lean_path_matches_add_and_its_errors() -> None:
    rng = np.random.default_rng(3)
    items = []
    for k in range(200):
        q = tuple(float(x) for x in rng.normal(size=4) * 3.0)
        t = tuple(float(x) for x in rng.normal(size=3))
        items.append(("base", "tool" if k % 3 else "cam", 1000 + k, t, q))
    one, many = TfBuffer(), TfBuffer()
    for parent, child, stamp, t, q in items:
        one.add(parent, child, stamp, t, q, static=False)
    many.add_transforms(items, static=False)
    for child in ("tool", "cam"):
        a, b = one._edges[child], many._edges[child]
        assert (a.parent, a.static, a.stamps, a.translations) == (
            b.parent,
            b.static,
            b.stamps,
            b.translations,
        )
        assert a.quats == b.quats  # bit for bit: the same norm and divisions
    static = TfBuffer()
    static.add_transforms([("base", "s", 1, (0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 2.0))], static=True)
    static.add_transforms([("base", "s", 9, (1.0, 0.0, 0.0), (0.0, 0.0, 2.0, 0.0))], static=True)
    edge = static._edges["s"]
    assert (edge.stamps, edge.translations, edge.quats) == (
        [9],
        [(1.0, 0.0, 0.0)],
        [(0.0, 0.0, 1.0, 0.0)],
    )
    bad = [
        ("base", "tool", 5, (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
        ("base", "tool", 5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)),
        ("base", "tool", 5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1e7)),
        ("other", "tool", 5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
        ("tool", "tool", 5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
    ]
    for item in bad:
        with pytest.raises(RecordingError) as lean:
            many.add_transforms([item], static=False)
        with pytest.raises(RecordingError) as plain:
            one.add(*item, static=False)
        assert str(lean.value) == str(plain.value)
    with pytest.raises(RecordingError, match="on both /tf and /tf_static"):
        many.add_transforms([("base", "tool", 5, (0.0,) * 3, (0.0, 0.0, 0.0, 1.0))], static=True)
