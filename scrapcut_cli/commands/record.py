"""``scrapcut record``: simulate a scan of a painted scrap piece into an MCAP recording."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click
import numpy as np

from scrapcut_cli.commands._options import (
    build_config,
    config_option,
    config_type,
    mm_to_m,
    paint_options,
)
from scrapcut_cli.config import FitMethod, ScanMode, choice_names

MODES = choice_names(ScanMode)
NOISES = ("ideal", "d435i", "yard")
METHODS = choice_names(FitMethod)


@click.command("record")
@click.option(
    "--object",
    "object_name",
    default=None,
    metavar="NAME",
    help="Scrap piece to scan (default cylinder); 'list' prints the pieces.",
)
@click.option(
    "--mode",
    type=click.Choice(MODES),
    default=None,
    help="sweep: views along the line; survey: dense views over the piece; explore: "
    "Algorithm 1 in closed loop (default sweep).",
)
@click.option(
    "--method",
    type=click.Choice(METHODS),
    default=None,
    help="Curve fit the explore planner extrapolates (explore mode; default nurbs).",
)
@click.option(
    "--noise",
    type=click.Choice(NOISES),
    default=None,
    help="Sensor model: exact, a D435i, or a D435i in a scrap yard (default d435i).",
)
@paint_options
@click.option(
    "--seed", type=config_type("sim.seed"), default=None, help="Random seed; same seed, same bytes."
)
@click.option(
    "--width", type=config_type("sim.width"), default=None, help="Image width [px] (640)."
)
@click.option(
    "--height", type=config_type("sim.height"), default=None, help="Image height [px] (480)."
)
@click.option(
    "--resolution",
    default=None,
    metavar="WxH",
    help="Image size, e.g. 1280x720 (realsense-ros 4.x's default); instead of --width/--height.",
)
@click.option(
    "--color-encoding",
    type=click.Choice(("rgb8", "jpeg")),
    default=None,
    help="Colour as raw rgb8 images, or JPEG-compressed only on "
    ".../color/image_raw/compressed as image_transport publishes it (default rgb8).",
)
@click.option(
    "--jpeg-quality",
    type=config_type("sim.jpeg_quality"),
    default=None,
    help="JPEG quality with --color-encoding jpeg (default 95, image_transport's).",
)
@click.option(
    "--storage",
    type=click.Choice(("sqlite3", "mcap")),
    default=None,
    help="Storage of a ROS 2 bag output (-o DIR) (default sqlite3, rosbag2's).",
)
@click.option(
    "--distractors",
    default=None,
    metavar="LIST",
    help="Things of paint-like colour on the floor beside the piece: comma list of box, cone, "
    "glove, or 'none' (default: the noise preset's; yard: all three).",
)
@click.option(
    "--faded-marks",
    type=config_type("sim.faded_marks"),
    default=None,
    help="Old faded marks of the same hue near the line (default: the noise preset's; yard 1).",
)
@click.option(
    "--glints/--no-glints",
    default=None,
    help="Mirror-like spots on the steel (default: the noise preset's; yard on).",
)
@click.option(
    "--paint-variation/--no-paint-variation",
    default=None,
    help="The can's colour varies around the preset's (default: on, except --noise ideal).",
)
@click.option(
    "--views",
    type=config_type("sim.views"),
    default=None,
    help="Number of views (sweep / survey); 0: one per 50 mm of line / the full survey.",
)
@click.option(
    "--frames-per-view",
    type=config_type("sim.frames_per_view"),
    default=None,
    help="Images captured at each view, at 30 Hz (default 1).",
)
@click.option(
    "--stroke-width-mm",
    type=config_type("sim.stroke_width_m", 1e-3),
    default=None,
    help="Spray stroke width [mm] (default 25).",
)
@click.option(
    "--distance-mm",
    type=config_type("sim.view_distance_m", 1e-3),
    default=None,
    help="Camera distance to the line [mm] (default 300).",
)
@click.option(
    "--start-fraction",
    type=config_type("sim.start_fraction"),
    default=None,
    help="Explore mode: where along the line (0-1) the first view looks, as a worker would "
    "point the robot (default: the middle; 0.2 on slanted, on one face).",
)
@click.option(
    "--depth-encoding",
    type=click.Choice(("16UC1", "32FC1")),
    default=None,
    help="Depth image encoding: millimetres as realsense-ros, or float metres (default 16UC1).",
)
@click.option(
    "--calibration-views",
    type=config_type("exploration.calibration_views"),
    default=None,
    help="Explore mode: after both ends, this many views of the first stretch, tilted and "
    "rolled, so that scrapcut calibrate can see every direction of the mount (default 0).",
)
@click.option(
    "--hand-eye-error-mm",
    type=config_type("sim.hand_eye_error_m", 1e-3),
    default=None,
    help="Hand-eye calibration error: the camera sits this far from where /tf_static says, "
    "in a random direction [mm] (default: the noise preset's; yard 2).",
)
@click.option(
    "--hand-eye-error-deg",
    type=config_type("sim.hand_eye_error_deg"),
    default=None,
    help="Hand-eye calibration error: rotation about a random axis [deg] (yard 0.3).",
)
@click.option(
    "--stamp-offset-ms",
    type=config_type("sim.stamp_offset_s", 1e-3),
    default=None,
    help="Image header stamps minus capture time on the robot's clock [ms] (default: the "
    "preset's; yard 10-20 either way, seeded).",
)
@click.option(
    "--motion-frames-hz",
    type=config_type("sim.motion_frames_hz"),
    default=None,
    help="Images per second recorded while the arm moves between views, as a streaming "
    "camera gives them (default: the preset's; yard 6; 0: only at rest).",
)
@config_option
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    default=None,
    help="MCAP file (*.mcap), or a ROS 2 bag directory (any other name) to write.",
)
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print what was recorded as JSON (scrapcut.record/v1) instead of the table.",
)
def record(
    object_name: str | None,
    mode: str | None,
    method: str | None,
    noise: str | None,
    paint: str | None,
    hsv: str | None,
    seed: int | None,
    width: int | None,
    height: int | None,
    resolution: str | None,
    color_encoding: str | None,
    jpeg_quality: int | None,
    storage: str | None,
    distractors: str | None,
    faded_marks: int | None,
    glints: bool | None,
    paint_variation: bool | None,
    views: int | None,
    frames_per_view: int | None,
    stroke_width_mm: float | None,
    distance_mm: float | None,
    start_fraction: float | None,
    depth_encoding: str | None,
    calibration_views: int | None,
    hand_eye_error_mm: float | None,
    hand_eye_error_deg: float | None,
    stamp_offset_ms: float | None,
    motion_frames_hz: float | None,
    config_path: Path | None,
    output: Path | None,
    as_json: bool,
) -> None:
    """Simulate a scan of a spray-painted scrap piece: a Panda with a D435i on its hand.

    Writes an MCAP (or a ROS 2 bag directory) with realsense-ros topics, /tf at 100 Hz, the
    painted reference on /scrapcut/reference and the settings in its metadata; it opens in
    Foxglove and in every scrapcut command. The piece is painted with a can of the --paint
    preset's colour (each can a little different; --hsv only tunes the filter of the explore
    planner). --noise yard also puts an old faded mark, distractors and glints in the scene.
    """
    from scrapcut_cli.commands._console import err, out, progress
    from scrapcut_cli.sim import list_objects
    from scrapcut_cli.sim import record as record_scan
    from scrapcut_cli.sim.recorder import validate

    if object_name == "list":
        _print_objects(out, list_objects())
        return
    if output is None:
        raise click.UsageError("missing -o/--output (the MCAP file to write)")
    if output.suffix.lower() == ".bag" or (output.suffix and output.suffix != ".mcap"):
        # Readers tell the format by name too: an MCAP called scan.bag would not open.
        raise click.BadParameter(
            f"the simulator writes MCAP (*.mcap) or a ROS 2 bag directory (a name without a "
            f"suffix), not {output.name!r} (`scrapcut convert` makes a ROS 1 bag)",
            param_hint="-o/--output",
        )
    if output.suffix != ".mcap" and output.is_file():
        raise click.BadParameter(
            f"{output} is a file; a ROS 2 bag is a directory", param_hint="-o/--output"
        )
    if resolution is not None:
        if width is not None or height is not None:
            raise click.UsageError("give --resolution or --width/--height, not both")
        width, height = _parse_resolution(resolution)

    config = build_config(config_path, paint=paint, hsv=hsv)
    config = config.override("exploration", method=method, calibration_views=calibration_views)
    config = config.override(
        "sim",
        object=object_name,
        mode=mode,
        noise=noise,
        paint=paint,
        seed=seed,
        width=width,
        height=height,
        views=views,
        frames_per_view=frames_per_view,
        stroke_width_m=mm_to_m(stroke_width_mm),
        view_distance_m=mm_to_m(distance_mm),
        start_fraction=start_fraction,
        depth_encoding=depth_encoding,
        hand_eye_error_m=mm_to_m(hand_eye_error_mm),
        hand_eye_error_deg=hand_eye_error_deg,
        stamp_offset_s=mm_to_m(stamp_offset_ms),
        motion_frames_hz=motion_frames_hz,
        color_encoding=color_encoding,
        jpeg_quality=jpeg_quality,
        storage=storage,
        distractors=_parse_distractors(distractors),
        faded_marks=faded_marks,
        glints=glints,
        paint_variation=paint_variation,
    )
    sim = config.sim
    validate(sim)
    err.print(
        f"recording {sim.object} ({sim.mode}, {sim.noise} noise, {sim.paint} paint, "
        f"{sim.width}×{sim.height} px, seed {sim.seed}) → {output}",
        soft_wrap=True,
        markup=False,
    )
    factory = None
    if sim.mode == "explore":
        from scrapcut_cli.exploration.planner import planner_factory
        from scrapcut_cli.perception.paint import resolve_paint

        # The planner looks for the simulator's paint unless --hsv tunes its filter.
        planner_hsv = resolve_paint(config.paint) if config.paint.hsv is not None else None
        factory = planner_factory(config, hsv=planner_hsv)
    with progress("views") as bar:
        task = bar.add_task("recording", total=None, status="")

        def advance(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        result = record_scan(sim, output, progress=advance, planner_factory=factory)
    if as_json:
        import dataclasses

        from scrapcut_cli.commands._console import json_document

        data = {k: getattr(result, k) for k in (f.name for f in dataclasses.fields(result))}
        data["path"] = str(result.path)
        data["size_bytes"] = result.path.stat().st_size
        click.echo(json_document("scrapcut.record/v1", data))
        return
    _print_result(out, result)


_PLANNED_WITH = {
    "truth": "the true piece (oracle)",
    "observed": "what the camera observed",
}


def _clearance_mm(clearance_m: float) -> str:
    if not np.isfinite(clearance_m):
        return "—"
    return f"{1000.0 * clearance_m:.0f}" if clearance_m < 0.1 else "≥ 100"


def _parse_resolution(text: str) -> tuple[int, int]:
    """``1280x720`` -> (1280, 720); a usage error naming the value otherwise."""
    parts = text.lower().replace("×", "x").split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        width = height = 0
    if width < 16 or height < 12:
        raise click.BadParameter(
            f"expected WIDTHxHEIGHT, e.g. 1280x720 (at least 16x12), got {text!r}",
            param_hint="--resolution",
        )
    return width, height


def _parse_distractors(text: str | None) -> tuple[str, ...] | None:
    """``box,cone`` -> ("box", "cone"); ``none`` -> (); a usage error for unknown names."""
    from scrapcut_cli.sim.scene import DISTRACTOR_KINDS

    if text is None:
        return None
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if names in ((), ("none",)):
        return ()
    if names == ("all",):
        return DISTRACTOR_KINDS
    unknown = [n for n in names if n not in DISTRACTOR_KINDS]
    if unknown:
        raise click.BadParameter(
            f"unknown distractor {unknown[0]!r}; choose from {', '.join(DISTRACTOR_KINDS)}, "
            "all or none",
            param_hint="--distractors",
        )
    return names


def _print_objects(console: Any, objects: list[tuple[str, str]]) -> None:
    from rich.table import Table

    table = Table(title="simulated scrap pieces", title_justify="left")
    table.add_column("object")
    table.add_column("description")
    for name, description in objects:
        table.add_row(name, description)
    console.print(table)


def _print_result(console: Any, result: Any) -> None:
    from rich.markup import escape
    from rich.table import Table

    path = result.path
    files = [p for p in path.iterdir() if p.is_file()] if path.is_dir() else [path]
    size_mb = sum(p.stat().st_size for p in files) / 1e6
    title = escape(f"{result.path} ({size_mb:.1f} MB)")
    table = Table(title=title, title_justify="left")
    table.add_column("")
    table.add_column("value", justify="right")
    rows = [
        ("object", result.object),
        ("mode / noise / seed", f"{result.mode} / {result.noise} / {result.seed}"),
        ("views executed", str(result.views)),
        ("frames (while moving)", f"{result.frames} ({result.moving_frames})"),
        ("infeasible views (skipped)", str(result.infeasible_views)),
        ("views adjusted (roll / back-off)", str(result.adjusted_views)),
        ("collision checks saw", _PLANNED_WITH.get(result.planned_with, result.planned_with)),
        ("crashes (true piece, floor)", f"{result.collisions} ({result.motion_collisions} moving)"),
        ("closest approach to the piece (mm)", _clearance_mm(result.min_clearance_m)),
        ("camera travel (m)", f"{result.camera_travel_m:.2f}"),
        ("simulated time (s)", f"{result.duration_s:.1f}"),
        ("wall time (s)", f"{result.wall_time_s:.1f}"),
        ("stopped because", result.stop_reason),
    ]
    for name, value in rows:
        table.add_row(name, value)
    console.print(table)
