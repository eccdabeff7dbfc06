"""``scrapcut stitch``: the stitched paint cloud of a recording (PLY or PCD)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from scrapcut_cli._io import check_output_path, real_path
from scrapcut_cli.commands._options import (
    apply_calibration_options,
    apply_stage_options,
    build_config,
    calibration_option,
    config_option,
    paint_options,
    perception_options,
    recording_options,
    split_stage_options,
    stitch_options,
)

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from scrapcut_cli.perception.stitch import StitchResult

CLOUD_SUFFIXES = (".ply", ".pcd")


def check_cloud_path(path: Path | None, option: str) -> None:
    """A usage error unless ``path`` ends in .ply or .pcd (open3d picks the format by it)."""
    if path is not None and path.suffix.lower() not in CLOUD_SUFFIXES:
        raise click.BadParameter(
            f"{path} must end in .ply or .pcd (the format is taken from it)", param_hint=option
        )


def write_cloud(target: Path, points: NDArray[np.float64]) -> None:
    """Write points (N, 3), metres, as PLY or PCD (by ``target``'s suffix), atomically.

    open3d chooses the format by the file name's extension, so it writes to a staging name
    with the target's suffix, which is then renamed onto the atomic temporary. open3d reports
    success even when the disk refused its writes, so the file is read back and its point
    count checked before it is committed.
    """
    import numpy as np

    from scrapcut_cli._io import atomic_path, quiet_stderr
    from scrapcut_cli._open3d import o3d
    from scrapcut_cli.errors import FileError, PerceptionError

    o3 = o3d()
    cloud = o3.geometry.PointCloud(o3.utility.Vector3dVector(np.asarray(points, np.float64)))

    def verify(tmp: Path) -> None:
        if binary_cloud_size(tmp) != tmp.stat().st_size:
            raise FileError(f"{target} was written incompletely (is the disk full?)")

    with atomic_path(target, verify=verify) as tmp:
        staging = tmp.with_name(tmp.name + target.suffix.lower())
        try:
            with quiet_stderr():
                written = len(points) > 0 and o3.io.write_point_cloud(str(staging), cloud)
            if not written:
                raise PerceptionError(f"cannot write {len(points)} points to {target}")
            os.replace(staging, tmp)
        finally:
            staging.unlink(missing_ok=True)


_PLY_TYPES = {"char": 1, "uchar": 1, "short": 2, "ushort": 2, "int": 4, "uint": 4, "float": 4}
_PLY_TYPES |= {"double": 8, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2, "int32": 4}
_PLY_TYPES |= {"uint32": 4, "float32": 4, "float64": 8}


def binary_cloud_size(path: Path) -> int:
    """The size in bytes a binary PLY or PCD file of vertices must have, from its header
    (-1 if the header is incomplete or not such a file): header + points x point size."""
    with path.open("rb") as f:
        head = f.read(4096)
    if head.startswith(b"ply\n"):
        end = head.find(b"end_header\n")
        if end < 0 or b"format binary" not in head[:end]:
            return -1
        count, size = 0, 0
        for line in head[:end].decode("ascii", "replace").splitlines():
            words = line.split()
            if words[:2] == ["element", "vertex"] and len(words) == 3:
                count = int(words[2])
            elif words[:1] == ["property"] and len(words) == 3:
                size += _PLY_TYPES.get(words[1], 0)
        return end + len("end_header\n") + count * size
    end = head.find(b"DATA binary\n")
    if end < 0:
        return -1
    fields = {}
    for line in head[:end].decode("ascii", "replace").splitlines():
        name, _, value = line.partition(" ")
        fields[name] = value
    try:
        sizes = [int(v) for v in fields.get("SIZE", "").split()]
        counts = [int(v) for v in fields.get("COUNT", "").split()]
        return (
            end
            + len("DATA binary\n")
            + int(fields["POINTS"]) * sum(s * c for s, c in zip(sizes, counts, strict=True))
        )
    except (KeyError, ValueError):
        return -1


@click.command("stitch")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Stitched paint cloud to write (.ply or .pcd), base frame, metres.",
)
@click.option(
    "--surface",
    "surface_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the surface band around the paint (.ply or .pcd).",
)
@click.option(
    "--json", "as_json", is_flag=True, help="Print the summary and per-frame growth as JSON."
)
@calibration_option
@config_option
@recording_options
@paint_options
@perception_options
@stitch_options
def stitch(
    recording: Path,
    output: Path,
    surface_path: Path | None,
    as_json: bool,
    calibration_path: Path | None,
    config_path: Path | None,
    **options: Any,
) -> None:
    """Stitch the paint seen in every frame of RECORDING into one cloud.

    Each frame's paint (HSV filter, depth gate, back-projection, voxel downsampling, outlier
    removal) is merged on a voxel grid, so paint seen twice counts once; --icp refines each
    frame against the cloud first. The cloud's size and its growth per frame (Algorithm 1's
    size(k) - size(k-1)) are printed; --json adds them frame by frame.
    """
    from scrapcut_cli.calibration.recipe import camera_mount_for
    from scrapcut_cli.commands._console import err, out, progress
    from scrapcut_cli.errors import PerceptionError
    from scrapcut_cli.perception.stitch import stitch_recording
    from scrapcut_cli.pipeline.fit import paint_for_recording
    from scrapcut_cli.recording.reader import open_recording

    check_cloud_path(output, "-o")
    check_cloud_path(surface_path, "--surface")
    if surface_path is not None and real_path(surface_path) == real_path(output):
        raise click.UsageError("--surface and -o name the same file")
    for target in (output, surface_path):
        if target is not None:
            check_output_path(target)
    stage, shared = split_stage_options(options)
    config = apply_stage_options(build_config(config_path, **shared), stage)
    config = apply_calibration_options(config, calibration_path)
    mount, _ = camera_mount_for(recording, config)

    with open_recording(recording, config.recording, mount=mount) as rec:
        plan = rec.plan()
        hsv, estimate = paint_for_recording(rec, config)
        if estimate is not None:
            err.print(f"paint {estimate.describe()}", soft_wrap=True, markup=False)
        with progress("frames") as bar:
            task = bar.add_task("stitching", total=plan.usable, status="")

            def advance(step: Any) -> None:
                bar.update(task, advance=1, status=f"{step.size} voxels")

            result = stitch_recording(rec.frames(), hsv, config, progress=advance)
    if surface_path is not None and len(result.surface_points) == 0:
        # Checked before anything is written: both clouds or neither.
        raise PerceptionError(
            f"no surface points to write to {surface_path} (surface band "
            f"{1000 * config.perception.surface_band_m:g} mm; see --surface-band-mm)"
        )
    write_cloud(output, result.paint_points)
    if surface_path is not None:
        write_cloud(surface_path, result.surface_points)

    summary = {
        "recording": str(recording),
        "output": str(output),
        "surface_output": None if surface_path is None else str(surface_path),
        "reader_skipped": plan.skipped,
        "reader_skip_reasons": dict(plan.skip_reasons),
        **result.to_dict(),
        "config": config.to_dict(),
    }
    if as_json:
        from scrapcut_cli.commands._console import json_document

        out.print_json(json_document("scrapcut.stitch/v1", summary))
        return
    _render(result, plan.skipped, output, surface_path)
    err.print(f"wrote {output}" + ("" if surface_path is None else f" and {surface_path}"))


def _render(result: StitchResult, reader_skipped: int, output: Path, surface: Path | None) -> None:
    from rich.table import Table

    from scrapcut_cli.commands._console import out

    tally = result.tally
    table = Table(title=f"stitched {result.hsv.describe()}", show_header=False)
    table.add_column("", style="bold")
    table.add_column("", justify="right")
    table.add_row("frames", str(tally.frames))
    table.add_row("frames with paint", str(tally.frames_with_paint))
    skipped = ", ".join(f"{k} {v}" for k, v in sorted(result.skip_reasons.items())) or "none"
    table.add_row("frames without usable paint", skipped)
    if reader_skipped:
        table.add_row("frames the reader skipped", str(reader_skipped))
    table.add_row("paint pixels", f"{tally.paint_pixels:,}")
    table.add_row("paint voxels (size)", f"{result.size:,}")
    last = [s.growth for s in result.steps[-3:]]
    table.add_row("growth, last frames", ", ".join(str(g) for g in last))
    table.add_row("surface points", f"{len(result.surface_points):,}")
    if any(s.icp is not None for s in result.steps):
        table.add_row("ICP corrections accepted", str(result.icp_accepted))
    table.add_row("cloud", str(output))
    if surface is not None:
        table.add_row("surface cloud", str(surface))
    out.print(table)
