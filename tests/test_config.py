"""Tests of the configuration: defaults, TOML loading, overrides, errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from scrapcut_cli.config import ScrapcutConfig, config_from_dict, load_config
from scrapcut_cli.errors import ConfigError


def test_defaults_match_the_paper() -> None:
    config = ScrapcutConfig()
    assert config.nurbs.smoothness == 1.0
    assert config.skeleton.leaf_size_m == pytest.approx(0.005)
    assert config.toolpath.standoff_m == pytest.approx(0.008)
    assert config.toolpath.spacing_m == pytest.approx(0.005)


def test_toml_overrides_defaults_and_cli_overrides_toml(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text("[nurbs]\nsmoothness = 0.5\ndegree = 2\n[perception]\nsor_neighbors = 30\n")
    config = load_config(path)
    assert config.nurbs.smoothness == 0.5
    assert config.nurbs.degree == 2
    assert config.perception.sor_neighbors == 30
    assert config.skeleton == ScrapcutConfig().skeleton
    config = config.override("nurbs", smoothness=2.0, degree=None)
    assert config.nurbs.smoothness == 2.0 and config.nurbs.degree == 2


def test_int_is_accepted_for_float_fields_and_lists_become_tuples() -> None:
    config = config_from_dict({"nurbs": {"smoothness": 1}, "paint": {"hsv": [10, 40, 0.6, 0.3]}})
    assert isinstance(config.nurbs.smoothness, float)
    assert config.paint.hsv == (10, 40, 0.6, 0.3)
    # A whole float is accepted for a count and becomes an int (open3d refuses 20.0).
    config = config_from_dict({"perception": {"sor_neighbors": 30.0}, "stitch": {"icp": True}})
    assert isinstance(config.perception.sor_neighbors, int)
    assert config.perception.sor_neighbors == 30
    assert config.stitch.icp is True


def test_round_trip_through_dict() -> None:
    config = ScrapcutConfig().override("sim", object="i_beam", seed=7)
    assert config_from_dict(config.to_dict()) == config


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[nurbs]\nsmoothnes = 1.0\n", "unknown parameter nurbs.smoothnes"),
        ("[nurb]\nsmoothness = 1.0\n", r"unknown section \[nurb\]"),
        ("[nurbs]\nsmoothness = 'high'\n", "must be a number"),
        ("[stitch]\nicp = 1\n", "true or false"),
        ("[perception]\nsor_neighbors = 2.5\n", "perception.sor_neighbors must be a whole number"),
        ("[nurbs]\nsmoothness = true\n", "nurbs.smoothness must be a number"),
        ("[nurbs\n", "cannot read configuration"),
    ],
)
def test_bad_files_name_the_problem(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path)


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.toml")


def test_every_stage_option_reaches_its_config_field_in_si_units() -> None:
    """Each perception/stitch command-line option sets the field it names, scaled to SI."""
    from scrapcut_cli.commands._options import _STAGE_OPTIONS, apply_stage_options

    base = ScrapcutConfig()
    for flag, name, stage, field_name, factor, kind, _ in _STAGE_OPTIONS:
        default = getattr(getattr(base, stage), field_name)
        if kind is None:  # an on/off flag
            value: object = not default
            expected: object = value
        elif isinstance(default, int) and not isinstance(default, bool):
            # Away from the default, inside the range (a default may be its top).
            value = expected = default + 1 if default + 1 <= kind.max else default - 1
        elif isinstance(default, str):
            continue  # a choice; covered by the commands' own tests
        else:  # a value inside the option's range, away from the default
            value = 1.25 * default / factor
            if not 0 < value <= kind.max:
                value = 0.5 * (kind.min + kind.max)
            expected = pytest.approx(value * factor)
        config = apply_stage_options(base, {name: value})
        assert getattr(getattr(config, stage), field_name) == expected, flag
        assert apply_stage_options(base, {name: None}) == base


def test_toml_keys_in_millimetres_and_milliseconds_are_converted(tmp_path: Path) -> None:
    """The saved form is SI (`voxel_size_m`); a user may write the unit they type in options."""
    path = tmp_path / "mm.toml"
    path.write_text(
        "[perception]\nvoxel_size_mm = 3\n[recording]\nsync_tolerance_ms = 15\n"
        "[toolpath]\nstandoff_m = 0.01\n"
    )
    config = load_config(path)
    assert config.perception.voxel_size_m == pytest.approx(0.003, abs=1e-15)
    assert config.recording.sync_tolerance_s == pytest.approx(0.015, abs=1e-15)
    assert config.toolpath.standoff_m == 0.01
    assert config.toolpath.thickness_mm == ScrapcutConfig().toolpath.thickness_mm  # a field
    both = {"perception": {"voxel_size_mm": 3, "voxel_size_m": 0.003}}
    with pytest.raises(ConfigError, match="voxel_size_mm and voxel_size_m name one parameter"):
        config_from_dict(both)
    with pytest.raises(ConfigError, match="voxel_size_m"):  # the range still holds: 1 m voxels
        config_from_dict({"perception": {"voxel_size_mm": 1000}})
