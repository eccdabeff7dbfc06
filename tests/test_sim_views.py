"""Tests of scrapcut_cli.sim.views: sweep and survey views, the pre-planned planner."""

from __future__ import annotations

import numpy as np
import pytest

from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import cumulative_length, interpolate_polyline
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.sim import make_object
from scrapcut_cli.sim.camera import d435i_color_camera
from scrapcut_cli.sim.views import PrePlannedPlanner, survey_views, sweep_views, tilt_up


def elevation_deg(v: np.ndarray) -> float:
    return float(np.degrees(np.arcsin(v[2] / np.linalg.norm(v))))


def test_tilt_up_raises_low_directions_only() -> None:
    steep = np.array([0.3, 0.0, 0.9])
    assert np.allclose(tilt_up(steep, 35.0), steep / np.linalg.norm(steep))
    raised = tilt_up((0.0, -1.0, 0.0), 35.0)
    assert elevation_deg(raised) == pytest.approx(35.0)
    assert raised[0] == pytest.approx(0.0) and raised[1] < 0


@pytest.mark.parametrize("name", ["cylinder", "i_beam", "basket"])
def test_sweep_looks_at_the_line_from_the_distance_and_above(name: str) -> None:
    obj = make_object(name)
    views = sweep_views(obj, distance_m=0.3, step_m=0.05, min_elevation_deg=35.0)
    length = obj.reference_length_m
    assert len(views) == int(np.ceil(length / 0.05)) + 1
    targets = interpolate_polyline(obj.reference, np.linspace(0.0, length, len(views)))
    for T, target in zip(views, targets, strict=True):
        to_target = target - T[:3, 3]
        assert np.linalg.norm(to_target) == pytest.approx(0.3)
        assert np.allclose(to_target / 0.3, T[:3, 2])  # on the optical axis
        assert elevation_deg(-T[:3, 2]) >= 35.0 - 1e-9
        assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
        assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)


def test_sweep_puts_the_line_across_the_image_and_honours_count() -> None:
    obj = make_object("planar_box")
    views = sweep_views(obj, count=7)
    assert len(views) == 7
    s = cumulative_length(obj.reference)
    mid = obj.reference[np.searchsorted(s, 0.1) + 1] - obj.reference[np.searchsorted(s, 0.1) - 1]
    x_axis = views[2][:3, 0]  # the view nearest s = 0.1 m on a flat top
    assert abs(np.dot(x_axis, mid / np.linalg.norm(mid))) > 0.95
    with pytest.raises(SimError, match="positive distance"):
        sweep_views(obj, distance_m=0.0)


def test_survey_is_dense_and_respects_reachability() -> None:
    obj = make_object("cylinder")
    views = survey_views(obj, spacing_m=0.1)
    assert len(views) >= 20
    assert min(elevation_deg(-T[:3, 2]) for T in views) == pytest.approx(55.0)
    downward = survey_views(obj, spacing_m=0.1, reachable=lambda T: T[2, 2] < -0.999)
    assert len(downward) == len(views) // 5
    assert len(survey_views(obj, spacing_m=0.1, count=7)) == 7
    with pytest.raises(SimError, match="no reachable view"):
        survey_views(obj, reachable=lambda T: False)


def test_survey_finds_a_wire_mesh() -> None:
    assert len(survey_views(make_object("basket"), spacing_m=0.1)) >= 5 * 6


def test_pre_planned_planner_walks_its_list() -> None:
    views = [np.eye(4) * (k + 1) for k in range(3)]
    planner = PrePlannedPlanner(views, reason="sweep")
    camera = d435i_color_camera(16, 12)
    frame = Frame(
        0,
        0,
        np.zeros((12, 16, 3), np.uint8),
        np.zeros((12, 16), np.float32),
        camera,
        np.eye(4),
    )
    first = planner.start()
    assert first.reason == "sweep" and not first.stop and first.T_base_cam is not None
    assert np.array_equal(first.T_base_cam, views[0])
    second = planner.skip("ik")
    assert second.T_base_cam is not None and second.T_base_cam[3, 3] == 2
    third = planner.observe(frame)
    assert third.T_base_cam is not None and third.T_base_cam[3, 3] == 3
    done = planner.observe(frame)
    assert done.stop and done.reason == "done" and done.T_base_cam is None
    assert planner.total == 3
    assert planner.start().T_base_cam is not None  # restartable
