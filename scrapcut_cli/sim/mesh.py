"""Triangle meshes for the procedural scrap pieces: boxes, prisms, surfaces of revolution, wires.

Every builder returns a :class:`TriMesh` in metres. Vertices are duplicated along creases (box
edges, the corners of a revolved profile), so area-weighted vertex normals are smooth across
curved surfaces and sharp across edges — the ray caster interpolates them for shading and for
the grazing-angle test of the depth model. Triangles are wound counter-clockwise seen from
outside (normals point out).

Written by hand because open3d's primitives (``create_box``, ``create_cylinder``) share vertices
across creases and cannot revolve an arbitrary profile; the builders are a few lines each.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.geometry import orthonormal_frame

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class TriMesh:
    """A triangle mesh: ``vertices`` (V, 3) float64 metres, ``faces`` (F, 3) int64 indices."""

    vertices: FloatArray
    faces: IndexArray

    def __post_init__(self) -> None:
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices must be (V, 3), got {self.vertices.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise ValueError(f"faces must be (F, 3), got {self.faces.shape}")
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= len(self.vertices)):
            raise ValueError("face index out of range")

    @property
    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Axis-aligned (min (3,), max (3,)) corners in metres."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def face_normals(self) -> FloatArray:
        """Unit outward normals (F, 3)."""
        v = self.vertices[self.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.asarray(n / np.where(length > 0, length, 1.0))

    def vertex_normals(self) -> FloatArray:
        """Area-weighted unit vertex normals (V, 3); smooth where vertices are shared."""
        v = self.vertices[self.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])  # length = 2 × area
        acc = np.zeros_like(self.vertices)
        for k in range(3):
            np.add.at(acc, self.faces[:, k], n)
        length = np.linalg.norm(acc, axis=1, keepdims=True)
        return np.asarray(acc / np.where(length > 0, length, 1.0))

    def area(self) -> float:
        """Total surface area in square metres."""
        v = self.vertices[self.faces]
        return float(
            0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum()
        )

    def transformed(self, T: ArrayLike) -> TriMesh:
        """The mesh moved by a rigid transform ``T`` (4, 4)."""
        T = np.asarray(T, dtype=np.float64)
        return TriMesh(self.vertices @ T[:3, :3].T + T[:3, 3], self.faces.copy())


def merge(meshes: Sequence[TriMesh]) -> TriMesh:
    """One mesh holding all triangles of ``meshes`` (vertices are not welded)."""
    if not meshes:
        raise ValueError("nothing to merge")
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    vertices = np.concatenate([m.vertices for m in meshes])
    faces = np.concatenate([m.faces + off for m, off in zip(meshes, offsets, strict=True)])
    return TriMesh(vertices, faces)


def box(lower: ArrayLike, upper: ArrayLike) -> TriMesh:
    """Axis-aligned box between corners ``lower`` and ``upper`` (3,), own vertices per face."""
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    if np.any(hi <= lo):
        raise ValueError(f"box corners must satisfy lower < upper, got {lo} and {hi}")
    corners = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
    # Corner index bits: 1 = x, 2 = y, 4 = z. Each face's four corners in cyclic order.
    quads = np.array(
        [[0, 2, 6, 4], [1, 3, 7, 5], [0, 1, 5, 4], [2, 3, 7, 6], [0, 1, 3, 2], [4, 5, 7, 6]]
    )
    vertices = corners[quads.reshape(-1)]
    base = 4 * np.arange(6)[:, None]
    faces = np.concatenate([base + np.array([0, 1, 2]), base + np.array([0, 2, 3])]).astype(
        np.int64
    )
    # Wind every triangle outwards (normal along centroid minus box centre).
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = np.einsum("ij,ij->i", normal, tri.mean(axis=1) - 0.5 * (lo + hi)) > 0
    faces[~outward] = faces[~outward][:, [0, 2, 1]]
    return TriMesh(vertices, faces)


def extrude(polygon_yz: ArrayLike, x_min: float, x_max: float) -> TriMesh:
    """Prism along x over a convex counter-clockwise polygon (K, 2) in the (y, z) plane."""
    poly = np.asarray(polygon_yz, dtype=np.float64)
    k = len(poly)
    if k < 3:
        raise ValueError("a polygon needs at least three corners")
    edge = np.roll(poly, -1, axis=0) - poly
    if np.any(
        edge[:, 0] * np.roll(edge, -1, axis=0)[:, 1] - edge[:, 1] * np.roll(edge, -1, axis=0)[:, 0]
        <= 0
    ):
        raise ValueError("extrude needs a convex polygon in counter-clockwise order")
    parts = []
    for i in range(k):  # one quad per side, own vertices so the edges stay sharp
        a, b = poly[i], poly[(i + 1) % k]
        v = np.array(
            [[x_min, *a], [x_min, *b], [x_max, *b], [x_max, *a]],
        )
        parts.append(TriMesh(v, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)))
    fan = np.array([[0, i + 1, i] for i in range(1, k - 1)], dtype=np.int64)
    cap_lo = np.column_stack([np.full(k, x_min), poly])
    cap_hi = np.column_stack([np.full(k, x_max), poly])
    parts.append(TriMesh(cap_lo, fan))  # seen from -x the polygon runs clockwise
    parts.append(TriMesh(cap_hi, fan[:, [0, 2, 1]]))
    return merge(parts)


def revolve(
    profile: ArrayLike,
    *,
    segments: int = 96,
    sharp: Sequence[int] = (),
    max_step: float | None = 0.01,
) -> TriMesh:
    """Surface of revolution about the local z axis.

    ``profile`` (K, 2) lists (radius, z) in metres along the generating curve; a closed solid
    starts and ends on the axis (radius 0). The curve must run so that the outside is on its
    right when walking with increasing index in the (r, z) half plane (e.g. up the outside of a
    tube from the bottom). Profile points listed in ``sharp`` get duplicated vertices, so
    shading and normals break there (a groove's lip, a tube's end ring). Profile segments
    longer than ``max_step`` metres are split, so a long pipe is not made of sliver triangles
    (closest-point queries lose precision on those).
    """
    prof = np.asarray(profile, dtype=np.float64)
    if prof.ndim != 2 or prof.shape[1] != 2 or len(prof) < 2:
        raise ValueError("profile must be (K, 2) with K >= 2")
    if np.any(prof[:, 0] < 0):
        raise ValueError("profile radii must be >= 0")
    if max_step is not None:
        prof, sharp = _subdivide(prof, tuple(sharp), max_step)
    # Split the profile at sharp points into smooth runs that each own their vertices.
    cuts = sorted({int(i) for i in sharp if 0 < int(i) < len(prof) - 1})
    runs = []
    start = 0
    for c in [*cuts, len(prof) - 1]:
        runs.append(prof[start : c + 1])
        start = c
    angles = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    cos, sin = np.cos(angles), np.sin(angles)
    parts = []
    for run in runs:
        r, z = run[:, 0], run[:, 1]
        vertices = np.stack(
            [
                r[:, None] * cos[None, :],
                r[:, None] * sin[None, :],
                np.repeat(z[:, None], segments, 1),
            ],
            axis=-1,
        ).reshape(-1, 3)
        i = np.arange(len(run) - 1)[:, None]
        j = np.arange(segments)[None, :]
        jn = (j + 1) % segments
        v00 = i * segments + j
        v01 = i * segments + jn
        v11 = (i + 1) * segments + jn
        v10 = (i + 1) * segments + j
        faces = np.concatenate(
            [
                np.stack([v00, v01, v11], -1).reshape(-1, 3),
                np.stack([v00, v11, v10], -1).reshape(-1, 3),
            ]
        )
        # Drop triangles that collapsed on the axis (two corners at radius 0).
        v = vertices[faces]
        area = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
        parts.append(TriMesh(vertices, faces[area > 1e-14].astype(np.int64)))
    return merge(parts)


def _subdivide(
    profile: FloatArray, sharp: tuple[int, ...], max_step: float
) -> tuple[FloatArray, tuple[int, ...]]:
    """Split profile segments longer than ``max_step``; sharp indices follow their points."""
    out = [profile[:1]]
    new_index = [0]
    for a, b in itertools.pairwise(profile):
        n = max(int(np.ceil(np.linalg.norm(b - a) / max_step)), 1)
        t = np.linspace(0.0, 1.0, n + 1)[1:, None]
        out.append(a + t * (b - a))
        new_index.append(new_index[-1] + n)
    return np.concatenate(out), tuple(new_index[i] for i in sharp if 0 <= i < len(new_index))


def cylinder_between(
    p0: ArrayLike, p1: ArrayLike, radius: float, *, segments: int = 8, capped: bool = True
) -> TriMesh:
    """A round bar (wire, rod) from ``p0`` to ``p1`` (3,) with ``radius`` metres."""
    a = np.asarray(p0, dtype=np.float64)
    b = np.asarray(p1, dtype=np.float64)
    axis = b - a
    length = float(np.linalg.norm(axis))
    if length <= 0:
        raise ValueError("cylinder_between needs two distinct end points")
    profile = [(0.0, 0.0), (radius, 0.0), (radius, length), (0.0, length)]
    if not capped:
        profile = profile[1:3]
    mesh = revolve(profile, segments=segments, sharp=(1, 2) if capped else (), max_step=None)
    R = orthonormal_frame(axis, (1.0, 0.0, 0.0))
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = a
    return mesh.transformed(T)


def frame_from_axis(origin: ArrayLike, z_axis: ArrayLike, x_hint: ArrayLike) -> FloatArray:
    """(4, 4) placement whose local z is ``z_axis`` and local x is near ``x_hint``."""
    T = np.eye(4)
    T[:3, :3] = orthonormal_frame(z_axis, x_hint)
    T[:3, 3] = np.asarray(origin, dtype=np.float64)
    return T


def floor_mesh(size_m: float = 6.0, *, z: float = 0.0) -> TriMesh:
    """A square floor of side ``size_m`` at height ``z``, centred under the robot, facing up."""
    h = 0.5 * size_m
    vertices = np.array([[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]])
    return TriMesh(vertices, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64))


# --------------------------------------------------------------------------- perforated sheet


@dataclass(frozen=True)
class Hole:
    """A convex hole through a sheet, centred at ``centre`` (x, y) metres of the sheet's plane.

    ``shape`` is ``"round"`` (diameter ``size[0]``) or ``"rect"`` (``size`` = (along x,
    along y)), rotated by ``angle_rad`` about its centre (rectangles only).
    """

    centre: tuple[float, float]
    shape: str
    size: tuple[float, float]
    angle_rad: float = 0.0

    def outline(self, max_step: float) -> FloatArray:
        """The hole's boundary (K, 2), counter-clockwise, vertices at most ``max_step`` apart;
        a rectangle keeps its corners exactly."""
        c = np.asarray(self.centre, dtype=np.float64)
        if self.shape == "round":
            r = 0.5 * self.size[0]
            k = max(int(np.ceil(2.0 * np.pi * r / max_step)), 12)
            a = np.linspace(0.0, 2.0 * np.pi, k, endpoint=False)
            return np.asarray(c + r * np.column_stack([np.cos(a), np.sin(a)]))
        if self.shape != "rect":
            raise ValueError(f"unknown hole shape {self.shape!r}; known: round, rect")
        hx, hy = 0.5 * self.size[0], 0.5 * self.size[1]
        corners = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
        # Start at the middle of the +x side so the outline runs counter-clockwise from angle 0.
        pts = [np.array([[hx, 0.0]])]
        for a, b in itertools.pairwise([np.array([hx, 0.0]), *corners, np.array([hx, 0.0])]):
            n = max(int(np.ceil(np.linalg.norm(b - a) / max_step)), 1)
            t = np.linspace(0.0, 1.0, n + 1)[1:, None]
            pts.append(a + t * (b - a))
        local = np.concatenate(pts)[:-1]
        cs, sn = np.cos(self.angle_rad), np.sin(self.angle_rad)
        return np.asarray(c + local @ np.array([[cs, sn], [-sn, cs]]))


def perforated_sheet(
    size: tuple[float, float],
    cell: float,
    holes: Sequence[Hole],
    *,
    thickness: float,
    max_step: float = 0.001,
) -> TriMesh:
    """A flat sheet with convex holes: top at z = 0, bottom at z = -``thickness``.

    The sheet spans x in [-size[0]/2, size[0]/2] and y likewise, split into square cells of side
    ``cell`` (which must divide both sides); each cell holds at most one hole, strictly inside
    it. A cell's top face is the ring between its boundary (sampled every ``max_step``, the
    same vertices as its neighbours': no T-junctions, so the ray caster sees no cracks) and
    its hole, triangulated by walking both outlines in order of angle about the hole's centre.
    Hole and sheet walls are quads with their own vertices (sharp edges). Raises ValueError
    when a hole does not fit its cell or the triangulation would fold.
    """
    sx, sy = size
    nx, ny = round(sx / cell), round(sy / cell)
    if nx < 1 or ny < 1 or abs(nx * cell - sx) > 1e-9 or abs(ny * cell - sy) > 1e-9:
        raise ValueError(f"cell {cell} m must divide the sheet {sx} x {sy} m")
    per_side = max(int(np.ceil(cell / max_step)), 1)
    x0, y0 = -0.5 * sx, -0.5 * sy
    by_cell: dict[tuple[int, int], Hole] = {}
    for hole in holes:
        key = (
            int(np.floor((hole.centre[0] - x0) / cell)),
            int(np.floor((hole.centre[1] - y0) / cell)),
        )
        if key in by_cell:
            raise ValueError(f"two holes in the cell at {key}")
        by_cell[key] = hole
    top: list[TriMesh] = []
    walls: list[TriMesh] = []
    for i in range(nx):
        for j in range(ny):
            lo = np.array([x0 + i * cell, y0 + j * cell])
            ring = _cell_outline(lo, cell, per_side)
            found = by_cell.get((i, j))
            if found is None:
                # A fan from the cell's centre over the same boundary vertices as a holed
                # neighbour's (four corners alone would leave T-junctions on its sides).
                k = len(ring)
                fan = np.vstack([ring, lo + 0.5 * cell])
                tri = np.column_stack([np.arange(k), (np.arange(k) + 1) % k, np.full(k, k)])
                top.append(TriMesh(np.column_stack([fan, np.zeros(k + 1)]), tri.astype(np.int64)))
                continue
            inner = found.outline(max_step)
            if np.any(inner <= lo + 1e-4) or np.any(inner >= lo + cell - 1e-4):
                raise ValueError(f"hole at {found.centre} does not fit inside its {cell} m cell")
            top.append(_ring_face(ring, inner, np.asarray(found.centre, dtype=np.float64)))
            walls.append(_wall(inner[::-1], thickness))  # seen from inside the hole
    outline = np.concatenate(
        [
            np.column_stack(
                [np.linspace(x0, -x0, nx * per_side + 1)[:-1], np.full(nx * per_side, y0)]
            ),
            np.column_stack(
                [np.full(ny * per_side, -x0), np.linspace(y0, -y0, ny * per_side + 1)[:-1]]
            ),
            np.column_stack(
                [np.linspace(-x0, x0, nx * per_side + 1)[:-1], np.full(nx * per_side, -y0)]
            ),
            np.column_stack(
                [np.full(ny * per_side, x0), np.linspace(-y0, y0, ny * per_side + 1)[:-1]]
            ),
        ]
    )
    walls.append(_wall(outline, thickness))
    faces_top = merge(top)
    bottom = TriMesh(
        faces_top.vertices - np.array([0.0, 0.0, thickness]), faces_top.faces[:, [0, 2, 1]]
    )
    return merge([faces_top, bottom, *walls])


def _cell_outline(lo: FloatArray, cell: float, per_side: int) -> FloatArray:
    """A square cell's boundary (4·per_side, 2), counter-clockwise from its lower-left corner;
    every cell samples its sides at the same positions, so neighbours share vertices."""
    t = np.linspace(0.0, cell, per_side + 1)[:-1]
    zero = np.zeros_like(t)
    return np.concatenate(
        [
            lo + np.column_stack([t, zero]),
            lo + np.column_stack([zero + cell, t]),
            lo + np.column_stack([cell - t, zero + cell]),
            lo + np.column_stack([zero, cell - t]),
        ]
    )


def _ring_face(outer: FloatArray, inner: FloatArray, centre: FloatArray) -> TriMesh:
    """Triangles (at z = 0, facing +z) between two counter-clockwise closed outlines (K, 2) and
    (L, 2) around ``centre``: both walked in order of angle, each step advancing the outline
    whose next vertex comes first."""

    def angles(points: FloatArray) -> FloatArray:
        d = points - centre
        return np.asarray(np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * np.pi))

    ao, ai = angles(outer), angles(inner)
    o0, i0 = int(np.argmin(ao)), int(np.argmin(ai))
    outer, ao = np.roll(outer, -o0, axis=0), np.roll(ao, -o0)
    inner, ai = np.roll(inner, -i0, axis=0), np.roll(ai, -i0)
    # Close both walks at angle 2π with their first vertex again.
    ao = np.append(ao, ao[0] + 2.0 * np.pi)
    ai = np.append(ai, ai[0] + 2.0 * np.pi)
    k, m = len(outer), len(inner)
    vertices = np.vstack([outer, inner])
    tris = []
    a, b = 0, 0
    while a < k or b < m:
        if b >= m or (a < k and ao[a + 1] <= ai[b + 1]):
            tris.append((a % k, (a + 1) % k, k + b % m))
            a += 1
        else:
            tris.append((a % k, k + (b + 1) % m, k + b % m))
            b += 1
    faces = np.asarray(tris, dtype=np.int64)
    v = vertices[faces]
    signed = 0.5 * (
        (v[:, 1, 0] - v[:, 0, 0]) * (v[:, 2, 1] - v[:, 0, 1])
        - (v[:, 1, 1] - v[:, 0, 1]) * (v[:, 2, 0] - v[:, 0, 0])
    )
    expected = _polygon_area(outer) - _polygon_area(inner)
    if signed.min() <= 0.0 or abs(signed.sum() - expected) > 1e-9 * max(expected, 1e-12) + 1e-12:
        raise ValueError(f"the ring around the hole at {tuple(centre)} cannot be triangulated")
    return TriMesh(np.column_stack([vertices, np.zeros(len(vertices))]), faces)


def _polygon_area(points: FloatArray) -> float:
    x, y = points[:, 0], points[:, 1]
    return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _wall(outline: FloatArray, thickness: float) -> TriMesh:
    """Vertical quads from z = 0 down to -``thickness`` along a closed outline (K, 2); they
    face right of the walking direction (outwards for a counter-clockwise sheet outline)."""
    k = len(outline)
    nxt = np.roll(outline, -1, axis=0)
    quads = np.stack(
        [
            np.column_stack([outline, np.zeros(k)]),
            np.column_stack([outline, np.full(k, -thickness)]),
            np.column_stack([nxt, np.full(k, -thickness)]),
            np.column_stack([nxt, np.zeros(k)]),
        ],
        axis=1,
    ).reshape(-1, 3)
    base = 4 * np.arange(k)[:, None]
    faces = np.concatenate([base + np.array([0, 1, 2]), base + np.array([0, 2, 3])])
    return TriMesh(quads, faces.astype(np.int64))
