"""What else a scrap yard puts in front of the camera: old marks near the line, other things of
paint-like colour on the floor beside the piece, and the can's own colour.

A real recording of a marked piece is not the piece alone. Next to the fresh line there is often
an old, faded mark of a previous job (same hue family, duller, partly worn, sometimes crossing
the line), and on the floor beside the piece lie crates, traffic cones and gloves in safety
colours. Perception has to find the marked line among them; the simulator puts them there
(:func:`build_scene`), seeded, so that it does not flatter the pipeline.

* **The can** (:func:`~scrapcut_cli.sim.surface.paint_can_rgb`): the preset's catalogue colour
  moved per recording, never its exact centre.
* **Old marks** (``faded_marks``): strokes of 80–160 mm on the piece's painted surface, half of
  them crossing the line at 35–90°, the others beside it (35–70 mm from it, within 20° of its
  direction), as wide as the line ±20 %, in a faded colour of the can's hue family
  (:func:`~scrapcut_cli.sim.surface.faded_rgb`), worn through in patches (20–50 %).
* **Distractors** (``box``: a 300 × 200 × 150 mm crate; ``cone``: a 300 mm traffic cone on its
  260 mm base; ``glove``: a 220 × 100 × 35 mm work glove), coloured like the paint (its hue
  ±8°, as saturated or more, a plastic's sheen), lying on the floor 40–100 mm beside the piece's
  footprint, beside the line rather than past its ends, never within 60 mm of the line. They are
  rendered with the D435i model like everything else and are obstacles for the robot.

The sizes are typical of the objects (a Euro crate's smallest size, a small road cone, a
glove); the placements are assumptions: "beside the piece, in view while it is scanned".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import cumulative_length, interpolate_polyline, nearest_distances
from scrapcut_cli.sim.mesh import TriMesh, box, merge, revolve
from scrapcut_cli.sim.objects import ScrapObject
from scrapcut_cli.sim.surface import (
    OVERSPRAY_PRESETS,
    PaintStroke,
    faded_rgb,
    hsv_to_rgb,
    paint_can_rgb,
)

FloatArray = NDArray[np.float64]

DISTRACTOR_KINDS = ("box", "cone", "glove")

#: Independent random streams of a scene (numpy Generators seeded by (seed, stream)).
_STREAM_CAN, _STREAM_FADED, _STREAM_DISTRACTORS = 101, 102, 103

#: Old marks: length, offset beside the line, angles, width and wear ranges (see module text).
_FADED_LENGTH_M = (0.08, 0.16)
_FADED_BESIDE_M = (0.035, 0.07)
_FADED_BESIDE_DEG = 20.0
_FADED_CROSS_DEG = (35.0, 90.0)
_FADED_WIDTH = (0.8, 1.2)
_FADED_WEAR = (0.2, 0.5)
#: Distractors: gap to the piece's footprint and least distance to the line.
_GAP_M = (0.04, 0.10)
_LINE_CLEARANCE_M = 0.06
_ROBOT_CLEARANCE_M = 0.35  # from the robot's base axis: not under the arm's column
_SPACING_M = 0.03  # between distractors' footprints
_ATTEMPTS = 60


@dataclass(frozen=True, eq=False)
class Distractor:
    """Something of paint-like colour lying on the floor beside the piece.

    ``mesh`` in metres, base frame; ``rgb`` its albedo (sRGB bytes); ``centre`` (3,) the middle
    of its footprint on the floor, base frame.
    """

    kind: str
    mesh: TriMesh
    rgb: tuple[int, int, int]
    centre: FloatArray

    def describe(self) -> dict[str, Any]:
        lo, hi = self.mesh.bounds
        return {
            "kind": self.kind,
            "rgb": list(self.rgb),
            "centre_m": [round(float(c), 4) for c in self.centre],
            "size_m": [round(float(c), 4) for c in hi - lo],
        }


@dataclass(frozen=True, eq=False)
class FadedMark:
    """An old mark on the piece: its stroke (faded colour, worn) and whether it crosses the
    line."""

    stroke: PaintStroke
    crosses: bool

    def describe(self) -> dict[str, Any]:
        ref = self.stroke.reference
        return {
            "crosses": self.crosses,
            "rgb": [round(float(c) * 255) for c in self.stroke.rgb],
            "width_m": round(self.stroke.width_m, 4),
            "wear": round(self.stroke.wear, 3),
            "length_m": round(float(cumulative_length(ref)[-1]), 4),
            "start_m": [round(float(c), 4) for c in ref[0]],
            "end_m": [round(float(c), 4) for c in ref[-1]],
        }


@dataclass(frozen=True, eq=False)
class YardScene:
    """The can's colour, old marks and distractors around one piece (see the module text)."""

    can_rgb: tuple[int, int, int]
    faded: tuple[FadedMark, ...] = ()
    distractors: tuple[Distractor, ...] = ()
    glints: bool = False
    notes: tuple[str, ...] = field(default_factory=tuple)

    def obstacles(self, obj: ScrapObject) -> TriMesh:
        """The piece and every distractor as one mesh (the robot's collision world)."""
        return merge([obj.mesh, *(d.mesh for d in self.distractors)])

    def describe(self) -> dict[str, Any]:
        """JSON-ready description for the recording's metadata."""
        return {
            "can_rgb": list(self.can_rgb),
            "faded_marks": [m.describe() for m in self.faded],
            "distractors": [d.describe() for d in self.distractors],
            "glints": self.glints,
            "notes": list(self.notes),
        }


def check_distractors(kinds: tuple[str, ...]) -> None:
    """SimError naming an unknown distractor kind."""
    for kind in kinds:
        if kind not in DISTRACTOR_KINDS:
            raise SimError(
                f"unknown distractor {kind!r}; distractors: {', '.join(DISTRACTOR_KINDS)}"
            )


def build_scene(
    obj: ScrapObject,
    *,
    paint_rgb: tuple[int, int, int],
    stroke_width_m: float,
    paint_variation: bool = True,
    faded_marks: int = 0,
    distractors: tuple[str, ...] = (),
    glints: bool = False,
    seed: int = 0,
) -> YardScene:
    """The scene around ``obj`` painted with a can of preset colour ``paint_rgb`` (sRGB bytes).

    Each part has its own random stream, so switching one on does not move the others.
    """
    check_distractors(distractors)
    if faded_marks < 0:
        raise SimError(f"faded marks must be >= 0, got {faded_marks}")
    can = paint_rgb
    if paint_variation:
        can = paint_can_rgb(paint_rgb, _rng(seed, _STREAM_CAN))
    notes: list[str] = []
    faded = _faded_marks(obj, faded_marks, can, stroke_width_m, seed, notes)
    placed = _distractors(obj, distractors, can, seed, notes)
    return YardScene(can, tuple(faded), tuple(placed), glints, tuple(notes))


def _rng(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, stream])


# --------------------------------------------------------------------------- old marks


def _faded_marks(
    obj: ScrapObject,
    count: int,
    can: tuple[int, int, int],
    width_m: float,
    seed: int,
    notes: list[str],
) -> list[FadedMark]:
    rng = _rng(seed, _STREAM_FADED)
    marks: list[FadedMark] = []
    for k in range(count):
        crosses = k % 2 == 0  # the first crosses the line, the next lies beside it, ...
        reference = None
        for _ in range(_ATTEMPTS):
            reference = _mark_reference(obj, crosses, width_m, rng)
            if reference is not None:
                break
        if reference is None:
            notes.append(f"old mark {k}: no place on the piece's surface found")
            continue
        marks.append(
            FadedMark(
                PaintStroke(
                    reference,
                    width_m=width_m * rng.uniform(*_FADED_WIDTH),
                    rgb=faded_rgb(can, rng),
                    overspray=OVERSPRAY_PRESETS["none"],  # weathered away
                    seed=seed + 1000 * (k + 1),
                    wear=rng.uniform(*_FADED_WEAR),
                ),
                crosses,
            )
        )
    return marks


def _mark_reference(
    obj: ScrapObject, crosses: bool, width_m: float, rng: np.random.Generator
) -> FloatArray | None:
    """An old mark's centre line on the painted surface near the line, or None if the draw
    fell off the piece (the caller draws again)."""
    ref = obj.reference
    s = cumulative_length(ref)
    at = rng.uniform(0.15, 0.85) * s[-1]
    p = interpolate_polyline(ref, [at], cumulative=s)[0]
    a, b = interpolate_polyline(ref, [at - 0.005, at + 0.005], cumulative=s)
    tangent = (b - a) / max(float(np.linalg.norm(b - a)), 1e-12)
    normal = obj.reference_normals[int(np.clip(np.searchsorted(s, at), 0, len(ref) - 1))]
    side = np.cross(normal, tangent)
    side /= max(float(np.linalg.norm(side)), 1e-12)
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if crosses:
        centre = p + rng.uniform(-0.01, 0.01) * tangent
        angle = np.radians(sign * rng.uniform(*_FADED_CROSS_DEG))
    else:
        centre = p + sign * rng.uniform(*_FADED_BESIDE_M) * side
        angle = np.radians(rng.uniform(-_FADED_BESIDE_DEG, _FADED_BESIDE_DEG))
    direction = np.cos(angle) * tangent + np.sin(angle) * side
    length = rng.uniform(*_FADED_LENGTH_M)
    t = np.arange(-0.5 * length, 0.5 * length + 1e-9, 0.0005)
    guide = centre + t[:, None] * direction
    hits = _drop_onto(obj.painted_surface, guide, normal)
    if hits is None:
        return None
    gap = nearest_distances(hits, ref)
    if not crosses and gap.min() < 0.5 * width_m * (1.0 + _FADED_WIDTH[1]) + 0.005:
        return None  # drawn beside the line, but it would touch it
    if crosses and gap.min() > 0.25 * width_m:
        return None
    return hits


def _distance_to(mesh: TriMesh, points: FloatArray) -> FloatArray:
    """Distance (N,) from points (N, 3) to the surface of ``mesh``, metres."""
    scene = _raycasting_scene(mesh)
    from scrapcut_cli._open3d import o3d as _o3d

    query = _o3d().core.Tensor(points.astype(np.float32))
    return np.asarray(scene.compute_distance(query).numpy(), dtype=np.float64)


def _raycasting_scene(mesh: TriMesh) -> Any:
    from scrapcut_cli._open3d import o3d as _o3d

    o3d = _o3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(mesh.vertices.astype(np.float32)),
        o3d.core.Tensor(mesh.faces.astype(np.uint32)),
    )
    return scene


def _drop_onto(mesh: TriMesh, guide: FloatArray, normal: FloatArray) -> FloatArray | None:
    """Guide points (K, 3) dropped onto ``mesh`` along -``normal`` (from 80 mm above); the
    longest run without a jump (> 5 mm between neighbours: the drop went over an edge), if it
    is at least 40 mm long."""
    from scrapcut_cli._open3d import o3d as _o3d

    o3d = _o3d()
    scene = _raycasting_scene(mesh)
    origins = guide + 0.08 * normal
    rays = np.column_stack([origins, np.tile(-normal, (len(guide), 1))]).astype(np.float32)
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
    ok = t < 0.16
    points = origins + np.where(ok, t, 0.0)[:, None] * (-normal)
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    joined = np.concatenate([[False], (step < 0.005) & ok[1:] & ok[:-1]])
    best, best_len = None, 0.0
    start = 0
    for k in range(1, len(points) + 1):
        if k == len(points) or not joined[k]:
            run = points[start:k]
            if ok[start] and len(run) > 1:
                length = float(cumulative_length(run)[-1])
                if length > best_len:
                    best, best_len = run, length
            start = k
    return best if best is not None and best_len >= 0.04 else None


# --------------------------------------------------------------------------- distractors


def _distractor_mesh(kind: str) -> TriMesh:
    """The distractor in its own frame: footprint centred on the origin, on the floor z = 0."""
    if kind == "box":
        return box((-0.15, -0.10, 0.0), (0.15, 0.10, 0.15))
    if kind == "cone":
        base = box((-0.13, -0.13, 0.0), (0.13, 0.13, 0.02))
        body = revolve(
            [(0.11, 0.02), (0.025, 0.30), (0.0, 0.30)], segments=48, sharp=(1,), max_step=0.02
        )
        return merge([base, body])
    if kind == "glove":
        phi = np.linspace(0.0, np.pi, 17)
        unit = revolve(np.column_stack([np.sin(phi), -np.cos(phi)]), segments=32, max_step=None)
        v = unit.vertices * np.array([0.11, 0.05, 0.0175]) + np.array([0.0, 0.0, 0.0175])
        return TriMesh(v, unit.faces)
    raise SimError(f"unknown distractor {kind!r}; distractors: {', '.join(DISTRACTOR_KINDS)}")


def _distractor_rgb(can: tuple[int, int, int], rng: np.random.Generator) -> tuple[int, int, int]:
    """Paint-like: the can's hue ±8°, as saturated or more, bright (safety-coloured plastic)."""
    import colorsys

    h, s, v = colorsys.rgb_to_hsv(*(c / 255.0 for c in can))
    rgb = hsv_to_rgb(
        360.0 * h + rng.uniform(-8.0, 8.0),
        min(1.0, s * rng.uniform(1.0, 1.1)),
        min(1.0, v * rng.uniform(0.85, 1.05)),
    )
    r, g, b = (int(c) for c in np.clip(np.rint(255.0 * rgb), 0, 255))
    return r, g, b


def _distractors(
    obj: ScrapObject,
    kinds: tuple[str, ...],
    can: tuple[int, int, int],
    seed: int,
    notes: list[str],
) -> list[Distractor]:
    rng = _rng(seed, _STREAM_DISTRACTORS)
    lo, hi = obj.mesh.bounds
    centre = 0.5 * (lo[:2] + hi[:2])
    half = 0.5 * (hi[:2] - lo[:2])
    # Beside the line: the line's main direction on the floor, and the sides across it.
    ref_xy = obj.reference[:, :2] - obj.reference[:, :2].mean(axis=0)
    _, vectors = np.linalg.eigh(ref_xy.T @ ref_xy)
    across = np.arctan2(vectors[1, 0], vectors[0, 0])  # smallest spread: across the line
    placed: list[Distractor] = []
    footprints: list[tuple[FloatArray, float]] = []
    for kind in kinds:
        local = _distractor_mesh(kind)
        l_lo, l_hi = local.bounds
        radius = float(np.hypot(*(0.5 * (l_hi[:2] - l_lo[:2]))))
        found = None
        for attempt in range(_ATTEMPTS):
            # Beside the line first; then anywhere around the piece.
            if attempt < _ATTEMPTS // 2:
                theta = across + (np.pi if rng.random() < 0.5 else 0.0) + rng.uniform(-0.5, 0.5)
            else:
                theta = rng.uniform(0.0, 2.0 * np.pi)
            u = np.array([np.cos(theta), np.sin(theta)])
            reach = float(abs(half[0] * u[0]) + abs(half[1] * u[1]))
            xy = centre + u * (reach + rng.uniform(*_GAP_M) + radius)
            yaw = rng.uniform(0.0, np.pi)
            T = np.eye(4)
            T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
            T[:2, 3] = xy
            mesh = local.transformed(T)
            if np.hypot(*xy) - radius < _ROBOT_CLEARANCE_M:
                continue
            if any(np.hypot(*(xy - c)) < radius + r + _SPACING_M for c, r in footprints):
                continue
            if _distance_to(mesh, obj.reference).min() < _LINE_CLEARANCE_M:
                continue
            found = (mesh, xy)
            break
        if found is None:
            notes.append(f"distractor {kind}: no free place beside the piece")
            continue
        mesh, xy = found
        footprints.append((xy, radius))
        placed.append(
            Distractor(kind, mesh, _distractor_rgb(can, rng), np.array([xy[0], xy[1], 0.0]))
        )
    return placed
