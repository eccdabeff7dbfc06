"""Tests of scrapcut_cli.sim.scene: old marks near the line, distractors beside the piece."""

from __future__ import annotations

import colorsys

import numpy as np
import pytest

from scrapcut_cli.config import SimConfig
from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import look_at, nearest_distances
from scrapcut_cli.sim.camera import T_HAND_CAMLINK, noise_preset
from scrapcut_cli.sim.recorder import make_scene, place_object
from scrapcut_cli.sim.scene import DISTRACTOR_KINDS, build_scene


def hsv(rgb: tuple[int, int, int]) -> tuple[float, float, float]:
    h, s, v = colorsys.rgb_to_hsv(*(c / 255.0 for c in rgb))
    return 360.0 * h, s, v


@pytest.mark.parametrize("name", ["cylinder", "basket"])
def test_yard_scene_places_marks_near_the_line_and_things_beside_the_piece(name: str) -> None:
    config = SimConfig(object=name, noise="yard", seed=2)
    obj = place_object(config)
    scene = make_scene(config, obj, noise_preset("yard"))
    again = make_scene(config, obj, noise_preset("yard"))
    assert scene.describe() == again.describe()  # seeded
    assert [d.kind for d in scene.distractors] == list(DISTRACTOR_KINDS)
    lo, hi = obj.mesh.bounds
    for d in scene.distractors:
        d_lo, d_hi = d.mesh.bounds
        assert d_lo[2] == pytest.approx(0.0, abs=1e-9)  # lying on the floor
        assert nearest_distances(d.mesh.vertices, obj.reference).min() >= 0.06
        outside = (d_lo[:2] > hi[:2]) | (d_hi[:2] < lo[:2])
        assert outside.any()  # beside the piece's footprint, not under or in it
        h, s, _ = hsv(d.rgb)
        h_can, s_can, _ = hsv(scene.can_rgb)
        assert abs((h - h_can + 180) % 360 - 180) <= 8.5 and s >= s_can - 0.01
    (mark,) = scene.faded
    gap = nearest_distances(mark.stroke.reference, obj.reference)
    assert mark.crosses and gap.min() < 0.25 * config.stroke_width_m
    h, s, v = colorsys.rgb_to_hsv(*mark.stroke.rgb)
    _, s_can, v_can = hsv(scene.can_rgb)
    assert s < 0.81 * s_can and v < 0.86 * v_can
    assert 0.2 <= mark.stroke.wear <= 0.5
    # Another seed, another scene; switching distractors on does not move the old mark.
    assert make_scene(SimConfig(object=name, noise="yard", seed=3), obj, noise_preset("yard"))
    alone = make_scene(
        SimConfig(object=name, noise="yard", seed=2, distractors=()), obj, noise_preset("yard")
    )
    assert (
        alone.distractors == ()
        and alone.describe()["faded_marks"] == scene.describe()["faded_marks"]
    )


def test_a_second_old_mark_lies_beside_the_line() -> None:
    obj = place_object(SimConfig(object="planar_box"))
    scene = build_scene(obj, paint_rgb=(255, 110, 0), stroke_width_m=0.025, faded_marks=2)
    first, second = scene.faded
    assert first.crosses and not second.crosses
    gap = nearest_distances(second.stroke.reference, obj.reference)
    assert gap.min() > 0.5 * 0.025 * 2.2


def test_distractors_are_obstacles_for_the_robot() -> None:
    """Joints that put the camera inside the crate collide with it, and only with it."""
    from scrapcut_cli.sim.robot import Q_READY, PandaSim

    obj = place_object(SimConfig(object="cylinder"))
    scene = build_scene(obj, paint_rgb=(255, 110, 0), stroke_width_m=0.025, distractors=("box",))
    (crate,) = scene.distractors
    centre = crate.centre + np.array([0.0, 0.0, 0.3])
    pose = look_at(centre, crate.centre, up_hint=(1.0, 0.0, 0.0))
    pose[:3, 3] = crate.centre + np.array([0.0, 0.0, 0.12])  # the lens inside the crate
    with PandaSim(obj.mesh, T_hand_camlink_nominal=T_HAND_CAMLINK) as free:
        solution = free.plan_view(pose, np.asarray(Q_READY))
        assert solution.feasible and solution.q is not None
        assert free.collision(solution.q) is None
    with PandaSim(scene.obstacles(obj), T_hand_camlink_nominal=T_HAND_CAMLINK) as blocked:
        hit = blocked.collision(solution.q)
        assert hit is not None and hit.endswith("/object")


def test_unknown_distractor_is_named() -> None:
    obj = place_object(SimConfig(object="cylinder"))
    with pytest.raises(SimError, match="unknown distractor 'barrel'"):
        build_scene(obj, paint_rgb=(255, 110, 0), stroke_width_m=0.025, distractors=("barrel",))
