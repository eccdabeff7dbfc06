"""Torch collision check against the observed cloud, and the tilt search that avoids it.

The torch body is a cylinder (``length_m``, ``radius_m``) that starts at the nozzle tip and runs
away from the surface along the torch axis. The jet must hit the same surface point whatever the
tilt, so a tilted torch pivots about the surface point: tip = surface point + standoff · axis.
A set-point collides when at least ``min_points`` observed points lie inside the body (a lone
speck of noise does not stop the cut). Colliding set-points try tilts up to ``max_tilt_deg`` in
``directions`` directions around the normal, smallest tilt first; among the free candidates of
a tilt the one with the fewest points inside a 25 % wider body (the most clearance) wins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.geometry import pack_voxel_keys, voxel_keys
from scrapcut_cli.toolpath.neighbours import ball_pairs

FloatArray = NDArray[np.float64]

#: Radius factor of the body used to rank free tilt candidates by clearance.
CLEARANCE_FACTOR = 1.25
#: The cloud is thinned to one point per voxel of this fraction of the torch radius before the
#: check: finer detail cannot change whether a 12 mm body touches it, and a dense cloud would
#: make the check quadratic in its density.
THINNING_FRACTION = 0.25
#: ... but never finer than this: voxel indices must stay packable (±2^20 voxels, ±100 m here).
MIN_THINNING_M = 1e-4


@dataclass(frozen=True, eq=False)
class TorchAxes:
    """Chosen torch axes.

    Attributes
    ----------
    axes : (N, 3) float64
        Unit torch axes pointing from the surface to the torch (the normal when not tilted).
    tilt_rad : (N,) float64
        Angle between axis and normal, radians.
    tilted : (N,) bool
        The normal collided and a tilted axis is free.
    colliding : (N,) bool
        No candidate within the tilt bound is free; the axis stays the normal.
    """

    axes: FloatArray
    tilt_rad: FloatArray
    tilted: NDArray[np.bool_]
    colliding: NDArray[np.bool_]


def choose_torch_axes(
    surface_points: FloatArray,
    normals: FloatArray,
    tangents: FloatArray,
    cloud_base: FloatArray,
    *,
    standoff_m: float,
    length_m: float,
    radius_m: float,
    max_tilt_deg: float,
    tilt_steps: int = 4,
    directions: int = 8,
    min_points: int = 3,
) -> TorchAxes:
    """Collision-free torch axes, tilting where the perpendicular torch hits the observed cloud.

    Parameters
    ----------
    surface_points : (N, 3) float64, metres, base frame
        Points on the surface the jet must hit.
    normals : (N, 3) float64
        Unit surface normals (out of the surface).
    tangents : (N, 3) float64
        Unit curve tangents, used to lay out the tilt directions.
    cloud_base : (M, 3) float64, metres, base frame
        Observed points (surface and paint) the torch must not touch.
    """
    pts = np.asarray(surface_points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    n = len(pts)
    axes = nrm.copy()
    tilt = np.zeros(n)
    tilted = np.zeros(n, dtype=bool)
    cloud = np.asarray(cloud_base, dtype=np.float64).reshape(-1, 3)
    if n == 0 or len(cloud) == 0:
        return TorchAxes(axes, tilt, tilted, np.zeros(n, dtype=bool))
    cloud = thin_cloud(cloud, max(THINNING_FRACTION * radius_m, MIN_THINNING_M))
    tree = cKDTree(cloud)

    def inside(
        sel_rows: NDArray[np.int64], sel_q: FloatArray, axis: FloatArray, r: float
    ) -> NDArray[np.bool_]:
        return _inside_body(pts[sel_rows], sel_q, axis, standoff_m, length_m, r)

    # The upright body lies in the ball around its own middle, which clears a flat surface
    # below it: few candidate points, however large the cloud.
    middle = pts + (standoff_m + 0.5 * length_m) * nrm
    rows, index = ball_pairs(tree, middle, float(np.hypot(0.5 * length_m, radius_m)))
    hits = np.bincount(rows[inside(rows, cloud[index], nrm[rows], radius_m)], minlength=n)
    pending = hits >= min_points
    if not pending.any() or max_tilt_deg <= 0 or tilt_steps <= 0:
        return TorchAxes(axes, tilt, tilted, pending)
    # Every tilted body pivots at the surface point: it lies in the ball of the body's reach
    # around it. Only colliding set-points search.
    todo = np.flatnonzero(pending)
    reach = float(np.hypot(standoff_m + length_m, CLEARANCE_FACTOR * radius_m))
    rows, index = ball_pairs(tree, pts[todo], reach)
    rows = todo[rows]
    q = cloud[index]

    # Tilt directions around the normal, laid out from the tangent so they are reproducible.
    u = tangents - np.einsum("ij,ij->i", tangents, nrm)[:, None] * nrm
    u_norm = np.linalg.norm(u, axis=1)
    fallback = np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    fallback = fallback - np.einsum("ij,ij->i", fallback, nrm)[:, None] * nrm
    u = np.where(u_norm[:, None] > 1e-9, u, fallback)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(nrm, u)
    phis = 2.0 * np.pi * np.arange(directions) / max(directions, 1)
    thetas = np.radians(max_tilt_deg) * np.arange(1, tilt_steps + 1) / tilt_steps

    for theta in thetas:
        if not pending.any():
            break
        pair = pending[rows]
        sub_rows, sub_q = rows[pair], q[pair]
        best_score = np.full(n, np.inf)
        best_axis = np.zeros((n, 3))
        for phi in phis:
            cand = np.cos(theta) * nrm + np.sin(theta) * (np.cos(phi) * u + np.sin(phi) * w)
            a = cand[sub_rows]
            count = np.bincount(sub_rows[inside(sub_rows, sub_q, a, radius_m)], minlength=n)
            score = np.bincount(
                sub_rows[inside(sub_rows, sub_q, a, CLEARANCE_FACTOR * radius_m)], minlength=n
            ).astype(np.float64)
            better = pending & (count < min_points) & (score < best_score)
            best_score[better] = score[better]
            best_axis[better] = cand[better]
        found = pending & np.isfinite(best_score)
        axes[found] = best_axis[found]
        tilt[found] = theta
        tilted[found] = True
        pending &= ~found
    return TorchAxes(axes, tilt, tilted, pending)


def _inside_body(
    surface_points: FloatArray,
    q: FloatArray,
    axis: FloatArray,
    standoff_m: float,
    length_m: float,
    radius_m: float,
) -> NDArray[np.bool_]:
    """Pairwise test (P,): is point ``q`` inside the body pivoting at ``surface_points``?"""
    v = q - (surface_points + standoff_m * axis)
    along = np.einsum("ij,ij->i", v, axis)
    radial2 = np.einsum("ij,ij->i", v, v) - along * along
    return np.asarray((along >= 0.0) & (along <= length_m) & (radial2 <= radius_m * radius_m))


def thin_cloud(points: FloatArray, voxel_m: float) -> FloatArray:
    """One point (the first, in input order) per occupied voxel of ``voxel_m`` metres."""
    _, first = np.unique(pack_voxel_keys(voxel_keys(points, voxel_m)), return_index=True)
    return np.asarray(points[np.sort(first)])
