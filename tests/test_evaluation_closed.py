"""Closed references: the CSV marker, scoring as a loop, observed and unobserved arcs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.evaluation.metrics import path_error
from scrapcut_cli.evaluation.sources import loop_summary, read_reference_csv_loop

RADIUS = 0.075
TOTAL = 2 * np.pi * RADIUS


def circle(start_deg: float = 0.0, *, step_m: float = 0.001, ccw: bool = True) -> np.ndarray:
    """Vertices (N, 3) of the 150 mm circle in z = 0 once round, not repeating the first."""
    phi = np.radians(start_deg) + np.arange(0.0, 2 * np.pi, step_m / RADIUS) * (1 if ccw else -1)
    return np.column_stack([RADIUS * np.cos(phi), RADIUS * np.sin(phi), np.zeros_like(phi)])


def write_csv(path: Path, points: np.ndarray, *, head: str = "") -> Path:
    rows = "\n".join(",".join(f"{v:.9f}" for v in p) for p in points)
    path.write_text(f"{head}x,y,z\n{rows}\n", encoding="utf-8")
    return path


def test_csv_marks_a_loop_by_comment_or_by_repeating_the_first_point(tmp_path: Path) -> None:
    ring = circle(step_m=0.01)
    marked, closed = read_reference_csv_loop(
        write_csv(tmp_path / "a.csv", ring, head="# a cut-out\n# closed: true\n")
    )
    assert closed and len(marked) == len(ring)
    repeated, closed = read_reference_csv_loop(
        write_csv(tmp_path / "b.csv", np.vstack([ring, ring[:1]]))
    )
    assert closed and len(repeated) == len(ring)  # the repeated row dropped
    open_line, closed = read_reference_csv_loop(write_csv(tmp_path / "c.csv", ring[:20]))
    assert not closed and len(open_line) == 20
    bad = tmp_path / "d.csv"
    bad.write_text("# closed: true\nx,y,z\n1,2\n", encoding="utf-8")
    with pytest.raises(EvaluationError, match=r"d\.csv"):
        read_reference_csv_loop(bad)


def test_a_loop_is_scored_round_its_closing_segment_whatever_its_start_and_way() -> None:
    reference = circle()
    curve = circle(123.0, ccw=False) * (1 + 0.0005 / RADIUS)  # 0.5 mm outside
    error = path_error(curve, reference, curve_closed=True, reference_closed=True)
    assert abs(error.mean_m - 0.0005) < 5e-5
    assert error.coverage == 1.0
    assert abs(error.curve_length_m / error.reference_length_m - 1.0 - 0.0005 / RADIUS) < 1e-3
    assert abs(error.reference_length_m - TOTAL) < 1e-4
    # An open curve missing 40 degrees of the loop leaves that arc uncovered.
    phi = np.arange(0.0, np.radians(320.0), 0.001 / RADIUS)
    part = np.column_stack([RADIUS * np.cos(phi), RADIUS * np.sin(phi), np.zeros_like(phi)])
    partial = path_error(part, reference, reference_closed=True)
    missing = (np.radians(40.0) * RADIUS - 2 * 0.010) / TOTAL  # less the 10 mm threshold twice
    assert abs((1.0 - partial.coverage) - missing) < 0.01


@pytest.mark.parametrize("ccw", [True, False])
def test_unobserved_arcs_against_the_truth(ccw: bool) -> None:
    reference = circle()
    true_arc = (0.60 * TOTAL, 0.75 * TOTAL)
    # The curve: 0.4 mm off on observed arcs, 6 mm off on the unobserved one; it starts at 90
    # degrees and runs either way; it reports the arc 4 mm short at one end, 3 mm long at the
    # other.
    start_deg = 90.0
    curve = circle(start_deg, ccw=ccw)
    angle = np.mod(np.arctan2(curve[:, 1], curve[:, 0]), 2 * np.pi) * RADIUS
    inside = (angle >= true_arc[0]) & (angle <= true_arc[1])
    curve = curve * np.where(inside, 1 + 0.006 / RADIUS, 1 + 0.0004 / RADIUS)[:, None]
    a_ref, b_ref = true_arc[0] + 0.004, true_arc[1] + 0.003
    # Those ends as arc lengths along the curve (longer than the reference: it lies outside).
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])

    def at(s_ref: float) -> float:
        return float(along[int(np.argmin(np.abs((angle - s_ref + TOTAL / 2) % TOTAL - TOTAL / 2)))])

    reported = [(at(a_ref), at(b_ref))] if ccw else [(at(b_ref), at(a_ref))]
    # Set-points every 5 mm on the reference; the flag on most on the arc, 1 in 20 elsewhere.
    s = np.arange(0.0, TOTAL, 0.005)
    sp = np.column_stack([RADIUS * np.cos(s / RADIUS), RADIUS * np.sin(s / RADIUS), 0 * s])
    on = (s >= true_arc[0]) & (s <= true_arc[1])
    flags = on.copy()
    flags[np.flatnonzero(on)[::10]] = False
    flags[np.flatnonzero(~on)[::20]] = True
    error = path_error(
        curve,
        reference,
        curve_closed=True,
        reference_closed=True,
        true_unseen_arcs_m=[true_arc],
        reported_unobserved_m=reported,
        setpoints=sp,
        setpoint_unobserved=flags,
    )
    loop = error.loop
    assert loop is not None and loop.observed_from == "truth"
    assert abs(loop.observed_mean_m - 0.0004) < 5e-5  # type: ignore[operator]
    assert loop.observed_coverage == 1.0
    assert abs(loop.observed_share - 0.85) < 0.01
    assert error.mean_m > loop.observed_mean_m  # type: ignore[operator]
    assert loop.arcs_missed == 0
    assert abs(loop.extent_error_m - 0.004) < 0.0006  # type: ignore[operator]
    assert abs(loop.flagged_on_arcs - flags[on].mean()) < 1e-9  # type: ignore[operator]
    assert abs(loop.flagged_elsewhere - flags[~on].mean()) < 1e-9  # type: ignore[operator]
    text = loop_summary(error.summary_mm())
    assert text.startswith("closed; observed arcs (85 % of the loop)")
    assert (
        "ends within 4." in text
        and f"{100 * flags[on].mean():.0f} % of set-points on them flagged" in text
    )


def test_a_true_arc_nothing_reports_is_missed() -> None:
    reference = circle()
    error = path_error(
        reference,
        reference,
        curve_closed=True,
        reference_closed=True,
        true_unseen_arcs_m=[(0.1, 0.2)],
    )
    assert error.loop is not None
    assert error.loop.arcs_missed == 1 and error.loop.extent_error_m is None


def test_eval_scores_a_loop_path_against_a_closed_csv(tmp_path: Path) -> None:
    """``scrapcut eval`` end to end: a loop's path file and a CSV marked closed."""
    from click.testing import CliRunner

    from scrapcut_cli.cli import cli
    from scrapcut_cli.config import ToolpathConfig
    from scrapcut_cli.fitting.curve import Curve
    from scrapcut_cli.toolpath.pathfile import path_to_dict, write_path_file
    from scrapcut_cli.toolpath.setpoints import make_cutting_path

    ring = circle(200.0) * (1 + 0.0006 / RADIUS)  # 0.6 mm outside, starting elsewhere
    curve = Curve(points=ring, method="nurbs", spacing_m=0.001, closed=True)
    grid = np.mgrid[-0.1:0.1:0.004, -0.1:0.1:0.004].reshape(2, -1).T
    plate = np.column_stack([grid, np.zeros(len(grid))])
    path = make_cutting_path(
        curve, plate, plate + np.array([0.0, 0.0, 0.3]), config=ToolpathConfig()
    )
    data = path_to_dict(curve, path, source={}, method_params={}, config={}, frame_id="panda_link0")
    write_path_file(tmp_path / "ring.json", data)
    reference = write_csv(tmp_path / "ring.csv", circle(), head="# closed: true\n")
    result = CliRunner().invoke(
        cli,
        ["eval", str(tmp_path / "ring.json"), "--reference", str(reference), "--format", "json"],
        catch_exceptions=False,
    )
    assert result.exit_code == 0, result.output
    (row,) = json.loads(result.stdout)["rows"]
    assert row["closed"] is True and row["coverage"] == 1.0
    assert abs(row["mean_mm"] - 0.6) < 0.05
    assert row["observed_from"] == "all" and row["observed_share"] == 1.0
