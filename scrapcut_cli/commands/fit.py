"""``scrapcut fit``: fit the painted line of a recording and write the cutting path."""

from __future__ import annotations

import glob
from dataclasses import replace
from pathlib import Path
from typing import Any

import click

from scrapcut_cli._io import prepare_output, real_path
from scrapcut_cli.commands._options import (
    apply_calibration_options,
    apply_stage_options,
    build_config,
    calibration_option,
    config_option,
    config_type,
    mm_to_m,
    output_options,
    paint_options,
    perception_options,
    recording_options,
    split_stage_options,
    stitch_options,
)
from scrapcut_cli.config import FitMethod, choice_names
from scrapcut_cli.errors import FileError, ScrapcutError

METHODS = choice_names(FitMethod)


@click.command("fit")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option(
    "--method",
    type=click.Choice(METHODS),
    default="nurbs",
    help="Curve fit: open NURBS or 3-D skeleton (default nurbs).",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Path file to write (scrapcut.path/v1 JSON, named *.json).",
)
@click.option(
    "--csv",
    "write_csv",
    is_flag=True,
    help="Also write the set-points as PATH.csv (SI units, a flags column, a # frame_id line).",
)
@click.option(
    "--tum",
    "write_tum",
    is_flag=True,
    help="Also write the torch poses as PATH.tum (t x y z qx qy qz qw; evo_traj tum reads it).",
)
@click.option(
    "--mcap",
    "write_mcap",
    is_flag=True,
    help="Also write PATH.mcap: curve, torch poses and stitched clouds for Foxglove.",
)
@click.option(
    "--nurbs-json",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the NURBS as geomdl JSON (--method nurbs).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option(
    "--reference",
    type=click.Path(path_type=Path),
    default=None,
    metavar="REC|CSV",
    help="Reference curve to measure the path against: a CSV x,y,z in metres (e.g. probed "
    "points) or a recording with /scrapcut/reference (default: the recording's own, if any).",
)
@click.option(
    "--no-eval",
    is_flag=True,
    help="Do not measure the path against a reference (no PATH.error.json).",
)
@click.option(
    "--pick",
    type=click.Choice(("scan", "longest", "nearest-start", "all")),
    default=None,
    help="Which line-like paint to cut when there are several: the one the scan follows "
    "(default), the longest, the one nearest to where the scan started, or all (one path "
    "file each: PATH.json, PATH_2.json, ...).",
)
@click.option(
    "--leaf-size-mm",
    "leaf_size_mm",
    type=config_type("skeleton.leaf_size_m", 1e-3),
    default=None,
    help="Skeleton voxel (leaf) size [mm] (default 5, the paper's).",
)
@click.option(
    "--leaf-size",
    "old_leaf_size_mm",
    type=config_type("skeleton.leaf_size_m", 1e-3),
    default=None,
    hidden=True,
    help="Deprecated spelling of --leaf-size-mm.",
)
@click.option(
    "--smoothness",
    type=config_type("nurbs.smoothness"),
    default=None,
    help="NURBS smoothness weight w (default 1.0, the paper's).",
)
@click.option(
    "--control-points",
    type=config_type("nurbs.control_points"),
    default=None,
    help="NURBS control points (default: scales with the curve length).",
)
@click.option(
    "--degree", type=config_type("nurbs.degree"), default=None, help="NURBS degree (default 3)."
)
@click.option(
    "--spacing-mm",
    type=config_type("toolpath.spacing_m", 1e-3),
    default=None,
    help="Set-point spacing along the curve [mm] (default 5).",
)
@click.option(
    "--standoff-mm",
    type=config_type("toolpath.standoff_m", 1e-3),
    default=None,
    help="Torch tip distance from the surface [mm] (default 8).",
)
@click.option(
    "--normal-radius-mm",
    type=config_type("toolpath.normal_radius_m", 1e-3),
    default=None,
    help="Surface neighbourhood for normals [mm] (default 15).",
)
@click.option(
    "--material",
    default=None,
    help="Material key of the speed table (default mild_steel; a wrong name lists them).",
)
@click.option(
    "--thickness-mm",
    type=config_type("toolpath.thickness_mm"),
    default=None,
    help="Plate thickness [mm] for the cutting speed (default 10).",
)
@click.option(
    "--max-tilt-deg",
    type=config_type("toolpath.max_tilt_deg"),
    default=None,
    help="Largest torch tilt from the normal to avoid a collision [deg] (default 20).",
)
@click.option(
    "--torch-length-mm",
    type=config_type("toolpath.torch_length_m", 1e-3),
    default=None,
    help="Torch body length for the collision check [mm] (default 150).",
)
@click.option(
    "--torch-radius-mm",
    type=config_type("toolpath.torch_radius_m", 1e-3),
    default=None,
    help="Torch body radius for the collision check [mm] (default 12).",
)
@click.option(
    "--closure",
    type=click.Choice(["auto", "open", "closed"]),
    default=None,
    help="Is the line a loop (a ring, a cut-out)? auto (default): decided from the paint and "
    "the surface seen around it; open or closed force it.",
)
@click.option(
    "--start",
    default=None,
    metavar="top|reachable|X,Y,Z",
    help="Where a loop's cut starts: top (default: the highest observed point), reachable "
    "(the observed point nearest the robot's base) or X,Y,Z in metres, base frame.",
)
@click.option(
    "--lead-in-mm",
    type=config_type("toolpath.lead_in_m", 1e-3),
    default=None,
    help="A loop's lead-in from the pierce onto the line [mm] (default 5).",
)
@click.option(
    "--overlap-mm",
    type=config_type("toolpath.overlap_m", 1e-3),
    default=None,
    help="How far a loop's cut runs past its start, so the ring is severed [mm] (default 10).",
)
@click.option(
    "--speed-table",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Cutting-speed CSV (default: the bundled oxy-fuel chart).",
)
@calibration_option
@click.option(
    "--self-calibrate",
    is_flag=True,
    help="Estimate the camera mount and clock offset from this scan first (scrapcut "
    "calibrate) and pose the frames with them; recorded in the path file.",
)
@config_option
@recording_options
@paint_options
@perception_options
@stitch_options
@output_options
def fit(
    recording: Path,
    method: str,
    output: Path,
    write_csv: bool,
    write_tum: bool,
    write_mcap: bool,
    nurbs_json: Path | None,
    as_json: bool,
    reference: Path | None,
    no_eval: bool,
    pick: str | None,
    leaf_size_mm: float | None,
    old_leaf_size_mm: float | None,
    smoothness: float | None,
    control_points: int | None,
    degree: int | None,
    spacing_mm: float | None,
    standoff_mm: float | None,
    normal_radius_mm: float | None,
    material: str | None,
    thickness_mm: float | None,
    max_tilt_deg: float | None,
    torch_length_mm: float | None,
    torch_radius_mm: float | None,
    closure: str | None,
    start: str | None,
    lead_in_mm: float | None,
    overlap_mm: float | None,
    speed_table: Path | None,
    calibration_path: Path | None,
    self_calibrate: bool,
    config_path: Path | None,
    force: bool,
    parents: bool,
    **shared: Any,
) -> None:
    """Fit the painted line of RECORDING and write the cutting path.

    Reads the recording (MCAP, ROS 1 bag or ROS 2 bag directory), stitches the paint seen in
    every frame, finds the marked line among the paint's candidates (crates, cones, old faded
    marks and rust are rejected and listed), fits a NURBS or a 3-D skeleton to it, cuts back
    whatever runs past its paint, and places torch set-points perpendicular to the observed
    surface at the standoff, tilted where the torch would hit the piece, timed by the
    material's cutting speed. A line that closes on itself (a ring round a pipe, a cut-out) is
    fitted as a loop and cut from a pierce with a lead-in, once round and past its start; an
    arc of it no camera saw is bridged by the fit, its set-points flagged unobserved and the
    arc reported.

    When a reference is at hand (the recording's /scrapcut/reference, or --reference), the
    path is measured against it as `scrapcut eval` does, and PATH.error.json and PATH.error.md
    are written beside the path file.
    """
    from rich.markup import escape

    from scrapcut_cli.commands._console import deprecated, err, progress
    from scrapcut_cli.pipeline.evaluate import error_report_paths
    from scrapcut_cli.pipeline.job import Job, Pipeline

    csv_path = output.with_suffix(".csv") if write_csv else None
    tum_path = output.with_suffix(".tum") if write_tum else None
    mcap_path = output.with_suffix(".mcap") if write_mcap else None
    extra = [p for p in (csv_path, tum_path, mcap_path, nurbs_json) if p is not None]
    reports = [] if no_eval else list(error_report_paths(output))
    for target in [output, *extra, *reports]:
        if real_path(target) == real_path(recording):
            raise click.UsageError(f"{target} would overwrite the recording; choose another -o")
    if any(real_path(p) == real_path(output) for p in [*extra, *reports]):
        raise click.UsageError(f"-o {output} would be overwritten by an export; name it .json")
    if nurbs_json is not None and method != FitMethod.NURBS:
        raise click.UsageError("--nurbs-json needs --method nurbs")
    if no_eval and reference is not None:
        raise click.UsageError("--reference and --no-eval contradict each other")
    for target in [output, *extra, *reports]:
        # Before minutes of work: an existing file (--force), a missing folder (--parents),
        # /dev/null, a FIFO, a link loop.
        option = "--nurbs-json" if target == nurbs_json else "-o"
        prepare_output(target, force=force, parents=parents, option=option)
    if output.suffix.lower() != ".json":
        raise click.UsageError(
            f"-o {output}: a path file is JSON; name it {output.with_suffix('.json').name} "
            "(--csv, --tum and --mcap write their files beside it)"
        )

    if old_leaf_size_mm is not None:
        if leaf_size_mm is not None:
            raise click.UsageError("--leaf-size is the old spelling of --leaf-size-mm; give one")
        deprecated("--leaf-size", "--leaf-size-mm")
        leaf_size_mm = old_leaf_size_mm
    stage, shared = split_stage_options(shared)
    config = apply_stage_options(build_config(config_path, **shared), stage)
    config = config.override("selection", pick=pick)
    if config.selection.pick == "all" and not force:
        # --pick all names PATH_2.json, PATH_3.json, ... once it knows how many lines there
        # are: an earlier run's files under those names are refused now, not replaced then.
        taken = sorted(output.parent.glob(f"{glob.escape(output.stem)}_[0-9]*.json"))
        if taken:
            raise FileError(
                f"-o {output}: --pick all would replace {taken[0]} "
                f"({len(taken)} file(s) {output.stem}_N*.json); add --force to replace them"
            )
    config = config.override("skeleton", leaf_size_m=mm_to_m(leaf_size_mm))
    config = config.override(
        "nurbs", smoothness=smoothness, control_points=control_points, degree=degree
    )
    config = config.override(
        "toolpath",
        spacing_m=mm_to_m(spacing_mm),
        standoff_m=mm_to_m(standoff_mm),
        normal_radius_m=mm_to_m(normal_radius_mm),
        material=material,
        thickness_mm=thickness_mm,
        max_tilt_deg=max_tilt_deg,
        torch_length_m=mm_to_m(torch_length_mm),
        torch_radius_m=mm_to_m(torch_radius_mm),
        speed_table=None if speed_table is None else str(speed_table),
        start=start,
        lead_in_m=mm_to_m(lead_in_mm),
        overlap_m=mm_to_m(overlap_mm),
    )
    config = apply_calibration_options(config, calibration_path, self_calibrate)
    config = config.override("closure", mode=closure)
    if start is not None:
        from scrapcut_cli.toolpath.loop import parse_start

        try:
            parse_start(start)
        except ScrapcutError as exc:
            raise click.BadParameter(str(exc), param_hint="--start") from None

    job = Job(
        recording,
        FitMethod(method),
        config,
        output=output,
        reference=reference,
        evaluate=not no_eval,
        csv=write_csv,
        tum=write_tum,
        mcap=write_mcap,
        nurbs_json=nurbs_json,
    )
    with progress("frames") as bar:
        task = bar.add_task("stitching", total=None, status="")

        def advance(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        pipeline = Pipeline(job, progress=advance)
        results = [pipeline.run()]
    selection = None if pipeline.stitched is None else pipeline.stitched.selection
    for warning in () if selection is None else selection.warnings:
        err.print(f"[yellow]warning:[/] {escape(warning)}", soft_wrap=True)
    # --pick all: one more job per further line, on the same stitched clouds.
    for line in range(1, 0 if selection is None else len(selection.lines)):
        more = replace(
            job,
            line=line,
            output=output.with_name(f"{output.stem}_{line + 1}.json"),
            nurbs_json=None,
        )
        results.append(Pipeline(more, stitched=pipeline.stitched, speeds=pipeline.speeds).run())
    summaries = [result.summary() for result in results]
    if as_json:
        from scrapcut_cli.commands._console import json_document

        # One path: its summary; several (--pick all): {"paths": [one summary per path]}.
        data = summaries[0] if len(summaries) == 1 else {"paths": summaries}
        click.echo(json_document("scrapcut.fit/v1", data))
    else:
        for summary in summaries:
            _render(summary)
    for summary in summaries:
        if summary["flagged"]:
            err.print(
                f"[yellow]note:[/] {summary['flagged']} set-point(s) flagged "
                f"(tilted {summary['tilted']}, collision {summary['collision']}, "
                f"no surface {summary['no_surface']}"
                + (f", unobserved {summary['unobserved']}" if summary["closed"] else "")
                + (
                    f", bridged gap {confidence['bridged_gap']}, low support "
                    f"{confidence['low_support']}"
                    if (confidence := summary.get("confidence"))
                    else ""
                )
                + f"); see 'flags' in {summary['outputs'][0]}"
            )


def _render(summary: dict[str, Any]) -> None:
    from rich.table import Table

    from scrapcut_cli.commands._console import out
    from scrapcut_cli.pipeline.evaluate import error_text

    table = Table(title=f"scrapcut fit — {summary['method']}", show_header=False)
    table.add_column("", style="bold")
    table.add_column("")
    params = summary["method_params"]
    method = summary["method"]
    if method == "skeleton":
        method += f" (leaf {1000 * params['leaf_size_m']:g} mm)"
    reasons = ", ".join(f"{k} {v}" for k, v in summary["skip_reasons"].items())
    time_s = summary["time_s"]
    rows = [
        ("recording", summary["recording"]),
        ("method", method),
        ("paint", summary["paint"]),
        (
            "frames used / skipped",
            f"{summary['frames_used']} / {summary['frames_skipped']}"
            + (f" ({reasons})" if reasons else ""),
        ),
        (
            "stitched points",
            f"{summary['paint_points']} paint, {summary['surface_points']} surface",
        ),
        ("curve length", f"{1000 * summary['curve_length_m']:.1f} mm"),
        (
            "paint spread",
            f"{1000 * summary['paint_spread_rms_m']:.2f} mm RMS, "
            f"{1000 * summary['paint_spread_max_m']:.2f} mm max around the curve (the line's "
            "painted band's width and noise; not an accuracy: see error vs reference)",
        ),
        (
            "reverse distance",
            f"{1000 * summary['reverse_mean_m']:.2f} mm mean, "
            f"{1000 * summary['reverse_max_m']:.2f} mm max (curve to the line's paint)"
            + _trimmed(summary["paint_trim_m"]),
        ),
        ("line", _line_text(summary.get("selection"))),
        ("set-points", str(summary["setpoints"])),
        (
            "flagged",
            f"{summary['flagged']} (tilted {summary['tilted']}, collision "
            f"{summary['collision']}, no surface {summary['no_surface']}"
            + (f", unobserved {summary['unobserved']})" if summary["closed"] else ")"),
        ),
        *_loop_rows(summary),
        *(
            [
                (
                    "confidence",
                    f"σ {1000 * confidence['sigma_median_m']:.2f} mm median, "
                    f"{1000 * confidence['sigma_max_m']:.2f} mm max; "
                    f"{confidence['bridged_gap']} set-point(s) bridge a gap, "
                    f"{confidence['low_support']} low support",
                )
            ]
            if (confidence := summary.get("confidence"))
            else []
        ),
        (
            "cutting",
            f"{summary['material']} {summary['thickness_mm']:g} mm: "
            f"{60000 * summary['speed_m_s']:.0f} mm/min, pierce {summary['pierce_s']:.1f} s, "
            f"total {summary['cut_time_s']:.1f} s",
        ),
        (
            "time",
            f"{time_s['total']:.2f} s (read+stitch {time_s['read_stitch']:.2f}, "
            f"fit {time_s['fit']:.3f}, tool path {time_s['toolpath']:.3f})",
        ),
        ("error vs reference", error_text(summary["error"], summary["error_status"])),
        ("written", ", ".join(summary["outputs"])),
    ]
    calibration = summary.get("calibration")
    if calibration is not None:
        text = calibration.get("verdict") or f"from {calibration['origin']}"
        rows.insert(3, ("calibration", text))
    for key, value in rows:
        table.add_row(key, value)
    out.print(table)


def _loop_rows(summary: dict[str, Any]) -> list[tuple[str, str]]:
    """The summary rows of a closed line: how it closed, where the cut starts, what no camera
    saw."""
    if not summary["closed"]:
        return []
    closure = (summary.get("fitter_info") or {}).get("closure_reason", "")
    how = {
        "loop": "paint seen all round",
        "unobserved_gap": "through an arc no camera saw",
        "forced_closed": "forced (--closure closed)",
    }.get(closure, closure)
    loop = summary.get("loop") or {}
    pierce = ", ".join(f"{1000 * v:.0f}" for v in loop.get("pierce_point", []))
    rows = [
        ("closed loop", f"{how}; {1000 * loop.get('loop_length_m', 0.0):.1f} mm round"),
        (
            "cut",
            f"pierce at {loop.get('start', '?')} ({pierce} mm), lead-in "
            f"{1000 * loop.get('lead_in_m', 0.0):.1f} mm, overlap "
            f"{1000 * loop.get('overlap_m', 0.0):.1f} mm",
        ),
    ]
    arcs = summary.get("unobserved_arcs") or []
    text = (
        "none"
        if not arcs
        else "; ".join(
            f"{1000 * a['length_m']:.0f} mm at {1000 * a['start_s_m']:.0f}-"
            f"{1000 * a['end_s_m']:.0f} mm along the cut"
            for a in arcs
        )
    )
    rows.append(("unobserved arcs", text))
    return rows
    selection = summary.get("selection") or {}
    if selection.get("rejected"):
        _render_rejected(selection["rejected"])


def _trimmed(trims: list[float]) -> str:
    if not any(t > 0 for t in trims):
        return ""
    return f"; cut back {1000 * trims[0]:.1f} / {1000 * trims[1]:.1f} mm that ran past the paint"


def _line_text(selection: dict[str, Any] | None) -> str:
    if not selection:
        return "all stitched paint"
    line = selection["lines"][selection["line_index"]]
    counts: dict[str, int] = {}
    for c in selection["rejected"]:
        counts[c["kind"]] = counts.get(c["kind"], 0) + 1
    rejected = ", ".join(f"{n} {k}" for k, n in counts.items()) or "nothing"
    which = (
        f"line {selection['line_index'] + 1} of {selection['lines_found']}, "
        if selection["lines_found"] > 1
        else ""
    )
    return (
        f"{which}{line['points']} voxels, {line['length_mm']:.0f} mm, scan follows "
        f"{100 * line['follow']:.0f} %; rejected: {rejected}"
    )


def _render_rejected(rejected: list[dict[str, Any]]) -> None:
    from rich.table import Table

    from scrapcut_cli.commands._console import out

    table = Table(title="paint that is not the line", title_justify="left")
    for name in ("kind", "voxels", "size [mm]", "at (x, y, z) [m]", "S / V", "why"):
        table.add_column(name)
    for c in rejected:
        x, y, z = c["position_m"]
        sv = f"{c['saturation']:.2f} / {c['value']:.2f}" if c["saturation"] is not None else "-"
        table.add_row(
            c["kind"],
            str(c["points"]),
            f"{c['length_mm']:.0f} x {c['width_mm']:.0f}",
            f"{x:.3f}, {y:.3f}, {z:.3f}",
            sv,
            c["reason"],
        )
    out.print(table)
