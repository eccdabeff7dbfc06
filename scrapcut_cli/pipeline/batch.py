"""``scrapcut batch``: recordings × a parameter grid → one table of runs and a report, on Dask.

A batch is the product of its *inputs* (recordings, each with an optional paint and reference)
and a *grid* (lists of values for the fitting method and any config key). Each combination is
one run: one :class:`~scrapcut_cli.pipeline.job.Job` (path file + error report), executed on the
batch engine (:class:`~scrapcut_cli.pipeline.engine.Engine`). Each run gives one row of the
table (recording, parameters, metrics, timings, failure), written as Parquet and CSV, and the
report aggregates the rows per parameter value, with one Fig. 3-style plot per numeric
parameter.

Runs are keyed by content: sha256 of the recording's bytes, the reference's bytes, the
configuration the run depends on (a NURBS run does not depend on the skeleton's leaf size, so
a grid over leaf sizes runs NURBS once) and the tool version. Each finished run is saved at once
(``runs/<key>.json``, atomically), so re-running a finished batch does no work, an interrupted
one resumes where it stopped, and a failed run (a ScrapcutError: no paint, a broken skeleton) is
recorded, not retried and not fatal. A run lost on the cluster (a worker died too often, a bug)
is in the table as ``lost`` but not saved: the next invocation runs it again.

Output folder::

    DIR/batch.parquet, DIR/batch.csv   one row per run (this invocation's plan)
    DIR/report.md, DIR/report.json     aggregates per parameter value, the batch's description
    DIR/plots/<parameter>.png          mean error against each numeric parameter, per method
    DIR/paths/<name>_<method>_<key>.json (+ .error.json, .error.md)   each run's path file
    DIR/runs/<key>.json                each finished run's row (the resume record)
    DIR/hashes.json                    recording hashes by size and mtime (skips re-hashing)

Inputs: recording files or ROS 2 bag folders; a folder of recordings; a glob (quoted, so the
shell leaves it alone); or a manifest — CSV with the header ``recording[,paint][,hsv]
[,reference][,name]`` or TOML with ``[[recording]]`` tables of those keys — whose relative paths
are relative to the manifest.

Grid (TOML)::

    method = ["nurbs", "skeleton"]
    [skeleton]
    leaf_size_m = [0.005, 0.010, 0.020]
    [nurbs]
    smoothness = [0.5, 1.0, 2.0]

Any section and key of :class:`~scrapcut_cli.config.ScrapcutConfig` can be a grid axis; a
scalar is a one-value axis.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import shutil
import socket
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scrapcut_cli import __version__
from scrapcut_cli._io import write_text_atomic
from scrapcut_cli.config import FitMethod, ScrapcutConfig, choice_names, config_from_dict
from scrapcut_cli.errors import PipelineError
from scrapcut_cli.pipeline.batch_inputs import METHOD_AXIS, BatchInput, content_hash, slug
from scrapcut_cli.pipeline.batch_report import write_report, write_table
from scrapcut_cli.pipeline.engine import Engine, TaskLost

#: Config sections a fit does not read: they never change a run's key.
NOT_FIT_SECTIONS = ("exploration", "sim")
#: Figures of the table and the report (mm, coverage a share 0–1).
METRICS = (
    "mean_mm",
    "sd_mm",
    "min_mm",
    "max_mm",
    "coverage",
    "reverse_mean_mm",
    "reverse_max_mm",
    "length_ratio",
    "curve_length_mm",
    "reference_length_mm",
)

ProgressFn = Callable[[int, int, str], None]


# --------------------------------------------------------------------------- runs


@dataclass(frozen=True)
class BatchRun:
    """One run of the batch: everything a worker needs (picklable, absolute paths).

    ``params`` are the grid axes' values for this run (None for an axis the method does not
    read, e.g. the leaf size of a NURBS run); ``config`` the full configuration as a dict.
    """

    key: str
    recording: str
    name: str
    method: str
    params: dict[str, Any]
    config: dict[str, Any]
    output: str
    reference: str | None
    evaluate: bool = True
    given: dict[str, Any] = field(default_factory=dict)


def plan_runs(
    inputs: Sequence[BatchInput],
    grid: dict[str, list[Any]],
    *,
    config: ScrapcutConfig,
    out_dir: Path,
    evaluate: bool = True,
    hashes: dict[str, str] | None = None,
) -> list[BatchRun]:
    """Every input × grid point, keyed by content; duplicates (same key) run once."""
    hashes = {} if hashes is None else hashes
    axes = list(grid)
    runs: dict[str, BatchRun] = {}
    out_dir = out_dir.resolve()
    for item in inputs:
        base = config
        if item.paint is not None:
            base = base.override("paint", preset=item.paint, hsv=None)
        if item.hsv is not None:
            from scrapcut_cli.commands._options import parse_hsv

            try:
                base = base.override("paint", hsv=parse_hsv(item.hsv))
            except Exception as exc:  # click's BadParameter: one line about the manifest
                raise PipelineError(f"{item.recording}: bad hsv {item.hsv!r} ({exc})") from None
        rec_hash = hashes.get(str(item.recording.resolve())) or content_hash(item.recording)
        ref_hash = None if item.reference is None else content_hash(item.reference)
        for values in itertools.product(*(grid[a] for a in axes)):
            point = dict(zip(axes, values, strict=True))
            method = str(point[METHOD_AXIS])
            run_config = base
            params: dict[str, Any] = {METHOD_AXIS: method}
            for axis, value in point.items():
                if axis == METHOD_AXIS:
                    continue
                section, _, name = axis.partition(".")
                if section in choice_names(FitMethod) and section != method:
                    params[axis] = None  # the other method's parameter: not read by this run
                    continue
                run_config = run_config.override(section, **{name: value})
                params[axis] = value
            relevant = {
                k: v
                for k, v in run_config.to_dict().items()
                if k not in NOT_FIT_SECTIONS and not (k in choice_names(FitMethod) and k != method)
            }
            key = run_key(rec_hash, method, relevant, ref_hash, evaluate)
            if key in runs:
                continue
            runs[key] = BatchRun(
                key=key,
                recording=str(item.recording.resolve()),
                name=item.name,
                method=method,
                params=params,
                config=run_config.to_dict(),
                output=str(out_dir / "paths" / f"{slug(item.name)}_{method}_{key[:12]}.json"),
                reference=None if item.reference is None else str(item.reference.resolve()),
                evaluate=evaluate,
                given={
                    "recording": str(item.recording),
                    "reference": None if item.reference is None else str(item.reference),
                    "paint": item.paint,
                    "hsv": item.hsv,
                    "recording_sha256": rec_hash,
                },
            )
    return list(runs.values())


def run_key(
    recording_sha256: str,
    method: str,
    config: dict[str, Any],
    reference_sha256: str | None,
    evaluate: bool,
) -> str:
    """sha256 of everything a run's result depends on, and the tool version."""
    blob = json.dumps(
        {
            "recording": recording_sha256,
            "method": method,
            "config": config,
            "reference": reference_sha256,
            "evaluate": evaluate,
            "tool_version": __version__,
        },
        sort_keys=True,
    )
    return hashlib.sha256(blob.encode()).hexdigest()


# --------------------------------------------------------------------------- one run (worker)


def run_batch_task(run: BatchRun) -> dict[str, Any]:
    """Run one job (on a worker) and return its row: parameters, metrics, timings, failure."""
    from scrapcut_cli.pipeline.job import Job, run_job

    t0 = time.perf_counter()
    job = Job(
        Path(run.recording),
        FitMethod(run.method),
        config_from_dict(run.config, where=f"run {run.key[:12]}"),
        output=Path(run.output),
        reference=None if run.reference is None else Path(run.reference),
        evaluate=run.evaluate,
        object_name=run.name,
    )
    result = run_job(job)
    figures = result.report.figures_mm() or {}
    fit = result.fit
    reports = [p.name for p in result.written if p.name.endswith(".error.json")]
    error_report = reports[0] if reports else None
    row: dict[str, Any] = {
        "status": "ok" if result.ok else "failed",
        "failure": result.failure,
        "note": result.note,
        "error_status": result.report.status,
        **{name: figures.get(name) for name in METRICS},
        "oracle_views": None if result.report.row is None else result.report.row.oracle_views,
        "setpoints": None if fit is None else len(fit.path),
        "flagged": None if fit is None else fit.path.flagged,
        "frames_used": None if fit is None else fit.source["frames_used"],
        "frames_skipped": None if fit is None else fit.source["frames_skipped"],
        "paint_points": None if fit is None else len(fit.stitch.paint_points),
        "path": Path(run.output).name if result.written else None,
        "error_report": error_report,
    }
    for step, seconds in result.timings_s.items():
        row[f"time_{step}_s"] = seconds
    row["time_total_s"] = time.perf_counter() - t0
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row


# --------------------------------------------------------------------------- the batch


@dataclass(frozen=True, eq=False)
class BatchResult:
    """The finished batch: one row per planned run; counts of what this invocation did."""

    out_dir: Path
    rows: list[dict[str, Any]]
    ran: int
    cached: int
    lost: int
    wall_time_s: float
    axes: list[str]

    @property
    def failed(self) -> int:
        return sum(1 for r in self.rows if r["status"] != "ok")


def check_batch_dir(out_dir: Path) -> None:
    """Refuse an output folder that is not empty and not an earlier batch's."""
    if not out_dir.exists():
        return
    if not out_dir.is_dir():
        raise PipelineError(f"{out_dir} exists and is not a folder; choose another -o")
    if any(out_dir.iterdir()) and not (out_dir / "runs").is_dir():
        raise PipelineError(
            f"{out_dir} exists and is not a scrapcut batch output; choose another -o"
        )


def batch(
    inputs: Sequence[BatchInput],
    *,
    out_dir: str | Path,
    grid: dict[str, list[Any]],
    config: ScrapcutConfig,
    engine: Engine,
    evaluate: bool = True,
    plots: bool = True,
    progress: ProgressFn | None = None,
    command: str = "scrapcut batch",
) -> BatchResult:
    """Plan the runs, skip those already finished in ``out_dir``, run the rest on ``engine``
    (each saved as it finishes), then write the table and the report."""
    start = time.perf_counter()
    out_dir = Path(out_dir)
    check_batch_dir(out_dir)
    new_folder = not out_dir.exists()
    try:
        return _batch(
            inputs, out_dir, grid, config, engine, evaluate, plots, progress, command, start
        )
    except BaseException:
        # A batch that stopped before its first run was saved (no cluster, a bad input) leaves
        # no folder behind; one that saved runs keeps them, to resume.
        if new_folder and out_dir.is_dir() and not any((out_dir / "runs").glob("*.json")):
            shutil.rmtree(out_dir, ignore_errors=True)
        raise


def _batch(
    inputs: Sequence[BatchInput],
    out_dir: Path,
    grid: dict[str, list[Any]],
    config: ScrapcutConfig,
    engine: Engine,
    evaluate: bool,
    plots: bool,
    progress: ProgressFn | None,
    command: str,
    start: float,
) -> BatchResult:
    (out_dir / "runs").mkdir(parents=True, exist_ok=True)
    (out_dir / "paths").mkdir(exist_ok=True)
    hashes = _hash_inputs(inputs, out_dir / "hashes.json")
    runs = plan_runs(inputs, grid, config=config, out_dir=out_dir, evaluate=evaluate, hashes=hashes)
    rows: dict[str, dict[str, Any]] = {}
    for run in runs:
        saved = _load_saved(out_dir, run)
        if saved is not None:
            rows[run.key] = saved
    todo = [run for run in runs if run.key not in rows]
    cached = len(rows)
    if progress is not None:
        progress(cached, len(runs), f"{cached} finished before" if cached else "starting")
    lost = 0

    def finished(index: int, result: dict[str, Any] | TaskLost) -> None:
        nonlocal lost
        run = todo[index]
        if isinstance(result, TaskLost):
            lost += 1
            row = {"status": "lost", "failure": str(result)}
        else:
            row = result
        row = _full_row(run, row)
        if row["status"] != "lost":  # saved: never run again (a lost run is retried next time)
            write_text_atomic(_saved_path(out_dir, run), json.dumps(row, indent=1) + "\n")
        rows[run.key] = row
        if progress is not None:
            progress(len(rows), len(runs), f"{run.name} {run.method}: {row['status']}")

    engine.run(
        run_batch_task, todo, keys=[f"scrapcut-batch-{r.key}" for r in todo], on_done=finished
    )
    table = [rows[run.key] for run in runs]
    axes = [a for a in grid if a != METHOD_AXIS]
    wall = time.perf_counter() - start
    result = BatchResult(
        out_dir, table, ran=len(todo) - lost, cached=cached, lost=lost, wall_time_s=wall, axes=axes
    )
    write_table(table, out_dir)
    write_report(result, grid=grid, engine=engine.describe(), command=command, plots=plots)
    return result


def _full_row(run: BatchRun, result: dict[str, Any]) -> dict[str, Any]:
    """The table's row: who and what (recording, method, parameters), then the result."""
    row: dict[str, Any] = {
        "key": run.key,
        "name": run.name,
        "recording": run.given.get("recording", run.recording),
        "recording_sha256": run.given.get("recording_sha256"),
        "reference": run.given.get("reference"),
        "paint": run.given.get("paint"),
        "hsv": run.given.get("hsv"),
        **{("method" if k == METHOD_AXIS else k): v for k, v in run.params.items()},
    }
    for name in ("status", "failure", "note", "error_status", *METRICS):
        row[name] = result.get(name)
    row.update({k: v for k, v in result.items() if k not in row})
    row["tool_version"] = __version__
    return row


def _saved_path(out_dir: Path, run: BatchRun) -> Path:
    return out_dir / "runs" / f"{run.key}.json"


def _load_saved(out_dir: Path, run: BatchRun) -> dict[str, Any] | None:
    """A finished run's row, if saved and its path file is still there (a half-deleted output
    is run again)."""
    path = _saved_path(out_dir, run)
    try:
        row = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    if not isinstance(row, dict) or row.get("key") != run.key:
        return None
    if row.get("path") and not (Path(run.output).parent / row["path"]).is_file():
        return None
    return row


def _hash_inputs(inputs: Sequence[BatchInput], cache_file: Path) -> dict[str, str]:
    """Recording hashes, re-using the cache's when size and mtime have not changed."""
    try:
        cache = json.loads(cache_file.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        cache = {}
    cache = cache if isinstance(cache, dict) else {}
    hashes = {}
    changed = False
    for item in inputs:
        path = item.recording.resolve()
        stat = _stat(path)
        entry = cache.get(str(path))
        if isinstance(entry, dict) and entry.get("stat") == stat and entry.get("sha256"):
            hashes[str(path)] = str(entry["sha256"])
            continue
        digest = content_hash(path)
        hashes[str(path)] = digest
        cache[str(path)] = {"stat": stat, "sha256": digest}
        changed = True
    if changed:
        write_text_atomic(cache_file, json.dumps(cache, indent=1, sort_keys=True) + "\n")
    return hashes


def _stat(path: Path) -> list[int]:
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    return [v for f in files for v in (f.stat().st_size, f.stat().st_mtime_ns)]
