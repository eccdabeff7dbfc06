"""Collisions of the arm and the torch with the observed surface and the floor.

The arm is modelled by Franka's own coarse collision capsules (``franka_description``,
``robots/common/franka_arm.xacro``: the ``*_sc`` self-collision geometries, a cylinder with
two spheres per capsule, given by centre, axis direction, cylinder length and radius in each
link's frame); the torch by its body cylinder (``TorchMount``) and a holder back to the flange.
Every capsule is covered by a chain of spheres (centres every half radius along its axis, radii
grown so the chain contains the capsule), so a whole batch of configurations is checked with
one k-nearest-neighbour query of a KD-tree over the observed points (scipy).

A body collides when ``min_points`` observed points lie within its radius plus the margin (a
lone speck of depth noise does not stop a cut; the toolpath's torch check counts the same
way). Links 0 and 1 (the base and the column above it, which only turns about the vertical)
are not checked: they stand on the floor, and the scene around them is not what the camera
observed. The floor is the plane z = ``floor_z_m`` in the base frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from scrapcut_cli.geometry import pack_voxel_keys, voxel_keys
from scrapcut_cli.motion.panda import PandaKinematics
from scrapcut_cli.motion.tool import HOLDER_RADIUS_M, TorchMount

FloatArray = NDArray[np.float64]

_S45 = float(np.sqrt(0.5))
#: (link index 2..8, centre (3,), unit direction (3,), cylinder length, radius), link frames,
#: from franka_description's franka_arm.xacro (link7's geometry is turned 45° about z there).
FRANKA_CAPSULES: tuple[tuple[int, tuple[float, ...], tuple[float, ...], float, float], ...] = (
    (2, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.12, 0.06),
    (3, (0.0, 0.0, -0.145), (0.0, 0.0, 1.0), 0.15, 0.06),
    (4, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.12, 0.06),
    (5, (0.0, 0.0, -0.26), (0.0, 0.0, 1.0), 0.10, 0.06),
    (5, (0.0, 0.08, -0.13), (0.0, 0.0, 1.0), 0.14, 0.025),
    (6, (0.0, 0.0, -0.03), (0.0, 0.0, 1.0), 0.08, 0.05),
    (7, (0.0, 0.0, 0.01), (0.0, 0.0, 1.0), 0.14, 0.04),
    (7, (0.06 * _S45, 0.06 * _S45, 0.082), (_S45, _S45, 0.0), 0.01, 0.03),
    # Not in Franka's self-collision model, which stops short of the flange: link 7's end and
    # the flange (63 mm across, ISO 9409-1-31.5), as the robot's collision meshes have them.
    (8, (0.0, 0.0, -0.015), (0.0, 0.0, 1.0), 0.03, 0.045),
)
#: Link index of the flange (panda_link8) in :meth:`PandaKinematics.link_frames`.
FLANGE = 8


@dataclass(frozen=True)
class CollisionSettings:
    """Clearances (metres) and the point count that makes a collision.

    10 mm around the arm's capsules (which already cover the links with a few millimetres to
    spare) covers the D435i's depth noise at a scanning distance; the torch body gets no
    margin beyond its own radius, as in the toolpath's check, because it must come within the
    standoff of the surface; 20 mm above the floor as in the simulator's scan planning.
    """

    link_margin_m: float = 0.010
    torch_margin_m: float = 0.0
    floor_margin_m: float = 0.020
    floor_z_m: float = 0.0
    min_points: int = 3
    voxel_m: float = 0.003


@dataclass(frozen=True, eq=False)
class Spheres:
    """Sphere cover of the bodies: centre (M, 3) in its parent frame, radius (M,), clearance
    to the observed surface and to the floor (M,), parent (M,) (a link index 2..8 of
    ``link_frames``), body (M,) index into ``names``."""

    centres: FloatArray
    radii: FloatArray
    margins: FloatArray
    floor_margins: FloatArray
    parents: NDArray[np.intp]
    bodies: NDArray[np.intp]
    names: tuple[str, ...]


def sphere_cover(mount: TorchMount, settings: CollisionSettings) -> Spheres:
    """Spheres covering Franka's link capsules, the torch body and the holder."""
    centres: list[FloatArray] = []
    radii: list[FloatArray] = []
    margins: list[FloatArray] = []
    floor_margins: list[FloatArray] = []
    parents: list[NDArray[np.intp]] = []
    bodies: list[NDArray[np.intp]] = []
    names: list[str] = []

    def add(parent: int, a: FloatArray, b: FloatArray, r: float, torch: bool, name: str) -> None:
        length = float(np.linalg.norm(b - a))
        n = max(int(np.ceil(length / (0.5 * r))), 1) + 1
        spacing = length / (n - 1)
        t = np.linspace(0.0, 1.0, n)[:, None]
        if name not in names:
            names.append(name)
        centres.append(a + t * (b - a))
        radii.append(np.full(n, np.hypot(r, 0.5 * spacing)))
        margins.append(np.full(n, settings.torch_margin_m if torch else settings.link_margin_m))
        # The torch works close to whatever it cuts, the floor included (a line low on a piece).
        floor_margins.append(np.full(n, 0.0 if torch else settings.floor_margin_m))
        parents.append(np.full(n, parent, dtype=np.intp))
        bodies.append(np.full(n, names.index(name), dtype=np.intp))

    for link, centre, direction, length, radius in FRANKA_CAPSULES:
        c, d = np.asarray(centre), np.asarray(direction)
        add(
            link,
            c - 0.5 * length * d,
            c + 0.5 * length * d,
            radius,
            False,
            f"panda_link{min(link, 7)}",
        )
    T = mount.T_flange_tool
    tip, z = T[:3, 3], T[:3, 2]
    r = mount.body_radius_m
    body_end = tip - z * mount.body_length_m
    add(FLANGE, tip - z * r, body_end, r, True, "torch")
    # The holder: from the body's back end to the flange (where the torch is shorter than its
    # body, nothing).
    if float(np.linalg.norm(body_end)) > HOLDER_RADIUS_M and float(np.dot(body_end, z)) > 0:
        add(FLANGE, body_end, np.zeros(3), HOLDER_RADIUS_M, False, "holder")
    return Spheres(
        centres=np.concatenate(centres),
        radii=np.concatenate(radii),
        margins=np.concatenate(margins),
        floor_margins=np.concatenate(floor_margins),
        parents=np.concatenate(parents),
        bodies=np.concatenate(bodies),
        names=tuple(names),
    )


class CollisionChecker:
    """Checks joint configurations against an observed cloud and the floor.

    Parameters
    ----------
    kin : PandaKinematics
    mount : TorchMount
    points_base : (N, 3) float64, metres, base frame, optional
        The observed surface (thinned here to ``settings.voxel_m``); None or empty: floor only.
    settings : CollisionSettings
    unseen_base : (M, 3) float64, metres, base frame, optional
        Centres of voxels near the piece the camera never saw (``motion.observed``): a body
        whose sphere reaches one collides (``<body>/unseen``), whatever may be there.
    """

    def __init__(
        self,
        kin: PandaKinematics,
        mount: TorchMount,
        points_base: ArrayLike | None,
        settings: CollisionSettings | None = None,
        *,
        unseen_base: ArrayLike | None = None,
    ) -> None:
        self.kin = kin
        self.settings = settings or CollisionSettings()
        self.spheres = sphere_cover(mount, self.settings)
        pts = np.zeros((0, 3)) if points_base is None else np.asarray(points_base, float)
        pts = pts.reshape(-1, 3)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts):
            _, first = np.unique(
                pack_voxel_keys(voxel_keys(pts, self.settings.voxel_m)), return_index=True
            )
            pts = pts[np.sort(first)]
        self.points = pts
        self._tree = cKDTree(pts) if len(pts) >= self.settings.min_points else None
        unseen = np.zeros((0, 3)) if unseen_base is None else np.asarray(unseen_base, float)
        self.unseen = unseen.reshape(-1, 3)
        self._unseen_tree = cKDTree(self.unseen) if len(self.unseen) else None

    @property
    def names(self) -> tuple[str, ...]:
        """Body names, as :meth:`check` reports them."""
        return self.spheres.names

    def sphere_centres(self, q: ArrayLike) -> FloatArray:
        """Sphere centres (S, M, 3), base frame, at joint samples (S, 7)."""
        frames = self.kin.link_frames(np.atleast_2d(np.asarray(q, dtype=np.float64)))
        sp = self.spheres
        per_sphere = frames[:, sp.parents]  # (S, M, 4, 4)
        R = per_sphere[:, :, :3, :3]
        t = per_sphere[:, :, :3, 3]
        return np.asarray(np.einsum("smij,mj->smi", R, sp.centres) + t)

    def check(self, q: ArrayLike) -> list[str | None]:
        """Per joint sample (S, 7): None when clear, else ``<body>/surface``, ``<body>/unseen``
        or ``<body>/floor`` for the first colliding body (arm links from the base outwards,
        then the torch)."""
        qs = np.atleast_2d(np.asarray(q, dtype=np.float64))
        centres = self.sphere_centres(qs)
        sp, st = self.spheres, self.settings
        reach = sp.radii + sp.margins  # (M,)
        hit_floor = centres[:, :, 2] - sp.radii < st.floor_z_m + sp.floor_margins
        hit_cloud = np.zeros_like(hit_floor)
        if self._tree is not None:
            k = st.min_points
            d, _ = self._tree.query(
                centres.reshape(-1, 3), k=k, distance_upper_bound=float(reach.max())
            )
            kth = np.asarray(d).reshape(len(qs), -1, k)[:, :, -1] if k > 1 else np.asarray(d)
            hit_cloud = kth.reshape(len(qs), -1) <= reach[None]
        hit_unseen = np.zeros_like(hit_floor)
        if self._unseen_tree is not None:
            d1, _ = self._unseen_tree.query(
                centres.reshape(-1, 3), k=1, distance_upper_bound=float(sp.radii.max())
            )
            hit_unseen = np.asarray(d1).reshape(len(qs), -1) <= sp.radii[None]
        out: list[str | None] = []
        for s in range(len(qs)):
            found = None
            masks = (("surface", hit_cloud[s]), ("unseen", hit_unseen[s]), ("floor", hit_floor[s]))
            for kind, mask in masks:
                if mask.any():
                    body = sp.names[int(sp.bodies[int(np.argmax(mask))])]
                    found = f"{body}/{kind}"
                    break
            out.append(found)
        return out

    def clearance(self, q: ArrayLike) -> FloatArray:
        """Smallest distance (S,) in metres from any body's surface to an observed point
        (beyond its margin: negative inside), ``inf`` without a cloud."""
        qs = np.atleast_2d(np.asarray(q, dtype=np.float64))
        if self._tree is None:
            return np.full(len(qs), np.inf)
        centres = self.sphere_centres(qs)
        d, _ = self._tree.query(centres.reshape(-1, 3), k=1)
        gap = np.asarray(d).reshape(len(qs), -1) - self.spheres.radii[None]
        return np.asarray(gap.min(axis=1))
