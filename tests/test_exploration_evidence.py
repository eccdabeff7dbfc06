"""Was a line's end observed? Depth views of analytic scenes: flat plates, a box edge, a wall,
an occluder, a plate ending in the air. The line always runs along +x and ends at the origin,
on a surface whose normal is +z; the camera is a 160 x 120 D435i-like pinhole with +x up in
its image (looking down, +x runs towards the top border)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
from numpy.typing import NDArray
from perception_scenes import small_camera

from scrapcut_cli.exploration.evidence import (
    FOLDS_DEG,
    NO_DEPTH,
    OCCLUDED,
    OUTSIDE,
    SURFACE,
    THROUGH,
    DepthView,
    classify_probes,
    continuation_probes,
    depth_view,
    end_evidence,
)
from scrapcut_cli.geometry import look_at
from scrapcut_cli.recording.frame import CameraModel, Frame

FloatArray = NDArray[np.float64]
#: A parallelogram: corner and two edge vectors (metres, base frame).
Rect = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]

CAMERA = small_camera()
TIP = np.zeros(3)
X, Z = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
FLOOR: Rect = ((-1.0, -1.0, -0.5), (2.0, 0.0, 0.0), (0.0, 2.0, 0.0))
#: The plate the line is painted on: z = 0, x from -0.3 to ``end``.
GATES = {"min_depth_m": 0.1, "max_depth_m": 2.0, "flying_pixel_ratio": 0.03}
OPTIONS = {"probe_m": 0.025, "margin": 0.05, "window_m": 0.006, "tolerance_m": 0.01}


def plate(end: float = 0.3) -> Rect:
    return ((-0.3, -0.3, 0.0), (0.3 + end, 0.0, 0.0), (0.0, 0.6, 0.0))


def render_depth(camera: CameraModel, T_base_cam: FloatArray, rects: Sequence[Rect]) -> FloatArray:
    """Depth (H, W) float32, metres along the optical axis, of the nearest parallelogram hit
    by each pixel's ray (NaN where none is), 1 mm steps as a 16UC1 recording gives it."""
    rays = camera.ray_grid().reshape(-1, 2).astype(np.float64)
    d_cam = np.column_stack([rays, np.ones(len(rays))])  # the ray at z-depth 1
    d = d_cam @ T_base_cam[:3, :3].T
    o = T_base_cam[:3, 3]
    depth = np.full(len(rays), np.inf)
    for corner, a_, b_ in rects:
        c, a, b = (np.asarray(v, dtype=np.float64) for v in (corner, a_, b_))
        n = np.cross(a, b)
        denom = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((c - o) @ n) / denom
        hit = o + t[:, None] * d - c
        alpha = hit @ a / (a @ a)
        beta = hit @ b / (b @ b)
        inside = (t > 0) & (alpha >= 0) & (alpha <= 1) & (beta >= 0) & (beta <= 1)
        depth = np.where(inside & (t < depth), t, depth)
    depth[~np.isfinite(depth)] = np.nan
    depth = np.rint(depth * 1000.0) / 1000.0
    return depth.reshape(camera.height, camera.width).astype(np.float32)


def view_of(eye: Sequence[float], target: Sequence[float], rects: Sequence[Rect]) -> DepthView:
    T = look_at(eye, target, up_hint=(1.0, 0.0, 0.0))
    frame = Frame(
        index=7,
        stamp_ns=1,
        color=np.zeros((CAMERA.height, CAMERA.width, 3), dtype=np.uint8),
        depth=render_depth(CAMERA, T, rects),
        camera=CAMERA,
        T_base_cam=T,
    )
    return depth_view(frame, **GATES)


def evidence(views: Sequence[DepthView], *, normal: FloatArray = Z) -> dict:
    return end_evidence(views, TIP, X, normal, **OPTIONS).to_dict()


# --------------------------------------------------------------------------- depth views


def test_depth_view_keeps_usable_depth_on_a_stride_of_the_full_image() -> None:
    camera = small_camera(640, 480)
    T = look_at([0.0, 0.0, 0.3], [0.0, 0.0, 0.0])
    depth = render_depth(camera, T, [plate(), FLOOR])
    depth[100:140, 200:240] = np.nan  # a hole
    depth[300:, :] = 5.0  # beyond the depth gate
    original = depth.copy()
    frame = Frame(0, 1, np.zeros((480, 640, 3), np.uint8), depth, camera, T)
    view = depth_view(frame, **GATES)
    assert view.stride == 4 and view.depth.shape == (120, 160) and view.depth.dtype == np.float32
    assert np.array_equal(frame.depth, original, equal_nan=True)  # input untouched
    assert view.depth[10, 10] == depth[42, 42]  # kept pixel (v, u) = (4 * 10 + 2, 4 * 10 + 2)
    assert np.isnan(view.depth[30, 55]) and np.isnan(view.depth[100, 10])
    assert view.depth.nbytes == 160 * 120 * 4  # ~75 kB kept per 640 x 480 frame


def test_probes_are_classed_by_the_depth_seen_at_them() -> None:
    view = view_of([0.0, 0.0, 0.3], [0.0, 0.0, 0.0], [plate(), FLOOR])
    points = np.array(
        [
            [0.02, 0.01, 0.0],  # on the plate
            [0.02, 0.01, -0.05],  # under it: the plate hides it
            [0.02, 0.01, 0.05],  # above it: the ray passes on to the plate
            [0.5, 0.0, 0.0],  # out of the image
            [0.0, 0.0, 0.5],  # behind the camera
        ]
    )
    seen = classify_probes(view, points, margin_px=6.0, window_m=0.006, tolerance_m=0.01)
    assert seen.codes.tolist() == [SURFACE, OCCLUDED, THROUGH, OUTSIDE, OUTSIDE]
    assert seen.observed_m[0] == pytest.approx(0.3, abs=0.0015)
    assert seen.expected_m[1] == pytest.approx(0.35)
    assert seen.border_px[4] == -np.inf
    # 3 px from the top border: outside with a 6 px margin, seen without one.
    edge = np.array([[0.3 * (CAMERA.cy - 2.5) / CAMERA.fy, 0.0, 0.0]])
    near = classify_probes(view, edge, margin_px=6.0, window_m=0.006, tolerance_m=0.01)
    assert near.codes[0] == OUTSIDE and near.border_px[0] == pytest.approx(3.0, abs=0.01)
    anywhere = classify_probes(view, edge, margin_px=0.0, window_m=0.006, tolerance_m=0.01)
    assert anywhere.codes[0] == SURFACE


def test_a_thin_bar_across_a_probe_does_not_hide_it_but_a_hole_leaves_no_depth() -> None:
    bar: Rect = ((0.016, -0.2, 0.1), (0.003, 0.0, 0.0), (0.0, 0.4, 0.0))  # 3 mm wide, 10 cm up
    view = view_of([0.0, 0.0, 0.3], [0.0, 0.0, 0.0], [plate(), FLOOR, bar])
    point = np.array([[0.017, 0.0, 0.0]])
    assert (
        classify_probes(view, point, margin_px=6, window_m=0.006, tolerance_m=0.01).codes[0]
        == SURFACE
    )
    hidden = DepthView(
        view.frame_index, view.T_base_cam, view.camera, view.stride, view.depth.copy()
    )
    hidden.depth[:, :] = np.nan
    assert (
        classify_probes(hidden, point, margin_px=6, window_m=0.006, tolerance_m=0.01).codes[0]
        == NO_DEPTH
    )


def test_continuation_probes_fold_about_the_edge() -> None:
    probes = continuation_probes(TIP, [1.0, 0.0, 0.3], Z, [0.01, 0.02])  # made tangent
    assert probes.shape == (len(FOLDS_DEG), 2, 3)
    flat, away, towards = FOLDS_DEG.index(0.0), FOLDS_DEG.index(90.0), FOLDS_DEG.index(-90.0)
    assert np.allclose(probes[flat], [[0.01, 0, 0], [0.02, 0, 0]])
    assert np.allclose(probes[away], [[0, 0, -0.01], [0, 0, -0.02]])  # down, away from +z
    assert np.allclose(probes[towards], [[0, 0, 0.01], [0, 0, 0.02]])
    with pytest.raises(ValueError, match="along the surface normal"):
        continuation_probes(TIP, Z, Z, [0.01])


# --------------------------------------------------------------------------- evidence


def test_a_surface_going_on_past_the_tip_is_an_observed_end() -> None:
    view = view_of([0.0, 0.0, 0.3], [0.0, 0.0, 0.0], [plate(), FLOOR])
    result = evidence([view])
    assert result["observed"] and result["how"] == "surface"
    assert result["frame"] == 7 and result["k"] == 0
    assert result["tip_px"] == pytest.approx([CAMERA.cx, CAMERA.cy], abs=0.6)
    # The normal's sign does not matter: each view turns it to its camera.
    assert evidence([view], normal=-Z)["observed"]


def test_an_end_near_the_image_border_is_not_observed() -> None:
    # The tip 3 px from the top border (the margin is 6 px): the paint may leave the image.
    x = 0.3 * (2.5 - CAMERA.cy) / CAMERA.fy
    view = view_of([x, 0.0, 0.3], [x, 0.0, 0.0], [plate(), FLOOR])
    result = evidence([view])
    assert not result["observed"] and result["frame"] is None
    assert result["frames"][0]["verdict"] == "tip outside"
    assert result["frames"][0]["border_px"] == pytest.approx(3.0, abs=0.01)
    # The tip 12 px inside, its continuation (17 mm: ~9 px) within the margin: not observed.
    x = 0.3 * (11.5 - CAMERA.cy) / CAMERA.fy
    view = view_of([x, 0.0, 0.3], [x, 0.0, 0.0], [plate(), FLOOR])
    result = evidence([view])
    assert not result["observed"]
    assert result["frames"][0]["verdict"] == "17 mm past the tip: outside"
    # Further in, the same plate is an observed end.
    x = 0.3 * (30.0 - CAMERA.cy) / CAMERA.fy
    assert evidence([view_of([x, 0.0, 0.3], [x, 0.0, 0.0], [plate(), FLOOR])])["observed"]


def test_an_end_at_a_box_edge_seen_from_above_is_hidden_but_seen_from_beyond() -> None:
    """The line may go on down the box's side: from above the top face, that side is hidden
    behind the edge; a camera beyond the edge sees the side without paint."""
    side: Rect = ((0.0, -0.3, -0.2), (0.0, 0.0, 0.2), (0.0, 0.6, 0.0))
    floor: Rect = ((-1.0, -1.0, -0.2), (2.0, 0.0, 0.0), (0.0, 2.0, 0.0))
    scene = [plate(end=0.0), side, floor]
    above = view_of([-0.05, 0.0, 0.3], [0.0, 0.0, 0.0], scene)
    result = evidence([above])
    assert not result["observed"]
    check = result["frames"][0]
    assert check["verdict"].endswith("through")  # past the edge: the floor
    assert check["folds_deg"]["90"] == "occluded"  # the side: behind the edge
    beyond = view_of([0.2, 0.0, 0.25], [0.0, 0.0, 0.0], scene)
    result = evidence([above, beyond])
    assert result["observed"] and result["how"] == "fold" and result["k"] == 1
    assert [c["verdict"].startswith("observed") for c in result["frames"]] == [False, True]


def test_a_plate_ending_in_the_air_is_an_edge_only_seen_from_low_beyond_it() -> None:
    """From above, the plate itself hides where paint wrapped round its edge (a 135 degree
    fold) would be; from low beyond the edge every fold up to that is in sight."""
    above = view_of([0.2, 0.0, 0.3], [0.0, 0.0, 0.0], [plate(end=0.0), FLOOR])
    result = evidence([above])
    assert not result["observed"]
    assert result["frames"][0]["folds_deg"] == {
        "0": "through",
        "45": "through",
        "90": "through",
        "135": "occluded",
        "-45": "through",
        "-90": "through",
    }
    low = view_of([0.2, 0.0, 0.1], [0.0, 0.0, 0.0], [plate(end=0.0), FLOOR])
    result = evidence([low])
    assert result["observed"] and result["how"] == "edge"


def test_an_occluder_over_the_continuation_is_no_evidence() -> None:
    # 8 cm above the plate, from just short of the tip's line of sight on.
    block: Rect = ((-0.016, -0.04, 0.08), (0.08, 0.0, 0.0), (0.0, 0.08, 0.0))
    view = view_of([-0.08, 0.0, 0.3], [0.0, 0.0, 0.0], [plate(), FLOOR, block])
    result = evidence([view])
    assert not result["observed"]
    assert result["frames"][0]["verdict"].endswith("occluded")


def test_a_wall_rising_past_the_tip_in_sight_is_an_observed_end() -> None:
    wall: Rect = ((0.012, -0.3, 0.0), (0.0, 0.0, 0.2), (0.0, 0.6, 0.0))  # facing -x
    view = view_of([-0.15, 0.0, 0.3], [0.0, 0.0, 0.0], [plate(), FLOOR, wall])
    result = evidence([view])
    assert result["observed"] and result["how"] == "wall"
