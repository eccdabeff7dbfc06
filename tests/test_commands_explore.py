"""``scrapcut explore`` through click's CliRunner: replay, divergence, what-if, errors.

The recordings are the exploration tests' pipe scene written as MCAP (no simulator); the
simulator's own closed loop is exercised end to end at the bottom (small images).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from exploration_scenes import (
    REACH_ALL,
    CylinderScan,
    LoopResult,
    explore,
    write_exploration_recording,
)
from helpers import one_line_error
from perception_scenes import top_view

from scrapcut_cli.cli import cli
from scrapcut_cli.exploration.planner import ExplorationPlanner
from scrapcut_cli.perception.paint import PAINT_PRESETS


def _run(*args: object) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def explored(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, LoopResult]:
    scan = CylinderScan()
    planner = ExplorationPlanner(
        scan.initial_view, reachable=REACH_ALL, hsv=PAINT_PRESETS["orange"].hsv
    )
    loop = explore(planner, scan)
    path = tmp_path_factory.mktemp("explore") / "explored.mcap"
    write_exploration_recording(path, loop.frames, loop.log, reference=scan.reference)
    return path, loop


def test_replay_prints_the_steps_and_verifies_them(explored: tuple[Path, LoopResult]) -> None:
    """The replay's global fit is measured against the reference: on this pipe (160 × 120 px,
    0.5 mm depth noise) it gives 0.35 mm mean and 0.8 mm max; the margins are about 3×."""
    path, loop = explored
    result = _run("explore", path)
    assert result.exit_code == 0, result.output
    assert "matches the log" in result.stdout
    assert "verdict: the replay matches the log" in result.stderr
    assert "coverage 100.0 %" in result.stdout
    for word in ("extrapolate", "return", "done"):
        assert word in result.stdout
    data = json.loads(_run("explore", path, "--json").stdout)
    assert data["schema"] == "scrapcut.explore/v1" and data["tool_version"]
    assert data["matches_log"] is True and data["mode"] == "replay"
    assert data["views"] == len(loop.frames) and data["endpoints_found"] == 2
    assert data["error"]["coverage"] >= 0.95
    assert data["error"]["mean_mm"] < 1.0 and data["error"]["max_mm"] < 2.5
    assert data["error"]["reverse_max_mm"] < 2.5  # no stray branch either
    assert [s["growth"] for s in data["steps"]] == [e["growth"] for e in loop.log]


def test_a_divergence_is_a_verdict_with_exit_code_3(
    explored: tuple[Path, LoopResult], tmp_path: Path
) -> None:
    _, loop = explored
    log = json.loads(json.dumps(loop.log))
    log[1]["size"] += 5
    bad = tmp_path / "bad.mcap"
    write_exploration_recording(bad, loop.frames, log, reference=CylinderScan().reference)
    result = _run("explore", bad)
    assert result.exit_code == 3, result.output  # a finding, not an error (1)
    (line,) = [x for x in result.stderr.splitlines() if x.startswith("verdict:")]
    assert "diverged from the log" in line and "step 1: size" in line
    assert "Traceback" not in result.output and "error" not in result.stderr
    assert "differs" in result.stdout  # the table marks the step


def test_what_if_runs_other_parameters_over_a_dense_recording(tmp_path: Path) -> None:
    """The skeleton what-if on top views every 4 cm: 0.7 mm mean and 4.7 mm max error here
    (the skeleton's ends wander on the pipe's curvature); the margins are about 2×."""
    scan = CylinderScan()
    frames = [scan.capture(top_view(x, height_m=0.3)) for x in np.arange(-0.4, 0.401, 0.04)]
    path = tmp_path / "dense.mcap"
    write_exploration_recording(path, frames, [{}] * len(frames), reference=scan.reference)
    result = _run("explore", path, "--what-if", "--method", "skeleton", "--step-mm", "50", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["mode"] == "what_if" and data["method"] == "skeleton"
    assert data["config"]["exploration"]["step_m"] == pytest.approx(0.05)
    assert data["endpoints_found"] == 2 and data["views"] <= len(frames)
    assert data["error"]["coverage"] >= 0.9
    assert data["error"]["mean_mm"] < 1.5 and data["error"]["max_mm"] < 10.0
    table = _run("explore", path, "--what-if")
    assert (
        table.exit_code == 0
        and "what-if" in table.stdout
        and f"of {len(frames)} frames" in (table.stdout)
    )


def test_planner_options_need_what_if(explored: tuple[Path, LoopResult]) -> None:
    path, _ = explored
    result = _run("explore", path, "--delta-size", "5")
    assert result.exit_code == 2
    assert "--what-if" in result.stderr


def test_known_errors_are_one_line(explored: tuple[Path, LoopResult], tmp_path: Path) -> None:
    path, loop = explored
    line = one_line_error(_run("explore", path, "--method", "skeleton"))
    assert "explored with nurbs" in line
    bare = tmp_path / "bare.mcap"
    write_exploration_recording(bare, loop.frames[:1], [{}])
    assert "no exploration log" in one_line_error(_run("explore", bare))
    assert "recording not found" in one_line_error(_run("explore", tmp_path / "missing.mcap"))


@pytest.mark.slow
@pytest.mark.parametrize(("obj", "method"), [("slanted", "nurbs"), ("i_beam", "skeleton")])
def test_simulated_exploration_end_to_end(tmp_path: Path, obj: str, method: str) -> None:
    """`scrapcut record --mode explore` drives the Panda with the planner from the worker's
    start, planning only with what the camera observed; the run never touches the true piece,
    finds both ends, and `scrapcut explore` replays it decision for decision. The path error is
    guarded: 0.28 mm mean and 1.2 mm max (slanted, nurbs), 0.34 and 1.6 mm (i_beam, skeleton)
    at 160 x 120 px; the margins are about 3x."""
    from scrapcut_cli.recording.reader import open_recording

    out = tmp_path / f"{obj}.mcap"
    args = ["--object", obj, "--mode", "explore", "--method", method]
    recorded = _run("record", *args, "--width", 160, "--height", 120, "-o", out)
    assert recorded.exit_code == 0, recorded.output
    with open_recording(out) as rec:
        result = rec.metadata["scrapcut_result"]
        log = rec.exploration_log()
    assert result["stop_reason"] == "done"
    assert result["collisions"] == "0"
    assert log[0]["method"] == method and log[-1]["reason"] == "done"
    replayed = _run("explore", out, "--json")
    assert replayed.exit_code == 0, replayed.output
    data = json.loads(replayed.stdout)
    assert data["matches_log"] is True
    assert data["endpoints_found"] == 2
    assert data["views"] == int(result["views"])
    assert data["error"]["coverage"] >= 0.95
    assert data["error"]["mean_mm"] < 1.0 and data["error"]["max_mm"] < 5.0


def test_output_writes_the_path_file_of_the_observed_frames(
    explored: tuple[Path, LoopResult], tmp_path: Path
) -> None:
    """The replay's path file is as good as scrapcut fit's on the same frames.

    Not identical: the replay uses the exact pose matrices the planner saw, `fit` re-composes
    them from /tf (~1e-16 apart), and this scene's straight-down views put points exactly on
    stitching voxel boundaries (1 mm depth steps, 2 mm voxels), so a few voxels change sides.
    """
    from scrapcut_cli.evaluation.metrics import path_error
    from scrapcut_cli.toolpath.pathfile import read_path_file

    path, loop = explored
    reference = CylinderScan().reference
    out = tmp_path / "explored.json"
    result = _run("explore", path, "-o", out, "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["output"] == str(out)
    summary = json.loads(result.stdout)
    # Issue 20: the error report beside the path file, the figures `scrapcut eval` computes.
    report = json.loads((tmp_path / "explored.error.json").read_text())
    again = _run("eval", out, "--format", "json")
    assert again.exit_code == 0, again.output
    (row,) = json.loads(again.stdout)["rows"]
    for key in ("mean_mm", "sd_mm", "min_mm", "max_mm", "coverage", "reverse_max_mm"):
        assert report[key] == pytest.approx(row[key], abs=1e-9), key
        assert summary["error"][key] == pytest.approx(row[key], abs=1e-9), key
    assert summary["error_report"] == str(tmp_path / "explored.error.json")
    curve, cutting, data = read_path_file(out)
    assert data["error_report"] == "explored.error.json"
    assert data["source"]["frames_used"] == len(loop.frames)
    assert data["source"]["path"] == str(path)
    assert data["method"]["name"] == "nurbs" and len(cutting) > 100
    fitted = tmp_path / "fitted.json"
    assert _run("fit", path, "--method", "nurbs", "-o", fitted).exit_code == 0
    fit_curve, fit_cutting, _ = read_path_file(fitted)
    ours, theirs = path_error(curve.points, reference), path_error(fit_curve.points, reference)
    assert ours.coverage >= 0.95 and theirs.coverage >= 0.95
    assert abs(ours.mean_m - theirs.mean_m) < 0.001
    assert abs(len(cutting) - len(fit_cutting)) <= 3


def test_a_replay_with_a_calibration_fits_its_frames_posed_with_it(
    explored: tuple[Path, LoopResult], tmp_path: Path
) -> None:
    """The decisions are checked with the poses the planner had; the global fit poses the same
    frames with the calibration: here 3 mm further along the optical axis, which looks down."""
    path, _ = explored
    cal = tmp_path / "cal.yaml"
    cal.write_text(
        "schema: scrapcut.calibration/v1\nmoving_frame: camera_link\n"
        "camera_frame: camera_optical\n"
        "T_moving_camera: {translation_m: [0, 0, 0.003], rotation_xyzw: [0, 0, 0, 1]}\n"
        "time_offset_s: 0.0\n"
    )
    plain, moved = tmp_path / "plain.json", tmp_path / "moved.json"
    assert _run("explore", path, "-o", plain).exit_code == 0
    result = _run("explore", path, "-o", moved, "--calibration", cal)
    assert result.exit_code == 0, result.output
    assert "matches the log" in result.stdout
    a = json.loads(plain.read_text())
    b = json.loads(moved.read_text())
    assert "calibration" not in a and b["calibration"]["origin"] == str(cal)
    za = np.array(a["curve"]["points"])[:, 2]
    zb = np.array(b["curve"]["points"])[:, 2]
    assert np.median(zb) - np.median(za) == pytest.approx(-0.003, abs=0.0005)
