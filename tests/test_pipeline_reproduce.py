"""Tests of scrapcut_cli.pipeline.reproduce: options, checks, config, and seeds (inline engine).

The end-to-end command (simulate → fit → eval) is tested in tests/test_commands_reproduce.py.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from scrapcut_cli.config import ScrapcutConfig, load_config
from scrapcut_cli.errors import ConfigError, PipelineError
from scrapcut_cli.pipeline.engine import INLINE, Engine
from scrapcut_cli.pipeline.reproduce import (
    DEFAULT_OBJECTS,
    PAPER_OBJECTS,
    REAL_ROBOT_OBJECTS,
    config_to_toml,
    machine_description,
    parse_seeds,
    reproduce,
    resolve_objects,
    seeds_text,
)


def test_objects_default_to_the_papers_five_and_all_adds_the_robot_shapes() -> None:
    assert resolve_objects([]) == DEFAULT_OBJECTS == (*PAPER_OBJECTS, "perforated_plate")
    assert resolve_objects(["all"]) == DEFAULT_OBJECTS + REAL_ROBOT_OBJECTS
    assert resolve_objects(["basket", "cylinder", "basket"]) == ("basket", "cylinder")
    with pytest.raises(PipelineError, match=r"unknown object 'teapot'; known: .*cylinder"):
        resolve_objects(["teapot"])


def test_config_toml_reads_back_as_the_same_config(tmp_path: Path) -> None:
    config = (
        ScrapcutConfig()
        .override("skeleton", leaf_size_m=0.02)
        .override("paint", hsv=(350.0, 20.0, 0.5, 0.3))
        .override("sim", noise="yard", seed=7)
    )
    path = tmp_path / "config.toml"
    path.write_text(config_to_toml(config))
    assert load_config(path) == config
    assert load_config(path).to_dict() == config.to_dict()


def test_refuses_to_replace_a_folder_that_is_not_a_reproduce_output(tmp_path: Path) -> None:
    precious = tmp_path / "thesis"
    precious.mkdir()
    (precious / "chapter1.tex").write_text("...")
    with pytest.raises(PipelineError, match="is not a scrapcut reproduce output"):
        reproduce(precious, objects=["cylinder"], methods=["nurbs"], config=ScrapcutConfig())
    assert (precious / "chapter1.tex").read_text() == "..."
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    with pytest.raises(PipelineError, match="is not a folder"):
        reproduce(a_file, objects=["cylinder"], methods=["nurbs"], config=ScrapcutConfig())


def test_bad_options_fail_before_any_work(tmp_path: Path) -> None:
    out = tmp_path / "out"
    explore = ScrapcutConfig().override("sim", mode="survey")
    with pytest.raises(PipelineError, match="unknown mode 'survey'"):
        reproduce(out, objects=["cylinder"], methods=["nurbs"], config=explore)
    with pytest.raises(PipelineError, match="no seeds given"):
        reproduce(out, objects=["cylinder"], methods=["nurbs"], config=ScrapcutConfig(), seeds=[])
    with pytest.raises(PipelineError, match="seeds must be non-negative"):
        reproduce(out, objects=["cylinder"], methods=["nurbs"], config=ScrapcutConfig(), seeds=[-1])
    with pytest.raises(ConfigError, match=r"sim\.seed = .* is outside"):
        reproduce(
            out, objects=["cylinder"], methods=["nurbs"], config=ScrapcutConfig(), seeds=[2**40]
        )
    # Before, an infinite leaf passed the check and reached scipy after the scan (a traceback).
    with pytest.raises(PipelineError, match="leaf sizes must be positive"):
        reproduce(
            out,
            objects=["cylinder"],
            methods=["skeleton"],
            config=ScrapcutConfig(),
            leaf_sweep_m=[0.005, float("inf")],
        )
    assert not out.exists()


def test_machine_description_names_cores_and_python() -> None:
    text = machine_description()
    assert "cores" in text and "Python 3." in text


def test_seeds_parse_ranges_and_lists() -> None:
    assert parse_seeds("0-4") == (0, 1, 2, 3, 4)
    assert parse_seeds("7") == (7,)
    assert parse_seeds("0-2, 10,1") == (0, 1, 2, 10)
    for bad, message in (("3-1", "backwards"), ("a-b", "look like"), ("-1", "look like"),
                         ("0-5000", "more than")):  # fmt: skip
        with pytest.raises(PipelineError, match=message):
            parse_seeds(bad)
    assert seeds_text([0]) == "seed 0"
    assert seeds_text([0, 1, 2]) == "seeds 0–2 (3)"
    assert seeds_text([0, 5]) == "seeds 0, 5 (2)"


def test_several_seeds_give_table1_with_intervals(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Three seeds through the inline engine, the scans replaced by curves 1, 2 and 3 mm off a
    straight reference: one row per seed, Table I as the mean ± the 95 % interval over them."""
    from pipeline_fakes import fake_scan

    from scrapcut_cli.pipeline import reproduce as module

    planned: list[module.ScanTask] = []

    def recording_fake(task: module.ScanTask) -> module.ScanRun:
        planned.append(task)
        return fake_scan(task)

    monkeypatch.setattr(module, "run_scan", recording_fake)
    progress: list[tuple[int, int, str]] = []
    with Engine(scheduler=INLINE) as engine:
        result = reproduce(
            tmp_path / "out",
            objects=["cylinder"],
            methods=["nurbs"],
            config=ScrapcutConfig().override("sim", mode="explore"),  # a scan per method
            seeds=[0, 1, 2],
            engine=engine,
            plots=False,
            progress=lambda *p: progress.append(p),
            motion=False,
        )
    assert [t.stem for t in planned] == [f"cylinder_nurbs_seed{s}" for s in (0, 1, 2)]
    assert [t.suffix for t in planned] == ["_seed0", "_seed1", "_seed2"]
    assert [p[:2] for p in progress] == [(1, 3), (2, 3), (3, 3)]
    assert [(run.object, run.seed) for run in result.runs] == [("cylinder", s) for s in (0, 1, 2)]
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert [r["seed"] for r in report["rows"]] == [0, 1, 2]
    (table,) = report["table1"]
    # Means 1, 2, 3 mm: mean 2, SD 1, t(0.975, 2 dof) = 4.303, half width 4.303 / sqrt(3).
    assert (table["runs"], table["failed"]) == (3, 0)
    assert table["mean_mm"] == pytest.approx(2.0, abs=1e-9)
    assert table["mean_mm_ci95"] == pytest.approx(4.3027 / 3**0.5, rel=1e-4)
    assert table["paper"]["mean_mm"] == 3.01
    markdown = (tmp_path / "out" / "report.md").read_text()
    assert "seeds 0–2 (3)" in markdown
    assert "| cylinder | nurbs | 3/3 | 2.00 ± 2.48 | 3.01 |" in markdown
    assert result.table_markdown in markdown.replace(
        "# Table I reproduced on the simulator\n\n", ""
    )


def test_self_calibrate_adds_a_row_beside_each_plain_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The option reaches every scan task, and Table I keeps the self-calibrated rows apart."""
    from pipeline_fakes import fake_scan

    from scrapcut_cli.pipeline import reproduce as module

    planned: list[module.ScanTask] = []

    def recording_fake(task: module.ScanTask) -> module.ScanRun:
        planned.append(task)
        return fake_scan(task)

    monkeypatch.setattr(module, "run_scan", recording_fake)
    with Engine(scheduler=INLINE) as engine:
        result = reproduce(
            tmp_path / "out",
            objects=["cylinder"],
            methods=["nurbs", "skeleton"],
            config=ScrapcutConfig().override("sim", mode="explore"),
            seeds=[0, 1],
            engine=engine,
            plots=False,
            self_calibrate=True,
        )
    assert len(planned) == 4 and all(t.self_calibrate for t in planned)
    assert len(result.rows) == 8
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["options"]["self_calibrate"] is True
    labels = [(t["label"], t["runs"]) for t in report["table1"]]
    assert labels == [
        ("nurbs", 2),
        ("nurbs, self-calibrated", 2),
        ("skeleton", 2),
        ("skeleton, self-calibrated", 2),
    ]
    # Seeds 0 and 1: plain rows 1 and 2 mm off (mean 1.5), self-calibrated 0.1 and 0.2 mm.
    assert [t["mean_mm"] for t in report["table1"]] == pytest.approx([1.5, 0.15] * 2, abs=1e-9)
    assert "| cylinder | nurbs, self-calibrated | 2/2 | 0.15 ± " in result.table_markdown


def test_self_calibrated_rows_refuse_a_configured_calibration(tmp_path: Path) -> None:
    config = ScrapcutConfig().override("calibration", self_calibrate=True)
    with pytest.raises(PipelineError, match="must not set calibration"):
        reproduce(tmp_path / "out", objects=["cylinder"], methods=["nurbs"], config=config,
                  self_calibrate=True)  # fmt: skip
    assert not (tmp_path / "out").exists()


def test_the_self_calibrated_note_says_what_the_scan_could_check() -> None:
    from scrapcut_cli.pipeline.reproduce import _calibration_note

    def record(consistent: bool, observable: list[bool]) -> dict[str, object]:
        flags = {"translation": observable[:3], "rotation": observable[3:6],
                 "time_offset": observable[6]}  # fmt: skip
        return {"consistent": consistent, "observable": flags}

    assert _calibration_note(record(False, [True] * 7)) == "calibration corrected"
    assert _calibration_note(record(True, [True] * 7)) == "calibration consistent"
    where = _calibration_note(record(True, [True] * 6 + [False]))
    assert where == "calibration consistent where observable"
    nothing = _calibration_note(record(True, [False] * 7))
    assert nothing == "calibration not observable: published kept"
