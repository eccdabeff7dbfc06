"""The pipeline's last step: the path's error against the reference, and the report files.

Every result is a path file plus its error report (issue 20). Whenever a reference is at hand —
the recording's own /scrapcut/reference (a simulator recording), or one given by the user (a CSV
``x,y,z`` of probed points, or another recording) — the job measures its path with the very code
of ``scrapcut eval`` (:func:`~scrapcut_cli.evaluation.sources.evaluate_path_file` on the path
file's own dictionary, whose floats are written with their shortest round-trip repr) and writes,
beside ``PATH.json``:

- ``PATH.error.json`` — one object with the keys of an ``eval --format json`` row (``object``,
  ``method``, ``mean_mm``, ``sd_mm``, ``min_mm``, ``max_mm``, ``coverage``, ...) plus ``schema``
  (:data:`ERROR_SCHEMA`), ``tool_version``, ``path_file`` and ``reference``;
- ``PATH.error.md`` — the same row as a short Markdown table.

The path file names its report (``"error_report": "PATH.error.json"``). The reference is read
here and nowhere else in the pipeline: the steps before it never see the truth.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from scrapcut_cli import __version__
from scrapcut_cli.config import RecordingConfig, ScrapcutConfig

if TYPE_CHECKING:
    from scrapcut_cli.evaluation.metrics import PathError
    from scrapcut_cli.evaluation.report import ReportRow
    from scrapcut_cli.evaluation.sources import Reference

ERROR_SCHEMA = "scrapcut.error/v1"
#: What a summary says when there is no figure to show.
NO_REFERENCE = "no reference: error not computed"
SKIPPED = "error not computed (--no-eval)"
COMPUTED = "computed"
#: The figures a summary prints (millimetres; coverage a share 0–1).
SUMMARY_KEYS = ("mean_mm", "sd_mm", "min_mm", "max_mm", "coverage", "reverse_max_mm")
#: And against a closed reference: the observed arcs' figures and the unobserved arcs'.
LOOP_SUMMARY_KEYS = (
    "closed",
    "observed_mean_mm",
    "observed_max_mm",
    "observed_coverage",
    "observed_share",
    "observed_from",
    "unobserved_arcs",
    "unobserved_true_arcs",
    "unobserved_reported_mm",
    "unobserved_true_mm",
    "unobserved_extent_error_mm",
    "unobserved_arcs_missed",
    "unobserved_flagged_on_arcs",
    "unobserved_flagged_elsewhere",
)


def error_report_paths(path_file: str | Path) -> tuple[Path, Path]:
    """``(PATH.error.json, PATH.error.md)`` beside the path file ``PATH.json``."""
    path_file = Path(path_file)
    return path_file.with_suffix(".error.json"), path_file.with_suffix(".error.md")


@dataclass(frozen=True, eq=False)
class ErrorReport:
    """The evaluation step's outcome.

    ``status`` is :data:`COMPUTED`, :data:`NO_REFERENCE` or :data:`SKIPPED`; ``row`` the
    ``scrapcut eval`` row when computed; ``reference`` where the reference came from.
    """

    status: str
    row: ReportRow | None = None
    reference: str | None = None

    @property
    def error(self) -> PathError | None:
        return None if self.row is None else self.row.error

    def figures_mm(self) -> dict[str, Any] | None:
        """Every figure of the row in millimetres (``PathError.summary_mm``), or None."""
        return None if self.row is None else self.row.figures_mm()

    def summary(self) -> dict[str, Any] | None:
        """mean, SD, min, max, coverage and reverse max — what a command's summary prints
        (and, against a closed reference, :data:`LOOP_SUMMARY_KEYS`)."""
        figures = self.figures_mm()
        if figures is None:
            return None
        keys = SUMMARY_KEYS + (LOOP_SUMMARY_KEYS if figures.get("closed") else ())
        return {k: figures[k] for k in keys if k in figures}

    def record(self, path_file: str | Path) -> dict[str, Any]:
        """The ``PATH.error.json`` object: an ``eval --format json`` row plus provenance."""
        from scrapcut_cli.evaluation.report import rows_to_records

        assert self.row is not None, "no report without a computed error"
        (row,) = rows_to_records([self.row])
        return {
            "schema": ERROR_SCHEMA,
            "tool_version": __version__,
            "path_file": Path(path_file).name,
            "reference": self.reference,
            **row,
        }

    def markdown(self) -> str:
        """The row as a short Markdown table (``PATH.error.md``)."""
        from scrapcut_cli.evaluation.report import render_markdown

        assert self.row is not None, "no report without a computed error"
        return render_markdown([self.row], title=f"Path error: {Path(self.row.source).name}")


def error_text(figures: dict[str, Any] | None, status: str) -> str:
    """One line for a summary: mean, SD, min, max, coverage, reverse max — or ``status``."""
    if figures is None:
        return status
    f = figures
    text = (
        f"mean {f['mean_mm']:.2f} mm, SD {f['sd_mm']:.2f}, min {f['min_mm']:.2f}, max "
        f"{f['max_mm']:.2f} mm; coverage {100 * f['coverage']:.1f} %; reverse max "
        f"{f['reverse_max_mm']:.2f} mm"
    )
    if f.get("closed"):
        from scrapcut_cli.evaluation.sources import loop_summary

        text += "; " + loop_summary(f)
    return text


def find_reference(
    recording: Path | None,
    given: Path | None,
    *,
    config: RecordingConfig,
) -> Reference | None:
    """The reference a job is measured against: ``given`` (CSV or recording; it must hold one),
    else the recording's own /scrapcut/reference, else None."""
    from scrapcut_cli.evaluation.sources import load_reference, recording_reference

    if given is not None:
        return load_reference(given, config=config)
    if recording is None:
        return None
    return recording_reference(recording, config=config)


def check_reference_given(given: Path | None) -> None:
    """Refuse a ``--reference`` that does not exist before any work is done."""
    from scrapcut_cli.errors import EvaluationError

    if given is not None and not given.exists():
        raise EvaluationError(f"reference not found: {given}")


def evaluate_path_dict(
    path_dict: dict[str, Any],
    path_file: str | Path,
    reference: Reference | None,
    *,
    config: ScrapcutConfig,
    object_name: str | None = None,
    note: str = "",
) -> ErrorReport:
    """Measure the path file ``path_dict`` (to be written at ``path_file``) against
    ``reference`` with ``scrapcut eval``'s code; :data:`NO_REFERENCE` when there is none."""
    from scrapcut_cli.evaluation.sources import evaluate_path_file, path_file_from_dict

    if reference is None:
        return ErrorReport(NO_REFERENCE)
    row = evaluate_path_file(
        path_file_from_dict(path_dict, path_file),
        reference,
        config=config.evaluation,
        object_name=object_name,
        note=note,
    )
    return ErrorReport(COMPUTED, row=row, reference=str(reference.origin))


def write_error_report(report: ErrorReport, path_file: str | Path) -> list[Path]:
    """Write ``PATH.error.json`` and ``PATH.error.md`` (atomically); the files written."""
    from scrapcut_cli._io import write_text_atomic

    if report.row is None:
        return []
    json_path, md_path = error_report_paths(path_file)
    record = report.record(path_file)
    write_text_atomic(json_path, json.dumps(record, indent=2, allow_nan=False) + "\n")
    write_text_atomic(md_path, report.markdown())
    return [json_path, md_path]


def with_source(report: ErrorReport, source: str) -> ErrorReport:
    """The report with its row naming the path file as ``source`` (e.g. relative to a folder)."""
    if report.row is None:
        return report
    return replace(report, row=replace(report.row, source=source))
