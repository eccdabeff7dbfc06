"""``scrapcut trajectory``: the joint trajectory that cuts a path, for the recording's Panda."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from scrapcut_cli.commands._options import (
    build_config,
    config_option,
    config_type,
    mm_to_m,
    recording_options,
)


@click.command("trajectory")
@click.argument("path_file", metavar="PATH.json", type=click.Path(path_type=Path))
@click.option(
    "--recording",
    type=click.Path(path_type=Path),
    default=None,
    help="Recording the path was fitted from: its depth images are the observed surface the "
    "arm must clear (default: the path's source recording, if it exists).",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Trajectory file to write (scrapcut.trajectory/v1 JSON).",
)
@click.option("--csv", "write_csv", is_flag=True, help="Also write one row per point as TRAJ.csv.")
@click.option(
    "--mcap",
    "write_mcap",
    is_flag=True,
    help="Also write TRAJ.mcap: JointTrajectory, the torch tip as a Path, /joint_states.",
)
@click.option(
    "--tool-offset",
    default=None,
    metavar="X,Y,Z[,R,P,Y]|FILE",
    help="Torch tip on the flange (panda_link8): x,y,z [mm] and roll,pitch,yaw [deg], or a "
    "YAML/JSON file with translation_m and rotation_xyzw (default: straight torch, tip "
    "250 mm along the flange z axis).",
)
@click.option(
    "--urdf",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Panda URDF (default: pybullet_data's franka_panda/panda.urdf).",
)
@click.option(
    "--max-tilt-deg",
    type=config_type("motion.max_tilt_deg"),
    default=None,
    help="Largest torch tilt where a set-point cannot be reached as given [deg] (default 20).",
)
@click.option(
    "--floor-z-mm",
    type=config_type("motion.floor_z_m", 1e-3),
    default=None,
    help="Height of the floor (or table) below the robot base, base frame z [mm] (default 0).",
)
@click.option(
    "--approach-mm",
    type=config_type("motion.approach_m", 1e-3),
    default=None,
    help="Approach and retreat along the torch axis [mm] (default 100).",
)
@click.option(
    "--run-out-mm",
    type=config_type("motion.run_out_m", 1e-3),
    default=None,
    help="Run-out past a far edge [mm] (default 10).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@config_option
@recording_options
def trajectory(
    path_file: Path,
    recording: Path | None,
    output: Path,
    write_csv: bool,
    write_mcap: bool,
    tool_offset: str | None,
    urdf: Path | None,
    max_tilt_deg: float | None,
    floor_z_mm: float | None,
    approach_mm: float | None,
    run_out_mm: float | None,
    as_json: bool,
    config_path: Path | None,
    **shared: Any,
) -> None:
    """Plan the Panda's joint trajectory that cuts PATH.json.

    Inverse kinematics per set-point with continuous redundancy resolution (away from joint
    limits and singularities, no wrist flips), torch tilts where a set-point cannot be
    reached as given, collisions of the arm and torch with the observed surface and the
    floor, and timing within Franka's joint velocity, acceleration and jerk limits:
    approach, pierce (or edge preheat) dwell, the cut at the path's speed, run-out, retreat.
    """
    from scrapcut_cli.commands._console import err, progress
    from scrapcut_cli.motion.recipe import trajectory_from_files
    from scrapcut_cli.motion.trajfile import (
        write_trajectory_csv,
        write_trajectory_file,
        write_trajectory_mcap,
    )

    csv_path = output.with_suffix(".csv") if write_csv else None
    mcap_path = output.with_suffix(".mcap") if write_mcap else None
    extra = [p for p in (csv_path, mcap_path) if p is not None]
    inputs = [path_file] + ([recording] if recording is not None else [])
    for target in [output, *extra]:
        if any(target.resolve() == p.resolve() for p in inputs):
            raise click.UsageError(f"{target} would overwrite an input; choose another -o")
    if any(p.resolve() == output.resolve() for p in extra):
        raise click.UsageError(f"-o {output} would be overwritten by an export; name it .json")

    config = build_config(config_path, **shared)
    config = config.override(
        "motion",
        tool_offset=tool_offset,
        urdf=None if urdf is None else str(urdf),
        max_tilt_deg=max_tilt_deg,
        floor_z_m=mm_to_m(floor_z_mm),
        approach_m=mm_to_m(approach_mm),
        retreat_m=mm_to_m(approach_mm),
        run_out_m=mm_to_m(run_out_mm),
    )
    with progress("frames") as bar:
        task = bar.add_task("observed surface", total=None, status="")

        def advance(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        result = trajectory_from_files(
            path_file, recording=recording, config=config, progress=advance
        )

    traj = result.trajectory
    write_trajectory_file(output, result.to_dict())
    written = [output]
    if csv_path is not None:
        write_trajectory_csv(traj, csv_path)
        written.append(csv_path)
    if mcap_path is not None:
        write_trajectory_mcap(mcap_path, traj)
        written.append(mcap_path)

    summary = dict(traj.summary)
    summary["outputs"] = [str(p) for p in written]
    summary["time_s"] = result.timings_s
    if as_json:
        from scrapcut_cli.commands._console import json_document

        click.echo(json_document("scrapcut.trajectory_summary/v1", summary))
    else:
        _render(summary, path_file)
    if summary["observed_surface"] == "none":
        err.print(
            "[yellow]note:[/] no recording found: collisions checked against the floor only; "
            "give --recording REC to check the arm against what the camera saw"
        )
    if not summary["executable"]:
        err.print(
            f"[yellow]note:[/] not executable as planned: {summary['unreachable']} unreachable, "
            f"{summary['in_collision']} in collision, {summary['trajectory_collisions']} "
            f"colliding points, limits {'ok' if summary['limits_ok'] else 'EXCEEDED'}; "
            f"see 'setpoints' in {output}"
        )


def _render(summary: dict[str, Any], path_file: Path) -> None:
    from rich.table import Table

    from scrapcut_cli.commands._console import print_table

    table = Table(title=f"scrapcut trajectory — {path_file.name}", show_header=False)
    table.add_column("", style="bold")
    table.add_column("")
    reasons = ", ".join(f"{k} {v}" for k, v in summary["reasons"].items())
    rows = [
        (
            "set-points",
            f"{summary['setpoints']}: {summary['reached']} reached, {summary['tilted']} tilted, "
            f"{summary['unreachable']} unreachable, {summary['in_collision']} in collision"
            + (f" ({reasons})" if reasons else ""),
        ),
        (
            "executable",
            f"{100 * summary['executable_share']:.1f} % of the set-points, in "
            f"{summary['cut_segments']} cut(s)",
        ),
        (
            "accuracy",
            f"tip {summary['tip_error_max_mm']:.3f} mm, axis {summary['axis_error_max_deg']:.3f}° "
            "max (forward kinematics at the set-points)",
        ),
        (
            "start / finish",
            f"{summary['start']} ({summary['dwell_s']:.1f} s dwell) / {summary['finish']}"
            + (f" {1000 * summary['run_out_m']:.0f} mm" if summary["run_out_m"] else ""),
        ),
        (
            "duration",
            f"{summary['duration_s']:.1f} s (cut {summary['cut_duration_s']:.1f} s, "
            f"speed ×{summary['cut_speed_scale']:.2f} of the path's), {summary['points']} points",
        ),
        (
            "joint limits",
            f"{'ok' if summary['limits_ok'] else 'EXCEEDED'}: velocity "
            f"{100 * summary['velocity_ratio_max']:.0f} %, acceleration "
            f"{100 * summary['acceleration_ratio_max']:.0f} %, jerk "
            f"{100 * summary['jerk_ratio_max']:.0f} % of the datasheet's; closest position "
            f"{summary['joint_limit_margin_min_rad']:.3f} rad "
            f"({summary['joint_limit_margin_joint']})",
        ),
        (
            "collisions",
            f"{summary['trajectory_collisions']} of {summary['points']} points; observed surface: "
            f"{summary['observed_surface']} ({summary['observed_points']} points, "
            f"{summary['unseen_voxels']} unseen voxels near the piece avoided); "
            f"{summary['transits_around_obstacles']} move(s) between cuts around obstacles",
        ),
        ("robot base", summary["robot_base"]),
        ("time", f"{summary['time_s']['total']:.2f} s (plan {summary['time_s']['plan']:.2f} s)"),
        ("written", ", ".join(summary["outputs"])),
    ]
    for key, value in rows:
        table.add_row(key, value)
    print_table(table)
