"""Collision-free moves between two cuts: a joint-space path around the observed scene.

Where a cut is interrupted (set-points the arm cannot reach), the torch retreats, moves to the
approach of the next run of set-points and comes down again. The straight line in joint space
between the two often sweeps the torch or the arm through the piece (the piece lies between
the two ends). :func:`plan_transit` keeps the straight line when it is clear and otherwise
searches with RRT-Connect (Kuffner & LaValle, "RRT-Connect: An efficient approach to
single-query path planning", ICRA 2000; the default planner of MoveIt's OMPL pipeline): two
trees of joint configurations grown from both ends towards random configurations and towards
each other, every edge checked on a fine joint-space grid, then shortened by random
shortcutting. The random configurations come from a generator seeded by the caller, so the
same inputs give the same path.

Configurations are (7,) float64 joint angles in radians; ``collides`` answers for a batch
(S, 7) → (S,) bool (:meth:`~.collision.CollisionChecker.check` against the observed surface,
the unseen space and the floor). Nothing here prints.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Collides = Callable[[FloatArray], NDArray[np.bool_]]


@dataclass(frozen=True)
class TransitSettings:
    """Search parameters (joint-space distances are the largest single joint's, radians).

    ``check_step_rad`` 0.02 rad moves the torch tip, 0.8 m from the shoulder, by at most about
    16 mm between checks, less than the arm's capsule radii (40–60 mm) plus their margin.
    """

    check_step_rad: float = 0.02
    extend_step_rad: float = 0.3
    max_samples: int = 1500
    shortcut_tries: int = 60
    limit_margin_rad: float = 0.05


def edge_clear(a: FloatArray, b: FloatArray, collides: Collides, step: float) -> bool:
    """Whether the straight joint-space segment a → b (both (7,)) is clear, checked every
    ``step`` radians of the largest joint motion (ends included)."""
    return bool(not np.any(collides(segment_samples(a, b, step))))


def segment_samples(a: FloatArray, b: FloatArray, step: float) -> FloatArray:
    """Configurations (n + 1, 7) along a → b, at most ``step`` apart in every joint."""
    n = max(int(np.ceil(float(np.max(np.abs(b - a))) / step)), 1)
    return np.asarray(a + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a))


def plan_transit(
    q_from: FloatArray,
    q_to: FloatArray,
    collides: Collides,
    lower: FloatArray,
    upper: FloatArray,
    rng: np.random.Generator,
    settings: TransitSettings | None = None,
) -> FloatArray | None:
    """A collision-free piecewise-linear joint path (K, 7) from ``q_from`` to ``q_to`` (both
    included), or None when the ends collide or no path was found within
    ``settings.max_samples`` random configurations. ``lower``/``upper`` (7,) are the joint
    position limits (radians); random configurations keep ``limit_margin_rad`` inside them."""
    st = settings or TransitSettings()
    a = np.asarray(q_from, dtype=np.float64)
    b = np.asarray(q_to, dtype=np.float64)
    if np.any(collides(np.vstack([a, b]))):
        return None
    if edge_clear(a, b, collides, st.check_step_rad):
        return np.vstack([a, b])
    lo = np.minimum(np.asarray(lower, float) + st.limit_margin_rad, np.minimum(a, b))
    hi = np.maximum(np.asarray(upper, float) - st.limit_margin_rad, np.maximum(a, b))
    trees = [_Tree(a), _Tree(b)]
    for _ in range(st.max_samples):
        target = lo + rng.random(7) * (hi - lo)
        grown, other = trees
        new = grown.extend(target, collides, st)
        if new is not None and other.connect(grown.nodes[new], collides, st):
            # root(grown) → the new node (== other's last node) → root(other)
            branch = grown.branch(new)[::-1] + other.branch(len(other.nodes) - 1)[1:]
            path = np.vstack(branch)
            if not np.array_equal(path[0], a):
                path = path[::-1]
            return shortcut(path, collides, rng, st)
        trees.reverse()
    return None


class _Tree:
    """Joint configurations with a parent each (the root's is -1)."""

    def __init__(self, root: FloatArray) -> None:
        self.nodes: list[FloatArray] = [root]
        self.parent: list[int] = [-1]
        self._array = root[None].copy()

    def nearest(self, q: FloatArray) -> int:
        return int(np.argmin(np.sum((self._array - q) ** 2, axis=1)))

    def add(self, q: FloatArray, parent: int) -> int:
        self.nodes.append(q)
        self.parent.append(parent)
        self._array = np.vstack([self._array, q])
        return len(self.nodes) - 1

    def extend(self, target: FloatArray, collides: Collides, st: TransitSettings) -> int | None:
        """One step from the nearest node towards ``target``: the new node, or None."""
        near = self.nearest(target)
        q_near = self.nodes[near]
        delta = target - q_near
        reach = float(np.max(np.abs(delta)))
        if reach < 1e-9:
            return None
        q_new = q_near + delta * min(1.0, st.extend_step_rad / reach)
        if not edge_clear(q_near, q_new, collides, st.check_step_rad):
            return None
        return self.add(q_new, near)

    def connect(self, target: FloatArray, collides: Collides, st: TransitSettings) -> bool:
        """Step towards ``target`` until reaching it (True) or hitting something (False)."""
        while True:
            near = self.nearest(target)
            q_near = self.nodes[near]
            delta = target - q_near
            reach = float(np.max(np.abs(delta)))
            if reach <= st.extend_step_rad:
                if edge_clear(q_near, target, collides, st.check_step_rad):
                    self.add(target.copy(), near)
                    return True
                return False
            q_new = q_near + delta * (st.extend_step_rad / reach)
            if not edge_clear(q_near, q_new, collides, st.check_step_rad):
                return False
            self.add(q_new, near)

    def branch(self, index: int) -> list[FloatArray]:
        """Nodes from ``index`` back to the root."""
        out = []
        while index >= 0:
            out.append(self.nodes[index])
            index = self.parent[index]
        return out


def shortcut(
    path: FloatArray, collides: Collides, rng: np.random.Generator, st: TransitSettings
) -> FloatArray:
    """Drop waypoints while the straight segment that replaces them is clear: first greedily
    from each end, then ``st.shortcut_tries`` random pairs."""
    pts = [np.asarray(p) for p in path]
    i = 0
    while i < len(pts) - 2:  # greedy: the farthest waypoint visible from each one
        for j in range(len(pts) - 1, i + 1, -1):
            if edge_clear(pts[i], pts[j], collides, st.check_step_rad):
                del pts[i + 1 : j]
                break
        i += 1
    for _ in range(st.shortcut_tries):
        if len(pts) < 3:
            break
        i, j = sorted(rng.choice(len(pts), size=2, replace=False))
        if j - i < 2:
            continue
        if edge_clear(pts[i], pts[j], collides, st.check_step_rad):
            del pts[i + 1 : j]
    return np.vstack(pts)
