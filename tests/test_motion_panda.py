"""Tests of scrapcut_cli.motion.panda: the URDF chain, a user URDF, unreadable URDFs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scrapcut_cli.errors import MotionError
from scrapcut_cli.motion.panda import PandaKinematics, default_urdf_path


def test_chain_composes_to_the_flange_for_many_samples() -> None:
    kin = PandaKinematics()
    qs = np.random.default_rng(1).uniform(kin.lower, kin.upper, (5, 7))
    chain = kin.chain(qs)
    assert chain.shape == (5, 8, 4, 4)
    product = np.stack([np.linalg.multi_dot(list(c)) for c in chain])
    assert np.allclose(product, kin.flange(qs), atol=1e-12)


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
        "m.PandaKinematics()\n"
        "bad = [n for n in sys.modules if n == 'pybullet' or n.startswith('scrapcut_cli.sim')]\n"
        "print(','.join(bad))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == ""
