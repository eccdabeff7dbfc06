"""The paper's Table I end to end on the simulator: simulate → pipeline jobs → report.

:func:`reproduce` is the recipe behind ``scrapcut reproduce``. It plans one *scan task* per
object, simulator seed and scan (:class:`ScanTask`), hands them to the batch engine
(:class:`~scrapcut_cli.pipeline.engine.Engine`: a local Dask cluster by default, a scheduler
address, or inline), and writes the reports as the scans come back. A scan task records a
simulated scan (``sim``), stitches it once, and runs one pipeline job per method on the stitched
clouds (:class:`~scrapcut_cli.pipeline.job.Pipeline`: fit, path file, error report — the files
``scrapcut fit`` writes and ``scrapcut eval`` reads, so every figure can be re-checked by hand).
In explore mode each method gets its own scan, since the planner's views follow that method's
fits (the paper ran each method separately); a sweep is one scan for every method, and its rows
are labelled "oracle views" (its views follow the true line).

The skeleton uses the configured leaf size (the paper's 5 mm); when that fit breaks it is
retried once at ``retry_leaf_size_m`` (20 mm, what the paper did for the basket) and the row says
so. A failure of one object or method is a row in the table, not an abort. With ``leaf_sweep_m``
the skeleton is also fitted at each of those leaf sizes on the same stitched cloud (no retry):
the rows of the paper's Fig. 3, kept apart from Table I. With several ``seeds`` Table I is the
mean ± 95 % interval over the seeds, next to the paper's single runs. With ``self_calibrate``
every scan is also fitted as ``fit --self-calibrate`` fits it (the hand-eye and clock
calibration estimated from the scan, the frames posed with it): a second row per object and
method, labelled "self-calibrated", with the calibration's verdict in its note.

The output folder is built under a temporary name and renamed at the end::

    DIR/recordings/<object>.mcap     the simulated scans (<object>_<method>.mcap when exploring;
                                     _seed<N> added with several seeds)
    DIR/paths/<object>_<method>.json the path files (scrapcut.path/v1) and their .error.json/.md
    DIR/paths/<object>_<method>_selfcal.json     the self-calibrated fits
    DIR/paths/<object>_skeleton_leaf<N>mm.json   the leaf-size sweep
    DIR/report.md, report.html (figures embedded), report.json, report.csv
    DIR/plots/*.png                  error along the curve, paths, leaf sizes (first seed)
    DIR/config.toml                  the stage parameters (usable as --config)
    DIR/config.json                  the same plus the reproduce options
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import platform
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from scrapcut_cli import __version__
from scrapcut_cli._io import atomic_path, write_text_atomic
from scrapcut_cli.config import FitMethod, ScanMode, ScrapcutConfig, choice_names
from scrapcut_cli.errors import PipelineError, ScrapcutError
from scrapcut_cli.evaluation.report import (
    ReportRow,
    aggregate_records,
    aggregate_rows,
    load_paper_table,
    render_csv,
    render_interval_markdown,
    render_markdown,
    rows_to_records,
    sort_rows,
)
from scrapcut_cli.pipeline.engine import Engine, TaskLost

if TYPE_CHECKING:
    from scrapcut_cli.motion.observed import ObservedScene
    from scrapcut_cli.pipeline.fit import FitResult, StitchedRecording
    from scrapcut_cli.sim.recorder import RecordResult

#: The paper's five simulated objects (Table I), the pieces Table I adds to them by default (a
#: perforated plate: holes across the stroke, issue 14), and the real-robot shapes ``all`` adds.
PAPER_OBJECTS = ("cylinder", "i_beam", "t_piece", "basket", "air_chamber")
EXTRA_OBJECTS = ("perforated_plate",)
DEFAULT_OBJECTS = (*PAPER_OBJECTS, *EXTRA_OBJECTS)
REAL_ROBOT_OBJECTS = ("slanted", "planar_box")
#: The scan modes reproduce runs: explore (Algorithm 1, Table I) or sweep (oracle views).
MODES = (ScanMode.SWEEP.value, ScanMode.EXPLORE.value)
REPORT_SCHEMA = "scrapcut.reproduce/v1"
#: The scan figures report.md shows (report.json keeps all of them).
SCAN_KEYS = (
    "views",
    "stop_reason",
    "infeasible_views",
    "collisions",
    "min_clearance_m",
    "camera_travel_m",
    "frames_used",
    "frames_skipped",
    "paint_points",
)
#: The most seeds one run takes (a typo like 0-20000 should not start a week of work).
MAX_SEEDS = 1000

#: progress(scans done, scans total, what finished last).
ProgressFn = Callable[[int, int, str], None]


@dataclass(frozen=True)
class ScanTask:
    """One simulated scan and the jobs run on it: everything a worker needs (picklable).

    ``out_dir`` is the absolute output folder (shared by the workers); ``stem`` names the
    recording (``recordings/<stem>.mcap``); ``suffix`` is appended to every path file's name
    (``_seed3`` with several seeds).
    """

    object: str
    seed: int
    methods: tuple[str, ...]
    config: dict[str, Any]
    out_dir: str
    stem: str
    suffix: str = ""
    retry_leaf_size_m: float | None = 0.020
    leaf_sweep_m: tuple[float, ...] = ()
    motion: bool = True  # plan the Panda's trajectory of every path (scrapcut trajectory)
    self_calibrate: bool = False

    @property
    def key(self) -> str:
        """The task's name on the cluster."""
        return f"scrapcut-reproduce-{self.stem}"


@dataclass(frozen=True, eq=False)
class ScanRun:
    """A scan task's outcome: Table I rows (one per method), leaf-sweep rows, the scan's
    figures (``summary``) and timings; ``failure`` when the scan itself failed."""

    task: ScanTask
    rows: list[ReportRow]
    sweep_rows: list[ReportRow]
    summary: dict[str, Any]
    timings_s: dict[str, float]
    failure: str | None = None


@dataclass(frozen=True, eq=False)
class ObjectRun:
    """What happened to one object with one seed: its rows (one per method), timings, and the
    figures of its scans (one recording in sweep mode, one per method in explore mode)."""

    object: str
    rows: list[ReportRow]
    timings_s: dict[str, float] = field(default_factory=dict)
    scans: list[dict[str, Any]] = field(default_factory=list)
    failure: str | None = None
    sweep_rows: list[ReportRow] = field(default_factory=list)
    seed: int = 0


@dataclass(frozen=True, eq=False)
class ReproduceResult:
    """The finished run: ``out_dir`` holds every file listed in the module docstring."""

    out_dir: Path
    runs: list[ObjectRun]
    wall_time_s: float
    report_markdown: str
    seeds: tuple[int, ...] = (0,)
    table_markdown: str = ""

    @property
    def rows(self) -> list[ReportRow]:
        """Table I: one row per object, method and seed."""
        return [row for run in self.runs for row in run.rows]

    @property
    def sweep_rows(self) -> list[ReportRow]:
        """The skeleton leaf-size sweep (Fig. 3), one row per object, leaf size and seed."""
        return [row for run in self.runs for row in run.sweep_rows]


# --------------------------------------------------------------------------- options


def resolve_objects(names: Sequence[str]) -> tuple[str, ...]:
    """Object names from the command line: ``all`` = the default pieces + the real-robot
    shapes; empty = the default pieces (the paper's five and the perforated plate). Unknown
    names raise PipelineError listing the known ones."""
    from scrapcut_cli.sim.objects import list_objects

    known = [name for name, _ in list_objects()]
    wanted: list[str] = []
    for name in names or DEFAULT_OBJECTS:
        expanded = [*DEFAULT_OBJECTS, *REAL_ROBOT_OBJECTS] if name == "all" else [name]
        for n in expanded:
            if n not in known:
                raise PipelineError(f"unknown object {n!r}; known: {', '.join(known)}, all")
            if n not in wanted:
                wanted.append(n)
    return tuple(wanted)


def resolve_methods(names: Sequence[str]) -> tuple[str, ...]:
    """Fitting methods, validated against :class:`FitMethod`; empty = all of them."""
    known = choice_names(FitMethod)
    wanted: list[str] = []
    for name in names or known:
        if name not in known:
            raise PipelineError(f"unknown method {name!r}; known: {', '.join(known)}")
        if name not in wanted:
            wanted.append(name)
    return tuple(wanted)


def parse_seeds(text: str) -> tuple[int, ...]:
    """``0-19`` → 0..19; ``0,3,7`` → those; ``5`` → (5,). Ranges and lists mix: ``0-4,10``."""
    seeds: list[int] = []
    for part in (p.strip() for p in text.split(",")):
        match = re.fullmatch(r"(\d+)(?:\s*-\s*(\d+))?", part)
        if match is None:
            raise PipelineError(f"seeds must look like 0-19 or 0,3,7; got {text!r}")
        lo = int(match.group(1))
        hi = int(match.group(2)) if match.group(2) is not None else lo
        if hi < lo:
            raise PipelineError(f"seed range {part!r} runs backwards")
        if hi - lo + 1 > MAX_SEEDS:
            raise PipelineError(f"seed range {part!r} holds more than {MAX_SEEDS} seeds")
        seeds += [s for s in range(lo, hi + 1) if s not in seeds]
    if len(seeds) > MAX_SEEDS:
        raise PipelineError(f"{len(seeds)} seeds; at most {MAX_SEEDS}")
    return tuple(seeds)


def check_out_dir(out_dir: Path) -> None:
    """Refuse to replace a folder that is not an earlier reproduce output."""
    if not out_dir.exists():
        return
    if not out_dir.is_dir():
        raise PipelineError(f"{out_dir} exists and is not a folder; choose another -o")
    if any(out_dir.iterdir()) and not (out_dir / "report.json").is_file():
        raise PipelineError(
            f"{out_dir} exists and is not a scrapcut reproduce output; choose another -o"
        )


# --------------------------------------------------------------------------- the recipe


def reproduce(
    out_dir: str | Path,
    *,
    objects: Sequence[str],
    methods: Sequence[str],
    config: ScrapcutConfig,
    seeds: Sequence[int] | None = None,
    engine: Engine | None = None,
    retry_leaf_size_m: float = 0.020,
    leaf_sweep_m: Sequence[float] = (),
    plots: bool = True,
    progress: ProgressFn | None = None,
    command: str = "scrapcut reproduce",
    motion: bool = True,
    self_calibrate: bool = False,
) -> ReproduceResult:
    """Record, fit and evaluate every object with every method (and seed); write ``out_dir``.

    ``config.sim`` sets the scan (mode, noise, resolution); its ``object`` and ``seed`` are
    replaced per task (``seeds`` default: ``config.sim.seed``). ``engine`` runs the scans
    (default: a local Dask cluster, one worker per core; closed at the end only if made here).
    ``self_calibrate`` adds a self-calibrated row per object and method (the scans' own
    ``config.calibration`` must name no calibration file or self-calibration).
    Raises PipelineError, before any work, if ``out_dir`` exists and is not an earlier reproduce
    output or an option is bad.
    """
    start = time.perf_counter()
    out_dir = Path(out_dir)
    objects = resolve_objects(objects)
    methods = resolve_methods(methods)
    seeds = tuple(seeds) if seeds is not None else (config.sim.seed,)
    if not seeds:
        raise PipelineError("no seeds given")
    if any(s < 0 for s in seeds):
        raise PipelineError(f"seeds must be non-negative integers, got {list(seeds)}")
    for seed in seeds:  # the simulator's own range for a seed (ConfigError names it)
        config.override("sim", seed=seed)
    if not (np.isfinite(retry_leaf_size_m) and retry_leaf_size_m > 0):
        raise PipelineError(f"the retry leaf size must be positive, got {retry_leaf_size_m}")
    sweep = tuple(sorted({float(leaf) for leaf in leaf_sweep_m}))
    if not all(np.isfinite(leaf) and leaf > 0 for leaf in sweep):
        raise PipelineError(f"leaf sizes must be positive, got {list(leaf_sweep_m)}")
    if config.sim.mode not in MODES:
        raise PipelineError(f"unknown mode {config.sim.mode!r}; reproduce runs {', '.join(MODES)}")
    if self_calibrate and (config.calibration.file or config.calibration.self_calibrate):
        raise PipelineError(
            "self-calibrated rows sit beside rows with the recordings' own calibration: the "
            "configuration must not set calibration.file or calibration.self_calibrate"
        )
    check_out_dir(out_dir)
    own_engine = engine is None
    engine = Engine() if engine is None else engine

    try:
        with atomic_path(out_dir, directory=True) as tmp:
            (tmp / "recordings").mkdir()
            (tmp / "paths").mkdir()
            tasks = plan_scans(
                tmp.resolve(),
                objects=objects,
                methods=methods,
                seeds=seeds,
                config=config,
                retry_leaf_size_m=retry_leaf_size_m,
                leaf_sweep_m=sweep,
                motion=motion,
                self_calibrate=self_calibrate,
            )
            scans = _run_scans(engine, tasks, progress)
            runs = _object_runs(scans)
            if plots:
                _write_plots([r for r in runs if r.seed == seeds[0]], tmp / "plots")
            wall = time.perf_counter() - start
            options = {
                "objects": list(objects),
                "methods": list(methods),
                "seeds": list(seeds),
                "engine": engine.describe(),
                "retry_leaf_size_mm": retry_leaf_size_m * 1000.0,
                "leaf_sweep_mm": [leaf * 1000.0 for leaf in sweep],
                "self_calibrate": self_calibrate,
                "mode": config.sim.mode,
                "noise": config.sim.noise,
                "seed": seeds[0],
                "width": config.sim.width,
                "height": config.sim.height,
                "motion": motion,
            }
            markdown, table = _write_reports(
                tmp, runs, config=config, options=options, wall_time_s=wall, command=command
            )
    finally:
        if own_engine:
            engine.close()
    return ReproduceResult(
        out_dir=out_dir,
        runs=runs,
        wall_time_s=wall,
        report_markdown=markdown,
        seeds=seeds,
        table_markdown=table,
    )


def plan_scans(
    out_dir: Path,
    *,
    objects: Sequence[str],
    methods: Sequence[str],
    seeds: Sequence[int],
    config: ScrapcutConfig,
    retry_leaf_size_m: float | None,
    leaf_sweep_m: tuple[float, ...] = (),
    motion: bool = True,
    self_calibrate: bool = False,
) -> list[ScanTask]:
    """One task per object, seed and scan: a sweep serves every method, exploration one each."""
    tasks = []
    settings = config.to_dict()
    for seed in seeds:
        suffix = f"_seed{seed}" if len(seeds) > 1 else ""
        for name in objects:
            groups: list[tuple[str, tuple[str, ...]]]
            if config.sim.mode == ScanMode.EXPLORE:
                groups = [(f"{name}_{m}", (m,)) for m in methods]
            else:
                groups = [(name, tuple(methods))]
            for stem, scan_methods in groups:
                tasks.append(
                    ScanTask(
                        object=name,
                        seed=seed,
                        methods=scan_methods,
                        config=settings,
                        out_dir=str(out_dir),
                        stem=stem + suffix,
                        suffix=suffix,
                        retry_leaf_size_m=retry_leaf_size_m,
                        leaf_sweep_m=leaf_sweep_m,
                        motion=motion,
                        self_calibrate=self_calibrate,
                    )
                )
    return tasks


def _run_scans(engine: Engine, tasks: list[ScanTask], progress: ProgressFn | None) -> list[ScanRun]:
    """Every task on the engine; a lost task becomes a failed scan."""
    done: dict[int, ScanRun] = {}

    def finished(index: int, result: ScanRun | TaskLost) -> None:
        task = tasks[index]
        if isinstance(result, TaskLost):
            result = _failed_scan(task, str(result), {}, {"recording": _recording_name(task)})
        done[index] = result
        if progress is not None:
            progress(len(done), len(tasks), f"{task.stem}")

    engine.run(run_scan, tasks, keys=[t.key for t in tasks], on_done=finished)
    return [done[i] for i in range(len(tasks))]


def _object_runs(scans: list[ScanRun]) -> list[ObjectRun]:
    """Scans grouped per object and seed, in task order."""
    groups: dict[tuple[str, int], list[ScanRun]] = {}
    for scan in scans:
        groups.setdefault((scan.task.object, scan.task.seed), []).append(scan)
    runs = []
    for (name, seed), members in groups.items():
        timings: dict[str, float] = {}
        for scan in members:
            if len(members) > 1:  # one scan per method: name the timings for it
                method = scan.task.methods[0]
                timings.update(
                    {
                        k if k.endswith(f"_{method}") else f"{k}_{method}": v
                        for k, v in scan.timings_s.items()
                    }
                )
            else:
                timings.update(scan.timings_s)
        failures = [s.failure for s in members if s.failure]
        runs.append(
            ObjectRun(
                name,
                [row for s in members for row in s.rows],
                timings_s=timings,
                scans=[s.summary for s in members],
                failure="; ".join(failures) or None,
                sweep_rows=[row for s in members for row in s.sweep_rows],
                seed=seed,
            )
        )
    return runs


# --------------------------------------------------------------------------- one scan (worker)


def run_scan(task: ScanTask) -> ScanRun:
    """Record ``recordings/<stem>.mcap``, stitch it once, run one pipeline job per method on it
    (and the leaf sweep, and the self-calibrated fits); known failures become failed rows. Runs
    on a worker."""
    from scrapcut_cli.config import config_from_dict
    from scrapcut_cli.pipeline.fit import stitch_recording_file

    config = config_from_dict(task.config)
    out_dir = Path(task.out_dir)
    rec_path = out_dir / "recordings" / f"{task.stem}.mcap"
    summary: dict[str, Any] = {"recording": _recording_name(task), "seed": task.seed}
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    try:
        recorded = _record(task, config, rec_path)
    except ScrapcutError as exc:
        return _failed_scan(task, f"recording failed: {exc}", timings, summary)
    timings["record"] = time.perf_counter() - t0
    summary.update(_scan_summary(recorded))

    try:
        stitched = stitch_recording_file(rec_path, config=config)
    except ScrapcutError as exc:
        return _failed_scan(task, f"stitching failed: {exc}", timings, summary)
    timings["stitch"] = stitched.time_s
    summary["frames_used"] = stitched.source["frames_used"]
    summary["frames_skipped"] = stitched.source["frames_skipped"]
    summary["paint_points"] = stitched.stitch.size
    scene = None
    if task.motion:
        t0 = time.perf_counter()
        scene = _observed_scene(rec_path, config)
        timings["observe"] = time.perf_counter() - t0

    rows = []
    for method in task.methods:
        t0 = time.perf_counter()
        rows.append(
            _job_row(task, method, stitched, rec_path, config, task.retry_leaf_size_m, None, scene)
        )
        timings[f"fit_{method}"] = time.perf_counter() - t0
    sweep: list[ReportRow] = []
    if FitMethod.SKELETON in task.methods and task.leaf_sweep_m:
        t0 = time.perf_counter()
        for leaf in task.leaf_sweep_m:
            leaf_config = config.override("skeleton", leaf_size_m=leaf)
            stem = f"{task.object}_skeleton_leaf{leaf * 1000:g}mm"
            sweep.append(
                _job_row(task, FitMethod.SKELETON, stitched, rec_path, leaf_config, None, stem)
            )
        timings["leaf_sweep"] = time.perf_counter() - t0
    if task.self_calibrate:
        rows += _self_calibrated_rows(task, config, rec_path, timings)
    return ScanRun(task, rows, sweep, summary, timings)


def _self_calibrated_rows(
    task: ScanTask, config: ScrapcutConfig, rec_path: Path, timings: dict[str, float]
) -> list[ReportRow]:
    """The scan stitched again with the calibration estimated from it, one job per method:
    rows marked ``self_calibrated``, the calibration's verdict in their note."""
    from scrapcut_cli.pipeline.fit import stitch_recording_file

    config = config.override("calibration", self_calibrate=True)
    t0 = time.perf_counter()
    try:
        stitched = stitch_recording_file(rec_path, config=config)
    except ScrapcutError as exc:
        failure = f"self-calibration failed: {exc}"
        return [
            ReportRow(task.object, m, None, failure=failure, self_calibrated=True)
            for m in task.methods
        ]
    finally:
        timings["self_calibrate"] = time.perf_counter() - t0
    record = stitched.calibration or {}
    note = _calibration_note(record)
    extras = _calibration_extras(record)
    rows = []
    for method in task.methods:
        t0 = time.perf_counter()
        stem = f"{task.object}_{method}_selfcal"
        row = _job_row(task, method, stitched, rec_path, config, task.retry_leaf_size_m, stem)
        notes = "; ".join(n for n in (note, row.note) if n)
        rows.append(replace(row, self_calibrated=True, note=notes, extras={**row.extras, **extras}))
        timings[f"fit_selfcal_{method}"] = time.perf_counter() - t0
    return rows


def _record(task: ScanTask, config: ScrapcutConfig, rec_path: Path) -> RecordResult:
    from scrapcut_cli.sim import record

    factory = None
    if config.sim.mode == ScanMode.EXPLORE:
        from scrapcut_cli.exploration.planner import planner_factory

        factory = planner_factory(config.override("exploration", method=task.methods[0]))
    sim = replace(config.sim, object=task.object, seed=task.seed)
    return record(sim, rec_path, planner_factory=factory)


def _job_row(
    task: ScanTask,
    method: str,
    stitched: StitchedRecording,
    rec_path: Path,
    config: ScrapcutConfig,
    retry_leaf_size_m: float | None,
    stem: str | None,
    scene: ObservedScene | None = None,
) -> ReportRow:
    """One pipeline job on the scan's stitched clouds, as a report row naming its path file
    relative to the output folder (which is renamed at the end); with the observed ``scene``,
    the row also says how much of the path the Panda can execute (``panda_*`` extras)."""
    from scrapcut_cli.pipeline.job import Job, run_job

    name = f"{stem or f'{task.object}_{method}'}{task.suffix}.json"
    job = Job(
        rec_path,
        FitMethod(method),
        config,
        output=Path(task.out_dir) / "paths" / name,
        source_name=f"../recordings/{rec_path.name}",
        object_name=task.object,
        retry_leaf_size_m=retry_leaf_size_m,
    )
    result = run_job(job, stitched=stitched)
    row = result.row(task.object)
    extras = {**row.extras, "seed": task.seed}
    if scene is not None and result.ok and result.fit is not None:
        extras.update(_execution(result.fit, scene, result.config))
    return replace(row, source=f"paths/{name}" if result.ok else "", extras=extras)


def _observed_scene(rec_path: Path, config: ScrapcutConfig) -> ObservedScene:
    """What the scan's camera saw (motion.observed), for the trajectories of its paths."""
    from scrapcut_cli.motion.observed import observe
    from scrapcut_cli.recording.reader import open_recording

    with open_recording(rec_path, config.recording) as rec:
        return observe(
            rec.frames(),
            surface_voxel_m=config.motion.collision_voxel_m,
            free_voxel_m=config.motion.unseen_voxel_m,
            perception=config.perception,
            floor_z_m=config.motion.floor_z_m,
        )


def _execution(fit: FitResult, scene: ObservedScene, config: ScrapcutConfig) -> dict[str, Any]:
    """The share of set-points the Panda can execute and why not (``scrapcut trajectory``)."""
    from scrapcut_cli.motion.recipe import execution_figures, plan_for_scene

    try:
        traj = plan_for_scene(fit.path, frame_id=fit.frame_id, scene=scene, config=config)
    except ScrapcutError as exc:
        return {"panda_executable": 0.0, "panda_failure": str(exc)}
    return execution_figures(traj)


def _calibration_note(record: dict[str, Any]) -> str:
    """What the self-calibration concluded, in a few words that stay the same over seeds."""
    observable = record.get("observable", {})
    flags = [*observable.get("translation", []), *observable.get("rotation", [])]
    flags.append(bool(observable.get("time_offset", False)))
    if not record.get("consistent"):
        return "calibration corrected"
    if not any(flags):
        return "calibration not observable: published kept"
    if not all(flags):
        return "calibration consistent where observable"
    return "calibration consistent"


def _calibration_extras(record: dict[str, Any]) -> dict[str, Any]:
    """A self-calibration's correction as row figures (mm, deg, ms; JSON and CSV)."""
    correction = record.get("correction")
    if not correction:
        return {}
    observable = record.get("observable", {})
    flags = [*observable.get("translation", []), *observable.get("rotation", [])]
    flags.append(observable.get("time_offset", False))
    return {
        "calibration_translation_mm": 1000.0 * float(np.linalg.norm(correction["translation_m"])),
        "calibration_rotation_deg": float(np.linalg.norm(correction["rotation_deg"])),
        "calibration_clock_ms": 1000.0 * float(correction["time_offset_s"]),
        "calibration_observable": f"{sum(bool(f) for f in flags)}/{len(flags)}",
    }


def _failed_scan(
    task: ScanTask, failure: str, timings: dict[str, float], summary: dict[str, Any]
) -> ScanRun:
    summary = {**summary, "failure": failure}
    rows = [ReportRow(task.object, m, None, failure=failure) for m in task.methods]
    if task.self_calibrate:
        rows += [
            ReportRow(task.object, m, None, failure=failure, self_calibrated=True)
            for m in task.methods
        ]
    return ScanRun(task, rows, [], summary, timings, failure=failure)


def _recording_name(task: ScanTask) -> str:
    return f"recordings/{task.stem}.mcap"


def _scan_summary(recorded: RecordResult) -> dict[str, Any]:
    """The scalar figures of the simulator's RecordResult (views, collisions, travel...)."""
    values = {f.name: getattr(recorded, f.name) for f in dataclasses.fields(recorded)}
    return {k: v for k, v in values.items() if isinstance(v, int | float | str | bool)}


# --------------------------------------------------------------------------- checks and output


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
    raise PipelineError(f"cannot write {value!r} to TOML")


def seeds_text(seeds: Sequence[int]) -> str:
    """``seed 0``, ``seeds 0–9 (10)`` or ``seeds 0, 3, 7 (3)``."""
    seeds = list(seeds)
    if len(seeds) == 1:
        return f"seed {seeds[0]}"
    if seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"seeds {seeds[0]}–{seeds[-1]} ({len(seeds)})"
    return f"seeds {', '.join(map(str, seeds))} ({len(seeds)})"


def _write_reports(
    out_dir: Path,
    runs: list[ObjectRun],
    *,
    config: ScrapcutConfig,
    options: dict[str, Any],
    wall_time_s: float,
    command: str,
) -> tuple[str, str]:
    """report.md, report.json, report.csv, config.toml and config.json.

    Returns the markdown and its part the README shows (the run's description and Table I).
    """
    paper = load_paper_table()
    rows = [row for run in runs for row in run.rows]
    seeds = options["seeds"]
    created = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    machine = machine_description()
    about = [
        f"- command: `{command}`",
        f"- date: {created}, scrapcut {__version__}",
        f"- machine: {machine}",
        f"- wall time: {wall_time_s:.1f} s on {options['engine']}",
        f"- scans: {options['mode']} mode, {options['noise']} noise, "
        f"{options['width']}×{options['height']} px, {seeds_text(seeds)}",
        "",
    ]
    aggregates = aggregate_rows(rows)
    if len(seeds) > 1:
        table = render_interval_markdown(aggregates, paper=paper)
    else:
        table = render_markdown(rows, paper=paper)
    section = "\n".join(about) + "\n" + table
    body = table + _execution_markdown(rows)
    sweep_rows = [row for run in runs for row in run.sweep_rows]
    if sweep_rows:
        sweep = (
            render_markdown(sweep_rows)
            if len(seeds) == 1
            else render_interval_markdown(aggregate_rows(sweep_rows))
        )
        body += (
            "\n### Skeleton leaf-size sweep (the paper's Fig. 3)\n\n"
            "The skeleton fitted at each leaf size to the same stitched cloud, no retry.\n\n"
            + sweep
        )
    timing_lines = [
        "",
        "### Runs",
        "",
        "| Object | Seed | Scan | Timings [s] |",
        "|---|---:|---|---|",
    ]
    for run in runs:
        scans = "<br>".join(
            f"{s['recording']}: " + ", ".join(f"{k} {_fmt(s[k])}" for k in SCAN_KEYS if k in s)
            for s in run.scans
        )
        timings = ", ".join(f"{k} {v:.1f}" for k, v in run.timings_s.items())
        timing_lines.append(f"| {run.object} | {run.seed} | {scans} | {timings} |")
    figures = sorted((out_dir / "plots").glob("*.png")) if (out_dir / "plots").is_dir() else []
    figure_lines = ["", f"### Figures ({seeds_text(seeds[:1])})", ""]
    figure_lines += [f"![{p.stem}](plots/{p.name})" for p in figures]
    title = ["# Table I reproduced on the simulator", ""]
    markdown = "\n".join(title + about) + "\n" + body + "\n".join(timing_lines) + "\n"
    if figures:
        markdown += "\n".join(figure_lines) + "\n"
    write_text_atomic(out_dir / "report.md", markdown)
    from scrapcut_cli.evaluation.html import markdown_to_html

    # The same report as one page to share, the figures embedded.
    images = {f"plots/{p.name}": p.read_bytes() for p in figures}
    page = markdown_to_html(markdown, title="scrapcut reproduce: Table I", images=images)
    write_text_atomic(out_dir / "report.html", page)
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
        "table1": aggregate_records(aggregates, paper=paper),
        "leaf_sweep": rows_to_records(sweep_rows),
        "runs": [
            {
                "object": run.object,
                "seed": run.seed,
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
    return markdown, section


def _execution_markdown(rows: Sequence[ReportRow]) -> str:
    """What the Panda can execute of each path (``scrapcut trajectory``), when planned."""
    planned = [row for row in rows if "panda_executable" in row.extras]
    if not planned:
        return ""
    lines = [
        "",
        "### What the Panda can execute",
        "",
        "Each path planned as `scrapcut trajectory` does (default torch mount, the scan's depth "
        "as the observed surface, unseen space near the piece avoided).",
        "",
        "| Object | Method | Set-points | Executable | Tilted | Unreachable | In collision "
        "| Cuts | Limits |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for row in sort_rows(planned):
        e = row.extras
        if "panda_failure" in e:
            lines.append(f"| {row.object} | {row.label} | | 0.0% | | | | | {e['panda_failure']} |")
            continue
        lines.append(
            f"| {row.object} | {row.label} | {e['panda_setpoints']} | "
            f"{100 * e['panda_executable']:.1f}% | {e['panda_tilted']} | "
            f"{e['panda_unreachable']} | {e['panda_in_collision']} | {e['panda_cuts']} | "
            f"{'ok' if e['panda_limits_ok'] else 'exceeded'} |"
        )
    return "\n".join(lines) + "\n"


def _fmt(value: Any) -> str:
    return f"{value:.2f}" if isinstance(value, float) else str(value)
