"""The paper's scrap pieces, built procedurally, each with its painted reference line.

Each piece is built in its own frame (x away from the robot, y to its left, z up, origin on
the floor under the piece's centre) and placed in front of the Panda by ``T_base_object``
(default 0.5 m straight ahead, the middle of the arm's comfortable reach 0.3–0.8 m). The
reference is the ground truth of Table I: an ordered polyline ON the surface, about a
millimetre between vertices, 0.3–0.6 m long.

A reference is made exactly on the surface: on flat faces it is constructed on the faces
(including the crease point where it crosses an edge, so the polyline never cuts a corner);
on curved pieces a guide curve is projected onto the mesh by ray casting (open3d
``RaycastingScene``). The basket's line is drawn on the envelope over its wires — what a worker
sprays across a wire mesh — so paint lands only where wires are.

Two pieces carry closed lines (``ScrapObject.closed``): a ring around a pipe lying on two
supports (the part under the pipe no camera can see) and a round cut-out drawn on a plate. A
closed reference does not repeat its first point; :attr:`ScrapObject.painted_line` closes it.

Sizes are typical of yard scrap (pipe DN150, IPE-300-like beam, a 260 mm air receiver) and were
chosen so every view of the sweep is reachable by the Panda without collision.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import cumulative_length, polyline_length
from scrapcut_cli.sim.mesh import (
    Hole,
    TriMesh,
    box,
    cylinder_between,
    extrude,
    frame_from_axis,
    merge,
    perforated_sheet,
    revolve,
)
from scrapcut_cli.sim.surface import MetalFinish

FloatArray = NDArray[np.float64]

#: Default placement of every piece: 0.5 m in front of the robot base, on the floor.
DEFAULT_PLACEMENT = (0.5, 0.0, 0.0)


@dataclass(frozen=True, eq=False)
class ScrapObject:
    """A scrap piece placed in the robot cell.

    Attributes
    ----------
    name, description : str
        Catalogue name and a one-line description.
    vertices : (V, 3) float64
        Mesh vertices, metres, base frame (``panda_link0``).
    faces : (F, 3) int64
        Triangles, counter-clockwise seen from outside.
    reference : (N, 3) float64
        The painted line's centre, ordered, on the surface, metres, base frame.
    reference_normals : (N, 3) float64
        Unit outward normals of the painted surface at the reference vertices (for the basket,
        of the envelope the line was sprayed across), base frame.
    material : MetalFinish
        Steel tone and rust coverage.
    T_base_object : (4, 4) float64
        Placement of the piece's own frame in the base frame.
    seed : int
        Seeds the piece's rust pattern (the geometry is fixed).
    closed : bool
        The line is a loop: ``reference`` runs once around it and does not repeat its first
        point (the last point joins the first).
    painted : TriMesh or None
        The surface the line was sprayed across when it is not the mesh (the basket's
        envelope over its wires), base frame; other marks are sprayed across it too.
    """

    name: str
    description: str
    vertices: FloatArray
    faces: NDArray[np.int64]
    reference: FloatArray
    reference_normals: FloatArray
    material: MetalFinish
    T_base_object: FloatArray
    seed: int = 0
    closed: bool = False
    painted: TriMesh | None = None

    @property
    def mesh(self) -> TriMesh:
        return TriMesh(self.vertices, self.faces)

    @property
    def painted_line(self) -> FloatArray:
        """The reference as a polyline to paint along (N, 3) or (N + 1, 3): a closed line
        with its first point repeated at the end."""
        if self.closed:
            return np.asarray(np.vstack([self.reference, self.reference[:1]]))
        return self.reference

    @property
    def painted_surface(self) -> TriMesh:
        """The surface paint is sprayed across: ``painted``, else the mesh."""
        return self.painted if self.painted is not None else self.mesh

    @property
    def reference_length_m(self) -> float:
        """Length of the line, the closing segment of a loop included."""
        return polyline_length(self.painted_line)

    @property
    def centre(self) -> FloatArray:
        """Centre (3,) of the mesh's bounding box, base frame."""
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        return np.asarray(0.5 * (lo + hi))


@dataclass(frozen=True)
class _Built:
    mesh: TriMesh
    reference: FloatArray
    material: MetalFinish
    painted_surface: TriMesh | None = None  # where the line was drawn, if not the mesh
    closed: bool = False  # the reference is a loop (its last point joins its first)


_STEEL = MetalFinish()


# --------------------------------------------------------------------------- helpers


def _scene(mesh: TriMesh) -> tuple[Any, Any]:
    """(open3d module, RaycastingScene of ``mesh``)."""
    from scrapcut_cli._open3d import o3d as _o3d

    o3d = _o3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(mesh.vertices.astype(np.float32)),
        o3d.core.Tensor(mesh.faces.astype(np.uint32)),
    )
    return o3d, scene


def surface_normals(mesh: TriMesh, points: ArrayLike) -> FloatArray:
    """Outward unit normals (N, 3) of the triangles nearest to ``points`` (N, 3)."""
    o3d, scene = _scene(mesh)
    p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    normals = scene.compute_closest_points(o3d.core.Tensor(p))["primitive_normals"].numpy()
    normals = normals.astype(np.float64)
    return np.asarray(normals / np.linalg.norm(normals, axis=1, keepdims=True))


def _project(mesh: TriMesh, origins: ArrayLike, directions: ArrayLike, what: str) -> FloatArray:
    """First hits (N, 3) of rays from ``origins`` along ``directions`` on ``mesh``."""
    o3d, scene = _scene(mesh)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    # Cast from near the surface: float32 keeps ~0.05 µm resolution there.
    rays = np.concatenate([o, d], axis=1).astype(np.float32)
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
    if not np.all(np.isfinite(t)):
        raise SimError(
            f"{what}: the guide curve misses the mesh at {int((~np.isfinite(t)).sum())} points"
        )
    return np.asarray(o + t[:, None] * d)


def _polyline(*points: ArrayLike, spacing: float = 0.0005) -> FloatArray:
    """Straight segments through ``points`` (3,), sampled every ``spacing`` metres, corners kept."""
    pts = [np.asarray(p, dtype=np.float64) for p in points]
    out = [pts[0][None, :]]
    for a, b in itertools.pairwise(pts):
        n = max(int(np.ceil(np.linalg.norm(b - a) / spacing)), 1)
        t = np.linspace(0.0, 1.0, n + 1)[1:, None]
        out.append(a + t * (b - a))
    return np.concatenate(out)


def _samples(length_hint_m: float, spacing: float = 0.0005) -> FloatArray:
    """Parameters t in [0, 1] for about one sample per ``spacing`` metres of curve."""
    return np.linspace(0.0, 1.0, max(int(length_hint_m / spacing), 2) + 1)


def _tube(outer: float, wall: float, length: float, *, segments: int) -> TriMesh:
    """Pipe along local z from -length/2 to +length/2, with end rings."""
    inner = outer - wall
    h = 0.5 * length
    profile = [(outer, -h), (outer, h), (inner, h), (inner, -h), (outer, -h)]
    return revolve(profile, segments=segments, sharp=(1, 2, 3))


# --------------------------------------------------------------------------- the pieces


def _cylinder() -> _Built:
    """DN150-like pipe (outer radius 80 mm, 6 mm wall, 400 mm long) lying along x."""
    radius, wall, length = 0.08, 0.006, 0.40
    pipe = _tube(radius, wall, length, segments=128).transformed(
        frame_from_axis((0.0, 0.0, radius), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    )
    # A helix-like line over the top: 0.32 m along the axis while turning 110 degrees.
    t = _samples(0.36)
    x = -0.16 + 0.32 * t
    phi = np.radians(-55.0 + 110.0 * t + 8.0 * np.sin(2.0 * np.pi * t))
    radial = np.column_stack([np.zeros_like(t), np.sin(phi), np.cos(phi)])
    axis_points = np.column_stack([x, np.zeros_like(t), np.full_like(t, radius)])
    reference = _project(pipe, axis_points + 0.12 * radial, -radial, "cylinder")
    return _Built(pipe, reference, _STEEL)


def _i_beam() -> _Built:
    """IPE-300-like beam (300 mm deep, 150 mm flanges, 500 mm long) lying on its flange edges.

    The web is horizontal, so from above the beam is a channel; the line runs down one
    flange's inner face, across the web and up the other flange: two ~90 degree turns.
    """
    length, depth, flange_w, tf, tw = 0.50, 0.30, 0.15, 0.015, 0.010
    h = 0.5 * length
    y_in = 0.5 * depth - tf
    web_z = 0.5 * flange_w
    mesh = merge(
        [
            box((-h, -0.5 * depth, 0.0), (h, -y_in, flange_w)),
            box((-h, y_in, 0.0), (h, 0.5 * depth, flange_w)),
            box((-h, -y_in - 0.001, web_z - 0.5 * tw), (h, y_in + 0.001, web_z + 0.5 * tw)),
        ]
    )
    top = web_z + 0.5 * tw
    reference = _polyline(
        (-0.08, -y_in, 0.14),
        (-0.06, -y_in, top),
        (0.06, y_in, top),
        (0.08, y_in, 0.14),
    )
    return _Built(mesh, reference, MetalFinish(rust_fraction=0.45))


def _t_piece() -> _Built:
    """Pipe T-junction lying flat: a 140 mm main pipe along x, a 100 mm branch along +y.

    The line comes along the branch's crown, climbs over the saddle where the pipes meet and
    runs over the main pipe's crown down its -y side.
    """
    main_r, branch_r, wall = 0.07, 0.05, 0.005
    axis_z = main_r
    main = _tube(main_r, wall, 0.44, segments=128).transformed(
        frame_from_axis((0.0, 0.0, axis_z), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    )
    branch_start = float(np.sqrt((main_r - wall) ** 2 - branch_r**2))
    branch_len = 0.30 - branch_start
    branch = _tube(branch_r, wall, branch_len, segments=96).transformed(
        frame_from_axis(
            (0.0, branch_start + 0.5 * branch_len, axis_z), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0)
        )
    )
    mesh = merge([main, branch])
    t = _samples(0.40)
    y = 0.26 - (0.26 + main_r * np.sin(np.radians(45.0))) * t
    x = 0.015 * np.sin(1.5 * np.pi * t)
    top = np.column_stack([x, y, np.full_like(t, 0.5)])
    reference = _project(mesh, top, np.tile([0.0, 0.0, -1.0], (len(t), 1)), "t_piece")
    return _Built(mesh, reference, MetalFinish(rust_fraction=0.30))


def _basket() -> _Built:
    """An upturned wire-mesh basket (300 × 400 × 150 mm, 4 mm wires at 40 mm pitch).

    A 40 mm mesh (common for scrap and storage cages) leaves gaps of 15–36 mm along the line:
    at the paper's 5 mm leaf the skeleton falls apart, at 20 mm it bridges them, as in the paper.

    The line is sprayed across the wire grid: up the -y side and over the top in an S. Paint
    lands only on wires, so the painted line has gaps (the paper's skeletonisation broke here
    at a 5 mm leaf size).
    """
    sx, sy, sz = 0.15, 0.20, 0.15  # half sizes in x, y; height
    r = 0.002
    pitch = 0.040
    wires: list[TriMesh] = []
    xs = np.arange(-sx, sx + 1e-9, pitch)
    ys = np.arange(-sy, sy + 1e-9, pitch)
    zs = np.arange(pitch, sz - 0.5 * pitch, pitch)
    for y in ys:  # top, lower layer: wires along x
        wires.append(cylinder_between((-sx, y, sz - 3 * r), (sx, y, sz - 3 * r), r))
    for x in xs:  # top, upper layer: wires along y, their tops on the envelope
        wires.append(cylinder_between((x, -sy, sz - r), (x, sy, sz - r), r))
    for sign in (-1.0, 1.0):
        for y in ys:  # x = ±sx walls: vertical wires outside, horizontal inside
            wires.append(cylinder_between((sign * (sx - r), y, 0.0), (sign * (sx - r), y, sz), r))
        for z in zs:
            wires.append(
                cylinder_between((sign * (sx - 3 * r), -sy, z), (sign * (sx - 3 * r), sy, z), r)
            )
        for x in xs:  # y = ±sy walls
            wires.append(cylinder_between((x, sign * (sy - r), 0.0), (x, sign * (sy - r), sz), r))
        for z in zs:
            wires.append(
                cylinder_between((-sx, sign * (sy - 3 * r), z), (sx, sign * (sy - 3 * r), z), r)
            )
    mesh = merge(wires)
    # The line on the envelope: up the -y side, over the edge, an S across the top.
    side = _polyline((-0.06, -sy, 0.05), (-0.05, -sy, sz))
    t = _samples(0.45)[1:]
    y = -sy + 0.36 * t
    x = -0.05 + 0.11 * t + 0.05 * np.sin(2.0 * np.pi * t)
    across = np.column_stack([x, y, np.full_like(t, sz)])
    reference = np.concatenate([side, across])
    envelope = box((-sx, -sy, 0.0), (sx, sy, sz))
    return _Built(
        mesh,
        reference,
        MetalFinish(steel_hsv=(200.0, 0.03, 0.62), rust_fraction=0.15),
        painted_surface=envelope,
    )


def _perforated_plate() -> _Built:
    """A perforated steel plate (440 × 320 × 3 mm) on two rails, 125 mm above the floor.

    Punched in a 40 mm grid: slots 14 × 30 mm in the half nearer the robot's left (rows
    alternately across and along x), a plain 40 mm strip in the middle, round holes of 24
    and 14 mm in the other half. The line sweeps across it in an S, so holes cross the
    stroke at every lateral offset: some take one edge, some its middle, the wide ones all of
    it. Through a hole the camera sees the floor 125 mm below (a depth jump with flying pixels
    at the hole's rim); the line is drawn on the plate's plane, over the holes too.
    """
    sx, sy, cell, thickness, height = 0.44, 0.32, 0.04, 0.003, 0.125
    holes: list[Hole] = []
    for i in range(round(sx / cell)):
        for j in range(round(sy / cell)):
            centre = (-0.5 * sx + (i + 0.5) * cell, -0.5 * sy + (j + 0.5) * cell)
            if i < 5:
                size = (0.014, 0.030) if j % 2 == 0 else (0.030, 0.014)
                holes.append(Hole(centre, "rect", size))
            elif i > 5:
                d = 0.024 if (i + j) % 2 == 0 else 0.014
                holes.append(Hole(centre, "round", (d, d)))
    sheet = perforated_sheet((sx, sy), cell, holes, thickness=thickness).transformed(
        frame_from_axis((0.0, 0.0, height), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0))
    )
    rails = [
        box((-0.5 * sx + 0.01, y - 0.012, 0.0), (0.5 * sx - 0.01, y + 0.012, height - thickness))
        for y in (-0.5 * sy + 0.012, 0.5 * sy - 0.012)
    ]
    t = _samples(0.42)[1:]
    x = -0.19 + 0.38 * t
    y = -0.005 + 0.075 * (2.0 * t - 1.0) + 0.03 * np.sin(2.0 * np.pi * t)
    reference = np.column_stack([x, y, np.full_like(t, height)])
    return _Built(
        merge([sheet, *rails]),
        reference,
        MetalFinish(rust_fraction=0.30),
        painted_surface=box(
            (-0.5 * sx, -0.5 * sy, height - thickness), (0.5 * sx, 0.5 * sy, height)
        ),
    )


def _air_chamber() -> _Built:
    """A 260 mm air receiver lying along y with dished ends and a sharp V groove near one end.

    The line runs along the crown, dips through the 12 mm deep groove (a sharp curvature
    change) and ends on the dished head.
    """
    radius, half_body, head = 0.13, 0.18, 0.06
    groove_at, groove_half_w, groove_depth = 0.13, 0.010, 0.012
    a = np.linspace(0.0, np.pi / 2, 24)
    head_lo = np.column_stack([radius * np.sin(a), -half_body - head * np.cos(a)])
    head_hi = np.column_stack([radius * np.cos(a), half_body + head * np.sin(a)])
    groove = [
        [radius, groove_at - groove_half_w],
        [radius - groove_depth, groove_at],
        [radius, groove_at + groove_half_w],
    ]
    profile = np.concatenate([head_lo, groove, head_hi])
    k = len(head_lo)
    sharp = (k, k + 1, k + 2)  # the groove's lips and root; the heads meet the shell tangentially
    mesh = revolve(profile, segments=160, sharp=sharp).transformed(
        frame_from_axis((0.0, 0.0, radius), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))
    )
    t = _samples(0.40)
    y = -0.14 + 0.345 * t
    phi = np.radians(14.0 * np.sin(1.5 * np.pi * t))  # from the crown towards -x
    radial = np.column_stack([-np.sin(phi), np.zeros_like(t), np.cos(phi)])
    axis_points = np.column_stack([np.zeros_like(t), y, np.full_like(t, radius)])
    reference = _project(mesh, axis_points + 0.2 * radial, -radial, "air_chamber")
    return _Built(mesh, reference, MetalFinish(rust_fraction=0.55, rust_scale_m=0.07))


def _slanted() -> _Built:
    """Two faces meeting at a sharp 57 degree ridge (a 240 mm wide, 220 mm high roof prism).

    The line climbs one face, crosses the ridge and runs down the other: from a view normal
    to one face the other is hidden (the paper's real-robot failure).
    """
    half_w, height, half_len = 0.12, 0.22, 0.12
    mesh = extrude([(-half_w, 0.0), (half_w, 0.0), (0.0, height)], -half_len, half_len)
    t = _samples(0.25)

    def on_face(sign: float, z: FloatArray, x: FloatArray) -> FloatArray:
        return np.column_stack([x, sign * half_w * (1.0 - z / height), z])

    z_up = 0.04 + (height - 0.04) * t
    x_up = -0.05 + 0.05 * t + 0.01 * np.sin(np.pi * t)
    up = on_face(-1.0, z_up, x_up)
    down = on_face(1.0, z_up[::-1], 0.05 * t - 0.01 * np.sin(np.pi * t))[1:]
    reference = np.concatenate([up, down])
    return _Built(mesh, reference, MetalFinish(rust_fraction=0.25))


def _planar_box() -> _Built:
    """A closed box (200 × 300 × 150 mm); the line crosses the top and runs down the -y face."""
    hx, hy, hz = 0.10, 0.15, 0.15
    mesh = box((-hx, -hy, 0.0), (hx, hy, hz))
    t = _samples(0.30)
    y = 0.11 - (0.11 + hy) * t
    x = 0.05 - 0.08 * t + 0.02 * np.sin(np.pi * t)
    across = np.column_stack([x, y, np.full_like(t, hz)])
    edge = across[-1]
    down = _polyline(edge, (edge[0] - 0.02, -hy, 0.03))[1:]
    reference = np.concatenate([across, down])
    return _Built(mesh, reference, MetalFinish(rust_fraction=0.20))


def _pipe_ring() -> _Built:
    """A DN150-like pipe (outer radius 80 mm, 6 mm wall, 500 mm long) lying along x on two
    sleepers 40 mm high, with a ring painted all the way round it between them: the cut that
    divides a pipe into sections. The quarter or so of the ring under the pipe faces the floor
    from 40 mm up; no camera on the arm sees it.

    The ring is drawn by hand: it wanders along the pipe by a few millimetres as it goes round.
    It starts at the top and runs towards -y (down the side nearer the robot's right).
    """
    radius, wall, length = 0.08, 0.006, 0.50
    lift, sleeper_x, sleeper_half = 0.04, 0.20, (0.04, 0.09)
    axis_z = lift + radius
    pipe = _tube(radius, wall, length, segments=128).transformed(
        frame_from_axis((0.0, 0.0, axis_z), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    )
    sleepers = [
        box(
            (x - sleeper_half[0], -sleeper_half[1], 0.0),
            (x + sleeper_half[0], sleeper_half[1], lift),
        )
        for x in (-sleeper_x, sleeper_x)
    ]
    mesh = merge([pipe, *sleepers])
    theta = 2.0 * np.pi * _samples(2.0 * np.pi * radius)[:-1]  # the loop, once round
    x = 0.004 * np.sin(theta) + 0.003 * np.sin(2.0 * theta + 0.7)
    radial = np.column_stack([np.zeros_like(theta), -np.sin(theta), np.cos(theta)])
    axis_points = np.column_stack([x, np.zeros_like(theta), np.full_like(theta, axis_z)])
    reference = _project(pipe, axis_points + 0.12 * radial, -radial, "pipe_ring")
    return _Built(mesh, reference, MetalFinish(rust_fraction=0.35), closed=True)


def _plate_hole() -> _Built:
    """A 12 mm plate (420 x 320 mm) resting on two flat bars of different heights (a 7 degree
    slope down towards the robot), with a round cut-out (about 150 mm across) drawn on it by
    hand: its radius wanders by a couple of millimetres. The line starts on the side nearest
    the robot and runs counter-clockwise seen from above.
    """
    half_x, half_y, thick = 0.21, 0.16, 0.012
    low, high, bar_x = 0.03, 0.07, 0.17
    slope = np.arctan2(high - low, 2.0 * bar_x)
    centre_z = 0.5 * (low + high)
    plate = box((-half_x, -half_y, 0.0), (half_x, half_y, thick))
    c, s = np.cos(slope), np.sin(slope)
    T = np.eye(4)
    T[:3, :3] = [[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]  # +x end up
    T[:3, 3] = (0.0, 0.0, centre_z)
    bars = [
        box((x - 0.015, -half_y, 0.0), (x + 0.015, half_y, z - 0.002))
        for x, z in ((-bar_x, low), (bar_x, high))
    ]
    mesh = merge([plate.transformed(T), *bars])
    theta = 2.0 * np.pi * _samples(2.0 * np.pi * 0.075)[:-1]
    r = 0.075 + 0.0015 * np.sin(3.0 * theta + 0.4) + 0.001 * np.sin(5.0 * theta)
    local = np.column_stack(
        [0.02 - r * np.cos(theta), -r * np.sin(theta), np.full_like(theta, thick + 0.05)]
    )
    above = local @ T[:3, :3].T + T[:3, 3]
    down = np.tile(-T[:3, 2], (len(theta), 1))
    reference = _project(mesh, above, down, "plate_hole")
    return _Built(mesh, reference, MetalFinish(rust_fraction=0.25), closed=True)


_CATALOGUE: dict[str, tuple[str, Callable[[], _Built]]] = {
    "cylinder": ("pipe, 160 mm; the line winds over it (the paper's simple case)", _cylinder),
    "i_beam": ("I-beam on its side; flange -> web -> flange, two ~90 degree turns", _i_beam),
    "t_piece": ("pipe T-junction; the line crosses the saddle where the pipes meet", _t_piece),
    "basket": ("wire-mesh basket; paint only on the wires, so the line has gaps", _basket),
    "air_chamber": (
        "tank with a sharp groove near one end; the line dips through it",
        _air_chamber,
    ),
    "perforated_plate": (
        "perforated plate on rails; slots and round holes cross the stroke",
        _perforated_plate,
    ),
    "slanted": ("two faces at a sharp ridge; the line crosses it (self-occlusion)", _slanted),
    "planar_box": ("box; the line crosses the top and turns down a side face", _planar_box),
    "pipe_ring": (
        "pipe on two sleepers; a ring painted all round it (closed; the underside unseen)",
        _pipe_ring,
    ),
    "plate_hole": ("sloping plate; a round cut-out drawn on it (closed)", _plate_hole),
}


#: Where along its line (0-1) explore mode starts, i.e. where the worker points the robot. The
#: middle, except on the slanted piece: its middle is the ridge, where both faces are in view;
#: starting on one face is the paper's real-robot case, where exploration stopped at the edge.
#: A ring around a pipe is started at its top (its reference starts there), a cut-out on its
#: side nearest the robot.
EXPLORE_START_FRACTION: dict[str, float] = {"slanted": 0.2, "pipe_ring": 0.0, "plate_hole": 0.0}


def explore_start_fraction(name: str) -> float:
    """Default start of explore mode on piece ``name``, as a fraction of its line's length."""
    return EXPLORE_START_FRACTION.get(name, 0.5)


def list_objects() -> list[tuple[str, str]]:
    """(name, one-line description) of every simulated scrap piece, in catalogue order."""
    return [(name, entry[0]) for name, entry in _CATALOGUE.items()]


def make_object(name: str, *, seed: int = 0, placement: ArrayLike | None = None) -> ScrapObject:
    """Build the scrap piece ``name`` placed in the robot's base frame.

    ``placement`` is (x, y, yaw_deg) of the piece's frame on the floor; default
    :data:`DEFAULT_PLACEMENT`. ``seed`` only changes the rust pattern; geometry and reference
    are fixed so results are comparable across seeds.
    """
    entry = _CATALOGUE.get(name)
    if entry is None:
        raise SimError(f"unknown object {name!r}; objects: {', '.join(_CATALOGUE)}")
    description, builder = entry
    x, y, yaw_deg = DEFAULT_PLACEMENT if placement is None else np.asarray(placement, dtype=float)
    yaw = np.radians(float(yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    T[:2, 3] = (float(x), float(y))
    built = builder()
    mesh = built.mesh.transformed(T)
    reference = built.reference @ T[:3, :3].T + T[:3, 3]
    # Drop repeated vertices (a projected guide can land twice on the same spot), and a loop's
    # last point if it lands on its first.
    keep = np.concatenate([[True], np.diff(cumulative_length(reference)) > 1e-9])
    reference = reference[keep]
    if built.closed and np.linalg.norm(reference[-1] - reference[0]) <= 1e-9:
        reference = reference[:-1]
    painted = built.painted_surface.transformed(T) if built.painted_surface else mesh
    return ScrapObject(
        name=name,
        description=description,
        vertices=mesh.vertices,
        faces=mesh.faces,
        reference=reference,
        reference_normals=surface_normals(painted, reference),
        material=built.material,
        T_base_object=T,
        seed=int(seed),
        closed=built.closed,
        painted=painted if built.painted_surface is not None else None,
    )
