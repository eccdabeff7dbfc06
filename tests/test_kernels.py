"""The compiled neighbour kernels (scrapcut_cli/_native.c through scrapcut_cli._kernels) against
open3d's statistical outlier removal and scipy's bounded nearest-neighbour query: the same
points kept, the same points within the band, on clouds shaped like a frame's and on the
awkward ones (duplicates, far outliers, lines, planes, fewer points than neighbours)."""

from __future__ import annotations

import importlib
import os
import shutil
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from scrapcut_cli import _kernels
from scrapcut_cli._open3d import o3d

native = pytest.mark.skipif(
    not _kernels.native(), reason="the compiled kernels did not build (no C compiler?)"
)


def open3d_inliers(points: np.ndarray, k: int, ratio: float) -> np.ndarray:
    o3 = o3d()
    cloud = o3.geometry.PointCloud(o3.utility.Vector3dVector(np.asarray(points, dtype=float)))
    _, kept = cloud.remove_statistical_outlier(nb_neighbors=k, std_ratio=ratio)
    return np.asarray(kept, dtype=np.intp)


def stroke_cloud(rng: np.random.Generator, n_outliers: int = 30) -> np.ndarray:
    """A frame's paint voxels: a 2 mm grid on a bent strip 25 mm wide, depth noise, outliers
    scattered up to 5 cm off it, in no particular order (as a voxel downsampling returns)."""
    s, w = np.meshgrid(np.arange(0, 0.16, 0.002), np.arange(-0.0125, 0.0125, 0.002))
    s, w = s.ravel(), w.ravel()
    strip = np.c_[0.3 * np.sin(s / 0.3), w, 0.3 * (1 - np.cos(s / 0.3))]
    strip += rng.normal(0, 0.0004, strip.shape)
    out = strip[rng.integers(0, len(strip), n_outliers)] + rng.normal(0, 0.02, (n_outliers, 3))
    pts = np.vstack([strip, out]) + np.array([0.4, -0.1, 0.05])
    return pts[rng.permutation(len(pts))]


def clouds() -> list[tuple[str, np.ndarray]]:
    rng = np.random.default_rng(7)
    line = np.c_[np.linspace(0, 1, 500), np.zeros(500), np.zeros(500)]
    lattice = np.round(rng.uniform(0, 0.05, (1500, 3)) / 0.002) * 0.002  # many duplicates
    plane = np.c_[rng.uniform(0, 0.1, 2000), rng.uniform(0, 0.1, 2000), np.zeros(2000)]
    blob = rng.normal(size=(800, 3))
    far = stroke_cloud(rng, 5)
    far[:3] += [50.0, -20.0, 1000.0]  # a handful kilometres off: the exhaustive fallback
    # a tight knot in a sparse cloud: no one grid suits both, the kernel declines (open3d)
    knot = np.vstack([rng.normal(0, 1e-4, (600, 3)), rng.uniform(-1, 1, (300, 3))])
    return [
        ("stroke", stroke_cloud(rng)),
        ("stroke, no outliers", stroke_cloud(rng, 0)),
        ("line", line),
        ("lattice with duplicates", lattice),
        ("plane", plane),
        ("gaussian blob", blob),
        ("far outliers", far),
        ("dense knot in a sparse cloud", knot),
    ]


@native
@pytest.mark.parametrize(("name", "points"), clouds(), ids=[name for name, _ in clouds()])
@pytest.mark.parametrize(("k", "ratio"), [(20, 2.0), (1, 1.0), (6, 0.5), (50, 3.0)])
def test_compiled_outlier_removal_keeps_what_open3d_keeps(
    name: str, points: np.ndarray, k: int, ratio: float
) -> None:
    kept = _kernels.statistical_inliers(points, neighbors=k, std_ratio=ratio)
    expected = open3d_inliers(points, k, ratio)
    assert kept.dtype == np.intp
    np.testing.assert_array_equal(kept, expected, err_msg=name)


@native
def test_outlier_removal_really_removes_the_scattered_points() -> None:
    # The comparison above would also pass if both kept everything: here the 30 points
    # scattered off the strip are found (the strip's own noisy edge may lose a few more).
    rng = np.random.default_rng(3)
    strip = stroke_cloud(rng, 0)
    scattered = strip[:30] + rng.normal(0, 0.01, (30, 3)) + [0, 0, 0.05]
    kept = _kernels.statistical_inliers(np.vstack([strip, scattered]), neighbors=20, std_ratio=2)
    assert np.sum(kept >= len(strip)) <= 3
    assert np.sum(kept < len(strip)) >= 0.95 * len(strip)


@native
def test_outlier_removal_on_random_clouds_equals_open3d() -> None:
    rng = np.random.default_rng(11)
    for trial in range(60):
        n = int(rng.integers(2, 1500))
        points = rng.normal(size=(n, 3)) * rng.uniform(1e-4, 10, 3)
        if trial % 3 == 0:
            points[: n // 4] = points[0]  # a quarter of them one point
        k = int(rng.integers(1, 30))
        ratio = float(rng.uniform(0.1, 4))
        np.testing.assert_array_equal(
            _kernels.statistical_inliers(points, neighbors=k, std_ratio=ratio),
            open3d_inliers(points, k, ratio) if n > k else np.arange(n),
            err_msg=f"trial {trial}: n={n} k={k}",
        )


@native
def test_the_kernel_declines_a_cloud_no_grid_suits() -> None:
    from scrapcut_cli import _native

    rng = np.random.default_rng(4)
    knot = np.vstack([rng.normal(0, 1e-4, (2000, 3)), rng.uniform(-1, 1, (1000, 3))])
    assert _native.statistical_inliers(knot, 20, 2.0, np.zeros(len(knot), np.uint8)) == -1
    strip = stroke_cloud(rng)
    kept = _native.statistical_inliers(strip, 20, 2.0, keep := np.zeros(len(strip), np.uint8))
    assert kept == keep.sum() > 0.9 * len(strip)


def test_outlier_removal_edge_cases_without_a_tree() -> None:
    pts = np.random.default_rng(0).normal(size=(10, 3))
    np.testing.assert_array_equal(
        _kernels.statistical_inliers(pts, neighbors=0, std_ratio=2.0), np.arange(10)
    )
    np.testing.assert_array_equal(
        _kernels.statistical_inliers(pts, neighbors=10, std_ratio=2.0), np.arange(10)
    )
    assert _kernels.statistical_inliers(np.zeros((0, 3)), neighbors=5, std_ratio=2).size == 0


def test_all_points_on_one_spot_keep_none_like_open3d() -> None:
    # Every mean distance is 0: open3d keeps only positive means.
    pts = np.tile([0.1, 0.2, 0.3], (40, 1))
    assert _kernels.statistical_inliers(pts, neighbors=5, std_ratio=2.0).size == 0
    assert open3d_inliers(pts, 5, 2.0).size == 0


def test_a_ratio_open3d_refuses_is_refused_alike() -> None:
    pts = stroke_cloud(np.random.default_rng(8))
    with pytest.raises(RuntimeError, match="positive"):
        _kernels.statistical_inliers(pts, neighbors=20, std_ratio=0.0)


def test_non_finite_points_take_open3d_s_path() -> None:
    pts = stroke_cloud(np.random.default_rng(5))
    pts[4] = np.nan
    np.testing.assert_array_equal(
        _kernels.statistical_inliers(pts, neighbors=20, std_ratio=2.0),
        open3d_inliers(pts, 20, 2.0),
    )


def scipy_within(points: np.ndarray, targets: np.ndarray, radius: float) -> np.ndarray:
    distance, _ = cKDTree(targets).query(points, distance_upper_bound=radius)
    return np.isfinite(distance)


@native
def test_compiled_within_distance_equals_scipy() -> None:
    rng = np.random.default_rng(2)
    targets = stroke_cloud(rng)[::7]
    points = targets.mean(axis=0) + rng.uniform(-0.15, 0.15, (20000, 3))
    for radius in (0.04, 0.005, 0.08):
        got = _kernels.within_distance(points, targets, radius)
        expected = scipy_within(points, targets, radius)
        assert got.dtype == bool
        np.testing.assert_array_equal(got, expected)
        assert 0 < got.sum() < len(points)  # both kinds present


@native
def test_within_distance_is_strictly_closer_than_the_radius() -> None:
    targets = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    points = np.array([[0.5, 0, 0], [0.4999999, 0, 0], [0.3, 0.4, 0.0], [1, 1, 1.2], [9, 9, 9]])
    np.testing.assert_array_equal(
        _kernels.within_distance(points, targets, 0.5), [False, True, False, True, False]
    )
    np.testing.assert_array_equal(
        scipy_within(points, targets, 0.5), [False, True, False, True, False]
    )


def test_within_distance_without_points_targets_or_radius() -> None:
    pts = np.ones((3, 3))
    assert not _kernels.within_distance(pts, np.zeros((0, 3)), 1.0).any()
    assert _kernels.within_distance(np.zeros((0, 3)), pts, 1.0).shape == (0,)
    assert not _kernels.within_distance(pts, pts, 0.0).any()
    assert _kernels.within_distance(pts, np.zeros((1, 3)), float("inf")).all()


def test_fallback_gives_the_same_results(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(9)
    pts = stroke_cloud(rng)
    targets = pts[::11]
    probes = pts.mean(axis=0) + rng.uniform(-0.1, 0.1, (3000, 3))
    first = (
        _kernels.statistical_inliers(pts, neighbors=20, std_ratio=2.0),
        _kernels.within_distance(probes, targets, 0.02),
    )
    monkeypatch.setattr(_kernels, "_native", None)
    assert not _kernels.native()
    np.testing.assert_array_equal(
        _kernels.statistical_inliers(pts, neighbors=20, std_ratio=2.0), first[0]
    )
    np.testing.assert_array_equal(_kernels.within_distance(probes, targets, 0.02), first[1])


def test_environment_switches_the_compiled_kernels_off(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SCRAPCUT_NATIVE", "0")
    assert _kernels._load_native() is None
    monkeypatch.delenv("SCRAPCUT_NATIVE")
    assert (_kernels._load_native() is not None) == (
        importlib.util.find_spec("scrapcut_cli._native") is not None
    )


@native
def test_compiled_kernels_check_their_buffers() -> None:
    from scrapcut_cli import _native

    pts = np.zeros((4, 3))
    with pytest.raises(ValueError, match="uint8"):
        _native.statistical_inliers(pts, 2, 2.0, np.zeros(3, np.uint8))
    with pytest.raises(ValueError, match="positive"):
        _native.statistical_inliers(pts, 0, 2.0, np.zeros(4, np.uint8))
    with pytest.raises(ValueError, match="positive"):
        _native.within_distance(pts, pts, float("nan"), np.zeros(4, np.uint8))
    with pytest.raises(TypeError):
        _native.within_distance(pts, pts, 0.1, b"read-only")


def test_within_distance_with_a_radius_tiny_against_the_spread() -> None:
    # 1e-20 m cells across 1e30 m: the cell indices saturate, the answer stays exact.
    targets = np.array([[0.0, 0.0, 0.0], [1e30, 0.0, 0.0]])
    points = np.array([[1e-25, 0.0, 0.0], [1e30, 0.0, 1e-25], [5.0, 5.0, 5.0], [2e-20, 0, 0]])
    np.testing.assert_array_equal(
        _kernels.within_distance(points, targets, 1e-20), [True, True, False, False]
    )


def test_the_extension_is_built_where_it_can_be() -> None:
    # The extension is optional, so a build error during `pip install` is only a warning and
    # every test above would silently run the fallback: where a C compiler and Python's headers
    # are present (as on the machines `make test` runs on), it must have been built.
    headers = Path(sysconfig.get_paths()["include"], "Python.h").exists()
    compiler = any(shutil.which(cc) for cc in ("cc", "gcc", "clang"))
    if os.environ.get("SCRAPCUT_NATIVE", "").strip() == "0" or not (headers and compiler):
        pytest.skip("no C compiler or Python headers here, or SCRAPCUT_NATIVE=0")
    assert _kernels.native(), "scrapcut_cli/_native.c did not build: see `pip install -v -e .`"
