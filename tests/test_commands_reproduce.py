"""CLI tests of ``scrapcut reproduce``: one small object end to end, and the known errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
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
        "report.html",
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
    # The same report as one page: tables rendered, all six figures embedded.
    page = (out / "report.html").read_text()
    assert page.count("<table>") == markdown.count("\n|---") and "<td>cylinder</td>" in page
    assert page.count('src="data:image/png;base64,') == 6 and "plots/" not in page
    # Every path file comes with its error report, the row's own figures.
    error = json.loads((out / "paths" / "cylinder_nurbs.error.json").read_text())
    assert error["mean_mm"] == rows[("cylinder", "nurbs")]["mean_mm"]
    assert "cores" in markdown  # the machine the figures were measured on
    # What the Panda can execute of each path (scrapcut trajectory), per object and method.
    assert "### What the Panda can execute" in markdown
    for row in rows.values():
        assert 0.0 <= row["panda_executable"] <= 1.0 and row["panda_setpoints"] > 0
        assert row["panda_limits_ok"] is True
    assert rows[("cylinder", "nurbs")]["panda_executable"] == 1.0
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
    (again,) = json.loads(result.stdout)["rows"]
    assert again["object"] == "cylinder"  # from the recording's metadata
    for key in ("mean_mm", "sd_mm", "min_mm", "max_mm", "coverage", "reverse_max_mm"):
        assert again[key] == pytest.approx(row[key], abs=1e-12)


def test_unknown_object_is_one_line(tmp_path: Path) -> None:
    line = one_line_error(run("reproduce", "--objects", "teapot", "-o", tmp_path / "out"))
    assert line.startswith("scrapcut: error: unknown object 'teapot'; known: cylinder")


def test_unknown_method_is_one_line(tmp_path: Path) -> None:
    line = one_line_error(run("reproduce", "--methods", "nurbs,spline", "-o", tmp_path / "out"))
    assert "unknown method 'spline'; known: nurbs, skeleton" in line


# --------------------------------------------------------------------------- guarded figures

#: Table I's fast configuration (`make guard-figures` regenerates its expected figures): explore
#: mode (the default), 160x120, seed 0; NURBS on two objects, the skeleton on two others. The
#: basket is left out: at 160x120 its paint on 3 mm wires does not survive the filter (its
#: figures are guarded by the 320x240 fit tests).
FAST = {"nurbs": "cylinder,t_piece", "skeleton": "i_beam,air_chamber"}
FAST_OPTIONS = ("--width", 160, "--height", 120, "--leaf-sweep-mm", "none", "--no-plots",
                "--no-motion", "--seeds", 0, "--scheduler", "inline")  # fmt: skip
#: A figure passes while within this factor of the committed one, plus this much: another CPU
#: (different views after a float changes a planner decision) moves them by far less; a
#: several-fold regression fails.
FACTOR, SLACK_MM = 1.5, 0.3
EXPECTED = Path(__file__).parents[1] / "fixtures" / "reproduce_fast.csv"


@pytest.fixture(scope="module")
def fast_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("fast")
    for method, objects in FAST.items():
        result = run("reproduce", "--objects", objects, "--methods", method, *FAST_OPTIONS,
                     "-o", folder / method, "--json")  # fmt: skip
        assert result.exit_code == 0, result.output
        printed = json.loads(result.stdout)  # --json prints report.json, nothing else
        assert printed["schema"] == "scrapcut.reproduce/v1" and printed["tool_version"]
        assert printed == json.loads((folder / method / "report.json").read_text())
    return {method: folder / method for method in FAST}


@pytest.mark.slow
def test_table1_figures_stay_within_a_margin_of_the_committed_ones(
    fast_runs: dict[str, Path],
) -> None:
    import csv

    with EXPECTED.open() as fh:
        expected = {(r["object"], r["method"]): r for r in csv.DictReader(fh)}
    rows = {}
    for out in fast_runs.values():
        rows.update({(r["object"], r["method"]): r for r in json.loads(
            (out / "report.json").read_text())["rows"]})  # fmt: skip
    assert sorted(rows) == sorted(expected)
    for key, row in rows.items():
        want = expected[key]
        assert row["failure"] is None, (key, row["failure"])
        for name in ("mean_mm", "max_mm"):
            bound = FACTOR * float(want[name]) + SLACK_MM
            assert row[name] <= bound, f"{key} {name} {row[name]:.2f} mm > {bound:.2f} mm"
        assert row["coverage"] >= float(want["coverage"]) - 0.02, key


@pytest.mark.slow
def test_explore_mode_is_the_default_and_scans_once_per_method(
    fast_runs: dict[str, Path],
) -> None:
    report = json.loads((fast_runs["nurbs"] / "report.json").read_text())
    assert report["options"]["mode"] == "explore"
    scans = [scan for run in report["runs"] for scan in run["scans"]]
    assert [s["recording"] for s in scans] == [
        "recordings/cylinder_nurbs.mcap",
        "recordings/t_piece_nurbs.mcap",
    ]
    assert all(s["stop_reason"] == "done" and s["collisions"] == 0 for s in scans)
    assert not any(r["oracle_views"] for r in report["rows"])  # explored: no oracle label
    assert not (fast_runs["nurbs"] / "plots").exists()


@pytest.mark.slow
def test_a_recording_stripped_of_every_truth_gives_the_same_path(
    fast_runs: dict[str, Path], tmp_path: Path
) -> None:
    """The blind test: without /scrapcut/reference, the exploration log and every metadata
    record (with --paint given), the fitted path is the same: no truth reaches the fit."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    from scrapcut_cli.toolpath.pathfile import read_path_file

    source = fast_runs["nurbs"] / "recordings" / "cylinder_nurbs.mcap"
    blind = tmp_path / "blind.mcap"
    dropped = {"/scrapcut/reference", "/scrapcut/exploration"}
    with source.open("rb") as fin, blind.open("wb") as fout:
        reader = make_reader(fin)
        header = reader.get_header()
        writer = Writer(fout)
        writer.start(profile=header.profile, library="scrapcut blind test")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        kept = 0
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.topic in dropped:
                continue
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)  # fmt: skip
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding,
                    schemas[schema.id] if schema is not None else 0, channel.metadata,
                )  # fmt: skip
            writer.add_message(channels[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)  # fmt: skip
            kept += 1
        writer.finish()  # no metadata records are written
    info = json.loads(run("info", blind, "--json").stdout)
    assert not info["has_reference"] and not info["has_exploration_log"] and kept > 10

    paths = {}
    for name, rec in (("original", source), ("blind", blind)):
        paths[name] = tmp_path / f"{name}.json"
        result = run("fit", rec, "--paint", "orange", "-o", paths[name], "--json")
        assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["error_status"] == "no reference: error not computed"
    (curve_a, path_a, _), (curve_b, path_b, _) = (read_path_file(p) for p in paths.values())
    np.testing.assert_array_equal(curve_a.points, curve_b.points)  # same process: same floats
    np.testing.assert_array_equal(path_a.positions, path_b.positions)
    np.testing.assert_array_equal(path_a.orientations_xyzw, path_b.orientations_xyzw)
    assert path_a.flags == path_b.flags


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


def test_readme_sections_are_rewritten_from_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`--readme` replaces exactly the marked section with the run's description and table."""
    from pipeline_fakes import fake_scan

    from scrapcut_cli.evaluation.report import replace_marked_section
    from scrapcut_cli.pipeline import reproduce as module

    monkeypatch.setattr(module, "run_scan", fake_scan)
    readme = tmp_path / "README.md"
    readme.write_text(
        "# Title\n\n<!-- scrapcut:table1 begin (generated: do not edit by hand) -->\nOLD TABLE\n"
        "<!-- scrapcut:table1 end -->\n\nkept text\n"
    )
    args = ["reproduce", "--objects", "cylinder", "--methods", "nurbs", "--seeds", "0-1",
            "--scheduler", "inline", "--no-plots", "--readme", readme]  # fmt: skip
    result = run(*args, "-o", tmp_path / "out")
    assert result.exit_code == 0, result.output
    text = readme.read_text()
    assert text.startswith("# Title\n\n<!-- scrapcut:table1 begin") and "OLD TABLE" not in text
    assert text.endswith("<!-- scrapcut:table1 end -->\n\nkept text\n")
    assert "- scans: explore mode, d435i noise, 640×480 px, seeds 0–1 (2)" in text
    assert "| cylinder | nurbs | 2/2 | 1.50 ± 6.35 | 3.01 |" in text  # 1 and 2 mm: t(1) = 12.71
    assert "- machine: " in text and "- date: " in text
    # Without the markers the command refuses before any work.
    line = one_line_error(run(*args, "--readme-section", "yard", "-o", tmp_path / "out2"))
    assert "scrapcut:yard begin" in line and not (tmp_path / "out2").exists()
    # The project's README has both sections `make readme` rewrites.
    project_readme = (Path(__file__).parents[1] / "README.md").read_text()
    for name in ("table1", "yard"):
        assert replace_marked_section(project_readme, name, "x").count("\nx\n") == 1
