"""Ranges: every numeric parameter and every numeric option is bounded, in one table.

A parameter added without a range, or an option whose bounds disagree with its parameter's,
fails here. The bounds come from the physics of the cell (see the ``why`` of each).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from helpers import one_line_error

from scrapcut_cli.cli import COMMANDS, cli
from scrapcut_cli.commands._options import BoundedFloat, BoundedInt, ConfigFloat, ConfigInt
from scrapcut_cli.config import (
    RANGE,
    UNIT,
    WHY,
    ScrapcutConfig,
    config_from_dict,
    field_range,
    load_config,
    validate,
)
from scrapcut_cli.errors import ConfigError

NUMERIC = ("int", "float")


def _parameters() -> list[tuple[str, dataclasses.Field[object], object]]:
    config = ScrapcutConfig()
    out = []
    for section in dataclasses.fields(config):
        stage = getattr(config, section.name)
        for f in dataclasses.fields(stage):
            out.append((f"{section.name}.{f.name}", f, getattr(stage, f.name)))
    return out


def _is_numeric(declared: str) -> bool:
    kind = declared.replace(" | None", "")
    return kind in NUMERIC or kind.startswith("tuple[float") or kind.startswith("tuple[int")


def test_every_numeric_parameter_declares_a_range_with_its_reason() -> None:
    missing = [
        key for key, f, _ in _parameters() if _is_numeric(str(f.type)) and RANGE not in f.metadata
    ]
    assert not missing, f"add rng(default, lo, hi, unit, why) to: {', '.join(missing)}"
    for key, f, default in _parameters():
        if RANGE not in f.metadata:
            continue
        assert f.metadata[WHY].strip() and isinstance(f.metadata[UNIT], str), key
        if default is None:
            continue
        bounds = f.metadata[RANGE]
        values = default if isinstance(default, tuple) else (default,)
        for k, value in enumerate(values):
            lo, hi = bounds[k] if isinstance(bounds[0], tuple) else bounds
            assert math.isfinite(lo) and math.isfinite(hi) and lo <= value <= hi, key


def test_the_defaults_are_valid_and_validation_returns_the_config() -> None:
    config = ScrapcutConfig()
    assert validate(config) is config


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ("[perception]\nvoxel_size_m = 1e-9\n", r"perception.voxel_size_m = 1e-09 m is outside"),
        ("[recording]\nsync_tolerance_s = inf\n", "must be a finite number, got inf"),
        ("[toolpath]\nstandoff_m = nan\n", "toolpath.standoff_m must be a finite number"),
        ("[toolpath]\nstandoff_m = 1e12\n", r"standoff_m = 1e\+12 m is outside 0.0005 to 0.1 m"),
        ("[nurbs]\ncontrol_points = 100000\n", "nurbs.control_points = 100000 is outside"),
        ("[sim]\nwidth = 100000\n", "sim.width = 100000 px is outside 16 to 4096 px"),
        ("[paint]\nhsv = [10, 400, 0.5, 0.5]\n", r"paint.hsv\[1\] = 400 deg is outside 0 to 360"),
        ("[exploration]\nlook_past_angles_deg = [60, -1]\n", r"look_past_angles_deg\[1\]"),
        ("[perception]\nmin_depth_m = 3.0\n", "min_depth_m = 3 is above perception.max_depth_m"),
        ("[nurbs]\ndegree = 2.5\n", "nurbs.degree must be a whole number"),
    ],
)
def test_a_config_file_out_of_range_names_the_key_and_the_bound(
    tmp_path: Path, toml: str, message: str
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(toml)
    with pytest.raises(ConfigError, match=message):
        load_config(path)


def test_overrides_are_checked_too_and_related_fields_together() -> None:
    config = ScrapcutConfig()
    with pytest.raises(ConfigError, match=r"toolpath.spacing_m = 1e-09 m"):
        config.override("toolpath", spacing_m=1e-9)
    # Moving both ends of the depth gate at once is fine in one override.
    moved = config.override("perception", min_depth_m=3.0, max_depth_m=5.0)
    assert (moved.perception.min_depth_m, moved.perception.max_depth_m) == (3.0, 5.0)
    assert config_from_dict(moved.to_dict()) == moved


def _numeric_options() -> list[tuple[str, click.Parameter]]:
    out = []
    for name in COMMANDS:
        command = cli.get_command(click.Context(cli), name)  # type: ignore[attr-defined]
        if command is None:
            continue
        for param in command.params:
            if isinstance(param.type, click.types.FloatParamType | click.types.IntParamType):
                out.append((f"{name} {param.opts[0]}", param))
    return out


def test_every_numeric_option_is_bounded_and_agrees_with_its_parameter() -> None:
    options = _numeric_options()
    assert len(options) > 40  # every command was found
    for where, param in options:
        kind = param.type
        assert isinstance(kind, BoundedFloat | BoundedInt), (
            f"{where}: use config_type('section.field', scale) or bounded(lo, hi, why)"
        )
        assert kind.min is not None and kind.max is not None, where
        if isinstance(kind, ConfigFloat | ConfigInt):
            lo, hi, unit, _ = field_range(*kind.key.split("."))
            assert kind.min == pytest.approx(lo / kind.scale), where
            assert kind.max == pytest.approx(hi / kind.scale), where
            flag = param.opts[0]
            # The option's unit suffix matches the parameter's unit and the scale.
            if flag.endswith("-mm2"):
                assert (unit, kind.scale) == ("m2", 1e-6), where
            elif flag.endswith("-mm") or flag == "--leaf-size":
                assert (unit, kind.scale) in (("m", 1e-3), ("mm", 1.0)), where
            elif flag.endswith("-ms"):
                assert (unit, kind.scale) == ("s", 1e-3), where
            elif flag.endswith("-deg"):
                assert (unit, kind.scale) == ("deg", 1.0), where
            elif flag.endswith("-hz"):
                assert (unit, kind.scale) == ("Hz", 1.0), where
            else:
                assert kind.scale == 1.0 and unit in ("", "px"), where
        for bad in ("inf", "-inf", "nan"):
            with pytest.raises(click.BadParameter, match="not a finite number"):
                kind.convert(bad, param, None)


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["fit", "REC", "-o", "p.json", "--sync-tolerance-ms", "inf"], "--sync-tolerance-ms"),
        (["fit", "REC", "-o", "p.json", "--voxel-mm", "1e-9"], "--voxel-mm"),
        (["fit", "REC", "-o", "p.json", "--control-points", "100000"], "--control-points"),
        (["fit", "REC", "-o", "p.json", "--spacing-mm", "1e-6"], "--spacing-mm"),
        (["fit", "REC", "-o", "p.json", "--surface-band-mm", "1e9"], "--surface-band-mm"),
        (["fit", "REC", "-o", "p.json", "--standoff-mm", "1e12"], "--standoff-mm"),
        (["record", "-o", "x.mcap", "--width", "100000"], "--width"),
        (["stitch", "REC", "-o", "c.ply", "--icp-max-distance-mm", "nan"], "--icp-max-distance-mm"),
    ],
)
def test_the_issues_out_of_range_options_are_usage_errors(args: list[str], option: str) -> None:
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 2, result.output
    assert f"Invalid value for '{option}'" in result.output
    assert "Traceback" not in result.output


def test_a_bad_config_file_is_one_line_on_the_command_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[toolpath]\nstandoff_m = 5.0\n")
    result = CliRunner().invoke(cli, ["info", "missing.mcap", "--config", str(path)])
    assert "toolpath.standoff_m = 5 m is outside" in one_line_error(result)
