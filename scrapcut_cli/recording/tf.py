"""A TF buffer over a whole recording: /tf_static (timeless) and /tf (interpolated in time).

Each child frame has exactly one parent. Static transforms hold at every time, whichever
publisher sent them and however old their stamps. A dynamic transform is interpolated between
its two neighbouring samples (linear translation, slerp rotation); a query outside its sampled
time range is reported invalid, never extrapolated. Lookups are vectorised over stamps and
compose chains of any length through the frames' common ancestor.

tf2 does this inside ROS; outside ROS there is no maintained Python equivalent (the
``tf2_py`` bindings need a ROS installation), hence this small buffer.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from scrapcut_cli.errors import RecordingError
from scrapcut_cli.geometry import MAX_COORDINATE_M

FloatArray = NDArray[np.float64]


@dataclass
class _Edge:
    """The transform parent <- child: T_parent_child, static or sampled in time."""

    parent: str
    static: bool
    stamps: list[int]
    translations: list[tuple[float, ...]]
    quats: list[tuple[float, float, float, float]]
    # Sorted, de-duplicated arrays, built on first lookup.
    t: NDArray[np.int64] | None = None
    xyz: FloatArray | None = None
    rot: Rotation | None = None


def _floats(value: ArrayLike, n: int) -> tuple[float, ...]:
    """``value`` as a tuple of ``n`` Python floats (a tuple of floats passes through cheaply)."""
    if type(value) is tuple and len(value) == n:
        return tuple(map(float, value))
    return tuple(np.asarray(value, dtype=np.float64).reshape(n).tolist())


class TfBuffer:
    """Transforms between frames at given stamps (integer nanoseconds)."""

    def __init__(self) -> None:
        self._edges: dict[str, _Edge] = {}

    # ------------------------------------------------------------------ filling

    def add(
        self,
        parent: str,
        child: str,
        stamp_ns: int,
        translation: ArrayLike,
        quat_xyzw: ArrayLike,
        *,
        static: bool,
    ) -> None:
        """Record T_parent_child (translation metres, quaternion x, y, z, w) at ``stamp_ns``.

        Raises RecordingError if ``child`` already has another parent, or is published both
        on /tf and /tf_static.
        """
        if parent == child:
            raise RecordingError(f"TF transform from frame {child!r} to itself")
        # Plain floats and chained comparisons, not numpy nor all() over generators: a
        # recording's /tf holds tens of thousands of transforms.
        t = _floats(translation, 3)
        q = _floats(quat_xyzw, 4)
        x, y, z = t
        qx, qy, qz, qw = q
        bound = MAX_COORDINATE_M
        # Bounded before any arithmetic: 1e300 would overflow the norm (NaN fails too).
        bounded = (
            -bound <= x <= bound
            and -bound <= y <= bound
            and -bound <= z <= bound
            and -1e6 <= qx <= 1e6
            and -1e6 <= qy <= 1e6
            and -1e6 <= qz <= 1e6
            and -1e6 <= qw <= 1e6
        )
        # numpy's dot, as the poses have always been normalised (the same bytes out).
        qa = np.array(q)
        norm = math.sqrt(qa.dot(qa)) if bounded else 0.0
        if not bounded or norm < 1e-9:
            raise RecordingError(
                f"TF transform {parent} -> {child} is not a valid pose: {list(t)}, {list(q)}"
            )
        edge = self._edges.get(child)
        if edge is None:
            edge = _Edge(parent, static, [], [], [])
            self._edges[child] = edge
        elif edge.parent != parent:
            raise RecordingError(
                f"TF frame {child!r} has two parents, {edge.parent!r} and {parent!r}; "
                "a TF tree allows one"
            )
        elif edge.static != static:
            raise RecordingError(
                f"TF frame {child!r} is published on both /tf and /tf_static (parent {parent!r})"
            )
        if static:
            # Timeless: the latest message from any publisher replaces the transform.
            edge.stamps[:] = [int(stamp_ns)]
            edge.translations[:] = [t]
            edge.quats[:] = [(qx / norm, qy / norm, qz / norm, qw / norm)]
        else:
            edge.stamps.append(int(stamp_ns))
            edge.translations.append(t)
            edge.quats.append((qx / norm, qy / norm, qz / norm, qw / norm))
        edge.t = None

    def add_transforms(
        self,
        transforms: Iterable[
            tuple[str, str, int, tuple[float, float, float], tuple[float, float, float, float]]
        ],
        *,
        static: bool,
    ) -> None:
        """:meth:`add` for every (parent, child, stamp_ns, translation, quat_xyzw)."""
        add = self.add
        for parent, child, stamp, t, q in transforms:
            add(parent, child, stamp, t, q, static=static)

    # ------------------------------------------------------------------ structure

    @property
    def frames(self) -> list[str]:
        """Every frame id that appears, sorted."""
        names = set(self._edges)
        names.update(e.parent for e in self._edges.values())
        return sorted(names)

    def parent(self, frame: str) -> str | None:
        """The parent of ``frame``, None for a root or an unknown frame."""
        edge = self._edges.get(frame)
        return None if edge is None else edge.parent

    def has_frame(self, frame: str) -> bool:
        return frame in self._edges or any(e.parent == frame for e in self._edges.values())

    def root(self, frame: str) -> str:
        """The root of the tree that holds ``frame``."""
        return self._path_to_root(frame)[-1]

    @property
    def roots(self) -> list[str]:
        """The root of every tree in the buffer (frames without a parent), sorted."""
        return sorted({self._path_to_root(f)[-1] for f in self._edges})

    def moving_links(self, frame: str) -> list[tuple[str, str]]:
        """(parent, child) of every time-varying (/tf) link between ``frame`` and its root,
        nearest ``frame`` first; empty if ``frame`` is fixed to its root."""
        path = self._path_to_root(frame)
        return [(self._edges[c].parent, c) for c in path[:-1] if not self._edges[c].static]

    def moving_frames(self, root: str) -> list[str]:
        """Frames of the tree under ``root`` that move relative to it, sorted."""
        return sorted(f for f in self._edges if self.root(f) == root and self.moving_links(f))

    def is_static(self, target_frame: str, source_frame: str) -> bool:
        """True if every link between the two frames comes from /tf_static."""
        chain = self._chain(target_frame, source_frame)
        return all(self._edges[c].static for c in chain[0] + chain[1])

    def moving_frame(self, target_frame: str, source_frame: str) -> str:
        """The last frame /tf moves on the way from ``target_frame`` down to ``source_frame``.

        The child of the last dynamic transform of the chain; below it only /tf_static links
        lead to ``source_frame`` (a camera on a robot's flange: the flange). ``target_frame``
        itself when every link is static, ``source_frame`` when its own link is dynamic.
        """
        up, down = self._chain(target_frame, source_frame)
        moving = target_frame
        for child in down:
            if not self._edges[child].static:
                moving = child
        if moving == target_frame and any(not self._edges[c].static for c in up):
            # The chain moves only above the common ancestor: the ancestor carries the camera.
            moving = self._edges[up[-1]].parent
        return moving

    def path_down(self, ancestor: str, frame: str) -> list[str]:
        """Frames from ``ancestor`` down to ``frame``, both included (a chain of links).

        Raises RecordingError if ``ancestor`` is not ``frame`` or one of its ancestors.
        """
        path = self._path_to_root(frame)
        if ancestor not in path:
            raise RecordingError(f"TF frame {ancestor!r} is not above {frame!r}")
        return path[: path.index(ancestor) + 1][::-1]

    def time_range(self, target_frame: str, source_frame: str) -> tuple[int, int] | None:
        """(first, last) stamp at which the transform is known; None if it is timeless."""
        up, down = self._chain(target_frame, source_frame)
        ranges = [self._arrays(c)[0] for c in up + down if not self._edges[c].static]
        if not ranges:
            return None
        return int(max(r[0] for r in ranges)), int(min(r[-1] for r in ranges))

    def _path_to_root(self, frame: str) -> list[str]:
        path = [frame]
        seen = {frame}
        while (edge := self._edges.get(path[-1])) is not None:
            if edge.parent in seen:
                raise RecordingError(f"TF frames form a loop through {edge.parent!r}")
            path.append(edge.parent)
            seen.add(edge.parent)
        return path

    def _chain(self, target_frame: str, source_frame: str) -> tuple[list[str], list[str]]:
        """Child frames of the edges from ``target`` up to the common ancestor, and from the
        ancestor down to ``source`` (each list nearest-the-ancestor last / first)."""
        for frame in (target_frame, source_frame):
            if not self.has_frame(frame):
                raise RecordingError(
                    f"TF frame {frame!r} does not exist; TF frames: {self._frames_text()}"
                )
        up = self._path_to_root(target_frame)
        down = self._path_to_root(source_frame)
        if up[-1] != down[-1]:
            raise RecordingError(
                f"no TF path from {source_frame!r} to {target_frame!r} (their trees have roots "
                f"{down[-1]!r} and {up[-1]!r}); TF frames: {self._frames_text()}"
            )
        common = set(up)
        ancestor = next(f for f in down if f in common)
        return up[: up.index(ancestor)], down[: down.index(ancestor)][::-1]

    def _frames_text(self) -> str:
        frames = self.frames
        return ", ".join(frames) if frames else "(none: the recording has no /tf or /tf_static)"

    # ------------------------------------------------------------------ lookup

    def lookup(
        self, target_frame: str, source_frame: str, stamps_ns: ArrayLike
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """T_target_source at each stamp.

        Parameters
        ----------
        target_frame, source_frame : str
            The result maps points in ``source_frame`` into ``target_frame``.
        stamps_ns : (N,) int64
            Query stamps, nanoseconds.

        Returns
        -------
        T : (N, 4, 4) float64
            Transforms; identity where not valid.
        valid : (N,) bool
            False where a dynamic link has no samples around the stamp.
        """
        stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        up, down = self._chain(target_frame, source_frame)
        n = len(stamps)
        valid = np.ones(n, dtype=bool)
        T_anc_target = np.tile(np.eye(4), (n, 1, 1))
        for child in reversed(up):
            T_edge, ok = self._edge_at(child, stamps)
            T_anc_target = T_anc_target @ T_edge
            valid &= ok
        T_anc_source = np.tile(np.eye(4), (n, 1, 1))
        for child in down:
            T_edge, ok = self._edge_at(child, stamps)
            T_anc_source = T_anc_source @ T_edge
            valid &= ok
        T = _invert(T_anc_target) @ T_anc_source
        T[~valid] = np.eye(4)
        return T, valid

    def lookup_one(self, target_frame: str, source_frame: str, stamp_ns: int) -> FloatArray:
        """T_target_source (4, 4) at one stamp; RecordingError outside the known time range."""
        T, valid = self.lookup(target_frame, source_frame, [stamp_ns])
        if not valid[0]:
            known = self.time_range(target_frame, source_frame)
            raise RecordingError(
                f"no TF from {source_frame!r} to {target_frame!r} at {stamp_ns} ns; known from "
                f"{known[0] if known else '?'} to {known[1] if known else '?'} ns"
            )
        return np.asarray(T[0])

    def _arrays(self, child: str) -> tuple[NDArray[np.int64], FloatArray, Rotation]:
        edge = self._edges[child]
        if edge.t is None or edge.xyz is None or edge.rot is None:
            stamps = np.asarray(edge.stamps, dtype=np.int64)
            # Stable sort, then keep the last sample of equal stamps (the latest message).
            order = np.argsort(stamps, kind="stable")
            stamps = stamps[order]
            keep = np.append(stamps[1:] != stamps[:-1], True)
            idx = order[keep]
            edge.t = stamps[keep]
            edge.xyz = np.asarray(edge.translations, dtype=np.float64)[idx]
            edge.rot = Rotation.from_quat(np.asarray(edge.quats, dtype=np.float64)[idx])
        return edge.t, edge.xyz, edge.rot

    def _edge_at(
        self, child: str, stamps: NDArray[np.int64]
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """T_parent_child (N, 4, 4) at the stamps and whether each is inside the samples."""
        t, xyz, rot = self._arrays(child)
        n = len(stamps)
        T = np.tile(np.eye(4), (n, 1, 1))
        if self._edges[child].static:
            T[:, :3, :3] = rot.as_matrix()[0]
            T[:, :3, 3] = xyz[0]
            return T, np.ones(n, dtype=bool)
        valid = (stamps >= t[0]) & (stamps <= t[-1])
        if len(t) == 1:
            T[:, :3, :3] = rot.as_matrix()[0]
            T[:, :3, 3] = xyz[0]
            return T, valid
        i = np.clip(np.searchsorted(t, stamps, side="right") - 1, 0, len(t) - 2)
        # Differences of int64 stamps are exact; only the ratio is floating point.
        alpha = np.clip((stamps - t[i]) / (t[i + 1] - t[i]), 0.0, 1.0)
        r0 = rot[i]
        delta = (r0.inv() * rot[i + 1]).as_rotvec()  # shortest arc: slerp
        T[:, :3, :3] = (r0 * Rotation.from_rotvec(alpha[:, None] * delta)).as_matrix()
        T[:, :3, 3] = (1.0 - alpha)[:, None] * xyz[i] + alpha[:, None] * xyz[i + 1]
        return T, valid


def _invert(T: FloatArray) -> FloatArray:
    """Inverse of (N, 4, 4) rigid transforms."""
    out = np.tile(np.eye(4), (len(T), 1, 1))
    Rt = np.transpose(T[:, :3, :3], (0, 2, 1))
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", Rt, T[:, :3, 3])
    return out
