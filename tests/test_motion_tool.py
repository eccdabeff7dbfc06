"""Tests of scrapcut_cli.motion.tool (the torch mount) and motion.timing (moves, the check)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scrapcut_cli.errors import MotionError
from scrapcut_cli.motion.limits import panda_limits
from scrapcut_cli.motion.timing import check_sampled, quintic_hermite, time_move
from scrapcut_cli.motion.tool import default_mount, parse_tool_offset


def test_the_default_mount_is_a_straight_torch_250_mm_out() -> None:
    T = default_mount().T_flange_tool
    np.testing.assert_allclose(T[:3, :3], np.eye(3))
    np.testing.assert_allclose(T[:3, 3], [0.0, 0.0, 0.25])


def test_tool_offsets_in_mm_and_degrees_and_from_files(tmp_path: Path) -> None:
    m = parse_tool_offset("10, -5, 300, 0, 30, 90")
    np.testing.assert_allclose(m.T_flange_tool[:3, 3], [0.01, -0.005, 0.3])
    expected = Rotation.from_euler("xyz", np.radians([0.0, 30.0, 90.0])).as_matrix()
    np.testing.assert_allclose(m.T_flange_tool[:3, :3], expected, atol=1e-12)
    data = {"translation_m": [0.0, 0.02, 0.2], "rotation_xyzw": [0.0, 0.0, 0.0, 1.0]}
    (tmp_path / "m.json").write_text(json.dumps({"T_flange_tool": data}))
    (tmp_path / "m.yaml").write_text(
        "translation_m: [0.0, 0.02, 0.2]\nrotation_xyzw: [0.0, 0.0, 0.0, 1.0]\n"
    )
    for name in ("m.json", "m.yaml"):
        mount = parse_tool_offset(str(tmp_path / name))
        np.testing.assert_allclose(mount.T_flange_tool[:3, 3], [0.0, 0.02, 0.2])
        assert mount.source.endswith(name)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1,2", "expected x,y,z"),
        ("0,0,nan", "finite"),
        ("0,0,2000", "from the flange"),
        ("missing.yaml", "not found"),
    ],
)
def test_bad_tool_offsets_are_named(text: str, message: str) -> None:
    with pytest.raises(MotionError, match=message):
        parse_tool_offset(text)


def test_a_bad_mount_file_names_the_key(tmp_path: Path) -> None:
    path = tmp_path / "m.yaml"
    path.write_text("translation_m: [0, 0]\n")
    with pytest.raises(MotionError, match="translation_m must be 3"):
        parse_tool_offset(str(path))
    path.write_text("translation_m: [0, 0, 0.2]\nrotation_xyzw: [0, 0, 0, 2]\n")
    with pytest.raises(MotionError, match="unit quaternion"):
        parse_tool_offset(str(path))


def test_a_move_is_slowed_until_it_is_within_the_limits() -> None:
    limits = panda_limits().scaled(0.5)
    mid = 0.5 * (limits.lower + limits.upper)
    q = np.tile(mid, (3, 1))
    q[1, 0], q[2, 0] = 0.5, 1.0  # joint 1 turns 1 rad over a 0.1 m "path"
    move = time_move(q, [0.0, 0.05, 0.1], [0.5, 0.5], limits)
    assert move.time_scale > 1.0  # at 0.5 m/s joint 1 would need 5 rad/s
    times = np.linspace(0.0, move.duration_s, 2001)
    p, v, a = move.state(times)
    assert np.abs(v[:, 0]).max() <= limits.velocity[0] * 1.001
    np.testing.assert_allclose(p[[0, -1], 0], [0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(v[[0, -1]], 0.0, atol=1e-9)
    check = check_sampled(times, p, v, a, panda_limits())
    assert check.ok and check.velocity_ratio[0] <= 0.5 * 1.01


def test_the_check_catches_a_jump() -> None:
    t = np.array([0.0, 0.1, 0.2])
    q = np.zeros((3, 7))
    q[1, 3] = -1.0  # -1 rad in 0.1 s and back: far beyond 2.175 rad/s
    q[:, 3] -= 1.0
    check = check_sampled(t, q, np.zeros_like(q), np.zeros_like(q), panda_limits())
    assert not check.ok and check.velocity_ratio[3] > 1.0


def test_quintic_hermite_meets_its_data_and_matches_scipy() -> None:
    from scipy.interpolate import BPoly

    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.05, 0.3, 12))
    P, V, A = rng.normal(size=(3, 12, 2))
    x = np.linspace(t[0], t[-1], 500)
    q = quintic_hermite(t, P, V, A, x)
    np.testing.assert_allclose(quintic_hermite(t, P, V, A, t), P, atol=1e-12)
    for j in range(2):
        ref = BPoly.from_derivatives(t, np.stack([P[:, j], V[:, j], A[:, j]], axis=1))(x)
        np.testing.assert_allclose(q[:, j], ref, atol=1e-10)
