"""Rigid transforms, quaternions, polylines and nearest-point queries.

Conventions (docs/design.md): ``T_a_b`` is a (4, 4) float64 matrix mapping points expressed in frame
``b`` into frame ``a``; quaternions are (x, y, z, w) as ROS has them; lengths are metres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

FloatArray = NDArray[np.float64]

#: No coordinate of a robot cell lies 1000 km from its base: a larger one is damaged data (and
#: 1e300 would overflow the squares of every distance computed from it).
MAX_COORDINATE_M = 1e6


# --------------------------------------------------------------------------- SE(3)


def make_transform(rotation: ArrayLike, translation: ArrayLike) -> FloatArray:
    """Build ``T`` (4, 4) from a (3, 3) rotation matrix and a (3,) translation in metres."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(rotation, dtype=np.float64)
    T[:3, 3] = np.asarray(translation, dtype=np.float64)
    return T


def invert_transform(T: ArrayLike) -> FloatArray:
    """Inverse of a rigid transform, using the rotation's transpose (exact, no ``inv``)."""
    T = np.asarray(T, dtype=np.float64)
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def transform_points(T_a_b: ArrayLike, points_b: ArrayLike) -> FloatArray:
    """Map ``points_b`` (N, 3) from frame b into frame a with ``T_a_b`` (4, 4)."""
    T = np.asarray(T_a_b, dtype=np.float64)
    pts = np.asarray(points_b, dtype=np.float64).reshape(-1, 3)
    return pts @ T[:3, :3].T + T[:3, 3]


def rotate_vectors(T_a_b: ArrayLike, vectors_b: ArrayLike) -> FloatArray:
    """Rotate direction vectors (N, 3) from frame b into frame a (no translation)."""
    T = np.asarray(T_a_b, dtype=np.float64)
    return np.asarray(vectors_b, dtype=np.float64).reshape(-1, 3) @ T[:3, :3].T


def quat_xyzw_to_matrix(quat_xyzw: ArrayLike) -> FloatArray:
    """(3, 3) rotation matrix (or (N, 3, 3)) from unit quaternion(s) (x, y, z, w)."""
    return np.asarray(Rotation.from_quat(np.asarray(quat_xyzw, dtype=np.float64)).as_matrix())


def matrix_to_quat_xyzw(rotation: ArrayLike) -> FloatArray:
    """Quaternion(s) (x, y, z, w) with w >= 0 from (3, 3) or (N, 3, 3) rotation matrices."""
    q = np.asarray(Rotation.from_matrix(np.asarray(rotation, dtype=np.float64)).as_quat())
    # A canonical sign makes outputs reproducible byte for byte.
    sign = np.where(q[..., 3:4] < 0.0, -1.0, 1.0)
    return np.asarray(q * sign)


def transform_from_pose(position: ArrayLike, quat_xyzw: ArrayLike) -> FloatArray:
    """``T`` (4, 4) from a position (3,) and a quaternion (x, y, z, w)."""
    return make_transform(quat_xyzw_to_matrix(quat_xyzw), position)


def pose_from_transform(T: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(position (3,), quaternion (x, y, z, w)) of a rigid transform."""
    T = np.asarray(T, dtype=np.float64)
    return T[:3, 3].copy(), matrix_to_quat_xyzw(T[:3, :3])


def interpolate_transform(T0: ArrayLike, T1: ArrayLike, alpha: float) -> FloatArray:
    """Pose between ``T0`` (alpha = 0) and ``T1`` (alpha = 1): lerp translation, slerp rotation."""
    T0 = np.asarray(T0, dtype=np.float64)
    T1 = np.asarray(T1, dtype=np.float64)
    r0 = Rotation.from_matrix(T0[:3, :3])
    r1 = Rotation.from_matrix(T1[:3, :3])
    delta = (r0.inv() * r1).as_rotvec()
    R = (r0 * Rotation.from_rotvec(alpha * delta)).as_matrix()
    t = (1.0 - alpha) * T0[:3, 3] + alpha * T1[:3, 3]
    return make_transform(R, t)


def rotation_angle(R_a: ArrayLike, R_b: ArrayLike) -> float:
    """Angle in radians of the rotation taking ``R_a`` to ``R_b`` (both (3, 3))."""
    R = np.asarray(R_a, dtype=np.float64).T @ np.asarray(R_b, dtype=np.float64)
    # Rotation.magnitude goes through the quaternion: accurate near 0, unlike arccos of the trace.
    return float(Rotation.from_matrix(R).magnitude())


def look_at(eye: ArrayLike, target: ArrayLike, up_hint: ArrayLike = (0.0, 0.0, 1.0)) -> FloatArray:
    """Camera pose ``T_base_cam`` with the optical axis (+z) from ``eye`` towards ``target``.

    Optical frame convention (REP-103): z forward, x right, y down. ``up_hint`` is a direction
    in the base frame that should appear "up" (−y) in the image; if it is parallel to the
    viewing direction another axis is used.
    """
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    norm = np.linalg.norm(z)
    if norm < 1e-12:
        raise ValueError("look_at: eye and target coincide")
    z /= norm
    up = np.asarray(up_hint, dtype=np.float64)
    if abs(float(np.dot(up / np.linalg.norm(up), z))) > 0.999:
        up = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_transform(np.column_stack([x, y, z]), eye)


def orthonormal_frame(z_axis: ArrayLike, x_hint: ArrayLike) -> FloatArray:
    """(3, 3) rotation with columns (x, y, z): z along ``z_axis``, x as close to ``x_hint``.

    If ``x_hint`` is (nearly) parallel to ``z_axis`` an arbitrary perpendicular x is chosen.
    """
    z = np.asarray(z_axis, dtype=np.float64)
    z = z / np.linalg.norm(z)
    x = np.asarray(x_hint, dtype=np.float64)
    x = x - np.dot(x, z) * z
    if np.linalg.norm(x) < 1e-9:
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = helper - np.dot(helper, z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


# --------------------------------------------------------------------------- polylines


def polyline_length(points: ArrayLike) -> float:
    """Total length in metres of an ordered polyline (N, 3)."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


def cumulative_length(points: ArrayLike) -> FloatArray:
    """Arc length (N,) at each vertex of an ordered polyline, starting at 0."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) == 0:
        return np.zeros(0)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def resample_polyline(points: ArrayLike, spacing: float) -> FloatArray:
    """Evenly spaced points along an ordered polyline (N, 3), ``spacing`` metres apart.

    The first and last vertices are kept; the spacing is adjusted to divide the length
    evenly, so consecutive points are at most ``spacing`` apart along the curve.
    """
    if spacing <= 0:
        raise ValueError(f"spacing must be positive, got {spacing}")
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 2:
        return pts.copy()
    s = cumulative_length(pts)
    total = s[-1]
    if total <= 0:
        return pts[:1].copy()
    n = max(int(np.ceil(total / spacing - 1e-9)), 1) + 1
    return interpolate_polyline(pts, np.linspace(0.0, total, n), cumulative=s)


def closed_polyline(points: ArrayLike) -> FloatArray:
    """A loop's vertices (N, 3) as a polyline that returns to its start: (N + 1, 3)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.asarray(np.vstack([pts, pts[:1]]))


def resample_loop(points: ArrayLike, spacing: float) -> FloatArray:
    """Evenly spaced points (M, 3) around a loop given by its vertices (N, 3) (the last joins the
    first, which is not repeated), at most ``spacing`` metres apart; the first vertex is kept
    and the first point is not repeated at the end."""
    return resample_polyline(closed_polyline(points), spacing)[:-1]


def interpolate_polyline(
    points: ArrayLike, arc_lengths: ArrayLike, *, cumulative: ArrayLike | None = None
) -> FloatArray:
    """Points (M, 3) on an ordered polyline at the given arc lengths (M,), clamped to its ends."""
    pts = np.asarray(points, dtype=np.float64)
    s = cumulative_length(pts) if cumulative is None else np.asarray(cumulative, dtype=np.float64)
    q = np.clip(np.asarray(arc_lengths, dtype=np.float64), 0.0, s[-1])
    # Drop zero-length segments so interpolation is well defined.
    keep = np.concatenate([[True], np.diff(s) > 0])
    s, pts = s[keep], pts[keep]
    if len(pts) == 1:
        return np.repeat(pts, len(q), axis=0)
    return np.column_stack([np.interp(q, s, pts[:, k]) for k in range(3)])


def polyline_tangents(points: ArrayLike) -> FloatArray:
    """Unit tangents (N, 3) of an ordered polyline (central differences, one-sided at ends)."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 2:
        raise ValueError("a polyline needs at least two points for tangents")
    t = np.gradient(pts, axis=0)
    n = np.linalg.norm(t, axis=1, keepdims=True)
    n[n == 0] = 1.0
    return np.asarray(t / n)


def false_runs(mask: ArrayLike, *, closed: bool = False) -> list[tuple[int, int]]:
    """Runs of False in a boolean sequence (N,) as (first, stop) index pairs, in order of their
    first index; with ``closed`` the sequence is a loop and a run may wrap past its end
    (stop <= first then, indices modulo N; an all-False loop is one run (0, N))."""
    m = np.asarray(mask, dtype=bool).reshape(-1)
    n = len(m)
    if n == 0 or m.all():
        return []
    if not m.any():
        return [(0, n)]
    shift = int(np.flatnonzero(m)[0]) if closed else 0  # start on a True: no run is cut
    step = np.diff(np.concatenate([[0], (~np.roll(m, -shift)).astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(step == 1), np.flatnonzero(step == -1)
    runs = [
        (int((a + shift) % n), int((b + shift - 1) % n + 1))
        for a, b in zip(starts, stops, strict=True)
    ]
    return sorted(runs)


#: (query, segment) pairs evaluated at once by :class:`PolylineDistance` (~100 MB of arrays);
#: a query with more candidates than _CROWDED (and a tenth of all) is compared with all.
_PAIRS_PER_BATCH = 1 << 20
_CROWDED = 1024


class PolylineDistance:
    """Exact distances from query points to an ordered polyline (nearest point on its segments).

    Candidate segments come from a KD-tree over the midpoints of pieces of the segments (a
    long segment is cut into pieces about twice the median segment long): a segment can only
    be nearest if one of its pieces' midpoints is within (distance to the nearest piece
    midpoint + the longest half piece), so the search is exact, not approximate. One long
    segment (a jump in an unordered path) thus does not make every segment a candidate, and
    memory stays bounded however many candidates there are (batches; a query with most
    segments as candidates, near the centre of a closed curve, is compared with all at once).
    """

    def __init__(self, points: ArrayLike) -> None:
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(pts) == 0:
            raise ValueError("polyline is empty")
        if len(pts) == 1:
            pts = np.vstack([pts, pts])
        self.points = pts
        self._a = pts[:-1]
        self._d = pts[1:] - pts[:-1]
        self._len2 = np.einsum("ij,ij->i", self._d, self._d)
        lengths = np.sqrt(self._len2)
        positive = lengths[lengths > 0]
        piece = max(
            2.0 * float(np.median(positive)) if len(positive) else 1.0,
            float(lengths.sum()) / 1e6,  # at most about a million extra pieces
        )
        pieces = np.maximum(1, np.ceil(lengths / piece)).astype(np.int64)
        self._segment_of = np.repeat(np.arange(len(lengths)), pieces)
        first = np.repeat(np.cumsum(pieces) - pieces, pieces)
        k = np.arange(len(self._segment_of)) - first
        fraction = (k + 0.5) / pieces[self._segment_of]
        mids = self._a[self._segment_of] + fraction[:, None] * self._d[self._segment_of]
        self._half_max = float((0.5 * lengths / pieces).max())
        self._tree = cKDTree(mids)

    def query(self, query_points: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Distances (M,), nearest points (M, 3), and polyline parameters (M,).

        The parameter is ``segment_index + fraction`` in [0, N - 1].
        """
        q = np.asarray(query_points, dtype=np.float64).reshape(-1, 3)
        m = len(q)
        best_d2 = np.full(m, np.inf)
        best_p = np.zeros((m, 3))
        best_u = np.zeros(m)
        if m == 0:
            return best_d2, best_p, best_u
        d0, _ = self._tree.query(q)
        radius = d0 + self._half_max + 1e-12
        # Far from a closed curve (or at its centre) every segment is a candidate: work in
        # batches of a bounded number of (query, segment) pairs, so memory stays flat.
        counts = np.asarray(self._tree.query_ball_point(q, radius, return_length=True))
        # Queries with most segments as candidates (the centre of a closed curve) are cheaper
        # to compare with every segment at once than to list.
        crowded = counts > max(_CROWDED, len(self._segment_of) // 10)
        if crowded.any():
            self._nearest_of_all(q, np.flatnonzero(crowded), best_d2, best_p, best_u)
            counts = np.where(crowded, 0, counts)
        ends = np.cumsum(counts)
        start = 0
        while start < m:
            budget = (ends[start - 1] if start else 0) + _PAIRS_PER_BATCH
            stop = max(start + 1, int(np.searchsorted(ends, budget, side="right")))
            rows = np.arange(start, stop)[~crowded[start:stop]]
            if len(rows):
                self._nearest(q, radius, rows, best_d2, best_p, best_u)
            start = stop
        return np.sqrt(best_d2), best_p, best_u

    def _nearest_of_all(
        self,
        q: FloatArray,
        rows: NDArray[np.int64],
        best_d2: FloatArray,
        best_p: FloatArray,
        best_u: FloatArray,
    ) -> None:
        """Exact nearest segment of queries ``rows`` among all segments, in batches."""
        n = len(self._a)
        per_batch = max(1, _PAIRS_PER_BATCH // n)
        safe = np.where(self._len2 > 0, self._len2, 1.0)
        for k in range(0, len(rows), per_batch):
            batch = rows[k : k + per_batch]
            rel = q[batch, None, :] - self._a[None, :, :]  # (B, N, 3)
            t = np.clip(np.einsum("bnj,nj->bn", rel, self._d) / safe, 0.0, 1.0)
            t = np.where(self._len2 > 0, t, 0.0)
            diff = rel - t[:, :, None] * self._d[None, :, :]
            d2 = np.einsum("bnj,bnj->bn", diff, diff)
            seg = np.argmin(d2, axis=1)  # lowest index wins ties
            pick = np.arange(len(batch))
            best_d2[batch] = d2[pick, seg]
            best_p[batch] = self._a[seg] + t[pick, seg][:, None] * self._d[seg]
            best_u[batch] = seg + t[pick, seg]

    def _nearest(
        self,
        q: FloatArray,
        radius: FloatArray,
        which: NDArray[np.int64],
        best_d2: FloatArray,
        best_p: FloatArray,
        best_u: FloatArray,
    ) -> None:
        """Exact nearest segment of queries ``which`` among their ball candidates."""
        candidates = self._tree.query_ball_point(q[which], radius[which])
        lengths = np.fromiter((len(c) for c in candidates), dtype=np.int64, count=len(which))
        rows = np.repeat(which, lengths)
        pieces = np.fromiter((i for c in candidates for i in c), dtype=np.int64, count=rows.size)
        segs = self._segment_of[pieces]
        a = self._a[segs]
        d = self._d[segs]
        l2 = self._len2[segs]
        safe = np.where(l2 > 0, l2, 1.0)
        t = np.clip(np.einsum("ij,ij->i", q[rows] - a, d) / safe, 0.0, 1.0)
        t = np.where(l2 > 0, t, 0.0)
        p = a + t[:, None] * d
        d2 = np.einsum("ij,ij->i", q[rows] - p, q[rows] - p)
        # Pick the minimum per query row (stable: lowest segment index wins ties).
        order = np.lexsort((segs, d2, rows))
        first = np.ones(order.size, dtype=bool)
        first[1:] = rows[order][1:] != rows[order][:-1]
        pick = order[first]
        best_d2[rows[pick]] = d2[pick]
        best_p[rows[pick]] = p[pick]
        best_u[rows[pick]] = segs[pick] + t[pick]

    def distance(self, query_points: ArrayLike) -> FloatArray:
        """Distances (M,) in metres from each query point to the polyline."""
        return self.query(query_points)[0]


def sight_cosines(points: ArrayLike, viewpoints: ArrayLike, normal: ArrayLike) -> FloatArray:
    """Cosine (N,) of the angle between ``normal`` (3,) and each point's sight line towards the
    camera that saw it (``points`` and ``viewpoints`` (N, 3)): 1 seen head-on, 0 edge-on,
    negative from behind."""
    sight = np.asarray(viewpoints, dtype=np.float64) - np.asarray(points, dtype=np.float64)
    return np.asarray(
        (sight @ np.asarray(normal, dtype=np.float64))
        / np.maximum(np.linalg.norm(sight, axis=1), 1e-12)
    )


def orient_over_edge(
    normal: ArrayLike,
    at: ArrayLike,
    known_normal: ArrayLike,
    known_at: ArrayLike,
    *,
    margin_m: float,
    same_plane_cos: float,
) -> FloatArray | None:
    """``normal`` (3,) at ``at`` turned out of a closed surface, from a nearby point
    ``known_at`` whose outward normal ``known_normal`` is known; None when it cannot tell.

    A face behind the known face's plane (farther than ``margin_m``) lies past a convex edge and
    faces away from the known point; one in front of it lies past a concave edge and faces
    towards it; a face in that plane (normals within ``same_plane_cos``) faces as the known one
    does. For a surface seen only from behind (a wire mesh's far wall through its near one) the
    cameras' side is the wrong side; this is the side a closed piece has.
    """
    n = np.asarray(normal, dtype=np.float64)
    nj = np.asarray(known_normal, dtype=np.float64)
    offset = np.asarray(at, dtype=np.float64) - np.asarray(known_at, dtype=np.float64)
    ahead = float(np.dot(offset, nj))
    towards = -float(np.dot(offset, n))
    if abs(ahead) > margin_m and abs(towards) > margin_m:
        return n if (towards > 0.0) == (ahead > 0.0) else -n
    if abs(float(np.dot(n, nj))) >= same_plane_cos:
        return n if float(np.dot(n, nj)) > 0.0 else -n
    return None


def nearest_distances(points: ArrayLike, reference_points: ArrayLike) -> FloatArray:
    """Distance (N,) from each point to the nearest of ``reference_points`` (a point set)."""
    ref = np.asarray(reference_points, dtype=np.float64).reshape(-1, 3)
    d, _ = cKDTree(ref).query(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    return np.asarray(d, dtype=np.float64)


# --------------------------------------------------------------------------- voxels


def voxel_keys(points: ArrayLike, voxel_size: float) -> NDArray[np.int64]:
    """Integer voxel indices (N, 3) of points for a grid of ``voxel_size`` metres at the origin."""
    if voxel_size <= 0:
        raise ValueError(f"voxel_size must be positive, got {voxel_size}")
    return np.floor(np.asarray(points, dtype=np.float64) / voxel_size).astype(np.int64)


def pack_voxel_keys(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    """Pack (N, 3) voxel indices into one int64 each (21 bits per axis, ±1 M voxels).

    At a 1 mm voxel that is ±1 km, far beyond any robot cell.
    """
    offset = np.int64(1 << 20)
    k = np.asarray(keys, dtype=np.int64) + offset
    if k.size and (k.min() < 0 or k.max() >= (1 << 21)):
        raise ValueError("voxel index out of the packable range (±2^20)")
    return (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]


def unpack_voxel_keys(packed: NDArray[np.int64]) -> NDArray[np.int64]:
    """Inverse of :func:`pack_voxel_keys`: (N,) int64 → (N, 3) voxel indices."""
    p = np.asarray(packed, dtype=np.int64)
    mask = np.int64((1 << 21) - 1)
    offset = np.int64(1 << 20)
    return np.column_stack([(p >> 42) & mask, (p >> 21) & mask, p & mask]) - offset
