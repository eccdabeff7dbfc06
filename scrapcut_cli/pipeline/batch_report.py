"""The results of ``scrapcut batch``: the table (Parquet and CSV) and the report.

The report aggregates the rows per value of each grid parameter (and method): runs, failures,
the mean of the runs' mean errors and its spread, the worst max, the mean coverage — and draws,
for each numeric parameter, the mean error against its value per method (the paper's Fig. 3,
for any parameter).
"""

from __future__ import annotations

import csv
import datetime
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from scrapcut_cli import __version__
from scrapcut_cli._io import write_text_atomic
from scrapcut_cli.pipeline.batch_inputs import METHOD_AXIS, slug

if TYPE_CHECKING:
    from scrapcut_cli.pipeline.batch import BatchResult

SCHEMA = "scrapcut.batch/v1"


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
                out_dir / f"{slug(axis)}.png",
                xlabel=axis,
                title=f"error against {axis}",
            )
        )
    return written


def _num(value: float | None) -> str:
    return "—" if value is None else f"{value:.2f}"


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{100 * value:.1f}%"
