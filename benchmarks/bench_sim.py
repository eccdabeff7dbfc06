"""Simulator speed: the renderer choice, and a 60-view sweep of every object.

1. Renderer: open3d's RaycastingScene (what ``sim.render`` uses) against pybullet's
   ``getCameraImage`` (TinyRenderer, the only renderer in DIRECT mode) on the same scene —
   the cylinder on the floor seen from a sweep view at 640×480 — timing (median of several
   runs) and depth error against the exact ray-cast depth.
2. Recording: wall time of ``record()`` for a 60-view sweep of each object at 640×480 with the
   d435i noise model (target: under 20 s each), median of ``--runs`` runs.

Run: ``.venv/bin/python benchmarks/bench_sim.py [--runs 3] [--objects cylinder,basket]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from scrapcut_cli.config import SimConfig
from scrapcut_cli.recording.frame import CameraModel
from scrapcut_cli.sim import list_objects, record
from scrapcut_cli.sim._pybullet import pybullet, quiet_stdout
from scrapcut_cli.sim.mesh import floor_mesh
from scrapcut_cli.sim.recorder import place_object, planned_views
from scrapcut_cli.sim.render import SceneRenderer
from scrapcut_cli.sim.surface import PaintStroke

NEAR, FAR = 0.05, 5.0


def median_time(fn: Callable[[], Any], runs: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def pybullet_depth(vertices: np.ndarray, faces: np.ndarray, T: np.ndarray, cam: CameraModel) -> Any:
    """A callable rendering metric z depth (H, W) with pybullet's TinyRenderer."""
    p = pybullet()
    with quiet_stdout():
        client = p.connect(p.DIRECT)
    for mesh_v, mesh_f in ((vertices, faces), (floor_mesh().vertices, floor_mesh().faces)):
        shape = p.createVisualShape(
            p.GEOM_MESH,
            vertices=mesh_v.tolist(),
            indices=mesh_f.reshape(-1).tolist(),
            physicsClientId=client,
        )
        p.createMultiBody(baseMass=0, baseVisualShapeIndex=shape, physicsClientId=client)
    eye = T[:3, 3]
    view = p.computeViewMatrix(eye.tolist(), (eye + T[:3, 2]).tolist(), (-T[:3, 1]).tolist())
    fov_y = np.degrees(2.0 * np.arctan(0.5 * cam.height / cam.fy))
    proj = p.computeProjectionMatrixFOV(fov_y, cam.width / cam.height, NEAR, FAR)

    def render() -> np.ndarray:
        _, _, _, depth_buffer, _ = p.getCameraImage(
            cam.width,
            cam.height,
            view,
            proj,
            renderer=p.ER_TINY_RENDERER,
            physicsClientId=client,
        )
        d = np.asarray(depth_buffer, dtype=np.float64).reshape(cam.height, cam.width)
        return FAR * NEAR / (FAR - (FAR - NEAR) * d)  # OpenGL depth buffer -> eye z

    return render


def bench_renderers(runs: int) -> None:
    config = SimConfig(object="cylinder")
    obj = place_object(config)
    T = planned_views(config, obj)[4]
    # A centred principal point: pybullet's FOV projection cannot express an offset one.
    cam = CameraModel(640, 480, 615.0, 615.0, 319.5, 239.5)
    renderer = SceneRenderer(obj, PaintStroke(obj.reference, width_m=0.025, rgb=(255, 110, 0)))
    renderer.render(T, cam)
    t_o3d, view = median_time(lambda: renderer.render(T, cam), runs)
    render_pb = pybullet_depth(obj.vertices, obj.faces, T, cam)
    t_pb, depth_pb = median_time(render_pb, runs)
    both = np.isfinite(view.depth) & (depth_pb < FAR * 0.999)
    # Compare away from silhouettes, where both renderers see the same surface.
    edge = np.zeros_like(both)
    jump = np.abs(np.diff(view.depth, axis=1)) > 0.005
    edge[:, 1:] |= jump
    edge[:, :-1] |= jump
    inner = both & ~edge
    err = np.abs(depth_pb[inner] - view.depth[inner]) * 1000.0
    print("renderer, 640x480, cylinder + floor, median of", runs, "runs")
    print(f"{'renderer':<54} {'ms':>8} {'depth error vs exact (mm)':>28}")
    print(f"{'open3d RaycastingScene (full render: paint, shading)':<54} {1000 * t_o3d:>8.1f}")
    print(f"{'  of which ray casting only':<54} {1000 * _cast_only(renderer, T, cam, runs):>8.1f}")
    p50, p99, worst = np.percentile(err, [50, 99, 100])
    print(
        f"{'pybullet getCameraImage (TinyRenderer, depth)':<54} {1000 * t_pb:>8.1f} "
        f"median {p50:.3f}, p99 {p99:.3f}, max {worst:.2f}"
    )
    print(f"{'':<63} (open3d: exact, float32 rays)")


def _cast_only(renderer: SceneRenderer, T: np.ndarray, cam: CameraModel, runs: int) -> float:
    o3d = renderer._o3d
    grid = cam.ray_grid().reshape(-1, 2)
    d = np.column_stack([grid, np.ones(len(grid), np.float32)]) @ T[:3, :3].T
    rays = o3d.core.Tensor(np.column_stack([np.tile(T[:3, 3], (len(d), 1)), d]).astype(np.float32))
    return median_time(lambda: renderer._scene.cast_rays(rays), runs)[0]


def bench_sweeps(objects: list[str], runs: int, width: int, height: int) -> None:
    print()
    print(f"record(): 60-view sweep, {width}x{height}, d435i noise, median of {runs} run(s)")
    print(
        f"{'object':<12} {'views':>5} {'frames':>6} {'MB':>6} {'wall s':>7} {'ms/view':>8} target"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for name in objects:
            config = SimConfig(object=name, views=60, width=width, height=height)
            path = Path(tmp) / f"{name}.mcap"
            wall, result = median_time(lambda c=config, p=path: record(c, p), runs)
            size = path.stat().st_size / 1e6
            ok = "ok" if wall < 20.0 else "SLOW (> 20 s)"
            print(
                f"{name:<12} {result.views:>5} {result.frames:>6} {size:>6.1f} {wall:>7.2f} "
                f"{1000 * wall / max(result.views, 1):>8.0f} {ok}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--objects", default=",".join(name for name, _ in list_objects()))
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--skip-renderers", action="store_true")
    args = parser.parse_args()
    if not args.skip_renderers:
        bench_renderers(max(args.runs, 5))
    bench_sweeps(args.objects.split(","), args.runs, args.width, args.height)


if __name__ == "__main__":
    main()
