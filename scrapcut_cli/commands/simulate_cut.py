"""``scrapcut simulate-cut``: play a joint trajectory on the simulated Panda and measure it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from scrapcut_cli.commands._options import (
    bounded,
    build_config,
    config_option,
    config_type,
    recording_options,
)


@click.command("simulate-cut")
@click.argument("traj_file", metavar="TRAJ.json", type=click.Path(path_type=Path))
@click.option(
    "--recording",
    type=click.Path(path_type=Path),
    required=True,
    help="The recording the path was fitted from: its base frame, and (simulator "
    "recordings) the true piece for collisions.",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the report as JSON.",
)
@click.option(
    "--time-step-ms",
    type=bounded(0.1, 20.0, "pybullet is unstable beyond 20 ms; 0.1 ms is ten times Franka's rate"),
    default=1.0,
    help="Simulation and control step [ms] (default 1: Franka's controller runs at 1 ms).",
)
@click.option(
    "--check-period-ms",
    type=bounded(1.0, 10_000.0, "one check per control period at most; 10 s misses a pass"),
    default=50.0,
    help="Collision checks along the simulated motion, every [ms] (default 50).",
)
@click.option(
    "--floor-z-mm",
    type=config_type("motion.floor_z_m", 1e-3),
    default=0.0,
    help="Height of the floor in the base frame [mm] (default 0).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@config_option
@recording_options
def simulate_cut(
    traj_file: Path,
    recording: Path,
    output: Path | None,
    time_step_ms: float,
    check_period_ms: float,
    floor_z_mm: float,
    as_json: bool,
    config_path: Path | None,
    **shared: Any,
) -> None:
    """Play TRAJ.json on pybullet's Panda with a torch and report what it did.

    The points are interpolated as a joint-trajectory controller does (quintics through
    positions, velocities, accelerations) and tracked by pybullet's position controller with
    Franka's torque limits, under gravity. Reports the torch tip's deviation from the
    set-points, the joints' margins to their limits and, for simulator recordings, collisions
    of the arm and torch with the piece's true mesh and the floor.
    """
    from scrapcut_cli._io import write_text_atomic
    from scrapcut_cli.sim.cut import CutSimSettings
    from scrapcut_cli.sim.cut_job import simulate_cut_files

    if output is not None and output.resolve() in (traj_file.resolve(), recording.resolve()):
        raise click.UsageError(f"{output} would overwrite an input; choose another -o")
    config = build_config(config_path, **shared)
    report = simulate_cut_files(
        traj_file,
        recording,
        config=config,
        settings=CutSimSettings(
            time_step_s=time_step_ms / 1000.0, check_period_s=check_period_ms / 1000.0
        ),
        floor_z_m=floor_z_mm / 1000.0,
    )
    if output is not None:
        write_text_atomic(output, json.dumps(report, indent=1, allow_nan=False) + "\n")
        report["outputs"] = [str(output)]
    if as_json:
        from scrapcut_cli.commands._console import json_document

        click.echo(json_document("scrapcut.simulate_cut/v1", report))
    else:
        _render(report, traj_file)


def _render(report: dict[str, Any], traj_file: Path) -> None:
    from rich.table import Table

    from scrapcut_cli.commands._console import print_table

    def mm(stats: dict[str, Any]) -> str:
        if stats["max"] is None:
            return "-"
        return f"{stats['max']:.3f} max, {stats['mean']:.3f} mean"

    table = Table(title=f"scrapcut simulate-cut — {traj_file.name}", show_header=False)
    table.add_column("", style="bold")
    table.add_column("")
    collisions = report["collisions"]
    hit_text = (
        ", ".join(f"{c['body']}/{c['obstacle']} from {c['first_t_s']:.1f} s" for c in collisions)
        or "none"
    )
    torch_clear = report["clearance_mm"]["torch"]
    rows = [
        ("set-points", f"{report['setpoints_checked']} passed by the torch"),
        ("tip deviation", f"{mm(report['tip_error_mm'])} mm (simulated arm vs set-point)"),
        ("axis deviation", f"{mm(report['axis_error_deg'])} °"),
        ("plan accuracy", f"{mm(report['planned_tip_error_mm'])} mm (commanded joints)"),
        ("joint tracking", f"{report['tracking_error_max_rad']:.5f} rad max"),
        (
            "joint limits",
            f"closest {report['joint_margin_min_rad']:.3f} rad ({report['joint_margin_joint']})",
        ),
        ("piece", report["piece"] or "none (not a simulator recording: floor only)"),
        ("collisions", hit_text),
        (
            "torch clearance",
            "more than 15 mm" if torch_clear is None else f"{torch_clear:.1f} mm to the piece",
        ),
        (
            "simulated",
            f"{report['duration_s']:.1f} s in {report['steps']} steps of "
            f"{1000 * report['time_step_s']:g} ms, {report['collision_checks']} checks",
        ),
    ]
    if report.get("outputs"):
        rows.append(("written", ", ".join(report["outputs"])))
    for key, value in rows:
        table.add_row(key, value)
    print_table(table)
