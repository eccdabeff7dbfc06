"""``scrapcut calibrate REC``: the camera mount and clock offset, estimated from the scan."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from scrapcut_cli.commands._options import (
    build_config,
    config_option,
    config_type,
    paint_options,
    recording_options,
)

if TYPE_CHECKING:
    from scrapcut_cli.calibration.result import Calibration


@click.command("calibrate")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of tables.")
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    metavar="CAL.yaml",
    help="Write the calibration: YAML values, static_transform_publisher lines for ROS 1 and "
    "ROS 2, usable as --calibration by filter, stitch, fit and explore.",
)
@click.option(
    "--max-frames",
    type=config_type("calibration.max_frames"),
    default=None,
    help="Frames compared, chosen for diverse poses and speeds (default 40).",
)
@config_option
@recording_options
@paint_options
def calibrate(
    recording: Path,
    as_json: bool,
    output: Path | None,
    max_frames: int | None,
    config_path: Path | None,
    **shared: Any,
) -> None:
    """Estimate the camera mount and clock offset of RECORDING from its own frames.

    Overlapping frames see the same surface and the same paint edges from different poses:
    with the right hand-eye transform (the moving frame of /tf, e.g. panda_link8, to the
    image's optical frame) and camera-to-/tf clock offset they coincide. Reports each
    correction with its standard deviation, which directions this scan cannot determine and
    why (those keep the published values), and the residual before and after. When the
    correction is not significant the published calibration is kept.
    """
    from scrapcut_cli.calibration.calfile import write_calibration_file
    from scrapcut_cli.calibration.recipe import calibrate_recording
    from scrapcut_cli.commands._console import err, progress

    if output is not None and output.resolve() == recording.resolve():
        raise click.UsageError(f"{output} would overwrite the recording; choose another -o")
    config = build_config(config_path, **shared)
    config = config.override("calibration", max_frames=max_frames)
    with progress("frames") as bar:
        task = bar.add_task("reading", total=None, status="")

        def advance(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        result = calibrate_recording(recording, config=config, progress=advance)
    if output is not None:
        write_calibration_file(output, result)
    if as_json:
        data = result.to_dict()
        data["output"] = None if output is None else str(output)
        from scrapcut_cli.commands._console import json_document

        click.echo(json_document("scrapcut.calibration/v1", data))
    else:
        _render(result)
        if output is not None:
            err.print(f"wrote {output}")


def _render(result: Calibration) -> None:
    import math

    from rich.markup import escape
    from rich.table import Table

    from scrapcut_cli.commands._console import print_table

    s = result.solution
    data = result.to_dict()
    table = Table(title=escape(f"scrapcut calibrate — {data['source'].get('path', '')}"))
    table.add_column("parameter")
    table.add_column("correction", justify="right")
    table.add_column("sigma", justify="right")
    table.add_column("observable")
    names = [
        ("translation x (camera, right)", "mm"),
        ("translation y (camera, down)", "mm"),
        ("translation z (optical axis)", "mm"),
        ("rotation about x", "deg"),
        ("rotation about y", "deg"),
        ("rotation about z", "deg"),
        ("clock offset", "ms"),
    ]
    for (name, unit), x, sigma, ok in zip(names, s.correction, s.sigma, s.observable, strict=True):
        digits = 3 if unit == "deg" else 2
        table.add_row(
            name,
            f"{x:+.{digits}f} {unit}",
            "-" if not math.isfinite(sigma) else f"{sigma:.{digits}f} {unit}",
            "yes" if ok else "[yellow]no[/]",
        )
    print_table(table)

    summary = Table(show_header=False, title="summary")
    summary.add_column("", style="bold")
    summary.add_column("")
    before, after = s.residual_before_mm, s.residual_after_mm
    rows = [
        ("mount", f"{data['moving_frame']} → {data['camera_frame']}"),
        (
            "frames",
            f"{s.frames} compared of {data['source'].get('frames', '?')}, {s.pairs} overlapping "
            f"pairs, {s.residuals} residuals",
        ),
        (
            "residual RMS",
            f"{before['all']:.2f} → {after['all']:.2f} mm (surface {before['surface']:.2f} → "
            f"{after['surface']:.2f}, paint edges {before['edge']:.2f} → {after['edge']:.2f})",
        ),
    ]
    for u in s.unobservable:
        rows.append(("not observable", f"{u.what}: {u.why}"))
    effect = data["calibration_views"]
    if effect is not None:
        ratios = [r for r in effect["sigma_ratio"] if r is not None]
        text = f"{effect['frames']} frames"
        if ratios:
            text += f"; sigma narrowed {min(ratios):.1f}x to {max(ratios):.1f}x"
        if effect["became_observable"]:
            text += f"; made observable: {', '.join(effect['became_observable'])}"
        rows.append(("calibration views", text))
    t = data["T_moving_camera"]
    rows += [
        (
            "T_moving_camera",
            "xyz "
            + " ".join(f"{v:.5f}" for v in t["translation_m"])
            + " m, xyzw "
            + " ".join(f"{v:.6f}" for v in t["rotation_xyzw"]),
        ),
        ("time offset", f"{1000 * data['time_offset_s']:+.2f} ms (added to image stamps)"),
        ("time", f"{result.time_s:.1f} s"),
        ("verdict", data["verdict"]),
    ]
    for key, value in rows:
        summary.add_row(key, escape(value))
    print_table(summary)
