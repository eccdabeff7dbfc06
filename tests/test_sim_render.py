"""Tests of scrapcut_cli.sim.render: exact depth, consistent geometry, paint where it belongs."""

from __future__ import annotations

import numpy as np

from scrapcut_cli.geometry import PolylineDistance, look_at, transform_points
from scrapcut_cli.perception.paint import PAINT_PRESETS, paint_mask
from scrapcut_cli.sim import make_object
from scrapcut_cli.sim.camera import Lighting, d435i_color_camera
from scrapcut_cli.sim.render import FLOOR, MISS, OBJECT, SceneRenderer
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


def test_paint_passes_the_orange_filter_and_rust_does_not() -> None:
    r = renderer("air_chamber", overspray="light")
    ref = r.object.reference
    view = r.render(above(ref[len(ref) // 3], 0.3, 0.05), CAMERA)
    rgb = np.clip(np.rint(view.color * 255), 0, 255).astype(np.uint8)
    mask = paint_mask(rgb, PAINT_PRESETS["orange"].hsv)
    assert view.rust.sum() > 1000
    assert mask[view.paint].mean() > 0.99
    assert mask[view.rust].mean() < 0.01
    assert not mask[view.geometry == FLOOR].any()


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
