"""Tests of scrapcut_cli.sim.camera: the D435i noise model measured the way Intel measures it."""

from __future__ import annotations

import numpy as np
import pytest

from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import look_at, rotation_angle, transform_points
from scrapcut_cli.sim import make_object
from scrapcut_cli.sim.camera import (
    NOISE_PRESETS,
    T_CAMLINK_OPTICAL,
    T_HAND_CAMLINK,
    d435i_color_camera,
    depth_to_millimetres,
    noise_preset,
    perturb_hand_eye,
    simulate_color,
    simulate_depth,
)
from scrapcut_cli.sim.render import FLOOR, SceneRenderer
from scrapcut_cli.sim.surface import OVERSPRAY_PRESETS, PaintStroke

D435I = NOISE_PRESETS["d435i"]


def floor_view(height_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact depth, incidence and pose of a camera looking straight down at the floor."""
    obj = make_object("planar_box", placement=(4.0, 4.0, 0.0))  # out of sight
    stroke = PaintStroke(obj.reference, width_m=0.025, rgb=(255, 110, 0))
    T = look_at((0.6, 0.0, height_m), (0.6, 0.0, 0.0), up_hint=(1.0, 0.0, 0.0))
    view = SceneRenderer(obj, stroke).render(T, d435i_color_camera(320, 240))
    assert (view.geometry == FLOOR).all()
    return view.depth, view.cos_incidence, T


def plane_fit_rms(depth: np.ndarray) -> float:
    """RMS (m) of the residuals of the best plane through the back-projected valid pixels."""
    camera = d435i_color_camera(320, 240)
    v, u = np.nonzero(np.isfinite(depth))
    points = camera.unproject(u, v, depth[v, u])
    centred = points - points.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
    return float(np.sqrt(np.mean((centred @ normal) ** 2)))


@pytest.mark.parametrize("distance_m", [0.3, 0.6])
def test_depth_rms_error_on_a_plane_matches_the_d435_formula(distance_m: float) -> None:
    """σ_z = z²·s/(f·B) within 15 %, measured on the float depth before 1 mm quantisation.

    (At 0.3 m σ_z = 0.32 mm is below the 1 mm step of 16UC1, whose rounding would dominate the
    measurement; the quantised case is checked at 0.6 m below.)
    """
    depth, cos, _ = floor_view(distance_m)
    rng = np.random.default_rng(11)
    noisy = simulate_depth(depth, cos, D435I, rng)
    expected = distance_m**2 * 0.08 / (447.0 * 0.050)
    assert D435I.depth_sigma_m(distance_m) == pytest.approx(expected, rel=1e-12)
    assert plane_fit_rms(noisy) == pytest.approx(expected, rel=0.15)


def test_quantised_depth_adds_the_step_variance_when_noise_exceeds_it() -> None:
    depth, cos, _ = floor_view(0.6)
    noisy = simulate_depth(depth, cos, D435I, np.random.default_rng(12))
    mm = depth_to_millimetres(noisy)
    quantised = np.where(mm > 0, mm / 1000.0, np.nan)
    sigma = D435I.depth_sigma_m(0.6)
    assert plane_fit_rms(quantised) == pytest.approx(np.hypot(sigma, 0.001 / np.sqrt(12)), rel=0.15)


def test_ideal_preset_keeps_exact_depth() -> None:
    depth, cos, _ = floor_view(0.3)
    exact = simulate_depth(depth, cos, NOISE_PRESETS["ideal"], np.random.default_rng(0))
    assert np.allclose(exact, depth.astype(np.float32), rtol=0, atol=0)
    assert plane_fit_rms(exact) < 1e-6


def test_depth_range_limits() -> None:
    ones = np.ones((40, 40))
    for z, valid in ((0.15, False), (0.2, True), (2.5, True), (3.5, False)):
        out = simulate_depth(ones * z, ones, D435I, np.random.default_rng(0))
        assert np.isfinite(out).mean() == (pytest.approx(1.0, abs=0.01) if valid else 0.0)
    ideal = simulate_depth(ones * 0.1, ones, NOISE_PRESETS["ideal"], np.random.default_rng(0))
    assert np.isfinite(ideal).all()


def test_grazing_incidence_makes_holes_and_dropout_is_sparse() -> None:
    shape = (200, 200)
    z = np.full(shape, 0.4)
    head_on = simulate_depth(z, np.ones(shape), D435I, np.random.default_rng(1))
    assert 1 - np.isfinite(head_on).mean() == pytest.approx(D435I.dropout, abs=0.001)
    at_60 = simulate_depth(
        z, np.full(shape, np.cos(np.radians(60))), D435I, np.random.default_rng(1)
    )
    at_80 = simulate_depth(
        z, np.full(shape, np.cos(np.radians(80))), D435I, np.random.default_rng(1)
    )
    at_88 = simulate_depth(
        z, np.full(shape, np.cos(np.radians(88))), D435I, np.random.default_rng(1)
    )
    assert np.isfinite(at_60).mean() > 0.99
    assert 0.25 < np.isfinite(at_80).mean() < 0.45  # 2/3 of the way up the 70-85 deg ramp
    assert np.isfinite(at_88).sum() == 0


def test_flying_pixels_appear_only_at_depth_edges() -> None:
    z = np.full((60, 80), 0.3)
    z[:, 40:] = 0.5
    out = simulate_depth(z, np.ones_like(z), D435I, np.random.default_rng(2))
    between = np.isfinite(out) & (out > 0.305) & (out < 0.495)
    cols = np.unique(np.nonzero(between)[1])
    assert set(cols.tolist()) == {39}  # the foreground pixel next to the jump
    assert 0.3 < between[:, 39].mean() < 0.7  # chance 0.5


def test_colour_noise_has_the_preset_sigma() -> None:
    grey = np.full((200, 200, 3), 0.5)
    out = simulate_color(grey, D435I, np.random.default_rng(3)).astype(float)
    assert out.std() == pytest.approx(2.0, rel=0.05)
    assert out.mean() == pytest.approx(127.5, abs=0.1)
    ideal = simulate_color(grey, NOISE_PRESETS["ideal"], np.random.default_rng(3))
    assert np.all(ideal == 128)


def test_hand_eye_error_has_the_yard_magnitude() -> None:
    yard = noise_preset("yard")
    for seed in range(5):
        T = perturb_hand_eye(T_HAND_CAMLINK, yard, np.random.default_rng(seed))
        delta = np.linalg.inv(T_HAND_CAMLINK) @ T
        assert np.linalg.norm(delta[:3, 3]) == pytest.approx(0.002, rel=1e-9)
        assert np.degrees(rotation_angle(np.eye(3), delta[:3, :3])) == pytest.approx(0.3, rel=1e-6)


def test_millimetre_encoding_rounds_and_marks_invalid_zero() -> None:
    depth = np.array([[0.3004, 0.3006, np.nan], [0.0, 70.0, 1.0]], dtype=np.float32)
    assert depth_to_millimetres(depth).tolist() == [[300, 301, 0], [0, 0, 1000]]


def test_camera_model_and_mount() -> None:
    full = d435i_color_camera()
    assert (full.width, full.height) == (640, 480)
    assert full.fx == pytest.approx(615, abs=1) and full.fy == pytest.approx(615, abs=1)
    half = d435i_color_camera(320, 240)
    assert half.fx == pytest.approx(full.fx / 2) and half.frame_id == full.frame_id
    # The optical axis (z) looks along camera_link x, which looks along the hand's z.
    T_hand_opt = T_HAND_CAMLINK @ T_CAMLINK_OPTICAL
    assert np.allclose(T_hand_opt[:3, 2], (0.0, 0.0, 1.0))
    assert np.allclose(np.linalg.det(T_hand_opt[:3, :3]), 1.0)
    assert np.allclose(transform_points(T_CAMLINK_OPTICAL, [[0.0, 0.0, 1.0]]), [[1.0, 0.015, 0.0]])
    with pytest.raises(SimError, match="unknown noise preset"):
        noise_preset("foggy")
    assert OVERSPRAY_PRESETS[D435I.overspray].density > 0
