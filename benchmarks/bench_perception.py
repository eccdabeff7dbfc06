"""Paint filter + back-projection speed at 640x480 on one core, against the straightforward way.

Frames come from a simulated D435i sweep of the painted cylinder (``scrapcut_cli.sim.record``,
d435i noise), decoded into memory first so decoding is not timed; if the simulator's recorder
is not available, from the analytic cylinder scene of ``tests/perception_scenes.py``.

Timed, each over all frames, median of several runs:

* ours — :func:`scrapcut_cli.perception.cloud.backproject_paint`: colour filter on bytes, depth
  gate with flying-pixel test, back-projection of the usable paint pixels only, base frame;
* ours, whole frame — :func:`~scrapcut_cli.perception.cloud.process_frame` (adds voxel
  downsampling, outlier removal and the surface band), for reference;
* straightforward — open3d RGBD image → full point cloud (every valid pixel, base frame) →
  HSV of every point's colour (matplotlib's ``rgb_to_hsv``) → select the paint.

Target (issue 4): >= 300 frames/s for ours, ten times the camera's 30 Hz.

    .venv/bin/python benchmarks/bench_perception.py [--frames 30] [--runs 7]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy / open3d load their thread pools

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from matplotlib.colors import rgb_to_hsv  # noqa: E402

from scrapcut_cli._open3d import o3d  # noqa: E402
from scrapcut_cli.config import PerceptionConfig, SimConfig  # noqa: E402
from scrapcut_cli.perception.cloud import backproject_paint, process_frame  # noqa: E402
from scrapcut_cli.perception.paint import PAINT_PRESETS, HsvRange  # noqa: E402
from scrapcut_cli.recording.frame import Frame  # noqa: E402


def simulated_frames(count: int) -> tuple[list[Frame], str]:
    """Decoded frames of a 640x480 d435i sweep of the cylinder, or synthetic ones."""
    record: Callable[..., object] | None
    try:
        from scrapcut_cli.sim import record
    except ImportError:
        record = None
    if record is not None:
        from scrapcut_cli.recording.reader import open_recording

        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "sweep.mcap"
            record(SimConfig(object="cylinder", mode="sweep", noise="d435i"), path)
            with open_recording(path) as rec:
                frames = [f for f, _ in zip(rec.frames(), range(count), strict=False)]
        return frames, "simulated d435i sweep of the cylinder (scrapcut_cli.sim)"
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from perception_scenes import (  # type: ignore[import-not-found]
        SceneNoise,
        cylinder_top_line,
        render_cylinder,
        small_camera,
        top_view,
    )

    noise = SceneNoise(depth_sigma_m=0.0005, hole_fraction=0.02, flying_pixels=True, color_sigma=2)
    reference = cylinder_top_line()
    frames = [
        render_cylinder(small_camera(640, 480), top_view(x), reference, noise=noise, seed=i)
        for i, x in enumerate(np.linspace(-0.12, 0.12, count))
    ]
    return frames, "analytic painted cylinder (tests/perception_scenes.py; no simulator)"


def straightforward(frame: Frame, hsv: HsvRange, config: PerceptionConfig) -> np.ndarray:
    """open3d RGBD → full cloud in the base frame → colour filter on every point."""
    o3 = o3d()
    cam = frame.camera
    depth = np.nan_to_num(frame.depth, nan=0.0)  # open3d treats 0 as invalid
    rgbd = o3.geometry.RGBDImage.create_from_color_and_depth(
        o3.geometry.Image(frame.color),
        o3.geometry.Image(depth),
        depth_scale=1.0,
        depth_trunc=config.max_depth_m,
        convert_rgb_to_intensity=False,
    )
    intrinsic = o3.camera.PinholeCameraIntrinsic(
        cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy
    )
    cloud = o3.geometry.PointCloud.create_from_rgbd_image(
        rgbd, intrinsic, np.linalg.inv(frame.T_base_cam)
    )
    h_s_v = rgb_to_hsv(np.asarray(cloud.colors))
    hue = h_s_v[:, 0] * 360.0
    in_hue = (
        (hue >= hsv.hue_min_deg) | (hue <= hsv.hue_max_deg)
        if hsv.wraps
        else (hue >= hsv.hue_min_deg) & (hue <= hsv.hue_max_deg)
    )
    keep = in_hue & (h_s_v[:, 1] >= hsv.sat_min) & (h_s_v[:, 2] >= hsv.val_min)
    return np.asarray(cloud.points)[keep]


def frames_per_second(frames: list[Frame], step: Callable[[Frame], object], runs: int) -> float:
    """Median over ``runs`` passes of frames processed per CPU second of this process.

    CPU time, not wall time: this machine is shared, and another job's load would otherwise
    be charged to us. With one thread the two agree on an idle machine.
    """
    for frame in frames[:3]:
        step(frame)  # warm caches (ray grid, colour tables, open3d)
    rates = []
    for _ in range(runs):
        t0 = time.process_time()
        for frame in frames:
            step(frame)
        rates.append(len(frames) / (time.process_time() - t0))
    return statistics.median(rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()

    frames, source = simulated_frames(args.frames)
    hsv = PAINT_PRESETS["orange"].hsv
    config = PerceptionConfig()
    cam = frames[0].camera
    ours_points = [len(backproject_paint(f, hsv, config)[0]) for f in frames]
    naive_points = [len(straightforward(f, hsv, config)) for f in frames]
    print(f"frames: {len(frames)} x {cam.width}x{cam.height} from {source}")
    print(
        f"one thread; rates per CPU second, median of {args.runs} runs; "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    print(
        f"paint points per frame (median): ours {statistics.median(ours_points):,.0f} "
        f"(depth-gated, flying pixels and isolated pixels dropped), "
        f"straightforward {statistics.median(naive_points):,.0f}"
    )
    ours = frames_per_second(frames, lambda f: backproject_paint(f, hsv, config), args.runs)
    whole = frames_per_second(frames, lambda f: process_frame(f, hsv, config), args.runs)
    naive = frames_per_second(frames, lambda f: straightforward(f, hsv, config), args.runs)
    print(f"filter + back-projection, ours:           {ours:8.1f} frames/s  (target >= 300)")
    print(f"filter + back-projection, straightforward: {naive:7.1f} frames/s")
    print(f"speed-up:                                  {ours / naive:7.1f} x")
    print(f"whole frame (+ voxel, outliers, surface):  {whole:7.1f} frames/s")


if __name__ == "__main__":
    main()
