"""``scrapcut trajectory`` and ``scrapcut simulate-cut`` end to end on the fixture recording.

The committed fixture (a simulated pipe, six views at 320x240) is fitted once; the trajectory
of its path is checked with Franka's DH parameters (helpers), independent of the planner's URDF
chain, and played in pybullet against the pipe's true mesh.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from helpers import one_line_error, panda_dh_flange
from test_docs import check_schema

from scrapcut_cli.cli import cli
from scrapcut_cli.geometry import quat_xyzw_to_matrix
from scrapcut_cli.toolpath.pathfile import read_path_file

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "sim_cylinder_small.mcap"


def _run(*args: object) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def planned(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict[str, object]]:
    folder = tmp_path_factory.mktemp("trajectory")
    path_file = folder / "path.json"
    result = _run("fit", FIXTURE, "--method", "nurbs", "-o", path_file)
    assert result.exit_code == 0, result.output
    traj = folder / "traj.json"
    result = _run(
        "trajectory", path_file, "--recording", FIXTURE, "-o", traj, "--csv", "--mcap", "--json"
    )
    assert result.exit_code == 0, result.output
    return path_file, traj, json.loads(result.stdout)


def test_the_fixtures_trajectory_reaches_every_setpoint_as_franka_dh_says(
    planned: tuple[Path, Path, dict[str, object]],
) -> None:
    path_file, traj_file, summary = planned
    _, path, _ = read_path_file(path_file)
    data = json.loads(traj_file.read_text())
    check_schema(data, "trajectory.schema.json")  # docs/ describes what is written
    assert data["schema"] == "scrapcut.trajectory/v1" and data["robot"] == "panda"
    assert data["base_frame"] == "panda_link0" and len(data["joint_names"]) == 7
    assert summary["schema"] == "scrapcut.trajectory_summary/v1" and summary["tool_version"]
    assert summary["executable"] and summary["reached"] == len(path)
    assert summary["observed_surface"].startswith("recording depth")
    assert summary["observed_points"] > 1000 and summary["trajectory_collisions"] == 0
    T_ft = np.eye(4)
    T_ft[:3, :3] = quat_xyzw_to_matrix(data["T_flange_tool"]["rotation_xyzw"])
    T_ft[:3, 3] = data["T_flange_tool"]["translation_m"]
    axes = quat_xyzw_to_matrix(path.orientations_xyzw)[:, :, 2]
    seen = set()
    for point in data["points"]:
        i = point["setpoint"]
        if i is None:
            continue
        seen.add(i)
        T = panda_dh_flange(point["positions"]) @ T_ft
        assert np.linalg.norm(T[:3, 3] - path.positions[i]) < 5e-4
        assert np.degrees(np.arccos(min(1.0, float(T[:3, 2] @ axes[i])))) < 1.0
    assert seen == set(range(len(path)))
    rows = traj_file.with_suffix(".csv").read_text().splitlines()
    assert len(rows) == len(data["points"]) + 1
    assert traj_file.with_suffix(".mcap").stat().st_size > 0


def test_simulate_cut_tracks_the_setpoints_without_touching_the_true_pipe(
    planned: tuple[Path, Path, dict[str, object]], tmp_path: Path
) -> None:
    _, traj_file, _ = planned
    report_file = tmp_path / "report.json"
    result = _run(
        "simulate-cut",
        traj_file,
        "--recording",
        FIXTURE,
        "--time-step-ms",
        "5",
        "--check-period-ms",
        "250",
        "-o",
        report_file,
        "--json",
    )
    assert result.exit_code == 0, result.output
    report = json.loads(report_file.read_text())
    assert report["piece"] == "cylinder" and report["collision_count"] == 0
    assert report["tip_error_mm"]["max"] < 0.5 and report["axis_error_deg"]["max"] < 1.0
    assert report["joint_margin_min_rad"] > 0.0
    # The torch works at the standoff: within 15 mm of the pipe, never touching it.
    assert 0.0 < report["clearance_mm"]["torch"] < 15.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["trajectory", "missing.json", "-o", "{out}"], "path file not found"),
        (["trajectory", "{path}", "-o", "{out}", "--tool-offset", "1,2"], "--tool-offset"),
        (["trajectory", "{path}", "-o", "{out}", "--urdf", "nope.urdf"], "cannot read URDF"),
        (
            ["trajectory", "{path}", "-o", "{out}", "--recording", "nope.mcap"],
            "recording not found",
        ),
        (["simulate-cut", "{path}", "--recording", str(FIXTURE)], "schema"),
    ],
)
def test_errors_are_one_line_and_leave_no_output(
    planned: tuple[Path, Path, dict[str, object]], tmp_path: Path, args: list[str], message: str
) -> None:
    path_file, _, _ = planned
    out = tmp_path / "t.json"
    argv = [a.format(path=path_file, out=out) for a in args]
    line = one_line_error(CliRunner().invoke(cli, argv))
    assert message in line
    assert not out.exists() and list(tmp_path.iterdir()) == []
