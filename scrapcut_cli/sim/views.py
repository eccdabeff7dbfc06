"""Pre-planned camera views (sweep, survey) and the planner that replays them.

``sweep``: views along the reference line, each looking at a point of the line along the
surface normal there (averaged over ±30 mm of line, so a view at a crease looks into the
corner), at ``distance_m`` (0.3 m default, inside the D435i's 0.25–0.35 m sweet spot where
σ_z < 0.5 mm yet a view spans ~0.3 m), with the line across the wide image axis. Consecutive
views overlap: at 0.3 m a 640-px image spans 0.31 m, so the default 50 mm step shares ~85 %.
A camera is never lower than ``min_elevation_deg`` above its target: a normal pointing
sideways (a vertical face) is tilted up towards the sky, as an operator would, keeping the arm
above the piece.

``survey``: a dense set of views over the whole piece — a grid of targets on its top surface,
each seen from straight above and from four sides at 55° elevation.

Both feed :class:`PrePlannedPlanner`, which implements ``cell.ViewPlanner`` so the recorder
runs one loop for every mode. Both are oracles: their views follow the true line and the true
shape of the piece.

``worker_view``: explore mode's start, where a worker points the robot by hand — a view of the
line moved and turned by a seeded amount, not the exact line point, normal and tangent.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.cell import Decision
from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import (
    cumulative_length,
    interpolate_polyline,
    make_transform,
    orthonormal_frame,
    polyline_tangents,
)
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.sim.objects import ScrapObject

FloatArray = NDArray[np.float64]

#: A worker pointing the robot at the line lands within this much of a view computed from it:
#: the camera up to 20 mm off along each base axis, its optical axis tilted by up to 10° and
#: turned about itself by up to 10° (assumed: hand guiding by eye, at ~0.3 m).
START_POSITION_NOISE_M = 0.02
START_ANGLE_NOISE_DEG = 10.0


def tilt_up(direction: ArrayLike, min_elevation_deg: float) -> FloatArray:
    """``direction`` (3,) unit, raised in its vertical plane to at least the given elevation."""
    n = np.asarray(direction, dtype=np.float64)
    n = n / np.linalg.norm(n)
    min_el = np.radians(min_elevation_deg)
    if np.arcsin(np.clip(n[2], -1.0, 1.0)) >= min_el:
        return n
    horizontal = np.array([n[0], n[1], 0.0])
    h = np.linalg.norm(horizontal)
    horizontal = horizontal / h if h > 1e-9 else np.array([1.0, 0.0, 0.0])
    return np.asarray(np.cos(min_el) * horizontal + np.array([0.0, 0.0, np.sin(min_el)]))


def view_at(
    target: ArrayLike, outward: ArrayLike, x_hint: ArrayLike, distance_m: float
) -> FloatArray:
    """T_base_cam (4, 4) looking at ``target`` from ``distance_m`` along ``outward``.

    The image x axis is as close to ``x_hint`` as possible (the line runs across the image).
    """
    out = np.asarray(outward, dtype=np.float64)
    out = out / np.linalg.norm(out)
    R = orthonormal_frame(-out, x_hint)
    return make_transform(R, np.asarray(target, dtype=np.float64) + distance_m * out)


def sweep_views(
    obj: ScrapObject,
    *,
    distance_m: float = 0.3,
    step_m: float = 0.05,
    count: int = 0,
    min_elevation_deg: float = 35.0,
    normal_window_m: float = 0.03,
) -> list[FloatArray]:
    """Camera poses (4, 4) along the reference from its start to its end.

    ``count`` views evenly spaced, or (``count`` = 0) one every ``step_m`` of line, ends
    included.
    """
    if distance_m <= 0 or step_m <= 0 or count < 0:
        raise SimError(
            f"sweep needs a positive distance and step and count >= 0, got distance "
            f"{distance_m} m, step {step_m} m, count {count}"
        )
    length = float(cumulative_length(obj.reference)[-1])
    n = count if count > 0 else int(np.ceil(length / step_m - 1e-9)) + 1
    fractions = np.linspace(0.0, 1.0, n) if n > 1 else np.array([0.5])
    return views_along(
        obj,
        fractions,
        distance_m=distance_m,
        min_elevation_deg=min_elevation_deg,
        normal_window_m=normal_window_m,
    )


def views_along(
    obj: ScrapObject,
    fractions: ArrayLike,
    *,
    distance_m: float = 0.3,
    min_elevation_deg: float = 35.0,
    normal_window_m: float = 0.03,
) -> list[FloatArray]:
    """Camera poses (4, 4) looking at the line at the given fractions (0-1) of its length.

    Each camera looks along the painted surface's normal there (averaged over
    ``normal_window_m`` of line, raised to ``min_elevation_deg``), image x along the line.
    """
    ref = obj.reference
    arc = cumulative_length(ref)
    s = np.clip(np.asarray(fractions, dtype=np.float64).reshape(-1), 0.0, 1.0) * arc[-1]
    normals = obj.reference_normals
    tangents = polyline_tangents(ref)
    targets = interpolate_polyline(ref, s, cumulative=arc)
    views = []
    for si, target in zip(s, targets, strict=True):
        window = np.abs(arc - si) <= normal_window_m
        normal = normals[window].sum(axis=0)
        if np.linalg.norm(normal) < 1e-9:  # faces cancel (a knife edge): look from above
            normal = np.array([0.0, 0.0, 1.0])
        tangent = tangents[window].sum(axis=0)
        views.append(view_at(target, tilt_up(normal, min_elevation_deg), tangent, distance_m))
    return views


def worker_view(
    T_base_cam: ArrayLike,
    rng: np.random.Generator,
    *,
    position_m: float = START_POSITION_NOISE_M,
    angle_deg: float = START_ANGLE_NOISE_DEG,
) -> FloatArray:
    """``T_base_cam`` (4, 4) as a worker would point the camera at it by hand.

    The camera moves by a uniform offset within ±``position_m`` along each base axis; its
    optical axis tilts by a uniform angle within ``angle_deg`` towards a uniform direction,
    and the image turns about the axis by a uniform angle within ±``angle_deg``.
    """
    from scipy.spatial.transform import Rotation

    T = np.asarray(T_base_cam, dtype=np.float64)
    offset = rng.uniform(-position_m, position_m, 3)
    tilt = np.radians(rng.uniform(0.0, angle_deg))
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    roll = np.radians(rng.uniform(-angle_deg, angle_deg))
    turn = Rotation.from_rotvec(tilt * np.array([np.cos(azimuth), np.sin(azimuth), 0.0]))
    R = T[:3, :3] @ turn.as_matrix() @ Rotation.from_rotvec([0.0, 0.0, roll]).as_matrix()
    return make_transform(R, T[:3, 3] + offset)


def survey_views(
    obj: ScrapObject,
    *,
    distance_m: float = 0.3,
    spacing_m: float = 0.10,
    count: int = 0,
    oblique_elevation_deg: float = 55.0,
    reachable: Callable[[FloatArray], bool] | None = None,
) -> list[FloatArray]:
    """Camera poses over the whole piece: targets on a grid over its top, five views each.

    The grid spans the piece's bounding box at ``spacing_m``; a target is the highest point of
    the piece within ±12 mm of a grid point (so a wire mesh counts; grid points over bare
    floor are dropped). Each target is seen from above and from four sides; views
    ``reachable`` rejects (if given) are left out. Views run target by target in a serpentine
    order; ``count`` > 0 keeps that many, evenly spread over the list.
    """
    from scrapcut_cli._open3d import o3d as _o3d

    if distance_m <= 0 or spacing_m <= 0 or count < 0:
        raise SimError(
            f"survey needs a positive distance and spacing and count >= 0, got distance "
            f"{distance_m} m, spacing {spacing_m} m, count {count}"
        )
    o3d = _o3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(obj.vertices.astype(np.float32)),
        o3d.core.Tensor(obj.faces.astype(np.uint32)),
    )
    lo, hi = obj.vertices.min(axis=0), obj.vertices.max(axis=0)
    nx = max(int(np.ceil((hi[0] - lo[0]) / spacing_m)), 1)
    ny = max(int(np.ceil((hi[1] - lo[1]) / spacing_m)), 1)
    xs = np.linspace(lo[0], hi[0], nx + 2)[1:-1]
    ys = np.linspace(lo[1], hi[1], ny + 2)[1:-1]
    grid = np.array([(x, y) for i, x in enumerate(xs) for y in (ys if i % 2 == 0 else ys[::-1])])
    # A 7 × 7 probe patch at 4 mm pitch cannot slip between 4 mm wires.
    steps = np.linspace(-0.012, 0.012, 7)
    offsets = np.array([(dx, dy) for dx in steps for dy in steps])
    probes = (grid[:, None, :] + offsets[None, :, :]).reshape(-1, 2)
    top = hi[2] + 0.5
    rays = np.column_stack(
        [probes, np.full(len(probes), top), np.tile([0.0, 0.0, -1.0], (len(probes), 1))]
    )
    t = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
    t = t.astype(np.float64).reshape(len(grid), len(offsets))
    nearest = np.min(t, axis=1)  # the highest hit around each grid point
    hit = np.isfinite(nearest)
    targets = np.column_stack([grid[hit], top - nearest[hit]])
    el = np.radians(oblique_elevation_deg)
    directions = [np.array([0.0, 0.0, 1.0])] + [
        np.array([np.cos(el) * np.cos(a), np.cos(el) * np.sin(a), np.sin(el)])
        for a in np.radians([180.0, 90.0, 0.0, 270.0])  # robot side first
    ]
    views = [
        view_at(target, d, (1.0, 0.0, 0.0) if abs(d[0]) < 0.9 else (0.0, 1.0, 0.0), distance_m)
        for target in targets
        for d in directions
    ]
    if reachable is not None:
        views = [v for v in views if reachable(v)]
    if not views:
        raise SimError(f"survey found no reachable view over {obj.name}")
    if 0 < count < len(views):
        keep = np.unique(np.round(np.linspace(0, len(views) - 1, count)).astype(int))
        views = [views[k] for k in keep]
    return views


@dataclass
class PrePlannedPlanner:
    """A :class:`~scrapcut_cli.cell.ViewPlanner` over a fixed list of views.

    ``observe`` ignores the frame and moves on; ``skip`` (called by the recorder when a view
    cannot be executed) moves on too.
    """

    views: Sequence[FloatArray]
    reason: str = "sweep"
    _next: int = 0

    @property
    def total(self) -> int:
        return len(self.views)

    def start(self) -> Decision:
        self._next = 0
        return self._decide()

    def observe(self, frame: Frame) -> Decision:
        return self._decide()

    def skip(self, reason: str) -> Decision:
        """The last decided view could not be executed (``reason``); go on with the next."""
        return self._decide()

    def _decide(self) -> Decision:
        if self._next >= len(self.views):
            return Decision(None, "done", stop=True, info={"views": len(self.views)})
        k = self._next
        self._next += 1
        return Decision(np.asarray(self.views[k], dtype=np.float64), self.reason, info={"view": k})
