"""Estimate the camera mount and clock offset that make overlapping frames agree.

Model
-----
Frame ``i`` (image header stamp ``t_i``) is posed as::

    T_base_cam_i(x) = T_base_moving(t_i + dt0 + dt) @ M0 @ [Rot(r), t]

with ``M0`` the published mount (``dt0`` its offset, normally 0) and the correction
``x = (t, r, dt)``: a translation ``t`` and a rotation vector ``r`` in the camera's optical
frame (x right, y down, z along the optical axis) and a clock offset ``dt``. The solver works in
millimetres, degrees and milliseconds.

Residuals
---------
For each selected pair of overlapping frames (both directions):

- surface, point to plane: a depth sample of frame ``i`` posed in the base frame, against the
  nearest sample of frame ``k`` and its normal: ``n_k · (P_i − Q_k)``;
- paint edge, point to line in the surface: a paint-edge point of ``i`` against the nearest
  edge point of ``k`` with the same outward direction: ``m_k · (P_i − Q_k)`` with ``m_k`` the
  in-surface direction across ``k``'s edge. A flat surface cannot tell a slide along itself;
  the paint's edges can.

Both move with ``x`` through both frames' poses; the Jacobian is analytic (the clock offset
moves a point with the moving frame's velocity at the capture time, from /tf by central
differences). Each kind of residual is scaled by its own robust spread (1.4826 × MAD) and
weighted with Huber's loss; correspondences are found again every iteration with a gate that
shrinks from ``max_distance_m`` to ``min_distance_m`` (ICP's alternation).

Observability
-------------
The normal equations ``JᵀWJ`` are analysed in units of the accuracy each parameter needs
(``observable_sigma_*``: a unit step moves the estimate by one "tolerance"); an eigen-direction
is observable when its standard deviation — the larger of the formal one and a leave-one-frame-out
jackknife, which sees errors shared by a frame's residuals — is below one such unit. The solve
is then repeated with the unobservable directions held at the published values, and those
directions are described in words with the reason the scan cannot see them. Nothing here reads
files or prints.
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
from scrapcut_cli.config import CalibrationConfig
from scrapcut_cli.errors import CalibrationError
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
#: Gauss-Newton steps taken with one set of correspondences.
STEPS_PER_MATCH = 2
#: Partner frames each point is compared with.
PARTNERS_PER_POINT = 3
#: A coarse voxel (m) for judging which frames overlap.
OVERLAP_VOXEL_M = 0.02


@dataclass(frozen=True)
class Direction:
    """A direction of the correction the scan cannot pin down.

    ``vector`` (7,) is unit in the analysis units (``observable_sigma_*``), in :data:`PARAMETERS`
    order; ``sigma`` its standard deviation in those units (> 1: unobservable); ``what`` and
    ``why`` describe it for a user.
    """

    vector: tuple[float, ...]
    sigma: float
    what: str
    why: str


@dataclass(frozen=True, eq=False)
class Solution:
    """The estimate and everything the report needs.

    Attributes
    ----------
    correction : (7,) float64
        ``x`` in :data:`PARAMETERS` units (mm, deg, ms), relative to the published mount.
    sigma : (7,) float64
        Standard deviations, same units; NaN where not observable.
    observable : (7,) bool
        Parameters the scan determines (less than a quarter of each in an unobservable
        direction).
    unobservable : tuple of Direction
        Eigen-directions held at the published values, with the reason.
    residual_before_mm, residual_after_mm : dict
        RMS of the gated residuals per kind (``surface``, ``edge``) and ``all``, millimetres.
    frames, pairs, residuals : int
        Frames used, frame pairs compared, residuals at the solution.
    iterations : int
    eigen : list of dict
        The eigen-analysis: per direction ``sigma`` (analysis units) and ``vector``.
    """

    correction: FloatArray
    sigma: FloatArray
    observable: NDArray[np.bool_]
    unobservable: tuple[Direction, ...]
    residual_before_mm: dict[str, float]
    residual_after_mm: dict[str, float]
    frames: int
    pairs: int
    residuals: int
    iterations: int
    eigen: list[dict[str, object]] = field(default_factory=list)


# --------------------------------------------------------------------------- poses


@dataclass(frozen=True, eq=False)
class _Motion:
    """Per frame: the moving frame's pose and velocity at the capture time (base frame)."""

    T_base_moving: FloatArray  # (F, 4, 4)
    origin_velocity: FloatArray  # (F, 3) m/s
    angular_velocity: FloatArray  # (F, 3) rad/s
    valid: NDArray[np.bool_]  # (F,)


def _motion(trajectory: Trajectory, stamps_ns: NDArray[np.int64]) -> _Motion:
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
    return _Motion(T, velocity, angular, ok)


def _correction_transform(x: FloatArray) -> FloatArray:
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
        published.T_moving_camera @ _correction_transform(x),
        published.time_offset_s + float(x[6]) / 1000.0,
    )


# --------------------------------------------------------------------------- the problem


@dataclass
class _Frames:
    """The observations stacked for the solver, and their current poses."""

    obs: list[FrameObservation]
    stamps: NDArray[np.int64]
    published: CameraMount
    trajectory: Trajectory
    T: FloatArray = field(init=False)  # (F, 4, 4) current T_base_cam
    R: FloatArray = field(init=False)  # (F, 3, 3) its rotations, contiguous
    motion: _Motion = field(init=False)
    kinds: tuple[_Kind, _Kind] = field(init=False)
    partners: list[NDArray[np.int64]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.kinds = (
            _Kind.stack([(o.surface, o.normals) for o in self.obs]),
            _Kind.stack([(o.edges, o.edge_across) for o in self.obs]),
        )

    def pose(self, x: FloatArray) -> None:
        mount = corrected_mount(self.published, x)
        self.motion = _motion(self.trajectory, self.stamps + mount.time_offset_ns)
        self.T = self.motion.T_base_moving @ mount.T_moving_camera
        self.R = np.ascontiguousarray(self.T[:, :3, :3])


@dataclass
class _Residuals:
    """Residuals (mm), Jacobian rows (n, 7) in PARAMETERS units, kinds and the two frames."""

    r: FloatArray
    J: FloatArray
    kind: NDArray[np.int8]  # 0 surface, 1 edge
    frames: NDArray[np.int64]  # (n, 2) source, target

    @staticmethod
    def empty() -> _Residuals:
        return _Residuals(
            np.zeros(0), np.zeros((0, 7)), np.zeros(0, np.int8), np.zeros((0, 2), np.int64)
        )


@dataclass(frozen=True, eq=False)
class _Kind:
    """One kind of measurement of every frame, stacked: camera frame and posed in the base."""

    cam: FloatArray  # (N, 3) camera frame
    dirs_cam: FloatArray  # (N, 3) normals / across-edge directions, camera frame
    frame: NDArray[np.int64]  # (N,) owning frame
    start: NDArray[np.int64]  # (F + 1,) offsets of each frame's points

    @staticmethod
    def stack(arrays: Sequence[tuple[FloatArray, FloatArray]]) -> _Kind:
        counts = np.array([len(a) for a, _ in arrays], dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(counts)])
        return _Kind(
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
class _Matches:
    """Corresponding points per kind: stacked indices (source, target), fixed for a few steps."""

    src: tuple[NDArray[np.int64], NDArray[np.int64]]
    tgt: tuple[NDArray[np.int64], NDArray[np.int64]]


def _match(frames: _Frames, partners: list[NDArray[np.int64]], gate_m: float) -> _Matches:
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
    return _Matches((srcs[0], srcs[1]), (tgts[0], tgts[1]))


def _share(kind: _Kind, partners: list[NDArray[np.int64]], i: int, k: int) -> NDArray[np.int64]:
    """The points of frame ``i`` compared against partner ``k``: every point of a frame is
    compared with about :data:`PARTNERS_PER_POINT` of its partners, in turn (neighbouring
    points say nearly the same; this keeps the problem small and every point in it)."""
    mine = partners[i]
    stride = max(1, math.ceil(len(mine) / PARTNERS_PER_POINT))
    offset = int(np.searchsorted(mine, k)) % stride
    return np.arange(kind.start[i] + offset, kind.start[i + 1], stride, dtype=np.int64)


def _residuals(frames: _Frames, matches: _Matches) -> _Residuals:
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
        parts.append(_Residuals(r, J, np.full(r.size, kind_id, dtype=np.int8), pair))
    if not parts:
        return _Residuals.empty()
    return _Residuals(
        np.concatenate([p.r for p in parts]),
        np.vstack([p.J for p in parts]),
        np.concatenate([p.kind for p in parts]),
        np.vstack([p.frames for p in parts]),
    )


def _point_rows(
    frames: _Frames, kind: _Kind, points: NDArray[np.int64], P: FloatArray, a: FloatArray
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


def _partners(pairs: Sequence[tuple[int, int]], n: int) -> list[NDArray[np.int64]]:
    """For each frame the frames paired with it (the sources compared against it)."""
    out: list[list[int]] = [[] for _ in range(n)]
    for a, b in pairs:
        out[a].append(b)
        out[b].append(a)
    return [np.array(sorted(p), dtype=np.int64) for p in out]


# --------------------------------------------------------------------------- weights


def _scales(res: _Residuals) -> FloatArray:
    """Robust spread (mm) of each kind: 1.4826 × MAD, floored at 0.05 mm."""
    scales = np.ones(2)
    for kind in (0, 1):
        r = res.r[res.kind == kind]
        if r.size >= 10:
            scales[kind] = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 0.05)
    return scales


def _weights(res: _Residuals, scales: FloatArray) -> FloatArray:
    """Huber weight / scale² per residual (whitened least squares)."""
    s = scales[res.kind]
    u = np.abs(res.r) / s
    w = np.where(u <= HUBER_K, 1.0, HUBER_K / np.maximum(u, 1e-12))
    return np.asarray(w / (s * s))


def _normal_equations(res: _Residuals, w: FloatArray) -> tuple[FloatArray, FloatArray]:
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


# --------------------------------------------------------------------------- the solve


def solve(
    observations: Sequence[FrameObservation],
    trajectory: Trajectory,
    published: CameraMount,
    config: CalibrationConfig,
) -> Solution:
    """The correction to ``published`` that makes the frames agree (see the module docstring).

    Parameters
    ----------
    observations : sequence of FrameObservation
        Camera-frame measurements of the frames to compare (at least 2).
    trajectory : callable
        ``trajectory(stamps_ns)`` -> (T_base_moving (N, 4, 4), valid (N,)) on the TF clock.
    published : CameraMount
        The mount and offset the recording publishes; the correction is relative to it.
    config : CalibrationConfig

    Raises
    ------
    CalibrationError
        Fewer than two frames, or no pair of frames that overlap.
    """
    obs = [o for o in observations if len(o.surface) > 0]
    if len(obs) < 2:
        raise CalibrationError(
            f"{len(obs)} frame(s) with valid depth: the calibration compares frames with each "
            "other and needs at least 2 that overlap"
        )
    stamps = np.array([o.stamp_ns for o in obs], dtype=np.int64)
    frames = _Frames(obs, stamps, published, trajectory)
    zero = np.zeros(7)
    frames.pose(zero)
    if not frames.motion.valid.all():
        bad = int(np.count_nonzero(~frames.motion.valid))
        raise CalibrationError(f"{bad} frame(s) lie outside the /tf time range")
    pairs = select_pairs(
        obs,
        frames.motion.origin_velocity,
        partners=config.partners,
        min_overlap=config.min_overlap,
    )
    frames.partners = _partners(pairs, len(obs))
    if not pairs:
        raise CalibrationError(
            f"none of the {len(obs)} frames overlap (less than {100 * config.min_overlap:g} % "
            "shared surface): the calibration compares overlapping views"
        )
    tau = _tolerances(config)
    prior = 1.0 / np.square(_prior_sigmas(config))  # information per PARAMETERS unit

    # 1. All seven parameters, weakly held by the prior.
    x, res, scales, gate, iterations = _iterate(frames, zero, None, prior, config)
    # 2. Observability at that solution; 3. again with the unobservable directions held.
    analysis = _analyse(frames, res, scales, x, prior, tau, config)
    basis = analysis.observable_basis  # (7, m) in PARAMETERS units (columns)
    if basis.shape[1] < 7:
        x0 = _project(x, basis, tau)
        x, res, scales, gate, more = _iterate(frames, x0, basis, prior, config, warm=True)
        iterations += more
    sigma = _sigmas(frames, res, scales, x, basis, prior)
    observable = _observable_parameters(analysis.unobservable_vectors, tau)
    sigma = np.where(observable, sigma, np.nan)

    after = _rms_of(res)
    before = _rms_of(_residuals_at(frames, zero, gate))
    return Solution(
        correction=x,
        sigma=sigma,
        observable=observable,
        unobservable=analysis.unobservable,
        residual_before_mm=before,
        residual_after_mm=after,
        frames=len(obs),
        pairs=len(pairs),
        residuals=len(res.r),
        iterations=iterations,
        eigen=analysis.eigen,
    )


def _tolerances(config: CalibrationConfig) -> FloatArray:
    """One analysis unit per parameter, in PARAMETERS units."""
    return np.array(
        [1000.0 * config.observable_sigma_m] * 3
        + [config.observable_sigma_deg] * 3
        + [1000.0 * config.observable_sigma_s]
    )


def _prior_sigmas(config: CalibrationConfig) -> FloatArray:
    return np.array(
        [1000.0 * config.prior_translation_m] * 3
        + [config.prior_rotation_deg] * 3
        + [1000.0 * config.prior_time_offset_s]
    )


def _iterate(
    frames: _Frames,
    x0: FloatArray,
    basis: FloatArray | None,
    prior: FloatArray,
    config: CalibrationConfig,
    *,
    warm: bool = False,
) -> tuple[FloatArray, _Residuals, FloatArray, float, int]:
    """Gauss-Newton with re-found correspondences; returns x, residuals, scales, gate, steps.

    Correspondences are found once per gate and kept for ``STEPS_PER_MATCH`` steps. ``basis``
    (7, m): move only within its columns (None: all parameters). ``warm``: start at the
    narrowest gate (the correspondences are already good).
    """
    x = np.array(x0, dtype=np.float64)
    gates = _gates(config)
    if warm:
        gates = gates[-2:]
    P = np.diag(prior)
    steps = 0
    tolerance = 1e-3 * _tolerances(config)
    for gate in gates:
        frames.pose(x)
        matches = _match(frames, frames.partners, gate)
        small = False
        for _ in range(STEPS_PER_MATCH):
            res = _residuals(frames, matches)
            if len(res.r) < 7:
                raise CalibrationError(
                    f"only {len(res.r)} corresponding points between the overlapping frames"
                )
            H, g = _normal_equations(res, _weights(res, _scales(res)))
            A = H + P
            b = -(g + P @ x)
            if basis is None:
                step = np.linalg.solve(A, b)
            else:
                step = basis @ np.linalg.solve(basis.T @ A @ basis, basis.T @ b)
            x = x + step
            steps += 1
            frames.pose(x)
            small = bool(np.all(np.abs(step) < tolerance))
            if small:
                break
        if small and gate == gates[-1]:
            break
    matches = _match(frames, frames.partners, gates[-1])
    res = _residuals(frames, matches)
    return x, res, _scales(res), gates[-1], steps


def _gates(config: CalibrationConfig) -> list[float]:
    """Correspondence gates (m): from max_distance_m down to min_distance_m, then held."""
    n = max(config.iterations, 2)
    hi, lo = config.max_distance_m, config.min_distance_m
    shrink = max(2, n * 2 // 3)
    out = [hi * (lo / hi) ** (j / (shrink - 1)) for j in range(shrink)]
    return out + [lo] * (n - shrink)


def _project(x: FloatArray, basis: FloatArray, tau: FloatArray) -> FloatArray:
    """``x`` without its components outside ``basis`` (orthogonal in analysis units)."""
    u = x / tau
    B = basis / tau[:, None]
    Q, _ = np.linalg.qr(B)
    return np.asarray((Q @ (Q.T @ u)) * tau)


def _residuals_at(frames: _Frames, x: FloatArray, gate: float) -> _Residuals:
    """The residuals with correction ``x``, correspondences found again within ``gate``."""
    frames.pose(x)
    return _residuals(frames, _match(frames, frames.partners, gate))


def _rms_of(res: _Residuals) -> dict[str, float]:
    """RMS (mm) of residuals per kind (``surface``, ``edge``) and ``all``."""
    out = {}
    for name, sel in ((SURFACE, res.kind == 0), (EDGE, res.kind == 1), ("all", slice(None))):
        r = res.r[sel]
        out[name] = float(np.sqrt(np.mean(r * r))) if r.size else float("nan")
    return out


# --------------------------------------------------------------------------- uncertainty


def _jackknife(
    res: _Residuals,
    w: FloatArray,
    A: FloatArray,
    n_frames: int,
) -> FloatArray:
    """Leave-one-frame-out covariance (k, k) of a linearised problem with matrix ``A``.

    ``res.J`` is in the problem's parameters (k columns); at the solution the gradient of the
    whole problem vanishes, so dropping frame f's residuals moves the estimate by
    ``(A − H_f)⁻¹ g_f``.
    """
    k = A.shape[0]
    deltas = []
    Jw = res.J * w[:, None]
    for f in range(n_frames):
        sel = (res.frames[:, 0] == f) | (res.frames[:, 1] == f)
        if not sel.any():
            continue
        H_f = Jw[sel].T @ res.J[sel]
        g_f = Jw[sel].T @ res.r[sel]
        try:
            deltas.append(np.linalg.solve(A - H_f, g_f))
        except np.linalg.LinAlgError:
            continue
    if len(deltas) < 3:
        return np.zeros((k, k))
    D = np.array(deltas)
    D -= D.mean(axis=0)
    m = len(deltas)
    return np.asarray((m - 1) / m * (D.T @ D))


def _formal_variance_factor(res: _Residuals, w: FloatArray, k: int) -> float:
    """Σ w r² / (n − k): the whitened residuals' variance (1 when the scales are right)."""
    n = len(res.r)
    return float(np.sum(w * res.r * res.r) / max(n - k, 1))


def _sigmas(
    frames: _Frames,
    res: _Residuals,
    scales: FloatArray,
    x: FloatArray,
    basis: FloatArray,
    prior: FloatArray,
) -> FloatArray:
    """Standard deviation (7,) of each parameter within the observable ``basis``."""
    w = _weights(res, scales)
    Jb = res.J @ basis
    sub = _Residuals(res.r, Jb, res.kind, res.frames)
    A = Jb.T @ (Jb * w[:, None]) + basis.T @ np.diag(prior) @ basis
    formal = np.linalg.inv(A) * _formal_variance_factor(res, w, basis.shape[1])
    jack = _jackknife(sub, w, A, len(frames.obs))
    cov = np.maximum(np.diag(basis @ formal @ basis.T), np.diag(basis @ jack @ basis.T))
    return np.sqrt(cov)


@dataclass(frozen=True)
class _Analysis:
    observable_basis: FloatArray  # (7, m)
    unobservable_vectors: FloatArray  # (7, 7 - m) unit in analysis units
    unobservable: tuple[Direction, ...]
    eigen: list[dict[str, object]]


def _analyse(
    frames: _Frames,
    res: _Residuals,
    scales: FloatArray,
    x: FloatArray,
    prior: FloatArray,
    tau: FloatArray,
    config: CalibrationConfig,
) -> _Analysis:
    """Eigen-analysis of the data's normal equations in analysis units (module docstring)."""
    w = _weights(res, scales)
    Ju = res.J * tau[None, :]  # d r / d u with x = tau * u
    H = Ju.T @ (Ju * w[:, None])
    H = 0.5 * (H + H.T)
    values, vectors = np.linalg.eigh(H)
    factor = max(_formal_variance_factor(res, w, 7), 1.0)
    # The jackknife of the weakly regularised problem, in analysis units.
    sub = _Residuals(res.r, Ju, res.kind, res.frames)
    A = H + np.diag(prior * tau * tau)
    jack = _jackknife(sub, w, A, len(frames.obs))
    eigen: list[dict[str, object]] = []
    unobservable_idx = []
    for j in range(7):
        v = vectors[:, j]
        formal = factor / values[j] if values[j] > 0 else math.inf
        var = max(formal, float(v @ jack @ v))
        sigma = math.sqrt(var) if math.isfinite(var) else math.inf
        eigen.append(
            {
                "sigma": sigma if math.isfinite(sigma) else None,
                "vector": [round(float(c), 4) for c in v],
            }
        )
        if not sigma <= 1.0:
            unobservable_idx.append(j)
    U = vectors[:, unobservable_idx]
    kept = vectors[:, [j for j in range(7) if j not in unobservable_idx]]
    context = _Context.of(frames)
    directions = tuple(
        _describe(vectors[:, j], eigen[j]["sigma"], context) for j in unobservable_idx
    )
    return _Analysis(
        observable_basis=kept * tau[:, None],
        unobservable_vectors=U,
        unobservable=directions,
        eigen=eigen,
    )


def _observable_parameters(unobservable: FloatArray, tau: FloatArray) -> NDArray[np.bool_]:
    """A parameter is observable when less than a quarter of it lies in unobservable
    directions (in analysis units)."""
    if unobservable.shape[1] == 0:
        return np.ones(7, dtype=bool)
    share = np.sum(unobservable * unobservable, axis=1)  # |projection of e_j|²
    return np.asarray(share < 0.25)


# --------------------------------------------------------------------------- words


@dataclass(frozen=True)
class _Context:
    """What the scan's motion looks like, to explain an unobservable direction."""

    max_angle_deg: float  # largest rotation between any two frames
    rotation_axis_cam: FloatArray | None  # (3,) when all rotations share one axis
    max_speed_m_s: float  # fastest moving-frame motion at a capture time
    flat: bool  # all surface normals within 10 degrees of one direction
    travel_line_cam: FloatArray | None  # (3,) when the camera only slid along one line

    @staticmethod
    def of(frames: _Frames) -> _Context:
        R = frames.T[:, :3, :3]
        rotvecs = []
        for i in range(len(R)):
            rel = Rotation.from_matrix(np.einsum("ji,njk->nik", R[i], R))  # R_iᵀ R_k, camera i
            rotvecs.append(rel.as_rotvec())
        rv = np.vstack(rotvecs)
        angles = np.linalg.norm(rv, axis=1)
        max_angle = float(np.degrees(angles.max())) if angles.size else 0.0
        axis = None
        big = rv[angles > math.radians(1.0)]
        if len(big) >= 1:
            _, s, vt = np.linalg.svd(big, full_matrices=False)
            if len(s) == 1 or s[1] < 0.1 * s[0]:
                axis = vt[0]
        speeds = np.linalg.norm(frames.motion.origin_velocity, axis=1)
        normals = np.vstack([o.normals @ frames.T[f, :3, :3].T for f, o in enumerate(frames.obs)])
        mean = normals.mean(axis=0)
        mean /= max(float(np.linalg.norm(mean)), 1e-12)
        flat = bool(np.quantile(normals @ mean, 0.05) > math.cos(math.radians(10.0)))
        line = None
        if max_angle < 2.0 and len(R) >= 2:
            shifts = (frames.T[:, :3, 3] - frames.T[0, :3, 3]) @ R[0]  # camera 0's axes
            _, s, vt = np.linalg.svd(shifts, full_matrices=False)
            if s[0] > 1e-3 and (len(s) < 2 or s[1] < 0.1 * s[0]):
                line = vt[0]
        return _Context(max_angle, axis, float(speeds.max()), flat, line)


_AXES = ("x (across the image)", "y (down the image)", "z (the optical axis)")


def _describe(vector: FloatArray, sigma: object, context: _Context) -> Direction:
    """Words for an unobservable eigen-direction (analysis units) and why."""
    v = np.asarray(vector, dtype=np.float64)
    groups = {"translation": v[0:3], "rotation": v[3:6], "time": v[6:7]}
    weight = {k: float(np.sum(g * g)) for k, g in groups.items()}
    main = max(weight, key=lambda k: weight[k])
    if main == "time":
        what = "the clock offset between the camera and /tf"
        if context.max_speed_m_s < 0.005:
            why = "the arm never moved while images were taken: the time offset is not observable"
        else:
            why = (
                f"the arm moved slowly while images were taken (at most "
                f"{1000 * context.max_speed_m_s:.0f} mm/s): the time offset is weakly determined"
            )
    else:
        g = groups[main] / math.sqrt(weight[main])
        along = _axis_text(g)
        what = f"{main} {'along' if main == 'translation' else 'about'} {along}"
        if main == "translation" and context.max_angle_deg < 2.0:
            why = (
                "all views share one orientation: a mount translation moves every frame alike "
                "and is not observable"
            )
        elif main == "translation" and context.rotation_axis_cam is not None:
            why = (
                f"the views differ only by rotation about one axis "
                f"({_vector_text(context.rotation_axis_cam)} in the camera frame): translation "
                "along it is not observable"
            )
        elif (
            main == "rotation"
            and context.travel_line_cam is not None
            and abs(float(g @ context.travel_line_cam)) > 0.9
        ):
            why = (
                f"the camera only moved along one line ({_axis_text(context.travel_line_cam)}) "
                "without turning: rotation about that line is not observable"
            )
        elif context.flat:
            why = "the surface seen is flat and the paint's edges do not constrain this direction"
        else:
            why = "the views and the surface seen do not constrain this direction"
    return Direction(
        vector=tuple(round(float(c), 4) for c in v),
        sigma=float(sigma) if isinstance(sigma, float) else math.inf,
        what=what,
        why=why,
    )


def _axis_text(v: FloatArray) -> str:
    """``camera y (down the image)`` when ``v`` is close to an axis, else its components."""
    axis = int(np.argmax(np.abs(v)))
    return f"camera {_AXES[axis]}" if abs(v[axis]) > 0.9 else _vector_text(v)


def _vector_text(v: FloatArray) -> str:
    return "(" + ", ".join(f"{c:+.2f}" for c in v) + ")"
