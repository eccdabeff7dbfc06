"""``scrapcut filter``: per-frame paint clouds of a recording (MCAP for Foxglove, or PLY files)."""

from __future__ import annotations

import contextlib
import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from scrapcut_cli._io import real_path
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
)

if TYPE_CHECKING:
    from scrapcut_cli.perception.cloud import FrameClouds, PerceptionTally
    from scrapcut_cli.recording.reader import FramePlan

PAINT_TOPIC = "/scrapcut/paint"
SURFACE_TOPIC = "/scrapcut/surface"


class _McapSink:
    """Every frame's clouds as sensor_msgs/PointCloud2 at the image stamp, base frame."""

    def __init__(self, writer: Any, base_frame: str, rgb: tuple[int, int, int], surface: bool):
        self.writer = writer
        self.base_frame = base_frame
        self.rgb = rgb
        self.surface = surface

    def add(self, clouds: FrameClouds) -> None:
        import numpy as np

        colours = np.tile(np.asarray(self.rgb, dtype=np.uint8), (len(clouds.paint_base), 1))
        # Frames without paint get an empty cloud, so a viewer clears the previous one.
        self.writer.write_pointcloud(
            PAINT_TOPIC, clouds.stamp_ns, self.base_frame, clouds.paint_base, colours
        )
        if self.surface:
            self.writer.write_pointcloud(
                SURFACE_TOPIC, clouds.stamp_ns, self.base_frame, clouds.surface_base
            )


class _PlySink:
    """One PLY per frame with paint: ``paint_000012.ply`` (and ``surface_000012.ply``)."""

    def __init__(self, directory: Path, surface: bool) -> None:
        self.directory = directory
        self.surface = surface

    def add(self, clouds: FrameClouds) -> None:
        from scrapcut_cli.commands.stitch import write_cloud

        if clouds.skipped:
            return
        write_cloud(self.directory / f"paint_{clouds.frame_index:06d}.ply", clouds.paint_base)
        if self.surface and len(clouds.surface_base):
            name = f"surface_{clouds.frame_index:06d}.ply"
            write_cloud(self.directory / name, clouds.surface_base)


#: The files a PLY folder written by ``scrapcut filter`` holds; only such a folder is replaced.
_PLY_NAME = re.compile(r"(paint|surface)_\d{6}\.ply")


def _check_output(output: Path, recording: Path) -> None:
    """A usage error unless ``-o`` names an .mcap file or a folder that may be (re)placed.

    A PLY folder replaces an existing one as a whole, so an existing folder must hold only what
    an earlier ``scrapcut filter`` wrote there: ``-o .`` or ``-o ~/data`` is refused, never wiped.
    """
    if output.suffix and output.suffix.lower() != ".mcap":
        raise click.BadParameter(
            f"{output}: give a .mcap file or a folder name (no suffix)", param_hint="-o"
        )
    if output.exists() and real_path(output) == real_path(recording):
        raise click.BadParameter(f"{output} is the recording itself", param_hint="-o")
    if output.suffix or not output.exists():
        return
    if not output.is_dir():
        raise click.BadParameter(f"{output} exists and is not a folder", param_hint="-o")
    target = real_path(output)
    if target == real_path(Path.cwd()) or target in real_path(Path.cwd()).parents:
        raise click.BadParameter(f"{output} holds the current folder", param_hint="-o")
    foreign = sorted(p.name for p in output.iterdir() if not _PLY_NAME.fullmatch(p.name))
    if foreign:
        raise click.BadParameter(
            f"{output} holds files scrapcut filter did not write (e.g. {foreign[0]}) and would "
            "be replaced as a whole; give a new folder",
            param_hint="-o",
        )


@contextlib.contextmanager
def _sink(
    output: Path | None,
    *,
    base_frame: str,
    rgb: tuple[int, int, int],
    surface: bool,
    meta: dict[str, str],
) -> Iterator[_McapSink | _PlySink | None]:
    """Where the clouds go; the output appears only if the block finishes without an error."""
    if output is None:
        yield None
        return
    if output.suffix.lower() == ".mcap":
        from scrapcut_cli.recording.writer import McapWriter

        with McapWriter(output) as writer:
            writer.add_metadata("scrapcut", meta)
            yield _McapSink(writer, base_frame, rgb, surface)
        return
    from scrapcut_cli._io import atomic_path

    with atomic_path(output, directory=True) as tmp:
        yield _PlySink(tmp, surface)


@click.command("filter")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    default=None,
    help="PAINT.mcap (PointCloud2 on /scrapcut/paint, base frame) or a folder of PLY files "
    "(replaced whole, so an existing one may hold only an earlier run's PLYs); without it "
    "only the summary is printed.",
)
@click.option(
    "--with-surface",
    "with_surface",
    is_flag=True,
    help="Also write each frame's surface band (/scrapcut/surface, or surface_*.ply).",
)
@click.option(
    "--surface",
    "old_surface",
    is_flag=True,
    hidden=True,
    help="Deprecated spelling of --with-surface (`--surface FILE` names a file elsewhere).",
)
@click.option(
    "--overlay",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder of per-frame PNGs (frame_000012.png): the image with the paint mask (kept "
    "green, dropped yellow), the stitched line (cyan) and rejected candidates (red, labelled), "
    "next to a hue-saturation histogram of paint vs background with the filter's range.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@calibration_option
@config_option
@recording_options
@paint_options
@perception_options
def filter_cmd(
    recording: Path,
    output: Path | None,
    with_surface: bool,
    old_surface: bool,
    overlay: Path | None,
    as_json: bool,
    calibration_path: Path | None,
    config_path: Path | None,
    **options: Any,
) -> None:
    """Filter the paint out of every frame of RECORDING and back-project it.

    Per frame: HSV colour filter, depth gate (range, flying pixels), back-projection into the
    base frame, voxel downsampling and statistical outlier removal. Frames without paint are
    counted, not fatal; a recording without any paint is an error that names the colours seen.
    """
    from scrapcut_cli.calibration.recipe import camera_mount_for
    from scrapcut_cli.commands._console import deprecated, err, out, progress

    if old_surface:
        deprecated("--surface", "--with-surface")
        with_surface = True
    from scrapcut_cli.perception.cloud import PerceptionTally, process_frame
    from scrapcut_cli.perception.paint import PAINT_PRESETS
    from scrapcut_cli.perception.stitch import Stitcher
    from scrapcut_cli.pipeline.fit import paint_for_recording
    from scrapcut_cli.recording.reader import open_recording

    if output is not None:
        _check_output(output, recording)
    if overlay is not None:
        _check_overlay(overlay, recording)
    stage, shared = split_stage_options(options)
    config = apply_stage_options(build_config(config_path, **shared), stage)
    config = apply_calibration_options(config, calibration_path)
    mount, _ = camera_mount_for(recording, config)

    with open_recording(recording, config.recording, mount=mount) as rec:
        plan = rec.plan()
        hsv, estimate = paint_for_recording(rec, config)
        if estimate is not None:
            err.print(f"paint {estimate.describe()}", soft_wrap=True, markup=False)
        preset = PAINT_PRESETS.get(estimate.preset if estimate is not None else hsv.name)
        meta = {
            "kind": "paint_clouds",
            "source": str(recording),
            "paint": hsv.describe(),
            "params": json.dumps(config.to_dict(), sort_keys=True),
        }
        if calibration_path is not None:
            meta["calibration"] = str(calibration_path)
        tally = PerceptionTally(hsv)
        stitcher = Stitcher(config.stitch, perception=config.perception) if overlay else None
        centres = []
        with (
            _sink(
                output,
                base_frame=rec.base_frame,
                rgb=preset.rgb if preset else (255, 0, 255),
                surface=with_surface,
                meta=meta,
            ) as sink,
            progress("frames") as bar,
        ):
            task = bar.add_task("filtering", total=plan.usable, status="")
            for frame in rec.frames():
                clouds = process_frame(frame, hsv, config.perception)
                tally.add(clouds, frame.color)
                if sink is not None:
                    sink.add(clouds)
                if stitcher is not None:
                    stitcher.add(clouds)
                    if clouds.view_centre is not None:
                        centres.append([clouds.T_base_cam[:3, 3], clouds.view_centre])
                bar.update(task, advance=1, status=f"{tally.paint_points:,} points")
            tally.raise_if_no_paint()  # before the output is committed
        if overlay is not None and stitcher is not None:
            _write_overlays(rec, overlay, hsv, config, stitcher, centres)

    summary = {
        "recording": str(recording),
        "output": None if output is None else str(output),
        "reader_skipped": plan.skipped,
        "reader_skip_reasons": dict(plan.skip_reasons),
        **tally.to_dict(),
    }
    if as_json:
        from scrapcut_cli.commands._console import json_document

        out.print_json(json_document("scrapcut.filter/v1", summary))
        return
    _render(tally, plan)
    if output is not None:
        err.print(f"wrote {output}")
    if overlay is not None:
        err.print(f"wrote {plan.usable} overlay PNGs to {overlay}")


#: The files an overlay folder written by ``scrapcut filter`` holds.
_PNG_NAME = re.compile(r"frame_\d{6}\.png")


def _check_overlay(folder: Path, recording: Path) -> None:
    """A usage error unless ``--overlay`` names a folder that may be (re)placed whole."""
    if folder.exists() and folder.resolve() == recording.resolve():
        raise click.BadParameter(f"{folder} is the recording itself", param_hint="--overlay")
    if not folder.exists():
        return
    if not folder.is_dir():
        raise click.BadParameter(f"{folder} exists and is not a folder", param_hint="--overlay")
    target = folder.resolve()
    if target == Path.cwd().resolve() or target in Path.cwd().resolve().parents:
        raise click.BadParameter(f"{folder} holds the current folder", param_hint="--overlay")
    foreign = sorted(p.name for p in folder.iterdir() if not _PNG_NAME.fullmatch(p.name))
    if foreign:
        raise click.BadParameter(
            f"{folder} holds files scrapcut filter did not write (e.g. {foreign[0]}) and would "
            "be replaced as a whole; give a new folder",
            param_hint="--overlay",
        )


def _write_overlays(
    rec: Any, folder: Path, hsv: Any, config: Any, stitcher: Any, centres: list[Any]
) -> None:
    """Second pass over the frames: one PNG each with the mask and the candidates."""
    import numpy as np
    from PIL import Image

    from scrapcut_cli._io import atomic_path
    from scrapcut_cli.commands._console import err, progress
    from scrapcut_cli.errors import PerceptionError
    from scrapcut_cli.perception.candidates import select_line
    from scrapcut_cli.perception.overlay import Marked, overlay_image

    points = np.vstack([stitcher.paint_points, stitcher.other_points])
    marked: list[Marked] = []
    try:
        selection = select_line(
            points,
            np.vstack([stitcher.paint_rgb, stitcher.other_rgb]),
            np.asarray(centres).reshape(-1, 2, 3),
            voxel_m=config.stitch.voxel_size_m,
            config=config.selection,
        )
    except PerceptionError as exc:
        err.print(f"[yellow]note:[/] no line picked for the overlay ({exc})", soft_wrap=True)
    else:
        marked = [Marked(points[c.points], "line", line=True) for c in selection.lines]
        marked += [
            Marked(points[c.points], c.kind) for c in selection.rejected if c.kind != "speck"
        ]
    with atomic_path(folder, directory=True) as tmp, progress("frames") as bar:
        task = bar.add_task("overlays", total=rec.plan().usable, status="")
        for frame in rec.frames():
            picture = overlay_image(frame, hsv, config.perception, marked)
            Image.fromarray(picture).save(tmp / f"frame_{frame.index:06d}.png")
            bar.update(task, advance=1)


def _render(tally: PerceptionTally, plan: FramePlan) -> None:
    from rich.table import Table

    from scrapcut_cli.commands._console import out

    table = Table(title=f"paint filter: {tally.hsv.describe()}", show_header=False)
    table.add_column("", style="bold")
    table.add_column("", justify="right")
    table.add_row("frames", str(tally.frames))
    table.add_row("frames with paint", str(tally.frames_with_paint))
    skipped = ", ".join(f"{k} {v}" for k, v in sorted(tally.skip_reasons.items())) or "none"
    table.add_row("frames skipped (why)", skipped)
    if plan.skipped:
        reader = ", ".join(f"{k} {v}" for k, v in sorted(plan.skip_reasons.items()))
        table.add_row("frames the reader skipped", f"{plan.skipped} ({reader})")
    table.add_row("paint pixels", f"{tally.paint_pixels:,}")
    table.add_row("with usable depth", f"{tally.valid_paint_pixels:,}")
    table.add_row("paint points kept", f"{tally.paint_points:,}")
    table.add_row("surface points", f"{tally.surface_points:,}")
    out.print(table)
