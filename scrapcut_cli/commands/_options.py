"""Options shared by several subcommands, and turning them into a :class:`ScrapcutConfig`.

Every numeric option is bounded: an option that sets a configuration parameter takes the
parameter's declared range (:func:`config_type`, scaled to the option's unit, e.g. millimetres);
any other numeric option names its own finite range (:func:`bounded`). Non-finite numbers
(inf, nan) are refused by both. ``tests/test_config_ranges.py`` checks every command's options.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from scrapcut_cli.config import ScrapcutConfig, field_range, is_count, load_config

F = TypeVar("F", bound=Callable[..., Any])


class _Finite(click.ParamType):
    """Mixin for click's ranges: refuse inf and nan, and say why a bound is there."""

    why: str = ""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        text = str(value).strip().lower().lstrip("+-")
        if text in ("inf", "infinity", "nan"):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        try:
            return super().convert(value, param, ctx)
        except click.BadParameter as exc:
            if not self.why or "range" not in exc.message:
                raise
            self.fail(f"{exc.message.rstrip('.')}: {self.why}", param, ctx)


class BoundedFloat(_Finite, click.FloatRange):
    """A finite float within [min, max] (both required)."""

    def __init__(self, lo: float, hi: float, why: str = "") -> None:
        super().__init__(lo, hi)
        self.why = why


class BoundedInt(_Finite, click.IntRange):
    """A whole number within [min, max] (both required)."""

    def __init__(self, lo: int, hi: int, why: str = "") -> None:
        super().__init__(lo, hi)
        self.why = why


class ConfigFloat(BoundedFloat):
    """The range of configuration parameter ``key`` in the option's unit (value x scale = SI)."""

    def __init__(self, key: str, scale: float = 1.0) -> None:
        lo, hi, _, why = field_range(*key.split("."))
        super().__init__(_in_unit(lo, scale), _in_unit(hi, scale), why)
        self.key, self.scale = key, scale


class ConfigInt(BoundedInt):
    """The range of the count parameter ``key``."""

    def __init__(self, key: str) -> None:
        lo, hi, _, why = field_range(*key.split("."))
        super().__init__(int(lo), int(hi), why)
        self.key, self.scale = key, 1.0


def _in_unit(value: float, scale: float) -> float:
    """A bound in the option's unit, without the binary noise of the division (0.1 mm)."""
    return float(f"{value / scale:.12g}")


def config_type(key: str, scale: float = 1.0) -> ConfigFloat | ConfigInt:
    """The click type of an option setting ``section.field`` (``scale``: option unit in SI,
    1e-3 for millimetres): its declared range, finite numbers only."""
    if is_count(*key.split(".")):
        if scale != 1.0:
            raise ValueError(f"{key} is a count; it has no unit to scale")
        return ConfigInt(key)
    return ConfigFloat(key, scale)


def bounded(lo: float, hi: float, why: str = "") -> BoundedFloat | BoundedInt:
    """The click type of a numeric option that is no configuration parameter: finite, in
    [lo, hi] (ints give a whole-number option)."""
    if isinstance(lo, int) and isinstance(hi, int):
        return BoundedInt(lo, hi, why)
    return BoundedFloat(float(lo), float(hi), why)


def mm_to_m(value: float | None) -> float | None:
    """An option given in millimetres, in metres (``None``: not given)."""
    return None if value is None else value / 1000.0


def config_option(f: F) -> F:
    """``--config FILE``: a TOML file of stage parameters (see ``scrapcut_cli.config``)."""
    return click.option(
        "--config",
        "config_path",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help="TOML file of stage parameters; command-line options override it.",
    )(f)


def _crop_range(
    ctx: click.Context, param: click.Parameter, text: str | None
) -> tuple[float, float] | None:
    """``A:B`` → (A, B) with open ends as 0 and :data:`CROP_END`; B must exceed A."""
    from scrapcut_cli.config import CROP_END

    if text is None:
        return None
    name = param.opts[0] if param.opts else "--frames"
    first, sep, last = text.partition(":")
    try:
        lo = float(first) if first.strip() else 0.0
        hi = float(last) if last.strip() else CROP_END
    except ValueError:
        lo = hi = math.nan
    if not sep or not (0.0 <= lo < hi <= CROP_END):
        raise click.BadParameter(
            f"expected A:B with 0 <= A < B (either may be left out), got {text!r}",
            param_hint=name,
        )
    if name == "--frames" and not (lo.is_integer() and (hi == CROP_END or hi.is_integer())):
        raise click.BadParameter(f"frame numbers are whole, got {text!r}", param_hint=name)
    return lo, hi


def recording_options(f: F) -> F:
    """Topic, frame and pairing options for commands that read a recording."""
    options = [
        click.option("--color-topic", default=None, help="Colour image topic (default: auto)."),
        click.option("--depth-topic", default=None, help="Aligned depth topic (default: auto)."),
        click.option("--info-topic", default=None, help="CameraInfo topic (default: auto)."),
        click.option(
            "--base-frame",
            default=None,
            help="TF frame the output is expressed in (default: root).",
        ),
        click.option(
            "--sync-tolerance-ms",
            type=config_type("recording.sync_tolerance_s", 1e-3),
            default=None,
            help="Max colour/depth stamp difference for a pair [ms] (default 20).",
        ),
        click.option(
            "--salvage",
            is_flag=True,
            default=None,
            help="Read a damaged or truncated MCAP up to the damage (as `mcap recover`).",
        ),
        click.option(
            "--frames",
            "frames",
            default=None,
            metavar="A:B",
            callback=_crop_range,
            help="Use only usable frames A to B-1 (counted from 0, as info lists them; A: or :B "
            "leave an end open; default all).",
        ),
        click.option(
            "--time",
            "time_s",
            default=None,
            metavar="A:B",
            callback=_crop_range,
            help="Use only frames from A to B seconds after the recording's start (default all).",
        ),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def paint_options(f: F) -> F:
    """``--paint PRESET`` or ``--hsv H1,H2,S,V``."""
    f = click.option(
        "--hsv",
        default=None,
        metavar="H1,H2,S,V",
        help="Custom paint range: hue from H1 to H2 degrees (wraps if H1 > H2), "
        "saturation >= S and value >= V (0-1).",
    )(f)
    f = click.option(
        "--paint",
        default=None,
        metavar="PRESET",
        help="Paint colour preset: orange, pink, yellow, green, blue, or auto: estimated from "
        "the recording's images (default: the recording's own, else auto).",
    )(f)
    return f


def parse_hsv(text: str | None) -> tuple[float, float, float, float] | None:
    """Parse ``H1,H2,S,V``; raise a usage error naming the value when it is malformed."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 4:
        raise click.BadParameter(
            f"expected H1,H2,S,V (four numbers), got {text!r}", param_hint="--hsv"
        )
    h1, h2, s, v = values
    if not (0 <= h1 <= 360 and 0 <= h2 <= 360):
        raise click.BadParameter(f"hues must be in 0-360 degrees, got {text!r}", param_hint="--hsv")
    if not (0 <= s <= 1 and 0 <= v <= 1):
        raise click.BadParameter(
            f"saturation and value must be in 0-1, got {text!r}", param_hint="--hsv"
        )
    return (h1, h2, s, v)


def build_config(
    config_path: Path | None,
    *,
    color_topic: str | None = None,
    depth_topic: str | None = None,
    info_topic: str | None = None,
    base_frame: str | None = None,
    sync_tolerance_ms: float | None = None,
    salvage: bool | None = None,
    frames: tuple[float, float] | None = None,
    time_s: tuple[float, float] | None = None,
    paint: str | None = None,
    hsv: str | None = None,
) -> ScrapcutConfig:
    """Defaults < TOML file < the shared command-line options."""
    config = load_config(config_path)
    config = config.override(
        "recording",
        color_topic=color_topic,
        depth_topic=depth_topic,
        info_topic=info_topic,
        base_frame=base_frame,
        sync_tolerance_s=None if sync_tolerance_ms is None else sync_tolerance_ms / 1000.0,
        salvage=salvage or None,
        frames=frames,
        time_s=time_s,
    )
    parsed = parse_hsv(hsv)
    if parsed is not None:
        config = config.override("paint", hsv=parsed)
    if paint is not None:
        config = config.override("paint", preset=paint)
    return config


# --------------------------------------------------------------------------- perception, stitching

# (option, parameter, stage, field, factor to SI, click type, help). One table, so that every
# parameter of the two stages is on the command line of `filter` and `stitch` (and of any
# command that stitches), and applying them is one loop.
_STAGE_OPTIONS: list[tuple[str, str, str, str, float, Any, str]] = [
    (
        "--min-depth-mm",
        "min_depth_mm",
        "perception",
        "min_depth_m",
        1e-3,
        config_type("perception.min_depth_m", 1e-3),
        "Nearest usable depth [mm] (default 100).",
    ),
    (
        "--max-depth-mm",
        "max_depth_mm",
        "perception",
        "max_depth_m",
        1e-3,
        config_type("perception.max_depth_m", 1e-3),
        "Farthest usable depth [mm] (default 2000).",
    ),
    (
        "--flying-pixel-ratio",
        "flying_pixel_ratio",
        "perception",
        "flying_pixel_ratio",
        1.0,
        config_type("perception.flying_pixel_ratio"),
        "Drop pixels whose depth jumps by more than this share of it to a neighbour "
        "(default 0.03).",
    ),
    (
        "--min-paint-neighbors",
        "min_paint_neighbors",
        "perception",
        "min_paint_neighbors",
        1,
        config_type("perception.min_paint_neighbors"),
        "Drop paint pixels with fewer of 4 neighbours also paint (default 3; 0: off).",
    ),
    (
        "--voxel-mm",
        "voxel_mm",
        "perception",
        "voxel_size_m",
        1e-3,
        config_type("perception.voxel_size_m", 1e-3),
        "Per-frame paint downsampling voxel [mm] (default 2).",
    ),
    (
        "--max-decimation",
        "max_decimation",
        "perception",
        "max_decimation",
        1,
        config_type("perception.max_decimation"),
        "Read a frame at every 2nd (4th, 8th) pixel each way when its pixels are finer than "
        "the voxels need, up to this step: 1280x720 at 0.3 m reads like 640x360 (default 8; "
        "1 reads every pixel).",
    ),
    (
        "--sor-neighbors",
        "sor_neighbors",
        "perception",
        "sor_neighbors",
        1,
        config_type("perception.sor_neighbors"),
        "Statistical outlier removal: neighbours per point (default 20; 0: off).",
    ),
    (
        "--sor-std-ratio",
        "sor_std_ratio",
        "perception",
        "sor_std_ratio",
        1.0,
        config_type("perception.sor_std_ratio"),
        "Statistical outlier removal: standard deviations allowed (default 2.0).",
    ),
    (
        "--max-paint-share",
        "max_paint_share",
        "perception",
        "max_paint_share",
        1,
        config_type("perception.max_paint_share"),
        "Skip frames with more of the image in the paint's colour: no stroke fills it "
        "(default 0.5; 1: off).",
    ),
    (
        "--min-paint-area-mm2",
        "min_paint_area_mm2",
        "perception",
        "min_paint_area_m2",
        1e-6,
        config_type("perception.min_paint_area_m2", 1e-6),
        "Drop paint blobs covering less surface than this, e.g. overspray specks [mm²] "
        "(default 25; 0: off).",
    ),
    (
        "--max-stroke-width-mm",
        "max_stroke_width_mm",
        "perception",
        "max_stroke_width_m",
        1e-3,
        config_type("perception.max_stroke_width_m", 1e-3),
        "Image blobs of paint wider than this are no stroke (a crate, a cone) [mm] "
        "(default 80; 0: off).",
    ),
    (
        "--min-paint-points",
        "min_paint_points",
        "perception",
        "min_paint_points",
        1,
        config_type("perception.min_paint_points"),
        "Fewer paint voxels in a frame after cleaning: frame skipped (default 20).",
    ),
    (
        "--surface-band-mm",
        "surface_band_mm",
        "perception",
        "surface_band_m",
        1e-3,
        config_type("perception.surface_band_m", 1e-3),
        "Width of the surface kept around the paint [mm] (default 40; 0: none).",
    ),
    (
        "--surface-voxel-mm",
        "surface_voxel_mm",
        "perception",
        "surface_voxel_m",
        1e-3,
        config_type("perception.surface_voxel_m", 1e-3),
        "Surface downsampling voxel [mm] (default 4).",
    ),
    (
        "--stitch-voxel-mm",
        "stitch_voxel_mm",
        "stitch",
        "voxel_size_m",
        1e-3,
        config_type("stitch.voxel_size_m", 1e-3),
        "Stitching voxel [mm]: the unit of the cloud's size (default 2).",
    ),
    (
        "--icp/--no-icp",
        "icp",
        "stitch",
        "icp",
        1,
        None,
        "Refine each frame against the stitched cloud with ICP (default off).",
    ),
    (
        "--icp-method",
        "icp_method",
        "stitch",
        "icp_method",
        1,
        click.Choice(["point_to_point", "point_to_plane"]),
        "ICP error metric (default point_to_point).",
    ),
    (
        "--icp-max-distance-mm",
        "icp_max_distance_mm",
        "stitch",
        "icp_max_distance_m",
        1e-3,
        config_type("stitch.icp_max_distance_m", 1e-3),
        "ICP correspondence distance [mm] (default 10).",
    ),
    (
        "--icp-max-translation-mm",
        "icp_max_translation_mm",
        "stitch",
        "icp_max_translation_m",
        1e-3,
        config_type("stitch.icp_max_translation_m", 1e-3),
        "Largest ICP correction accepted, at the frame's centre [mm] (default 5).",
    ),
    (
        "--icp-max-rotation-deg",
        "icp_max_rotation_deg",
        "stitch",
        "icp_max_rotation_deg",
        1,
        config_type("stitch.icp_max_rotation_deg"),
        "Largest ICP rotation accepted [deg] (default 2).",
    ),
    (
        "--icp-max-iterations",
        "icp_max_iterations",
        "stitch",
        "icp_max_iterations",
        1,
        config_type("stitch.icp_max_iterations"),
        "ICP iterations (default 30).",
    ),
    (
        "--icp-min-overlap",
        "icp_min_overlap",
        "stitch",
        "icp_min_overlap",
        1,
        config_type("stitch.icp_min_overlap"),
        "Share of a frame's paint near the cloud needed to try ICP (default 0.3).",
    ),
]


def _stage_options(stages: tuple[str, ...]) -> Callable[[F], F]:
    def decorate(f: F) -> F:
        for flag, name, stage, _, _, kind, text in reversed(_STAGE_OPTIONS):
            if stage not in stages:
                continue
            if kind is None:  # a --x/--no-x flag
                f = click.option(flag, name, default=None, help=text)(f)
            else:
                f = click.option(flag, name, type=kind, default=None, help=text)(f)
        return f

    return decorate


#: Every perception parameter as an option (``--voxel-mm``, ``--sor-neighbors``...).
perception_options = _stage_options(("perception",))
#: Every stitching parameter as an option (``--stitch-voxel-mm``, ``--icp``...).
stitch_options = _stage_options(("stitch",))


def split_stage_options(options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(perception/stitch option values, the rest) of a command's keyword arguments."""
    names = {row[1] for row in _STAGE_OPTIONS}
    stage = {k: v for k, v in options.items() if k in names}
    rest = {k: v for k, v in options.items() if k not in names}
    return stage, rest


def apply_stage_options(config: ScrapcutConfig, values: dict[str, Any]) -> ScrapcutConfig:
    """``config`` with perception/stitch option values applied (None: not given), in SI units.

    One override per stage, so that related options (``--min-depth-mm`` and ``--max-depth-mm``)
    are checked together.
    """
    by_stage: dict[str, dict[str, Any]] = {}
    for _, name, stage, field_name, factor, _, _ in _STAGE_OPTIONS:
        value = values.get(name)
        if value is None:
            continue
        if isinstance(value, float) and factor != 1:
            value = value * factor
        by_stage.setdefault(stage, {})[field_name] = value
    for stage, given in by_stage.items():
        config = config.override(stage, **given)
    return config


# --------------------------------------------------------------------------- batch engine


def engine_options(f: F) -> F:
    """``--workers N`` (alias ``--jobs``) and ``--scheduler ADDR``: where Dask runs the tasks."""
    f = click.option(
        "--scheduler",
        default=None,
        metavar="ADDR",
        help="A running Dask scheduler, e.g. tcp://host:8786 (workers must see the same files), "
        "or 'inline' to run in this process without Dask (default: a local cluster).",
    )(f)
    f = click.option(
        "--workers",
        "--jobs",
        "workers",
        type=bounded(1, 1024, "worker processes"),
        default=None,
        help="Worker processes of the local Dask cluster, one thread each (default: one per core).",
    )(f)
    return f


# --------------------------------------------------------------------------- calibration


def calibration_option(f: F) -> F:
    """``--calibration CAL.yaml``: pose frames with a saved camera mount and clock offset."""
    return click.option(
        "--calibration",
        "calibration_path",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        metavar="CAL.yaml",
        help="Pose frames with the camera mount and clock offset of a calibration "
        "(scrapcut calibrate -o CAL.yaml) instead of the recording's /tf_static.",
    )(f)


def apply_calibration_options(
    config: ScrapcutConfig, calibration_path: Path | None, self_calibrate: bool = False
) -> ScrapcutConfig:
    """``config`` with ``--calibration`` / ``--self-calibrate`` (``config.calibration``); the
    file is read here so that a bad one fails before any frame is."""
    if calibration_path is not None and self_calibrate:
        raise click.UsageError("--self-calibrate estimates the calibration; drop --calibration")
    if calibration_path is not None:
        from scrapcut_cli.calibration.calfile import read_calibration_file

        read_calibration_file(calibration_path)
    return config.override(
        "calibration",
        file=None if calibration_path is None else str(calibration_path),
        self_calibrate=True if self_calibrate else None,
    )


# --------------------------------------------------------------------------- outputs


def output_options(f: F) -> F:
    """``--force`` (replace existing outputs) and ``--parents`` (create a missing folder)."""
    f = click.option(
        "--parents",
        is_flag=True,
        help="Create the output's missing parent folders (default: a missing folder is an error).",
    )(f)
    f = click.option(
        "--force",
        is_flag=True,
        help="Replace outputs that exist (default: an existing output is an error).",
    )(f)
    return f
