"""Rich output helpers: one stderr console for progress, stdout for results."""

from __future__ import annotations

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

#: Results (tables, JSON) go to stdout; progress and notes to stderr so pipes stay clean.
out = Console(highlight=False, soft_wrap=True)
err = Console(stderr=True, highlight=False)


def progress(unit: str = "frames") -> Progress:
    """A progress bar over frames (or views), with counts and rate; transient on a terminal."""
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn(unit),
        TextColumn("{task.fields[status]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err,
        transient=True,
        disable=not err.is_terminal,
    )


def print_table(table: object) -> None:
    """Print a rich table on stdout at its natural width when the terminal (or a pipe's 80
    columns) is narrower: a wrapped line is better than a cut topic name or figure."""
    from rich.measure import Measurement

    natural = Measurement.get(out, out.options.update_width(1000), table)  # type: ignore[arg-type]
    if natural.maximum <= out.width:
        out.print(table)
    else:
        Console(width=natural.maximum, highlight=False, soft_wrap=True).print(table)
