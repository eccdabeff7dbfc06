"""Rigid alignment of a fitted curve to its reference: shape error apart from calibration error.

A path can be the right shape in the wrong place: every frame posed with the same wrong
hand-eye calibration moves the whole stitched line rigidly. ``scrapcut eval --align`` separates
the two as evo's ``--align`` does for trajectories: the rigid motion (rotation + translation, no
scale) that best lays the curve onto the reference is the *calibration error*; the distances
left after applying it are the *shape error*.

Curves have no point-to-point correspondences, so the alignment is an ICP: the curve is sampled
every ``sample_spacing_m``, each sample is paired with its nearest point on the reference
polyline, and the small rigid motion minimising the pairs' distances *across* the reference's
tangent is solved (point-to-line Gauss-Newton, as point-to-plane ICP does for surfaces: plain
point-to-point steps, Umeyama's closed form on the pairs, crawl along a curve for thousands of
iterations); repeated until the motion stops changing. Pairs go from the curve to the reference
(a curve that stops early is not dragged along the missing part of the reference; a sample past
the reference's end pulls only across it).

Some motions leave a curve on itself: sliding and rolling along a straight line, turning a
circle about its axis, screwing a helix. Each step takes the smallest motion of the solutions
(singular directions below :data:`UNOBSERVABLE` of the strongest are dropped), so such a
motion is never reported as calibration error; :attr:`Alignment.straight` flags the common
case of a straight reference. :func:`umeyama_rigid` (the closed form on paired points) is
kept for callers with true correspondences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.geometry import PolylineDistance, resample_polyline, transform_points

FloatArray = NDArray[np.float64]

#: ICP stops when an iteration moves the curve's samples by less than this (metres) ...
CONVERGED_M = 1e-9
#: ... or after this many iterations (point-to-line steps converge in a few tens).
MAX_ITERATIONS = 200
#: A motion direction whose singular value is under this share of the strongest is not
#: observable from the curve (roll about a line that is straight to 0.3 mm over 300 mm).
UNOBSERVABLE = 1e-3


@dataclass(frozen=True, eq=False)
class Alignment:
    """The rigid motion laying a curve onto its reference.

    Attributes
    ----------
    T_ref_curve : (4, 4) float64
        Maps curve points (metres, base frame) onto the reference.
    translation_m : float
        Length of the translation at the curve's centroid (how far the curve's middle moves).
    rotation_deg : float
        Angle of the rotation.
    iterations : int
        ICP iterations run.
    straight : bool
        True when the reference is a straight line (roll about it and sliding along it are
        not observable, hence not reported).
    aligned_points : (N, 3) float64, metres
        The curve after the motion.
    """

    T_ref_curve: FloatArray
    translation_m: float
    rotation_deg: float
    iterations: int
    straight: bool
    aligned_points: FloatArray


def umeyama_rigid(source: ArrayLike, target: ArrayLike) -> FloatArray:
    """The rotation and translation (4×4) minimising ``sum |T·source_i - target_i|²``.

    Parameters
    ----------
    source, target : (N, 3) float64
        Corresponding points (N ≥ 3 for a unique rotation; fewer give the smallest one).

    Umeyama's closed form without scale: the SVD of the cross-covariance, with the sign of
    the last singular vector chosen so that the result is a rotation, not a reflection.
    """
    src = np.asarray(source, dtype=np.float64).reshape(-1, 3)
    dst = np.asarray(target, dtype=np.float64).reshape(-1, 3)
    if len(src) != len(dst) or len(src) == 0:
        raise EvaluationError(f"umeyama needs pairs of points, got {len(src)} and {len(dst)}")
    mu_src, mu_dst = src.mean(axis=0), dst.mean(axis=0)
    covariance = (dst - mu_dst).T @ (src - mu_src) / len(src)
    u, _, vt = np.linalg.svd(covariance)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1.0
    rotation = u @ sign @ vt
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = mu_dst - rotation @ mu_src
    return T


def align_curve(
    curve_points: ArrayLike, reference: ArrayLike, *, sample_spacing_m: float
) -> Alignment:
    """Align the fitted curve rigidly onto the reference (point-to-line ICP).

    Parameters
    ----------
    curve_points, reference : (N, 3), (M, 3) float64, metres, base frame
        Ordered polylines, at least two distinct points each.
    sample_spacing_m : float
        The curve is sampled this finely for the pairs (the evaluation's spacing).
    """
    curve = np.asarray(curve_points, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    samples = resample_polyline(curve, sample_spacing_m)
    nearest = PolylineDistance(ref)
    segment = np.diff(ref, axis=0)
    norms = np.linalg.norm(segment, axis=1, keepdims=True)
    tangents = np.divide(segment, norms, out=np.zeros_like(segment), where=norms > 0)
    T = np.eye(4)
    moved = samples
    iterations = 0
    for iterations in range(1, MAX_ITERATIONS + 1):  # noqa: B007 (reported)
        _, partners, u = nearest.query(moved)
        tangent = tangents[np.clip(u.astype(np.int64), 0, len(tangents) - 1)]
        step = _point_to_line_step(moved, partners, tangent)
        T = step @ T
        before = moved
        moved = transform_points(T, samples)
        if float(np.max(np.linalg.norm(moved - before, axis=1))) < CONVERGED_M:
            break
    centroid = samples.mean(axis=0)
    return Alignment(
        T_ref_curve=T,
        translation_m=float(np.linalg.norm(transform_points(T, centroid[None])[0] - centroid)),
        rotation_deg=_angle_deg(T[:3, :3]),
        iterations=iterations,
        straight=_is_straight(ref),
        aligned_points=transform_points(T, curve),
    )


def _point_to_line_step(
    points: FloatArray, partners: FloatArray, tangents: FloatArray
) -> FloatArray:
    """The smallest rigid motion (4×4) moving ``points`` onto the lines through ``partners``
    along ``tangents`` (all (N, 3)), linearised about the points' centroid."""
    from scipy.spatial.transform import Rotation

    centre = points.mean(axis=0)
    p = points - centre
    across = np.eye(3)[None] - tangents[:, :, None] * tangents[:, None, :]  # (N, 3, 3)
    # d(point)/d(omega, t) = [-[p]x, I]: rotation about the centroid, then translation.
    skew = np.zeros((len(p), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2] = -p[:, 2], p[:, 1]
    skew[:, 1, 0], skew[:, 1, 2] = p[:, 2], -p[:, 0]
    skew[:, 2, 0], skew[:, 2, 1] = -p[:, 1], p[:, 0]
    jacobian = np.concatenate([-skew, np.broadcast_to(np.eye(3), skew.shape)], axis=2)
    a = np.einsum("nij,njk->nik", across, jacobian).reshape(-1, 6)
    b = -np.einsum("nij,nj->ni", across, points - partners).reshape(-1)
    x, *_ = np.linalg.lstsq(a, b, rcond=UNOBSERVABLE)
    rotation = Rotation.from_rotvec(x[:3]).as_matrix()
    step = np.eye(4)
    step[:3, :3] = rotation
    step[:3, 3] = centre + x[3:] - rotation @ centre
    return step


def _is_straight(points: FloatArray) -> bool:
    """True if ``points`` lie on a straight line (second principal extent negligible)."""
    centred = points - points.mean(axis=0)
    singular = np.linalg.svd(centred, compute_uv=False)
    return bool(singular[0] > 0 and singular[1] <= UNOBSERVABLE * singular[0])


def _angle_deg(rotation: FloatArray) -> float:
    cos = np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos)))
