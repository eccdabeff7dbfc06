"""The paper's Table I end to end on the simulator: record → stitch → fit → path file → eval.

:func:`reproduce` is the recipe behind ``scrapcut reproduce``. For each object it records a
simulated scan (``sim``), stitches the paint once (``perception``), fits every method on the
same stitched cloud (``fitting``), makes the cutting path (``toolpath``), writes the path file,
reads it back and measures it (``evaluation``) — the same files ``scrapcut fit`` writes and
``scrapcut eval`` reads, so every figure can be re-checked by hand. In explore mode each method
gets its own scan, since the planner's views follow that method's fits (the paper ran each
method separately). Objects run in parallel processes (``jobs``); progress comes back through
one queue to one callback.

The skeleton uses the configured leaf size (the paper's 5 mm); when that fit fails (the usual
reason: it breaks into pieces) it is retried once at ``retry_leaf_size_m`` (20 mm, what the
paper did for the basket) and the row says so. A failure of one object or method is a row in
the table, not an abort. With ``leaf_sweep_m`` the skeleton is also fitted at each of those
leaf sizes on the same stitched cloud (no retry): the rows of the paper's Fig. 3, kept apart
from Table I.

The output folder is built under a temporary name and renamed at the end::

    DIR/recordings/<object>.mcap     the simulated scans (<object>_<method>.mcap when exploring)
    DIR/paths/<object>_<method>.json the path files (scrapcut.path/v1)
    DIR/paths/<object>_skeleton_leaf<N>mm.json   the leaf-size sweep
    DIR/report.md, report.json, report.csv
    DIR/plots/*.png                  error along the curve, paths, leaf sizes
    DIR/config.toml                  the stage parameters (usable as --config)
    DIR/config.json                  the same plus the reproduce options
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import multiprocessing
import os
import platform
import queue as queue_module
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from scrapcut_cli import __version__
from scrapcut_cli._io import atomic_path, write_text_atomic
from scrapcut_cli.config import ScrapcutConfig
from scrapcut_cli.errors import EvaluationError, FittingError, ScrapcutError
from scrapcut_cli.evaluation.report import (
    ReportRow,
    load_paper_table,
    render_csv,
    render_markdown,
    rows_to_records,
)

if TYPE_CHECKING:
    from scrapcut_cli.evaluation.sources import Reference
    from scrapcut_cli.sim.recorder import RecordResult
    from scrapcut_cli.toolpath.recipe import StitchedRecording

#: The paper's five simulated objects (Table I), and the real-robot shapes ``all`` adds.
PAPER_OBJECTS = ("cylinder", "i_beam", "t_piece", "basket", "air_chamber")
REAL_ROBOT_OBJECTS = ("slanted", "planar_box")
MODES = ("sweep", "explore")
REPORT_SCHEMA = "scrapcut.reproduce/v1"
#: The scan figures report.md shows (report.json keeps all of them).
SCAN_KEYS = (
    "views",
    "stop_reason",
    "infeasible_views",
    "collisions",
    "camera_travel_m",
    "frames_used",
    "frames_skipped",
    "paint_points",
)

#: progress(object, stage, done, total): stage is "record", "stitch", "fit <method>", "done".
ProgressFn = Callable[[str, str, int, int], None]


@dataclass(frozen=True, eq=False)
class ObjectRun:
    """What happened to one object: its rows (one per method), timings, and the figures of its
    scans (one recording in sweep mode, one per method in explore mode)."""

    object: str
    rows: list[ReportRow]
    timings_s: dict[str, float] = field(default_factory=dict)
    scans: list[dict[str, Any]] = field(default_factory=list)
    failure: str | None = None
    sweep_rows: list[ReportRow] = field(default_factory=list)


@dataclass(frozen=True, eq=False)
class ReproduceResult:
    """The finished run: ``out_dir`` holds every file listed in the module docstring."""

    out_dir: Path
    runs: list[ObjectRun]
    wall_time_s: float
    report_markdown: str

    @property
    def rows(self) -> list[ReportRow]:
        """Table I: one row per object and method."""
        return [row for run in self.runs for row in run.rows]

    @property
    def sweep_rows(self) -> list[ReportRow]:
        """The skeleton leaf-size sweep (Fig. 3), one row per object and leaf size."""
        return [row for run in self.runs for row in run.sweep_rows]


def resolve_objects(names: Sequence[str]) -> tuple[str, ...]:
    """Object names from the command line: ``all`` = the paper's five + the real-robot shapes;
    empty = the paper's five. Unknown names raise EvaluationError listing the known ones."""
    from scrapcut_cli.sim.objects import list_objects

    known = [name for name, _ in list_objects()]
    wanted: list[str] = []
    for name in names or PAPER_OBJECTS:
        expanded = [*PAPER_OBJECTS, *REAL_ROBOT_OBJECTS] if name == "all" else [name]
        for n in expanded:
            if n not in known:
                raise EvaluationError(f"unknown object {n!r}; known: {', '.join(known)}, all")
            if n not in wanted:
                wanted.append(n)
    return tuple(wanted)


def resolve_methods(names: Sequence[str]) -> tuple[str, ...]:
    """Fitting methods, validated against ``toolpath.recipe.METHODS``; empty = all of them."""
    from scrapcut_cli.toolpath.recipe import METHODS

    wanted: list[str] = []
    for name in names or METHODS:
        if name not in METHODS:
            raise EvaluationError(f"unknown method {name!r}; known: {', '.join(METHODS)}")
        if name not in wanted:
            wanted.append(name)
    return tuple(wanted)


def reproduce(
    out_dir: str | Path,
    *,
    objects: Sequence[str],
    methods: Sequence[str],
    config: ScrapcutConfig,
    jobs: int = 1,
    retry_leaf_size_m: float = 0.020,
    leaf_sweep_m: Sequence[float] = (),
    plots: bool = True,
    progress: ProgressFn | None = None,
    command: str = "scrapcut reproduce",
) -> ReproduceResult:
    """Record, fit and evaluate every object with every method; write ``out_dir``.

    ``config.sim`` sets the scan (mode, noise, resolution, seed); its ``object`` is replaced
    per object. ``jobs`` > 1 runs objects in that many processes. Raises EvaluationError, before
    any work, if ``out_dir`` exists and is not an earlier reproduce output or an option is bad.
    """
    start = time.perf_counter()
    out_dir = Path(out_dir)
    objects = resolve_objects(objects)
    methods = resolve_methods(methods)
    if jobs < 1:
        raise EvaluationError(f"jobs must be at least 1, got {jobs}")
    if not (np.isfinite(retry_leaf_size_m) and retry_leaf_size_m > 0):
        raise EvaluationError(f"the retry leaf size must be positive, got {retry_leaf_size_m}")
    sweep = tuple(sorted({float(leaf) for leaf in leaf_sweep_m}))
    if not all(np.isfinite(leaf) and leaf > 0 for leaf in sweep):
        raise EvaluationError(f"leaf sizes must be positive, got {list(leaf_sweep_m)}")
    _check_mode(config.sim.mode)
    check_out_dir(out_dir)
    report = progress or _no_progress

    with atomic_path(out_dir, directory=True) as tmp:
        (tmp / "recordings").mkdir()
        (tmp / "paths").mkdir()
        tasks = [
            _Task(name, methods, config.to_dict(), str(tmp), retry_leaf_size_m, sweep)
            for name in objects
        ]
        runs = _run_tasks(tasks, jobs=jobs, progress=report)
        if plots:
            _write_plots(runs, tmp / "plots")
        wall = time.perf_counter() - start
        options = {
            "objects": list(objects),
            "methods": list(methods),
            "jobs": jobs,
            "retry_leaf_size_mm": retry_leaf_size_m * 1000.0,
            "leaf_sweep_mm": [leaf * 1000.0 for leaf in sweep],
            "mode": config.sim.mode,
            "noise": config.sim.noise,
            "seed": config.sim.seed,
            "width": config.sim.width,
            "height": config.sim.height,
        }
        markdown = _write_reports(
            tmp, runs, config=config, options=options, wall_time_s=wall, command=command
        )
    return ReproduceResult(out_dir=out_dir, runs=runs, wall_time_s=wall, report_markdown=markdown)


# --------------------------------------------------------------------------- one object


@dataclass(frozen=True)
class _Task:
    """Everything a worker process needs (picklable)."""

    object: str
    methods: tuple[str, ...]
    config: dict[str, Any]
    out_dir: str
    retry_leaf_size_m: float
    leaf_sweep_m: tuple[float, ...] = ()


def run_object(task: _Task, progress: ProgressFn) -> ObjectRun:
    """Scan one object, stitch each scan once, then fit + write + evaluate each method.

    A sweep is one scan shared by every method; exploration is one scan per method, since the
    planner's decisions come from that method's fits (the paper ran each method on its own).
    Stitching and fitting are ``scrapcut fit``'s own recipe (``toolpath.recipe``), so a path
    file here is the one ``scrapcut fit`` writes for the same recording and parameters.
    """
    from scrapcut_cli.config import config_from_dict

    name = task.object
    config = config_from_dict(task.config)
    scans: list[tuple[str, tuple[str, ...]]]
    if config.sim.mode == "explore":
        scans = [(f"{name}_{method}", (method,)) for method in task.methods]
    else:
        scans = [(name, task.methods)]
    rows: list[ReportRow] = []
    sweep_rows: list[ReportRow] = []
    summaries: list[dict[str, Any]] = []
    timings: dict[str, float] = {}
    failures: list[str] = []
    for stem, methods in scans:
        scan_rows, scan_sweep, summary, scan_timings = _run_scan(
            task, stem, methods, config=config, progress=progress
        )
        rows += scan_rows
        sweep_rows += scan_sweep
        summaries.append(summary)
        if len(scans) > 1:  # one scan per method: name the timings for it
            method = methods[0]
            scan_timings = {
                k if k.endswith(f"_{method}") else f"{k}_{method}": v
                for k, v in scan_timings.items()
            }
        timings.update(scan_timings)
        if "failure" in summary:
            failures.append(str(summary["failure"]))
    progress(name, "done", 1, 1)
    return ObjectRun(
        name,
        rows,
        timings_s=timings,
        scans=summaries,
        failure="; ".join(failures) or None,
        sweep_rows=sweep_rows,
    )


def _run_scan(
    task: _Task,
    stem: str,
    methods: tuple[str, ...],
    *,
    config: ScrapcutConfig,
    progress: ProgressFn,
) -> tuple[list[ReportRow], list[ReportRow], dict[str, Any], dict[str, float]]:
    """Record ``recordings/<stem>.mcap``, stitch it, and fit + evaluate ``methods`` on it.

    Returns the Table I rows, the leaf-sweep rows, the scan's figures and the timings.
    """
    from scrapcut_cli.evaluation.sources import load_reference
    from scrapcut_cli.sim import record
    from scrapcut_cli.toolpath.recipe import stitch_recording_file

    name = task.object
    out_dir = Path(task.out_dir)
    rec_path = out_dir / "recordings" / f"{stem}.mcap"
    summary: dict[str, Any] = {"recording": f"recordings/{rec_path.name}"}
    timings: dict[str, float] = {}

    def failed(
        stage: str, exc: ScrapcutError
    ) -> tuple[list[ReportRow], list[ReportRow], dict[str, Any], dict[str, float]]:
        summary["failure"] = f"{stage} failed: {exc}"
        rows = [ReportRow(name, m, None, failure=summary["failure"]) for m in methods]
        return rows, [], summary, timings

    factory = None
    if config.sim.mode == "explore":
        from scrapcut_cli.exploration.planner import planner_factory

        factory = planner_factory(config.override("exploration", method=methods[0]))
    t0 = time.perf_counter()
    try:
        recorded = record(
            replace(config.sim, object=name),
            rec_path,
            planner_factory=factory,
            progress=lambda done, total: progress(name, "record", done, total),
        )
    except ScrapcutError as exc:
        return failed("recording", exc)
    timings["record"] = time.perf_counter() - t0
    summary.update(_scan_summary(recorded))

    try:
        stitched = stitch_recording_file(
            rec_path,
            config=config,
            progress=lambda done, total: progress(name, "stitch", done, total),
        )
        reference = load_reference(rec_path, config=config.recording)
    except ScrapcutError as exc:
        return failed("stitching", exc)
    timings["stitch"] = stitched.time_s
    # Path files name their recording relative to themselves: the folder is renamed at the end.
    stitched = replace(
        stitched, source={**stitched.source, "path": f"../recordings/{rec_path.name}"}
    )
    summary["frames_used"] = stitched.source["frames_used"]
    summary["frames_skipped"] = stitched.source["frames_skipped"]
    summary["paint_points"] = stitched.stitch.size

    rows = []
    for method in methods:
        progress(name, f"fit {method}", 0, 1)
        t0 = time.perf_counter()
        rows.append(
            _fit_and_evaluate(
                name,
                method,
                stitched,
                reference,
                config=config,
                out_dir=out_dir,
                retry_leaf_size_m=task.retry_leaf_size_m,
            )
        )
        timings[f"fit_{method}"] = time.perf_counter() - t0
        progress(name, f"fit {method}", 1, 1)
    sweep: list[ReportRow] = []
    if "skeleton" in methods and task.leaf_sweep_m:
        t0 = time.perf_counter()
        for i, leaf in enumerate(task.leaf_sweep_m):
            progress(name, "leaf sweep", i, len(task.leaf_sweep_m))
            sweep.append(
                _fit_and_evaluate(
                    name,
                    "skeleton",
                    stitched,
                    reference,
                    config=config.override("skeleton", leaf_size_m=leaf),
                    out_dir=out_dir,
                    retry_leaf_size_m=None,
                    path_stem=f"{name}_skeleton_leaf{leaf * 1000:g}mm",
                )
            )
        timings["leaf_sweep"] = time.perf_counter() - t0
    return rows, sweep, summary, timings


def _fit_and_evaluate(
    name: str,
    method: str,
    stitched: StitchedRecording,
    reference: Reference,
    *,
    config: ScrapcutConfig,
    out_dir: Path,
    retry_leaf_size_m: float | None,
    path_stem: str | None = None,
) -> ReportRow:
    """Fit one method (skeleton: retry once at the larger leaf unless that is None), write its
    path file ``paths/<path_stem>.json``, read it back and measure it. Known failures become a
    row with ``failure``."""
    from scrapcut_cli.evaluation.sources import evaluate_path_file, load_path_file
    from scrapcut_cli.toolpath.pathfile import write_path_file
    from scrapcut_cli.toolpath.recipe import fit_stitched

    note = ""
    params = _method_params(config, method)
    try:
        try:
            result = fit_stitched(stitched, method=method, config=config)
        except FittingError as exc:
            leaf = config.skeleton.leaf_size_m
            if (
                method != "skeleton"
                or retry_leaf_size_m is None
                or np.isclose(leaf, retry_leaf_size_m)
            ):
                raise
            config = config.override("skeleton", leaf_size_m=retry_leaf_size_m)
            params = _method_params(config, method)
            # The fitter's message ends with advice for the command line; the note needs the why.
            why = str(exc).split(";")[0]
            note = (
                f"{leaf * 1000:g} mm leaf broke ({why}); retried at {retry_leaf_size_m * 1000:g} mm"
            )
            result = fit_stitched(stitched, method=method, config=config)
        path_file = out_dir / "paths" / f"{path_stem or f'{name}_{method}'}.json"
        write_path_file(path_file, result.to_path_dict())
        row = evaluate_path_file(
            load_path_file(path_file),
            reference,
            config=config.evaluation,
            object_name=name,
            note=note,
        )
    except ScrapcutError as exc:
        return ReportRow(name, method, None, params=params, note=note, failure=str(exc))
    # Rows name their path file relative to the output folder, which is renamed at the end.
    return replace(row, source=str(Path("paths") / path_file.name))


def _method_params(config: ScrapcutConfig, method: str) -> dict[str, Any]:
    section = getattr(config, method, None)
    if section is None or not dataclasses.is_dataclass(section) or isinstance(section, type):
        return {}
    return dict(json.loads(json.dumps(dataclasses.asdict(section))))


def _scan_summary(recorded: RecordResult) -> dict[str, Any]:
    """The scalar figures of the simulator's RecordResult (views, collisions, travel...)."""
    values = {f.name: getattr(recorded, f.name) for f in dataclasses.fields(recorded)}
    return {k: v for k, v in values.items() if isinstance(v, int | float | str | bool)}


# --------------------------------------------------------------------------- running tasks

_QUEUE: Any = None


def _init_worker(events: Any) -> None:
    global _QUEUE
    _QUEUE = events


#: A worker's last message: everything it sent before is in the queue ahead of it.
_END = ("", "__end__", 0, 0)
#: How long to wait for a finished worker's last messages, seconds (a killed worker sends none).
_END_TIMEOUT_S = 30.0


def _worker(task: _Task) -> ObjectRun:
    def send(obj: str, stage: str, done: int, total: int) -> None:
        _QUEUE.put((obj, stage, done, total))

    try:
        return run_object(task, send)
    finally:
        _QUEUE.put(_END)


def _run_tasks(tasks: list[_Task], *, jobs: int, progress: ProgressFn) -> list[ObjectRun]:
    """Run the tasks inline (one job) or in a process pool, results in task order.

    A worker's messages reach the queue through a feeder thread, possibly after its task's
    future completes, so the last one (``_END``) is awaited before returning: the callback sees
    every message, "done" included.
    """
    if jobs == 1 or len(tasks) == 1:
        return [run_object(task, progress) for task in tasks]
    # spawn, not fork: open3d and BLAS keep threads that a fork would copy mid-flight.
    ctx = multiprocessing.get_context("spawn")
    events = ctx.Queue()
    with ProcessPoolExecutor(
        max_workers=min(jobs, len(tasks)),
        mp_context=ctx,
        initializer=_init_worker,
        initargs=(events,),
    ) as pool:
        futures = [pool.submit(_worker, task) for task in tasks]
        pending = set(futures)
        ended = 0
        while pending:
            _, pending = wait(pending, timeout=0.1, return_when=FIRST_COMPLETED)
            ended += _drain(events, progress)
        while ended < len(tasks):
            got = _drain(events, progress, timeout_s=_END_TIMEOUT_S)
            if got < 0:
                break  # a worker died without its last message: its future says why
            ended += got
        return [f.result() for f in futures]


def _drain(events: Any, progress: ProgressFn, *, timeout_s: float | None = None) -> int:
    """Pass queued messages to ``progress``; the number of ``_END`` messages among them.

    With ``timeout_s``, wait that long for the first message (-1 if none came).
    """
    ended = 0
    first = timeout_s is not None
    while True:
        try:
            event = events.get(timeout=timeout_s) if first else events.get_nowait()
        except queue_module.Empty:
            return -1 if first else ended
        first = False
        if tuple(event) == _END:
            ended += 1
        else:
            progress(*event)


def _no_progress(obj: str, stage: str, done: int, total: int) -> None:
    return None


# --------------------------------------------------------------------------- checks and output


def _check_mode(mode: str) -> None:
    if mode not in MODES:
        raise EvaluationError(f"unknown mode {mode!r}; reproduce runs {', '.join(MODES)}")


def check_out_dir(out_dir: Path) -> None:
    """Refuse to replace a folder that is not an earlier reproduce output."""
    if not out_dir.exists():
        return
    if not out_dir.is_dir():
        raise EvaluationError(f"{out_dir} exists and is not a folder; choose another -o")
    if any(out_dir.iterdir()) and not (out_dir / "report.json").is_file():
        raise EvaluationError(
            f"{out_dir} exists and is not a scrapcut reproduce output; choose another -o"
        )


def _write_plots(runs: list[ObjectRun], out_dir: Path) -> list[Path]:
    """Table I's figures per object, and Fig. 3 for each object with a leaf-size sweep."""
    from scrapcut_cli.evaluation.plots import plot_leaf_sweep, write_plots

    written = write_plots([row for run in runs for row in run.rows], out_dir)
    for run in runs:
        if len({r.leaf_size_m for r in run.sweep_rows}) >= 2:
            without_leaf = [r for r in run.rows if r.leaf_size_m is None]  # NURBS: reference line
            written.append(
                plot_leaf_sweep(
                    run.sweep_rows + without_leaf,
                    out_dir / f"leaf_sweep_{run.object}.png",
                    title=f"{run.object}: skeleton error against leaf size",
                )
            )
    return written


def machine_description() -> str:
    """CPU model, core count, OS and Python: where the figures and timings were measured."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (
        f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
        f"Python {platform.python_version()}"
    )


def config_to_toml(config: ScrapcutConfig) -> str:
    """The stage parameters as TOML that ``--config`` reads back (None = default: omitted)."""
    lines = [f"# scrapcut {__version__}: every stage parameter used (metres, seconds, degrees)"]
    for section, values in config.to_dict().items():
        lines += ["", f"[{section}]"]
        for key, value in values.items():
            if value is not None:
                lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise EvaluationError(f"cannot write {value!r} to TOML")


def _write_reports(
    out_dir: Path,
    runs: list[ObjectRun],
    *,
    config: ScrapcutConfig,
    options: dict[str, Any],
    wall_time_s: float,
    command: str,
) -> str:
    """report.md, report.json, report.csv, config.toml and config.json; returns the markdown."""
    paper = load_paper_table()
    rows = [row for run in runs for row in run.rows]
    created = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    machine = machine_description()
    header = [
        "# Table I reproduced on the simulator",
        "",
        f"- command: `{command}`",
        f"- date: {created}, scrapcut {__version__}",
        f"- machine: {machine}",
        f"- wall time: {wall_time_s:.1f} s with {options['jobs']} job(s)",
        f"- scans: {options['mode']} mode, {options['noise']} noise, "
        f"{options['width']}×{options['height']} px, seed {options['seed']}",
        "",
    ]
    table = render_markdown(rows, paper=paper)
    sweep_rows = [row for run in runs for row in run.sweep_rows]
    if sweep_rows:
        table += (
            "\n### Skeleton leaf-size sweep (the paper's Fig. 3)\n\n"
            "The skeleton fitted at each leaf size to the same stitched cloud, no retry.\n\n"
            + render_markdown(sweep_rows)
        )
    timing_lines = ["", "### Runs", "", "| Object | Scan | Timings [s] |", "|---|---|---|"]
    for run in runs:
        scans = "<br>".join(
            f"{s['recording']}: " + ", ".join(f"{k} {_fmt(s[k])}" for k in SCAN_KEYS if k in s)
            for s in run.scans
        )
        timings = ", ".join(f"{k} {v:.1f}" for k, v in run.timings_s.items())
        timing_lines.append(f"| {run.object} | {scans} | {timings} |")
    figures = sorted((out_dir / "plots").glob("*.png")) if (out_dir / "plots").is_dir() else []
    figure_lines = ["", "### Figures", ""] + [f"![{p.stem}](plots/{p.name})" for p in figures]
    markdown = "\n".join(header) + "\n" + table + "\n".join(timing_lines) + "\n"
    if figures:
        markdown += "\n".join(figure_lines) + "\n"
    write_text_atomic(out_dir / "report.md", markdown)
    write_text_atomic(out_dir / "report.csv", render_csv(rows, paper=paper))
    report = {
        "schema": REPORT_SCHEMA,
        "tool_version": __version__,
        "created": created,
        "command": command,
        "machine": machine,
        "wall_time_s": wall_time_s,
        "options": options,
        "rows": rows_to_records(rows, paper=paper),
        "leaf_sweep": rows_to_records(sweep_rows),
        "runs": [
            {
                "object": run.object,
                "scans": run.scans,
                "timings_s": run.timings_s,
                "failure": run.failure,
            }
            for run in runs
        ],
    }
    write_text_atomic(out_dir / "report.json", json.dumps(report, indent=2) + "\n")
    write_text_atomic(out_dir / "config.toml", config_to_toml(config))
    write_text_atomic(
        out_dir / "config.json",
        json.dumps({"reproduce": options, "config": config.to_dict()}, indent=2) + "\n",
    )
    return markdown


def _fmt(value: Any) -> str:
    return f"{value:.2f}" if isinstance(value, float) else str(value)
