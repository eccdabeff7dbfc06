"""Was a line's end observed? Evidence from the depth images the planner already took.

Algorithm 1 declares an end when a view past it adds no paint. When no view past the frontier
is feasible (the target lies under the floor, every camera pose is inside an obstacle or out of
the robot's reach) that test cannot be made, and the direction would end with
``no_feasible_view``. The end still counts when an earlier frame *observed* it: the tip lies
well inside that image, and the frame's depth shows that, had the paint gone on, the camera
would have seen it. What is checked, per frame (:func:`end_evidence`):

1. the tip projects at least a margin (a share of the image) inside the border, in front of
   the camera, and its depth there is valid and not behind an occluder;
2. past the tip, along the line's direction in the surface's plane, at ``2/3`` and all of the
   probe length: where the surface would go on flat, the depth is valid and

   - at that point's depth: the surface goes on past the tip and shows no paint (``surface``);
   - farther: the ray passes where the surface would be, so it ends or folds there. A surface
     folding away from the camera would hide the line (a box's edge, a ridge), so the points
     the line would reach on folds of 45°, 90° and 135° away from the camera must be seen too,
     in turn: a surface there is the fold, seen without paint (``fold``); the rays passing all
     three, the surface ends at the tip (``edge``). A sharper fold (a ridge under 45°, paint
     wrapped round a sheet's edge) cannot be told from an end;
   - nearer: something stands in front of the continuation. That is a concave fold (the line
     would run up a wall) only if the wall is where the line would reach on a 45° or 90° fold
     towards the camera (``wall``); otherwise an occluder hides it.

Anything else — the tip or its continuation near the border or out of the image (the paint may
simply leave it), without valid depth, or behind an occluding edge or object — is no evidence,
and the direction keeps ``no_feasible_view``.

Frames are kept small for this (:class:`DepthView`: the pose, the camera model and the usable
depth on a strided grid, about 160 pixels wide: ~75 kB per 640 × 480 frame). Depth is z along
the optical axis (the recording's convention), metres; unusable pixels (out of the perception
depth range, flying pixels) are NaN.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli.perception.cloud import grid_pixels, usable_depth_pixels
from scrapcut_cli.recording.frame import CameraModel, Frame

FloatArray = NDArray[np.float64]

#: Kept depth images are about this many pixels wide (a stride of 4 at 640 × 480).
DEPTH_VIEW_WIDTH = 160
#: What a probe's pixel window shows (a probe is a point where the line would go on).
OUTSIDE, NO_DEPTH, OCCLUDED, SURFACE, THROUGH = 0, 1, 2, 3, 4
PROBE_CLASSES = ("outside", "no_depth", "occluded", "surface", "through")
#: Folds of the surface about the edge at the tip, degrees: away from the camera (positive)
#: and towards it (negative). 0 is the surface going on flat.
AWAY_FOLDS_DEG = (45.0, 90.0, 135.0)
TOWARDS_FOLDS_DEG = (-45.0, -90.0)
FOLDS_DEG = (0.0, *AWAY_FOLDS_DEG, *TOWARDS_FOLDS_DEG)
#: Probe distances past the tip, as shares of the probe length.
PROBE_SHARES = (2.0 / 3.0, 1.0)
#: A probe counts as seen when at least this share of its window shows depth not in front of
#: it (a wire of a mesh or a thin bar across the window hides part of it, not all), and as
#: occluded when no such share is seen but this share is in front of it.
MIN_SEEN_SHARE = 1.0 / 3.0


@dataclass(frozen=True, eq=False)
class DepthView:
    """What one frame saw, kept small: pose, camera model and a strided usable-depth image.

    Attributes
    ----------
    frame_index : int
        The frame's position in the recording.
    T_base_cam : (4, 4) float64
        Camera pose (optical frame, base frame).
    camera : CameraModel
        The frame's full-resolution camera.
    stride : int
        Pixel ``(v, u)`` of the full image is kept at ``(v // stride, u // stride)`` when
        ``v % stride == u % stride == stride // 2``.
    depth : (h, w) float32
        Usable depth at the kept pixels, metres (z along the optical axis); NaN elsewhere.
    """

    frame_index: int
    T_base_cam: FloatArray
    camera: CameraModel
    stride: int
    depth: NDArray[np.float32]


def depth_view(
    frame: Frame,
    *,
    min_depth_m: float,
    max_depth_m: float,
    flying_pixel_ratio: float,
    width: int = DEPTH_VIEW_WIDTH,
) -> DepthView:
    """The frame's :class:`DepthView`: usable depth (perception's gate: depth range, flying
    pixels judged on the full image) on a grid of stride ``camera.width // width`` (>= 1)."""
    stride = max(1, frame.depth.shape[1] // max(width, 1))
    pixels, grid = grid_pixels(frame.depth.shape, stride)
    usable = usable_depth_pixels(
        frame.depth,
        pixels,
        min_depth_m=min_depth_m,
        max_depth_m=max_depth_m,
        flying_pixel_ratio=flying_pixel_ratio,
    )
    kept = np.full(pixels.size, np.nan, dtype=np.float32)
    kept[np.isin(pixels, usable, assume_unique=True)] = frame.depth.reshape(-1)[usable]
    return DepthView(
        frame_index=frame.index,
        T_base_cam=np.asarray(frame.T_base_cam, dtype=np.float64).copy(),
        camera=frame.camera,
        stride=stride,
        depth=kept.reshape(grid),
    )


@dataclass(frozen=True, eq=False)
class ProbeResult:
    """Probes seen by one view: class codes (N,) int (``PROBE_CLASSES``), pixel coordinates
    (N, 2) float64 in the full image (NaN behind the camera), expected and observed depth (N,)
    float64 metres (the median of the window's seen pixels; NaN if not seen), and distance to
    the border (N,) in pixels (-inf behind the camera)."""

    codes: NDArray[np.int8]
    pixels: FloatArray
    expected_m: FloatArray
    observed_m: FloatArray
    border_px: FloatArray


def classify_probes(
    view: DepthView,
    points_base: ArrayLike,
    *,
    margin_px: float,
    window_m: float,
    tolerance_m: float,
) -> ProbeResult:
    """What ``view`` saw at each point (N, 3) float64, metres, base frame.

    A point is ``outside`` when it is behind the camera or projects less than ``margin_px``
    from the image border. Else the kept pixels within ``window_m`` of its projection (at the
    point's depth; at least the nearest and its neighbours) decide: when at least
    :data:`MIN_SEEN_SHARE` of them show valid depth not more than ``tolerance_m`` in front of
    the point, it was seen — ``through`` when their median lies more than ``tolerance_m``
    behind the point, ``surface`` otherwise; when not, but that share lies in front of it,
    ``occluded``; otherwise ``no_depth``.
    """
    pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 3)
    n = len(pts)
    T = view.T_base_cam
    cam = (pts - T[:3, 3]) @ T[:3, :3]  # R^T (p - t), row-wise
    z = cam[:, 2]
    codes = np.full(n, OUTSIDE, dtype=np.int8)
    pixels = np.full((n, 2), np.nan)
    observed = np.full(n, np.nan)
    border = np.full(n, -np.inf)
    front = z > 1e-6
    if not front.any():
        return ProbeResult(codes, pixels, z.copy(), observed, border)
    camera = view.camera
    pixels[front] = camera.project(cam[front])
    u, v = pixels[:, 0], pixels[:, 1]
    with np.errstate(invalid="ignore"):
        border = np.minimum(
            np.minimum(u + 0.5, camera.width - 0.5 - u),
            np.minimum(v + 0.5, camera.height - 0.5 - v),
        )
    inside = front & (border >= margin_px)
    border = np.where(front, border, -np.inf)
    if not inside.any():
        return ProbeResult(codes, pixels, z.copy(), observed, border)
    s = view.stride
    rows, cols = view.depth.shape
    idx = np.flatnonzero(inside)
    # Each point's window of kept pixels: at least the nearest one and its 8 neighbours.
    focal = min(camera.fx, camera.fy)
    radius = np.maximum(1, np.rint(window_m * focal / (z[idx] * s))).astype(np.intp)
    R = int(radius.max())
    centre_col = np.rint((u[idx] - s // 2) / s).astype(np.intp)
    centre_row = np.rint((v[idx] - s // 2) / s).astype(np.intp)
    dr, dc = np.mgrid[-R : R + 1, -R : R + 1]
    dr, dc = dr.reshape(-1), dc.reshape(-1)
    row = centre_row[:, None] + dr[None, :]
    col = centre_col[:, None] + dc[None, :]
    in_window = (
        (np.abs(dr)[None, :] <= radius[:, None])
        & (np.abs(dc)[None, :] <= radius[:, None])
        & (row >= 0)
        & (row < rows)
        & (col >= 0)
        & (col < cols)
    )
    values = view.depth[np.clip(row, 0, rows - 1), np.clip(col, 0, cols - 1)].astype(np.float64)
    values[~in_window] = np.nan
    size = in_window.sum(axis=1)
    residual = values - z[idx, None]
    # NaN compares False: a pixel without depth is neither in front nor seen.
    in_front = residual < -tolerance_m
    seen = np.isfinite(residual) & ~in_front
    n_seen, n_front = seen.sum(axis=1), in_front.sum(axis=1)
    visible = (n_seen > 0) & (n_seen >= MIN_SEEN_SHARE * size)
    blocked = ~visible & (n_front >= MIN_SEEN_SHARE * size)
    median = np.full(idx.size, np.nan)
    if visible.any():
        median[visible] = np.nanmedian(np.where(seen, values, np.nan)[visible], axis=1)
    behind = median - z[idx] > tolerance_m
    codes[idx] = np.where(
        visible, np.where(behind, THROUGH, SURFACE), np.where(blocked, OCCLUDED, NO_DEPTH)
    )
    observed[idx] = median
    return ProbeResult(codes, pixels, z.copy(), observed, border)


def continuation_probes(
    tip: ArrayLike, direction: ArrayLike, normal: ArrayLike, distances_m: ArrayLike
) -> FloatArray:
    """Where the line would go on past ``tip``: (len(FOLDS_DEG), D, 3) float64, metres.

    ``direction`` (3,) is the line's way out of the tip, made tangent to the surface whose unit
    ``normal`` (3,) points to the side it was seen from; fold ``b`` (:data:`FOLDS_DEG`) turns it
    by ``b`` degrees about the edge ``direction × normal``, away from the normal's side for
    positive ``b``.
    """
    n = np.asarray(normal, dtype=np.float64).reshape(3)
    n = n / np.linalg.norm(n)
    d = np.asarray(direction, dtype=np.float64).reshape(3)
    d = d - np.dot(d, n) * n
    norm = float(np.linalg.norm(d))
    if norm < 1e-9:
        raise ValueError("the line's direction is along the surface normal")
    d = d / norm
    b = np.radians(np.asarray(FOLDS_DEG))
    ways = np.cos(b)[:, None] * d[None, :] - np.sin(b)[:, None] * n[None, :]
    s = np.asarray(distances_m, dtype=np.float64).reshape(-1)
    return np.asarray(tip, dtype=np.float64).reshape(3) + s[None, :, None] * ways[:, None, :]


def _continuation(codes: NDArray[np.int8]) -> str | None:
    """How the continuation at one distance was seen from the fold codes (in
    :data:`FOLDS_DEG` order), or None when it was not."""
    flat, away, towards = (
        codes[0],
        codes[1 : 1 + len(AWAY_FOLDS_DEG)],
        codes[1 + len(AWAY_FOLDS_DEG) :],
    )
    if flat == SURFACE:
        return "surface"
    if flat == THROUGH:
        for code in away:
            if code == SURFACE:
                return "fold"
            if code != THROUGH:
                return None
        return "edge"
    if flat == OCCLUDED:
        for code in towards:
            if code == SURFACE:
                return "wall"
            if code != THROUGH:
                return None
    return None


HOW = {
    "surface": "the surface goes on past the tip without paint",
    "fold": "the surface folds away past the tip, in sight, without paint",
    "edge": "the surface ends at the tip: seen past it and past a fold away",
    "wall": "a wall rises past the tip, in sight, without paint",
}


@dataclass(frozen=True)
class EndEvidence:
    """Whether an earlier frame observed the line's end, and how (see the module docstring).

    ``frame``, ``k`` and ``how`` name the first frame (in the order observed) that saw it;
    ``checks`` holds one short verdict per frame with the tip in front of its camera.
    """

    observed: bool
    frame: int | None
    k: int | None
    how: str | None
    tip_px: tuple[float, float] | None
    border_px: float | None
    checks: tuple[dict[str, Any], ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (pixels and depths rounded to 0.1 px and 0.1 mm)."""
        return {
            "observed": self.observed,
            "frame": self.frame,
            "k": self.k,
            "how": self.how,
            "why": None if self.how is None else HOW[self.how],
            "tip_px": None if self.tip_px is None else [round(c, 1) for c in self.tip_px],
            "border_px": None if self.border_px is None else round(self.border_px, 1),
            "frames": [dict(c) for c in self.checks],
        }


def end_evidence(
    views: Sequence[DepthView],
    tip: ArrayLike,
    direction: ArrayLike,
    normal: ArrayLike,
    *,
    probe_m: float,
    margin: float,
    window_m: float,
    tolerance_m: float,
    steps: Sequence[int] | None = None,
) -> EndEvidence:
    """The first of ``views`` that observed the line's end at ``tip`` (module docstring).

    Parameters
    ----------
    views : sequence of DepthView
        The frames taken so far, in the order observed.
    tip, direction, normal : (3,) float64
        The line's end, metres, base frame; its unit way out; the surface's unit normal there
        (either sign: each view turns it to face its camera).
    probe_m : float
        How far past the tip the continuation must be seen, metres.
    margin : float
        Share of the image's smaller side the tip and probes must keep from the border.
    window_m, tolerance_m : float
        Pixel window around a probe (metres at its depth) and depth tolerance
        (:func:`classify_probes`).
    steps : sequence of int, optional
        The planner's step k of each view (for the log); default their positions.
    """
    tip_ = np.asarray(tip, dtype=np.float64).reshape(3)
    n = np.asarray(normal, dtype=np.float64).reshape(3)
    distances = probe_m * np.asarray(PROBE_SHARES)
    checks: list[dict[str, Any]] = []
    ks = list(range(len(views))) if steps is None else [int(k) for k in steps]
    for view, k in zip(views, ks, strict=True):
        camera_side = n if float(np.dot(view.T_base_cam[:3, 3] - tip_, n)) >= 0.0 else -n
        try:
            probes = continuation_probes(tip_, direction, camera_side, distances)
        except ValueError:
            return EndEvidence(False, None, None, None, None, None, tuple(checks))
        points = np.vstack([tip_[None, :], probes.reshape(-1, 3)])
        margin_px = margin * min(view.camera.width, view.camera.height)
        seen = classify_probes(
            view, points, margin_px=margin_px, window_m=window_m, tolerance_m=tolerance_m
        )
        if not np.isfinite(seen.border_px[0]):
            continue  # the tip is behind this camera: not worth a line in the log
        check: dict[str, Any] = {
            "frame": view.frame_index,
            "k": k,
            "tip_px": [round(float(c), 1) for c in seen.pixels[0]],
            "border_px": round(float(seen.border_px[0]), 1),
        }
        tip_code = int(seen.codes[0])
        if tip_code not in (SURFACE, THROUGH):
            check["verdict"] = f"tip {PROBE_CLASSES[tip_code]}"
            checks.append(check)
            continue
        codes = seen.codes[1:].reshape(len(FOLDS_DEG), len(distances))
        hows = [_continuation(codes[:, i]) for i in range(len(distances))]
        if any(h is None for h in hows):
            i = next(i for i, h in enumerate(hows) if h is None)
            flat = PROBE_CLASSES[int(codes[0, i])]
            check["verdict"] = f"{1000 * distances[i]:.0f} mm past the tip: {flat}"
            check["folds_deg"] = {
                f"{b:g}": PROBE_CLASSES[int(c)] for b, c in zip(FOLDS_DEG, codes[:, i], strict=True)
            }
            checks.append(check)
            continue
        # The weakest kind of evidence over the distances names the frame's.
        order = ("surface", "wall", "fold", "edge")
        how = max((h for h in hows if h is not None), key=order.index)
        check["verdict"] = f"observed ({how})"
        checks.append(check)
        return EndEvidence(
            True,
            view.frame_index,
            k,
            how,
            (float(seen.pixels[0, 0]), float(seen.pixels[0, 1])),
            float(seen.border_px[0]),
            tuple(checks),
        )
    return EndEvidence(False, None, None, None, None, None, tuple(checks))
