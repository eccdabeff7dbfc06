"""Tests of scrapcut_cli.sim.robot: kinematics, inverse kinematics, collisions, free DOFs."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator

import numpy as np
import pytest

from scrapcut_cli.geometry import look_at, rotation_angle
from scrapcut_cli.sim import make_object
from scrapcut_cli.sim.camera import T_HAND_CAMLINK
from scrapcut_cli.sim.robot import Q_READY, PandaSim


@pytest.fixture(scope="module")
def panda() -> Iterator[PandaSim]:
    with PandaSim(make_object("planar_box").mesh, T_hand_camlink_nominal=T_HAND_CAMLINK) as sim:
        yield sim


def test_numpy_forward_kinematics_matches_pybullet(panda: PandaSim) -> None:
    rng = np.random.default_rng(0)
    kin = panda.kin
    for _ in range(10):
        q = rng.uniform(kin.lower, kin.upper)
        panda.set_joints(q)
        state = panda._client.getLinkState(panda._robot, 7, computeForwardKinematics=True)
        T = kin.flange(q)
        assert np.allclose(T[:3, 3], state[4], atol=1e-6)
        R_pb = np.array(panda._client.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        assert rotation_angle(T[:3, :3], R_pb) < 1e-6


def test_ik_places_the_camera_where_asked(panda: PandaSim) -> None:
    target = look_at((0.45, -0.25, 0.45), (0.5, 0.0, 0.15))
    q, reason = panda.solve_ik(target, Q_READY)
    assert reason == "ok" and q is not None
    assert panda.kin.within_limits(q)
    T = panda.camera_pose(q)
    assert np.linalg.norm(T[:3, 3] - target[:3, 3]) < 2e-4
    assert rotation_angle(T[:3, :3], target[:3, :3]) < 2e-3
    assert panda.reachable(target)


def test_out_of_reach_gives_up_quickly(panda: PandaSim) -> None:
    far = look_at((1.6, 0.0, 0.4), (1.9, 0.0, 0.0))
    solution = panda.plan_view(far, Q_READY)
    assert not solution.feasible and solution.reason in ("ik", "joint_limits")
    assert solution.attempts == len(panda.limits.roll_steps_deg)  # no back-off for reach
    assert not panda.reachable(far)


def test_too_close_a_view_collides_and_the_free_dofs_back_it_off(panda: PandaSim) -> None:
    top = np.array([0.5, 0.0, 0.15])  # centre of the box's top face
    close = look_at(top + np.array([0.0, 0.0, 0.02]), top, up_hint=(1.0, 0.0, 0.0))
    hits = []
    for roll in np.radians(panda.limits.roll_steps_deg):
        turn = np.eye(4)
        turn[:2, :2] = [[np.cos(roll), -np.sin(roll)], [np.sin(roll), np.cos(roll)]]
        q, _ = panda.solve_ik(close @ turn, Q_READY)
        if q is not None:
            hits.append(panda.collision(q))
    assert hits and all(hit is not None for hit in hits)  # reachable, but it hits the box
    solution = panda.plan_view(close, Q_READY)
    assert solution.feasible and solution.backoff_m > 0.0
    assert solution.T_base_cam is not None and solution.q is not None
    assert panda.collision(solution.q) is None
    # The optical axis is kept: the camera only moved back along it.
    offset = solution.T_base_cam[:3, 3] - close[:3, 3]
    assert np.allclose(np.cross(offset, close[:3, 2]), 0.0, atol=5e-4)
    assert np.dot(offset, close[:3, 2]) == pytest.approx(-solution.backoff_m, abs=5e-4)


def test_importing_and_connecting_prints_nothing() -> None:
    code = (
        "from scrapcut_cli.sim.robot import PandaSim\n"
        "from scrapcut_cli.sim.mesh import box\n"
        "from scrapcut_cli.sim.camera import T_HAND_CAMLINK\n"
        "PandaSim(box((0.4, -0.1, 0), (0.6, 0.1, 0.1)), T_hand_camlink_nominal=T_HAND_CAMLINK)"
        ".close()\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout == "" and result.stderr == ""
