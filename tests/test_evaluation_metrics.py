"""Tests of scrapcut_cli.evaluation.metrics: the Table I metric on analytic cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scrapcut_cli.config import EvaluationConfig
from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.evaluation.metrics import path_error
from scrapcut_cli.geometry import make_transform, transform_points

MM = 1e-3


def line(x0: float, x1: float, n: int = 2, *, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """Points along x from x0 to x1 (metres), n vertices, at height (y, z)."""
    x = np.linspace(x0, x1, n)
    return np.column_stack([x, np.full(n, y), np.full(n, z)])


def arc(radius: float, angle: float, n: int, *, z: float = 0.0) -> np.ndarray:
    t = np.linspace(0.0, angle, n)
    return np.column_stack([radius * np.cos(t), radius * np.sin(t), np.full(n, z)])


def test_straight_path_offset_3mm_gives_exactly_3mm() -> None:
    reference = line(0.0, 0.4, 5)
    curve = line(0.0, 0.4, 7, y=3 * MM)
    e = path_error(curve, reference)
    assert e.mean_m == pytest.approx(3 * MM, abs=1e-12)
    assert e.min_m == pytest.approx(3 * MM, abs=1e-12)
    assert e.max_m == pytest.approx(3 * MM, abs=1e-12)
    assert e.sd_m == pytest.approx(0.0, abs=1e-12)
    assert e.coverage == 1.0
    assert e.reverse_mean_m == pytest.approx(3 * MM, abs=1e-12)
    assert e.reverse_max_m == pytest.approx(3 * MM, abs=1e-12)
    assert e.length_ratio == pytest.approx(1.0, abs=1e-12)
    # 400 mm sampled every 1 mm: 401 samples, normalised positions 0..1.
    assert e.samples == 401
    assert e.sample_s[0] == 0.0 and e.sample_s[-1] == pytest.approx(1.0)
    np.testing.assert_allclose(np.diff(e.sample_s), 1 / 400, atol=1e-12)
    summary = e.summary_mm()
    assert summary["mean_mm"] == pytest.approx(3.0, abs=1e-9)
    assert summary["max_mm"] == pytest.approx(3.0, abs=1e-9)


def test_offset_along_the_normal_of_an_arc() -> None:
    # Concentric arcs 3 mm apart: every sample is 3 mm from the curve, up to the sagitta of the
    # 1 mm polyline chords (s^2 / 8R = 1.25e-6 m at R = 0.1 m).
    reference = arc(0.1, np.pi, 2000)
    curve = arc(0.103, np.pi, 2000)
    e = path_error(curve, reference)
    assert e.mean_m == pytest.approx(3 * MM, abs=2e-6)
    assert e.max_m == pytest.approx(3 * MM, abs=2e-6)
    assert e.min_m == pytest.approx(3 * MM, abs=2e-6)
    assert e.length_ratio == pytest.approx(1.03, rel=1e-4)


def test_path_covering_half_the_reference() -> None:
    # The curve lies exactly on the first half of the reference, stopping 9.5 mm short of the
    # middle (half a sample off the threshold): samples 0..200 mm are within 10 mm, 201 of 401.
    reference = line(0.0, 0.4)
    curve = line(0.0, 0.1905)
    e = path_error(curve, reference)
    assert e.coverage == pytest.approx(201 / 401, abs=1e-12)
    assert e.coverage == pytest.approx(0.5, abs=0.002)
    assert e.min_m == 0.0
    assert e.max_m == pytest.approx(0.2095, abs=1e-12)
    assert e.length_ratio == pytest.approx(0.1905 / 0.4)
    # The path itself is on the reference: the reverse distance does not see the gap.
    assert e.reverse_max_m == pytest.approx(0.0, abs=1e-12)


def test_coverage_threshold_is_configurable() -> None:
    reference = line(0.0, 0.4)
    curve = line(0.0, 0.4, y=6 * MM)
    assert path_error(curve, reference).coverage == 1.0
    strict = EvaluationConfig(coverage_threshold_m=5 * MM)
    assert path_error(curve, reference, config=strict).coverage == 0.0


def test_reverse_distance_catches_a_wandering_path() -> None:
    # The curve runs over the whole reference but makes a 50 mm excursion at x = 0.2 m and
    # comes back: the reference-to-curve metric is perfect, the reverse one is not.
    reference = line(0.0, 0.4)
    curve = np.array([[0.0, 0, 0], [0.2, 0, 0], [0.2, 0.05, 0], [0.2, 0, 0], [0.4, 0, 0]])
    e = path_error(curve, reference)
    assert e.max_m == pytest.approx(0.0, abs=1e-12)
    assert e.coverage == 1.0
    assert e.reverse_max_m == pytest.approx(0.05, abs=1e-12)
    # 100 of the 500 mm of curve are off the line, at 25 mm on average.
    assert e.reverse_mean_m == pytest.approx(0.1 / 0.5 * 0.025, rel=0.02)
    assert e.length_ratio == pytest.approx(1.25)


def test_curve_vertex_density_does_not_matter() -> None:
    # Distances are to the curve's segments, not its vertices.
    reference = arc(0.2, 1.0, 50)
    sparse = line(-0.1, 0.3, 2, y=0.05)
    dense = line(-0.1, 0.3, 4001, y=0.05)
    a = path_error(sparse, reference)
    b = path_error(dense, reference)
    np.testing.assert_allclose(a.sample_errors_m, b.sample_errors_m, atol=1e-12)


def test_curve_direction_does_not_matter() -> None:
    rng = np.random.default_rng(3)
    reference = arc(0.15, 2.0, 300)
    curve = reference + rng.normal(scale=2 * MM, size=reference.shape)
    a = path_error(curve, reference)
    b = path_error(curve[::-1], reference)
    assert a.mean_m == pytest.approx(b.mean_m, abs=1e-12)
    assert a.max_m == pytest.approx(b.max_m, abs=1e-12)
    assert a.reverse_mean_m == pytest.approx(b.reverse_mean_m, abs=1e-9)


def test_invariant_to_a_rigid_motion() -> None:
    rng = np.random.default_rng(4)
    reference = arc(0.15, 2.0, 300, z=0.1)
    curve = reference + rng.normal(scale=2 * MM, size=reference.shape)
    T = make_transform(Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3))
    a = path_error(curve, reference)
    b = path_error(transform_points(T, curve), transform_points(T, reference))
    np.testing.assert_allclose(b.sample_errors_m, a.sample_errors_m, atol=1e-9)
    assert b.reverse_max_m == pytest.approx(a.reverse_max_m, abs=1e-9)


def test_noisy_curve_statistics_match_numpy() -> None:
    rng = np.random.default_rng(5)
    reference = line(0.0, 0.3, 2)
    lateral = rng.uniform(1 * MM, 4 * MM, size=301)
    curve = np.column_stack([np.linspace(0.0, 0.3, 301), lateral, np.zeros(301)])
    e = path_error(curve, reference)
    errors = e.sample_errors_m
    assert e.mean_m == pytest.approx(errors.mean())
    assert e.sd_m == pytest.approx(errors.std())
    assert 1 * MM - 1e-12 <= e.min_m <= e.max_m <= 4 * MM + 1e-12


def test_inputs_are_not_modified() -> None:
    reference = arc(0.1, 1.0, 20)
    curve = reference + 0.001
    before = (reference.copy(), curve.copy())
    path_error(curve, reference)
    np.testing.assert_array_equal(reference, before[0])
    np.testing.assert_array_equal(curve, before[1])


@pytest.mark.parametrize(
    ("curve", "message"),
    [
        (np.zeros((0, 3)), "fitted curve needs at least two distinct points"),
        (np.zeros((1, 3)), "fitted curve needs at least two distinct points"),
        (np.zeros((5, 3)), "fitted curve needs at least two distinct points"),
        (np.array([[0, 0, 0], [np.nan, 0, 0]]), "fitted curve has non-finite"),
        (np.zeros((4, 2)), "fitted curve must be an (N, 3) array"),
    ],
)
def test_bad_curves_raise_one_clear_error(curve: np.ndarray, message: str) -> None:
    with pytest.raises(EvaluationError, match=message.replace("(", r"\(").replace(")", r"\)")):
        path_error(curve, line(0.0, 0.1))


def test_bad_reference_and_config_raise() -> None:
    with pytest.raises(EvaluationError, match="reference needs at least two"):
        path_error(line(0.0, 0.1), np.zeros((1, 3)))
    with pytest.raises(EvaluationError, match="sample_spacing_m must be a finite number > 0"):
        path_error(line(0.0, 0.1), line(0.0, 0.1), config=EvaluationConfig(sample_spacing_m=0))
    with pytest.raises(EvaluationError, match="sample_spacing_m must be a finite number > 0"):
        path_error(line(0.0, 0.1), line(0.0, 0.1), config=EvaluationConfig(sample_spacing_m=np.inf))
    with pytest.raises(EvaluationError, match="coverage_threshold_m must be a finite number > 0"):
        path_error(
            line(0.0, 0.1), line(0.0, 0.1), config=EvaluationConfig(coverage_threshold_m=-1.0)
        )


def test_a_closed_100k_point_path_is_measured_in_bounded_memory() -> None:
    """A closed path (a half circle shut by its 0.6 m diameter) of 100,000 points against a
    reference 2 mm outside it. Every reference sample lies within half the long segment of
    its midpoint, so a midpoint KD-tree alone made every segment a candidate of every sample
    (10^5 x 2,000 pairs, gigabytes); cut into pieces, each sample has a few."""
    import tracemalloc

    n = 100_000
    t = np.linspace(0.0, np.pi, n - 1)
    closed = np.column_stack([0.3 * np.cos(t), 0.3 * np.sin(t), np.zeros(n - 1)])
    closed = np.vstack([closed, closed[:1]])  # back along the diameter
    s = np.linspace(0.0, np.pi, 2000)
    outside = np.column_stack([0.302 * np.cos(s), 0.302 * np.sin(s), np.zeros(2000)])
    tracemalloc.start()
    try:
        e = path_error(closed, outside)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 200e6
    assert e.mean_m == pytest.approx(2 * MM, abs=1e-6)  # the arc is 2 mm away everywhere
    assert e.max_m == pytest.approx(2 * MM, abs=1e-6)
    assert e.reverse_max_m == pytest.approx(0.302, abs=1e-3)  # the diameter's middle


def test_errors_against_sigma_and_its_calibration() -> None:
    # A straight reference and a path 1 mm beside it on its first half, 3 mm on its second;
    # the path claims σ = 1 mm on the first half (so 1 mm is within 2σ) and 1 mm on the second
    # (3 mm is not): half the samples lie within 2σ.
    x = np.linspace(0.0, 0.2, 201)
    reference = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    offset = np.where(x < 0.1, 0.001, 0.003)
    curve = np.column_stack([x, offset, np.zeros_like(x)])
    error = path_error(curve, reference, sigma_m=np.full(len(x), 0.001))
    assert error.sample_sigma_m is not None
    assert error.within_2sigma == pytest.approx(0.5, abs=0.02)
    figures = error.summary_mm()
    assert figures["sigma_median_mm"] == pytest.approx(1.0)
    assert figures["within_2sigma"] == pytest.approx(0.5, abs=0.02)
    # σ growing along the curve is interpolated at each sample's nearest curve point.
    grown = path_error(curve, reference, sigma_m=np.where(x < 0.1, 0.001, 0.002))
    assert grown.within_2sigma == pytest.approx(1.0, abs=0.01)  # (the step itself)
    # Without σ: no calibration figures.
    plain = path_error(curve, reference)
    assert plain.within_2sigma is None and plain.summary_mm()["sigma_median_mm"] is None
    with pytest.raises(EvaluationError, match="sigma_m"):
        path_error(curve, reference, sigma_m=np.full(5, 0.001))
    with pytest.raises(EvaluationError, match="sigma_m"):
        path_error(curve, reference, sigma_m=np.full(len(x), -0.001))
