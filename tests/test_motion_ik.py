"""Tests of scrapcut_cli.motion.ik: round trips, the free roll, unreachable targets."""

from __future__ import annotations

import numpy as np
import pytest

from scrapcut_cli.motion.ik import IkSettings, TorchIk
from scrapcut_cli.motion.limits import panda_limits
from scrapcut_cli.motion.panda import Q_READY, PandaKinematics
from scrapcut_cli.motion.tool import default_mount


@pytest.fixture(scope="module")
def ik() -> TorchIk:
    kin = PandaKinematics()
    return TorchIk(kin, default_mount().T_flange_tool, panda_limits(kin.lower, kin.upper))


def test_round_trip_from_a_nearby_seed_meets_the_tolerances(ik: TorchIk) -> None:
    rng = np.random.default_rng(0)
    s = IkSettings()
    for _ in range(20):
        q_true = rng.uniform(ik.lower + 0.2, ik.upper - 0.2)
        T = ik.tool_poses(q_true)[0]
        seed = q_true + rng.normal(scale=0.1, size=7)
        r = ik.solve(T[:3, 3], T[:3, 2], seed)
        assert r.converged and r.reason == "ok"
        got = ik.tool_poses(r.q)[0]
        assert np.linalg.norm(got[:3, 3] - T[:3, 3]) < s.position_tol_m
        assert np.arccos(np.clip(got[:3, 2] @ T[:3, 2], -1, 1)) < s.axis_tol_rad
        assert np.all(r.q >= ik.lower) and np.all(r.q <= ik.upper)


def test_the_roll_about_the_torch_axis_is_left_free(ik: TorchIk) -> None:
    # A target whose axis matches the ready pose's but turned 90 degrees about the axis: the
    # solver must not chase the roll (5-D task), so it stays close to the seed.
    T = ik.tool_poses(np.array(Q_READY))[0]
    r = ik.solve(T[:3, 3], T[:3, 2], np.array(Q_READY))
    assert r.converged and r.iterations <= 2
    assert np.max(np.abs(r.q - np.array(Q_READY))) < 0.05


def test_posture_iterations_move_away_from_the_joint_limits(ik: TorchIk) -> None:
    # Joint 7 near its limit: the torch's free roll lets the null space turn it back.
    q0 = np.array(Q_READY)
    q0[6] = ik.upper[6] - 0.05
    T = ik.tool_poses(q0)[0]
    r = ik.solve(T[:3, 3], T[:3, 2], q0, posture_iterations=60)
    assert r.converged
    margin = np.minimum(r.q - ik.lower, ik.upper - r.q)
    assert margin[6] > 0.3  # 60 steps of at most 0.01 rad: most went into joint 7
    assert margin.min() > 0.3


def test_out_of_reach_and_joint_limits_are_named(ik: TorchIk) -> None:
    far = ik.solve([1.5, 0.0, 0.3], [0.0, 0.0, -1.0], np.array(Q_READY))
    assert not far.converged and far.reason in ("out_of_reach", "joint_limits")
    assert far.position_error_m > 0.3
    # Right above the base, torch pointing straight down at the column: inside its own base.
    inside = ik.solve([0.0, 0.0, 0.1], [0.0, 0.0, -1.0], np.array(Q_READY))
    assert not inside.converged


def test_the_reach_bound_never_refuses_a_reachable_target(ik: TorchIk) -> None:
    qs = np.random.default_rng(5).uniform(ik.lower, ik.upper, (2000, 7))
    T = ik.tool_poses(qs)
    assert not any(ik.beyond_reach(t[:3, 3], t[:3, 2]) for t in T)
    # ... and it does refuse what is clearly beyond the arm.
    assert ik.beyond_reach([1.2, 0.0, 0.3], [0.0, 0.0, -1.0])
