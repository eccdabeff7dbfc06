"""``scrapcut eval PATH.json... [--reference REC|CSV]``: the paper's Table I for path files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from scrapcut_cli.commands._console import err, print_table
from scrapcut_cli.commands._options import build_config, config_option, config_type

if TYPE_CHECKING:
    from rich.table import Table

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
    help="Write PNG figures into DIR (error along the curve, paths, leaf-size sweep).",
)
@click.option(
    "--coverage-mm",
    type=config_type("evaluation.coverage_threshold_m", 1e-3),
    default=None,
    help="Coverage threshold [mm] (default 10).",
)
@config_option
def eval_cmd(
    paths: tuple[Path, ...],
    reference: Path | None,
    object_name: str | None,
    fmt: str | None,
    output: Path | None,
    paper: bool,
    plot_dir: Path | None,
    coverage_mm: float | None,
    config_path: Path | None,
) -> None:
    """Path error of PATH.json files against the painted reference (the paper's Table I).

    Samples the reference every 1 mm and measures the distance to the nearest point of each
    fitted curve: mean, SD, min, max in mm, plus coverage (share of samples within 10 mm),
    the reverse distance (curve to reference) and the length ratio.
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
    )
    from scrapcut_cli.evaluation.sources import evaluate_path_files

    if output is not None and fmt is None:
        fmt = _SUFFIX_FORMATS.get(output.suffix.lower())
        if fmt is None:
            raise click.BadParameter(
                f"cannot tell the format from {output.name!r}; use .md, .csv, .json or --format",
                param_hint="-o",
            )
    fmt = fmt or "table"
    if output is not None:
        from scrapcut_cli._io import check_output_path

        check_output_path(output)
    config = build_config(config_path)
    config = config.override(
        "evaluation",
        coverage_threshold_m=None if coverage_mm is None else coverage_mm / 1000.0,
    )
    rows = evaluate_path_files(
        paths, reference=reference, config=config.evaluation, recording_config=config.recording
    )
    if object_name:
        rows = [replace(r, object=object_name) for r in rows]
    table1 = load_paper_table() if paper else None
    table = rich_table(rows, paper=table1, title="Path error (Table I)")

    if fmt == "table" and output is None:
        print_table(table)
    else:
        if fmt == "table":
            text = _plain_table(table)
        elif fmt == "markdown":
            text = render_markdown(rows, paper=table1)
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
    if plot_dir is not None:
        written = write_plots(rows, plot_dir)
        err.print(f"wrote {len(written)} figure(s) to {plot_dir}/")


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
