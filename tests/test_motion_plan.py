"""Tests of scrapcut_cli.motion.plan (and follow, timing, collision through it).

Forward kinematics of the trajectories is checked with Franka's DH parameters (helpers),
not with the URDF chain the planner uses; joint limits with scipy's quintic interpolation
of the points and finite differences at 1 kHz, against the datasheet values written here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import panda_dh_flange, surface_patch
from scipy.interpolate import BPoly

from scrapcut_cli.config import MotionConfig, ToolpathConfig
from scrapcut_cli.errors import MotionError
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.geometry import quat_xyzw_to_matrix
from scrapcut_cli.motion.collision import CollisionChecker
from scrapcut_cli.motion.follow import FollowSettings, PathFollower
from scrapcut_cli.motion.ik import TorchIk
from scrapcut_cli.motion.limits import panda_limits
from scrapcut_cli.motion.panda import PandaKinematics
from scrapcut_cli.motion.plan import Trajectory, plan_trajectory
from scrapcut_cli.motion.tool import default_mount
from scrapcut_cli.motion.trajfile import (
    read_trajectory_file,
    trajectory_to_dict,
    write_trajectory_csv,
    write_trajectory_file,
    write_trajectory_mcap,
)
from scrapcut_cli.toolpath.path import CuttingPath
from scrapcut_cli.toolpath.setpoints import make_cutting_path

#: Franka's datasheet (FCI "Limits for Panda"): velocity, acceleration, jerk per joint.
DQ_MAX = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
DDQ_MAX = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])
DDDQ_MAX = np.array([7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0])
Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
PLATE_Z = 0.1


def _plate(x0: float, x1: float) -> np.ndarray:
    return surface_patch((x0, -0.1, PLATE_Z), (x1 - x0, 0.0, 0.0), (0.0, 0.2, 0.0), spacing_m=0.004)


def _path(a: float, b: float, plate: tuple[float, float]) -> tuple[CuttingPath, np.ndarray]:
    x = np.linspace(a, b, 400)
    pts = np.column_stack([x, 0.03 * np.sin(12 * x), np.full_like(x, PLATE_Z)])
    cloud = _plate(*plate)
    path = make_cutting_path(
        Curve(pts, "test"), cloud, cloud + np.array([0.0, 0.0, 0.3]), config=ToolpathConfig()
    )
    return path, cloud


def _plan(path: CuttingPath, cloud: np.ndarray | None, **overrides: object) -> Trajectory:
    return plan_trajectory(
        path,
        base_frame="panda_link0",
        surface_base=cloud,
        mount=default_mount(),
        config=MotionConfig(**overrides),  # type: ignore[arg-type]
    )


@pytest.fixture(scope="module")
def plate_cut() -> tuple[CuttingPath, Trajectory]:
    """0.2 m wavy line on a plate in front of the robot, pierced, cut, stopped."""
    path, cloud = _path(0.40, 0.60, (0.30, 0.70))
    return path, _plan(path, cloud)


def _dh_tool(q: np.ndarray) -> np.ndarray:
    return np.stack([panda_dh_flange(qq) for qq in q]) @ default_mount().T_flange_tool


def test_every_setpoint_is_reached_within_half_a_millimetre_and_a_degree(
    plate_cut: tuple[CuttingPath, Trajectory],
) -> None:
    path, traj = plate_cut
    assert traj.summary["reached"] == len(path) and traj.summary["executable"]
    at = traj.setpoint >= 0
    T = _dh_tool(traj.positions[at])
    index = traj.setpoint[at]
    assert set(index.tolist()) == set(range(len(path)))
    tip_err = np.linalg.norm(T[:, :3, 3] - path.positions[index], axis=1)
    axes = quat_xyzw_to_matrix(path.orientations_xyzw)[index, :, 2]
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", T[:, :3, 2], axes), -1, 1)))
    assert tip_err.max() < 5e-4 and angle.max() < 1.0
    # The solver's own tolerance is much tighter than the criterion.
    assert tip_err.max() < 1e-4 and angle.max() < 0.1


def test_sampled_trajectory_is_within_the_datasheet_limits(
    plate_cut: tuple[CuttingPath, Trajectory],
) -> None:
    _, traj = plate_cut
    t = traj.t
    assert np.all(np.diff(t) > 0)
    fine = np.arange(t[0], t[-1], 0.001)
    q = np.column_stack(
        [
            BPoly.from_derivatives(
                t,
                np.stack(
                    [traj.positions[:, j], traj.velocities[:, j], traj.accelerations[:, j]],
                    axis=1,
                ),
            )(fine)
            for j in range(7)
        ]
    )
    dt = 0.001
    assert np.all(q >= Q_MIN) and np.all(q <= Q_MAX)
    assert np.all(np.abs(np.diff(q, axis=0) / dt) <= DQ_MAX)
    assert np.all(np.abs(np.diff(q, 2, axis=0) / dt**2) <= DDQ_MAX)
    assert np.all(np.abs(np.diff(q, 3, axis=0) / dt**3) <= DDDQ_MAX)
    # The velocities given with the points are the positions' derivatives (within 1 %).
    v_fd = np.gradient(q, dt, axis=0)
    v_given = np.column_stack([np.interp(fine, t, traj.velocities[:, j]) for j in range(7)])
    assert np.abs(v_fd - v_given).max() < 0.01 * DQ_MAX.max()
    assert traj.summary["limits_ok"]


def test_phases_rest_between_moves_and_the_cut_runs_at_the_paths_speed(
    plate_cut: tuple[CuttingPath, Trajectory],
) -> None:
    path, traj = plate_cut
    order = [p for k, p in enumerate(traj.phase) if k == 0 or p != traj.phase[k - 1]]
    assert order == ["approach", "pierce", "cut", "retreat"]
    for k in (0, len(traj) - 1):
        assert np.abs(traj.velocities[k]).max() < 1e-9
    dwell = [t for t, p in zip(traj.t, traj.phase, strict=True) if p == "pierce"]
    assert dwell[-1] - dwell[0] == pytest.approx(path.time[0], abs=1e-9)
    # Away from the ramps, the tip travels at the path's speed between set-points.
    at = np.flatnonzero(traj.setpoint >= 0)
    at = at[traj.setpoint[at] > 0]  # after the dwell
    tips = traj.tool_poses[at, :3, 3]
    speed = np.linalg.norm(np.diff(tips, axis=0), axis=1) / np.diff(traj.t[at])
    middle = speed[5:-5]
    assert np.abs(middle / path.speed[0] - 1.0).max() < 0.02
    # Approach and retreat: 100 mm along the torch axis.
    first = traj.tool_poses[0]
    axis = quat_xyzw_to_matrix(path.orientations_xyzw[0])[:, 2]
    np.testing.assert_allclose(first[:3, 3], path.positions[0] - 0.1 * axis, atol=1e-4)


def test_far_setpoints_are_flagged_with_a_reason_and_tilts_stay_within_the_bound(
    tmp_path: Path,
) -> None:
    path, cloud = _path(0.72, 1.02, (0.62, 1.12))
    traj = _plan(path, cloud, max_tilt_deg=20.0)
    s = traj.summary
    n = len(path)
    assert s["reached"] + s["tilted"] + s["unreachable"] + s["in_collision"] == n
    assert s["unreachable"] > 0 and s["reached"] > 0
    assert set(s["reasons"]) <= {"out_of_reach", "joint_limits", "flip"}
    assert not s["executable"] and s["executable_share"] < 1.0
    sol = traj.solution
    bad = [i for i, st in enumerate(sol.status) if st == "unreachable"]
    assert min(bad) > 5  # the far end, not the near one
    assert all(sol.reason[i] for i in bad)
    assert all(np.isnan(sol.q[i]).all() for i in bad)
    # Tilted set-points pivot about the surface point, within the bound.
    tilted = [i for i, st in enumerate(sol.status) if st == "tilted"]
    for i in tilted:
        assert 0 < sol.tilt_rad[i] <= np.radians(20.0) + 1e-9
        assert np.linalg.norm(sol.tip[i] - path.surface_points[i]) == pytest.approx(
            path.standoff_m, abs=1e-9
        )
    # The file lists every set-point's outcome.
    data = trajectory_to_dict(
        traj, source={}, limits=panda_limits(), config={}, urdf="x", created="2026-01-01"
    )
    assert [sp["status"] for sp in data["setpoints"]] == sol.status


def test_large_joint_steps_are_walked_or_become_a_new_cut() -> None:
    path, cloud = _path(0.48, 0.54, (0.40, 0.60))
    # A bound below the joints' step per set-point: every step is walked through
    # intermediate targets (and counted) ...
    walked = _plan(path, cloud, max_joint_step_rad=0.012)
    assert walked.summary["flips_avoided"] > 0 and walked.summary["cut_segments"] == 1
    # ... and with one far below it (under the configurable range) even the walk's eighths
    # jump: no flip mid-cut, the set-point starts a new cut in its own posture.
    kin = PandaKinematics()
    ik = TorchIk(kin, default_mount().T_flange_tool, panda_limits(kin.lower, kin.upper))
    follower = PathFollower(
        ik,
        CollisionChecker(kin, default_mount(), cloud),
        FollowSettings(max_joint_step_rad=0.0005, max_tilt_deg=0.0),
    )
    axes = quat_xyzw_to_matrix(path.orientations_xyzw)[:, :, 2]
    split = follower.follow_best(path.positions, axes, path.surface_points)
    assert split.status == ["reached"] * len(path)
    assert split.breaks and split.breaks[0] == 1


def test_the_floor_above_the_piece_leaves_nothing_reachable() -> None:
    path, cloud = _path(0.48, 0.52, (0.40, 0.60))
    with pytest.raises(MotionError, match=r"no set-point of the path is reachable.*floor"):
        _plan(path, cloud, floor_z_m=0.2)


def test_an_obstacle_over_the_line_is_a_collision(tmp_path: Path) -> None:
    path, cloud = _path(0.40, 0.60, (0.30, 0.70))
    # A slab 4 cm above the middle of the line: the torch body runs into it.
    slab = surface_patch((0.47, -0.1, PLATE_Z + 0.04), (0.06, 0.0, 0.0), (0.0, 0.2, 0.0))
    traj = _plan(path, np.vstack([cloud, slab]), max_tilt_deg=10.0)
    s = traj.summary
    assert s["in_collision"] > 0
    hits = [
        traj.solution.reason[i] for i, st in enumerate(traj.solution.status) if st == "collision"
    ]
    assert all(h.endswith("/surface") for h in hits)
    blocked = np.flatnonzero([st == "collision" for st in traj.solution.status])
    x = path.surface_points[blocked, 0]
    assert x.min() > 0.44 and x.max() < 0.56  # only under the slab (and its torch-radius rim)


def test_edges_give_a_preheat_and_a_run_out() -> None:
    path, cloud = _path(0.40, 0.60, (0.40, 0.60))  # the line crosses the whole plate
    assert path.info["ends"]["start"]["kind"] == "edge"
    traj = _plan(path, cloud, run_out_m=0.01)
    assert "preheat" in traj.phase and "pierce" not in traj.phase
    run = [k for k, p in enumerate(traj.phase) if p == "run_out"]
    assert run and all(traj.setpoint[k] < 0 for k in run)
    last_tip = path.positions[-1]
    end = traj.tool_poses[run[-1], :3, 3]
    assert np.linalg.norm(end - last_tip) == pytest.approx(0.01, abs=1e-3)
    assert traj.summary["finish"] == "run_out" and traj.summary["run_out_m"] == pytest.approx(0.01)


def test_trajectory_files_round_trip(
    plate_cut: tuple[CuttingPath, Trajectory], tmp_path: Path
) -> None:
    _, traj = plate_cut
    data = trajectory_to_dict(
        traj,
        source={"path_file": "p.json"},
        limits=panda_limits(),
        config={},
        urdf="u",
        created="2026-01-01T00:00:00+00:00",
    )
    target = tmp_path / "traj.json"
    write_trajectory_file(target, data)
    back = read_trajectory_file(target)
    np.testing.assert_array_equal(back.t, traj.t)
    np.testing.assert_array_equal(back.positions, traj.positions)
    np.testing.assert_array_equal(back.setpoint, traj.setpoint)
    assert back.phase == traj.phase and back.base_frame == "panda_link0"
    np.testing.assert_allclose(back.T_flange_tool, default_mount().T_flange_tool, atol=1e-12)
    for key in ("robot", "base_frame", "joint_names", "T_flange_tool", "points", "summary"):
        assert key in back.data
    write_trajectory_csv(traj, tmp_path / "traj.csv")
    rows = (tmp_path / "traj.csv").read_text().splitlines()
    assert len(rows) == len(traj) + 1 and rows[0].startswith("t_s,setpoint,phase,q1")
    write_trajectory_mcap(tmp_path / "traj.mcap", traj)
    from mcap.reader import make_reader

    with (tmp_path / "traj.mcap").open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    counts = {
        summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()
    }
    assert counts == {
        "/scrapcut/joint_trajectory": 1,
        "/scrapcut/tcp_path": 1,
        "/joint_states": len(traj),
    }


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.update(schema="x"), "schema"),
        (lambda d: d["points"][3].update(t_s=d["points"][2]["t_s"]), r"points\[3\].t_s"),
        (lambda d: d["points"][1].update(positions=[0.0] * 6), "rows of 7"),
        (lambda d: d["points"][1].update(setpoint=-2), "setpoint"),
        (lambda d: d.pop("joint_names"), "joint_names"),
    ],
)
def test_bad_trajectory_files_are_refused_with_the_key_named(
    plate_cut: tuple[CuttingPath, Trajectory], tmp_path: Path, edit: object, message: str
) -> None:
    _, traj = plate_cut
    data = trajectory_to_dict(traj, source={}, limits=panda_limits(), config={}, urdf="u")
    edit(data)  # type: ignore[operator]
    target = tmp_path / "bad.json"
    write_trajectory_file(target, data)
    with pytest.raises(MotionError, match=message):
        read_trajectory_file(target)


def test_the_move_between_two_cuts_goes_around_a_fin_between_them() -> None:
    """A fin standing across the line splits the cut in two; the straight joint-space move
    between the cuts would sweep the torch through it: the transit goes around (or over) it,
    as Franka's DH forward kinematics of the sampled points confirms."""
    path, cloud = _path(0.40, 0.60, (0.30, 0.70))
    top = PLATE_Z + 0.2
    fin = surface_patch((0.50, -0.1, PLATE_Z), (0.0, 0.2, 0.0), (0.0, 0.0, 0.2), spacing_m=0.004)
    traj = _plan(path, np.vstack([cloud, fin]))
    s = traj.summary
    assert s["cut_segments"] == 2 and s["transits_around_obstacles"] == 1
    assert s["trajectory_collisions"] == 0 and s["limits_ok"]
    transit = np.flatnonzero(np.array(traj.phase) == "transit")
    t = traj.t[transit[0] : transit[-1] + 1]
    q = traj.positions[transit[0] : transit[-1] + 1]
    fine = np.arange(t[0], t[-1], 0.005)
    q_fine = np.column_stack([np.interp(fine, t, q[:, j]) for j in range(7)])
    tips = _dh_tool(q_fine)[:, :3, 3]
    cross = np.flatnonzero(np.diff(np.sign(tips[:, 0] - 0.50)) != 0)
    assert len(cross) >= 1  # it does get to the other side
    clear = ToolpathConfig().torch_radius_m
    for i in cross:  # beside the fin's ends or above its top, never through it
        assert abs(tips[i, 1]) > 0.1 + clear or tips[i, 2] > top + clear, tips[i]
