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
    help="Storage plugin of a ROS 2 bag (default mcap).",
)
@click.option(
    "--compress",
    "compression",
    type=click.Choice(["zstd", "lz4", "bz2", "none"]),
    default=None,
    help="Compression (default: zstd; lz4 for a ROS 1 bag, which cannot hold zstd). MCAP takes "
    "zstd, lz4 or none; a ROS 2 bag zstd or none; a ROS 1 bag lz4, bz2 or none.",
)
@click.option(
    "--topics",
    "topics",
    multiple=True,
    metavar="T1,T2,...",
    help="Copy only these topics (comma-separated or repeated; default: all). Metadata is "
    "always kept; a topic the recording lacks is an error that lists those it has.",
)
@click.option("--json", "as_json", is_flag=True, help="Print what was written as JSON.")
def convert(
    recording: Path,
    output: Path,
    fmt: str | None,
    storage: str,
    compression: str | None,
    topics: tuple[str, ...],
    as_json: bool,
) -> None:
    """Convert RECORDING (.mcap, ROS 1 .bag or ROS 2 bag directory) to another format.

    Every topic (or those of --topics) is copied with its log times; ROS 1 output uses ROS 1
    message definitions (CameraInfo K/D, header.seq). Metadata records are kept. The output
    is compressed as recorders write it unless --compress none. OUT appears only when complete.
    """
    import json

    from scrapcut_cli import __version__
    from scrapcut_cli.recording.convert import (
        DEFAULT_COMPRESSION,
        convert_recording,
        format_for_path,
    )

    fmt = fmt or format_for_path(output)
    wanted = [t.strip() for group in topics for t in group.split(",") if t.strip()] or None
    convert_recording(
        recording, output, fmt=fmt, storage=storage, compression=compression, topics=wanted
    )
    compression = compression or DEFAULT_COMPRESSION.get(fmt, "none")
    if as_json:
        summary = {
            "schema": "scrapcut.convert/v1",
            "tool_version": __version__,
            "recording": str(recording),
            "output": str(output),
            "format": fmt,
            "storage": storage if fmt == "ros2" else None,
            "compression": compression,
            "topics": wanted,
            "size_bytes": _size(output),
        }
        click.echo(json.dumps(summary, indent=2))
    err.print(f"wrote {output} ({fmt}, {compression})", soft_wrap=True, markup=False)


def _size(path: Path) -> int:
    """Bytes of a file, or of every file in a folder (a ROS 2 bag)."""
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size
