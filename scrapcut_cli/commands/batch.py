"""``scrapcut batch RECS|DIR|MANIFEST -o DIR``: many recordings × a parameter grid on Dask."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Any

import click

from scrapcut_cli.commands._options import (
    build_config,
    config_option,
    engine_options,
    paint_options,
    recording_options,
)


def _names(values: tuple[str, ...]) -> list[str]:
    return [n.strip() for v in values for n in v.split(",") if n.strip()]


@click.command("batch")
@click.argument("sources", nargs=-1, required=True, metavar="RECS|DIR|MANIFEST...")
@click.option(
    "--grid",
    "grid_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="TOML of parameter lists: method = [...] and [section] key = [...] for any config key "
    "(e.g. [skeleton] leaf_size_m = [0.005, 0.01]); every combination runs on every recording.",
)
@click.option(
    "--methods",
    multiple=True,
    metavar="NAMES",
    help="Fitting methods, comma-separated, when the grid names none (default: nurbs).",
)
@click.option(
    "--reference",
    type=click.Path(path_type=Path),
    default=None,
    metavar="REC|CSV",
    help="Reference for recordings without their own (a manifest's reference column wins).",
)
@click.option("--no-eval", is_flag=True, help="Measure nothing (no error reports).")
@engine_options
@click.option("--no-plots", is_flag=True, help="Skip the PNG figures.")
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print the runs as JSON (scrapcut.batch/v1: counts and one row per run).",
)
@click.option(
    "-o",
    "--output",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Output folder; an earlier batch's folder is resumed (finished runs are not redone).",
)
@config_option
@recording_options
@paint_options
def batch(
    sources: tuple[str, ...],
    grid_path: Path | None,
    methods: tuple[str, ...],
    reference: Path | None,
    no_eval: bool,
    workers: int | None,
    scheduler: str | None,
    no_plots: bool,
    out_dir: Path,
    as_json: bool,
    config_path: Path | None,
    **shared: Any,
) -> None:
    """Fit every recording with every combination of a parameter grid, on Dask.

    RECS are recording files or ROS 2 bag folders, folders of recordings, quoted globs, or a
    manifest (CSV with the header recording,paint,hsv,reference,name, or TOML [[recording]]
    tables). Each run writes its path file and error report under DIR/paths/ and one row of
    DIR/batch.parquet and DIR/batch.csv (recording, parameters, metrics, timings, failure);
    DIR/report.md aggregates the rows per parameter value. Runs are keyed by content, so
    running the same batch again does only what is missing.
    """
    from scrapcut_cli.commands._console import err, out, progress
    from scrapcut_cli.pipeline.batch import batch as run_batch
    from scrapcut_cli.pipeline.batch import check_batch_dir
    from scrapcut_cli.pipeline.batch_inputs import collect_inputs, load_grid
    from scrapcut_cli.pipeline.engine import Engine

    if no_eval and reference is not None:
        raise click.UsageError("--reference and --no-eval contradict each other")
    config = build_config(config_path, **shared)
    check_batch_dir(out_dir)
    grid = load_grid(grid_path, methods=_names(methods))
    inputs = collect_inputs(sources, reference=reference)
    points = 1
    for values in grid.values():
        points *= len(values)
    with Engine(scheduler=scheduler, workers=workers) as engine:
        err.print(
            f"batch: {len(inputs)} recording(s) × {points} grid point(s) on {engine.describe()} "
            f"→ {out_dir}/"
        )
        with progress("runs") as bar:
            task = bar.add_task("batch", total=None, status="hashing recordings")

            def update(done: int, total: int, last: str) -> None:
                bar.update(task, total=total, completed=done, status=last)

            result = run_batch(
                inputs,
                out_dir=out_dir,
                grid=grid,
                config=config,
                engine=engine,
                evaluate=not no_eval,
                plots=not no_plots,
                progress=update,
                command=" ".join(["scrapcut", *(shlex.quote(a) for a in sys.argv[1:])])
                if sys.argv and Path(sys.argv[0]).name == "scrapcut"
                else "scrapcut batch",
            )
    if result.failed:
        err.print(f"[yellow]{result.failed} run(s) failed or were lost; see {out_dir}/report.md")
    if as_json:
        from scrapcut_cli.commands._console import json_document

        summary = {
            "out_dir": str(out_dir),
            "ran": result.ran,
            "cached": result.cached,
            "lost": result.lost,
            "failed": result.failed,
            "wall_time_s": result.wall_time_s,
            "rows": result.rows,
        }
        click.echo(json_document("scrapcut.batch/v1", summary))
        return
    out.print(
        f"{len(result.rows)} run(s): {result.ran} run now, {result.cached} finished before, "
        f"{result.failed} failed; wrote {out_dir}/batch.parquet, batch.csv, report.md in "
        f"{result.wall_time_s:.1f} s"
    )
