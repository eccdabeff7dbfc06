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

import csv
import datetime
import glob
import hashlib
import io
import itertools
import json
import os
import socket
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scrapcut_cli import __version__
from scrapcut_cli._io import write_text_atomic
from scrapcut_cli.config import FitMethod, ScrapcutConfig, choice_names, config_from_dict
from scrapcut_cli.errors import ConfigError, PipelineError
from scrapcut_cli.pipeline.engine import Engine, TaskLost

SCHEMA = "scrapcut.batch/v1"
#: File name suffixes of recordings found in a folder (ROS 2 bag folders are found too).
RECORDING_SUFFIXES = (".mcap", ".bag")
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
#: Read in chunks of this many bytes while hashing.
_HASH_CHUNK = 1 << 20

ProgressFn = Callable[[int, int, str], None]


# --------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class BatchInput:
    """One recording of the batch, with its own paint (preset or H1,H2,S,V) and reference."""

    recording: Path
    name: str
    paint: str | None = None
    hsv: str | None = None
    reference: Path | None = None


def collect_inputs(
    sources: Sequence[str | Path], *, reference: Path | None = None
) -> list[BatchInput]:
    """Recordings from files, bag folders, folders of recordings, globs and manifests.

    ``reference`` is the default for inputs without their own. Raises PipelineError naming the
    first source that is missing, empty or malformed.
    """
    if not sources:
        raise PipelineError("no recordings given")
    inputs: list[BatchInput] = []
    for source in sources:
        text = str(source)
        path = Path(text)
        if any(c in text for c in "*?[") and not path.exists():
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise PipelineError(f"no recording matches {text!r}")
            inputs += [_input(Path(m), reference=reference) for m in matches]
        elif path.suffix.lower() in (".csv", ".toml") and path.is_file():
            inputs += read_manifest(path, reference=reference)
        elif not path.exists():
            raise PipelineError(f"recording not found: {path}")
        elif path.is_dir() and not (path / "metadata.yaml").is_file():
            found = _recordings_in(path)
            if not found:
                raise PipelineError(f"{path} holds no recordings (.mcap, .bag, ROS 2 bag folders)")
            inputs += [_input(p, reference=reference) for p in found]
        else:
            inputs.append(_input(path, reference=reference))
    unique: dict[tuple[Any, ...], BatchInput] = {}
    for item in inputs:
        key = (item.recording.resolve(), item.paint, item.hsv, item.reference)
        unique.setdefault(key, item)
    return list(unique.values())


def _input(path: Path, *, reference: Path | None, **options: Any) -> BatchInput:
    name = path.parent.name if path.name == "metadata.yaml" else path.stem
    return BatchInput(
        recording=path, name=options.pop("name", None) or name, reference=reference, **options
    )


def _recordings_in(folder: Path) -> list[Path]:
    found = []
    for path in sorted(folder.iterdir()):
        recording = path.is_file() and path.suffix.lower() in RECORDING_SUFFIXES
        if recording or (path.is_dir() and (path / "metadata.yaml").is_file()):
            found.append(path)
    return found


MANIFEST_KEYS = ("recording", "paint", "hsv", "reference", "name")


def read_manifest(path: Path, *, reference: Path | None = None) -> list[BatchInput]:
    """A manifest's recordings: CSV (header ``recording,paint,hsv,reference,name``; only
    ``recording`` required) or TOML (``[[recording]]`` tables with ``path`` and those keys)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise PipelineError(f"cannot read manifest {path}: {exc}") from None
    entries: list[dict[str, Any]]
    if path.suffix.lower() == ".toml":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise PipelineError(f"manifest {path}: {exc}") from None
        tables = data.get("recording")
        if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
            raise PipelineError(f"manifest {path}: expected [[recording]] tables with a path")
        entries = [{("recording" if k == "path" else k): v for k, v in t.items()} for t in tables]
    else:
        reader = csv.DictReader(io.StringIO(text))
        header = [h.strip() for h in reader.fieldnames or []]
        if "recording" not in header:
            raise PipelineError(f"manifest {path}: the header must name a 'recording' column")
        entries = [{(k or "").strip(): (v or "").strip() for k, v in row.items()} for row in reader]
    if not entries:
        raise PipelineError(f"manifest {path} lists no recordings")
    out = []
    for i, entry in enumerate(entries, start=1):
        unknown = sorted(set(entry) - set(MANIFEST_KEYS) - {""})
        if unknown:
            raise PipelineError(
                f"manifest {path}: unknown column(s) {', '.join(unknown)}; known: "
                f"{', '.join(MANIFEST_KEYS)}"
            )
        rec = entry.get("recording")
        if not isinstance(rec, str) or not rec:
            raise PipelineError(f"manifest {path}: entry {i} names no recording")
        recording = _relative_to(path, rec)
        if not recording.exists():
            raise PipelineError(f"manifest {path}: entry {i}: recording not found: {recording}")
        own_reference = entry.get("reference") or None
        out.append(
            _input(
                recording,
                reference=_relative_to(path, own_reference) if own_reference else reference,
                paint=_text(entry.get("paint")),
                hsv=_text(entry.get("hsv")),
                name=_text(entry.get("name")),
            )
        )
    return out


def _relative_to(manifest: Path, value: str) -> Path:
    p = Path(value).expanduser()
    return p if p.is_absolute() else manifest.parent / p


def _text(value: Any) -> str | None:
    return None if value in (None, "") else str(value)


# --------------------------------------------------------------------------- grid


#: The grid axis that chooses the fitting method (every other axis is ``section.key``).
METHOD_AXIS = "method"


def load_grid(path: Path | None, *, methods: Sequence[str] = ()) -> dict[str, list[Any]]:
    """Grid axes in file order: ``method`` and ``section.key`` → the values to try.

    ``methods`` (``--methods``) is the method axis when the file has none (default nurbs).
    Every key is checked against the configuration at once (a typo fails before any run).
    """
    data: dict[str, Any] = {}
    if path is not None:
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise PipelineError(f"grid file not found: {path}") from None
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise PipelineError(f"cannot read grid {path}: {exc}") from None
    grid: dict[str, list[Any]] = {}
    where = str(path) if path is not None else "grid"
    for key, value in data.items():
        if isinstance(value, dict):
            for name, values in value.items():
                grid[f"{key}.{name}"] = _values(values)
        else:
            grid[key] = _values(value)
    if METHOD_AXIS in grid and methods:
        raise PipelineError(f"{where} sets the method; drop --methods or the grid's 'method'")
    if METHOD_AXIS not in grid:
        grid = {METHOD_AXIS: list(methods or [FitMethod.NURBS.value]), **grid}
    known = choice_names(FitMethod)
    for method in grid[METHOD_AXIS]:
        if method not in known:
            raise PipelineError(f"{where}: unknown method {method!r}; known: {', '.join(known)}")
    for axis, values in grid.items():
        if not values:
            raise PipelineError(f"{where}: {axis} has no values")
        if axis == METHOD_AXIS:
            continue
        section, _, name = axis.partition(".")
        if not name or "." in name:
            raise PipelineError(f"{where}: {axis!r} is not a [section] key or 'method'")
        for value in values:
            try:
                ScrapcutConfig().override(section, **{name: value})
            except AttributeError:
                raise PipelineError(f"{where}: unknown section [{section}]") from None
            except ConfigError as exc:
                raise PipelineError(f"{where}: {exc}") from None
    return grid


def _values(value: Any) -> list[Any]:
    return list(value) if isinstance(value, list) else [value]


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
                output=str(out_dir / "paths" / f"{_slug(item.name)}_{method}_{key[:12]}.json"),
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


def content_hash(path: Path) -> str:
    """sha256 of a file's bytes, or of a folder's files (relative names and bytes, sorted)."""
    digest = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    if not files:
        raise PipelineError(f"{path} is empty")
    for file in files:
        if file != path:
            digest.update(str(file.relative_to(path)).encode() + b"\0")
        try:
            with file.open("rb") as fh:
                while chunk := fh.read(_HASH_CHUNK):
                    digest.update(chunk)
        except OSError as exc:
            raise PipelineError(f"cannot read {file}: {exc.strerror or exc}") from None
    return digest.hexdigest()


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name) or "recording"


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


# --------------------------------------------------------------------------- table and report


def write_table(rows: list[dict[str, Any]], out_dir: Path) -> tuple[Path, Path]:
    """``batch.parquet`` and ``batch.csv``: one row per run, the union of the rows' columns."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from scrapcut_cli._io import atomic_path

    columns = list(dict.fromkeys(k for row in rows for k in row))
    records = [{c: _cell(row.get(c)) for c in columns} for row in rows]
    parquet, csv_path = out_dir / "batch.parquet", out_dir / "batch.csv"
    table = pa.Table.from_pylist(records) if records else pa.table({})
    with atomic_path(parquet) as tmp:
        pq.write_table(table, tmp)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for record in records:
        writer.writerow({k: "" if v is None else v for k, v in record.items()})
    write_text_atomic(csv_path, buffer.getvalue())
    return parquet, csv_path


def _cell(value: Any) -> Any:
    """Columns hold scalars: lists and dicts become JSON text."""
    if isinstance(value, list | dict | tuple):
        return json.dumps(value)
    return value


def aggregate(rows: Sequence[dict[str, Any]], axis: str) -> list[dict[str, Any]]:
    """Per value of ``axis`` (and method): runs, failures, and the error figures over the runs
    that succeeded — mean of the means, mean SD across runs, worst max, mean coverage."""
    import numpy as np

    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for row in rows:
        value = row.get(axis)
        if value is None:
            continue
        groups.setdefault((str(row.get("method")), json.dumps(value)), []).append(row)
    out = []
    for (method, value), members in sorted(
        groups.items(), key=lambda kv: (kv[0][0], _sortable(kv[0][1]))
    ):
        ok = [r for r in members if r.get("status") == "ok" and r.get("mean_mm") is not None]
        means = np.array([r["mean_mm"] for r in ok], dtype=np.float64)
        entry: dict[str, Any] = {
            "axis": axis,
            "value": json.loads(value),
            "method": method,
            "runs": len(members),
            "failed": sum(1 for r in members if r.get("status") != "ok"),
            "measured": len(ok),
            "mean_mm": float(means.mean()) if len(ok) else None,
            "mean_mm_sd": float(means.std(ddof=1)) if len(ok) > 1 else None,
            "max_mm": max((r["max_mm"] for r in ok), default=None),
            "coverage": float(np.mean([r["coverage"] for r in ok])) if ok else None,
            "time_s": float(np.mean([r.get("time_total_s") or 0.0 for r in members])),
        }
        out.append(entry)
    return out


def _sortable(value_json: str) -> tuple[int, Any]:
    value = json.loads(value_json)
    return (
        (0, value)
        if isinstance(value, int | float) and not isinstance(value, bool)
        else (1, str(value))
    )


def write_report(
    result: BatchResult,
    *,
    grid: dict[str, list[Any]],
    engine: str,
    command: str,
    plots: bool = True,
) -> str:
    """``report.md`` and ``report.json``: what ran, aggregates per parameter value, plots."""
    from scrapcut_cli.pipeline.reproduce import machine_description

    out_dir, rows = result.out_dir, result.rows
    created = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    axes = [METHOD_AXIS, *result.axes]
    tables = {axis: aggregate(rows, axis) for axis in axes}
    figures = _write_plots(tables, out_dir / "plots") if plots else []
    recordings = len({r["recording_sha256"] for r in rows})
    lines = [
        "# scrapcut batch",
        "",
        f"- command: `{command}`",
        f"- date: {created}, scrapcut {__version__}",
        f"- machine: {machine_description()}",
        f"- engine: {engine}",
        f"- runs: {len(rows)} ({recordings} recording(s) × grid), {result.ran} run now, "
        f"{result.cached} finished before, {result.failed} failed, {result.lost} lost",
        f"- wall time: {result.wall_time_s:.1f} s",
        "",
        "Error figures in millimetres against each recording's reference; coverage = share of "
        "reference samples within the threshold; failed runs are counted, not averaged.",
    ]
    for axis, entries in tables.items():
        lines += ["", f"### {axis}", ""]
        lines.append(
            "| Value | Method | Runs | Failed | Mean [mm] | SD of means [mm] | Worst max [mm] "
            "| Coverage | Time [s] |"
        )
        lines.append("|---|---|---:|---:|---:|---:|---:|---:|---:|")
        for e in entries:
            lines.append(
                f"| {e['value']} | {e['method']} | {e['runs']} | {e['failed']} | "
                f"{_num(e['mean_mm'])} | {_num(e['mean_mm_sd'])} | {_num(e['max_mm'])} | "
                f"{_pct(e['coverage'])} | {e['time_s']:.1f} |"
            )
    failures = [r for r in rows if r["status"] != "ok"]
    if failures:
        lines += [
            "",
            "### Failed runs",
            "",
            "| Recording | Method | Parameters | Why |",
            "|---|---|---|---|",
        ]
        for r in failures[:50]:
            params = ", ".join(f"{a} {r.get(a)}" for a in result.axes if r.get(a) is not None)
            why = str(r.get("failure") or r.get("error_status")).replace("|", "\\|")
            lines.append(f"| {r['name']} | {r['method']} | {params} | {why} |")
    if figures:
        lines += ["", "### Figures", ""] + [f"![{p.stem}](plots/{p.name})" for p in figures]
    markdown = "\n".join(lines) + "\n"
    write_text_atomic(out_dir / "report.md", markdown)
    report = {
        "schema": SCHEMA,
        "tool_version": __version__,
        "created": created,
        "command": command,
        "engine": engine,
        "grid": grid,
        "runs": len(rows),
        "ran": result.ran,
        "cached": result.cached,
        "failed": result.failed,
        "lost": result.lost,
        "wall_time_s": result.wall_time_s,
        "aggregates": tables,
    }
    write_text_atomic(out_dir / "report.json", json.dumps(report, indent=2) + "\n")
    return markdown


def _write_plots(tables: dict[str, list[dict[str, Any]]], out_dir: Path) -> list[Path]:
    """Mean error (± SD of the means) against each numeric parameter, one line per method."""
    from scrapcut_cli.evaluation.plots import plot_parameter_study

    written = []
    for axis, entries in tables.items():
        numeric = [
            e
            for e in entries
            if isinstance(e["value"], int | float)
            and not isinstance(e["value"], bool)
            and e["mean_mm"] is not None
        ]
        if len({e["value"] for e in numeric}) < 2:
            continue
        series: dict[str, tuple[list[float], list[float], list[float]]] = {}
        for e in sorted(numeric, key=lambda e: e["value"]):
            xs, ys, sds = series.setdefault(e["method"], ([], [], []))
            xs.append(float(e["value"]))
            ys.append(float(e["mean_mm"]))
            sds.append(float(e["mean_mm_sd"] or 0.0))
        written.append(
            plot_parameter_study(
                series,
                out_dir / f"{_slug(axis)}.png",
                xlabel=axis,
                title=f"error against {axis}",
            )
        )
    return written


def _num(value: float | None) -> str:
    return "—" if value is None else f"{value:.2f}"


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{100 * value:.1f}%"
