"""Surface normals at the set-points: robust local planes, camera orientation, edge-aware smoothing.

The normal at a set-point is the normal of the surface around it (a plane fitted to the observed
surface cloud, paint included, within ``radius_m``), not of the paint band alone. Near a sharp
edge (an I-beam's web-flange joint, a slanted edge) a plain PCA over the radius averages the two
faces; here the plane is fitted by iteratively reweighted PCA that starts from the points closest
to the set-point and down-weights points far from the current plane, so it settles on the face
the set-point lies on. Along the path, normals are smoothed with a bilateral, locally linear
filter: neighbours on another face (normals further apart than ``edge_angle_deg``) are left out,
and the linear term keeps a steadily turning normal (a pipe) unbiased up to the path's ends.

open3d's ``estimate_normals`` gives per-point normals of the cloud; what we need is one normal
per set-point from a weighted, face-aware neighbourhood, which no library call does, so the
weighted PCA is written here over flat (set-point, neighbour) pairs with ``np.bincount``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.toolpath.neighbours import ball_pairs

FloatArray = NDArray[np.float64]

#: A neighbourhood whose second spread is below this fraction of its first is a line (a wire of
#: a basket), whose normal PCA cannot tell: it is taken from the viewing direction instead.
LINE_RATIO = 0.2
#: Floor of the residual scale of the reweighting: depth noise of a D435i at 0.3-0.5 m is
#: 0.3-1 mm, so points within ~3 mm of the plane must keep most of their weight.
MIN_RESIDUAL_SCALE_M = 0.003
#: A fine neighbourhood whose points sit further than this (weighted RMS) from their plane is
#: not a surface at that scale (wire mesh, heavy noise): the coarse radius decides there. A
#: stitched D435i cloud at 0.3-0.5 m is 0.3-0.7 mm RMS on a plate.
ROUGH_RMS_M = 0.0006


@dataclass(frozen=True, eq=False)
class NormalEstimate:
    """Normals at query points.

    Attributes
    ----------
    normals : (N, 3) float64
        Unit normals oriented towards the cameras that observed the neighbourhood; rows without
        support are zero.
    support : (N,) int64
        Surface points within the radius.
    supported : (N,) bool
        ``support >= min_points``.
    line_like : (N,) bool
        The neighbourhood is a line (a wire); the normal is the viewing direction made
        perpendicular to it.
    coarse : (N,) bool
        The fine neighbourhood was rough; the normal comes from the coarse radius.
    rms_m : (N,) float64
        Weighted RMS distance of the fine neighbourhood to its plane, metres.
    """

    normals: FloatArray
    support: NDArray[np.int64]
    supported: NDArray[np.bool_]
    line_like: NDArray[np.bool_]
    coarse: NDArray[np.bool_]
    rms_m: FloatArray


def estimate_normals(
    points_base: FloatArray,
    surface_base: FloatArray,
    surface_viewpoints: FloatArray,
    *,
    radius_m: float,
    min_points: int = 8,
    iterations: int = 3,
) -> NormalEstimate:
    """Surface normals at ``points_base`` from the observed surface around each point.

    Parameters
    ----------
    points_base : (N, 3) float64, metres, base frame
        Where normals are wanted (set-points on the fitted curve).
    surface_base : (M, 3) float64, metres, base frame
        The observed surface (surface band and paint points).
    surface_viewpoints : (M, 3) float64, metres, base frame
        Camera centre that observed each surface point; normals point towards them.
    radius_m : float
        Neighbourhood radius.
    min_points : int
        Fewer neighbours than this: the row is not supported.
    iterations : int
        Reweighting passes after the local start.
    """
    points = np.asarray(points_base, dtype=np.float64).reshape(-1, 3)
    surface = np.asarray(surface_base, dtype=np.float64).reshape(-1, 3)
    viewpoints = np.asarray(surface_viewpoints, dtype=np.float64).reshape(-1, 3)
    fit = _fit_planes(points, cKDTree(surface), surface, viewpoints, radius_m, iterations)
    supported = fit.support >= max(min_points, 3)
    fit.normal[~supported] = 0.0
    return NormalEstimate(
        normals=fit.normal,
        support=fit.support,
        supported=supported,
        line_like=fit.line_like & supported,
        coarse=np.zeros(len(points), dtype=bool),
        rms_m=fit.rms,
    )


def estimate_path_normals(
    points_base: FloatArray,
    surface_base: FloatArray,
    surface_viewpoints: FloatArray,
    *,
    radius_m: float,
    coarse_radius_m: float,
    rough_rms_m: float = ROUGH_RMS_M,
    window: int = 7,
    min_points: int = 8,
) -> NormalEstimate:
    """Normals at points ordered along a path, at two scales.

    As :func:`estimate_normals` at ``radius_m``; where the surface along the path is rough at
    that scale — the running median (``window`` set-points) of the fine planes' RMS residual
    above ``rough_rms_m`` — the normal comes from ``coarse_radius_m`` instead. That is a wire
    mesh (two layers of 4 mm wires make no plane at 15 mm but do at 30 mm) or very noisy data.
    A sharp edge is rough only at the two or three set-points next to it, which the running
    median ignores, so edges keep the fine, face-true normals.
    """
    fine = estimate_normals(
        points_base, surface_base, surface_viewpoints, radius_m=radius_m, min_points=min_points
    )
    n = len(fine.rms_m)
    if n == 0 or coarse_radius_m <= radius_m:
        return fine
    half = max(window // 2, 0)
    j = np.clip(np.arange(n)[:, None] + np.arange(-half, half + 1)[None, :], 0, n - 1)
    rough = (np.median(fine.rms_m[j], axis=1) > rough_rms_m) & fine.supported
    if not rough.any():
        return fine
    wide = estimate_normals(
        np.asarray(points_base, dtype=np.float64).reshape(-1, 3)[rough],
        surface_base,
        surface_viewpoints,
        radius_m=coarse_radius_m,
        min_points=min_points,
    )
    normals = fine.normals.copy()
    line_like = fine.line_like.copy()
    normals[rough] = wide.normals
    line_like[rough] = wide.line_like
    return NormalEstimate(
        normals=normals,
        support=fine.support,
        supported=fine.supported,
        line_like=line_like,
        coarse=rough,
        rms_m=fine.rms_m,
    )


@dataclass(frozen=True, eq=False)
class _Planes:
    normal: FloatArray  # (n, 3), oriented to the viewpoints
    line_like: NDArray[np.bool_]  # (n,)
    rms: FloatArray  # (n,) weighted RMS residual of the final plane, metres
    support: NDArray[np.int64]  # (n,) points within the radius


def _fit_planes(
    points: FloatArray,
    tree: cKDTree,
    surface: FloatArray,
    viewpoints: FloatArray,
    radius_m: float,
    iterations: int,
) -> _Planes:
    """Iteratively reweighted local planes at ``points`` (see the module docstring)."""
    n = len(points)
    rows, index = ball_pairs(tree, points, radius_m)
    support = np.bincount(rows, minlength=n).astype(np.int64)
    q = surface[index]
    d2 = np.einsum("ij,ij->i", q - points[rows], q - points[rows])
    # Distance weights: the start only trusts the closest points (sigma r/4), later passes the
    # whole ball (sigma r/2) but only where points fit the current plane.
    w_ball = np.exp(-d2 / (2.0 * (radius_m / 2.0) ** 2))
    weights = np.exp(-d2 / (2.0 * (radius_m / 4.0) ** 2))
    tau = max(MIN_RESIDUAL_SCALE_M, radius_m / 5.0)
    for _ in range(iterations):
        centroid, _, vectors = _weighted_pca(rows, q, weights, n)
        residual = np.einsum("ij,ij->i", q - centroid[rows], vectors[rows, :, 0])
        weights = w_ball * np.exp(-((residual / tau) ** 2))
    centroid, eigenvalues, vectors = _weighted_pca(rows, q, weights, n)
    normal = np.ascontiguousarray(vectors[:, :, 0])  # least spread
    axis = vectors[:, :, 2]  # largest spread
    residual = np.einsum("ij,ij->i", q - centroid[rows], normal[rows])
    total = np.bincount(rows, weights=weights, minlength=n).astype(np.float64)
    rms = np.sqrt(
        np.bincount(rows, weights=weights * residual**2, minlength=n) / np.maximum(total, 1e-300)
    )

    view = viewpoints[index] - q
    view /= np.maximum(np.linalg.norm(view, axis=1, keepdims=True), 1e-12)
    mean_view = _row_sums(rows, view * w_ball[:, None], n)
    mean_view /= np.maximum(np.linalg.norm(mean_view, axis=1, keepdims=True), 1e-12)

    line_like = eigenvalues[:, 1] < (LINE_RATIO**2) * eigenvalues[:, 2]
    along = np.einsum("ij,ij->i", mean_view, axis)
    from_view = mean_view - along[:, None] * axis
    norm = np.linalg.norm(from_view, axis=1)
    use_view = line_like & (norm > 1e-6)
    normal[use_view] = from_view[use_view] / norm[use_view, None]

    sign = np.where(np.einsum("ij,ij->i", normal, mean_view) < 0.0, -1.0, 1.0)
    normal *= sign[:, None]
    return _Planes(normal=normal, line_like=line_like, rms=rms, support=support)


def fill_unsupported(
    arc_length: FloatArray, normals: FloatArray, supported: NDArray[np.bool_]
) -> FloatArray:
    """Normals (N, 3) with unsupported rows interpolated along the path from supported ones.

    Gaps (the basket's wires, a shadow) get the normal interpolated in arc length between the
    supported set-points on either side, held constant beyond the first and last.
    """
    out = np.array(normals, dtype=np.float64, copy=True)
    ok = np.asarray(supported, dtype=bool)
    if ok.all() or not ok.any():
        return out
    s_ok = arc_length[ok]
    filled = np.column_stack([np.interp(arc_length, s_ok, out[ok, k]) for k in range(3)])
    norm = np.linalg.norm(filled, axis=1)
    # Interpolating between opposite normals can cancel out: take the nearest supported one
    # (of the supported set-points just before and just after, the closer in arc length).
    after = np.clip(np.searchsorted(s_ok, arc_length), 0, len(s_ok) - 1)
    before = np.clip(after - 1, 0, len(s_ok) - 1)
    closer = np.where(
        np.abs(arc_length - s_ok[before]) <= np.abs(s_ok[after] - arc_length), before, after
    )
    nearest = np.flatnonzero(ok)[closer]
    bad = norm < 0.5
    filled[bad] = out[nearest[bad]]
    filled[~bad] /= norm[~bad, None]
    out[~ok] = filled[~ok]
    return out


def smooth_along_path(
    arc_length: FloatArray,
    normals: FloatArray,
    *,
    sigma_m: float,
    edge_angle_deg: float,
) -> FloatArray:
    """Edge-aware smoothing of unit normals (N, 3) along the path (arc length (N,), metres).

    A locally linear fit in arc length with Gaussian weights (sigma ``sigma_m``) over the
    neighbours whose normal is within ``edge_angle_deg`` of the row's own: faces are smoothed,
    edges stay sharp (the transition set-point at an edge keeps its own, bisecting, normal).
    """
    n_rows = len(arc_length)
    normals = np.asarray(normals, dtype=np.float64)
    if n_rows < 3 or sigma_m <= 0:
        return normals.copy()
    steps = np.diff(arc_length)
    step = float(np.median(steps[steps > 0])) if np.any(steps > 0) else sigma_m
    half = int(min(max(np.ceil(2.5 * sigma_m / step), 1), n_rows - 1))
    offsets = np.arange(-half, half + 1)
    j = np.arange(n_rows)[:, None] + offsets[None, :]
    valid = (j >= 0) & (j < n_rows)
    j = np.clip(j, 0, n_rows - 1)
    ds = arc_length[j] - arc_length[:, None]
    nj = normals[j]
    cos = np.einsum("nwk,nk->nw", nj, normals)
    w = np.exp(-0.5 * (ds / sigma_m) ** 2) * valid * (cos >= np.cos(np.radians(edge_angle_deg)))
    s0 = w.sum(axis=1)
    s1 = (w * ds).sum(axis=1)
    s2 = (w * ds * ds).sum(axis=1)
    t0 = np.einsum("nw,nwk->nk", w, nj)
    t1 = np.einsum("nw,nwk->nk", w * ds, nj)
    det = s0 * s2 - s1 * s1
    linear = det > 1e-9 * np.maximum(s0 * s2, 1e-300)
    safe = np.where(linear, det, 1.0)
    fitted = np.where(
        linear[:, None],
        (s2[:, None] * t0 - s1[:, None] * t1) / safe[:, None],
        t0 / np.maximum(s0, 1e-300)[:, None],
    )
    norm = np.linalg.norm(fitted, axis=1)
    keep = norm < 1e-9
    fitted[~keep] /= norm[~keep, None]
    fitted[keep] = normals[keep]
    return np.asarray(fitted)


# --------------------------------------------------------------------------- weighted PCA


def _row_sums(rows: NDArray[np.int64], values: FloatArray, n: int) -> FloatArray:
    """Per-row sums (n, K) of pair values (P, K)."""
    # bincount of no pairs returns integers; sums are always float here.
    return np.column_stack(
        [np.bincount(rows, weights=values[:, k], minlength=n) for k in range(values.shape[1])]
    ).astype(np.float64)


def _weighted_covariance(
    rows: NDArray[np.int64], q: FloatArray, w: FloatArray, n: int
) -> tuple[FloatArray, FloatArray]:
    """Weighted centroids (n, 3) and covariances (n, 3, 3) of each row's neighbours."""
    total = np.bincount(rows, weights=w, minlength=n).astype(np.float64)
    safe = np.where(total > 0, total, 1.0)
    centroid = _row_sums(rows, q * w[:, None], n) / safe[:, None]
    x = q - centroid[rows]
    cov = np.zeros((n, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            c = np.bincount(rows, weights=w * x[:, a] * x[:, b], minlength=n) / safe
            cov[:, a, b] = c
            cov[:, b, a] = c
    cov[total <= 0] = np.eye(3)
    return centroid, cov


def _weighted_pca(
    rows: NDArray[np.int64], q: FloatArray, w: FloatArray, n: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Centroids (n, 3), eigenvalues (n, 3) ascending and eigenvectors (n, 3, 3) as columns."""
    centroid, cov = _weighted_covariance(rows, q, w, n)
    eigenvalues, eigenvectors = np.linalg.eigh(cov)
    return centroid, eigenvalues, eigenvectors
