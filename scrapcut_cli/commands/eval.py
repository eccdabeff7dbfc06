"""``scrapcut eval PATH.json... [--reference REC|CSV]``: the paper's Table I for path files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from scrapcut_cli.commands._console import err, print_table
from scrapcut_cli.commands._options import (
    build_config,
    config_option,
    config_type,
    output_options,
)

if TYPE_CHECKING:
    from rich.table import Table

    from scrapcut_cli.evaluation.report import ReportRow

FORMATS = ("table", "markdown", "csv", "json")
_SUFFIX_FORMATS = {".md": "markdown", ".markdown": "markdown", ".csv": "csv", ".json": "json"}


@click.command("eval")
@click.argument("paths", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--reference",
    "reference",
    type=click.Path(path_type=Path),
    default=None,
    metavar="REC|CSV",
    help="Reference curve: a recording with /scrapcut/reference or a CSV x,y,z in metres "
    "(default: the recording named in each path file).",
)
@click.option(
    "--object",
    "object_name",
    default=None,
    help="Object name for every row (default: the recording's, else the path file's stem).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(FORMATS),
    default=None,
    help="Output format (default: table on screen; with -o, from the file's suffix).",
)
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print one JSON object (scrapcut.eval/v1: schema, tool_version, rows); as --format json.",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the report to FILE (.md, .csv, .json); the table is still shown.",
)
@click.option("--paper", is_flag=True, help="Show the paper's Table I figures beside ours.")
@click.option(
    "--plot",
    "plot_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Write PNG figures into DIR (error along the curve, paths, leaf-size sweep); an "
    "existing folder with files needs --force (its other files are kept).",
)
@click.option(
    "--save-results",
    "results_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    metavar="DIR",
    help="Write every per-sample error into DIR: LABEL.errors.npy (metres), LABEL.errors.csv "
    "(where each sample is), LABEL.setpoints.csv and results.json (as evo's --save_results).",
)
@click.option(
    "--html",
    "html_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    metavar="FILE.html",
    help="Write one self-contained HTML page: the table, the warnings and the figures "
    "(embedded), to share as one file.",
)
@click.option(
    "--mcap",
    "mcap_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    metavar="FILE.mcap",
    help="Write a review file for Foxglove: every curve, the reference, the curves coloured "
    "by their distance to it, the torches along their axis, the flagged set-points "
    "(docs/foxglove_layout.json shows them).",
)
@click.option(
    "--align",
    is_flag=True,
    help="Also lay each curve rigidly onto the reference (ICP with Umeyama steps, no scale): "
    "the motion is the calibration error, the distances left the shape error.",
)
@click.option(
    "--coverage-mm",
    type=config_type("evaluation.coverage_threshold_m", 1e-3),
    default=None,
    help="Coverage threshold [mm] (default 10).",
)
@config_option
@output_options
def eval_cmd(
    paths: tuple[Path, ...],
    reference: Path | None,
    object_name: str | None,
    fmt: str | None,
    as_json: bool,
    output: Path | None,
    paper: bool,
    plot_dir: Path | None,
    results_dir: Path | None,
    mcap_path: Path | None,
    html_path: Path | None,
    align: bool,
    coverage_mm: float | None,
    config_path: Path | None,
    force: bool,
    parents: bool,
) -> None:
    """Path error of PATH.json files against the painted reference (the paper's Table I).

    Samples the reference every 1 mm and measures the distance to the nearest point of each
    fitted curve: mean, SD, min, max, RMSE, median and P95 in mm, plus coverage (share of
    samples within 10 mm), the reverse distance (curve to reference) and the length ratio. The
    set-points are scored too (their surface points against the reference).

    Refused: a path and a reference in different frames, or one about 1000× the size of the
    other (millimetres read as metres). Warned: coverage near 0, a length ratio far from 1, no
    set-points, flagged set-points, set-points missing along the line.
    """
    from dataclasses import replace

    from scrapcut_cli._io import write_text_atomic
    from scrapcut_cli.evaluation.plots import write_plots
    from scrapcut_cli.evaluation.report import (
        load_paper_table,
        render_csv,
        render_json,
        render_markdown,
        rich_table,
        sort_rows,
    )
    from scrapcut_cli.evaluation.sources import evaluate_path_files

    if as_json:
        if fmt not in (None, "json"):
            raise click.UsageError(f"--json and --format {fmt} contradict each other")
        fmt = "json"
    if output is not None and fmt is None:
        fmt = _SUFFIX_FORMATS.get(output.suffix.lower())
        if fmt is None:
            raise click.BadParameter(
                f"cannot tell the format from {output.name!r}; use .md, .csv, .json or --format",
                param_hint="-o",
            )
    fmt = fmt or "table"
    from scrapcut_cli._io import prepare_output

    for target, option, directory in (
        (output, "-o", False),
        (plot_dir, "--plot", True),
        (results_dir, "--save-results", True),
        (mcap_path, "--mcap", False),
        (html_path, "--html", False),
    ):
        if target is None:
            continue
        prepare_output(target, force=force, parents=parents, directory=directory, option=option)
    config = build_config(config_path)
    config = config.override(
        "evaluation",
        coverage_threshold_m=None if coverage_mm is None else coverage_mm / 1000.0,
    )
    rows = evaluate_path_files(
        paths,
        reference=reference,
        config=config.evaluation,
        recording_config=config.recording,
        align=align,
    )
    if object_name:
        rows = [replace(r, object=object_name) for r in rows]
    table1 = load_paper_table() if paper else None
    table = rich_table(rows, paper=table1, title="Path error (Table I)", detail=True)

    if fmt == "table" and output is None:
        print_table(table)
    else:
        if fmt == "table":
            text = _plain_table(table)
        elif fmt == "markdown":
            text = render_markdown(rows, paper=table1, detail=True)
        elif fmt == "csv":
            text = render_csv(rows, paper=table1)
        else:
            text = render_json(rows, paper=table1)
        if output is None:
            click.echo(text, nl=False)
        else:
            write_text_atomic(output, text)
            print_table(table)
            err.print(f"wrote {output}")
    if align and fmt == "table":
        print_table(alignment_table(rows))
    for row in sort_rows(rows):
        for warning in row.warnings:
            err.print(f"[yellow]warning:[/] {row.name}: {warning}", soft_wrap=True)
    if plot_dir is not None:
        written = write_plots(rows, plot_dir)
        err.print(f"wrote {len(written)} figure(s) to {plot_dir}/")
    if html_path is not None:
        _write_html(rows, html_path, paper=table1, align=align)
        err.print(f"wrote {html_path}", soft_wrap=True, markup=False)
    if mcap_path is not None:
        _write_review(paths, rows, mcap_path, config.evaluation.coverage_threshold_m)
        err.print(f"wrote {mcap_path}", soft_wrap=True, markup=False)
    if results_dir is not None:
        from scrapcut_cli.evaluation.results import write_results

        write_results(rows, results_dir)
        err.print(f"wrote per-sample errors of {len(rows)} path file(s) to {results_dir}/")


def _write_html(rows: list[ReportRow], target: Path, *, paper: Any, align: bool) -> None:
    """``eval --html``: the markdown report, the warnings and the figures in one page."""
    import tempfile

    from scrapcut_cli._io import write_text_atomic
    from scrapcut_cli.evaluation.html import markdown_to_html
    from scrapcut_cli.evaluation.plots import write_plots
    from scrapcut_cli.evaluation.report import render_markdown, sort_rows

    parts = ["# Path error (Table I)", "", render_markdown(rows, paper=paper, detail=True)]
    warnings = [f"- **{r.name}**: {w}" for r in sort_rows(rows) for w in r.warnings]
    if warnings:
        parts += ["## Warnings", "", *warnings, ""]
    if align:
        parts += ["## After rigid alignment (--align)", "", _alignment_markdown(rows), ""]
    with tempfile.TemporaryDirectory(prefix="scrapcut-html-") as folder:
        figures = write_plots(rows, Path(folder) / "plots")
        images = {f"plots/{p.name}": p.read_bytes() for p in figures}
    if images:
        parts += ["## Figures", "", *(f"![{Path(k).stem}]({k})" for k in sorted(images)), ""]
    page = markdown_to_html("\n".join(parts), title="scrapcut eval", images=images)
    write_text_atomic(target, page)


def _alignment_markdown(rows: list[ReportRow]) -> str:
    """The --align table as markdown (file, shape error, calibration error)."""
    from scrapcut_cli.evaluation.report import sort_rows

    lines = [
        "| File | Mean [mm] | RMSE [mm] | Max [mm] | Translation [mm] | Rotation [deg] |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for row in sort_rows(rows):
        f = row.aligned_mm()
        if f is None:
            lines.append(f"| {row.name} | — | — | — | — | — |")
            continue
        lines.append(
            f"| {row.name} | {f['aligned_mean_mm']:.2f} | {f['aligned_rmse_mm']:.2f} | "
            f"{f['aligned_max_mm']:.2f} | {f['align_translation_mm']:.2f} | "
            f"{f['align_rotation_deg']:.2f} |"
        )
    return "\n".join(lines)


def _write_review(
    paths: tuple[Path, ...], rows: list[ReportRow], target: Path, error_scale_m: float
) -> None:
    """The review MCAP of ``eval --mcap``: each path file against its reference."""
    from scrapcut_cli.errors import EvaluationError
    from scrapcut_cli.evaluation.sources import load_path_file
    from scrapcut_cli.toolpath.review import ReviewPath, write_review_mcap

    files = [load_path_file(p) for p in paths]
    frames = sorted({f.frame_id for f in files if f.frame_id})
    if len(frames) > 1:
        raise EvaluationError(
            f"--mcap: the path files are in different frames ({', '.join(frames)}); one review "
            "file shows one frame"
        )
    reference = {r.source: r.reference_points for r in rows}
    review = [
        ReviewPath(
            f.name,
            f.curve_points,
            f.setpoint_positions,
            f.setpoint_orientations_xyzw,
            f.setpoint_flags,
            reference=reference.get(str(f.path)),
        )
        for f in files
    ]
    starts = [f.source_start_ns for f in files if f.source_start_ns is not None]
    write_review_mcap(
        target,
        review,
        frame_id=frames[0] if frames else (rows[0].frame_id if rows else ""),
        stamp_ns=min(starts, default=0),
        reference=rows[0].reference_points if rows else None,
        error_scale_m=error_scale_m,
    )


def alignment_table(rows: list[ReportRow]) -> Table:
    """Shape error after the rigid alignment, and the alignment (the calibration error)."""
    from rich.table import Table

    from scrapcut_cli.evaluation.report import sort_rows

    table = Table(
        title="After rigid alignment (--align): shape error vs calibration error",
        caption="Shape error: distances left once the curve is laid rigidly onto the reference. "
        "Calibration error: the rigid motion that did it (translation of the curve's middle, "
        "rotation angle).",
    )
    for name in ("File", "Mean [mm]", "RMSE [mm]", "Max [mm]", "Coverage"):
        table.add_column(name, justify="left" if name == "File" else "right")
    table.add_column("Translation [mm]", justify="right")
    table.add_column("Rotation [deg]", justify="right")
    for row in sort_rows(rows):
        figures = row.aligned_mm()
        if figures is None:
            table.add_row(row.name, *(["—"] * 6))
            continue
        rotation = f"{figures['align_rotation_deg']:.2f}"
        if figures["align_straight_reference"]:
            rotation += " (roll about the line unobservable)"
        table.add_row(
            row.name,
            f"{figures['aligned_mean_mm']:.2f}",
            f"{figures['aligned_rmse_mm']:.2f}",
            f"{figures['aligned_max_mm']:.2f}",
            f"{100.0 * figures['aligned_coverage']:.1f}%",
            f"{figures['align_translation_mm']:.2f}",
            rotation,
        )
    return table


def _plain_table(table: Table) -> str:
    """The rich table as plain text (for ``--format table -o FILE``)."""
    import io

    from rich.console import Console
    from rich.measure import Measurement

    buffer = io.StringIO()
    console = Console(file=buffer, width=1000, color_system=None)
    natural = Measurement.get(console, console.options, table)
    console.print(table, width=natural.maximum)
    return "\n".join(line.rstrip() for line in buffer.getvalue().splitlines()) + "\n"
