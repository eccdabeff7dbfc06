"""Nearest-neighbour kernels of the per-frame perception, compiled where possible.

Each frame asks two neighbour questions of a few thousand points: the statistical outlier
removal's 20 nearest neighbours of every paint voxel, and which surface samples lie within the
band around the paint. A k-d tree answers them at a few microseconds a query; a uniform grid
in C (``_native.c``, built by pip with the package as an optional extension) answers the same
questions exactly, 1.6 (outliers) and 3.3 (band) times as fast at a frame's sizes
(``benchmarks/bench_kernels.py``). Where the extension did not build (no C compiler), or with
``SCRAPCUT_NATIVE=0`` in the environment, the same results come from open3d and scipy; so
they do for a cloud the grid does not suit (a dense knot in a sparse cloud), which the compiled
outlier removal declines. The band's targets are the paint's centroids on a grid a quarter of
the band wide, so a cell of the band's size holds a few tens of them.

The compiled outlier removal follows open3d's ``remove_statistical_outlier`` to the bit: the
mean distance to the k nearest points (the point itself among them) summed in ascending order,
the cloud's mean and standard deviation of those means (divided by N and N - 1, over positive
means), kept when positive and below mean + ratio × deviation. The within-distance test is
scipy's ``cKDTree.query(..., distance_upper_bound=r)`` being finite: squared distance below r².
"""

from __future__ import annotations

import os
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli._open3d import o3d


def _load_native() -> ModuleType | None:
    if os.environ.get("SCRAPCUT_NATIVE", "").strip() == "0":
        return None
    try:
        from scrapcut_cli import _native
    except ImportError:
        return None
    return _native


_native = _load_native()


def native() -> bool:
    """Whether the compiled kernels are in use."""
    return _native is not None


def statistical_inliers(points: ArrayLike, *, neighbors: int, std_ratio: float) -> NDArray[np.intp]:
    """Indices (M,) ascending of the points (N, 3) open3d's statistical outlier removal keeps
    with ``nb_neighbors=neighbors`` and ``std_ratio``; all of them when ``neighbors`` is 0 or
    not below N."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if neighbors == 0 or len(pts) <= neighbors:
        return np.arange(len(pts), dtype=np.intp)
    if _native is not None and std_ratio > 0 and np.isfinite(pts).all():
        keep = np.empty(len(pts), dtype=np.uint8)
        # -1: a cloud of dense and sparse parts, which no one grid suits: open3d's tree
        if _native.statistical_inliers(pts, neighbors, float(std_ratio), keep) >= 0:
            return np.flatnonzero(keep)
    o3 = o3d()
    cloud = o3.geometry.PointCloud(o3.utility.Vector3dVector(pts))
    _, kept = cloud.remove_statistical_outlier(nb_neighbors=neighbors, std_ratio=std_ratio)
    return np.asarray(kept, dtype=np.intp)


def within_distance(points: ArrayLike, targets: ArrayLike, radius: float) -> NDArray[np.bool_]:
    """(N,) whether each point (N, 3) lies closer than ``radius`` to some target (M, 3)."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    tgt = np.ascontiguousarray(targets, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0 or len(tgt) == 0 or not radius > 0:
        return np.zeros(len(pts), dtype=bool)
    if (
        _native is not None
        and np.isfinite(radius)
        and np.isfinite(pts).all()
        and np.isfinite(tgt).all()
    ):
        hit = np.empty(len(pts), dtype=np.uint8)
        _native.within_distance(pts, tgt, float(radius), hit)
        return hit.view(bool)
    distance, _ = cKDTree(tgt).query(pts, distance_upper_bound=radius)
    return np.asarray(np.isfinite(distance))
