"""``scrapcut explore REC``: replay Algorithm 1 over a recording, or tune it with ``--what-if``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from scrapcut_cli._io import real_path
from scrapcut_cli.commands._options import (
    apply_calibration_options,
    bounded,
    build_config,
    calibration_option,
    config_option,
    config_type,
    mm_to_m,
    paint_options,
    recording_options,
)
from scrapcut_cli.config import FitMethod, choice_names

if TYPE_CHECKING:
    from scrapcut_cli.exploration.replay import ExplorationRun
    from scrapcut_cli.pipeline.job import JobResult

METHODS = choice_names(FitMethod)
#: Exit code of a replay that diverged from its log (a finding; 1 stays a known error).
DIVERGED = 3


@click.command("explore")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option(
    "--method",
    type=click.Choice(METHODS),
    default=None,
    help="Curve fit the planner extrapolates (replay: must be the logged one; what-if: "
    "default nurbs).",
)
@click.option(
    "--what-if",
    "what_if_mode",
    is_flag=True,
    help="Run the planner with these parameters over the recording's frames (a survey or any "
    "dense scan), answering each planned view with the nearest recorded frame.",
)
@click.option(
    "--delta-size",
    type=config_type("exploration.delta_size"),
    default=None,
    help="What-if: new paint voxels at or below which an end is declared (default 20).",
)
@click.option(
    "--step-mm",
    type=config_type("exploration.step_m", 1e-3),
    default=None,
    help="What-if: next target this far beyond the fitted curve's end [mm] (default 60).",
)
@click.option(
    "--min-distance-mm",
    type=config_type("exploration.min_distance_m", 1e-3),
    default=None,
    help="What-if: nearest camera distance tried [mm] (default 200).",
)
@click.option(
    "--max-distance-mm",
    type=config_type("exploration.max_distance_m", 1e-3),
    default=None,
    help="What-if: farthest camera distance tried [mm] (default 450).",
)
@click.option(
    "--max-steps",
    type=config_type("exploration.max_steps"),
    default=None,
    help="What-if: frames observed before stopping with 'budget' (default 60).",
)
@click.option(
    "--look-past/--no-look-past",
    default=None,
    help="What-if: re-observe past an edge before declaring an end (default on).",
)
@click.option(
    "--match-distance-mm",
    type=bounded(0.1, 2000.0, "a recorded view over 2 m from the planned one shows other things"),
    default=100.0,
    help="What-if: a recorded frame answers a planned view within this camera distance [mm] "
    "(default 100).",
)
@click.option(
    "--match-angle-deg",
    type=bounded(0.1, 180.0, "an angle between optical axes"),
    default=30.0,
    help="What-if: ...and within this angle between the optical axes [deg] (default 30).",
)
@click.option(
    "--start-frame",
    type=bounded(0, 10_000_000, "a frame index"),
    default=None,
    help="What-if: frame index of the initial view (default: the frame showing most paint).",
)
@click.option(
    "--reference",
    type=click.Path(path_type=Path),
    default=None,
    metavar="REC|CSV",
    help="Reference curve for the global fit's error (default: the recording's "
    "/scrapcut/reference, if any).",
)
@click.option(
    "--no-eval",
    is_flag=True,
    help="Do not measure the global fit against a reference (no PATH.error.json).",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the path file (scrapcut.path/v1 JSON) of the global fit over the frames "
    "the planner used (scrapcut fit's job), and its error report PATH.error.json/.md.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the run (summary and steps) as JSON.")
@calibration_option
@config_option
@recording_options
@paint_options
def explore(
    recording: Path,
    method: str | None,
    what_if_mode: bool,
    delta_size: int | None,
    step_mm: float | None,
    min_distance_mm: float | None,
    max_distance_mm: float | None,
    max_steps: int | None,
    look_past: bool | None,
    match_distance_mm: float,
    match_angle_deg: float,
    start_frame: int | None,
    reference: Path | None,
    no_eval: bool,
    output: Path | None,
    as_json: bool,
    calibration_path: Path | None,
    config_path: Path | None,
    **shared: Any,
) -> None:
    """Replay Algorithm 1 over RECORDING, or tune it with --what-if.

    On an exploration recording (scrapcut record --mode explore) every decision is recomputed
    from the recorded frames, the reachability answers come from the log, and each decision is
    compared with the logged one; a divergence is reported and exits with status 3 (1 stays an
    error: an unreadable recording, a bad option). The method is read from the log.

    With --what-if the planner runs with the given parameters over any recording's frames (a
    survey is dense enough) and reports the views it would take, the endpoints it finds and the
    coverage of the final fit.
    With -o, the global fit over the frames the planner used is written as a path file, with
    its error report beside it when a reference is at hand. --calibration poses the frames of
    the global fit (and of a what-if run) with a saved camera mount and clock offset; a replay
    still checks each decision with the poses the planner had.
    """
    from scrapcut_cli.commands._console import err, progress
    from scrapcut_cli.pipeline.evaluate import check_reference_given
    from scrapcut_cli.pipeline.explore import fit_exploration

    planner_options = {
        "--delta-size": delta_size,
        "--step-mm": step_mm,
        "--min-distance-mm": min_distance_mm,
        "--max-distance-mm": max_distance_mm,
        "--max-steps": max_steps,
        "--look-past/--no-look-past": look_past,
        "--start-frame": start_frame,
    }
    given = [name for name, value in planner_options.items() if value is not None]
    if given and not what_if_mode:
        raise click.UsageError(
            f"{', '.join(given)} change the planner: add --what-if (a replay repeats the logged "
            "parameters)"
        )
    if no_eval and reference is not None:
        raise click.UsageError("--reference and --no-eval contradict each other")
    if not what_if_mode and (shared.get("frames") or shared.get("time_s")):
        raise click.UsageError(
            "--frames/--time crop what --what-if runs over; a replay repeats its whole log"
        )
    if output is not None and real_path(output) == real_path(recording):
        raise click.UsageError(f"{output} would overwrite the recording; choose another -o")
    config = apply_calibration_options(build_config(config_path, **shared), calibration_path)
    check_reference_given(reference)

    with progress("steps" if not what_if_mode else "frames") as bar:
        task = bar.add_task("what-if" if what_if_mode else "replaying", total=None, status="")

        def advance(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        if what_if_mode:
            from scrapcut_cli.exploration.replay import what_if

            config = config.override(
                "exploration",
                method=method,
                delta_size=delta_size,
                step_m=mm_to_m(step_mm),
                min_distance_m=mm_to_m(min_distance_mm),
                max_distance_m=mm_to_m(max_distance_mm),
                max_steps=max_steps,
                look_past=look_past,
            )
            run = what_if(
                recording,
                config=config,
                start_frame=start_frame,
                match_distance_m=match_distance_mm / 1000.0,
                match_angle_deg=match_angle_deg,
                progress=advance,
            )
        else:
            from scrapcut_cli.exploration.replay import replay_exploration

            run = replay_exploration(
                recording,
                config=config,
                method=method,
                progress=advance,
            )

    fitted = fit_exploration(
        run, config=config, output=output, reference=reference, evaluate=not no_eval
    )
    summary = fitted.summary()
    if as_json:
        data = run.to_dict()
        data["output"] = None if output is None else str(output)
        data["fit_failure"] = fitted.failure
        data["curve_length_mm"] = None if fitted.fit is None else 1000.0 * fitted.fit.curve.length
        for key in ("error", "error_status", "error_report"):
            data[key] = summary[key]
        from scrapcut_cli.commands._console import json_document

        click.echo(json_document("scrapcut.explore/v1", data))
    else:
        _render(run, fitted)
        if fitted.written:
            err.print(f"wrote {', '.join(str(p) for p in fitted.written)}")
    if fitted.failure:
        err.print(f"[yellow]note:[/] the global fit failed: {fitted.failure}")
    if run.divergences:
        # A finding about the recording, not a failure of the command: the replay ran and the
        # report above is complete. A distinct exit code lets scripts tell it from an error.
        err.print(
            f"verdict: the replay diverged from the log in {len(run.divergences)} place(s); "
            f"first: {run.divergences[0]}",
            soft_wrap=True,
            markup=False,
        )
        raise click.exceptions.Exit(DIVERGED)
    if not what_if_mode:
        err.print("verdict: the replay matches the log", markup=False)


def _render(run: ExplorationRun, fitted: JobResult) -> None:
    import numpy as np
    from rich.table import Table

    from scrapcut_cli.commands._console import out, print_table
    from scrapcut_cli.pipeline.evaluate import error_text

    title = "Algorithm 1 " + ("replayed" if run.mode == "replay" else "what-if")
    steps = Table(title=f"{title}: {run.source} ({run.method})")
    for name in ("k", "frame", "action", "reason", "new", "size", "ends", "exec. err", "queries"):
        steps.add_column(name, justify="right" if name not in ("action", "reason") else "left")
    if run.mode == "replay":
        steps.add_column("log")
    for step in run.steps:
        error = step.execution_error()
        err_text = "-" if error is None else f"{1000 * error[0]:.1f} mm {np.degrees(error[1]):.1f}°"
        row = [
            str(step.k),
            str(step.frame_index),
            step.action,
            step.reason,
            str(step.growth),
            str(step.size),
            str(step.endpoints_found),
            err_text,
            str(step.queries),
        ]
        if run.mode == "replay":
            row.append("[green]ok[/]" if not step.divergences else "[red]differs[/]")
        steps.add_row(*row)
    print_table(steps)

    summary = Table(show_header=False, title="summary")
    summary.add_column("", style="bold")
    summary.add_column("")
    ends = (
        ", ".join(
            e["reason"]
            + (f" seen in frame {e['observed_by']['frame']}" if "observed_by" in e else "")
            for e in run.ends
        )
        or "-"
    )
    rows = [
        (
            "views",
            f"{run.views}" + (f" of {run.frames_available} frames" if run.mode != "replay" else ""),
        ),
        ("endpoints found", f"{run.endpoints_found} ({ends})"),
        ("stopped", str(run.stop_reason)),
        ("camera travel", f"{1000 * run.camera_travel_m:.0f} mm (straight lines between views)"),
        ("stitched paint", f"{len(run.paint_points)} points"),
    ]
    if fitted.fit is not None:
        rows.append(("global fit", f"{1000 * fitted.fit.curve.length:.1f} mm of curve"))
    if fitted.failure is None:
        rows.append(
            ("against the reference", error_text(fitted.report.summary(), fitted.report.status))
        )
    if run.timings:
        planner = np.median([t.planner for t in run.timings])
        total = np.median([t.total for t in run.timings])
        timing = f"median {planner:.0f} ms planner, {total:.0f} ms with perception"
        if run.mode != "replay":
            timing = f"median {planner:.0f} ms planner (frames perceived beforehand)"
        rows.append(("decision time", timing))
    if run.mode == "replay":
        verdict = (
            "[green]matches the log[/]"
            if run.matches
            else f"[red]{len(run.divergences)} divergence(s)[/]"
        )
        rows.append(("verification", verdict))
    for key, value in rows:
        summary.add_row(key, value)
    out.print(summary)
