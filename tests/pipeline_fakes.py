"""A stand-in for reproduce's simulated scan: rows whose curves lie a known distance off a
straight reference (seed s: s + 1 mm; self-calibrated rows a tenth of that), so reports over
seeds have figures known in advance."""

from __future__ import annotations

import numpy as np

from scrapcut_cli.evaluation.metrics import path_error
from scrapcut_cli.evaluation.report import ReportRow
from scrapcut_cli.pipeline.reproduce import ScanRun, ScanTask

REFERENCE = np.column_stack([np.linspace(0, 0.3, 31), np.zeros(31), np.zeros(31)])


def fake_scan(task: ScanTask) -> ScanRun:
    """One row per method, ``task.seed + 1`` millimetres off :data:`REFERENCE`; no files."""
    offset = np.array([0.0, 0.001 * (task.seed + 1), 0.0])
    rows = [
        ReportRow(task.object, method, path_error(REFERENCE + offset, REFERENCE),
                  extras={"seed": task.seed})
        for method in task.methods
    ]  # fmt: skip
    if task.self_calibrate:  # self-calibrated rows a tenth as far off
        rows += [
            ReportRow(task.object, method, path_error(REFERENCE + offset / 10, REFERENCE),
                      extras={"seed": task.seed}, self_calibrated=True)
            for method in task.methods
        ]  # fmt: skip
    summary = {"recording": f"recordings/{task.stem}.mcap", "seed": task.seed, "views": 3}
    return ScanRun(task, rows, [], summary, {"record": 0.1})
