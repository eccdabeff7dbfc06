"""One frozen dataclass of parameters per pipeline stage; a TOML file plus command-line overrides.

A TOML file has one table per stage, named as the fields of :class:`ScrapcutConfig`::

    [perception]
    sor_std_ratio = 1.5

    [nurbs]
    smoothness = 0.5

Precedence: built-in defaults < ``--config FILE`` < command-line options. The resolved
configuration is saved next to every result (path files, reproduce reports).

Units follow docs/design.md: metres, radians, seconds inside; a name ending in ``_mm`` or ``_deg``
says otherwise.

Every numeric parameter declares its range where it is declared, from the physics of the cell
(a depth camera, a torch, a Panda), with the reason: ``rng(default, lo, hi, unit, why)``.
:func:`validate` checks a whole configuration against these ranges (finite, within [lo, hi],
whole numbers for counts) plus the relations between fields (``ORDERED``); it runs wherever a
configuration is built from outside: a TOML file (:func:`load_config`, :func:`config_from_dict`)
and command-line overrides (:meth:`ScrapcutConfig.override`). Command-line options take their
bounds from the same table (``commands._options.config_type``). A test fails for any numeric
parameter without a range.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, ClassVar, TypeVar

from scrapcut_cli.errors import ConfigError

T = TypeVar("T")

#: Metadata keys of a ranged field (see :func:`rng`).
RANGE, UNIT, WHY = "range", "unit", "why"


def rng(default: T, lo: float, hi: float, unit: str, why: str) -> T:
    """A dataclass field with ``default`` whose value (when not None) lies in [lo, hi] ``unit``.

    ``why`` says where the bounds come from (it is part of the error message). For a tuple
    field the range holds for every element. Counts (int fields) must be whole numbers.
    """
    if not lo <= hi:
        raise ValueError(f"empty range [{lo}, {hi}]")
    meta = {RANGE: (lo, hi), UNIT: unit, WHY: why}
    return field(default=default, metadata=meta)


class FitMethod(enum.StrEnum):
    """The curve models (``fitting``): an open NURBS or a 3-D skeleton. The one list of methods:
    every command, config check and report imports it. A member is its string (``"nurbs"``)."""

    NURBS = "nurbs"
    SKELETON = "skeleton"


class ScanMode(enum.StrEnum):
    """How the simulator chooses views (``SimConfig.mode``). ``sweep`` views follow the true
    reference line, so its results are labelled "oracle views" in every report."""

    SWEEP = "sweep"
    SURVEY = "survey"
    EXPLORE = "explore"


def choice_names(choices: type[enum.StrEnum]) -> tuple[str, ...]:
    """The members' strings in declaration order, e.g. ``("nurbs", "skeleton")``."""
    return tuple(member.value for member in choices)


#: An open end of ``--frames A:`` / ``--time A:`` (a billion frames or seconds: the end).
CROP_END = 1e9


@dataclass(frozen=True)
class RecordingConfig:
    """Which topics to read and how to pair and pose frames."""

    color_topic: str | None = None  # None: first default of docs/design.md that exists
    depth_topic: str | None = None
    info_topic: str | None = None
    base_frame: str | None = None  # None: the TF root
    salvage: bool = False  # read a damaged MCAP up to the damage (recording.salvage)
    # colour/depth pairing by header stamp (D435i at 30 Hz: 33 ms)
    sync_tolerance_s: float = rng(
        0.02,
        0.0,
        1.0,
        "s",
        "a colour and a depth image over 1 s apart do not show one scene from a moving wrist "
        "(cameras stream at 6-90 Hz)",
    )
    # crop a long recording: usable frames [first, end) and seconds [from, to) since its start
    frames: tuple[float, float] | None = field(
        default=None,
        metadata={
            RANGE: ((0.0, CROP_END), (0.0, CROP_END)),
            UNIT: "frame, frame",
            WHY: "frame numbers count the usable frames from 0; the end is not included",
        },
    )
    time_s: tuple[float, float] | None = field(
        default=None,
        metadata={
            RANGE: ((0.0, CROP_END), (0.0, CROP_END)),
            UNIT: "s, s",
            WHY: "seconds since the recording's first message; the end is not included",
        },
    )


@dataclass(frozen=True)
class PaintConfig:
    """The marking paint's colour: a preset name or an explicit HSV range.

    ``hsv`` = (hue_min_deg, hue_max_deg, sat_min, val_min); hue in degrees 0–360 (a range with
    hue_min > hue_max wraps through 0, for reds and pinks), saturation and value in 0–1.
    ``preset = None`` means "not chosen": a recording's own paint (simulator metadata), else
    orange; an explicit name, even "orange", overrides the recording's.
    """

    preset: str | None = None
    hsv: tuple[float, float, float, float] | None = field(
        default=None,
        metadata={
            RANGE: ((0.0, 360.0), (0.0, 360.0), (0.0, 1.0), (0.0, 1.0)),
            UNIT: "deg, deg, -, -",
            WHY: "hues are angles on the colour wheel; saturation and value are shares",
        },
    )


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

    #: (a, b): field a must not exceed field b.
    ORDERED: ClassVar[tuple[tuple[str, str], ...]] = (("min_depth_m", "max_depth_m"),)

    min_depth_m: float = rng(
        0.1, 0.0, 10.0, "m", "depth cameras see from 0 to about 10 m (the D435i's maximum range)"
    )
    max_depth_m: float = rng(
        2.0,
        0.01,
        10.0,
        "m",
        "a depth gate under 10 mm keeps nothing; the D435i sees at most about 10 m",
    )
    sor_neighbors: int = rng(
        20,
        0,
        1000,
        "",
        "0 switches outlier removal off; 1000 neighbours at 2 mm voxels span more stroke than a "
        "frame shows",
    )
    sor_std_ratio: float = rng(
        2.0,
        0.1,
        100.0,
        "",
        "under 0.1 standard deviations removes most of an honest stroke; over 100 removes nothing "
        "(0 neighbours switches it off)",
    )
    voxel_size_m: float = rng(
        0.002,
        1e-4,
        0.05,
        "m",
        "0.1 mm is finer than any depth camera resolves at the wrist; 50 mm is twice a stroke's "
        "width, no stroke left",
    )
    surface_band_m: float = rng(
        0.04,
        0.0,
        1.0,
        "m",
        "0 keeps no surface; 1 m is more than the whole scene a wrist camera sees",
    )
    surface_voxel_m: float = rng(
        0.004,
        1e-4,
        0.1,
        "m",
        "0.1 mm is finer than any depth camera resolves; 100 mm leaves no surface shape for "
        "normals",
    )
    # reject depth jumping > ratio * depth to a 4-neighbour
    flying_pixel_ratio: float = rng(
        0.03,
        1e-3,
        1.0,
        "",
        "under 0.1 % of the depth is below the D435i's own noise; a jump larger than the depth "
        "itself is no flying pixel test",
    )
    # fewer voxels of paint after outlier removal: frame skipped
    min_paint_points: int = rng(
        20,
        0,
        1_000_000,
        "",
        "a frame of 4096 x 4096 px at 2 mm voxels never holds a million paint voxels",
    )
    # of 4; paint pixels with fewer paint neighbours are noise
    min_paint_neighbors: int = rng(3, 0, 4, "", "a pixel has 4 neighbours")
    # Paint blobs (8-connected in the image) covering less surface than this are overspray
    # specks, not a stroke: a speck is a drop a few mm across (at most ~12 mm^2 seen on the
    # simulator's heavy overspray), the least a stroke shows is a wire's share (4 x 25 mm).
    # 0: off
    # A stroke (25 mm wide) covers at most about a fifth of a wrist camera's image even at
    # its closest (0.17 m, 150 mm across); a frame mostly in the paint's colour shows a
    # paint-coloured surface or light, or a colour range that is too wide: it is skipped.
    max_paint_share: float = rng(
        0.5, 0.01, 1.0, "", "a share of the image's pixels (1: any share is accepted)"
    )
    min_paint_area_m2: float = rng(
        25e-6,
        0.0,
        0.01,
        "m2",
        "0 is off; a blob of 1 dm^2 is a 25 mm stroke 400 mm long, not a speck",
    )
    # A marking stroke is 2-5 cm wide: an image blob wider than this is something else of the
    # paint's colour (a crate's face, a cone), kept apart from the frame's paint. 0: off.
    max_stroke_width_m: float = rng(
        0.08,
        0.0,
        1.0,
        "m",
        "0 is off; spray-can strokes are 2-5 cm wide, and a 1 m wide blob fills a wrist "
        "camera's view",
    )
    # Up to this step, a frame whose pixels are finer than the voxels need is read at every
    # 2nd (4th, 8th) pixel each way (perception.cloud.decimation): 1280x720 at the wrist's
    # 0.3 m reads like 640x360, its perception in about three quarters of the time; 1 reads
    # every pixel.
    max_decimation: int = rng(
        8,
        1,
        8,
        "",
        "1 reads every pixel; past 8 a 1280x720 image keeps 160x90 pixels, coarser than any "
        "voxel at the wrist",
    )


@dataclass(frozen=True)
class StitchConfig:
    """Accumulation of per-frame clouds, voxel deduplication and optional ICP refinement.

    ``voxel_size_m`` is the unit of the stitched cloud's size (Algorithm 1's size(k)). ICP is
    off by default: with the robot's poses it corrects offsets along the surface normal well,
    and along the surface weakly; its guards accept a correction only if it brings more of the
    frame's overlapping paint within one voxel of the cloud, and it is within the bounds.
    """

    voxel_size_m: float = rng(
        0.002,
        1e-4,
        0.05,
        "m",
        "0.1 mm is finer than any depth camera resolves at the wrist; 50 mm is twice a stroke's "
        "width",
    )
    icp: bool = False
    icp_max_distance_m: float = rng(
        0.01,
        1e-4,
        0.2,
        "m",
        "under 0.1 mm no correspondence survives sensor noise; beyond 0.2 m ICP pairs other parts "
        "of the piece",
    )
    icp_max_translation_m: float = rng(
        0.005,
        0.0,
        0.1,
        "m",
        "a pose error over 100 mm is a broken calibration, not drift ICP should absorb",
    )
    icp_max_rotation_deg: float = rng(
        2.0,
        0.0,
        45.0,
        "deg",
        "a pose error over 45 deg is a broken calibration, not drift ICP should absorb",
    )
    icp_method: str = "point_to_point"  # or "point_to_plane" (slides on planes and pipes)
    icp_max_iterations: int = rng(
        30, 1, 10_000, "", "ICP converges in tens of iterations; 10,000 only burns time"
    )
    # share of the frame's points near the cloud needed to try ICP
    icp_min_overlap: float = rng(0.3, 0.0, 1.0, "", "a share of the frame's points")


@dataclass(frozen=True)
class SelectionConfig:
    """Finding the marked line among the stitched paint's candidates (perception/candidates.py).

    ``pick``: ``scan`` (the candidate the scan follows), ``longest``, ``nearest-start`` (nearest
    to where the scan started) or ``all`` (one path per line-like candidate). Paint within
    ``link_m`` is one candidate (45 mm bridges a 40 mm wire mesh's gaps); a stroke is at least
    ``min_elongation`` times as long as wide and at most ``max_width_m`` wide; a candidate less
    saturated than the line by ``dull_margin`` of its saturation is another paint (an old mark,
    rust); paint farther than ``off_surface_m`` from every sight line (camera to view centre)
    was never looked at;
    duller paint within ``rim_m`` of the line is its own thin edge.
    """

    pick: str = "scan"
    link_m: float = rng(
        0.045,
        0.001,
        0.5,
        "m",
        "paint 1 mm apart is one piece; 0.5 m would join everything a wrist camera sees",
    )
    # grid of the shape analysis
    cell_m: float = rng(
        0.01, 0.001, 0.1, "m", "finer than 1 mm is below the stitching voxel; 0.1 m is 4 strokes"
    )
    # fewer paint voxels: a speck
    min_points: int = rng(30, 1, 1_000_000, "", "a count of voxels")
    min_elongation: float = rng(
        3.0, 1.0, 100.0, "", "a stroke is longer than wide; 100 is a 2.5 m line of a 25 mm stroke"
    )
    # a stroke's width measured on the stitched paint (twice the 90 % quantile of the offsets)
    max_width_m: float = rng(
        0.08,
        0.005,
        1.0,
        "m",
        "spray-can strokes are 2-5 cm wide (with overspray and a wire mesh's two layers ~4 cm); "
        "1 m is a wrist camera's whole view",
    )
    dull_margin: float = rng(
        0.12,
        0.0,
        0.99,
        "",
        "a share of the line's saturation: 0 calls any duller voxel another paint",
    )
    # a sight line this close to a candidate: the scan looked at it
    follow_m: float = rng(
        0.05, 0.001, 1.0, "m", "closer than 1 mm is below the depth noise; 1 m is the whole view"
    )
    off_surface_m: float = rng(
        0.1, 0.001, 10.0, "m", "closer than 1 mm is below the depth noise; 10 m is the cell"
    )
    rim_m: float = rng(0.003, 0.0, 0.05, "m", "0 is off; a 50 mm rim is twice a stroke's width")


@dataclass(frozen=True)
class NurbsConfig:
    """Open NURBS fit (point-distance minimisation, as PCL on_nurbs but with clamped ends)."""

    degree: int = rng(
        3, 1, 5, "", "degrees 1-5 cover polylines to quintics; higher degrees oscillate"
    )
    # None: scales with curve length
    control_points: int | None = rng(
        None,
        2,
        5000,
        "",
        "a curve needs at least 2; 5000 on a 5 m line are 1 mm apart, finer than the sensor, and "
        "the solve grows with their square",
    )
    # the paper's weight
    smoothness: float = rng(
        1.0,
        0.0,
        1e8,
        "",
        "a weight >= 0; at 1e8 it damps wiggles up to metres long (wavelength grows with its 4th "
        "root): the curve is a straight line",
    )
    max_iterations: int = rng(
        50, 1, 10_000, "", "the fit converges in tens of iterations; 10,000 only burns time"
    )
    tolerance_m: float = rng(
        1e-6,
        1e-12,
        1e-3,
        "m",
        "a tolerance must be > 0; over 1 mm it stops before the fit resolves a 25 mm stroke",
    )
    refine: bool = True
    # smoothness w weighs the bending energy w * l^4 * integral |C''(s)|^2 ds against the squared
    # residual, both per metre of curve: independent of point density and of the number of
    # control points; w = 1 damps wiggles shorter than about 2*pi*l. l is this length or 1.5x
    # the RMS residual of the initial fit (the paint band's own scale), whichever is larger.
    smoothing_length_m: float = rng(
        0.003,
        1e-4,
        0.5,
        "m",
        "0.1 mm is under the sensor's noise; 0.5 m smooths away every turn of a scrap piece",
    )
    # default count: length / spacing + degree
    control_point_spacing_m: float = rng(
        0.02,
        1e-3,
        1.0,
        "m",
        "under 1 mm control points follow sensor noise; 1 m spacing is one span for a whole piece",
    )
    max_control_points: int = rng(
        200,
        2,
        5000,
        "",
        "a curve needs at least 2; 5000 on a 5 m line are 1 mm apart, finer than the sensor",
    )
    init: str = "auto"  # "principal" (the paper), "chain" (spanning-tree order) or "auto": best
    # knot insertion where the residuals stay one-sided
    refine_rounds: int = rng(
        4, 0, 100, "", "each round at most doubles the knots; 100 rounds is far past convergence"
    )
    # a knot span's mean residual above this (and noise) is split
    refine_bias_m: float = rng(
        0.0005,
        0.0,
        0.05,
        "m",
        "a mean residual over 50 mm is twice a stroke's width, no refinement criterion",
    )
    min_knot_spacing_m: float = rng(
        0.004, 1e-4, 1.0, "m", "0.1 mm is under the sensor's noise; 1 m leaves one span for a piece"
    )
    robust: bool = True  # Huber weights against outliers left by the outlier filter
    # the curve ends where this share of the points lies beyond
    end_quantile: float = rng(
        0.002,
        0.0,
        0.25,
        "",
        "a share of the points beyond each end; 0.25 at both ends already drops half the line",
    )
    # spacing of Curve.points
    sample_spacing_m: float = rng(
        0.001,
        1e-4,
        0.05,
        "m",
        "0.1 mm is finer than any sensor; over 50 mm the polyline cuts corners of a scrap piece",
    )
    # sharper turns become kinks (C0 knots); 0: smooth only
    corner_angle_deg: float = rng(30.0, 0.0, 180.0, "deg", "an angle between directions")
    max_corners: int = rng(8, 0, 1000, "", "more than 1000 kinks is no line a torch follows")
    # Ends: a spray stroke's round cap reaches about half a stroke width past the line's end.
    # "auto": end at each cap's centre (a square end, paint running off an edge, is kept);
    # "cap": always a round cap; "none": the paint's extent. See fitting/ends.py.
    end_trim: str = "auto"
    # fixed trim at each end instead of the estimate
    end_trim_m: float | None = rng(
        None,
        0.0,
        0.5,
        "m",
        "a trim over 0.5 m at each end cuts away more than a stroke's cap by far",
    )


@dataclass(frozen=True)
class SkeletonConfig:
    """3-D skeletonisation (voxelise, thin, graph, prune, longest path)."""

    # the paper's leaf size
    leaf_size_m: float = rng(
        0.005,
        1e-3,
        0.1,
        "m",
        "under 1 mm the leaf thins sensor noise and the thinning grid of a 1 m piece reaches 1e9 "
        "voxels; 100 mm is four strokes wide",
    )
    prune_length_m: float = rng(0.02, 0.0, 1.0, "m", "branches over 1 m are the line itself")
    smoothing_window: int = rng(5, 1, 1001, "", "a window of points along the skeleton (1: none)")
    # morphological closing radius, voxels (0: none)
    closing_voxels: int = rng(
        1, 0, 20, "", "a closing radius of 20 leaves bridges gaps of 10 cm at the paper's 5 mm leaf"
    )
    # smaller pieces (share of points) are stray paint, ignored
    min_piece_share: float = rng(0.02, 0.0, 1.0, "", "a share of the points")
    # dense thinning block budget (4 MiB); larger: tiled
    max_block_voxels: int = rng(
        4_194_304,
        1000,
        268_435_456,
        "",
        "under 1000 (10^3) a tile has no room for its margin; 2^28 voxels need gigabytes for one "
        "block",
    )
    # overlap of the thinning tiles
    block_margin_m: float = rng(
        0.05, 0.0, 1.0, "m", "tiles overlapping by over 1 m are the whole piece"
    )
    # paint points this close to the skeleton pull it to their centre
    refine_radius_m: float = rng(
        0.03,
        1e-4,
        0.5,
        "m",
        "under 0.1 mm no paint point is near; over 0.5 m every point of a piece pulls",
    )
    # arc-length half window; None: from the band width
    refine_window_m: float | None = rng(
        None, 1e-4, 1.0, "m", "a half window along the curve; 1 m averages the whole line"
    )
    # sharper turns are kept as corners (not smoothed across)
    corner_angle_deg: float = rng(30.0, 0.0, 180.0, "deg", "an angle between directions")
    refine_iterations: int = rng(2, 0, 100, "", "the refinement settles in a few iterations")
    # the curve ends where this share of the points lies beyond
    end_quantile: float = rng(
        0.002,
        0.0,
        0.25,
        "",
        "a share of the points beyond each end; 0.25 at both ends already drops half the line",
    )
    # spacing of Curve.points
    sample_spacing_m: float = rng(
        0.001,
        1e-4,
        0.05,
        "m",
        "0.1 mm is finer than any sensor; over 50 mm the polyline cuts corners of a scrap piece",
    )
    end_trim: str = "auto"  # "auto" | "cap" | "none": as NurbsConfig.end_trim
    # fixed trim at each end instead of the estimate
    end_trim_m: float | None = rng(
        None,
        0.0,
        0.5,
        "m",
        "a trim over 0.5 m at each end cuts away more than a stroke's cap by far",
    )


@dataclass(frozen=True)
class ToolpathConfig:
    """Cutting set-points, torch orientation, collisions and speeds."""

    spacing_m: float = rng(
        0.005,
        1e-4,
        0.5,
        "m",
        "0.1 mm is the Panda's repeatability (a 2 m cut would hold 20,000 set-points); 0.5 m "
        "spacing misses every turn",
    )
    standoff_m: float = rng(
        0.008,
        5e-4,
        0.1,
        "m",
        "an oxy-fuel or plasma torch cuts 1-10 mm off the plate; under 0.5 mm it touches, beyond "
        "100 mm the flame does not reach",
    )
    normal_radius_m: float = rng(
        0.015,
        1e-3,
        0.5,
        "m",
        "under 1 mm a neighbourhood holds no surface points; 0.5 m averages the whole piece",
    )
    torch_length_m: float = rng(
        0.15, 0.01, 2.0, "m", "hand-held to machine torches are 0.01-2 m long"
    )
    torch_radius_m: float = rng(
        0.012, 1e-3, 0.2, "m", "torch nozzles and bodies are 1-200 mm in radius"
    )
    max_tilt_deg: float = rng(20.0, 0.0, 89.0, "deg", "at 90 deg the torch lies on the plate")
    material: str = "mild_steel"
    thickness_mm: float = rng(
        10.0,
        0.1,
        2000.0,
        "mm",
        "thinner than 0.1 mm is foil; oxy-fuel charts end well before 2 m of steel",
    )
    # used where the normal_radius_m plane is rough
    coarse_normal_radius_m: float = rng(
        0.030,
        1e-3,
        0.5,
        "m",
        "under 1 mm a neighbourhood holds no surface points; 0.5 m averages the whole piece",
    )
    # Gaussian sigma of the smoothing along the path
    normal_smoothing_m: float = rng(
        0.010,
        0.0,
        1.0,
        "m",
        "a Gaussian sigma along the path; 1 m flattens a whole piece's normals",
    )
    # normals further apart are on different faces: not averaged
    edge_angle_deg: float = rng(30.0, 0.0, 180.0, "deg", "an angle between normals")
    # fewer within normal_radius_m: "no_surface", normal interpolated
    min_surface_points: int = rng(
        8,
        3,
        100_000,
        "",
        "a plane needs 3 points; no neighbourhood at sensor density holds 100,000",
    )
    # observed points inside the torch body that make a collision
    collision_min_points: int = rng(
        3, 1, 100_000, "", "at least one point; no torch body at sensor density holds 100,000"
    )
    # tilt angles tried, evenly up to max_tilt_deg
    tilt_steps: int = rng(
        4, 1, 90, "", "more than one step per degree of tilt tries the same pose twice"
    )
    # tilt directions tried around the normal
    tilt_directions: int = rng(
        8, 1, 360, "", "more than one direction per degree tries the same pose twice"
    )
    speed_table: str | None = None  # CSV of speeds; None: the bundled oxy-fuel table
    # Start at an edge the line reaches (no pierce) and run out past a far edge (toolpath.ends):
    # the observed surface must end within edge_gap_m of the paint's end; it counts as going on
    # when seen edge_probe_m past it; measured in a corridor of edge_corridor_m around the line.
    edge_start: bool = True
    edge_gap_m: float = rng(
        0.006,
        0.0,
        0.1,
        "m",
        "a few mm of paint blur and overspray; 100 mm from an edge is not at it",
    )
    edge_probe_m: float = rng(
        0.03,
        0.004,
        0.5,
        "m",
        "one 4 mm surface voxel at least; a scan's views see about 0.5 m of a piece",
    )
    edge_corridor_m: float = rng(
        0.01,
        0.002,
        0.2,
        "m",
        "half a 4 mm surface voxel at least; 0.2 m around a line is another part of the piece",
    )
    # Closed loops (a ring, a cut-out): where the torch pierces ("top": the highest observed
    # point; "reachable": the observed point nearest the robot's base; or "X,Y,Z" in metres,
    # base frame: the loop's point nearest to it), the lead-in from the pierce onto the line
    # and the overlap past the start at closure, so the loop is fully severed.
    start: str = "top"
    lead_in_m: float = rng(
        0.005,
        0.0,
        0.1,
        "m",
        "0 pierces on the line; a lead-in over 100 mm cuts far into the piece",
    )
    overlap_m: float = rng(
        0.01,
        0.0,
        0.2,
        "m",
        "0 stops where the cut began (a kerf's width can stay uncut); over 200 mm recuts the loop",
    )


@dataclass(frozen=True)
class ClosureConfig:
    """Whether the stitched paint closes on itself (``fitting.closure``) and its unobserved arcs.

    ``mode``: "auto" decides from the paint and the observed surface; "open" and "closed"
    force the answer (a worker who knows the mark is a ring).
    """

    mode: str = "auto"
    # voxel of the centre chain the decision is made on
    chain_voxel_m: float = rng(
        0.01,
        0.002,
        0.1,
        "m",
        "under 2 mm the chain follows sensor noise; 100 mm is four strokes wide",
    )
    # an end's direction must lie this close to the chord to the other end (a circular gap of up
    # to twice the angle) and run on into the other end when they lie side by side
    max_end_angle_deg: float = rng(100.0, 0.0, 180.0, "deg", "an angle between directions")
    # the gap may be at most this share of the loop
    max_gap_share: float = rng(
        0.5, 0.0, 0.9, "", "a share of the loop; closing over 90 % unseen is a guess, not a fit"
    )
    # how far past each tip the observed surface is probed for a real end
    end_probe_m: float = rng(
        0.025, 0.002, 0.2, "m", "under 2 mm probes one voxel; 200 mm reaches past most pieces"
    )
    # shorter stretches with neither paint nor surface are holes in the data, not arcs
    min_unobserved_arc_m: float = rng(
        0.01,
        0.002,
        1.0,
        "m",
        "under 2 mm is one bin along the curve; 1 m hides any arc of a scrap piece",
    )


@dataclass(frozen=True)
class ExplorationConfig:
    """Algorithm 1's next-view planner and stopping criterion."""

    ORDERED: ClassVar[tuple[tuple[str, str], ...]] = (("min_distance_m", "max_distance_m"),)

    method: str = "nurbs"
    # growth(k) = new paint voxels farther than novelty_m from the cloud before frame k; an end
    # is declared when growth(k) <= delta_size (re-observing known paint grows ~0 this way).
    delta_size: int = rng(
        20, 0, 1_000_000, "", "a frame of 4096 x 4096 px never adds a million paint voxels"
    )
    # next view's target: this far beyond the fitted curve's end
    step_m: float = rng(
        0.06,
        1e-3,
        1.0,
        "m",
        "a step under 1 mm never leaves the view; beyond 1 m it leaves the Panda's reach",
    )
    # camera distance search, from the camera's minimum upward
    min_distance_m: float = rng(
        0.2,
        0.05,
        3.0,
        "m",
        "depth cameras see from about 0.1 m; beyond 3 m a D435i's depth is too coarse for a 25 mm "
        "stroke",
    )
    max_distance_m: float = rng(
        0.45,
        0.05,
        3.0,
        "m",
        "depth cameras see from about 0.1 m; beyond 3 m a D435i's depth is too coarse for a 25 mm "
        "stroke",
    )
    distance_step_m: float = rng(
        0.025, 1e-3, 1.0, "m", "steps under 1 mm repeat one view; over 1 m skip the whole range"
    )
    # frames observed before stopping with "budget"
    max_steps: int = rng(60, 1, 10_000, "", "a scan of 10,000 views takes hours of robot time")
    novelty_m: float = rng(
        0.01,
        1e-4,
        0.5,
        "m",
        "under 0.1 mm every noisy point is new; over 0.5 m nothing on a piece is",
    )
    # the local fit runs on the paint thinned to this voxel
    fit_voxel_m: float = rng(
        0.006, 1e-4, 0.1, "m", "0.1 mm is finer than any sensor; 100 mm is four strokes wide"
    )
    # local fit window: the frame's paint extent plus this margin
    fit_margin_m: float = rng(
        0.05, 0.0, 2.0, "m", "a margin beyond 2 m is the whole reach of the arm"
    )
    # observed surface used for the normal at a target
    normal_radius_m: float = rng(
        0.03,
        1e-3,
        0.5,
        "m",
        "under 1 mm a neighbourhood holds no surface points; 0.5 m averages the whole piece",
    )
    # views stay at least this high above their target
    min_elevation_deg: float = rng(
        35.0, 0.0, 90.0, "deg", "an elevation above the target's surface"
    )
    # rotation about the optical axis tried in these steps
    roll_step_deg: float = rng(
        45.0, 1.0, 360.0, "deg", "a roll step under 1 deg tries hundreds of near-equal views"
    )
    # a target this close to a visited one is not taken again
    revisit_radius_m: float = rng(
        0.02, 0.0, 1.0, "m", "a radius over 1 m forbids every target on a piece after the first"
    )
    # voxel hash of every observed depth point (collisions)
    occupancy_voxel_m: float = rng(
        0.01,
        1e-3,
        0.5,
        "m",
        "under 1 mm the voxel hash of every depth point grows past memory; 0.5 m voxels block the "
        "whole cell",
    )
    # safety margin around occupied voxels
    inflation_m: float = rng(
        0.02, 0.0, 0.5, "m", "a safety margin over 0.5 m blocks the whole cell"
    )
    # camera + hand as a capsule along the optical axis: front,
    body_front_m: float = rng(
        0.07, 0.0, 1.0, "m", "the camera and hand of a Panda measure well under 1 m"
    )
    # back (towards the flange) and radius
    body_back_m: float = rng(
        0.25, 0.0, 1.0, "m", "the camera and hand of a Panda measure well under 1 m"
    )
    body_radius_m: float = rng(
        0.06, 0.0, 1.0, "m", "the camera and hand of a Panda measure well under 1 m"
    )
    look_past: bool = True  # re-observe past an edge or sharp turn before declaring an end
    # view tilts about the edge
    look_past_angles_deg: tuple[float, ...] = rng(
        (60.0, 90.0, 40.0), 0.0, 180.0, "deg", "tilts about an edge"
    )
    # A look past an edge found nothing and no frame observed the end: look once more from over
    # the line (a wall at a concave corner shows its paint only from there)
    look_back: bool = True
    # surface must continue this far beyond a confirmed end
    edge_probe_m: float = rng(0.025, 0.0, 0.5, "m", "a probe over 0.5 m reaches past most pieces")
    # the fitted curve turning more near its end: look past
    turn_angle_deg: float = rng(45.0, 0.0, 180.0, "deg", "an angle between directions")
    # No view past an end from the normal's side: try the surface's other side (a mesh, a sheet)
    other_side_views: bool = True
    # Still no view: the end counts if an earlier frame observed it (exploration.evidence):
    # tip and continuation (edge_probe_m past it) this share of the image inside the border,
    # judged on depth windows of this radius with this tolerance.
    observed_end: bool = True
    observed_end_margin: float = rng(
        0.05, 0.0, 0.5, "", "a share of the image; 0.5 leaves no inside"
    )
    observed_end_window_m: float = rng(
        0.006,
        1e-4,
        0.1,
        "m",
        "0.1 mm is finer than any sensor; a 100 mm window is four strokes wide",
    )
    observed_end_tolerance_m: float = rng(
        0.01, 1e-4, 0.5, "m", "under 0.1 mm no depth agrees; over 0.5 m every depth does"
    )
    # After both ends: this many views of the initial stretch, tilted round its normal and
    # rolled, so that the hand-eye and clock self-calibration can see every direction.
    calibration_views: int = rng(
        0, 0, 12, "", "a dozen views already turn the camera about every axis"
    )
    calibration_tilt_deg: float = rng(
        30.0,
        5.0,
        60.0,
        "deg",
        "under 5 deg the views barely turn; over 60 they see the paint edge-on",
    )


@dataclass(frozen=True)
class SimConfig:
    """The simulator: object, camera, noise, paint stroke, views."""

    object: str = "cylinder"
    mode: str = "sweep"
    noise: str = "d435i"
    width: int = rng(
        640,
        16,
        4096,
        "px",
        "16 px shows nothing; a 4096 px image is beyond any RGB-D sensor (the D435i's colour is "
        "1920 x 1080)",
    )
    height: int = rng(
        480,
        12,
        4096,
        "px",
        "12 px shows nothing; a 4096 px image is beyond any RGB-D sensor (the D435i's colour is "
        "1920 x 1080)",
    )
    stroke_width_m: float = rng(0.025, 1e-3, 0.2, "m", "marking-paint strokes are 5-100 mm wide")
    view_distance_m: float = rng(
        0.3,
        0.1,
        3.0,
        "m",
        "the D435i sees from about 0.1 m; beyond 3 m its depth is too coarse for a 25 mm stroke",
    )
    seed: int = rng(
        0,
        0,
        4_294_967_295,
        "",
        "the simulator draws from the seed's low 32 bits: a larger seed would repeat a smaller one",
    )
    paint: str = "orange"  # preset the piece is painted with (perception.paint.PAINT_PRESETS)
    # 0: sweep one view per view_step_m of line, survey its full grid
    views: int = rng(0, 0, 10_000, "", "a scan of 10,000 views takes hours of robot time")
    # sweep spacing along the line (~85 % overlap at 0.3 m)
    view_step_m: float = rng(
        0.05, 1e-3, 1.0, "m", "steps under 1 mm repeat one view; over 1 m skip whole pieces"
    )
    # survey target grid over the piece's top
    survey_spacing_m: float = rng(
        0.10, 0.01, 1.0, "m", "under 10 mm the survey grid of a piece holds thousands of views"
    )
    # cameras stay at least this high above their target
    min_elevation_deg: float = rng(
        35.0, 0.0, 89.0, "deg", "an elevation above the target's surface (90: straight down only)"
    )
    # images at 30 Hz while the robot rests at a view
    frames_per_view: int = rng(1, 1, 300, "", "300 frames are 10 s at 30 Hz per view")
    # budget of executed views (explore mode safety stop)
    max_views: int = rng(200, 1, 10_000, "", "a scan of 10,000 views takes hours of robot time")
    # free DOF: how far a view may back off along its axis
    max_backoff_m: float = rng(0.15, 0.0, 1.0, "m", "the Panda reaches 0.855 m")
    # share of the Panda's joint speed limits used between views
    speed_scale: float = rng(0.25, 0.01, 1.0, "", "a share of the Panda's joint speed limits")
    # /tf and /joint_states rate
    tf_rate_hz: float = rng(100.0, 1.0, 1000.0, "Hz", "the Panda's control loop runs at 1 kHz")
    depth_encoding: str = "16UC1"  # or "32FC1" (float metres: no 1 mm quantisation)
    # placement of the piece on the floor, base frame
    object_x_m: float = rng(
        0.5, -2.0, 2.0, "m", "the Panda reaches 0.855 m; 2 m is out of any view"
    )
    object_y_m: float = rng(
        0.0, -2.0, 2.0, "m", "the Panda reaches 0.855 m; 2 m is out of any view"
    )
    object_yaw_deg: float = rng(0.0, -360.0, 360.0, "deg", "one turn either way")
    # explore start along the line, 0-1; None: the piece's
    start_fraction: float | None = rng(None, 0.0, 1.0, "", "a fraction of the line")
    # Calibration errors and the camera's clock; None: the noise preset's (yard: 2 mm, 0.3 deg,
    # 10-20 ms either way, 6 images/s while moving; others: none).
    hand_eye_error_m: float | None = rng(
        None, 0.0, 0.05, "m", "a hand-eye error beyond 50 mm is a camera on another mount"
    )
    hand_eye_error_deg: float | None = rng(
        None, 0.0, 10.0, "deg", "a hand-eye error beyond 10 deg is a camera on another mount"
    )
    # header stamp minus capture time
    stamp_offset_s: float | None = rng(
        None,
        -0.5,
        0.5,
        "s",
        "camera clocks drift by milliseconds to tens of ms from a robot's; half a second is a "
        "misconfigured clock, not an offset",
    )
    # images per second recorded while moving (0: none)
    motion_frames_hz: float | None = rng(
        None, 0.0, 30.0, "Hz", "the D435i streams colour at 6, 15 or 30 Hz at 640 x 480"
    )
    color_encoding: str = "rgb8"  # or "jpeg": CompressedImage on .../image_raw/compressed only
    # image_transport's compressed default
    jpeg_quality: int = rng(95, 1, 100, "", "libjpeg's quality scale")
    storage: str = "sqlite3"  # a ROS 2 bag's storage (-o without .mcap): rosbag2's default
    # What lies in the scene (sim.scene); None: the noise preset's.
    paint_variation: bool | None = None  # the can's colour varies around the preset
    # old marks near the line
    faded_marks: int | None = rng(
        None, 0, 20, "", "a piece marked for twenty earlier jobs has no room for a new line"
    )
    distractors: tuple[str, ...] | None = None  # box, cone, glove on the floor beside the piece
    glints: bool | None = None  # mirror-like spots on the steel


@dataclass(frozen=True)
class CalibrationConfig:
    """Hand-eye and clock self-calibration from the scan (``scrapcut calibrate``).

    Frames are compared pairwise where they overlap: surface point-to-plane and paint-edge
    residuals (calibration/solver.py). ``observable_sigma_*`` are the accuracies a direction
    must be determined to for it to count as observable (an eigen-direction's standard
    deviation in these units below 1); ``prior_*`` weakly hold every parameter near the
    published value; a correction within ``consistent_*`` (or 3 sigma) of zero leaves the
    published calibration as it is.

    ``file`` (a CAL.yaml of ``scrapcut calibrate -o``) or ``self_calibrate`` (estimate it from
    the recording first) make every stitch pose the frames with that mount and clock offset.
    """

    ORDERED: ClassVar[tuple[tuple[str, str], ...]] = (("min_distance_m", "max_distance_m"),)

    file: str | None = None  # CAL.yaml to pose frames with (--calibration)
    self_calibrate: bool = False  # estimate the calibration from the recording (--self-calibrate)

    # frames compared, chosen for diverse poses and speeds
    max_frames: int = rng(
        40, 2, 1000, "", "two frames are the least to compare; 1000 frames take minutes"
    )
    # depth samples per frame (a pixel grid)
    surface_samples: int = rng(
        1500, 50, 100_000, "", "under 50 samples a frame's surface is unknown; 100,000 is slow"
    )
    # paint-edge points thinned to one per cell of this size
    edge_spacing_m: float = rng(
        0.002, 2e-4, 0.02, "m", "0.2 mm is below a pixel at the wrist; 20 mm loses the edge"
    )
    # overlapping frames each frame is compared with (the most telling)
    partners: int = rng(6, 1, 100, "", "at least one partner; 100 partners repeat each other")
    # share of shared 20 mm voxels for two frames to be compared
    min_overlap: float = rng(0.2, 0.0, 1.0, "", "a share of a frame's surface")
    max_distance_m: float = rng(
        0.015,
        5e-4,
        0.1,
        "m",
        "correspondences beyond 100 mm are different surfaces; the first gate must exceed the "
        "calibration error",
    )
    min_distance_m: float = rng(
        0.005, 5e-4, 0.1, "m", "the last gate must exceed the depth noise (0.3-1.3 mm)"
    )
    # correspondence searches (gates), two Gauss-Newton steps each
    iterations: int = rng(6, 2, 100, "", "two searches at least; 100 never improve on 10")
    observable_sigma_m: float = rng(
        0.0002, 1e-6, 0.01, "m", "the accuracy a mount translation must be determined to"
    )
    observable_sigma_deg: float = rng(
        0.04, 1e-4, 1.0, "deg", "the accuracy a mount rotation must be determined to"
    )
    observable_sigma_s: float = rng(
        0.001, 1e-5, 0.05, "s", "the accuracy the clock offset must be determined to"
    )
    prior_translation_m: float = rng(
        0.01, 1e-4, 0.1, "m", "how far a published hand-eye translation may plausibly be off"
    )
    prior_rotation_deg: float = rng(
        2.0, 0.01, 20.0, "deg", "how far a published hand-eye rotation may plausibly be off"
    )
    prior_time_offset_s: float = rng(
        0.1, 1e-3, 1.0, "s", "how far a camera's stamps may plausibly be off the robot's clock"
    )
    consistent_translation_m: float = rng(
        0.0002, 0.0, 0.01, "m", "smaller mount corrections move a path by less than this"
    )
    consistent_rotation_deg: float = rng(
        0.03, 0.0, 1.0, "deg", "0.03 deg moves a point 0.3 m away by 0.16 mm"
    )
    consistent_time_offset_s: float = rng(
        0.001, 0.0, 0.05, "s", "1 ms at the arm's 0.1-0.3 m/s between views is 0.1-0.3 mm"
    )


@dataclass(frozen=True)
class EvaluationConfig:
    """The error report of docs/design.md: reference sampling and coverage threshold."""

    sample_spacing_m: float = rng(
        0.001,
        1e-4,
        0.1,
        "m",
        "the paper samples every 1 mm; under 0.1 mm a 5 m reference holds 50,000+ samples for "
        "nothing, over 100 mm it misses turns",
    )
    coverage_threshold_m: float = rng(
        0.010,
        1e-4,
        1.0,
        "m",
        "under 0.1 mm no fit covers anything; over 1 m every path covers every reference",
    )


@dataclass(frozen=True)
class MotionConfig:
    """Joint trajectory (``scrapcut trajectory``): mount, tilts, moves, timing, collisions.

    The torch body checked for collisions is the toolpath's (``toolpath.torch_length_m``,
    ``torch_radius_m``, ``collision_min_points``), so both checks agree. Approach and retreat
    run 100 mm along the torch axis at 50 mm/s; the cut's speed is the path's (the chart's).
    """

    tool_offset: str | None = None  # "x,y,z[,roll,pitch,yaw]" mm/deg or YAML/JSON; None: default
    urdf: str | None = None  # None: pybullet_data's franka_panda/panda.urdf
    # torch tilt allowed where the axis as given is not reachable
    max_tilt_deg: float = rng(20.0, 0.0, 89.0, "deg", "at 90 deg the torch lies on the plate")
    tilt_steps: int = rng(
        4, 1, 90, "", "more than one step per degree of tilt tries the same pose twice"
    )
    tilt_directions: int = rng(
        8, 1, 360, "", "more than one direction per degree tries the same pose twice"
    )
    # between neighbouring set-points; more is a flip
    max_joint_step_rad: float = rng(
        0.25,
        0.01,
        3.2,
        "rad",
        "under 0.01 rad a 5 mm step of a wrist near a singularity is refused; over pi any flip "
        "passes",
    )
    approach_m: float = rng(
        0.10, 0.005, 1.0, "m", "one waypoint at least; the Panda reaches about 0.85 m"
    )
    retreat_m: float = rng(
        0.10, 0.005, 1.0, "m", "one waypoint at least; the Panda reaches about 0.85 m"
    )
    # TCP speed of approach and retreat
    travel_speed_m_s: float = rng(
        0.05,
        0.001,
        1.7,
        "m/s",
        "1 mm/s crawls; 1.7 m/s is the Panda's Cartesian velocity limit",
    )
    # joint speed of the transit between two cuts (around set-points it cannot reach)
    transit_speed_rad_s: float = rng(
        0.5, 0.01, 2.175, "rad/s", "0.01 rad/s crawls; 2.175 rad/s is the Panda's joint limit"
    )
    # past the far edge, so the kerf leaves the piece
    run_out_m: float = rng(0.010, 0.0, 0.2, "m", "0 is no run-out; 0.2 m cuts air for long")
    # IK waypoints of approach, retreat and run-out
    waypoint_spacing_m: float = rng(
        0.005, 1e-4, 0.1, "m", "0.1 mm is the Panda's repeatability; 0.1 m skips obstacles"
    )
    # trajectory points (plus one at every set-point)
    sample_period_s: float = rng(
        0.1, 0.001, 1.0, "s", "1 ms is Franka's control period; over 1 s hides the ramps"
    )
    # speed-profile filters (motion.timing.MoveProfile)
    accel_time_s: float = rng(
        0.2, 0.002, 10.0, "s", "2 control periods at least; 10 s to reach a cutting speed crawls"
    )
    jerk_time_s: float = rng(
        0.05, 0.001, 10.0, "s", "one control period at least; 10 s to reach a cutting speed crawls"
    )
    # plan to this share of the velocity/acceleration/jerk limits
    limit_share: float = rng(0.5, 0.01, 1.0, "", "a share of Franka's limits: over 1 exceeds them")
    # clearance of the arm's capsules to the observed surface
    link_margin_m: float = rng(
        0.010, 0.0, 0.2, "m", "0 touches; 0.2 m keeps the arm away from every piece it cuts"
    )
    floor_margin_m: float = rng(
        0.020, 0.0, 0.5, "m", "0 touches; 0.5 m keeps the arm off most pieces on the floor"
    )
    # the floor (or table) plane in the base frame
    floor_z_m: float = rng(
        0.0, -2.0, 1.0, "m", "a Panda stands on a table at most 2 m high, or on the floor"
    )
    # the space near the piece the camera never saw counts as an obstacle (motion.observed)
    avoid_unseen: bool = True
    unseen_voxel_m: float = rng(
        0.01,
        0.004,
        0.1,
        "m",
        "free space is carved on this grid: under 4 mm rays miss voxels between them; 10 cm "
        "hides a flange",
    )
    # the observed surface is thinned to this grid
    collision_voxel_m: float = rng(
        0.003, 5e-4, 0.05, "m", "finer than 0.5 mm is below depth noise; 5 cm misses a flange"
    )


@dataclass(frozen=True)
class ScrapcutConfig:
    """Every stage's parameters."""

    recording: RecordingConfig = field(default_factory=RecordingConfig)
    paint: PaintConfig = field(default_factory=PaintConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    stitch: StitchConfig = field(default_factory=StitchConfig)
    selection: SelectionConfig = field(default_factory=SelectionConfig)
    nurbs: NurbsConfig = field(default_factory=NurbsConfig)
    skeleton: SkeletonConfig = field(default_factory=SkeletonConfig)
    closure: ClosureConfig = field(default_factory=ClosureConfig)
    toolpath: ToolpathConfig = field(default_factory=ToolpathConfig)
    exploration: ExplorationConfig = field(default_factory=ExplorationConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    evaluation: EvaluationConfig = field(default_factory=EvaluationConfig)
    calibration: CalibrationConfig = field(default_factory=CalibrationConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON/TOML-ready dictionary of every parameter."""
        return _jsonable(dataclasses.asdict(self))

    def override(self, section: str, **values: Any) -> ScrapcutConfig:
        """A copy with ``section``'s fields replaced; ``None`` values mean "not given".

        The new values are checked (:func:`validate`): ConfigError names the first bad one.
        """
        given = {k: v for k, v in values.items() if v is not None}
        if not given:
            return self
        current = getattr(self, section)
        return replace(self, **{section: update_dataclass(current, given, section)})


#: Keys a user may write in another unit than the one saved: ``voxel_size_mm = 2`` for
#: ``voxel_size_m = 0.002``. (suffix typed, suffix of the field, factor to the field's unit).
UNIT_ALIASES = (("_mm", "_m", 1e-3), ("_ms", "_s", 1e-3), ("_deg", "_rad", math.pi / 180.0))


def unit_aliases(obj: Any, values: dict[str, Any], where: str) -> dict[str, Any]:
    """``values`` with keys in a user's unit converted to the field's (the one place it is
    done): a TOML file may say ``voxel_size_mm = 2`` where the saved form is
    ``voxel_size_m = 0.002``. A key that is itself a field is left alone; both forms of one
    parameter are refused (which one wins would be a guess)."""
    known = {f.name for f in fields(obj)}
    out: dict[str, Any] = {}
    for key, value in values.items():
        target, factor = key, None
        for typed, saved, scale in UNIT_ALIASES:
            stem = key.removesuffix(typed)
            if key not in known and key.endswith(typed) and stem + saved in known:
                target, factor = stem + saved, scale
                break
        if factor is not None:
            if target in values:
                raise ConfigError(f"{where}: {key} and {target} name one parameter; keep one")
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"{where}: {key} must be a number, got {value!r}")
            value = value * factor
        out[target] = value
    return out


def update_dataclass(obj: T, values: dict[str, Any], where: str) -> T:
    """``dataclasses.replace`` with a clear error for unknown names, wrong types and values
    outside their ranges (the section is validated as a whole afterwards)."""
    known = {f.name: f for f in fields(obj)}  # type: ignore[arg-type]
    for name, value in values.items():
        if name not in known:
            raise ConfigError(
                f"unknown parameter {where}.{name}; known: {', '.join(sorted(known))}"
            )
        if value is not None:
            values[name] = _coerce(value, str(known[name].type), f"{where}.{name}")
    updated = replace(obj, **values)  # type: ignore[type-var]
    validate_section(updated, where)
    return updated


def _coerce(value: Any, declared: str, key: str) -> Any:
    """``value`` as the declared type (``"int | None"``...), or ConfigError naming ``key``."""
    kind = declared.replace(" | None", "")
    if kind == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"{key} must be true or false, got {value!r}")
        return value
    if kind in ("int", "float"):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{key} must be a number, got {value!r}")
        if kind == "float":
            return float(value)
        # A count (neighbours, iterations, pixels) reaches libraries refusing floats.
        if not float(value).is_integer():
            raise ConfigError(f"{key} must be a whole number, got {value!r}")
        return int(value)
    if kind == "str":
        if not isinstance(value, str):
            raise ConfigError(f"{key} must be a string, got {value!r}")
        return value
    if kind.startswith("tuple[str"):
        if not isinstance(value, list | tuple) or any(not isinstance(v, str) for v in value):
            raise ConfigError(f"{key} must be a list of names, got {value!r}")
        return tuple(value)
    if kind.startswith("tuple"):
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{key} must be a list of numbers, got {value!r}")
        if any(isinstance(v, bool) or not isinstance(v, int | float) for v in value):
            raise ConfigError(f"{key} must be a list of numbers, got {value!r}")
        return tuple(float(v) for v in value)
    return value


def load_config(path: str | Path | None = None) -> ScrapcutConfig:
    """Defaults, updated from the TOML file at ``path`` when given."""
    config = ScrapcutConfig()
    if path is None:
        return config
    from scrapcut_cli._io import read_text_input
    from scrapcut_cli.errors import FileError

    path = Path(path)
    try:
        data = tomllib.loads(read_text_input(path, "configuration file", max_bytes=1 << 24))
    except FileError as exc:
        raise ConfigError(str(exc)) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"cannot read configuration {path}: {exc}") from None
    except RecursionError:
        raise ConfigError(f"cannot read configuration {path}: nested too deep") from None
    return config_from_dict(data, where=str(path))


def config_from_dict(data: dict[str, Any], *, where: str = "config") -> ScrapcutConfig:
    """Defaults updated from a nested dictionary (the shape of :meth:`ScrapcutConfig.to_dict`)."""
    config = ScrapcutConfig()
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a table of sections")
    sections = {f.name for f in fields(config)}
    for section, values in data.items():
        if section not in sections:
            raise ConfigError(
                f"{where}: unknown section [{section}]; known: {', '.join(sorted(sections))}"
            )
        if not isinstance(values, dict):
            raise ConfigError(f"{where}: [{section}] must be a table")
        current = getattr(config, section)
        values = unit_aliases(current, dict(values), f"{where}: [{section}]")
        config = replace(config, **{section: update_dataclass(current, values, section)})
    return validate(config)


# --------------------------------------------------------------------------- ranges


def config_field(section: str, name: str) -> dataclasses.Field[Any]:
    """The dataclass field of parameter ``section.name`` (KeyError if there is none)."""
    if section not in ScrapcutConfig.__dataclass_fields__:
        raise KeyError(section)
    for f in fields(getattr(ScrapcutConfig(), section)):
        if f.name == name:
            return f
    raise KeyError(f"{section}.{name}")


def field_range(section: str, name: str) -> tuple[float, float, str, str]:
    """(lo, hi, unit, why) declared for ``section.name``; KeyError if it has no range."""
    f = config_field(section, name)
    lo, hi = f.metadata[RANGE]
    return lo, hi, f.metadata[UNIT], f.metadata[WHY]


def is_count(section: str, name: str) -> bool:
    """True if ``section.name`` is declared an int (a count: whole numbers only)."""
    return str(config_field(section, name).type).replace(" | None", "") == "int"


def validate(config: ScrapcutConfig) -> ScrapcutConfig:
    """Check every parameter of ``config`` against its declared range and the relations
    between fields; return ``config``. Raises ConfigError naming the first bad value."""
    for f in fields(config):
        validate_section(getattr(config, f.name), f.name)
    return config


def validate_section(section: Any, where: str) -> None:
    """:func:`validate` for one stage's dataclass (``where`` names it in messages)."""
    for f in fields(section):
        value = getattr(section, f.name)
        if RANGE in f.metadata and value is not None:
            _check_range(f, value, f"{where}.{f.name}")
    for a, b in getattr(section, "ORDERED", ()):
        va, vb = getattr(section, a), getattr(section, b)
        if va is not None and vb is not None and va > vb:
            raise ConfigError(f"{where}.{a} = {va:g} is above {where}.{b} = {vb:g}")


def _check_range(f: dataclasses.Field[Any], value: Any, key: str) -> None:
    bounds = f.metadata[RANGE]
    unit, why = f.metadata[UNIT], f.metadata[WHY]
    if isinstance(value, tuple):
        if isinstance(bounds[0], tuple):  # one range per element
            if len(value) != len(bounds):
                raise ConfigError(f"{key} needs {len(bounds)} numbers, got {len(value)}")
            units = [u.strip() for u in unit.split(",")]
            for k, (item, (lo, hi)) in enumerate(zip(value, bounds, strict=True)):
                _check_number(item, lo, hi, units[k] if k < len(units) else "", why, f"{key}[{k}]")
        else:
            for k, item in enumerate(value):
                _check_number(item, bounds[0], bounds[1], unit, why, f"{key}[{k}]")
        return
    lo, hi = bounds
    whole = str(f.type).replace(" | None", "") == "int"
    _check_number(value, lo, hi, unit, why, key, whole=whole)


def _check_number(
    value: Any, lo: float, hi: float, unit: str, why: str, key: str, *, whole: bool = False
) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{key} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ConfigError(f"{key} must be a finite number, got {value}")
    if whole and not float(value).is_integer():
        raise ConfigError(f"{key} must be a whole number, got {value!r}")
    # A bound typed in another unit (mm on the command line) may round by an ulp.
    slack = 1e-9 * max(abs(lo), abs(hi))
    if not lo - slack <= value <= hi + slack:
        units = f" {unit}" if unit else ""
        raise ConfigError(f"{key} = {value:g}{units} is outside {lo:g} to {hi:g}{units}: {why}")


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value
