"""``scrapcut info REC [--json]``: format, topics, camera and usable frames of a recording."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from scrapcut_cli.commands._console import print_table
from scrapcut_cli.commands._options import build_config, config_option, recording_options

if TYPE_CHECKING:
    from scrapcut_cli.recording.summary import RecordingSummary


@click.command("info")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of tables.")
@recording_options
@config_option
def info(
    recording: Path,
    as_json: bool,
    color_topic: str | None,
    depth_topic: str | None,
    info_topic: str | None,
    base_frame: str | None,
    sync_tolerance_ms: float | None,
    salvage: bool | None,
    frames: tuple[float, float] | None,
    time_s: tuple[float, float] | None,
    config_path: Path | None,
) -> None:
    """Describe RECORDING (an .mcap file, a ROS 1 .bag or a ROS 2 bag directory).

    Shows every topic with its type and count, the camera intrinsics, how many colour frames
    pair with depth and have a pose (and why the others do not), the base and camera frames,
    and whether a reference curve and an exploration log are present. Reads headers (and
    decodes one colour and one depth image as a check).
    """
    from scrapcut_cli.recording.summary import summarize_recording

    config = build_config(
        config_path,
        color_topic=color_topic,
        depth_topic=depth_topic,
        info_topic=info_topic,
        base_frame=base_frame,
        sync_tolerance_ms=sync_tolerance_ms,
        salvage=salvage,
        frames=frames,
        time_s=time_s,
    )
    summary = summarize_recording(recording, config.recording)
    if as_json:
        from scrapcut_cli.commands._console import json_document

        click.echo(json_document("scrapcut.info/v1", summary.to_json()))
    else:
        render(summary)


def render(summary: RecordingSummary) -> None:
    """Rich tables on stdout."""
    from rich.markup import escape
    from rich.table import Table

    cam, plan = summary.camera, summary.plan
    overview = Table(title=escape(str(summary.path)), show_header=False, title_justify="left")
    overview.add_column(style="bold")
    overview.add_column()
    overview.add_row("format", summary.format)
    if summary.salvaged:
        overview.add_row("salvaged", escape(summary.salvaged))
    overview.add_row("duration", f"{summary.duration_s:.3f} s")
    reasons = ", ".join(f"{k} {v}" for k, v in sorted(plan.skip_reasons.items()))
    overview.add_row(
        "frames",
        f"{plan.usable} usable, {plan.skipped} skipped" + (f" ({reasons})" if reasons else ""),
    )
    if plan.unpaired_depth:
        n = plan.unpaired_depth
        overview.add_row("", f"{n} depth image{'s' * (n != 1)} without a colour partner")
    overview.add_row("colour", summary.color_topic)
    overview.add_row("depth", summary.depth_topic)
    overview.add_row("camera_info", summary.info_topic)
    overview.add_row(
        "camera",
        f"{cam.width}x{cam.height}  fx {cam.fx:.2f}  fy {cam.fy:.2f}  cx {cam.cx:.2f}  "
        f"cy {cam.cy:.2f}  {cam.distortion_model}",
    )
    overview.add_row("base frame", summary.base_frame)
    overview.add_row("camera frame", summary.camera_frame)
    overview.add_row("reference", "yes" if summary.has_reference else "no")
    overview.add_row("exploration log", "yes" if summary.has_exploration_log else "no")
    for name, data in sorted(summary.metadata.items()):
        overview.add_row(
            escape(f"metadata {name}"),
            escape("\n".join(f"{k}={_short(v)}" for k, v in data.items())),
        )
    print_table(overview)

    topics = Table(title="topics", title_justify="left")
    topics.add_column("topic")
    topics.add_column("type")
    topics.add_column("count", justify="right")
    for topic in summary.topics:
        topics.add_row(topic.name, topic.msgtype, str(topic.count))
    print_table(topics)


def _short(value: str, limit: int = 60) -> str:
    """A metadata value for the table: long ones (the simulator's JSON of every parameter, a
    few kB) would stretch it to a thousand columns; ``--json`` prints them whole."""
    if len(value) <= limit:
        return value
    return f"({len(value)} characters; --json shows it)"
