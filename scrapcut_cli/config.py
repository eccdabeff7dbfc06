"""One frozen dataclass of parameters per pipeline stage; a TOML file plus command-line overrides.

A TOML file has one table per stage, named as the fields of :class:`ScrapcutConfig`::

    [perception]
    sor_std_ratio = 1.5

    [nurbs]
    smoothness = 0.5

Precedence: built-in defaults < ``--config FILE`` < command-line options. The resolved
configuration is saved next to every result (path files, reproduce reports).

Units follow DESIGN.md: metres, radians, seconds inside; a name ending in ``_mm`` or ``_deg``
says otherwise.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, TypeVar

from scrapcut_cli.errors import ConfigError

T = TypeVar("T")


@dataclass(frozen=True)
class RecordingConfig:
    """Which topics to read and how to pair and pose frames."""

    color_topic: str | None = None  # None: first default of DESIGN.md that exists
    depth_topic: str | None = None
    info_topic: str | None = None
    base_frame: str | None = None  # None: the TF root
    sync_tolerance_s: float = 0.02  # colour/depth pairing by header stamp (D435i at 30 Hz: 33 ms)


@dataclass(frozen=True)
class PaintConfig:
    """The marking paint's colour: a preset name or an explicit HSV range.

    ``hsv`` = (hue_min_deg, hue_max_deg, sat_min, val_min); hue in degrees 0–360 (a range with
    hue_min > hue_max wraps through 0, for reds and pinks), saturation and value in 0–1.
    """

    preset: str = "orange"
    hsv: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class PerceptionConfig:
    """Per-frame paint cloud: depth gate, outlier removal, downsampling, the surface band."""

    min_depth_m: float = 0.1
    max_depth_m: float = 2.0
    sor_neighbors: int = 20
    sor_std_ratio: float = 2.0
    voxel_size_m: float = 0.002
    surface_band_m: float = 0.04
    surface_voxel_m: float = 0.004


@dataclass(frozen=True)
class StitchConfig:
    """Accumulation of per-frame clouds, voxel deduplication and optional ICP refinement."""

    voxel_size_m: float = 0.002
    icp: bool = False
    icp_max_distance_m: float = 0.01
    icp_max_translation_m: float = 0.005
    icp_max_rotation_deg: float = 2.0


@dataclass(frozen=True)
class NurbsConfig:
    """Open NURBS fit (point-distance minimisation, as PCL on_nurbs but with clamped ends)."""

    degree: int = 3
    control_points: int | None = None  # None: scales with curve length
    smoothness: float = 1.0  # the paper's weight
    max_iterations: int = 50
    tolerance_m: float = 1e-6
    refine: bool = True


@dataclass(frozen=True)
class SkeletonConfig:
    """3-D skeletonisation (voxelise, thin, graph, prune, longest path)."""

    leaf_size_m: float = 0.005  # the paper's leaf size
    prune_length_m: float = 0.02
    smoothing_window: int = 5


@dataclass(frozen=True)
class ToolpathConfig:
    """Cutting set-points, torch orientation, collisions and speeds."""

    spacing_m: float = 0.005
    standoff_m: float = 0.008
    normal_radius_m: float = 0.015
    torch_length_m: float = 0.15
    torch_radius_m: float = 0.012
    max_tilt_deg: float = 20.0
    material: str = "mild_steel"
    thickness_mm: float = 10.0


@dataclass(frozen=True)
class ExplorationConfig:
    """Algorithm 1's next-view planner and stopping criterion."""

    method: str = "nurbs"
    delta_size: int = 20  # growth in stitched voxels at or below which an end is declared
    step_m: float = 0.06
    min_distance_m: float = 0.2
    max_distance_m: float = 0.45
    distance_step_m: float = 0.025
    max_steps: int = 60


@dataclass(frozen=True)
class SimConfig:
    """The simulator: object, camera, noise, paint stroke, views."""

    object: str = "cylinder"
    mode: str = "sweep"
    noise: str = "d435i"
    width: int = 640
    height: int = 480
    stroke_width_m: float = 0.025
    view_distance_m: float = 0.3
    seed: int = 0


@dataclass(frozen=True)
class EvaluationConfig:
    """The error report of DESIGN.md: reference sampling and coverage threshold."""

    sample_spacing_m: float = 0.001
    coverage_threshold_m: float = 0.010


@dataclass(frozen=True)
class ScrapcutConfig:
    """Every stage's parameters."""

    recording: RecordingConfig = field(default_factory=RecordingConfig)
    paint: PaintConfig = field(default_factory=PaintConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    stitch: StitchConfig = field(default_factory=StitchConfig)
    nurbs: NurbsConfig = field(default_factory=NurbsConfig)
    skeleton: SkeletonConfig = field(default_factory=SkeletonConfig)
    toolpath: ToolpathConfig = field(default_factory=ToolpathConfig)
    exploration: ExplorationConfig = field(default_factory=ExplorationConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    evaluation: EvaluationConfig = field(default_factory=EvaluationConfig)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON/TOML-ready dictionary of every parameter."""
        return _jsonable(dataclasses.asdict(self))

    def override(self, section: str, **values: Any) -> ScrapcutConfig:
        """A copy with ``section``'s fields replaced; ``None`` values mean "not given"."""
        given = {k: v for k, v in values.items() if v is not None}
        if not given:
            return self
        current = getattr(self, section)
        return replace(self, **{section: update_dataclass(current, given, section)})


def update_dataclass(obj: T, values: dict[str, Any], where: str) -> T:
    """``dataclasses.replace`` with a clear error for unknown names and wrong types."""
    known = {f.name: f for f in fields(obj)}  # type: ignore[arg-type]
    for name, value in values.items():
        if name not in known:
            raise ConfigError(
                f"unknown parameter {where}.{name}; known: {', '.join(sorted(known))}"
            )
        default = getattr(obj, name)
        if default is not None and value is not None:
            if isinstance(default, bool) and not isinstance(value, bool):
                raise ConfigError(f"{where}.{name} must be true or false, got {value!r}")
            if isinstance(default, int | float) and not isinstance(value, int | float):
                raise ConfigError(f"{where}.{name} must be a number, got {value!r}")
            if isinstance(default, str) and not isinstance(value, str):
                raise ConfigError(f"{where}.{name} must be a string, got {value!r}")
            if isinstance(default, float) and isinstance(value, int):
                values[name] = float(value)
        if isinstance(value, list):
            values[name] = tuple(value)
    return replace(obj, **values)  # type: ignore[type-var]


def load_config(path: str | Path | None = None) -> ScrapcutConfig:
    """Defaults, updated from the TOML file at ``path`` when given."""
    config = ScrapcutConfig()
    if path is None:
        return config
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"configuration file not found: {path}") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"cannot read configuration {path}: {exc}") from None
    return config_from_dict(data, where=str(path))


def config_from_dict(data: dict[str, Any], *, where: str = "config") -> ScrapcutConfig:
    """Defaults updated from a nested dictionary (the shape of :meth:`ScrapcutConfig.to_dict`)."""
    config = ScrapcutConfig()
    sections = {f.name for f in fields(config)}
    for section, values in data.items():
        if section not in sections:
            raise ConfigError(
                f"{where}: unknown section [{section}]; known: {', '.join(sorted(sections))}"
            )
        if not isinstance(values, dict):
            raise ConfigError(f"{where}: [{section}] must be a table")
        current = getattr(config, section)
        config = replace(config, **{section: update_dataclass(current, dict(values), section)})
    return config


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value
