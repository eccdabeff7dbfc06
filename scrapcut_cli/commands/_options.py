"""Options shared by several subcommands, and turning them into a :class:`ScrapcutConfig`."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from scrapcut_cli.config import ScrapcutConfig, load_config

F = TypeVar("F", bound=Callable[..., Any])


def config_option(f: F) -> F:
    """``--config FILE``: a TOML file of stage parameters (see ``scrapcut_cli.config``)."""
    return click.option(
        "--config",
        "config_path",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help="TOML file of stage parameters; command-line options override it.",
    )(f)


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
            type=click.FloatRange(min=0.0),
            default=None,
            help="Max colour/depth stamp difference for a pair [ms] (default 20).",
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
        help="Paint colour preset: orange, pink, yellow, green, blue "
        "(default: the recording's own, else orange).",
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
    )
    parsed = parse_hsv(hsv)
    if parsed is not None:
        config = config.override("paint", hsv=parsed)
    if paint is not None:
        config = config.override("paint", preset=paint)
    return config
