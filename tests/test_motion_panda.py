"""Tests of scrapcut_cli.motion.panda: the URDF chain, a user URDF, unreadable URDFs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import panda_dh_flange

from scrapcut_cli.errors import MotionError
from scrapcut_cli.geometry import rotation_angle
from scrapcut_cli.motion.panda import PandaKinematics, default_urdf_path


def test_chain_composes_to_the_flange_for_many_samples() -> None:
    kin = PandaKinematics()
    qs = np.random.default_rng(1).uniform(kin.lower, kin.upper, (5, 7))
    chain = kin.chain(qs)
    assert chain.shape == (5, 8, 4, 4)
    product = np.stack([np.linalg.multi_dot(list(c)) for c in chain])
    assert np.allclose(product, kin.flange(qs), atol=1e-12)


def test_the_urdf_chain_agrees_with_frankas_published_dh_parameters() -> None:
    kin = PandaKinematics()
    qs = np.random.default_rng(2).uniform(kin.lower, kin.upper, (50, 7))
    flanges = kin.flange(qs)
    for q, T in zip(qs, flanges, strict=True):
        oracle = panda_dh_flange(q)
        assert np.linalg.norm(T[:3, 3] - oracle[:3, 3]) < 1e-9
        assert rotation_angle(T[:3, :3], oracle[:3, :3]) < 1e-9


def test_the_analytic_jacobian_matches_finite_differences() -> None:
    kin = PandaKinematics()
    T_flange_tool = np.eye(4)
    T_flange_tool[:3, 3] = (0.01, -0.02, 0.25)
    rng = np.random.default_rng(3)
    h = 1e-6
    for q in rng.uniform(kin.lower + 0.1, kin.upper - 0.1, (5, 7)):
        T, J = kin.tool_jacobian(q[None], T_flange_tool)
        steps = q + h * np.eye(7)
        T_h, _ = kin.tool_jacobian(steps, T_flange_tool)
        linear = (T_h[:, :3, 3] - T[0, :3, 3]) / h  # (7, 3)
        # Angular: the skew part of dR R^T.
        dR = (T_h[:, :3, :3] - T[0, :3, :3]) / h
        W = dR @ T[0, :3, :3].T
        angular = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        assert np.allclose(J[0, :3].T, linear, atol=1e-5)
        assert np.allclose(J[0, 3:].T, angular, atol=1e-5)
    frames = kin.link_frames(q)
    assert frames.shape == (1, 9, 4, 4)
    assert np.allclose(frames[0, 8], kin.flange(q), atol=1e-12)


def test_a_user_urdf_is_read_instead_of_the_bundled_one(tmp_path: Path) -> None:
    text = default_urdf_path().read_text()
    # A longer link4 offset (panda_joint5's origin moves 0.1 m along x) must show in the FK.
    original = '<origin rpy="-1.57079632679 0 0" xyz="-0.0825 0.384 0"/>'
    assert text.count(original) == 1
    user = tmp_path / "my_panda.urdf"
    user.write_text(text.replace(original, original.replace("-0.0825", "-0.1825")))
    stock, mine = PandaKinematics(), PandaKinematics(user)
    assert mine.urdf == user
    q = np.zeros(7)
    moved = np.linalg.norm(mine.flange(q)[:3, 3] - stock.flange(q)[:3, 3])
    assert moved == pytest.approx(0.1, abs=1e-9)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "cannot read URDF"),
        ("<robot", "cannot read URDF"),
        ("<robot name='x'/>", "has no joint panda_joint1"),
        ("<robot name='x'><joint name='panda_joint1'/></robot>", "does not turn about z"),
    ],
)
def test_unreadable_urdfs_raise_one_clear_error(
    tmp_path: Path, content: str | None, message: str
) -> None:
    path = tmp_path / "bad.urdf"
    if content is not None:
        path.write_text(content)
    with pytest.raises(MotionError, match=message):
        PandaKinematics(path)


def test_motion_never_imports_the_simulator() -> None:
    code = (
        "import sys, scrapcut_cli.motion.panda as m\n"
        "import scrapcut_cli.motion.recipe, scrapcut_cli.motion.trajfile\n"
        "m.PandaKinematics()\n"
        "bad = [n for n in sys.modules if n == 'pybullet' or n.startswith('scrapcut_cli.sim')]\n"
        "print(','.join(bad))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == ""
