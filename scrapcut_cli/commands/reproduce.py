"""``scrapcut reproduce -o DIR``: the paper's Table I end to end on the simulator."""

from __future__ import annotations

import math
import shlex
import sys
from pathlib import Path

import click

from scrapcut_cli.commands._console import err, out
from scrapcut_cli.commands._options import (
    build_config,
    config_option,
    config_type,
    engine_options,
)
from scrapcut_cli.config import ScanMode

DEFAULT_LEAF_SWEEP = "2,3,5,10,15,20"


def _names(values: tuple[str, ...]) -> list[str]:
    """``--objects a,b --objects c`` → [a, b, c]."""
    return [n.strip() for v in values for n in v.split(",") if n.strip()]


@click.command("reproduce")
@click.option(
    "--objects",
    "objects",
    multiple=True,
    metavar="NAMES",
    help="Objects, comma-separated or repeated; 'all' adds slanted and planar_box "
    "(default: the paper's five — cylinder, i_beam, t_piece, basket, air_chamber — and "
    "perforated_plate).",
)
@click.option(
    "--methods",
    "methods",
    multiple=True,
    metavar="NAMES",
    help="Fitting methods, comma-separated (default: nurbs,skeleton).",
)
@click.option(
    "--noise",
    type=click.Choice(["ideal", "d435i", "yard"]),
    default=None,
    help="Simulated sensor noise (default: d435i).",
)
@click.option(
    "--mode",
    type=click.Choice([ScanMode.SWEEP.value, ScanMode.EXPLORE.value]),
    default=None,
    help="Scan by exploration (Algorithm 1, the paper's method) or by a pre-planned sweep along "
    "the true line (rows labelled 'oracle views') (default: explore; with --config, the file's "
    "sim.mode).",
)
@click.option(
    "--seeds",
    "--seed",
    "seeds",
    default=None,
    metavar="A-B|LIST",
    help="Simulator seeds, e.g. 0-19 or 0,3,7: Table I becomes the mean ± 95 % interval over "
    "them (default 0).",
)
@engine_options
@click.option(
    "--width", type=config_type("sim.width"), default=None, help="Image width [px] (default 640)."
)
@click.option(
    "--height",
    type=config_type("sim.height"),
    default=None,
    help="Image height [px] (default 480).",
)
@click.option(
    "--leaf-size-mm",
    type=config_type("skeleton.leaf_size_m", 1e-3),
    default=None,
    help="Skeleton leaf size [mm] (default 5, the paper's).",
)
@click.option(
    "--retry-leaf-mm",
    type=config_type("skeleton.leaf_size_m", 1e-3),
    default=20.0,
    help="Leaf size [mm] of the one retry when the skeleton breaks (the paper's basket; "
    "default 20).",
)
@click.option(
    "--leaf-sweep-mm",
    default=DEFAULT_LEAF_SWEEP,
    metavar="LIST",
    help="Skeleton leaf sizes [mm] also fitted on each stitched cloud for the paper's Fig. 3 "
    f"(comma-separated; 'none' to skip; default {DEFAULT_LEAF_SWEEP}).",
)
@click.option("--no-plots", is_flag=True, help="Skip the PNG figures.")
@click.option(
    "--no-motion",
    is_flag=True,
    help="Skip planning the Panda's trajectory of each path (the report's execution table).",
)
@click.option(
    "--self-calibrate",
    is_flag=True,
    help="Also fit every scan as 'fit --self-calibrate' does (hand-eye and clock calibration "
    "estimated from the scan): a second row per object and method, labelled self-calibrated.",
)
@click.option(
    "--readme",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="Also rewrite the marked section of this Markdown file (the README's Table I) with the "
    "run's description and table.",
)
@click.option(
    "--readme-section",
    default="table1",
    metavar="NAME",
    help="Which marked section --readme rewrites: the lines between "
    "'<!-- scrapcut:NAME begin ... -->' and '<!-- scrapcut:NAME end -->' (default table1).",
)
@click.option(
    "-o",
    "--output",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Output folder (replaced if it holds an earlier reproduce run).",
)
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print DIR/report.json (scrapcut.reproduce/v1) instead of the table.",
)
@config_option
def reproduce(
    objects: tuple[str, ...],
    methods: tuple[str, ...],
    noise: str | None,
    mode: str | None,
    seeds: str | None,
    workers: int | None,
    scheduler: str | None,
    width: int | None,
    height: int | None,
    leaf_size_mm: float | None,
    retry_leaf_mm: float,
    leaf_sweep_mm: str,
    no_plots: bool,
    no_motion: bool,
    self_calibrate: bool,
    readme: Path | None,
    readme_section: str,
    out_dir: Path,
    as_json: bool,
    config_path: Path | None,
) -> None:
    """Simulate, fit and evaluate the paper's objects; print Table I beside the paper's.

    Writes DIR/ with the recordings, path files (each with its error report), report.md,
    report.json, report.csv, plots/ and the configuration used (config.toml works as --config).
    The scans run on Dask: a local cluster (one worker per core) unless --scheduler names one.
    """
    from scrapcut_cli.commands._console import print_table, progress
    from scrapcut_cli.evaluation.report import (
        aggregate_rows,
        interval_rich_table,
        load_paper_table,
        replace_marked_section,
        rich_table,
    )
    from scrapcut_cli.pipeline.engine import Engine
    from scrapcut_cli.pipeline.reproduce import (
        check_out_dir,
        parse_seeds,
        resolve_methods,
        resolve_objects,
        seeds_text,
    )
    from scrapcut_cli.pipeline.reproduce import reproduce as run_reproduce

    config = build_config(config_path)
    if mode is None and config_path is None:
        mode = ScanMode.EXPLORE
    config = config.override("sim", noise=noise, mode=mode, width=width, height=height)
    if leaf_size_mm is not None:
        config = config.override("skeleton", leaf_size_m=leaf_size_mm / 1000.0)
    seed_list = parse_seeds(seeds) if seeds is not None else (config.sim.seed,)
    names = resolve_objects(_names(objects))
    method_names = resolve_methods(_names(methods))
    sweep = _leaf_sizes_m(leaf_sweep_mm)
    check_out_dir(out_dir)  # before the banner: a refusal is the only line printed
    if readme is not None:  # the markers must be there before minutes of work
        replace_marked_section(readme.read_text(encoding="utf-8"), readme_section, "")

    with Engine(scheduler=scheduler, workers=workers) as engine:
        err.print(
            f"reproducing Table I: {len(names)} object(s) × {len(method_names)} method(s), "
            f"{config.sim.mode} mode, {config.sim.noise} noise, "
            f"{config.sim.width}×{config.sim.height} px, {seeds_text(seed_list)}, "
            f"{engine.describe()} → {out_dir}/"
        )
        with progress("scans") as bar:
            task = bar.add_task("reproduce", total=None, status="starting")

            def update(done: int, total: int, last: str) -> None:
                bar.update(task, total=total, completed=done, status=f"{last} done")

            result = run_reproduce(
                out_dir,
                objects=names,
                methods=method_names,
                config=config,
                seeds=seed_list,
                engine=engine,
                retry_leaf_size_m=retry_leaf_mm / 1000.0,
                leaf_sweep_m=sweep,
                plots=not no_plots,
                motion=not no_motion,
                progress=update,
                self_calibrate=self_calibrate,
                command=" ".join(["scrapcut", *(shlex.quote(a) for a in sys.argv[1:])])
                if sys.argv and Path(sys.argv[0]).name == "scrapcut"
                else "scrapcut reproduce",
            )
    paper = load_paper_table()
    if as_json:
        click.echo((out_dir / "report.json").read_text(encoding="utf-8"), nl=False)
    elif len(result.seeds) > 1:
        print_table(
            interval_rich_table(
                aggregate_rows(result.rows),
                paper=paper,
                title="Table I (ours: mean ± 95 % interval)",
            )
        )
    else:
        print_table(rich_table(result.rows, paper=paper, title="Table I (ours vs paper)"))
    failed = [r for r in result.rows if r.failure]
    if failed:
        err.print(f"[yellow]{len(failed)} row(s) failed; see the Note column[/yellow]")
    if readme is not None:
        from scrapcut_cli._io import write_text_atomic

        text = readme.read_text(encoding="utf-8")
        write_text_atomic(
            readme, replace_marked_section(text, readme_section, result.table_markdown)
        )
        err.print(f"rewrote the '{readme_section}' section of {readme}")
    (err if as_json else out).print(
        f"wrote {out_dir}/ in {result.wall_time_s:.1f} s (report.md, report.html, report.json, "
        "plots/)"
    )


def _leaf_sizes_m(text: str) -> tuple[float, ...]:
    """``2,5,10`` (mm) → metres; ``none`` or empty → no sweep."""
    if text.strip().lower() in ("", "none"):
        return ()
    try:
        sizes = tuple(float(v) / 1000.0 for v in text.split(",") if v.strip())
    except ValueError:
        sizes = (-1.0,)
    if not sizes or any(not (math.isfinite(s) and s > 0) for s in sizes):
        raise click.BadParameter(
            f"expected positive millimetres like 2,5,10 or 'none', got {text!r}",
            param_hint="--leaf-sweep-mm",
        )
    return sizes
