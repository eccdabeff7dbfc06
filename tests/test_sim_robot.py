"""Tests of scrapcut_cli.sim.robot: kinematics, inverse kinematics, collisions, free DOFs, and
the two worlds collision checks see (the true piece, or what the camera observed)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator

import numpy as np
import pytest

from scrapcut_cli.cell import Reach, ReachQuery
from scrapcut_cli.geometry import look_at, rotation_angle
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.sim import make_object
from scrapcut_cli.sim.camera import T_HAND_CAMLINK, d435i_color_camera
from scrapcut_cli.sim.observed import ObservedScene
from scrapcut_cli.sim.robot import Q_READY, PandaSim, World


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
    assert reason is Reach.OK and q is not None
    assert panda.kin.within_limits(q)
    T = panda.camera_pose(q)
    assert np.linalg.norm(T[:3, 3] - target[:3, 3]) < 2e-4
    assert rotation_angle(T[:3, :3], target[:3, :3]) < 2e-3
    answer = panda.reachable(ReachQuery(target), Q_READY)
    assert answer.feasible and answer.reason is Reach.OK
    assert answer.T_base_cam is not None and np.allclose(answer.T_base_cam, T)


def test_out_of_reach_gives_up_quickly(panda: PandaSim) -> None:
    far = look_at((1.6, 0.0, 0.4), (1.9, 0.0, 0.0))
    solution = panda.plan_view(far, Q_READY)
    assert not solution.feasible and solution.answer.reason in (Reach.IK, Reach.JOINT_LIMITS)
    assert solution.answer.attempts == len(panda.limits.roll_steps_deg)  # no back-off for reach
    assert solution.q is None and solution.route == ()
    assert not panda.reachable(ReachQuery(far), Q_READY).feasible


def test_too_close_a_view_collides_and_the_free_dofs_back_it_off(panda: PandaSim) -> None:
    top = np.array([0.5, 0.0, 0.15])  # centre of the box's top face
    close = look_at(top + np.array([0.0, 0.0, 0.02]), top, up_hint=(1.0, 0.0, 0.0))
    hits, solvable = [], []
    for roll in np.radians(panda.limits.roll_steps_deg):
        turn = np.eye(4)
        turn[:2, :2] = [[np.cos(roll), -np.sin(roll)], [np.sin(roll), np.cos(roll)]]
        q, _ = panda.solve_ik(close @ turn, Q_READY)
        if q is not None:
            hits.append(panda.collision(q))
            solvable.append(close @ turn)
    assert hits and all(hit is not None for hit in hits)  # reachable, but it hits the box
    solution = panda.plan_view(close, Q_READY)
    answer = solution.answer
    assert solution.feasible and answer.backoff_m > 0.0
    assert answer.T_base_cam is not None and solution.q is not None
    assert panda.collision(solution.q) is None
    assert np.array_equal(solution.route[-1], solution.q)
    # The optical axis is kept: the camera only moved back along it.
    offset = answer.T_base_cam[:3, 3] - close[:3, 3]
    assert np.allclose(np.cross(offset, close[:3, 2]), 0.0, atol=5e-4)
    assert np.dot(offset, close[:3, 2]) == pytest.approx(-answer.backoff_m, abs=5e-4)
    # Exactly as asked (no free DOFs), the view is refused with what it hits.
    exact = panda.reachable(ReachQuery(solvable[0], free_dofs=False), Q_READY)
    assert not exact.feasible and exact.reason is Reach.COLLISION
    assert exact.detail.endswith("/object") and exact.attempts == 1


def _depth_of_plane(height_m: float, camera_z_m: float) -> Frame:
    """A frame looking straight down at a horizontal plane (no colour), 160 × 120 px."""
    camera = d435i_color_camera(160, 120)
    T = look_at((0.5, 0.0, camera_z_m), (0.5, 0.0, height_m), up_hint=(1.0, 0.0, 0.0))
    depth = np.full((120, 160), camera_z_m - height_m, dtype=np.float32)
    color = np.zeros((120, 160, 3), dtype=np.uint8)
    return Frame(0, 1, color, depth, camera, T)


def test_the_observed_world_knows_only_what_the_camera_saw(panda: PandaSim) -> None:
    """A camera pose 2 cm above the box's top: the true world refuses it, the observed world
    allows it until a depth image of the top has been observed; the crash check (true piece,
    no margin) sees the box whatever was observed."""
    top = np.array([0.5, 0.0, 0.15])
    close = look_at(top + np.array([0.0, 0.0, 0.02]), top, up_hint=(-1.0, 0.0, 0.0))
    query = ReachQuery(close)
    truth = panda.reachable(query, Q_READY, world=World.TRUTH)
    assert not truth.feasible and truth.detail.endswith("/object")
    panda.set_observed(np.zeros((0, 3)), np.zeros((0, 3)))
    blind = panda.plan_view(close, Q_READY, free_dofs=False, world=World.OBSERVED)
    assert blind.feasible and blind.q is not None
    hit, clearance = panda.crash(blind.q)  # what a cell planning blind would hit
    assert hit is not None and hit.endswith("/object") and clearance < 0.0
    scene = ObservedScene()
    assert scene.add(_depth_of_plane(0.15, 0.45)) > 100
    panda.set_observed(*scene.mesh())
    seen = panda.reachable(query, Q_READY, world=World.OBSERVED)
    assert not seen.feasible and seen.reason is Reach.COLLISION
    assert seen.detail.endswith("/observed")
    # A view 0.3 m above the observed top is clear in both worlds, and nothing touches it.
    far = look_at(top + np.array([0.0, 0.0, 0.3]), top, up_hint=(-1.0, 0.0, 0.0))
    clear = panda.plan_view(far, Q_READY, free_dofs=False, world=World.OBSERVED)
    assert clear.feasible and clear.q is not None
    assert panda.crash(clear.q).hit is None and panda.crash(clear.q).clearance_m > 0.05
    panda.set_observed(np.zeros((0, 3)), np.zeros((0, 3)))


def test_self_collision_is_a_collision_in_every_world(panda: PandaSim) -> None:
    """The robot knows its own geometry: planning refuses it in both worlds (crashes are
    counted against the true piece and the floor only)."""
    folded = np.array(Q_READY)
    folded[3], folded[5] = -2.8, 0.0  # elbow folded, wrist straight: link7 meets link5
    assert panda.kin.within_limits(folded)
    for world in World:
        assert panda.collision(folded, world=world) == "panda_link5/panda_link7"
    assert panda.collision(Q_READY, world=World.OBSERVED) is None


def test_a_move_through_the_piece_is_a_crash_and_a_blocked_route(panda: PandaSim) -> None:
    """From one side of the box to the other, low: the straight joint move sweeps the hand
    through it. Planning in the true world detours through the ready pose; the crash check of
    the straight move finds the box."""
    side = np.array([0.0, 1.0, 0.0])
    views = []
    for sign in (1.0, -1.0):
        eye = np.array([0.5, 0.0, 0.08]) + sign * 0.3 * side
        target = np.array([0.5, 0.0, 0.08])
        views.append(panda.plan_view(look_at(eye, target, up_hint=(0.0, 0.0, 1.0)), Q_READY))
    assert all(v.feasible and v.q is not None for v in views)
    a, b = (v.q for v in views)
    assert a is not None and b is not None
    hit, clearance = panda.motion_crash(a, b)
    assert hit is not None and clearance < 0.0
    route, blocked = panda.route(a, b)
    assert blocked is None and route is not None and len(route) == 2  # through the ready pose
    assert np.allclose(route[0], Q_READY)


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
