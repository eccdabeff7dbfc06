"""The calibration's least-squares problem: frames posed with a candidate mount, and their
disagreement.

Frame ``i`` (image header stamp ``t_i``) is posed as::

    T_base_cam_i(x) = T_base_moving(t_i + dt0 + dt) @ M0 @ [Rot(r), t]

with ``M0`` the published mount (``dt0`` its offset, normally 0) and the correction
``x = (t, r, dt)``: a translation ``t`` and a rotation vector ``r`` in the camera's optical
frame (x right, y down, z along the optical axis) and a clock offset ``dt``, in millimetres,
degrees and milliseconds (:data:`PARAMETERS`).

Residuals, for each selected pair of overlapping frames and both ways (:func:`evaluate`):

- surface, point to plane: a depth sample of frame ``i`` posed in the base frame, against the
  nearest sample of frame ``k`` and its normal: ``n_k · (P_i − Q_k)``;
- paint edge, point to line in the surface: a paint-edge point of ``i`` against the nearest
  edge point of ``k`` with the same outward direction: ``m_k · (P_i − Q_k)`` with ``m_k`` the
  in-surface direction across ``k``'s edge. A flat surface cannot tell a slide along itself;
  the paint's edges can.

Both move with ``x`` through both frames' poses; the Jacobian is analytic (the clock offset
moves a point with the moving frame's velocity at the capture time, from /tf by central
differences). Each kind of residual is scaled by its own robust spread (1.4826 × MAD) and
weighted with Huber's loss. Which frames are compared: :func:`select_pairs`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from scrapcut_cli.calibration.observations import FrameObservation
from scrapcut_cli.geometry import pack_voxel_keys, voxel_keys
from scrapcut_cli.recording.mount import CameraMount

FloatArray = NDArray[np.float64]

#: T_base_moving (N, 4, 4) and validity (N,) at TF-clock stamps (N,) int64 nanoseconds.
Trajectory = Callable[[NDArray[np.int64]], tuple[FloatArray, NDArray[np.bool_]]]

#: The seven parameters, in the solver's order and units.
PARAMETERS = ("tx_mm", "ty_mm", "tz_mm", "rx_deg", "ry_deg", "rz_deg", "dt_ms")
SURFACE, EDGE = "surface", "edge"
#: Half step of the central difference for the moving frame's velocity.
VELOCITY_STEP_NS = 2_000_000
#: Calibration errors a real cell has (issue 13: 1-2 mm, 0.2-0.5 deg, 5-30 ms): what makes two
#: frames informative is how far apart such errors would throw their points (pair selection).
TYPICAL_ERROR = (2.0, math.radians(0.3), 0.015)  # mm, rad, s
HUBER_K = 1.5
#: Partner frames each point is compared with.
PARTNERS_PER_POINT = 3
#: A coarse voxel (m) for judging which frames overlap.
OVERLAP_VOXEL_M = 0.02


# --------------------------------------------------------------------------- poses


@dataclass(frozen=True, eq=False)
class Motion:
    """Per frame: the moving frame's pose and velocity at the capture time (base frame)."""

    T_base_moving: FloatArray  # (F, 4, 4)
    origin_velocity: FloatArray  # (F, 3) m/s
    angular_velocity: FloatArray  # (F, 3) rad/s
    valid: NDArray[np.bool_]  # (F,)


def moving_frame_motion(trajectory: Trajectory, stamps_ns: NDArray[np.int64]) -> Motion:
    """The moving frame at ``stamps_ns`` and its velocity by central differences."""
    h = VELOCITY_STEP_NS
    T, ok = trajectory(stamps_ns)
    T_minus, ok_minus = trajectory(stamps_ns - h)
    T_plus, ok_plus = trajectory(stamps_ns + h)
    # Where one side is outside /tf (the first and last samples) use the other side.
    lo = np.where(ok_minus[:, None, None], T_minus, T)
    hi = np.where(ok_plus[:, None, None], T_plus, T)
    span = (np.where(ok_minus, h, 0) + np.where(ok_plus, h, 0)).astype(np.float64) * 1e-9
    span = np.where(span > 0, span, 1.0)
    velocity = (hi[:, :3, 3] - lo[:, :3, 3]) / span[:, None]
    relative = np.einsum("nij,nkj->nik", hi[:, :3, :3], lo[:, :3, :3])  # R_hi R_loᵀ
    angular = Rotation.from_matrix(relative).as_rotvec() / span[:, None]
    return Motion(T, velocity, angular, ok)


def correction_transform(x: FloatArray) -> FloatArray:
    """[Rot(r), t] (4, 4) of a correction ``x`` (mm, deg, ...)."""
    C = np.eye(4)
    C[:3, :3] = Rotation.from_rotvec(np.radians(x[3:6])).as_matrix()
    C[:3, 3] = x[:3] / 1000.0
    return C


def corrected_mount(published: CameraMount, x: ArrayLike) -> CameraMount:
    """The published mount with a correction ``x`` (:data:`PARAMETERS` units) applied."""
    x = np.asarray(x, dtype=np.float64)
    return CameraMount(
        published.moving_frame,
        published.camera_frame,
        published.T_moving_camera @ correction_transform(x),
        published.time_offset_s + float(x[6]) / 1000.0,
    )


# --------------------------------------------------------------------------- the problem


@dataclass
class Frames:
    """The observations stacked for the solver, and their current poses."""

    obs: list[FrameObservation]
    stamps: NDArray[np.int64]
    published: CameraMount
    trajectory: Trajectory
    T: FloatArray = field(init=False)  # (F, 4, 4) current T_base_cam
    R: FloatArray = field(init=False)  # (F, 3, 3) its rotations, contiguous
    motion: Motion = field(init=False)
    kinds: tuple[Measurements, Measurements] = field(init=False)
    partners: list[NDArray[np.int64]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.kinds = (
            Measurements.stack([(o.surface, o.normals) for o in self.obs]),
            Measurements.stack([(o.edges, o.edge_across) for o in self.obs]),
        )

    def pose(self, x: FloatArray) -> None:
        """Pose every frame with the published mount corrected by ``x`` (PARAMETERS units)."""
        mount = corrected_mount(self.published, x)
        self.motion = moving_frame_motion(self.trajectory, self.stamps + mount.time_offset_ns)
        self.T = self.motion.T_base_moving @ mount.T_moving_camera
        self.R = np.ascontiguousarray(self.T[:, :3, :3])


@dataclass
class Residuals:
    """Residuals (mm), Jacobian rows (n, 7) in PARAMETERS units, kinds and the two frames."""

    r: FloatArray
    J: FloatArray
    kind: NDArray[np.int8]  # 0 surface, 1 edge
    frames: NDArray[np.int64]  # (n, 2) source, target

    @staticmethod
    def empty() -> Residuals:
        return Residuals(
            np.zeros(0), np.zeros((0, 7)), np.zeros(0, np.int8), np.zeros((0, 2), np.int64)
        )


@dataclass(frozen=True, eq=False)
class Measurements:
    """One kind of measurement of every frame, stacked: camera frame and posed in the base."""

    cam: FloatArray  # (N, 3) camera frame
    dirs_cam: FloatArray  # (N, 3) normals / across-edge directions, camera frame
    frame: NDArray[np.int64]  # (N,) owning frame
    start: NDArray[np.int64]  # (F + 1,) offsets of each frame's points

    @staticmethod
    def stack(arrays: Sequence[tuple[FloatArray, FloatArray]]) -> Measurements:
        counts = np.array([len(a) for a, _ in arrays], dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(counts)])
        return Measurements(
            np.vstack([a for a, _ in arrays]) if arrays else np.zeros((0, 3)),
            np.vstack([d for _, d in arrays]) if arrays else np.zeros((0, 3)),
            np.repeat(np.arange(len(arrays), dtype=np.int64), counts),
            start,
        )

    def posed(self, T: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(points, directions) (N, 3) in the base frame with per-frame poses T (F, 4, 4)."""
        R = T[self.frame, :3, :3]
        P = np.einsum("nij,nj->ni", R, self.cam) + T[self.frame, :3, 3]
        return P, np.einsum("nij,nj->ni", R, self.dirs_cam)


@dataclass(frozen=True, eq=False)
class Matches:
    """Corresponding points per kind: stacked indices (source, target), fixed for a few steps."""

    src: tuple[NDArray[np.int64], NDArray[np.int64]]
    tgt: tuple[NDArray[np.int64], NDArray[np.int64]]


def match_points(frames: Frames, partners: list[NDArray[np.int64]], gate_m: float) -> Matches:
    """Nearest neighbours (within ``gate_m``) of every frame's points in each partner frame,
    at the current poses; normals (or outward edge directions) must agree."""
    srcs, tgts = [], []
    for kind_id, kind in enumerate(frames.kinds):
        P, D = kind.posed(frames.T)
        src_all: list[NDArray[np.int64]] = [np.zeros(0, np.int64)]
        tgt_all: list[NDArray[np.int64]] = [np.zeros(0, np.int64)]
        for k, sources in enumerate(partners):
            a, b = kind.start[k], kind.start[k + 1]
            if b - a < 2 or sources.size == 0:
                continue
            src = np.concatenate([_share(kind, partners, i, k) for i in sources])
            if src.size == 0:
                continue
            dist, idx = cKDTree(P[a:b]).query(P[src], distance_upper_bound=gate_m)
            hit = np.isfinite(dist)
            src_all.append(src[hit])
            tgt_all.append(idx[hit] + a)
        src = np.concatenate(src_all)
        tgt = np.concatenate(tgt_all)
        # Same side of the surface (normals) / of the stroke (outward directions).
        agree = np.einsum("ij,ij->i", D[src], D[tgt]) > (0.7 if kind_id == 0 else 0.5)
        srcs.append(src[agree])
        tgts.append(tgt[agree])
    return Matches((srcs[0], srcs[1]), (tgts[0], tgts[1]))


def _share(
    kind: Measurements, partners: list[NDArray[np.int64]], i: int, k: int
) -> NDArray[np.int64]:
    """The points of frame ``i`` compared against partner ``k``: every point of a frame is
    compared with about :data:`PARTNERS_PER_POINT` of its partners, in turn (neighbouring
    points say nearly the same; this keeps the problem small and every point in it)."""
    mine = partners[i]
    stride = max(1, math.ceil(len(mine) / PARTNERS_PER_POINT))
    offset = int(np.searchsorted(mine, k)) % stride
    return np.arange(kind.start[i] + offset, kind.start[i + 1], stride, dtype=np.int64)


def evaluate(frames: Frames, matches: Matches) -> Residuals:
    """Residuals and Jacobian rows of the matched points at the current poses."""
    parts = []
    for kind_id, kind in enumerate(frames.kinds):
        src, tgt = matches.src[kind_id], matches.tgt[kind_id]
        if src.size == 0:
            continue
        P, D = kind.posed(frames.T)
        d = D[tgt]
        r = np.einsum("ij,ij->i", d, P[src] - P[tgt]) * 1000.0
        J = _point_rows(frames, kind, src, P[src], d) - _point_rows(frames, kind, tgt, P[tgt], d)
        pair = np.column_stack([kind.frame[src], kind.frame[tgt]])
        parts.append(Residuals(r, J, np.full(r.size, kind_id, dtype=np.int8), pair))
    if not parts:
        return Residuals.empty()
    return Residuals(
        np.concatenate([p.r for p in parts]),
        np.vstack([p.J for p in parts]),
        np.concatenate([p.kind for p in parts]),
        np.vstack([p.frames for p in parts]),
    )


def _point_rows(
    frames: Frames, kind: Measurements, points: NDArray[np.int64], P: FloatArray, a: FloatArray
) -> FloatArray:
    """d(a · P)/dx (n, 7) for the stacked ``points`` posed at ``P`` (base) along ``a`` (n, 3).

    P = R (Rot(r) p + t) + ...: d/dt = Rᵀa, d/dr = p × Rᵀa (rad), d/d(dt) = a · velocity of P.
    """
    f = kind.frame[points]
    R = frames.R[f]  # (n, 3, 3)
    b = a[:, 0:1] * R[:, 0, :] + a[:, 1:2] * R[:, 1, :] + a[:, 2:3] * R[:, 2, :]  # Rᵀ a
    p = kind.cam[points]
    rows = np.empty((len(P), 7))
    rows[:, 0:3] = b
    scale = 1000.0 * math.pi / 180.0
    rows[:, 3] = (p[:, 1] * b[:, 2] - p[:, 2] * b[:, 1]) * scale
    rows[:, 4] = (p[:, 2] * b[:, 0] - p[:, 0] * b[:, 2]) * scale
    rows[:, 5] = (p[:, 0] * b[:, 1] - p[:, 1] * b[:, 0]) * scale
    m = frames.motion
    w = m.angular_velocity[f]
    q = P - m.T_base_moving[f, :3, 3]
    velocity = m.origin_velocity[f] + np.column_stack(
        [
            w[:, 1] * q[:, 2] - w[:, 2] * q[:, 1],
            w[:, 2] * q[:, 0] - w[:, 0] * q[:, 2],
            w[:, 0] * q[:, 1] - w[:, 1] * q[:, 0],
        ]
    )
    rows[:, 6] = np.einsum("ij,ij->i", a, velocity)  # m/s = mm/ms
    return rows


def partners_of(pairs: Sequence[tuple[int, int]], n: int) -> list[NDArray[np.int64]]:
    """For each frame the frames paired with it (the sources compared against it)."""
    out: list[list[int]] = [[] for _ in range(n)]
    for a, b in pairs:
        out[a].append(b)
        out[b].append(a)
    return [np.array(sorted(p), dtype=np.int64) for p in out]


# --------------------------------------------------------------------------- weights


def robust_scales(res: Residuals) -> FloatArray:
    """Robust spread (mm) of each kind: 1.4826 × MAD, floored at 0.05 mm."""
    scales = np.ones(2)
    for kind in (0, 1):
        r = res.r[res.kind == kind]
        if r.size >= 10:
            scales[kind] = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 0.05)
    return scales


def huber_weights(res: Residuals, scales: FloatArray) -> FloatArray:
    """Huber weight / scale² per residual (whitened least squares)."""
    s = scales[res.kind]
    u = np.abs(res.r) / s
    w = np.where(u <= HUBER_K, 1.0, HUBER_K / np.maximum(u, 1e-12))
    return np.asarray(w / (s * s))


def normal_equations(res: Residuals, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    Jw = res.J * w[:, None]
    return Jw.T @ res.J, Jw.T @ res.r


# --------------------------------------------------------------------------- pairs


def select_pairs(
    obs: Sequence[FrameObservation],
    velocities: FloatArray,
    *,
    partners: int,
    min_overlap: float,
) -> list[tuple[int, int]]:
    """Pairs (i, k), i < k, of overlapping frames, ``partners`` per frame at most.

    Overlap: the share of the smaller frame's 20 mm voxels (base frame, published poses) that
    the other frame also covers. Among overlapping frames each keeps those where a typical
    calibration error (:data:`TYPICAL_ERROR`) would show most: the larger the difference in
    orientation, position and velocity, the more the pair says about the mount and the clock.
    """
    n = len(obs)
    keys = []
    for ob in obs:
        P = ob.surface @ ob.T_base_cam[:3, :3].T + ob.T_base_cam[:3, 3]
        keys.append(np.unique(pack_voxel_keys(voxel_keys(P, OVERLAP_VOXEL_M))))
    T = np.array([ob.T_base_cam for ob in obs])
    R = T[:, :3, :3]
    # Angle between every two orientations from the trace of R_iᵀ R_k; distances; speeds.
    cos = (np.einsum("iab,kab->ik", R, R) - 1.0) / 2.0
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    shift = np.linalg.norm(T[:, None, :3, 3] - T[None, :, :3, 3], axis=2) * 1000.0
    speed = np.linalg.norm(velocities[:, None, :] - velocities[None, :, :], axis=2) * 1000.0
    t_err, r_err, dt_err = TYPICAL_ERROR
    score = t_err * angle + r_err * shift + dt_err * speed
    chosen: set[tuple[int, int]] = set()
    for i in range(n):
        scored = []
        for k in range(n):
            if k == i or len(keys[i]) == 0 or len(keys[k]) == 0:
                continue
            common = np.intersect1d(keys[i], keys[k], assume_unique=True).size
            if common < min_overlap * min(len(keys[i]), len(keys[k])):
                continue
            scored.append((float(score[i, k]), k))
        scored.sort(key=lambda item: (-item[0], item[1]))
        for _, k in scored[:partners]:
            chosen.add((min(i, k), max(i, k)))
    return sorted(chosen)
