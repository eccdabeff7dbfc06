"""``scrapcut eval`` catches mistakes: units, overlap, set-points, file labels, per-sample
results, rigid alignment, outputs that need --force / --parents (issue 18)."""

from __future__ import annotations

import json
import stat
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import one_line_error

from scrapcut_cli._io import _umask
from scrapcut_cli.cli import cli
from scrapcut_cli.geometry import make_transform, matrix_to_quat_xyzw, transform_points

MM = 1e-3
# A reference that is neither straight, nor a circle, nor a helix (each has rigid motions that
# map it onto itself), so a rigid alignment is fully observable: a quarter arc of 0.2 m radius
# rising quadratically by 40 mm, about 315 mm long.
_T = np.linspace(0.0, np.pi / 2, 200)
REFERENCE = np.column_stack(
    [0.3 + 0.2 * np.cos(_T), 0.2 * np.sin(_T), 0.1 + 0.04 * (_T / (np.pi / 2)) ** 2]
)


def setpoints_along(
    curve: np.ndarray, *, every: int = 5, flags: dict[int, list[str]] | None = None
) -> list[dict[str, Any]]:
    """Set-points on ``curve`` (surface point = the curve point), torch pointing down."""
    flags = flags or {}
    down = matrix_to_quat_xyzw(np.diag([1.0, -1.0, -1.0])).tolist()
    points = curve[::every]
    return [
        {
            "s": float(i),
            "position": (p + np.array([0, 0, 0.008])).tolist(),
            "orientation_xyzw": down,
            "normal": [0.0, 0.0, 1.0],
            "speed_m_s": 0.005,
            "t_s": float(i),
            "flags": flags.get(i, []),
            "surface_point": p.tolist(),
        }
        for i, p in enumerate(points)
    ]


def write_path(path: Path, curve: np.ndarray, setpoints: list[dict[str, Any]] | None = None,
               *, frame_id: str = "panda_link0", method: str = "nurbs") -> Path:  # fmt: skip
    data = {
        "schema": "scrapcut.path/v1",
        "source": {"path": None},
        "frame_id": frame_id,
        "units": "m",
        "method": {"name": method, "params": {}},
        "curve": {"points": np.asarray(curve).tolist()},
        "path": {
            "standoff_m": 0.008,
            "spacing_m": 0.005,
            "setpoints": setpoints_along(curve) if setpoints is None else setpoints,
        },
    }
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def write_reference(path: Path, points: np.ndarray) -> Path:
    rows = "\n".join(",".join(repr(float(v)) for v in p) for p in points)
    path.write_text("x,y,z\n" + rows + "\n", encoding="utf-8")
    return path


def run(*args: object) -> Any:
    return CliRunner().invoke(cli, [str(a) for a in args])


def eval_json(*args: object) -> tuple[list[dict[str, Any]], str]:
    result = run("eval", *args, "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["schema"] == "scrapcut.eval/v1"
    return data["rows"], result.stderr


@pytest.fixture
def ref(tmp_path: Path) -> Path:
    return write_reference(tmp_path / "ref.csv", REFERENCE)


def test_a_reference_in_millimetres_is_refused_and_named(tmp_path: Path) -> None:
    path = write_path(tmp_path / "cut.json", REFERENCE + np.array([0, 0, 2 * MM]))
    ref_mm = write_reference(tmp_path / "ref_mm.csv", REFERENCE * 1000.0)
    line = one_line_error(run("eval", path, "--reference", ref_mm))
    assert "reference" in line and "ref_mm.csv looks like millimetres" in line
    assert "divided by 1000 it lies 2.0 mm from the other" in line


def test_a_path_in_millimetres_is_refused_too(tmp_path: Path, ref: Path) -> None:
    path = write_path(tmp_path / "cut_mm.json", REFERENCE * 1000.0)
    line = one_line_error(run("eval", path, "--reference", ref))
    assert "path" in line and "cut_mm.json looks like millimetres" in line


def test_near_zero_coverage_and_far_length_ratio_are_warned(tmp_path: Path, ref: Path) -> None:
    # A third of the line, 50 mm beside it: coverage 0, length ratio ~0.33.
    far = write_path(tmp_path / "far.json", REFERENCE[:67] + np.array([0, 0, 0.05]))
    (row,), stderr = eval_json(far, "--reference", ref)
    assert row["coverage"] == 0.0
    assert any(w.startswith("coverage 0 %") for w in row["warnings"])
    assert any(w.startswith("length ratio 0.3") and "shorter" in w for w in row["warnings"])
    assert "warning: far.json: coverage 0 %" in " ".join(stderr.split())


def test_setpoints_are_scored_and_a_path_without_them_is_flagged(tmp_path: Path, ref: Path) -> None:
    curve = REFERENCE + np.array([0, 0, 1 * MM])
    full = write_path(tmp_path / "full.json", curve)
    empty = write_path(tmp_path / "empty.json", curve, setpoints=[])
    half = write_path(tmp_path / "half.json", curve, setpoints=setpoints_along(curve[:100]))
    flagged = write_path(
        tmp_path / "flagged.json",
        curve,
        setpoints=setpoints_along(curve, flags={3: ["tilted"], 4: ["tilted", "collision"]}),
    )
    rows, _ = eval_json(full, empty, half, flagged, "--reference", ref)
    by_file = {r["file"]: r for r in rows}
    # The curve is the same in all four: the Table I figures cannot tell them apart.
    assert len({round(r["mean_mm"], 9) for r in rows}) == 1
    mean = rows[0]["mean_mm"]
    assert mean == pytest.approx(1.0, abs=0.03)  # 1 mm up a slope of up to 14 deg
    assert by_file["full.json"]["setpoints"] == 40
    assert by_file["full.json"]["setpoint_mean_mm"] == pytest.approx(mean, abs=0.01)
    assert by_file["full.json"]["setpoint_coverage"] == 1.0
    assert by_file["full.json"]["warnings"] == []
    assert by_file["empty.json"]["setpoints"] == 0
    assert by_file["empty.json"]["setpoint_mean_mm"] is None
    assert by_file["empty.json"]["warnings"] == [
        "no set-points: the path file has a curve but nothing to cut"
    ]
    assert by_file["half.json"]["setpoint_coverage"] == pytest.approx(0.5, abs=0.05)
    assert "set-points are missing along the line" in by_file["half.json"]["warnings"][0]
    assert by_file["flagged.json"]["setpoints_flagged"] == 2
    assert by_file["flagged.json"]["setpoint_flags"] == {"collision": 1, "tilted": 2}
    assert by_file["flagged.json"]["warnings"] == [
        "2 of 40 set-points flagged (collision 1, tilted 2)"
    ]


def test_each_file_is_labelled_by_its_name(tmp_path: Path, ref: Path) -> None:
    paths = [
        write_path(tmp_path / f"t_piece_{k}.json", REFERENCE + np.array([0, k * MM, 0]))
        for k in range(4)
    ]
    result = run("eval", *paths, "--reference", ref, "--object", "t_piece")
    assert result.exit_code == 0, result.output
    for p in paths:
        assert p.name in result.stdout
    rows, _ = eval_json(*paths, "--reference", ref)
    assert sorted(r["file"] for r in rows) == sorted(p.name for p in paths)


def test_plot_colours_differ_per_file_of_one_method(tmp_path: Path, ref: Path) -> None:
    from scrapcut_cli.evaluation import plots
    from scrapcut_cli.evaluation.sources import evaluate_path_files

    paths = [
        write_path(tmp_path / f"p{k}.json", REFERENCE + np.array([0, k * MM, 0])) for k in range(4)
    ]
    rows = evaluate_path_files(paths, reference=ref)
    colours = [plots._colour(r, rows) for r in rows]
    assert len(set(colours)) == 4
    assert plots._legend(rows[0], rows).startswith("p0.json: nurbs")
    # Two methods, one file each: the methods' own colours, as in every other figure.
    two = evaluate_path_files(
        [
            paths[0],
            write_path(tmp_path / "s.json", REFERENCE, method="skeleton"),
        ],
        reference=ref,
    )
    assert {plots._colour(r, two) for r in two} == {"tab:blue", "tab:orange"}


def test_rmse_median_p95_of_a_linearly_growing_error() -> None:
    from scrapcut_cli.evaluation.metrics import path_error

    x = np.linspace(0.0, 0.4, 401)
    reference = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    # The curve leaves the line at 10 mm per metre: the error grows from 0 to 4 mm.
    curve = np.column_stack([x, 0.01 * x, np.zeros_like(x)])
    e = path_error(curve, reference)
    expected = 0.01 * x / np.sqrt(1.0 + 0.01**2)  # distance from (x, 0) to the tilted line
    assert e.rmse_m == pytest.approx(np.sqrt(np.mean(expected**2)), abs=1e-9)
    assert e.median_m == pytest.approx(2.0 * MM, abs=1e-6)
    assert e.p95_m == pytest.approx(3.8 * MM, abs=1e-6)
    summary = e.summary_mm()
    assert summary["rmse_mm"] == pytest.approx(1000.0 * e.rmse_m)


def test_save_results_writes_per_sample_errors(tmp_path: Path, ref: Path) -> None:
    path = write_path(tmp_path / "cut.json", REFERENCE + np.array([0, 0, 2 * MM]))
    out = tmp_path / "results"
    result = run("eval", path, "--reference", ref, "--save-results", out, "--align")
    assert result.exit_code == 0, result.output
    # The user's normal folder permissions (0755 under the usual umask 022), not mkdtemp's 0700.
    assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~_umask()
    assert sorted(p.name for p in out.iterdir()) == [
        "cut.errors.csv",
        "cut.errors.npy",
        "cut.setpoints.csv",
        "results.json",
    ]
    errors = np.load(out / "cut.errors.npy")
    (row,) = json.loads((out / "results.json").read_text())["rows"]
    assert len(errors) == row["samples"]
    assert 1000.0 * errors.mean() == pytest.approx(row["mean_mm"], abs=1e-9)
    lines = (out / "cut.errors.csv").read_text().splitlines()
    assert lines[0] == "# frame_id: panda_link0"
    assert lines[2] == "s,s_m,x,y,z,error_m,aligned_error_m"
    table = np.loadtxt(out / "cut.errors.csv", delimiter=",", comments="#", skiprows=3)
    np.testing.assert_allclose(table[:, 5], errors, atol=1e-15)
    assert table[-1, 0] == pytest.approx(1.0)
    setpoints = (out / "cut.setpoints.csv").read_text().splitlines()
    assert setpoints[2] == "index,x,y,z,error_m,flags" and len(setpoints) == 3 + 40
    # An existing folder is replaced only with --force.
    line = one_line_error(run("eval", path, "--reference", ref, "--save-results", out))
    assert "the folder exists; add --force to replace it" in line


def test_align_separates_calibration_from_shape_error(tmp_path: Path, ref: Path) -> None:
    # The fitted curve is the reference seen through a wrong calibration (1.5 deg, 4 mm).
    from scipy.spatial.transform import Rotation

    rotation = Rotation.from_euler("xyz", [0.5, -1.0, 1.0], degrees=True).as_matrix()
    T = make_transform(rotation, [0.004, -0.001, 0.001])
    centre = REFERENCE.mean(axis=0)
    moved = transform_points(T, REFERENCE - centre) + centre
    path = write_path(tmp_path / "cut.json", moved)
    (row,), _ = eval_json(path, "--reference", ref, "--align")
    assert row["mean_mm"] > 3.0  # the calibration error dominates the plain figure
    assert row["aligned_mean_mm"] < 0.05
    assert row["align_rotation_deg"] == pytest.approx(
        np.degrees(Rotation.from_matrix(rotation).magnitude()), abs=0.02
    )
    assert row["align_translation_mm"] == pytest.approx(np.linalg.norm([4, -1, 1]), abs=0.1)
    page = tmp_path / "report.html"
    result = run("eval", path, "--reference", ref, "--align", "--html", page)
    assert "shape error vs calibration error" in " ".join(result.stdout.split())
    # One page to share: the table, the alignment, both figures embedded (no other file).
    text = page.read_text()
    assert text.startswith("<!DOCTYPE html>") and "<td>cut.json</td>" in text
    assert "After rigid alignment" in text and text.count("<table>") == 2
    assert text.count('src="data:image/png;base64,') == 2 and "plots/" not in text


def test_umeyama_recovers_a_rigid_motion_and_a_straight_line_has_no_roll() -> None:
    from helpers import random_se3

    from scrapcut_cli.evaluation.align import align_curve, umeyama_rigid

    rng = np.random.default_rng(3)
    points = rng.normal(size=(50, 3))
    T = random_se3(4)
    np.testing.assert_allclose(umeyama_rigid(points, transform_points(T, points)), T, atol=1e-12)
    line = np.column_stack([np.linspace(0, 0.4, 50), np.zeros(50), np.zeros(50)])
    shifted = line + np.array([0.0, 0.003, 0.0])
    alignment = align_curve(shifted, line, sample_spacing_m=1e-3)
    assert alignment.straight
    assert alignment.rotation_deg == pytest.approx(0.0, abs=1e-9)
    assert alignment.translation_m == pytest.approx(0.003, abs=1e-9)


def test_outputs_need_force_to_replace_and_parents_to_create(tmp_path: Path, ref: Path) -> None:
    path = write_path(tmp_path / "cut.json", REFERENCE)
    report = tmp_path / "report.json"
    assert run("eval", path, "--reference", ref, "-o", report).exit_code == 0
    line = one_line_error(run("eval", path, "--reference", ref, "-o", report))
    assert "report.json: the file exists; add --force to replace it" in line
    assert run("eval", path, "--reference", ref, "-o", report, "--force").exit_code == 0
    deep = tmp_path / "no" / "such" / "report.json"
    line = one_line_error(run("eval", path, "--reference", ref, "-o", deep))
    assert "folder" in line and "does not exist (create it, or add --parents)" in line
    assert not (tmp_path / "no").exists()
    assert run("eval", path, "--reference", ref, "-o", deep, "--parents").exit_code == 0
    assert deep.is_file()


def test_eval_mcap_review_file_and_the_foxglove_layout(tmp_path: Path, ref: Path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from scrapcut_cli.toolpath.review import REVIEW_TOPICS

    flags = {2: ["tilted"], 7: ["collision"]}
    near = REFERENCE + np.array([0, 0, 1 * MM])
    paths = [
        write_path(tmp_path / "near.json", near, setpoints_along(near, flags=flags)),
        write_path(tmp_path / "far.json", REFERENCE + np.array([0, 0, 20 * MM])),
    ]
    out = tmp_path / "review.mcap"
    result = run("eval", *paths, "--reference", ref, "--mcap", out)
    assert result.exit_code == 0, result.output
    decoded = {}
    with out.open("rb") as fh:
        for _, channel, _, msg in make_reader(
            fh, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            decoded[channel.topic] = msg
    # No stitched clouds in a path file; two files: no single nav_msgs/Path curve.
    assert set(decoded) == set(REVIEW_TOPICS.values()) - {
        REVIEW_TOPICS["paint"],
        REVIEW_TOPICS["surface"],
        REVIEW_TOPICS["curve"],
    }
    lines = {m.ns: m for m in decoded[REVIEW_TOPICS["curve_error"]].markers}
    # 1 mm from the reference is green, 20 mm (beyond the 10 mm threshold) red.
    assert all(c.g > 0.75 and c.r < 0.25 for c in lines["near.json"].colors)
    assert all(c.r == 1.0 and c.g == 0.0 for c in lines["far.json"].colors)
    flagged = {m.ns: len(m.points) for m in decoded[REVIEW_TOPICS["flagged"]].markers}
    assert flagged == {"near.json/collision": 1, "near.json/tilted": 1}
    assert len(decoded[REVIEW_TOPICS["torch"]].markers) == 80

    # The layout shipped for Foxglove shows every review topic.
    layout = json.loads(
        (Path(__file__).parents[1] / "docs" / "foxglove_layout.json").read_text(encoding="utf-8")
    )
    panel = layout["configById"]["3D!scrapcut-review"]
    assert set(REVIEW_TOPICS.values()) <= set(panel["topics"])
    assert layout["layout"]["first"] == "3D!scrapcut-review"
