"""Stitching: voxel deduplication, growth per frame, guarded ICP, the recording recipe."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from perception_scenes import (
    CYLINDER_AXIS_YZ,
    CYLINDER_RADIUS_M,
    NOISY,
    cylinder_top_line,
    render_cylinder,
    small_camera,
    top_view,
)

from scrapcut_cli.config import PerceptionConfig, ScrapcutConfig, StitchConfig
from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.geometry import (
    PolylineDistance,
    make_transform,
    nearest_distances,
    pack_voxel_keys,
    resample_polyline,
    voxel_keys,
)
from scrapcut_cli.perception.cloud import FrameClouds, process_frame
from scrapcut_cli.perception.paint import PAINT_PRESETS
from scrapcut_cli.perception.stitch import Stitcher, stitch_recording
from scrapcut_cli.recording.frame import Frame

ORANGE = PAINT_PRESETS["orange"].hsv
PERCEPTION = PerceptionConfig()
HALF_WIDTH = 0.0125
SWEEP_X = np.linspace(-0.12, 0.12, 9)


def radial_error(points: np.ndarray) -> np.ndarray:
    y0, z0 = CYLINDER_AXIS_YZ
    return np.abs(np.hypot(points[:, 1] - y0, points[:, 2] - z0) - CYLINDER_RADIUS_M)


@pytest.fixture(scope="module")
def reference() -> np.ndarray:
    return cylinder_top_line()


@pytest.fixture(scope="module")
def sweep(reference: np.ndarray) -> list[Frame]:
    """Nine noisy views along the stroke, overlapping by about two thirds."""
    return [
        render_cylinder(
            small_camera(),
            top_view(x, tilt_m=0.03 * np.sin(3 * i)),
            reference,
            noise=NOISY,
            seed=i,
            index=i,
        )
        for i, x in enumerate(SWEEP_X)
    ]


@pytest.fixture(scope="module")
def sweep_clouds(sweep: list[Frame]) -> list[FrameClouds]:
    return [process_frame(f, ORANGE, PERCEPTION) for f in sweep]


def stitcher(**stitch: object) -> Stitcher:
    return Stitcher(replace(StitchConfig(), **stitch), perception=PERCEPTION)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- deduplication


@pytest.mark.parametrize("icp", [False, True])
def test_stitching_the_same_frame_twice_adds_nothing(
    sweep_clouds: list[FrameClouds], icp: bool
) -> None:
    s = stitcher(icp=icp)
    first = s.add(sweep_clouds[4])
    points, surface = s.paint_points, s.surface_points
    second = s.add(sweep_clouds[4])
    assert first.growth == first.size > 100
    assert second.growth == 0 and second.size == first.size
    assert second.surface_size == first.surface_size
    np.testing.assert_allclose(s.paint_points, points, atol=1e-15)  # the mean of equals
    np.testing.assert_allclose(s.surface_points, surface, atol=1e-15)
    if icp:
        assert second.icp is not None and not second.icp.accepted
        assert second.icp.reason == "no_improvement"


def test_each_voxel_counts_the_frames_that_saw_it(sweep_clouds: list[FrameClouds]) -> None:
    s = stitcher()
    s.add(sweep_clouds[4])
    assert np.all(s.paint_frames == 1) and len(s.paint_frames) == len(s.paint_points)
    assert np.all(s.surface_frames == 1) and len(s.surface_frames) == len(s.surface_points)
    assert len(s.edge_points) > 20 and np.all(s.edge_frames == 1)
    s.add(sweep_clouds[4])
    assert np.all(s.paint_frames == 2) and np.all(s.edge_frames == 2)
    # A sweep: overlapping views see the middle of the stroke more often than its ends.
    full = stitcher()
    for c in sweep_clouds:
        full.add(c)
    frames = full.paint_frames
    assert frames.min() >= 1 and frames.max() <= len(sweep_clouds)
    x = full.paint_points[:, 0]
    assert np.median(frames[np.abs(x) < 0.05]) > np.median(frames[np.abs(x) > 0.13])
    kept = full.kept_clouds()
    assert len(kept["edge_points"]) == len(kept["edge_frames"]) == len(full.edge_points)


def test_size_counts_occupied_voxels_and_growth_is_its_increment(
    sweep_clouds: list[FrameClouds],
) -> None:
    s = stitcher()
    steps = [s.add(c) for c in sweep_clouds]
    sizes = np.array([st.size for st in steps])
    assert np.all(np.diff(sizes) >= 0)
    assert [st.growth for st in steps] == list(np.diff(sizes, prepend=0))
    assert [st.k for st in steps] == list(range(len(steps)))
    keys = pack_voxel_keys(voxel_keys(s.paint_points, StitchConfig().voxel_size_m))
    assert len(np.unique(keys)) == s.size == len(s.paint_points)
    # Overlapping views: every later frame grows the cloud by less than it holds.
    assert all(st.growth < st.frame_points for st in steps[1:])


def test_viewpoints_are_the_cameras_that_first_saw_each_voxel(
    sweep: list[Frame], sweep_clouds: list[FrameClouds]
) -> None:
    s = stitcher()
    for c in sweep_clouds:
        s.add(c)
    cameras = np.array([f.camera_position for f in sweep])
    for points, views in (
        (s.paint_points, s.paint_viewpoints),
        (s.surface_points, s.surface_viewpoints),
    ):
        assert views.shape == points.shape
        assert nearest_distances(views, cameras).max() < 1e-12
        # The viewpoint sees the point's side of the pipe (front-facing, not grazing).
        y0, z0 = CYLINDER_AXIS_YZ
        normal = np.column_stack([np.zeros(len(points)), points[:, 1] - y0, points[:, 2] - z0])
        to_view = views - points
        cos = np.einsum("ij,ij->i", normal, to_view) / (
            np.linalg.norm(normal, axis=1) * np.linalg.norm(to_view, axis=1)
        )
        assert cos.min() > 0.1


def test_skipped_frames_leave_the_cloud_alone(sweep: list[Frame]) -> None:
    s = stitcher()
    s.add(process_frame(sweep[0], ORANGE, PERCEPTION))
    before = s.size
    blue = process_frame(sweep[1], PAINT_PRESETS["blue"].hsv, PERCEPTION)
    step = s.add(blue)
    assert step.skip_reason == "no_paint" and step.growth == 0 and s.size == before


# --------------------------------------------------------------------------- accuracy


def test_stitched_sweep_lies_on_the_stroke_and_covers_it(
    sweep_clouds: list[FrameClouds], reference: np.ndarray
) -> None:
    s = stitcher()
    for c in sweep_clouds:
        s.add(c)
    d = PolylineDistance(reference).distance(s.paint_points)
    assert np.quantile(d, 0.99) <= HALF_WIDTH + 0.002
    assert radial_error(s.paint_points).max() < 0.003
    # Reference samples between the first and last view's centres (the views' ends are
    # covered too, but the stroke runs on beyond them).
    samples = resample_polyline(reference, 0.001)
    inside = (samples[:, 0] > SWEEP_X[0]) & (samples[:, 0] < SWEEP_X[-1])
    near = nearest_distances(samples[inside], s.paint_points)
    assert np.mean(near < 0.005) >= 0.99


# --------------------------------------------------------------------------- ICP


@pytest.fixture(scope="module")
def overlapping_pair(reference: np.ndarray) -> tuple[FrameClouds, Frame]:
    first = render_cylinder(small_camera(), top_view(0.0), reference, index=0)
    second = render_cylinder(small_camera(), top_view(0.03), reference, index=1)
    return process_frame(first, ORANGE, PERCEPTION), second


def shifted(frame: Frame, offset: list[float]) -> FrameClouds:
    moved = replace(frame, T_base_cam=make_transform(np.eye(3), offset) @ frame.T_base_cam)
    return process_frame(moved, ORANGE, PERCEPTION)


def test_icp_removes_an_offset_along_the_surface_normal(
    overlapping_pair: tuple[FrameClouds, Frame],
) -> None:
    first, second = overlapping_pair
    wrong = shifted(second, [0.0, 0.0, 0.003])  # 3 mm off the pipe's top
    plain = stitcher()
    plain.add(first)
    plain.add(wrong)
    s = stitcher(icp=True)
    s.add(first)
    step = s.add(wrong)
    assert step.icp is not None and step.icp.accepted, step.icp
    centroid = wrong.paint_base.mean(axis=0)
    moved = (step.icp.T_correction[:3, :3] @ centroid + step.icp.T_correction[:3, 3]) - centroid
    assert abs(moved[2] - -0.003) < 2e-4  # the normal offset is undone
    assert np.linalg.norm(moved[:2]) < 1e-3  # tangential: ICP's weak direction
    assert step.icp.fitness_after > step.icp.fitness_before
    # Reported at the centroid of the overlapping part, which is near the whole frame's.
    assert step.icp.translation_m == pytest.approx(np.linalg.norm(moved), rel=0.05)
    # The stitched cloud is one layer again, not two 3 mm apart.
    assert np.quantile(radial_error(s.paint_points), 0.95) < 0.001
    assert np.quantile(radial_error(plain.paint_points), 0.95) > 0.0025


def test_icp_guards_reject_large_corrections_and_missing_overlap(
    overlapping_pair: tuple[FrameClouds, Frame],
) -> None:
    first, second = overlapping_pair
    wrong = shifted(second, [0.0, 0.0, 0.003])
    for bounds, reason in (
        ({"icp_max_translation_m": 0.001}, "translation_too_large"),
        ({"icp_max_rotation_deg": 0.0}, "rotation_too_large"),
    ):
        s = stitcher(icp=True, **bounds)
        s.add(first)
        step = s.add(wrong)
        assert step.icp is not None and step.icp.reason == reason and not step.icp.accepted
        np.testing.assert_array_equal(step.icp.T_correction, np.eye(4))
    s = stitcher(icp=True)
    assert s.add(first).icp is not None and s.steps[0].icp.reason == "first_frame"  # type: ignore[union-attr]
    step = s.add(shifted(second, [0.0, 0.0, 0.05]))  # 5 cm above the pipe: nothing near
    assert step.icp is not None and step.icp.reason == "low_overlap"
    assert step.growth == step.size - s.steps[0].size > 0  # stitched as it is


def test_bad_stitch_parameters_raise() -> None:
    with pytest.raises(PerceptionError, match="icp_method"):
        stitcher(icp_method="magic")
    with pytest.raises(PerceptionError, match="voxel_size_m"):
        stitcher(voxel_size_m=0.0)
    with pytest.raises(PerceptionError, match="icp_min_overlap"):
        stitcher(icp_min_overlap=2.0)


def test_a_voxel_too_fine_to_index_is_a_known_error(sweep_clouds: list[FrameClouds]) -> None:
    # 0.1 um voxels: the points, 0.5 m from the origin, are 5e6 voxels out (> 2^20).
    s = stitcher(voxel_size_m=1e-7)
    with pytest.raises(PerceptionError, match=r"--stitch-voxel-mm 0\.0001 is too fine"):
        s.add(sweep_clouds[0])


# --------------------------------------------------------------------------- the recipe


def test_stitch_recording_reports_each_frame_and_is_deterministic(sweep: list[Frame]) -> None:
    seen: list[int] = []
    result = stitch_recording(
        iter(sweep), ORANGE, ScrapcutConfig(), progress=lambda s: seen.append(s.k)
    )
    assert seen == list(range(len(sweep)))
    assert result.size == result.steps[-1].size == len(result.paint_points)
    assert result.tally.frames == len(sweep) and result.tally.frames_with_paint == len(sweep)
    again = stitch_recording(sweep, ORANGE, ScrapcutConfig())
    assert again.paint_points.tobytes() == result.paint_points.tobytes()
    assert again.surface_points.tobytes() == result.surface_points.tobytes()
    record = json.loads(json.dumps(result.to_dict()))
    assert [s["growth"] for s in record["steps"]] == [s.growth for s in result.steps]
    assert record["size"] == result.size and record["frames"] == len(sweep)


def test_stitch_recording_without_paint_names_the_range_and_hues(sweep: list[Frame]) -> None:
    green = PAINT_PRESETS["green"].hsv
    with pytest.raises(PerceptionError) as info:
        stitch_recording(sweep[:3], green, ScrapcutConfig())
    message = str(info.value)
    assert message.startswith("no paint found in any of 3 frames with green (hue 85-165 deg")
    assert "dominant hues seen: 30 deg" in message


def test_frames_without_paint_are_counted_not_fatal(sweep: list[Frame]) -> None:
    blank = replace(sweep[1], color=np.full_like(sweep[1].color, 100))
    result = stitch_recording([sweep[0], blank, sweep[2]], ORANGE, ScrapcutConfig())
    assert result.skip_reasons == {"no_paint": 1}
    assert result.tally.frames_with_paint == 2
    assert result.steps[1].growth == 0


def _voxel_map_by_insertion(
    batches: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]], voxel: float
) -> dict[str, np.ndarray]:
    """The voxel map as first written: every array kept in key order, new voxels inserted."""
    from scrapcut_cli.geometry import pack_voxel_keys, voxel_keys

    keys = np.zeros(0, dtype=np.int64)
    sums, rgb_sums, vps = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
    counts, frames = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    for points, viewpoint, rgb in batches:
        k, inverse = np.unique(pack_voxel_keys(voxel_keys(points, voxel)), return_inverse=True)
        c = np.bincount(inverse, minlength=k.size)
        s = np.column_stack([np.bincount(inverse, points[:, i], k.size) for i in range(3)])
        colours = np.full((len(points), 3), np.nan) if rgb is None else rgb
        r = np.column_stack([np.bincount(inverse, colours[:, i], k.size) for i in range(3)])
        pos = np.searchsorted(keys, k)
        found = pos < keys.size
        found[found] = keys[pos[found]] == k[found]
        sums[pos[found]] += s[found]
        rgb_sums[pos[found]] += r[found]
        counts[pos[found]] += c[found]
        frames[pos[found]] += 1
        new = ~found
        where = pos[new]
        keys = np.insert(keys, where, k[new])
        sums = np.insert(sums, where, s[new], axis=0)
        rgb_sums = np.insert(rgb_sums, where, r[new], axis=0)
        counts = np.insert(counts, where, c[new])
        frames = np.insert(frames, where, 1)
        vps = np.insert(vps, where, viewpoint, axis=0)
    return {
        "keys": keys,
        "points": sums / counts[:, None],
        "rgb": rgb_sums / counts[:, None],
        "frames": frames,
        "viewpoints": vps,
    }


@pytest.mark.parametrize("seed", range(4))
def test_voxel_map_matches_sorted_insertion(seed: int) -> None:
    """Values stored in first-seen order and read through the sorted keys' slots: the same
    keys, means, colours, frame counts and viewpoints as keeping every array sorted."""
    from scrapcut_cli.perception.stitch import _VoxelMap

    rng = np.random.default_rng(seed)
    voxel = 0.002
    vmap = _VoxelMap(voxel, option="--stitch-voxel-mm")
    batches: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]] = []
    centre = np.zeros(3)
    for k in range(40):
        centre = centre + rng.normal(0.0, 0.004, 3)  # a sweep: overlapping frames
        points = centre + rng.normal(0.0, 0.01, (int(rng.integers(0, 900)), 3))
        rgb = None if k % 5 == 3 else rng.random((len(points), 3))
        viewpoint = centre + np.array([0.0, 0.0, 0.3])
        batches.append((points, viewpoint, rgb))
        vmap.add(points, viewpoint, rgb)
        assert len(vmap) == len(np.unique(vmap.keys))
    expected = _voxel_map_by_insertion(batches, voxel)
    np.testing.assert_array_equal(vmap.keys, expected["keys"])
    np.testing.assert_allclose(vmap.points, expected["points"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(vmap.rgb, expected["rgb"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(vmap.frames, expected["frames"])
    np.testing.assert_array_equal(vmap.viewpoints, expected["viewpoints"])
