"""Order an unordered curve-like cloud: positions along it, from one end to the other.

A principal axis orders the points of a nearly straight line, but folds an arc around a pipe or
a U back onto itself. Here the cloud is reduced to voxel centroids, joined by their minimum
spanning tree (which bridges gaps by their shortest crossing), and the tree's longest path
(its diameter) is the chain from one end of the line to the other. scipy's csgraph does the
graph work; the centroid reduction keeps the dense distance matrix small.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra, minimum_spanning_tree
from scipy.spatial.distance import pdist, squareform

from scrapcut_cli.fitting._common import arc_positions, moving_average
from scrapcut_cli.geometry import cumulative_length

FloatArray = NDArray[np.float64]


def voxel_centroids(
    points: FloatArray, voxel_m: float
) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
    """Centroids (K, 3) of the occupied voxels, point counts (K,), and each point's voxel (N,).

    Voxels are numbered in the order of their packed integer keys (x, then y, then z)."""
    keys = np.floor(points / voxel_m).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    packed = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, inverse, counts = np.unique(packed, return_inverse=True, return_counts=True)
    sums = np.column_stack(
        [np.bincount(inverse, weights=points[:, k], minlength=len(counts)) for k in range(3)]
    )
    return sums / counts[:, None], counts.astype(np.int64), inverse.astype(np.int64)


def tree_diameter(tree: object, *, start: int = 0) -> NDArray[np.int64]:
    """Node indices along the longest path of a weighted tree (sparse (K, K), either triangle).

    Two Dijkstra sweeps: the farthest node from any node is an end of a longest path, and the
    farthest node from that end is the other end. On a forest, the tree holding ``start``. On a
    graph with cycles the same sweeps give the shortest path between two nodes (nearly) the
    farthest apart.
    """
    d0 = dijkstra(tree, directed=False, indices=start)
    a = int(np.argmax(np.where(np.isfinite(d0), d0, -1.0)))
    da, pred = dijkstra(tree, directed=False, indices=a, return_predecessors=True)
    b = int(np.argmax(np.where(np.isfinite(da), da, -1.0)))
    path = [b]
    while path[-1] != a:
        path.append(int(pred[path[-1]]))
    return np.asarray(path[::-1], dtype=np.int64)


def geodesic_positions(
    points: FloatArray, *, voxel_m: float = 0.01, max_nodes: int = 250, neighbours: int = 8
) -> tuple[FloatArray, float]:
    """Each point's position (N,) along a curve-like cloud (N, 3), metres from one end, and the
    cloud's length.

    Voxel centroids are linked by their minimum spanning tree (which bridges gaps by their
    shortest crossing) plus links to each centroid's nearest neighbours no longer than 2.5
    typical tree edges (a longer one could jump between two turns of a helix or the arms of a
    U). Geodesic distances over that graph from one end (the node farthest from an arbitrary
    one) grow steadily along the cloud. The centroids are then averaged in slices of that
    distance, one voxel thick, into a chain down the middle of the cloud, and every point's
    position is the arc length of its projection on the chain: points across a wide band get
    the same position, which geodesic distances alone would not give them. Voxels holding
    fewer than a tenth of the median count (stray points) take no part. The voxel grows by 1.5x
    until at most ``max_nodes`` remain, keeping the dense distance matrix small.
    """
    size = float(voxel_m)
    while True:
        centroids, counts, _ = voxel_centroids(points, size)
        keep = counts >= max(1.0, 0.1 * float(np.median(counts)))
        if int(keep.sum()) <= max_nodes:
            break
        size *= 1.5
    nodes, weight = centroids[keep], counts[keep].astype(np.float64)
    if len(nodes) < 3:
        return _principal_positions(points)
    distances = squareform(pdist(nodes))
    tree = minimum_spanning_tree(distances)
    typical = float(np.median(tree.data))
    k = min(neighbours, len(nodes) - 1)
    near = np.argpartition(distances, k, axis=1)[:, : k + 1].ravel()  # self included
    rows = np.repeat(np.arange(len(nodes)), k + 1)
    short = (distances[rows, near] <= 2.5 * typical) & (rows != near)
    links = csr_matrix(
        (distances[rows[short], near[short]], (rows[short], near[short])), shape=distances.shape
    )
    # Element-wise maximum: an edge both in the tree and among the links keeps its length
    # (a sum would double it).
    graph = links.maximum(tree)
    d0 = dijkstra(graph, directed=False, indices=0)
    end = int(np.argmax(np.where(np.isfinite(d0), d0, -1.0)))
    along = dijkstra(graph, directed=False, indices=end)
    if not np.isfinite(along).all() or float(along.max()) <= 0.0:
        return _principal_positions(points)
    chain = _slab_chain(nodes, along, weight, size)
    if len(chain) < 2:
        return _principal_positions(points)
    # Slices of geodesic distance lean across a wide band (the far side is farther from the
    # end), so the chain zig-zags a little; slicing the points again across the chain itself
    # straightens it.
    position = _positions_on(chain, points)
    chain = _slab_chain(points, position, np.ones(len(points)), size)
    if len(chain) < 2:
        return _principal_positions(points)
    position = _positions_on(chain, points)
    return position, float(cumulative_length(chain)[-1])


@dataclass(frozen=True, eq=False)
class PaintChain:
    """A chain down the middle of a curve-like cloud (see :func:`paint_chain`).

    ``points`` (K, 3) from one end of the line to the other, or once round a loop from and back
    to (next to) its start; ``loop``: the cloud goes all the way round; ``used`` (N,): the
    points it was made from (strays and small detached blobs left out).
    """

    points: FloatArray
    loop: bool
    used: NDArray[np.bool_]


def paint_chain(
    points: FloatArray,
    *,
    voxel_m: float = 0.01,
    max_nodes: int = 400,
    link_factor: float = 5.0,
    neighbours: int = 8,
    chain_lines: bool = True,
) -> PaintChain:
    """The chain down the middle of a curve-like cloud (N, 3), and whether it is a loop.

    Voxel centroids (voxels holding under a tenth of the median count left out) are linked as
    in :func:`geodesic_positions`: their minimum spanning tree, whose links longer than
    ``link_factor`` typical ones are cut (the piece holding the most points is kept: stray
    blobs fall away, a wire mesh's gaps do not), plus links to near neighbours no longer than
    2.5 typical links (distances run smoothly along a wide band). Two Dijkstra sweeps give the
    two nodes farthest apart, a and b: the ends of a line, or two opposite points of a loop.
    With a disk around each cut out of the graph (wider than the band), a line leaves one piece
    and a loop two arcs, each joining the disks. A loop is then cut next to a, between the
    nodes nearer one arc and those nearer the other, and geodesic distances from a run once
    round it. Slices of the geodesic distance, one voxel thick, are averaged into the chain,
    which is straightened twice by slicing the points across it. ``chain_lines=False`` asks
    only whether the cloud is a loop: a line's chain is then not made (``points`` holds its
    two ends a and b).
    """
    size = float(voxel_m)
    while True:
        centroids, counts, inverse = voxel_centroids(points, size)
        keep = counts >= max(1.0, 0.1 * float(np.median(counts)))
        if int(keep.sum()) <= max_nodes:
            break
        size *= 1.25
    node_of = np.full(len(centroids), -1, dtype=np.int64)
    node_of[keep] = np.arange(int(keep.sum()))
    nodes, weight = centroids[keep], counts[keep].astype(np.float64)
    if len(nodes) < 3:
        return PaintChain(nodes.copy(), False, node_of[inverse] >= 0)
    distances = squareform(pdist(nodes))
    tree = minimum_spanning_tree(distances).tocoo()
    typical = float(np.median(tree.data))
    short = tree.data <= link_factor * typical
    pruned = csr_matrix(
        (tree.data[short], (tree.row[short], tree.col[short])), shape=distances.shape
    )
    _, labels = connected_components(pruned, directed=False)
    piece = np.flatnonzero(labels == int(np.argmax(np.bincount(labels, weights=weight))))
    used = np.isin(node_of[inverse], piece)
    if len(piece) < 3:
        return PaintChain(nodes[piece].copy(), False, used)
    nodes, weight = nodes[piece], weight[piece]
    distances = distances[np.ix_(piece, piece)]
    k = min(neighbours, len(nodes) - 1)
    near = np.argpartition(distances, k, axis=1)[:, : k + 1].ravel()
    rows = np.repeat(np.arange(len(nodes)), k + 1)
    ok = (rows != near) & (distances[rows, near] <= 2.5 * typical)
    links = csr_matrix((distances[rows[ok], near[ok]], (rows[ok], near[ok])), shape=distances.shape)
    graph = csr_matrix(links.maximum(pruned[piece][:, piece]))
    graph = csr_matrix(graph.maximum(graph.T))
    a = int(np.argmax(_finite(dijkstra(graph, directed=False, indices=0))))
    along = dijkstra(graph, directed=False, indices=a)
    b = int(np.argmax(_finite(along)))
    arcs = _loop_arcs(graph, nodes, distances, a, b, typical)
    is_loop = arcs is not None
    if not is_loop and not chain_lines:
        return PaintChain(nodes[[a, b]], False, used)
    if arcs is not None:
        along = _once_round(graph, a, arcs)
    if not np.isfinite(along).all() or float(along.max()) <= 0.0:
        return PaintChain(nodes[[a, b]], False, used)
    chain = _slab_chain(nodes, along, weight, size)
    members = points[used]
    for _ in range(2):
        if len(chain) < 2:
            break
        chain = _slab_chain(members, _positions_on(chain, members), np.ones(len(members)), size)
    return PaintChain(chain, is_loop, used)


def _finite(values: FloatArray) -> FloatArray:
    return np.where(np.isfinite(values), values, -1.0)


def _loop_arcs(
    graph: csr_matrix,
    nodes: FloatArray,
    distances: FloatArray,
    a: int,
    b: int,
    typical: float,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]] | None:
    """The two arcs (node masks) of a loop between a and b, every node given to the nearer, or
    None for a line: with the disks round a and b removed, fewer than two pieces of at least a
    tenth of the nodes each touch both disks."""
    radius = max(3.0 * typical, 2.0 * _band_half_width(nodes, distances, typical) + typical)
    disk = (distances[a] <= radius) | (distances[b] <= radius)
    rest = np.flatnonzero(~disk)
    if len(rest) < 2:
        return None
    _, labels = connected_components(graph[rest][:, rest], directed=False)
    sizes = np.bincount(labels)
    near_a, near_b = distances[a] <= radius, distances[b] <= radius
    touching = []
    for label in np.argsort(-sizes, kind="stable")[:2]:
        if sizes[label] < 0.1 * len(nodes):
            continue
        members = rest[labels == label]
        linked = graph[members].nonzero()[1]
        if near_a[linked].any() and near_b[linked].any():
            touching.append(members)
    if len(touching) < 2:
        return None
    d1 = dijkstra(graph, directed=False, indices=touching[0], min_only=True)
    d2 = dijkstra(graph, directed=False, indices=touching[1], min_only=True)
    first = d1 <= d2
    return first, ~first


def _once_round(
    graph: csr_matrix, a: int, arcs: tuple[NDArray[np.bool_], NDArray[np.bool_]]
) -> FloatArray:
    """Geodesic distance from ``a`` round a loop cut next to ``a``: links between the two arcs
    near ``a`` (closer to it than to anything halfway round) are removed."""
    first, _ = arcs
    coo = graph.tocoo()
    from_a = dijkstra(graph, directed=False, indices=a)
    half = 0.5 * float(np.max(_finite(from_a)))
    across = (first[coo.row] != first[coo.col]) & (from_a[coo.row] < half)
    cut = csr_matrix((coo.data[~across], (coo.row[~across], coo.col[~across])), shape=graph.shape)
    return np.asarray(dijkstra(cut, directed=False, indices=a))


def _band_half_width(nodes: FloatArray, distances: FloatArray, typical: float) -> float:
    """The band's half width from the nodes' local spread: across a neighbourhood of four
    typical links, the second principal standard deviation times sqrt(3) (a uniform band's),
    the median over the nodes."""
    near = distances <= 4.0 * typical
    count = near.sum(axis=1)
    centre = (near @ nodes) / count[:, None]
    spreads = []
    for i in np.flatnonzero(count >= 4):
        local = nodes[near[i]] - centre[i]
        eig = np.linalg.eigvalsh(local.T @ local / len(local))
        spreads.append(float(np.sqrt(max(eig[1], 0.0))))
    return float(np.sqrt(3.0) * np.median(spreads)) if spreads else typical


def _slab_chain(
    points: FloatArray, along: FloatArray, weight: FloatArray, size: float
) -> FloatArray:
    """Weighted centroids (K, 3) of the points in slices ``size`` thick of ``along``, in order,
    smoothed by a three-vertex moving average. Slices holding less than a tenth of the median
    slice (stray points beyond an end) are left out."""
    slab = np.floor((along - along.min()) / size).astype(np.int64)
    total = np.bincount(slab, weights=weight)
    filled = total >= 0.1 * float(np.median(total[total > 0]))
    sums = np.column_stack([np.bincount(slab, weights=weight * points[:, j]) for j in range(3)])
    return moving_average(sums[filled] / total[filled][:, None], 3)


def _positions_on(chain: FloatArray, points: FloatArray) -> FloatArray:
    """Arc length (N,) of each point's projection on the chain (K, 3)."""
    return arc_positions(chain, points, step=0.001)[1]


def _principal_positions(points: FloatArray) -> tuple[FloatArray, float]:
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    proj = (points - centre) @ vt[0]
    return proj - proj.min(), float(np.ptp(proj))
