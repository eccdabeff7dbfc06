"""Table I: rows of object × method, the paper's figures beside ours, and four renderers.

Renderers return text (markdown, CSV, JSON) or a rich renderable (the screen table); none of
them prints. Figures are millimetres in every rendering; ``coverage`` stays a share (0–1) in
the machine-readable ones and a percentage on screen and in markdown.

A row measured on a simulator *sweep* (views that follow the true reference line: an oracle no
real cell has) is labelled "oracle views" in every rendering (its label, ``oracle_views`` in JSON
and CSV), so it is never mistaken for a result of the explored scans. A row fitted with the
hand-eye and clock calibration estimated from its own scan (``fit --self-calibrate``) is labelled
"self-calibrated" (``self_calibrated`` in JSON and CSV) and kept apart from the plain row.

Against the paper a figure of ours is *worse* when, rounded to the paper's two decimals, it is
larger than the paper's (every Table I column is an error, so larger is worse, the minimum
included). Failed fits are worse on every figure.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli._io import read_text_input
from scrapcut_cli.errors import EvaluationError, FileError
from scrapcut_cli.evaluation.metrics import PathError, SetpointError

if TYPE_CHECKING:
    from rich.table import Table

    from scrapcut_cli.evaluation.align import Alignment

#: The Table I columns, in the paper's order.
TABLE1_FIELDS = ("mean_mm", "sd_mm", "min_mm", "max_mm")
_TITLES = {"mean_mm": "Mean", "sd_mm": "SD", "min_mm": "Min", "max_mm": "Max"}

#: What the paper's Table I does not say in its cells (Section V-A).
PAPER_NOTES = {("basket", "skeleton"): "20 mm leaf (5 mm broke)"}

#: Marks a figure worse than the paper's.
WORSE_MARK = "▲"
#: Label of rows whose scan followed the true line (simulator sweep mode).
ORACLE_LABEL = "oracle views"
#: Label of rows fitted with the calibration estimated from their own scan.
SELF_CALIBRATED_LABEL = "self-calibrated"


@dataclass(frozen=True)
class PaperFigures:
    """One row of the paper's Table I, millimetres."""

    mean_mm: float
    sd_mm: float
    min_mm: float
    max_mm: float
    note: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {
            "mean_mm": self.mean_mm,
            "sd_mm": self.sd_mm,
            "min_mm": self.min_mm,
            "max_mm": self.max_mm,
            "note": self.note,
        }


PaperTable = dict[tuple[str, str], PaperFigures]


def load_paper_table(path: str | Path | None = None) -> PaperTable:
    """The paper's Table I keyed by (object, method); default: the bundled copy.

    The CSV has the header ``object,method,mean_mm,sd_mm,min_mm,max_mm``.
    """
    if path is None:
        text = resources.files("scrapcut_cli").joinpath("data/paper_table1.csv").read_text("utf-8")
        where = "bundled paper_table1.csv"
    else:
        try:
            text = read_text_input(path, "paper table", max_bytes=1 << 24)
        except FileError as exc:
            raise EvaluationError(f"cannot read the paper table: {exc}") from None
        where = str(path)
    rows = list(csv.DictReader(io.StringIO(text)))
    needed = {"object", "method", *TABLE1_FIELDS}
    if not rows or not needed <= set(rows[0]):
        raise EvaluationError(f"{where}: expected columns {', '.join(sorted(needed))}")
    table: PaperTable = {}
    for row in rows:
        key = (row["object"], row["method"])
        try:
            values = [float(row[f]) for f in TABLE1_FIELDS]
        except ValueError:
            raise EvaluationError(f"{where}: non-numeric figure in the row for {key}") from None
        mean, sd, lo, hi = values
        table[key] = PaperFigures(mean, sd, lo, hi, note=PAPER_NOTES.get(key, ""))
    return table


@dataclass(frozen=True, eq=False)
class ReportRow:
    """One object × method result: the metric, or why there is none.

    ``params`` are the method's parameters from the path file (``leaf_size_m`` for the
    skeleton); ``note`` says anything the figures alone do not (a retry at a larger leaf);
    ``failure`` is the one-line reason when the path could not be made; ``curve_points`` and
    ``reference_points`` ((N, 3) metres, base frame) are kept for the plots, not rendered;
    ``oracle_views`` marks a scan whose views followed the true line (a simulator sweep);
    ``extras`` holds further per-row figures (name → number or text), rendered in JSON and CSV;
    ``name`` labels the row by its path file's name; ``setpoints`` scores its set-points;
    ``warnings`` name what makes the figures suspect; ``alignment`` and ``aligned_error`` are
    the rigid alignment and the shape error after it (``eval --align``); ``frame_id`` the frame
    of every coordinate; ``setpoint_surface_points`` ((K, 3) metres) and ``setpoint_flags`` the
    set-points scored (kept for ``--save-results``, not rendered).
    ``self_calibrated`` marks a fit whose frames were posed with the calibration estimated
    from the scan itself.
    """

    object: str
    method: str
    error: PathError | None
    params: dict[str, Any] = field(default_factory=dict)
    note: str = ""
    failure: str | None = None
    source: str = ""
    curve_points: NDArray[np.float64] | None = None
    reference_points: NDArray[np.float64] | None = None
    oracle_views: bool = False
    extras: dict[str, Any] = field(default_factory=dict)
    name: str = ""
    setpoints: SetpointError | None = None
    warnings: tuple[str, ...] = ()
    alignment: Alignment | None = None
    aligned_error: PathError | None = None
    frame_id: str = ""
    setpoint_surface_points: NDArray[np.float64] | None = None
    setpoint_flags: tuple[tuple[str, ...], ...] = ()
    self_calibrated: bool = False

    @property
    def leaf_size_m(self) -> float | None:
        """The skeleton leaf size in metres, if the method has one."""
        return leaf_size_from_params(self.params)

    @property
    def label(self) -> str:
        """Method name, with the leaf size when there is one (``skeleton 5 mm``),
        ``, self-calibrated`` for a self-calibrated fit and ``(oracle views)`` for a sweep's
        row."""
        return _decorated_label(_plain_label(self), self.self_calibrated, self.oracle_views)

    def figures_mm(self) -> dict[str, Any] | None:
        """The metric in millimetres (``PathError.summary_mm``), or None for a failed row."""
        return None if self.error is None else self.error.summary_mm()

    def aligned_mm(self) -> dict[str, Any] | None:
        """Shape error after the rigid alignment and the alignment itself (mm, deg), or None."""
        if self.alignment is None or self.aligned_error is None:
            return None
        aligned = self.aligned_error.summary_mm()
        return {
            "aligned_mean_mm": aligned["mean_mm"],
            "aligned_rmse_mm": aligned["rmse_mm"],
            "aligned_max_mm": aligned["max_mm"],
            "aligned_coverage": aligned["coverage"],
            "align_translation_mm": self.alignment.translation_m * 1000.0,
            "align_rotation_deg": self.alignment.rotation_deg,
            "align_straight_reference": self.alignment.straight,
            "T_reference_curve": self.alignment.T_ref_curve.tolist(),
        }


def leaf_size_from_params(params: dict[str, Any]) -> float | None:
    """Leaf size in metres from method parameters (``leaf_size_m`` or ``leaf_size_mm``)."""
    for key, scale in (("leaf_size_m", 1.0), ("leaf_size_mm", 1e-3)):
        value = params.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value) * scale
    return None


def sort_rows(rows: Iterable[ReportRow]) -> list[ReportRow]:
    """Rows ordered by object, method, then leaf size (Table I's order)."""
    return sorted(
        rows,
        key=lambda r: (r.object, r.method, r.self_calibrated, r.leaf_size_m or 0.0, r.source),
    )


def worse_than_paper(row: ReportRow, paper: PaperFigures) -> list[str]:
    """Names of the Table I figures (``mean_mm``...) where ``row`` is worse than the paper."""
    figures = row.figures_mm()
    if figures is None:
        return list(TABLE1_FIELDS)
    return [f for f in TABLE1_FIELDS if round(figures[f], 2) > getattr(paper, f)]


def rows_to_records(
    rows: Sequence[ReportRow], *, paper: PaperTable | None = None
) -> list[dict[str, Any]]:
    """JSON-ready dictionaries, one per row (the fixed keys of docs/path-file.md first)."""
    records = []
    for row in sort_rows(rows):
        figures = row.figures_mm()
        record: dict[str, Any] = {"object": row.object, "method": row.method}
        if figures is None:
            record.update(dict.fromkeys((*TABLE1_FIELDS, "coverage")))
        else:
            record.update(figures)
        leaf = row.leaf_size_m
        record["leaf_size_mm"] = None if leaf is None else leaf * 1000.0
        record["note"] = row.note
        record["failure"] = row.failure
        record["path"] = row.source
        record["params"] = row.params
        record["label"] = row.label
        record["oracle_views"] = row.oracle_views
        record["file"] = row.name or (Path(row.source).name if row.source else "")
        record["frame_id"] = row.frame_id
        if row.setpoints is not None:
            record.update(row.setpoints.summary_mm())
        record["warnings"] = list(row.warnings)
        aligned = row.aligned_mm()
        if aligned is not None:
            record.update(aligned)
        if row.self_calibrated:
            record["self_calibrated"] = True
        record.update(row.extras)
        if paper is not None:
            figures_paper = paper.get((row.object, row.method))
            record["paper"] = None if figures_paper is None else figures_paper.as_dict()
            record["worse_than_paper"] = (
                None if figures_paper is None else worse_than_paper(row, figures_paper)
            )
        records.append(record)
    return records


#: Schema of ``scrapcut eval --json`` (and ``--save-results DIR/results.json``).
EVAL_SCHEMA = "scrapcut.eval/v1"


def render_json(rows: Sequence[ReportRow], *, paper: PaperTable | None = None) -> str:
    """``scrapcut eval --json``: one object, ``schema``, ``tool_version`` and ``rows`` (one
    dictionary per path file, the keys of docs/path-file.md's error report first)."""
    from scrapcut_cli import __version__

    data = {
        "schema": EVAL_SCHEMA,
        "tool_version": __version__,
        "units": "mm",
        "rows": rows_to_records(rows, paper=paper),
    }
    return json.dumps(data, indent=2, allow_nan=False) + "\n"


CSV_FIELDS = (
    "file",
    "object",
    "method",
    "leaf_size_mm",
    *TABLE1_FIELDS,
    "rmse_mm",
    "median_mm",
    "p95_mm",
    "coverage",
    "reverse_mean_mm",
    "reverse_max_mm",
    "length_ratio",
    "sigma_median_mm",
    "within_2sigma",
    "reference_length_mm",
    "curve_length_mm",
    "samples",
    "setpoints",
    "setpoints_flagged",
    "setpoint_mean_mm",
    "setpoint_max_mm",
    "setpoint_coverage",
    "note",
    "warnings",
    "failure",
    "path",
    "frame_id",
    "oracle_views",
)


def render_csv(rows: Sequence[ReportRow], *, paper: PaperTable | None = None) -> str:
    """CSV, one line per row; with ``paper``, ``paper_mean_mm``... and ``worse_than_paper``."""
    columns = list(CSV_FIELDS)
    if any(row.self_calibrated for row in rows):
        columns.append("self_calibrated")
    extras = list(dict.fromkeys(key for row in sort_rows(rows) for key in row.extras))
    columns += [key for key in extras if key not in columns]
    if paper is not None:
        columns += [f"paper_{f}" for f in TABLE1_FIELDS] + ["worse_than_paper"]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for record in rows_to_records(rows, paper=paper):
        line = {c: record.get(c) for c in columns if not c.startswith("paper_")}
        line.pop("worse_than_paper", None)
        if paper is not None:
            figures_paper = record["paper"] or {}
            for f in TABLE1_FIELDS:
                line[f"paper_{f}"] = figures_paper.get(f)
            worse = record["worse_than_paper"]
            line["worse_than_paper"] = "" if worse is None else ";".join(worse)
        writer.writerow({k: _csv_value(v) for k, v in line.items()})
    return buffer.getvalue()


#: Columns of the screen and markdown tables (markdown inserts the paper's after each figure).
COLUMNS = (
    "Object",
    "Method",
    *(f"{_TITLES[f]} [mm]" for f in TABLE1_FIELDS),
    "Coverage",
    "Rev. mean [mm]",
    "Rev. max [mm]",
    "Length ratio",
    "σ [mm]",
    "≤ 2σ",
    "Note",
)
#: ``scrapcut eval``'s tables (``detail=True``) add the file, the spread of the same distances
#: and the set-points' score; the note then carries the row's warnings (⚠).
DETAIL_FIGURES = ("RMSE [mm]", "Median [mm]", "P95 [mm]")
DETAIL_SETPOINTS = ("Set-points", "Set-pt mean [mm]", "Set-pt cover")
WARNING_MARK = "⚠"


def table_columns(*, detail: bool = False) -> tuple[str, ...]:
    """The column titles of the human-readable tables."""
    if not detail:
        return COLUMNS
    figures_end = 2 + len(TABLE1_FIELDS)
    return (
        "File",
        *COLUMNS[:figures_end],
        *DETAIL_FIGURES,
        *COLUMNS[figures_end:-1],
        *DETAIL_SETPOINTS,
        COLUMNS[-1],
    )


def _first_figure(detail: bool) -> int:
    """Index of the Mean column."""
    return 3 if detail else 2


@dataclass(frozen=True)
class TableLine:
    """One row of the human-readable tables: formatted cells, "worse" flags, paper figures."""

    cells: list[str]
    worse: list[bool]
    paper: list[str] | None  # the paper's mean, SD, min, max, formatted; None: not in Table I
    paper_note: str = ""


def table_lines(
    rows: Sequence[ReportRow], *, paper: PaperTable | None = None, detail: bool = False
) -> list[TableLine]:
    """The rows formatted for :func:`table_columns`, shared by the markdown and rich
    renderers."""
    lines = []
    for row in sort_rows(rows):
        figures = row.figures_mm()
        figures_paper = None if paper is None else paper.get((row.object, row.method))
        worse = set() if figures_paper is None else set(worse_than_paper(row, figures_paper))
        cells = [row.name or Path(row.source).name] if detail else []
        cells += [row.object, row.label]
        cells += ["—" if figures is None else f"{figures[f]:.2f}" for f in TABLE1_FIELDS]
        if detail:
            keys = ("rmse_mm", "median_mm", "p95_mm")
            cells += ["—" if figures is None else f"{figures[k]:.2f}" for k in keys]
        if figures is None:
            cells += ["—"] * 6
        else:
            cells += [
                f"{100.0 * figures['coverage']:.1f}%",
                f"{figures['reverse_mean_mm']:.2f}",
                f"{figures['reverse_max_mm']:.2f}",
                f"{figures['length_ratio']:.3f}",
                _optional(figures.get("sigma_median_mm"), "{:.2f}"),
                _optional(figures.get("within_2sigma"), "{:.1%}"),
            ]
        if detail:
            cells += _setpoint_cells(row.setpoints)
        notes = [n for n in (row.note, row.failure and f"failed: {row.failure}") if n]
        if detail:
            notes += [f"{WARNING_MARK} {w}" for w in row.warnings]
        cells.append("; ".join(notes))
        first = _first_figure(detail)
        flags = [False] * len(cells)
        for k, f in enumerate(TABLE1_FIELDS):
            flags[first + k] = f in worse
        lines.append(
            TableLine(
                cells=cells,
                worse=flags,
                paper=None
                if figures_paper is None
                else [f"{getattr(figures_paper, f):.2f}" for f in TABLE1_FIELDS],
                paper_note="" if figures_paper is None else figures_paper.note,
            )
        )
    return lines


def _setpoint_cells(setpoints: SetpointError | None) -> list[str]:
    """Set-points (flagged), their mean distance and their coverage, for the detail table."""
    if setpoints is None:
        return ["—"] * len(DETAIL_SETPOINTS)
    count = str(setpoints.count)
    if setpoints.flagged_total:
        count += f" ({setpoints.flagged_total} flagged)"
    mean = "—" if setpoints.mean_m is None else f"{setpoints.mean_m * 1000.0:.2f}"
    return [count, mean, f"{100.0 * setpoints.coverage:.1f}%"]


def paper_summary(rows: Sequence[ReportRow], paper: PaperTable) -> str:
    """One sentence: how many shared Table I figures are worse than the paper's, and which."""
    shared = [r for r in sort_rows(rows) if (r.object, r.method) in paper]
    if not shared:
        return "No object × method in common with the paper's Table I."
    worse = [(row, worse_than_paper(row, paper[(row.object, row.method)])) for row in shared]
    total = len(shared) * len(TABLE1_FIELDS)
    n_worse = sum(len(w) for _, w in worse)
    if n_worse == 0:
        return f"All {total} shared Table I figures are at or below the paper's."
    listing = ", ".join(
        f"{row.object} {row.label} ({', '.join(_TITLES[f].lower() for f in w)})"
        for row, w in worse
        if w
    )
    return f"Worse than the paper on {n_worse} of {total} shared figures: {listing}."


def render_markdown(
    rows: Sequence[ReportRow],
    *,
    paper: PaperTable | None = None,
    title: str | None = None,
    detail: bool = False,
) -> str:
    """A GitHub-flavoured markdown table; with ``paper``, the paper's figure follows each of
    ours and figures worse than the paper carry ``▲``; ``detail``: ``scrapcut eval``'s columns
    (file, RMSE, median, P95, set-points, warnings)."""
    columns = table_columns(detail=detail)
    first = _first_figure(detail)
    figure_columns = range(first, first + len(TABLE1_FIELDS))
    header: list[str] = []
    for i, name in enumerate(columns):
        header.append(name)
        if paper is not None and i in figure_columns:
            header.append(f"{_TITLES[TABLE1_FIELDS[i - first]]} paper")
    text = []
    if title:
        text += [f"### {title}", ""]
    text.append("| " + " | ".join(header) + " |")
    align = ["---"] * first + ["---:"] * (len(header) - first - 1) + ["---"]
    text.append("|" + "|".join(align) + "|")
    for line in table_lines(rows, paper=paper, detail=detail):
        cells: list[str] = []
        for i, (cell, worse) in enumerate(zip(line.cells, line.worse, strict=True)):
            if i == len(columns) - 1 and line.paper_note:
                cell = "; ".join(c for c in (cell, f"paper: {line.paper_note}") if c)
            cells.append(f"{cell} {WORSE_MARK}" if worse else cell)
            if paper is not None and i in figure_columns:
                cells.append("—" if line.paper is None else line.paper[i - first])
        text.append("| " + " | ".join(_md_escape(c) for c in cells) + " |")
    text.append("")
    text.append(
        "Distances in millimetres from each reference sample (every "
        f"{_spacing_mm(rows)} mm) to the fitted curve; coverage = share of samples within "
        f"{_threshold_mm(rows)} mm; reverse = from the curve back to the reference."
    )
    if detail:
        text.append(
            "Set-points: their surface points against the reference (mean) and the share of "
            f"reference samples they cover; {WARNING_MARK} = a figure to check before trusting "
            "the row."
        )
    if paper is not None:
        text.append(
            f"{WORSE_MARK} = larger (worse) than the paper's figure. " + paper_summary(rows, paper)
        )
    return "\n".join(text) + "\n"


def rich_table(
    rows: Sequence[ReportRow],
    *,
    paper: PaperTable | None = None,
    title: str | None = None,
    detail: bool = False,
) -> Table:
    """A :class:`rich.table.Table`: our row, then the paper's figures in a dim row beneath it;
    figures worse than the paper in red with ``▲``; ``detail`` as :func:`render_markdown`."""
    from rich.table import Table

    columns = table_columns(detail=detail)
    first = _first_figure(detail)
    table = Table(title=title, caption=paper_summary(rows, paper) if paper is not None else None)
    for i, name in enumerate(columns):
        if i < len(columns) - 1:
            header = _rich_escape(name.replace(" [", "\n["))
            table.add_column(header, justify="right" if i >= first else "left", no_wrap=True)
        else:
            table.add_column(name, max_width=60 if detail else 40, overflow="fold")
    for line in table_lines(rows, paper=paper, detail=detail):
        table.add_row(
            *(
                f"[red]{_rich_escape(c)} {WORSE_MARK}[/red]" if m else _rich_escape(c)
                for c, m in zip(line.cells, line.worse, strict=True)
            )
        )
        if line.paper is not None:
            cells = [""] * len(columns)
            cells[first - 1] = "paper"
            cells[first : first + len(TABLE1_FIELDS)] = line.paper
            cells[-1] = _rich_escape(line.paper_note)
            table.add_row(*cells, style="dim")
    return table


def _optional(value: Any, fmt: str) -> str:
    """``value`` formatted, or ``—`` when the path had no such figure (no σ)."""
    return "—" if value is None else fmt.format(value)


def _fmt_leaf(leaf_m: float) -> str:
    mm = leaf_m * 1000.0
    return f"{mm:.0f}" if math.isclose(mm, round(mm), abs_tol=1e-6) else f"{mm:.1f}"


def _spacing_mm(rows: Sequence[ReportRow]) -> str:
    spacings = {r.error.sample_spacing_m for r in rows if r.error is not None}
    return "/".join(f"{s * 1000.0:g}" for s in sorted(spacings)) or "1"


def _threshold_mm(rows: Sequence[ReportRow]) -> str:
    thresholds = {r.error.coverage_threshold_m for r in rows if r.error is not None}
    return "/".join(f"{t * 1000.0:g}" for t in sorted(thresholds)) or "10"


def _csv_value(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, dict):
        return json.dumps(value, sort_keys=True)
    if isinstance(value, list):
        return "; ".join(str(v) for v in value)
    return value


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|")


def _rich_escape(text: str) -> str:
    from rich.markup import escape

    return escape(text)


# --------------------------------------------------------------------------- over seeds

#: The figures averaged over simulator seeds, with a 95 % interval of their mean.
INTERVAL_FIELDS = (
    *TABLE1_FIELDS,
    "coverage",
    "reverse_max_mm",
    "length_ratio",
    "sigma_median_mm",
    "within_2sigma",
)
#: Confidence of the interval around a mean over seeds.
CONFIDENCE = 0.95


@dataclass(frozen=True)
class SeedAggregate:
    """One object × method over several runs (simulator seeds).

    ``mean[f]`` is the mean over the successful runs of figure ``f`` (:data:`INTERVAL_FIELDS`,
    millimetres, coverage a share); ``half_width[f]`` the half width of its 95 % Student-t
    interval (None with fewer than two runs); ``runs`` rows in the group, ``failed`` of them
    without figures; ``labels`` the distinct row labels (a skeleton retried at 20 mm on some
    seeds has two).
    """

    object: str
    method: str
    runs: int
    failed: int
    mean: dict[str, float]
    half_width: dict[str, float | None]
    labels: tuple[str, ...]
    notes: tuple[str, ...]
    oracle_views: bool = False
    self_calibrated: bool = False

    @property
    def label(self) -> str:
        label = self.labels[0] if len(self.labels) == 1 else self.method
        return _decorated_label(label, self.self_calibrated, self.oracle_views)

    def interval_text(self, field_name: str, *, percent: bool = False) -> str:
        """``0.99 ± 0.05`` (or ``99.5 ± 0.4%``); ``—`` when every run failed."""
        if field_name not in self.mean:
            return "—"
        scale = 100.0 if percent else 1.0
        unit = "%" if percent else ""
        digits = 1 if percent else (3 if field_name == "length_ratio" else 2)
        value = f"{scale * self.mean[field_name]:.{digits}f}"
        hw = self.half_width.get(field_name)
        return value + unit if hw is None else f"{value} ± {scale * hw:.{digits}f}{unit}"


def aggregate_rows(rows: Sequence[ReportRow]) -> list[SeedAggregate]:
    """Group rows by object, method, calibration and oracle label; mean and 95 % interval of
    each figure."""
    from scipy import stats

    groups: dict[tuple[str, str, bool, bool], list[ReportRow]] = {}
    for row in sort_rows(rows):
        key = (row.object, row.method, row.self_calibrated, row.oracle_views)
        groups.setdefault(key, []).append(row)
    out = []
    for (obj, method, self_calibrated, oracle), members in groups.items():
        figures = [f for f in (r.figures_mm() for r in members) if f is not None]
        mean: dict[str, float] = {}
        half: dict[str, float | None] = {}
        for name in INTERVAL_FIELDS if figures else ():
            present = [f[name] for f in figures if f.get(name) is not None]
            if not present:  # σ of paths that carry none
                continue
            values = np.array(present, dtype=np.float64)
            mean[name] = float(values.mean())
            n = len(values)
            if n >= 2:
                t = float(stats.t.ppf(0.5 + CONFIDENCE / 2.0, n - 1))
                half[name] = t * float(values.std(ddof=1)) / math.sqrt(n)
            else:
                half[name] = None
        labels = tuple(dict.fromkeys(_plain_label(r) for r in members))
        notes = tuple(dict.fromkeys(n for r in members for n in (r.note, r.failure) if n))
        out.append(
            SeedAggregate(
                object=obj,
                method=method,
                runs=len(members),
                failed=len(members) - len(figures),
                mean=mean,
                half_width=half,
                labels=labels,
                notes=notes,
                oracle_views=oracle,
                self_calibrated=self_calibrated,
            )
        )
    return out


def _plain_label(row: ReportRow) -> str:
    leaf = row.leaf_size_m
    return row.method if leaf is None else f"{row.method} {_fmt_leaf(leaf)} mm"


def _decorated_label(label: str, self_calibrated: bool, oracle_views: bool) -> str:
    """``nurbs`` → ``nurbs, self-calibrated (oracle views)`` as the flags say."""
    if self_calibrated and SELF_CALIBRATED_LABEL not in label:
        label = f"{label}, {SELF_CALIBRATED_LABEL}"
    if oracle_views and ORACLE_LABEL not in label:
        label = f"{label} ({ORACLE_LABEL})"
    return label


def aggregate_records(
    aggregates: Sequence[SeedAggregate], *, paper: PaperTable | None = None
) -> list[dict[str, Any]]:
    """JSON-ready: per object × method, ``<figure>`` (mean over runs) and
    ``<figure>_ci95`` (half width of the interval, None with one run)."""
    records = []
    for agg in aggregates:
        record: dict[str, Any] = {
            "object": agg.object,
            "method": agg.method,
            "label": agg.label,
            "runs": agg.runs,
            "failed": agg.failed,
            "oracle_views": agg.oracle_views,
        }
        if agg.self_calibrated:
            record["self_calibrated"] = True
        for name in INTERVAL_FIELDS:
            record[name] = agg.mean.get(name)
            record[f"{name}_ci95"] = agg.half_width.get(name)
        record["notes"] = list(agg.notes)
        if paper is not None:
            figures_paper = paper.get((agg.object, agg.method))
            record["paper"] = None if figures_paper is None else figures_paper.as_dict()
            record["worse_than_paper"] = (
                None if figures_paper is None else _aggregate_worse(agg, figures_paper)
            )
        records.append(record)
    return records


def _aggregate_worse(agg: SeedAggregate, paper: PaperFigures) -> list[str]:
    """Table I figures whose mean over runs is worse than the paper's single run."""
    if not agg.mean:
        return list(TABLE1_FIELDS)
    return [f for f in TABLE1_FIELDS if round(agg.mean[f], 2) > getattr(paper, f)]


def render_interval_markdown(
    aggregates: Sequence[SeedAggregate], *, paper: PaperTable | None = None
) -> str:
    """Table I as mean ± 95 % interval over runs, the paper's single run after each figure."""
    header = ["Object", "Method", "Runs"]
    for f in TABLE1_FIELDS:
        header.append(f"{_TITLES[f]} [mm]")
        if paper is not None:
            header.append(f"{_TITLES[f]} paper")
    header += ["Coverage", "Rev. max [mm]", "Length ratio", "σ [mm]", "≤ 2σ", "Note"]
    lines = ["| " + " | ".join(header) + " |"]
    lines.append("|" + "|".join(["---", "---"] + ["---:"] * (len(header) - 3) + ["---"]) + "|")
    worse_count = 0
    for agg in aggregates:
        figures_paper = None if paper is None else paper.get((agg.object, agg.method))
        worse = set() if figures_paper is None else set(_aggregate_worse(agg, figures_paper))
        worse_count += len(worse)
        runs = f"{agg.runs - agg.failed}/{agg.runs}"
        cells = [agg.object, agg.label, runs]
        for f in TABLE1_FIELDS:
            text = agg.interval_text(f)
            cells.append(f"{text} {WORSE_MARK}" if f in worse else text)
            if paper is not None:
                cells.append("—" if figures_paper is None else f"{getattr(figures_paper, f):.2f}")
        cells += [
            agg.interval_text("coverage", percent=True),
            agg.interval_text("reverse_max_mm"),
            agg.interval_text("length_ratio"),
            agg.interval_text("sigma_median_mm"),
            agg.interval_text("within_2sigma", percent=True),
            "; ".join(
                [
                    *agg.notes[:2],
                    *((figures_paper.note,) if figures_paper and figures_paper.note else ()),
                ]
            ),
        ]
        lines.append("| " + " | ".join(_md_escape(c) for c in cells) + " |")
    lines.append("")
    lines.append(
        "Each figure is the mean over the runs (simulator seeds) ± the half width of its 95 % "
        "Student-t interval; runs = successful/all. Distances in millimetres from each reference "
        "sample to the fitted curve; coverage = share of samples within the threshold; σ = the "
        "median lateral uncertainty the path file claims at the samples, ≤ 2σ = share of samples "
        "within 2σ of the path (about 95 % when σ is calibrated)."
    )
    if paper is not None:
        lines.append(
            f"{WORSE_MARK} = mean over runs larger (worse) than the paper's single run "
            f"({worse_count} figure(s))."
        )
    return "\n".join(lines) + "\n"


def interval_rich_table(
    aggregates: Sequence[SeedAggregate],
    *,
    paper: PaperTable | None = None,
    title: str | None = None,
) -> Table:
    """The screen version of :func:`render_interval_markdown` (paper's figures in a dim row)."""
    from rich.table import Table

    table = Table(title=title)
    for name in ("Object", "Method", "Runs", *(f"{_TITLES[f]}\n[mm]" for f in TABLE1_FIELDS)):
        table.add_column(
            _rich_escape(name), justify="left" if name in ("Object", "Method") else "right"
        )
    table.add_column("Coverage", justify="right")
    table.add_column("≤ 2σ", justify="right")
    table.add_column("Note", max_width=40, overflow="fold")
    for agg in aggregates:
        figures_paper = None if paper is None else paper.get((agg.object, agg.method))
        worse = set() if figures_paper is None else set(_aggregate_worse(agg, figures_paper))
        cells = [agg.object, agg.label, f"{agg.runs - agg.failed}/{agg.runs}"]
        for f in TABLE1_FIELDS:
            text = _rich_escape(agg.interval_text(f))
            cells.append(f"[red]{text} {WORSE_MARK}[/red]" if f in worse else text)
        cells += [
            agg.interval_text("coverage", percent=True),
            agg.interval_text("within_2sigma", percent=True),
            _rich_escape("; ".join(agg.notes[:1])),
        ]
        table.add_row(*cells)
        if figures_paper is not None:
            table.add_row(
                "", "paper", "1",
                *(f"{getattr(figures_paper, f):.2f}" for f in TABLE1_FIELDS),
                "", "", _rich_escape(figures_paper.note), style="dim",
            )  # fmt: skip
    return table


# --------------------------------------------------------------------------- marked sections

#: A generated section of a Markdown file (the README's tables) lies between these two lines.
SECTION_BEGIN = "<!-- scrapcut:{name} begin (generated: do not edit by hand) -->"
SECTION_END = "<!-- scrapcut:{name} end -->"


def replace_marked_section(text: str, name: str, body: str) -> str:
    """``text`` with the lines between the ``name`` section's markers replaced by ``body``.

    Raises EvaluationError when the markers are missing, repeated or out of order (the file is
    then left for a human to fix, not guessed at).
    """
    begin, end = SECTION_BEGIN.format(name=name), SECTION_END.format(name=name)
    lines = text.splitlines(keepends=True)
    starts = [i for i, line in enumerate(lines) if line.strip() == begin]
    ends = [i for i, line in enumerate(lines) if line.strip() == end]
    if len(starts) != 1 or len(ends) != 1 or ends[0] < starts[0]:
        raise EvaluationError(
            f"expected one '{begin}' line followed by one '{end}' line; found {len(starts)} and "
            f"{len(ends)}"
        )
    body = body if body.endswith("\n") else body + "\n"
    return "".join([*lines[: starts[0] + 1], body, *lines[ends[0] :]])
