"""``scrapcut eval --save-results DIR``: every per-sample error on disk, as evo saves its results.

One folder, written atomically (it appears whole or not at all), with for each path file
(``LABEL`` = the file's name without ``.json``; a repeated name gets ``_2``, ``_3``...):

- ``LABEL.errors.npy`` — (M,) float64, metres: the distance of each reference sample to the
  fitted curve (the numbers behind mean, SD, min, max; ``numpy.load`` reads it);
- ``LABEL.errors.csv`` — the same samples with where they are: ``s`` (normalised arc length
  0–1), ``s_m``, ``x, y, z`` (the reference sample, metres), ``error_m`` (and
  ``aligned_error_m`` with ``--align``); first lines ``# frame_id: ...``, ``# path_file: ...``;
- ``LABEL.setpoints.csv`` — one row per set-point: ``index, x, y, z`` (its surface point),
  ``error_m`` (to the reference) and ``flags``;

and ``results.json``: the rows of ``scrapcut eval --json`` (``scrapcut.eval/v1``).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scrapcut_cli._io import atomic_path
from scrapcut_cli.evaluation.report import ReportRow, render_json, sort_rows
from scrapcut_cli.geometry import PolylineDistance, cumulative_length


def result_labels(rows: Sequence[ReportRow]) -> list[str]:
    """A unique file label per row (sorted as the reports are): the path file's stem."""
    labels: list[str] = []
    seen: dict[str, int] = {}
    for row in sort_rows(rows):
        stem = Path(row.name or row.source or f"{row.object}_{row.method}").stem
        count = seen.get(stem, 0) + 1
        seen[stem] = count
        labels.append(stem if count == 1 else f"{stem}_{count}")
    return labels


def write_results(rows: Sequence[ReportRow], out_dir: str | Path) -> list[str]:
    """Write the folder described above; returns the labels used (one per row, sorted)."""
    ordered = sort_rows(rows)
    labels = result_labels(ordered)
    with atomic_path(out_dir, directory=True) as tmp:
        for row, label in zip(ordered, labels, strict=True):
            if row.error is None:
                continue
            np.save(tmp / f"{label}.errors.npy", np.asarray(row.error.sample_errors_m))
            (tmp / f"{label}.errors.csv").write_text(_samples_csv(row), encoding="utf-8")
            if row.setpoints is not None and row.reference_points is not None:
                (tmp / f"{label}.setpoints.csv").write_text(_setpoints_csv(row), encoding="utf-8")
        (tmp / "results.json").write_text(render_json(ordered), encoding="utf-8")
    return labels


def _header(row: ReportRow) -> list[str]:
    return [f"# frame_id: {row.frame_id}", f"# path_file: {row.source}"]


def _samples_csv(row: ReportRow) -> str:
    assert row.error is not None
    error = row.error
    samples = error.sample_points
    if samples is None:
        samples = np.full((error.samples, 3), np.nan)
    s_m = cumulative_length(samples) if np.isfinite(samples).all() else error.sample_s
    columns = ["s", "s_m", "x", "y", "z", "error_m"]
    table = [error.sample_s, s_m, samples[:, 0], samples[:, 1], samples[:, 2]]
    table.append(error.sample_errors_m)
    if row.aligned_error is not None:
        columns.append("aligned_error_m")
        table.append(row.aligned_error.sample_errors_m)
    buffer = io.StringIO()
    buffer.write("\n".join(_header(row)) + "\n")
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows([repr(float(v)) for v in values] for values in np.column_stack(table))
    return buffer.getvalue()


def _setpoints_csv(row: ReportRow) -> str:
    assert row.setpoints is not None and row.reference_points is not None
    points = np.asarray(row.setpoint_surface_points, dtype=np.float64).reshape(-1, 3)
    errors = PolylineDistance(row.reference_points).distance(points) if len(points) else np.zeros(0)
    buffer = io.StringIO()
    buffer.write("\n".join(_header(row)) + "\n")
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["index", "x", "y", "z", "error_m", "flags"])
    for i, (p, e) in enumerate(zip(points, errors, strict=True)):
        flags = row.setpoint_flags[i] if i < len(row.setpoint_flags) else []
        writer.writerow([i, *(repr(float(v)) for v in p), repr(float(e)), ";".join(flags)])
    return buffer.getvalue()
