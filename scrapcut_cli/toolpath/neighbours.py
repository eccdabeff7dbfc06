"""Fixed-radius neighbourhoods as flat (row, index) pairs, so per-query sums vectorise."""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree


def ball_pairs(
    tree: cKDTree, centres: NDArray[np.float64], radius: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """All (query row, tree index) pairs within ``radius`` metres, rows ascending.

    ``centres`` : (N, 3) float64, metres. Returns two (P,) int64 arrays; per-row reductions are
    then ``np.bincount(rows, weights, minlength=N)`` instead of a Python loop over queries.
    """
    if len(centres) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty.copy()
    lists = tree.query_ball_point(centres, radius, return_sorted=True)
    counts = np.fromiter((len(c) for c in lists), dtype=np.int64, count=len(lists))
    rows = np.repeat(np.arange(len(lists), dtype=np.int64), counts)
    index = np.fromiter(itertools.chain.from_iterable(lists), dtype=np.int64, count=rows.size)
    return rows, index
