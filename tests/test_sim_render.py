"""Tests of scrapcut_cli.sim.render: exact depth, consistent geometry, paint where it belongs."""

from __future__ import annotations

import numpy as np

from scrapcut_cli.geometry import PolylineDistance, look_at, transform_points
from scrapcut_cli.perception.paint import PAINT_PRESETS, paint_mask, rgb_to_hsv_deg
from scrapcut_cli.sim import make_object
from scrapcut_cli.sim.camera import Lighting, d435i_color_camera
from scrapcut_cli.sim.render import DISTRACTOR, FLOOR, MISS, OBJECT, SceneRenderer
from scrapcut_cli.sim.surface import OVERSPRAY_PRESETS, PaintStroke

CAMERA = d435i_color_camera(320, 240)


def renderer(name: str, overspray: str = "none") -> SceneRenderer:
    obj = make_object(name, seed=4)
    stroke = PaintStroke(
        obj.reference,
        width_m=0.025,
        rgb=PAINT_PRESETS["orange"].rgb,
        overspray=OVERSPRAY_PRESETS[overspray],
        seed=4,
    )
    return SceneRenderer(obj, stroke, seed=4)


def above(target: np.ndarray, height: float = 0.3, tilt: float = 0.0) -> np.ndarray:
    eye = np.asarray(target) + np.array([-tilt, 0.0, height])
    return look_at(eye, target, up_hint=(1.0, 0.0, 0.0))


def test_floor_depth_is_exact_metric_z() -> None:
    r = renderer("planar_box")
    T = look_at((0.2, -0.5, 0.45), (0.4, -0.7, 0.0))  # oblique view of bare floor
    view = r.render(T, CAMERA)
    floor = view.geometry == FLOOR
    assert floor.mean() > 0.9
    grid = CAMERA.ray_grid().astype(np.float64)
    rays = np.concatenate([grid, np.ones((*grid.shape[:2], 1))], axis=2) @ T[:3, :3].T
    z_analytic = -T[2, 3] / rays[..., 2]  # ray (x, y, 1) meets z = 0 at this optical depth
    assert np.abs(view.depth[floor] - z_analytic[floor]).max() < 2e-6
    v, u = np.nonzero(floor)
    points = transform_points(T, CAMERA.unproject(u, v, view.depth[v, u]))
    assert np.abs(points - view.points_base[v, u]).max() < 2e-6
    assert np.abs(view.points_base[floor][:, 2]).max() < 2e-6


def test_paint_lies_on_the_stroke_and_fills_it() -> None:
    r = renderer("cylinder")
    ref = r.object.reference
    view = r.render(above(ref[len(ref) // 2], 0.3, 0.1), CAMERA)
    assert view.stroke.sum() > 2000
    dist = PolylineDistance(ref).distance(view.points_base[view.geometry == OBJECT])
    painted = view.stroke[view.geometry == OBJECT]
    assert dist[painted].max() <= r.stroke.max_half_width_m
    assert painted[dist < r.stroke.min_half_width_m].all()
    assert (view.paint == view.stroke).all()  # no overspray asked for


def test_paint_passes_the_orange_filter_and_rust_only_partly_and_duller() -> None:
    r = renderer("air_chamber", overspray="light")
    ref = r.object.reference
    view = r.render(above(ref[len(ref) // 3], 0.3, 0.05), CAMERA)
    rgb = np.clip(np.rint(view.color * 255), 0, 255).astype(np.uint8)
    mask = paint_mask(rgb, PAINT_PRESETS["orange"].hsv)
    assert view.rust.sum() > 1000
    assert mask[view.paint].mean() > 0.99
    # Iron oxide is as saturated as the filter's bound in places: perception must tell it
    # apart from the paint by more than a threshold (its colour cluster, its shape).
    assert 0.05 < mask[view.rust].mean() < 0.6
    sat = rgb_to_hsv_deg(rgb.reshape(-1, 3))[:, 1].reshape(rgb.shape[:2])
    assert np.quantile(sat[view.rust & mask], 0.99) < np.quantile(sat[view.stroke], 0.05)
    assert not mask[view.geometry == FLOOR].any()


def test_a_yard_scene_renders_old_marks_distractors_and_glints() -> None:
    from scrapcut_cli.config import SimConfig
    from scrapcut_cli.sim.camera import noise_preset
    from scrapcut_cli.sim.recorder import make_scene, place_object

    config = SimConfig(object="planar_box", noise="yard", seed=1)
    obj = place_object(config)
    scene = make_scene(config, obj, noise_preset("yard"))
    assert [d.kind for d in scene.distractors] == ["box", "cone", "glove"]
    assert len(scene.faded) == 1 and scene.faded[0].crosses
    stroke = PaintStroke(obj.reference, width_m=0.025, rgb=scene.can_rgb, seed=1)
    r = SceneRenderer(
        obj,
        stroke,
        faded=[m.stroke for m in scene.faded],
        distractors=scene.distractors,
        glints=True,
        seed=1,
    )
    ref = r.object.reference
    view = r.render(look_at(ref[60] + np.array([-0.1, 0.0, 0.45]), ref[60]), CAMERA)
    assert view.faded.sum() > 100 and not (view.faded & view.paint).any()
    assert (view.geometry >= DISTRACTOR).sum() > 1000
    assert (view.glare > 0.5).sum() > 5
    # Distractors are lit plastic of the paint's colour: the orange filter takes them.
    rgb = np.clip(np.rint(view.color * 255), 0, 255).astype(np.uint8)
    mask = paint_mask(rgb, PAINT_PRESETS["orange"].hsv)
    assert mask[view.geometry >= DISTRACTOR].mean() > 0.9
    # Glints are white: never paint.
    assert not mask[view.glare > 0.5].any()


def test_wire_basket_paint_has_gaps_a_box_does_not() -> None:
    """Along the line's image, a box shows paint everywhere, a wire mesh only on its wires."""

    def painted_share(name: str) -> float:
        r = renderer(name)
        ref = r.object.reference
        top = ref[ref[:, 2] > ref[:, 2].max() - 1e-6]
        T = above(top[len(top) // 2], 0.35)
        view = r.render(T, CAMERA)
        uv = CAMERA.project(transform_points(np.linalg.inv(T), top))
        u, v = np.rint(uv).astype(int).T
        inside = (u >= 0) & (u < CAMERA.width) & (v >= 0) & (v < CAMERA.height)
        return float(view.stroke[v[inside], u[inside]].mean())

    assert painted_share("planar_box") > 0.99  # (a few samples at the edge fall off it)
    # 4 mm wires at a 40 mm pitch in two crossed layers: paint on a tenth to a half of the line.
    assert 0.1 < painted_share("basket") < 0.5


def test_render_is_deterministic_and_lighting_scales_colour() -> None:
    r = renderer("slanted", overspray="heavy")
    T = above(r.object.reference[100], 0.3, 0.1)
    a, b = r.render(T, CAMERA), renderer("slanted", overspray="heavy").render(T, CAMERA)
    assert np.array_equal(a.color, b.color) and np.array_equal(a.depth, b.depth)
    dim = r.render(T, CAMERA, lighting=Lighting(gain=(0.5, 0.5, 0.5)))
    assert np.allclose(dim.color, 0.5 * a.color)
    assert not (a.geometry == MISS).any()
