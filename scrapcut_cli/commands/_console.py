"""Rich output helpers: one stderr console for progress, stdout for results."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

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


def deprecated(old: str, new: str) -> None:
    """One warning line for an option's old spelling (it still works)."""
    err.print(f"warning: {old} is deprecated; use {new} (same meaning)", markup=False)


def json_document(schema: str, data: Mapping[str, Any]) -> str:
    """A command's ``--json`` output: ``schema`` (``data``'s own if it has one), then
    ``tool_version``, then ``data``; non-finite floats become null (strict JSON)."""
    from scrapcut_cli import __version__

    document: dict[str, Any] = {"schema": data.get("schema", schema), "tool_version": __version__}
    document.update((k, v) for k, v in data.items() if k not in document)
    return json.dumps(_finite(document), indent=2)


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value
