"""Tests of scrapcut_cli.evaluation.reproduce that need no simulation: options, checks, config.

The end-to-end run (simulate → fit → eval) is tested in tests/test_commands_reproduce.py.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from scrapcut_cli.config import ScrapcutConfig, load_config
from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.evaluation.reproduce import (
    PAPER_OBJECTS,
    REAL_ROBOT_OBJECTS,
    config_to_toml,
    machine_description,
    reproduce,
    resolve_objects,
)


def test_objects_default_to_the_papers_five_and_all_adds_the_robot_shapes() -> None:
    assert resolve_objects([]) == PAPER_OBJECTS
    assert resolve_objects(["all"]) == PAPER_OBJECTS + REAL_ROBOT_OBJECTS
    assert resolve_objects(["basket", "cylinder", "basket"]) == ("basket", "cylinder")
    with pytest.raises(EvaluationError, match=r"unknown object 'teapot'; known: .*cylinder"):
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
    with pytest.raises(EvaluationError, match="is not a scrapcut reproduce output"):
        reproduce(precious, objects=["cylinder"], methods=["nurbs"], config=ScrapcutConfig())
    assert (precious / "chapter1.tex").read_text() == "..."
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    with pytest.raises(EvaluationError, match="is not a folder"):
        reproduce(a_file, objects=["cylinder"], methods=["nurbs"], config=ScrapcutConfig())


def test_bad_options_fail_before_any_work(tmp_path: Path) -> None:
    out = tmp_path / "out"
    explore = ScrapcutConfig().override("sim", mode="survey")
    with pytest.raises(EvaluationError, match="unknown mode 'survey'"):
        reproduce(out, objects=["cylinder"], methods=["nurbs"], config=explore)
    with pytest.raises(EvaluationError, match="jobs must be at least 1"):
        reproduce(out, objects=["cylinder"], methods=["nurbs"], config=ScrapcutConfig(), jobs=0)
    # Before, an infinite leaf passed the check and reached scipy after the scan (a traceback).
    with pytest.raises(EvaluationError, match="leaf sizes must be positive"):
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


@pytest.mark.slow
def test_two_jobs_run_objects_in_processes_with_one_progress_stream(tmp_path: Path) -> None:
    config = ScrapcutConfig().override("sim", width=160, height=120)
    events: list[tuple[str, str, int, int]] = []
    result = reproduce(
        tmp_path / "out",
        objects=["planar_box", "cylinder"],
        methods=["nurbs"],
        config=config,
        jobs=2,
        plots=False,
        progress=lambda *event: events.append(event),
    )
    assert [run.object for run in result.runs] == ["planar_box", "cylinder"]  # task order
    assert all(row.error is not None for row in result.rows)
    for name in ("planar_box", "cylinder"):
        stages = [stage for obj, stage, _, _ in events if obj == name]
        assert stages[0] == "record" and "stitch" in stages and stages[-1] == "done"
    assert (tmp_path / "out" / "paths" / "planar_box_nurbs.json").is_file()


class _FakeFit:
    """What ``toolpath.recipe.fit_stitched`` returns, reduced to what reproduce uses."""

    def __init__(self, points: np.ndarray, method: str, params: dict[str, float]) -> None:
        self.points, self.method, self.params = points, method, params

    def to_path_dict(self) -> dict[str, object]:
        return {
            "schema": "scrapcut.path/v1",
            "source": {"path": "../recordings/x.mcap"},
            "frame_id": "panda_link0",
            "units": "m",
            "method": {"name": self.method, "params": self.params},
            "curve": {"points": self.points.tolist()},
            "path": {"standoff_m": 0.008, "spacing_m": 0.005, "setpoints": []},
        }


@pytest.mark.parametrize(
    ("method", "breaks_below_m", "label", "note", "failure"),
    [
        ("skeleton", 0.010, "skeleton 20 mm", "5 mm leaf broke (broken into 3 pieces at 5 mm)"
         "; retried at 20 mm", None),
        ("skeleton", 0.030, "skeleton 20 mm", "5 mm leaf broke", "broken into 3 pieces at 20 mm"),
        ("nurbs", 1.0, "nurbs", "", "broken into 3 pieces at 5 mm"),
    ],
)  # fmt: skip
def test_a_broken_skeleton_is_retried_once_at_the_larger_leaf(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    method: str,
    breaks_below_m: float,
    label: str,
    note: str,
    failure: str | None,
) -> None:
    from scrapcut_cli.errors import FittingError
    from scrapcut_cli.evaluation import reproduce as rp
    from scrapcut_cli.evaluation.sources import Reference
    from scrapcut_cli.toolpath import recipe

    reference = np.column_stack([np.linspace(0, 0.3, 31), np.zeros(31), np.zeros(31)])

    def fake_fit(stitched: object, *, method: str, config: ScrapcutConfig) -> _FakeFit:
        leaf = config.skeleton.leaf_size_m
        if leaf < breaks_below_m:
            raise FittingError(f"broken into 3 pieces at {leaf * 1000:g} mm; try --leaf-size")
        params = {"leaf_size_m": leaf} if method == "skeleton" else {}
        return _FakeFit(reference + np.array([0.0, 0.002, 0.0]), method, params)

    monkeypatch.setattr(recipe, "fit_stitched", fake_fit)
    (tmp_path / "paths").mkdir()
    row = rp._fit_and_evaluate(
        "basket",
        method,
        object(),  # type: ignore[arg-type]
        Reference(points=reference, origin=tmp_path / "x.mcap", object="basket"),
        config=ScrapcutConfig(),
        out_dir=tmp_path,
        retry_leaf_size_m=0.020,
    )
    assert row.label == label
    assert row.note.startswith(note)
    if failure is None:
        assert row.failure is None and row.error is not None
        assert row.error.mean_m == pytest.approx(0.002, abs=1e-12)
        assert row.source == "paths/basket_skeleton.json"
    else:
        assert row.error is None and row.failure is not None and failure in row.failure


def test_a_path_that_cannot_be_measured_is_a_failed_row(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A curve collapsed to one point fits but cannot be measured: the row fails, the run goes
    # on (before, the EvaluationError escaped and aborted every object).
    from scrapcut_cli.evaluation import reproduce as rp
    from scrapcut_cli.evaluation.sources import Reference
    from scrapcut_cli.toolpath import recipe

    reference = np.column_stack([np.linspace(0, 0.3, 31), np.zeros(31), np.zeros(31)])

    def fake_fit(stitched: object, *, method: str, config: ScrapcutConfig) -> _FakeFit:
        return _FakeFit(np.zeros((5, 3)), method, {})

    monkeypatch.setattr(recipe, "fit_stitched", fake_fit)
    (tmp_path / "paths").mkdir()
    row = rp._fit_and_evaluate(
        "cylinder",
        "nurbs",
        object(),  # type: ignore[arg-type]
        Reference(points=reference, origin=tmp_path / "x.mcap", object="cylinder"),
        config=ScrapcutConfig(),
        out_dir=tmp_path,
        retry_leaf_size_m=0.020,
    )
    assert row.error is None
    assert row.failure is not None and "fitted curve needs at least two distinct points" in (
        row.failure
    )


def test_drain_waits_for_messages_a_finished_worker_has_not_flushed_yet() -> None:
    # A process pool's future can complete before the worker's feeder thread has put its last
    # progress messages on the queue; the drain must wait for the worker's _END, not stop at
    # the first empty read.
    import queue
    import threading

    from scrapcut_cli.evaluation import reproduce as module

    events: queue.Queue[tuple[str, str, int, int]] = queue.Queue()
    seen: list[tuple[str, str, int, int]] = []

    def late_worker() -> None:
        time.sleep(0.3)
        events.put(("cylinder", "done", 1, 1))
        events.put(module._END)

    threading.Thread(target=late_worker).start()
    assert module._drain(events, lambda *e: seen.append(e)) == 0  # nothing there yet
    assert module._drain(events, lambda *e: seen.append(e), timeout_s=5.0) == 1
    assert seen == [("cylinder", "done", 1, 1)]
    assert module._drain(events, lambda *e: seen.append(e), timeout_s=0.05) == -1
