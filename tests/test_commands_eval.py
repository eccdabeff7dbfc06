"""CLI tests of ``scrapcut eval``: formats, output files, --paper, --plot and errors."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import one_line_error

from scrapcut_cli.cli import cli

MM = 1e-3
REFERENCE = np.column_stack([np.linspace(0.3, 0.6, 31), np.zeros(31), np.full(31, 0.1)])


def write_path_file(path: Path, curve: np.ndarray, *, method: str, source: str | None) -> Path:
    data = {
        "schema": "scrapcut.path/v1",
        "source": {"path": source},
        "frame_id": "panda_link0",
        "units": "m",
        "method": {"name": method, "params": {}},
        "curve": {"points": np.asarray(curve).tolist()},
        "path": {"standoff_m": 0.008, "spacing_m": 0.005, "setpoints": []},
    }
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    ref = tmp_path / "ref.csv"
    ref.write_text(
        "x,y,z\n" + "\n".join(",".join(repr(float(v)) for v in p) for p in REFERENCE) + "\n"
    )
    nurbs = write_path_file(
        tmp_path / "cylinder.json",
        REFERENCE + np.array([0, 2 * MM, 0]),
        method="nurbs",
        source="a.mcap",
    )
    skel = write_path_file(
        tmp_path / "cylinder_skeleton.json",
        REFERENCE + np.array([0, 0, 3.5 * MM]),
        method="skeleton",
        source="a.mcap",
    )
    return {"ref": ref, "nurbs": nurbs, "skeleton": skel, "dir": tmp_path}


def run(*args: object) -> object:
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_json_to_stdout(files: dict[str, Path]) -> None:
    result = run("eval", files["nurbs"], files["skeleton"], "--reference", files["ref"],
                 "--object", "cylinder", "--format", "json")  # fmt: skip
    assert result.exit_code == 0, result.output  # type: ignore[attr-defined]
    data = json.loads(result.stdout)  # type: ignore[attr-defined]
    assert data["schema"] == "scrapcut.eval/v1" and data["tool_version"]
    rows = data["rows"]
    assert [(r["object"], r["method"]) for r in rows] == [
        ("cylinder", "nurbs"),
        ("cylinder", "skeleton"),
    ]
    assert rows[0]["mean_mm"] == pytest.approx(2.0, abs=1e-9)
    assert rows[1]["max_mm"] == pytest.approx(3.5, abs=1e-9)
    assert rows[1]["coverage"] == 1.0
    assert "paper" not in rows[0]


def test_json_with_paper_marks_what_is_worse(files: dict[str, Path]) -> None:
    result = run("eval", files["nurbs"], files["skeleton"], "--reference", files["ref"],
                 "--object", "cylinder", "--format", "json", "--paper")  # fmt: skip
    assert result.exit_code == 0, result.output  # type: ignore[attr-defined]
    nurbs, skel = json.loads(result.stdout)["rows"]  # type: ignore[attr-defined]
    assert nurbs["paper"]["mean_mm"] == 3.01
    assert nurbs["worse_than_paper"] == ["min_mm"]  # 2.00 vs 0.30
    assert skel["worse_than_paper"] == ["mean_mm", "min_mm"]  # 3.50 vs 3.10 and 0.45


def test_table_on_screen(files: dict[str, Path]) -> None:
    result = run("eval", files["nurbs"], "--reference", files["ref"], "--paper")
    assert result.exit_code == 0, result.output  # type: ignore[attr-defined]
    out = result.stdout  # type: ignore[attr-defined]
    assert "Path error" in out and "cylinder" in out and "2.00" in out


@pytest.mark.parametrize(
    ("suffix", "fmt"), [(".md", "markdown"), (".csv", "csv"), (".json", "json")]
)
def test_output_file_format_from_suffix(files: dict[str, Path], suffix: str, fmt: str) -> None:
    target = files["dir"] / "out" / f"report{suffix}"
    result = run("eval", files["nurbs"], files["skeleton"], "--reference", files["ref"],
                 "-o", target, "--parents")  # fmt: skip
    assert result.exit_code == 0, result.output  # type: ignore[attr-defined]
    text = target.read_text()
    if fmt == "markdown":
        assert text.startswith("| File | Object | Method | Mean [mm]")
    elif fmt == "csv":
        assert len(list(csv.DictReader(io.StringIO(text)))) == 2
    else:
        assert len(json.loads(text)["rows"]) == 2
    assert "cylinder" in result.stdout  # type: ignore[attr-defined]  # table still shown
    assert not list(target.parent.glob("*.tmp"))


def test_explicit_table_format_to_file(files: dict[str, Path]) -> None:
    target = files["dir"] / "report.txt"
    result = run("eval", files["nurbs"], "--reference", files["ref"], "--format", "table",
                 "-o", target)  # fmt: skip
    assert result.exit_code == 0, result.output  # type: ignore[attr-defined]
    text = target.read_text()
    assert "Mean" in text and "[mm]" in text and "2.00" in text and "cylinder" in text


def test_unknown_output_suffix_is_a_usage_error(files: dict[str, Path]) -> None:
    result = run("eval", files["nurbs"], "--reference", files["ref"], "-o", files["dir"] / "r.xyz")
    assert result.exit_code == 2
    assert "cannot tell the format" in result.output  # type: ignore[attr-defined]


def test_plot_dir(files: dict[str, Path]) -> None:
    plots = files["dir"] / "plots"
    result = run("eval", files["nurbs"], files["skeleton"], "--reference", files["ref"],
                 "--object", "cylinder", "--plot", plots, "--format", "csv")  # fmt: skip
    assert result.exit_code == 0, result.output  # type: ignore[attr-defined]
    assert sorted(p.name for p in plots.iterdir()) == [
        "error_along_cylinder.png",
        "paths_cylinder.png",
    ]


def test_coverage_option(files: dict[str, Path]) -> None:
    result = run("eval", files["skeleton"], "--reference", files["ref"], "--coverage-mm", "3",
                 "--format", "json")  # fmt: skip
    assert result.exit_code == 0, result.output  # type: ignore[attr-defined]
    (row,) = json.loads(result.stdout)["rows"]  # type: ignore[attr-defined]
    assert row["coverage"] == 0.0 and row["coverage_threshold_mm"] == pytest.approx(3.0)


def test_no_reference_is_one_line_and_exit_1(files: dict[str, Path]) -> None:
    line = one_line_error(run("eval", files["nurbs"]))  # names a.mcap, which does not exist
    assert "a.mcap was not found; pass --reference" in line


def test_not_a_path_file_is_one_line_and_exit_1(files: dict[str, Path]) -> None:
    bogus = files["dir"] / "bogus.json"
    bogus.write_text("[1, 2, 3]")
    line = one_line_error(run("eval", bogus, "--reference", files["ref"]))
    assert "bogus.json: path file: expected a JSON object" in line


def test_missing_path_file(files: dict[str, Path]) -> None:
    result = run("eval", files["dir"] / "nope.json", "--reference", files["ref"])
    assert result.exit_code == 1
    assert "path file not found" in result.stderr  # type: ignore[attr-defined]


def test_default_reference_is_the_recording_in_the_path_file(tmp_path: Path) -> None:
    from scrapcut_cli.recording.writer import McapWriter

    with McapWriter(tmp_path / "scan.mcap") as writer:
        writer.add_metadata("scrapcut", {"object": "air_chamber", "paint": "orange"})
        writer.write_path("/scrapcut/reference", 1_000_000_000, "panda_link0", REFERENCE)
    path = write_path_file(
        tmp_path / "p.json",
        REFERENCE + np.array([0, 3 * MM, 0]),
        method="nurbs",
        source="scan.mcap",
    )
    result = run("eval", path, "--format", "json", "--paper")
    assert result.exit_code == 0, result.output  # type: ignore[attr-defined]
    (row,) = json.loads(result.stdout)["rows"]  # type: ignore[attr-defined]
    assert (row["object"], row["method"]) == ("air_chamber", "nurbs")
    assert row["mean_mm"] == pytest.approx(3.0, abs=1e-6)
    assert row["paper"]["max_mm"] == 13.37
