"""Per-frame clouds on synthetic RGB-D frames of a painted cylinder (see perception_scenes)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from perception_scenes import (
    CYLINDER_AXIS_YZ,
    CYLINDER_RADIUS_M,
    NOISY,
    SceneNoise,
    cylinder_ring_line,
    cylinder_top_line,
    render_cylinder,
    small_camera,
    top_view,
)
from scipy.spatial import cKDTree

from scrapcut_cli.config import PerceptionConfig
from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.geometry import (
    PolylineDistance,
    make_transform,
    nearest_distances,
    transform_points,
)
from scrapcut_cli.perception.cloud import (
    SKIP_NO_PAINT,
    SKIP_NO_VALID_DEPTH,
    SKIP_SCATTERED_PAINT,
    SKIP_TOO_LITTLE_PAINT,
    PerceptionTally,
    backproject_paint,
    backproject_pixels,
    boundary_pixels,
    check_perception_config,
    process_frame,
    reject_isolated_pixels,
    reject_small_blobs,
    sorted_union,
    split_wide_blobs,
    usable_depth_pixels,
)
from scrapcut_cli.perception.paint import PAINT_PRESETS, paint_mask, paint_pixel_indices
from scrapcut_cli.recording.frame import CameraModel, Frame

ORANGE = PAINT_PRESETS["orange"].hsv
CONFIG = PerceptionConfig()
HALF_WIDTH = 0.0125


def radial_error(points: np.ndarray) -> np.ndarray:
    """Distance (N,) of points from the cylinder's surface, metres."""
    y0, z0 = CYLINDER_AXIS_YZ
    return np.abs(np.hypot(points[:, 1] - y0, points[:, 2] - z0) - CYLINDER_RADIUS_M)


@pytest.fixture(scope="module")
def reference() -> np.ndarray:
    return cylinder_top_line()


@pytest.fixture(scope="module")
def exact_frame(reference: np.ndarray) -> Frame:
    return render_cylinder(small_camera(), top_view(0.02), reference)


@pytest.fixture(scope="module")
def noisy_frame(reference: np.ndarray) -> Frame:
    return render_cylinder(small_camera(), top_view(0.02, tilt_m=0.04), reference, noise=NOISY)


# --------------------------------------------------------------------------- stages


def test_backprojection_matches_the_camera_model_with_distortion() -> None:
    camera = CameraModel(
        64, 48, 60.0, 61.0, 31.0, 24.5, "plumb_bob", (-0.12, 0.05, 0.001, -0.002, 0.01)
    )
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.2, 1.0, size=(48, 64)).astype(np.float32)
    T = make_transform(np.eye(3)[[1, 2, 0]], [0.1, -0.2, 0.3])
    pixels = np.sort(rng.choice(64 * 48, 300, replace=False))
    v, u = np.divmod(pixels, 64)
    expected = transform_points(T, camera.unproject(u, v, depth[v, u]))
    got = backproject_pixels(camera, depth, pixels, T)
    np.testing.assert_allclose(got, expected, atol=1e-6)  # float32 ray grid: ~1e-7 relative
    # Re-projecting gives the pixels back.
    back = camera.project(transform_points(np.linalg.inv(T), got))
    np.testing.assert_allclose(back, np.column_stack([u, v]), atol=1e-3)


def test_flying_pixels_out_of_range_and_holes_are_rejected() -> None:
    depth = np.full((5, 8), 0.30, dtype=np.float32)
    depth[:, 5:] = 0.60  # a depth edge between columns 4 and 5
    depth[:, 4] = 0.45  # flying pixels smeared across it
    depth[0, 1] = np.nan  # a hole
    depth[4, 0] = 2.5  # beyond max depth
    pixels = np.arange(depth.size)
    kept = usable_depth_pixels(
        depth, pixels, min_depth_m=0.1, max_depth_m=2.0, flying_pixel_ratio=0.03
    )
    expected = np.zeros((5, 8), dtype=bool)
    expected[:, [0, 1, 2, 6, 7]] = True  # columns 3-5 touch the smeared column 4
    expected[0, 1] = False  # the hole
    expected[4, 0] = expected[3, 0] = expected[4, 1] = False  # out of range, and its edge
    # Pixels next to the hole stay: NaN neighbours are ignored.
    assert np.array_equal(kept, np.flatnonzero(expected))


def test_isolated_paint_pixels_are_dropped_solid_regions_kept() -> None:
    mask = np.zeros((20, 20), dtype=bool)
    mask[5:12, 3:15] = True  # a solid stroke
    mask[[1, 17, 18], [17, 2, 9]] = True  # scattered false positives
    mask[15, 15:17] = True  # a pair: one neighbour each
    kept = reject_isolated_pixels(np.flatnonzero(mask), (20, 20), min_neighbors=2)
    expected = np.zeros_like(mask)
    expected[5:12, 3:15] = True
    expected[[5, 5, 11, 11], [3, 14, 3, 14]] = True  # corners keep two neighbours
    assert np.array_equal(np.flatnonzero(expected), kept)
    assert np.array_equal(
        reject_isolated_pixels(np.flatnonzero(mask), (20, 20), min_neighbors=0),
        np.flatnonzero(mask),
    )


def test_small_blobs_are_dropped_by_the_surface_they_cover() -> None:
    # fx = fy = 300 px at 0.3 m depth: a pixel covers exactly 1 mm^2; the limit is 25 mm^2.
    camera = CameraModel(40, 30, 300.0, 300.0, 20.0, 15.0)
    depth = np.full((30, 40), 0.3, dtype=np.float32)
    mask = np.zeros((30, 40), dtype=bool)
    mask[2:6, 2:7] = True  # 20 px = 20 mm^2: a speck
    mask[2:8, 10:15] = True  # 30 px: kept
    mask[10:14, 2:6] = mask[14:18, 6:10] = True  # two 4x4 specks touching at a corner: 32 px
    mask[20:24, 2:7] = True  # 20 px, but at 0.6 m: 80 mm^2
    depth[20:24, 2:7] = 0.6
    mask[20:22, 20:25] = True  # 10 px without depth: size unknown, kept (the depth gate decides)
    depth[20:22, 20:25] = np.nan
    mask[26:28, 30:35] = True  # 10 px, half of them without depth: 10 mm^2, dropped
    depth[26, 30:35] = np.nan
    pixels = np.flatnonzero(mask)
    kept = reject_small_blobs(pixels, depth, camera, min_area_m2=25e-6, nearest_m=0.1)
    expected = mask.copy()
    expected[2:6, 2:7] = expected[26:28, 30:35] = False
    assert np.array_equal(kept, np.flatnonzero(expected))
    # Off, or no blob below the limit at the nearest usable depth: all kept.
    assert np.array_equal(
        reject_small_blobs(pixels, depth, camera, min_area_m2=0.0, nearest_m=0.1), pixels
    )
    assert np.array_equal(
        reject_small_blobs(pixels, depth, camera, min_area_m2=1e-7, nearest_m=0.1), pixels
    )


def test_overspray_specks_do_not_reach_the_cloud(reference: np.ndarray) -> None:
    # Overspray: paint specks 3-4 px (~3-4 mm) across, 5-30 mm beside the stroke's edge. They
    # pass the colour and neighbour tests, and (before the blob test) stitched into a halo
    # that carried the paint's extent past the stroke's caps.
    frame = render_cylinder(small_camera(320, 240), top_view(0.02), reference, rust=False)
    points = backproject_pixels(
        frame.camera, frame.depth, np.arange(frame.depth.size), frame.T_base_cam
    )
    gap = PolylineDistance(reference).distance(points) - HALF_WIDTH
    on_cylinder = radial_error(points) < 1e-6
    paint_colour = frame.color.reshape(-1, 3)[np.flatnonzero(on_cylinder & (gap < -0.005))[0]]
    rng = np.random.default_rng(3)
    beside = np.flatnonzero(on_cylinder & (gap > 0.005) & (gap < 0.03))
    color = frame.color.copy()
    for at in rng.choice(beside, 60, replace=False):
        v, u = divmod(int(at), 320)
        size = int(rng.integers(3, 5))
        color[v : v + size, u : u + size] = paint_colour
    specks = replace(frame, color=color)

    def far_share(config: PerceptionConfig) -> tuple[float, int]:
        clouds = process_frame(specks, ORANGE, config)
        d = PolylineDistance(reference).distance(clouds.paint_base)
        return float(np.mean(d > HALF_WIDTH + 0.004)), int(np.sum(d <= HALF_WIDTH))

    without_blob_test, stroke_before = far_share(replace(CONFIG, min_paint_area_m2=0.0))
    assert without_blob_test > 0.03  # the specks are in the cloud
    with_blob_test, stroke_after = far_share(CONFIG)
    assert with_blob_test == 0.0
    assert stroke_after >= 0.99 * stroke_before  # the stroke itself is all there


# --------------------------------------------------------------------------- the recipe


def test_exact_frame_paint_lies_on_the_stroke_and_the_surface(
    exact_frame: Frame, reference: np.ndarray
) -> None:
    points, pixels, paint_pixels = backproject_paint(exact_frame, ORANGE, CONFIG)
    assert paint_pixels > 500 and len(points) == len(pixels)
    assert radial_error(points).max() < 1e-5  # exact depth, float32 rays
    # Pixel-centre colours decide paint, so points reach the stroke's edge, not beyond.
    assert PolylineDistance(reference).distance(points).max() < HALF_WIDTH + 1e-4
    clouds = process_frame(exact_frame, ORANGE, CONFIG)
    assert clouds.skip_reason is None
    d = PolylineDistance(reference).distance(clouds.paint_base)
    assert d.max() < HALF_WIDTH + CONFIG.voxel_size_m
    # Voxel centroids of a curved surface sit a hair inside it.
    assert radial_error(clouds.paint_base).max() < 2e-4


def test_noisy_frame_rust_flying_pixels_and_holes_do_not_reach_the_cloud(
    noisy_frame: Frame, reference: np.ndarray
) -> None:
    filtered = paint_pixel_indices(noisy_frame.color, ORANGE)
    usable = usable_depth_pixels(
        noisy_frame.depth, filtered, min_depth_m=0.1, max_depth_m=2.0, flying_pixel_ratio=0.03
    )
    raw = backproject_pixels(noisy_frame.camera, noisy_frame.depth, usable, noisy_frame.T_base_cam)
    d_raw = PolylineDistance(reference).distance(raw)
    assert np.mean(d_raw > HALF_WIDTH + 0.005) > 0.001  # rust does leak into the raw filter
    clouds = process_frame(noisy_frame, ORANGE, CONFIG)
    assert clouds.skip_reason is None and len(clouds.paint_base) > 300
    d = PolylineDistance(reference).distance(clouds.paint_base)
    assert d.max() < HALF_WIDTH + 0.002
    assert radial_error(clouds.paint_base).max() < 0.003  # no flying pixel survived
    assert clouds.valid_paint_pixels < clouds.paint_pixels  # holes and edges were dropped


def test_flying_pixels_on_a_paint_silhouette_are_rejected() -> None:
    ring = cylinder_ring_line(x_m=0.0, half_angle_deg=120.0)
    noise = SceneNoise(flying_pixels=True)
    frame = render_cylinder(small_camera(), top_view(0.0), ring, noise=noise, rust=False)
    unfiltered = replace(CONFIG, flying_pixel_ratio=1e9)
    raw, _, _ = backproject_paint(frame, ORANGE, unfiltered)
    # The smeared silhouette pixels are paint-coloured; along a tangent ray 5 cm of depth
    # error is ~1 cm off the surface.
    assert radial_error(raw).max() > 0.008
    clouds = process_frame(frame, ORANGE, CONFIG)
    assert radial_error(clouds.paint_base).max() < 1e-3


def test_surface_band_flanks_the_stroke_on_both_sides(
    noisy_frame: Frame, reference: np.ndarray
) -> None:
    clouds = process_frame(noisy_frame, ORANGE, CONFIG)
    surface = clouds.surface_base
    assert len(surface) > 200
    d_ref = PolylineDistance(reference).distance(surface)
    assert d_ref.min() > HALF_WIDTH - 0.003  # not paint
    d_paint = nearest_distances(surface, clouds.paint_base)
    assert d_paint.max() < CONFIG.surface_band_m + 0.01  # the band is measured on a coarse grid
    assert np.quantile(d_paint, 0.9) > CONFIG.surface_band_m / 2  # and reaches out
    assert radial_error(surface).max() < 0.003  # on the pipe: no floor, no flying pixels
    # Both sides of the stroke: the sign of y relative to the reference's nearest point.
    _, nearest, _ = PolylineDistance(reference).query(surface)
    side = np.sign(surface[:, 1] - nearest[:, 1])
    assert np.mean(side > 0) > 0.25 and np.mean(side < 0) > 0.25
    # Downsampled to surface voxels: neighbours about a voxel apart (3.2 mm here), not the
    # pixel grid's half voxel (2.0 mm without the downsampling).
    spacing = np.median(cKDTree(surface).query(surface, k=2)[0][:, 1])
    assert spacing > 0.65 * CONFIG.surface_voxel_m


def test_skip_reasons(reference: np.ndarray, exact_frame: Frame) -> None:
    blue = PAINT_PRESETS["blue"].hsv
    assert process_frame(exact_frame, blue, CONFIG).skip_reason == SKIP_NO_PAINT
    holes = replace(exact_frame, depth=np.full_like(exact_frame.depth, np.nan))
    clouds = process_frame(holes, ORANGE, CONFIG)
    assert clouds.skip_reason == SKIP_NO_VALID_DEPTH
    assert clouds.paint_pixels > 0 and clouds.valid_paint_pixels == 0
    far = replace(CONFIG, min_paint_points=10**6)
    assert process_frame(exact_frame, ORANGE, far).skip_reason == SKIP_TOO_LITTLE_PAINT
    for skipped in (clouds, process_frame(exact_frame, blue, CONFIG)):
        assert skipped.skipped and skipped.paint_base.shape == (0, 3)
        assert skipped.surface_base.shape == (0, 3)


def test_deterministic_and_inputs_unchanged(noisy_frame: Frame) -> None:
    color, depth, pose = noisy_frame.color.copy(), noisy_frame.depth.copy(), noisy_frame.T_base_cam
    pose = pose.copy()
    a = process_frame(noisy_frame, ORANGE, CONFIG)
    b = process_frame(noisy_frame, ORANGE, CONFIG)
    assert a.paint_base.tobytes() == b.paint_base.tobytes()
    assert a.surface_base.tobytes() == b.surface_base.tobytes()
    assert np.array_equal(noisy_frame.color, color)
    assert np.array_equal(noisy_frame.depth, depth, equal_nan=True)
    assert np.array_equal(noisy_frame.T_base_cam, pose)
    np.testing.assert_allclose(a.camera_position, pose[:3, 3])


def test_backprojection_moves_with_the_base_frame(noisy_frame: Frame) -> None:
    rng = np.random.default_rng(5)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    G = make_transform(q * np.sign(np.linalg.det(q)), rng.normal(size=3))
    moved = replace(noisy_frame, T_base_cam=G @ noisy_frame.T_base_cam)
    a, pa, _ = backproject_paint(noisy_frame, ORANGE, CONFIG)
    b, pb, _ = backproject_paint(moved, ORANGE, CONFIG)
    assert np.array_equal(pa, pb)
    np.testing.assert_allclose(b, transform_points(G, a), atol=1e-9)


def test_bad_parameters_raise_naming_them(exact_frame: Frame) -> None:
    with pytest.raises(PerceptionError, match="voxel_size_m"):
        process_frame(exact_frame, ORANGE, replace(CONFIG, voxel_size_m=0.0))
    with pytest.raises(PerceptionError, match="depth range"):
        check_perception_config(replace(CONFIG, min_depth_m=3.0))
    with pytest.raises(PerceptionError, match="surface_band_m"):
        check_perception_config(replace(CONFIG, surface_band_m=-1.0))
    with pytest.raises(PerceptionError, match="min_paint_area_m2"):
        check_perception_config(replace(CONFIG, min_paint_area_m2=float("nan")))


# --------------------------------------------------------------------------- tally


def test_tally_names_the_range_and_the_hues_seen_when_no_paint(exact_frame: Frame) -> None:
    blue = PAINT_PRESETS["blue"].hsv
    tally = PerceptionTally(blue)
    for _ in range(3):
        tally.add(process_frame(exact_frame, blue, CONFIG), exact_frame.color)
    with pytest.raises(PerceptionError) as info:
        tally.raise_if_no_paint()
    message = str(info.value)
    assert "\n" not in message
    assert "no paint found in any of 3 frames with blue (hue 190-250 deg" in message
    assert "dominant hues seen: 30 deg" in message  # the orange stroke (26 deg)


def test_tally_counts_and_explains_paint_without_depth(exact_frame: Frame) -> None:
    holes = replace(exact_frame, depth=np.full_like(exact_frame.depth, np.nan))
    tally = PerceptionTally(ORANGE)
    tally.add(process_frame(holes, ORANGE, CONFIG), holes.color)
    with pytest.raises(PerceptionError, match="no usable paint points") as info:
        tally.raise_if_no_paint()
    # The hint names the options as the command line spells them.
    assert "check the depth range (--min-depth-mm/--max-depth-mm)" in str(info.value)
    assert "scattered" not in str(info.value)
    tally.add(process_frame(exact_frame, ORANGE, CONFIG), exact_frame.color)
    tally.raise_if_no_paint()
    counts = tally.to_dict()
    assert counts["frames"] == 2 and counts["frames_with_paint"] == 1
    assert counts["skip_reasons"] == {SKIP_NO_VALID_DEPTH: 1}
    assert counts["paint_points"] > 0
    with pytest.raises(PerceptionError, match="no usable frames"):
        PerceptionTally(ORANGE).raise_if_no_paint()


def test_scattered_specks_are_told_apart_from_paint_without_depth(exact_frame: Frame) -> None:
    # Rust lifted into the orange range by camera noise: isolated pixels, no stroke. The
    # remedy is another colour range, not another depth range.
    color = np.full_like(exact_frame.color, 110)
    color[::3, ::3] = PAINT_PRESETS["orange"].rgb  # no speck has a paint 4-neighbour
    specks = replace(exact_frame, color=color)
    clouds = process_frame(specks, ORANGE, CONFIG)
    assert clouds.skip_reason == SKIP_SCATTERED_PAINT
    assert clouds.paint_pixels == 40 * 54 and clouds.valid_paint_pixels == 0
    tally = PerceptionTally(ORANGE)
    tally.add(clouds, specks.color)
    with pytest.raises(PerceptionError) as info:
        tally.raise_if_no_paint()
    message = str(info.value)
    assert "\n" not in message
    assert "(scattered_paint 1)" in message and "dominant hues seen: 30 deg (100%)" in message
    assert "--min-paint-neighbors" in message and "depth range" not in message
    # Without the neighbour and blob tests the specks are paint (with depth): the frame is used.
    everything = replace(CONFIG, min_paint_neighbors=0, min_paint_area_m2=0.0, sor_neighbors=0)
    kept = process_frame(specks, ORANGE, everything)
    assert kept.skip_reason is None and len(kept.paint_base) > 100


def test_a_duller_cluster_and_wide_blobs_are_kept_apart_from_the_paint() -> None:
    """Rust at iron-oxide saturation passes the orange range: the frame's saturation clusters
    set it apart (other_base), and so does a crate face wider than any stroke."""
    camera = small_camera()
    reference = cylinder_top_line()
    frame = render_cylinder(camera, top_view(0.0), reference, rust=False)
    color = np.array(frame.color)
    rng = np.random.default_rng(3)
    paint = paint_mask(color, PAINT_PRESETS["orange"].hsv)
    # Rust patches beside the stroke: orange-brown at S ~0.72, inside the orange range.
    v, u = np.mgrid[0 : camera.height, 0 : camera.width]
    patch = ((u - 40) ** 2 + (v - 30) ** 2 < 15**2) & ~paint
    color[patch] = np.clip(np.array([150, 80, 42]) + rng.normal(0, 2, (patch.sum(), 3)), 0, 255)
    assert paint_mask(color, PAINT_PRESETS["orange"].hsv)[patch].mean() > 0.9
    rusty = Frame(frame.index, frame.stamp_ns, color, frame.depth, camera, frame.T_base_cam)
    config = PerceptionConfig(min_paint_points=5, sor_neighbors=0)
    clouds = process_frame(rusty, PAINT_PRESETS["orange"].hsv, config)
    assert len(clouds.other_base) > 0
    line = PolylineDistance(reference)
    assert line.distance(clouds.paint_base).max() < 0.0125 + 0.003  # no rust in the paint
    assert line.distance(clouds.other_base).min() > 0.012
    assert clouds.paint_rgb.shape == (len(clouds.paint_base), 3)
    # A plain stroke is one cluster: nothing apart.
    plain = process_frame(frame, PAINT_PRESETS["orange"].hsv, config)
    assert len(plain.other_base) == 0
    # A blob 10 cm wide is no stroke at 80 mm; at 0 (off) it is paint.
    mask = (u > 60) & (u < 150) & (v > 60)
    pixels = np.flatnonzero(mask.ravel())
    depth = np.full((camera.height, camera.width), 0.3, dtype=np.float32)  # 2.0 mm/px here
    kept, wide = split_wide_blobs(pixels, depth, camera, max_width_m=0.08)
    assert len(kept) == 0 and np.array_equal(wide, pixels)
    kept, wide = split_wide_blobs(pixels, depth, camera, max_width_m=0.0)
    assert np.array_equal(kept, pixels) and len(wide) == 0
    band = np.flatnonzero(((np.abs(v - 60) < 6) & (u > 10)).ravel())  # 11 px: 22 mm wide
    kept, wide = split_wide_blobs(band, depth, camera, max_width_m=0.08)
    assert np.array_equal(kept, band) and len(wide) == 0


# --------------------------------------------------------------------------- stroke edges


def plate_with_slot(*, hole_depth: float | None) -> tuple[Frame, float, float]:
    """A frame looking straight down (camera frame = base frame) at a plate 0.3 m away: a
    horizontal 25 mm stroke, and a slot (columns 150-250) that takes the stroke's top side
    from above it to 8 mm inside it. Through the slot the floor is ``hole_depth`` away (None:
    no depth), with a flying pixel at its rim. Returns the frame and the stroke's top and
    bottom edges' y, metres."""
    camera = CameraModel(640, 480, 615.0, 615.0, 319.5, 239.5, frame_id="camera_optical")
    z = 0.3
    h, w = camera.height, camera.width
    v, u = np.mgrid[0:h, 0:w]
    y = (v - camera.cy) / camera.fy * z
    top, bottom = -HALF_WIDTH, HALF_WIDTH
    paint = (y >= top) & (y <= bottom)
    slot = (u >= 150) & (u < 250) & (y >= top - 0.01) & (y < top + 0.008)
    color = np.empty((h, w, 3), dtype=np.uint8)
    color[:] = (118, 121, 127)
    color[paint] = (255, 110, 0)
    color[slot] = (70, 72, 70)
    depth = np.full((h, w), z, dtype=np.float32)
    depth[slot] = np.nan if hole_depth is None else hole_depth
    if hole_depth is not None:
        rim = slot & ~np.roll(slot, 1, axis=0)  # the slot's first row: a flying pixel
        rim |= slot & ~np.roll(slot, -1, axis=0)
        depth[rim] = 0.5 * (z + hole_depth)
    frame = Frame(
        index=0,
        stamp_ns=1_000_000_000,
        color=color,
        depth=depth,
        camera=camera,
        T_base_cam=np.eye(4),
    )
    return frame, top, bottom


@pytest.mark.parametrize("hole_depth", [None, 0.425])
def test_stroke_edges_are_where_paint_meets_metal_not_a_hole(hole_depth: float | None) -> None:
    frame, top, bottom = plate_with_slot(hole_depth=hole_depth)
    clouds = process_frame(frame, ORANGE, CONFIG)
    edges = clouds.edge_base
    assert len(edges) > 100
    x, y = edges[:, 0], edges[:, 1]
    pixel = 0.3 / 615.0
    over_slot = (x > (150 - 319.5) * pixel) & (x < (250 - 319.5) * pixel)
    # Every edge lies on one of the stroke's two sides, within a pixel.
    on_top = np.abs(y - top) < 1.5 * pixel
    on_bottom = np.abs(y - bottom) < 1.5 * pixel
    assert np.all(on_top | on_bottom)
    # The bottom side is seen all along; the top side only beside the slot, never across it,
    # and the paint's rim inside the slot (8 mm into the stroke) is no edge.
    assert on_bottom[over_slot].sum() > 30 and on_top[~over_slot].sum() > 100
    inner = (x > (155 - 319.5) * pixel) & (x < (245 - 319.5) * pixel)
    assert not on_top[inner].any()
    assert np.all(np.abs(edges[:, 2] - 0.3) < 0.001)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_boundary_pixels_are_those_with_a_4_neighbour_outside_the_set(seed: int) -> None:
    """Against the definition pixel by pixel, on random sets that touch every image border."""
    rng = np.random.default_rng(seed)
    shape = (13, 17)
    mask = rng.random(shape) < 0.6
    mask[0, :] = mask[-1, :] = mask[:, 0] = mask[:, -1] = True  # borders: outside the image
    pixels = np.flatnonzero(mask)
    padded = np.pad(mask, 1)
    inside = padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:]
    expected = np.flatnonzero(mask & ~inside)
    np.testing.assert_array_equal(boundary_pixels(pixels, shape), expected)
    assert boundary_pixels(pixels[:0], shape).size == 0


def test_sorted_union_is_numpys_union_of_ascending_pixel_sets() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        a = np.unique(rng.integers(0, 500, rng.integers(0, 60)))
        b = np.unique(rng.integers(0, 500, rng.integers(0, 60)))
        np.testing.assert_array_equal(sorted_union(a, b), np.union1d(a, b))


def _wide_blobs_by_boxes(
    pixels: np.ndarray, depth: np.ndarray, camera: CameraModel, max_width_m: float
) -> np.ndarray:
    """split_wide_blobs' wide pixels the way it was first written: every blob's box from
    scipy's find_objects over a labelled image."""
    from scipy.ndimage import find_objects, label

    height, width = depth.shape
    mask = np.zeros(height * width, dtype=bool)
    mask[pixels] = True
    labels, n = label(mask.reshape(height, width), structure=np.ones((3, 3), dtype=bool))
    blob = labels.reshape(-1)[pixels]
    count = np.bincount(blob, minlength=n + 1)
    focal = np.sqrt(camera.fx * camera.fy)
    wide = np.zeros(n + 1, dtype=bool)
    for k, box in enumerate(find_objects(labels), start=1):
        diagonal = float(np.hypot(box[0].stop - box[0].start, box[1].stop - box[1].start))
        blob_px = count[k] / max(diagonal, 1.0)
        if blob_px * 3.0 / focal < max_width_m:
            continue
        z = np.take(depth.reshape(-1), pixels[blob == k][::7]).astype(np.float64)
        z = z[np.isfinite(z) & (z > 0)]
        if z.size and blob_px * float(np.median(z)) / focal > max_width_m:
            wide[k] = True
    return pixels[wide[blob]]


@pytest.mark.parametrize("seed", range(6))
def test_split_wide_blobs_matches_boxes_of_every_blob(seed: int) -> None:
    """Boxes only for blobs that could be wide (the others bounded by their pixel count):
    the same split as boxing every blob, on specks, bands and squares at several depths."""
    rng = np.random.default_rng(seed)
    camera = small_camera()
    h, w = camera.height, camera.width
    v, u = np.mgrid[0:h, 0:w]
    mask = rng.random((h, w)) < 0.02  # specks
    for _ in range(6):
        r0, c0 = int(rng.integers(0, h - 10)), int(rng.integers(0, w - 10))
        mask[r0 : r0 + int(rng.integers(2, h)), c0 : c0 + int(rng.integers(2, w))] = True
    mask |= np.abs(v - u * rng.uniform(0.2, 2.0)) < rng.uniform(1, 8)  # a slanted band
    depth = rng.uniform(0.1, 1.5, (h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.1] = np.nan
    pixels = np.flatnonzero(mask.ravel())
    for max_width_m in (0.005, 0.02, 0.08, 0.3):
        kept, wide = split_wide_blobs(pixels, depth, camera, max_width_m=max_width_m)
        expected = _wide_blobs_by_boxes(pixels, depth, camera, max_width_m)
        np.testing.assert_array_equal(wide, expected)
        np.testing.assert_array_equal(np.sort(np.concatenate([kept, wide])), pixels)
