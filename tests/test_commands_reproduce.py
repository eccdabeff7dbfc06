"""CLI tests of ``scrapcut reproduce``: one small object end to end, and the known errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner, Result
from helpers import one_line_error

from scrapcut_cli.cli import cli
from scrapcut_cli.config import load_config


def run(*args: object) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def small_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Result]:
    """Cylinder and air chamber, both methods, at 320×240, a two-leaf sweep (about 10 s)."""
    out = tmp_path_factory.mktemp("reproduce") / "results"
    result = run("reproduce", "--objects", "cylinder,air_chamber", "--mode", "sweep",
                 "--width", 320, "--height", 240, "--scheduler", "inline",
                 "--leaf-sweep-mm", "5,20", "-o", out)  # fmt: skip
    return out, result


@pytest.mark.slow
def test_reproduce_writes_every_output(small_run: tuple[Path, Result]) -> None:
    out, result = small_run
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == [
        "config.json",
        "config.toml",
        "paths",
        "plots",
        "recordings",
        "report.csv",
        "report.json",
        "report.md",
    ]
    assert sorted(p.name for p in (out / "recordings").iterdir()) == [
        "air_chamber.mcap",
        "cylinder.mcap",
    ]
    assert sorted(p.name for p in (out / "plots").iterdir()) == [
        "error_along_air_chamber.png",
        "error_along_cylinder.png",
        "leaf_sweep_air_chamber.png",
        "leaf_sweep_cylinder.png",
        "paths_air_chamber.png",
        "paths_cylinder.png",
    ]
    assert (out / "paths" / "cylinder_skeleton_leaf20mm.json").is_file()
    assert not list(out.parent.glob(".results.*"))  # the temporary folder was renamed

    report = json.loads((out / "report.json").read_text())
    assert report["schema"] == "scrapcut.reproduce/v1"
    assert report["options"]["objects"] == ["cylinder", "air_chamber"]
    rows = {(r["object"], r["method"]): r for r in report["rows"]}
    assert sorted(rows) == [
        ("air_chamber", "nurbs"),
        ("air_chamber", "skeleton"),
        ("cylinder", "nurbs"),
        ("cylinder", "skeleton"),
    ]
    assert rows[("cylinder", "nurbs")]["paper"]["mean_mm"] == 3.01
    for row in rows.values():
        assert row["failure"] is None
        # The path follows the painted line over its whole length...
        assert row["coverage"] > 0.95
        assert 0.0 <= row["min_mm"] <= row["mean_mm"] <= row["max_mm"] < 10.0
        # ...and, the expectation for d435i sweeps, matches the paper on these two.
        assert row["worse_than_paper"] == [], (row["object"], row["method"])
    (scan,) = report["runs"][0]["scans"]
    assert scan["recording"] == "recordings/cylinder.mcap"
    assert scan["collisions"] == 0 and scan["views"] > 0
    # The leaf sweep: each object at 5 and 20 mm; 5 mm is the Table I skeleton row again.
    sweep = {(r["object"], r["leaf_size_mm"]): r for r in report["leaf_sweep"]}
    assert sorted(sweep) == [("air_chamber", 5.0), ("air_chamber", 20.0),
                             ("cylinder", 5.0), ("cylinder", 20.0)]  # fmt: skip
    assert sweep[("cylinder", 5.0)]["mean_mm"] == rows[("cylinder", "skeleton")]["mean_mm"]

    markdown = (out / "report.md").read_text()
    # A sweep's views follow the true line: its rows say so in every report.
    assert "scrapcut reproduce" in markdown and "| cylinder | nurbs (oracle views) |" in markdown
    assert "Skeleton leaf-size sweep" in markdown
    assert "| cylinder | skeleton 20 mm (oracle views) |" in markdown
    assert all(r["oracle_views"] and "oracle views" in r["label"] for r in report["rows"])
    assert "oracle_views" in (out / "report.csv").read_text().splitlines()[0]
    # Every path file comes with its error report, the row's own figures.
    error = json.loads((out / "paths" / "cylinder_nurbs.error.json").read_text())
    assert error["mean_mm"] == rows[("cylinder", "nurbs")]["mean_mm"]
    assert "cores" in markdown  # the machine the figures were measured on
    # The table on screen carries the paper's figures beside ours.
    assert "paper" in result.stdout and "3.01" in result.stdout
    # config.toml is a valid --config and holds the resolution used.
    config = load_config(out / "config.toml")
    assert (config.sim.width, config.sim.height) == (320, 240)


@pytest.mark.slow
def test_scrapcut_eval_gives_the_same_figures(small_run: tuple[Path, Result]) -> None:
    """The path files are ordinary ones: `scrapcut eval` on them reproduces the table."""
    out, _ = small_run
    rows = json.loads((out / "report.json").read_text())["rows"]
    row = next(r for r in rows if (r["object"], r["method"]) == ("cylinder", "nurbs"))
    result = run("eval", out / "paths" / "cylinder_nurbs.json", "--format", "json")
    assert result.exit_code == 0, result.output
    (again,) = json.loads(result.stdout)
    assert again["object"] == "cylinder"  # from the recording's metadata
    for key in ("mean_mm", "sd_mm", "min_mm", "max_mm", "coverage", "reverse_max_mm"):
        assert again[key] == pytest.approx(row[key], abs=1e-12)


def test_unknown_object_is_one_line(tmp_path: Path) -> None:
    line = one_line_error(run("reproduce", "--objects", "teapot", "-o", tmp_path / "out"))
    assert line.startswith("scrapcut: error: unknown object 'teapot'; known: cylinder")


def test_unknown_method_is_one_line(tmp_path: Path) -> None:
    line = one_line_error(run("reproduce", "--methods", "nurbs,spline", "-o", tmp_path / "out"))
    assert "unknown method 'spline'; known: nurbs, skeleton" in line


@pytest.mark.slow
def test_explore_mode_is_the_default_and_scans_once_per_method(tmp_path: Path) -> None:
    out = tmp_path / "explored"
    result = run("reproduce", "--objects", "cylinder", "--methods", "nurbs", "--width", 320,
                 "--height", 240, "--scheduler", "inline", "--no-plots", "-o", out)  # fmt: skip
    assert result.exit_code == 0, result.output
    report = json.loads((out / "report.json").read_text())
    assert report["options"]["mode"] == "explore"
    (scan,) = report["runs"][0]["scans"]
    assert scan["recording"] == "recordings/cylinder_nurbs.mcap"
    assert scan["stop_reason"] == "done"  # both ends found
    (row,) = report["rows"]
    assert row["failure"] is None and row["coverage"] > 0.95
    assert not (out / "plots").exists()


@pytest.mark.parametrize("sweep", ["2,x", "inf", "0,5"])
def test_a_bad_leaf_sweep_is_a_usage_error(tmp_path: Path, sweep: str) -> None:
    result = run("reproduce", "--objects", "cylinder", "--leaf-sweep-mm", sweep, "-o",
                 tmp_path / "out")  # fmt: skip
    assert result.exit_code == 2
    assert "expected positive millimetres" in result.stderr
    assert not (tmp_path / "out").exists()


def test_refuses_a_folder_that_is_not_a_reproduce_output(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("keep me")
    line = one_line_error(run("reproduce", "--objects", "cylinder", "-o", tmp_path))
    assert "is not a scrapcut reproduce output; choose another -o" in line
    assert (tmp_path / "notes.txt").read_text() == "keep me"
