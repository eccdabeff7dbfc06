"""scrapcut batch: inputs, manifests, grids, content keys, resume — and a real Dask cluster.

The recordings are the perception tests' painted pipe (160x120, four top views, its reference
on /scrapcut/reference): a run takes well under a second, so a batch of six is cheap. The
cluster is real: a ``dask scheduler`` and two ``dask worker`` processes on localhost, random
free ports (port 0, the address read from the scheduler file), stopped at the end.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from perception_scenes import cylinder_top_line, render_cylinder, small_camera, top_view
from perception_scenes import write_scene_recording as write_scene

from scrapcut_cli.cli import cli
from scrapcut_cli.config import ScrapcutConfig
from scrapcut_cli.errors import PipelineError
from scrapcut_cli.pipeline.batch import BatchResult, batch, plan_runs
from scrapcut_cli.pipeline.batch_inputs import (
    BatchInput,
    collect_inputs,
    content_hash,
    load_grid,
    read_manifest,
)
from scrapcut_cli.pipeline.engine import Engine

GRID = """
method = ["nurbs", "skeleton"]
[skeleton]
leaf_size_m = [0.005, 0.010]
[nurbs]
smoothness = [0.5, 1.0]
"""


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two small scans of the painted pipe (different lines) and a reference CSV."""
    folder = tmp_path_factory.mktemp("batch_inputs")
    camera = small_camera(160, 120)
    out = {}
    for name, length in (("pipe_a", 0.22), ("pipe_b", 0.18)):
        reference = cylinder_top_line(length_m=length)
        frames = [
            render_cylinder(camera, top_view(x, height_m=0.25), reference, index=i)
            for i, x in enumerate(np.linspace(-length / 2 + 0.03, length / 2 - 0.03, 4))
        ]
        write_scene(folder / f"{name}.mcap", frames, reference=reference)
        out[name] = folder / f"{name}.mcap"
        rows = "\n".join(",".join(repr(v) for v in p.tolist()) for p in reference[::10])
        (folder / f"{name}.csv").write_text("x,y,z\n" + rows + "\n")
        out[f"{name}_csv"] = folder / f"{name}.csv"
    return out


def _grid(tmp_path: Path, text: str = GRID) -> Path:
    path = tmp_path / "grid.toml"
    path.write_text(text)
    return path


# --------------------------------------------------------------------------- planning


def test_grid_axes_and_their_errors(tmp_path: Path) -> None:
    grid = load_grid(_grid(tmp_path))
    assert grid == {
        "method": ["nurbs", "skeleton"],
        "skeleton.leaf_size_m": [0.005, 0.010],
        "nurbs.smoothness": [0.5, 1.0],
    }
    assert load_grid(None) == {"method": ["nurbs"]}
    assert load_grid(None, methods=["skeleton"]) == {"method": ["skeleton"]}
    for text, message in (
        ('method = ["spline"]', "unknown method 'spline'"),
        ("[teapot]\nspout = [1]", r"unknown section \[teapot\]"),
        ("[nurbs]\nwiggle = [1]", "unknown parameter nurbs.wiggle"),
        ("[skeleton]\nleaf_size_m = [-1.0]", "skeleton.leaf_size_m"),
        ("[nurbs]\nsmoothness = []", "has no values"),
    ):
        with pytest.raises(PipelineError, match=message):
            load_grid(_grid(tmp_path, text))
    with pytest.raises(PipelineError, match="drop --methods"):
        load_grid(_grid(tmp_path), methods=["nurbs"])


def test_manifests_give_each_recording_its_paint_and_reference(
    recordings: dict[str, Path], tmp_path: Path
) -> None:
    a, b = recordings["pipe_a"], recordings["pipe_b"]
    csv_manifest = tmp_path / "scans.csv"
    csv_manifest.write_text(
        f"recording,paint,reference\n{a},orange,{recordings['pipe_a_csv']}\n{b},,\n"
    )
    first, second = read_manifest(csv_manifest)
    assert (first.recording, first.paint, first.reference) == (
        a,
        "orange",
        recordings["pipe_a_csv"],
    )
    assert (second.paint, second.reference) == (None, None)
    # TOML, relative to the manifest's folder; a manifest, a folder and a glob can be mixed.
    shutil.copy(a, tmp_path / "copy_a.mcap")
    toml_manifest = tmp_path / "scans.toml"
    toml_manifest.write_text('[[recording]]\npath = "copy_a.mcap"\nname = "first"\n')
    (entry,) = read_manifest(toml_manifest)
    assert entry.recording == tmp_path / "copy_a.mcap" and entry.name == "first"
    inputs = collect_inputs([str(toml_manifest), str(a.parent), str(tmp_path / "copy_*.mcap")])
    # The glob finds copy_a.mcap again: one input per recording (and paint and reference).
    assert [i.name for i in inputs] == ["first", "pipe_a", "pipe_b"]
    for bad, message in (
        ("recording,colour\nx.mcap,red\n", "unknown column"),
        ("recording\nmissing.mcap\n", "recording not found"),
        ("paint\norange\n", "must name a 'recording' column"),
    ):
        csv_manifest.write_text(bad)
        with pytest.raises(PipelineError, match=message):
            read_manifest(csv_manifest)
    with pytest.raises(PipelineError, match="no recording matches"):
        collect_inputs([str(tmp_path / "nothing_*.mcap")])


def test_runs_are_keyed_by_content_and_what_the_method_reads(
    recordings: dict[str, Path], tmp_path: Path
) -> None:
    copy = tmp_path / "renamed.mcap"
    shutil.copy(recordings["pipe_a"], copy)
    assert content_hash(copy) == content_hash(recordings["pipe_a"])
    grid = load_grid(_grid(tmp_path))
    runs = plan_runs(
        [BatchInput(recordings["pipe_a"], "pipe_a")],
        grid,
        config=ScrapcutConfig(),
        out_dir=tmp_path / "out",
    )
    # NURBS reads no leaf size and the skeleton no smoothness: 2 + 2 runs, not 2 x 2 x 2.
    points = sorted(
        (r.method, r.params.get("skeleton.leaf_size_m"), r.params.get("nurbs.smoothness"))
        for r in runs
    )
    assert points == [
        ("nurbs", None, 0.5),
        ("nurbs", None, 1.0),
        ("skeleton", 0.005, None),
        ("skeleton", 0.01, None),
    ]
    again = plan_runs(
        [BatchInput(copy, "renamed")], grid, config=ScrapcutConfig(), out_dir=tmp_path / "x"
    )
    assert sorted(r.key for r in again) == sorted(r.key for r in runs)  # same bytes, same runs
    other = plan_runs(
        [BatchInput(copy, "renamed", reference=recordings["pipe_a_csv"])],
        grid,
        config=ScrapcutConfig(),
        out_dir=tmp_path / "x",
    )
    assert not {r.key for r in other} & {r.key for r in runs}  # another reference: other runs


# --------------------------------------------------------------------------- worker processes

FAULT_PROBE = """
import resource
import numpy as np
from scrapcut_cli.pipeline.engine import _Guarded

def faults(rounds):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(rounds):
        block = np.ones(1 << 17)  # 1 MiB, as an image or a depth map
        del block
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before

print(faults(100), _Guarded(faults, on_worker=True)(100))
"""


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or not os.confstr("CS_GNU_LIBC_VERSION"),
    reason="glibc's allocator",
)
def test_tasks_on_a_worker_undo_the_nannys_malloc_setting() -> None:
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536: every 1 MiB block is
    then mapped afresh (a page fault per 4 KiB page). A task on a worker restores glibc's own
    thresholds first, so a block is reused. In a child process: mallopt is process-wide."""
    env = {**os.environ, "MALLOC_TRIM_THRESHOLD_": "65536"}
    out = subprocess.run(
        [sys.executable, "-c", FAULT_PROBE], env=env, capture_output=True, text=True, check=True
    )
    before, after = (int(n) for n in out.stdout.split())
    assert before > 100 * 200  # ~256 faults per block
    assert after < 100 * 20


# --------------------------------------------------------------------------- a real cluster


@pytest.fixture(scope="module")
def cluster(
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """``dask scheduler`` + two ``dask worker`` processes (no nanny: a kill is a real death)."""
    folder = tmp_path_factory.mktemp("dask")
    dask = str(Path(sys.executable).with_name("dask"))
    env = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    log = (folder / "cluster.log").open("wb")
    scheduler_file = folder / "scheduler.json"
    procs = [
        subprocess.Popen(
            [dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
             "--dashboard-address", ":0", "--scheduler-file", str(scheduler_file),
             "--idle-timeout", "600s"],
            stdout=log, stderr=subprocess.STDOUT, env=env,
        )
    ]  # fmt: skip
    try:
        deadline = time.monotonic() + 60.0
        while not scheduler_file.is_file() or not scheduler_file.read_text().strip():
            assert time.monotonic() < deadline, (folder / "cluster.log").read_text()
            assert procs[0].poll() is None, (folder / "cluster.log").read_text()
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        for i in range(2):
            procs.append(
                subprocess.Popen(
                    [dask, "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                     "--host", "127.0.0.1", "--name", f"w{i}", "--death-timeout", "60s"],
                    stdout=log, stderr=subprocess.STDOUT, env=env,
                )
            )  # fmt: skip
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        yield address, procs[1:]
    finally:
        for proc in procs:  # disposable: no graceful shutdown to wait for
            if proc.poll() is None:
                proc.kill()
            proc.wait()
        log.close()


def _eval_json(path: Path) -> dict[str, float]:
    result = CliRunner().invoke(cli, ["eval", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output
    (row,) = json.loads(result.stdout)["rows"]
    return dict(row)


@pytest.fixture(scope="module")
def finished(
    cluster: tuple[str, list[subprocess.Popen[bytes]]],
    recordings: dict[str, Path],
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, BatchResult]:
    """Two recordings × both methods, run on the cluster."""
    address, _ = cluster
    out = tmp_path_factory.mktemp("batch") / "out"
    inputs = collect_inputs([recordings["pipe_a"], recordings["pipe_b"]])
    grid = load_grid(None, methods=["nurbs", "skeleton"])
    with Engine(scheduler=address) as engine:
        result = batch(inputs, out_dir=out, grid=grid, config=ScrapcutConfig(), engine=engine,
                       plots=False)  # fmt: skip
    return out, result


def test_a_batch_runs_on_the_workers_of_a_dask_scheduler(
    cluster: tuple[str, list[subprocess.Popen[bytes]]], finished: tuple[Path, BatchResult]
) -> None:
    _, workers = cluster
    out, result = finished
    assert (result.ran, result.cached, result.lost, result.failed) == (4, 0, 0, 0)
    pids = {int(row["worker"].rsplit(":", 1)[1]) for row in result.rows}
    assert pids <= {w.pid for w in workers}  # ran on the cluster's workers, not here
    for row in result.rows:
        assert row["coverage"] > 0.9 and row["mean_mm"] < 3.0
        assert (out / "runs" / f"{row['key']}.json").is_file()
    # Issue 20: a run's error report holds the figures `scrapcut eval` computes.
    row = result.rows[-1]
    report = json.loads((out / "paths" / row["error_report"]).read_text())
    again = _eval_json(out / "paths" / row["path"])
    for key in ("mean_mm", "sd_mm", "min_mm", "max_mm", "coverage", "reverse_max_mm"):
        assert report[key] == pytest.approx(again[key], abs=1e-9)
        assert row[key] == pytest.approx(again[key], abs=1e-9)
    import pyarrow.parquet as pq

    table = pq.read_table(out / "batch.parquet").to_pylist()
    assert [r["key"] for r in table] == [r["key"] for r in result.rows]
    assert [r["mean_mm"] for r in table] == [r["mean_mm"] for r in result.rows]
    assert (out / "batch.csv").read_text().count("\n") == 5
    assert "### method" in (out / "report.md").read_text()


def test_a_finished_batch_does_no_work(
    finished: tuple[Path, BatchResult], recordings: dict[str, Path], tmp_path: Path
) -> None:
    out, result = finished
    inputs = collect_inputs([recordings["pipe_a"], recordings["pipe_b"]])
    grid = load_grid(None, methods=["nurbs", "skeleton"])
    # Every run is found finished, so no cluster is even contacted (this address is dead).
    with Engine(scheduler="tcp://127.0.0.1:9") as engine:
        again = batch(inputs, out_dir=out, grid=grid, config=ScrapcutConfig(), engine=engine,
                      plots=False)  # fmt: skip
    assert (again.ran, again.cached) == (0, 4)
    assert [r["mean_mm"] for r in again.rows] == [r["mean_mm"] for r in result.rows]
    # The command says so too, and refuses a folder that is no batch output.
    args = ["batch", str(recordings["pipe_a"]), str(recordings["pipe_b"]), "--methods",
            "nurbs,skeleton", "--scheduler", "tcp://127.0.0.1:9", "--no-plots"]  # fmt: skip
    rerun = CliRunner().invoke(cli, [*args, "-o", str(out)])
    assert rerun.exit_code == 0, rerun.output
    assert "4 run(s): 0 run now, 4 finished before, 0 failed" in rerun.stdout
    printed = CliRunner().invoke(cli, [*args, "-o", str(out), "--json"])
    assert printed.exit_code == 0, printed.output
    data = json.loads(printed.stdout)
    assert data["schema"] == "scrapcut.batch/v1" and data["tool_version"]
    assert (data["ran"], data["cached"], len(data["rows"])) == (0, 4, 4)
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "thesis.tex").write_text("keep")
    refused = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / "notes")])
    assert refused.exit_code == 1 and "not a scrapcut batch output" in refused.stderr
    assert (tmp_path / "notes" / "thesis.tex").read_text() == "keep"
    # With work to do, a dead address is one error and leaves no folder behind.
    with (
        Engine(scheduler="tcp://127.0.0.1:9", connect_timeout_s=0.5) as engine,
        pytest.raises(PipelineError, match="cannot reach the Dask scheduler"),
    ):
        batch(inputs, out_dir=tmp_path / "new", grid=grid, config=ScrapcutConfig(),
              engine=engine)  # fmt: skip
    assert not (tmp_path / "new").exists()


def test_killing_a_worker_mid_batch_loses_no_result(
    cluster: tuple[str, list[subprocess.Popen[bytes]]], recordings: dict[str, Path], tmp_path: Path
) -> None:
    address, workers = cluster
    out = tmp_path / "out"
    grid = load_grid(_grid(tmp_path))  # 2 recordings x 4 runs
    inputs = collect_inputs([recordings["pipe_a"], recordings["pipe_b"]])
    killed: list[int] = []

    def progress(done: int, total: int, last: str) -> None:
        if done == 1 and not killed:  # the first result is in: seven runs to go
            os.kill(workers[0].pid, signal.SIGKILL)
            killed.append(workers[0].pid)

    with Engine(scheduler=address) as engine:
        result = batch(inputs, out_dir=out, grid=grid, config=ScrapcutConfig(), engine=engine,
                       plots=False, progress=progress)  # fmt: skip
    assert killed and workers[0].wait(timeout=10) == -signal.SIGKILL
    assert len(result.rows) == 8 and result.lost == 0 and result.failed == 0
    assert all(row["status"] == "ok" for row in result.rows)
    assert len(list((out / "runs").glob("*.json"))) == 8  # every result saved
    survivors = {int(row["worker"].rsplit(":", 1)[1]) for row in result.rows}
    assert workers[1].pid in survivors
