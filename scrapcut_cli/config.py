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
    ``preset = None`` means "not chosen": a recording's own paint (simulator metadata), else
    orange; an explicit name, even "orange", overrides the recording's.
    """

    preset: str | None = None
    hsv: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class PerceptionConfig:
    """Per-frame paint cloud: depth gate, outlier removal, downsampling, the surface band.

    Defaults: the depth range brackets the D435i's useful range at the wrist (min-Z ~0.17 m,
    noise growing with z², about 3.6 mm at 1 m); a flying pixel jumps by more than 3 % of its
    depth (9 mm at 0.3 m, ~20 sigma of the sensor noise there); 2 mm voxels keep a 25 mm stroke
    about 12 voxels wide; outlier removal with 20 neighbours and 2 standard deviations (open3d's
    tutorial values) removes stray specks once the cloud is downsampled; the
    40 mm surface band is more than the toolpath's 15 mm normal radius on each side of the
    stroke, at 4 mm voxels. A paint pixel needs 3 of its 4 neighbours in the colour range: the
    inside and straight edges of a stroke have them; camera noise on rust, overspray specks up to
    2×2 pixels and 1-pixel lines do not (a diagonal edge loses at most one pixel). On the
    simulator's d435i sweeps this takes the share of stitched paint beyond half the stroke width
    + 2 mm from ~1 % (with 2 of 4) to under 0.1 %.
    """

    min_depth_m: float = 0.1
    max_depth_m: float = 2.0
    sor_neighbors: int = 20
    sor_std_ratio: float = 2.0
    voxel_size_m: float = 0.002
    surface_band_m: float = 0.04
    surface_voxel_m: float = 0.004
    flying_pixel_ratio: float = 0.03  # reject depth jumping > ratio * depth to a 4-neighbour
    min_paint_points: int = 20  # fewer voxels of paint after outlier removal: frame skipped
    min_paint_neighbors: int = 3  # of 4; paint pixels with fewer paint neighbours are noise
    # Paint blobs (8-connected in the image) covering less surface than this are overspray
    # specks, not a stroke: a speck is a drop a few mm across (at most ~12 mm^2 seen on the
    # simulator's heavy overspray), the least a stroke shows is a wire's share (4 x 25 mm).
    min_paint_area_m2: float = 25e-6  # 0: off


@dataclass(frozen=True)
class StitchConfig:
    """Accumulation of per-frame clouds, voxel deduplication and optional ICP refinement.

    ``voxel_size_m`` is the unit of the stitched cloud's size (Algorithm 1's size(k)). ICP is
    off by default: with the robot's poses it corrects offsets along the surface normal well,
    and along the surface weakly; its guards accept a correction only if it brings more of the
    frame's overlapping paint within one voxel of the cloud, and it is within the bounds.
    """

    voxel_size_m: float = 0.002
    icp: bool = False
    icp_max_distance_m: float = 0.01
    icp_max_translation_m: float = 0.005
    icp_max_rotation_deg: float = 2.0
    icp_method: str = "point_to_point"  # or "point_to_plane" (slides on planes and pipes)
    icp_max_iterations: int = 30
    icp_min_overlap: float = 0.3  # share of the frame's points near the cloud needed to try ICP


@dataclass(frozen=True)
class NurbsConfig:
    """Open NURBS fit (point-distance minimisation, as PCL on_nurbs but with clamped ends)."""

    degree: int = 3
    control_points: int | None = None  # None: scales with curve length
    smoothness: float = 1.0  # the paper's weight
    max_iterations: int = 50
    tolerance_m: float = 1e-6
    refine: bool = True
    # smoothness w weighs the bending energy w * l^4 * integral |C''(s)|^2 ds against the squared
    # residual, both per metre of curve: independent of point density and of the number of
    # control points; w = 1 damps wiggles shorter than about 2*pi*l. l is this length or 1.5x
    # the RMS residual of the initial fit (the paint band's own scale), whichever is larger.
    smoothing_length_m: float = 0.003
    control_point_spacing_m: float = 0.02  # default count: length / spacing + degree
    max_control_points: int = 200
    init: str = "auto"  # "principal" (the paper), "chain" (spanning-tree order) or "auto": best
    refine_rounds: int = 4  # knot insertion where the residuals stay one-sided
    refine_bias_m: float = 0.0005  # a knot span's mean residual above this (and noise) is split
    min_knot_spacing_m: float = 0.004
    robust: bool = True  # Huber weights against outliers left by the outlier filter
    end_quantile: float = 0.002  # the curve ends where this share of the points lies beyond
    sample_spacing_m: float = 0.001  # spacing of Curve.points
    corner_angle_deg: float = 30.0  # sharper turns become kinks (C0 knots); 0: smooth only
    max_corners: int = 8
    # Ends: a spray stroke's round cap reaches about half a stroke width past the line's end.
    # "auto": end at each cap's centre (a square end, paint running off an edge, is kept);
    # "cap": always a round cap; "none": the paint's extent. See fitting/ends.py.
    end_trim: str = "auto"
    end_trim_m: float | None = None  # fixed trim at each end instead of the estimate


@dataclass(frozen=True)
class SkeletonConfig:
    """3-D skeletonisation (voxelise, thin, graph, prune, longest path)."""

    leaf_size_m: float = 0.005  # the paper's leaf size
    prune_length_m: float = 0.02
    smoothing_window: int = 5
    closing_voxels: int = 1  # morphological closing radius, voxels (0: none)
    min_piece_share: float = 0.02  # smaller pieces (share of points) are stray paint, ignored
    max_block_voxels: int = 4_194_304  # dense thinning block budget (4 MiB); larger: tiled
    block_margin_m: float = 0.05  # overlap of the thinning tiles
    refine_radius_m: float = 0.03  # paint points this close to the skeleton pull it to their centre
    refine_window_m: float | None = None  # arc-length half window; None: from the band width
    corner_angle_deg: float = 30.0  # sharper turns are kept as corners (not smoothed across)
    refine_iterations: int = 2
    end_quantile: float = 0.002  # the curve ends where this share of the points lies beyond
    sample_spacing_m: float = 0.001  # spacing of Curve.points
    end_trim: str = "auto"  # "auto" | "cap" | "none": as NurbsConfig.end_trim
    end_trim_m: float | None = None  # fixed trim at each end instead of the estimate


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
    coarse_normal_radius_m: float = 0.030  # used where the normal_radius_m plane is rough
    normal_smoothing_m: float = 0.010  # Gaussian sigma of the smoothing along the path
    edge_angle_deg: float = 30.0  # normals further apart are on different faces: not averaged
    min_surface_points: int = 8  # fewer within normal_radius_m: "no_surface", normal interpolated
    collision_min_points: int = 3  # observed points inside the torch body that make a collision
    tilt_steps: int = 4  # tilt angles tried, evenly up to max_tilt_deg
    tilt_directions: int = 8  # tilt directions tried around the normal
    speed_table: str | None = None  # CSV of speeds; None: the bundled oxy-fuel table


@dataclass(frozen=True)
class ExplorationConfig:
    """Algorithm 1's next-view planner and stopping criterion."""

    method: str = "nurbs"
    # growth(k) = new paint voxels farther than novelty_m from the cloud before frame k; an end
    # is declared when growth(k) <= delta_size (re-observing known paint grows ~0 this way).
    delta_size: int = 20
    step_m: float = 0.06  # next view's target: this far beyond the fitted curve's end
    min_distance_m: float = 0.2  # camera distance search, from the camera's minimum upward
    max_distance_m: float = 0.45
    distance_step_m: float = 0.025
    max_steps: int = 60  # frames observed before stopping with "budget"
    novelty_m: float = 0.01
    fit_voxel_m: float = 0.006  # the local fit runs on the paint thinned to this voxel
    fit_margin_m: float = 0.05  # local fit window: the frame's paint extent plus this margin
    normal_radius_m: float = 0.03  # observed surface used for the normal at a target
    min_elevation_deg: float = 35.0  # views stay at least this high above their target
    roll_step_deg: float = 45.0  # rotation about the optical axis tried in these steps
    revisit_radius_m: float = 0.02  # a target this close to a visited one is not taken again
    occupancy_voxel_m: float = 0.01  # voxel hash of every observed depth point (collisions)
    inflation_m: float = 0.02  # safety margin around occupied voxels
    body_front_m: float = 0.07  # camera + hand as a capsule along the optical axis: front,
    body_back_m: float = 0.25  # back (towards the flange) and radius
    body_radius_m: float = 0.06
    look_past: bool = True  # re-observe past an edge or sharp turn before declaring an end
    look_past_angles_deg: tuple[float, ...] = (60.0, 90.0, 40.0)  # view tilts about the edge
    edge_probe_m: float = 0.025  # surface must continue this far beyond a confirmed end
    turn_angle_deg: float = 45.0  # the fitted curve turning more near its end: look past
    # No view past an end from the normal's side: try the surface's other side (a mesh, a sheet)
    other_side_views: bool = True
    # Still no view: the end counts if an earlier frame observed it (exploration.evidence):
    # tip and continuation (edge_probe_m past it) this share of the image inside the border,
    # judged on depth windows of this radius with this tolerance.
    observed_end: bool = True
    observed_end_margin: float = 0.05
    observed_end_window_m: float = 0.006
    observed_end_tolerance_m: float = 0.01


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
    paint: str = "orange"  # preset the piece is painted with (perception.paint.PAINT_PRESETS)
    views: int = 0  # 0: sweep one view per view_step_m of line, survey its full grid
    view_step_m: float = 0.05  # sweep spacing along the line (~85 % overlap at 0.3 m)
    survey_spacing_m: float = 0.10  # survey target grid over the piece's top
    min_elevation_deg: float = 35.0  # cameras stay at least this high above their target
    frames_per_view: int = 1  # images at 30 Hz while the robot rests at a view
    max_views: int = 200  # budget of executed views (explore mode safety stop)
    max_backoff_m: float = 0.15  # free DOF: how far a view may back off along its axis
    speed_scale: float = 0.25  # share of the Panda's joint speed limits used between views
    tf_rate_hz: float = 100.0  # /tf and /joint_states rate
    depth_encoding: str = "16UC1"  # or "32FC1" (float metres: no 1 mm quantisation)
    object_x_m: float = 0.5  # placement of the piece on the floor, base frame
    object_y_m: float = 0.0
    object_yaw_deg: float = 0.0
    start_fraction: float | None = None  # explore start along the line, 0-1; None: the piece's


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
            if isinstance(default, bool):
                if not isinstance(value, bool):
                    raise ConfigError(f"{where}.{name} must be true or false, got {value!r}")
            elif isinstance(default, int | float):
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise ConfigError(f"{where}.{name} must be a number, got {value!r}")
                if isinstance(default, int) and not isinstance(value, int):
                    # A count (neighbours, iterations, pixels) reaches libraries refusing floats.
                    if not float(value).is_integer():
                        raise ConfigError(f"{where}.{name} must be a whole number, got {value!r}")
                    values[name] = int(value)
                elif isinstance(default, float) and isinstance(value, int):
                    values[name] = float(value)
            elif isinstance(default, str) and not isinstance(value, str):
                raise ConfigError(f"{where}.{name} must be a string, got {value!r}")
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
