"""``scrapcut convert REC -o OUT [--format mcap|ros1|ros2]``: a recording in another format."""

from __future__ import annotations

from pathlib import Path

import click

from scrapcut_cli.commands._console import err


@click.command("convert")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    required=True,
    help="Output: FILE.mcap, FILE.bag (ROS 1) or a ROS 2 bag directory.",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["mcap", "ros1", "ros2"]),
    default=None,
    help="Output format (default: from -o: .mcap, .bag, else a ROS 2 bag directory).",
)
@click.option(
    "--storage",
    type=click.Choice(["mcap", "sqlite3"]),
    default="mcap",
    show_default=True,
    help="Storage plugin of a ROS 2 bag.",
)
def convert(recording: Path, output: Path, fmt: str | None, storage: str) -> None:
    """Convert RECORDING (.mcap, ROS 1 .bag or ROS 2 bag directory) to another format.

    Every topic is copied with its log times; ROS 1 output uses ROS 1 message definitions
    (CameraInfo K/D, header.seq). Metadata records are kept. OUT appears only when complete.
    """
    from scrapcut_cli.recording.convert import convert_recording, format_for_path

    fmt = fmt or format_for_path(output)
    convert_recording(recording, output, fmt=fmt, storage=storage)
    err.print(f"wrote {output} ({fmt})", soft_wrap=True, markup=False)
