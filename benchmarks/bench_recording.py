"""Recording read speed and memory: frames decoded per second on 640x480 RGB-D recordings
(target >= 200 frames/s on one core) and resident memory while streaming a 1,000-frame
recording (target: flat, under 300 MB).

    .venv/bin/python benchmarks/bench_recording.py [--frames 300] [--memory-frames 1000]

Recordings are synthetic (smooth colour with sensor-like noise, depth with holes), written
to a temporary directory and removed afterwards. Timings are medians over ``--runs`` passes
of ``Recording.frames()`` after its header pass (``plan()``), pinned to one CPU.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

WIDTH, HEIGHT = 640, 480
COLOR = "/camera/camera/color/image_raw"
DEPTH = "/camera/camera/aligned_depth_to_color/image_raw"
INFO = "/camera/camera/color/camera_info"


def _pin_one_core() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def write_recording(path: Path, n_frames: int, *, compressed: bool = False, seed: int = 0) -> None:
    """A 30 Hz scan of ``n_frames`` 640x480 colour + aligned 16UC1 depth images with TF."""
    from scrapcut_cli.geometry import make_transform
    from scrapcut_cli.recording.frame import CameraModel
    from scrapcut_cli.recording.writer import McapWriter

    rng = np.random.default_rng(seed)
    camera = CameraModel(WIDTH, HEIGHT, 615.0, 615.0, 319.5, 239.5, frame_id="camera_optical")
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH]
    base_rgb = np.stack([u * 255 // WIDTH, v * 255 // HEIGHT, (u + v) % 256], axis=-1)
    base_depth = 400 + (u // 4 + v // 8).astype(np.int64)
    period = 33_333_333
    t0 = 1_700_000_000_000_000_000
    with McapWriter(path) as writer:
        writer.write_tf(t0, [("panda_link8", "camera_optical", np.eye(4))], static=True)
        writer.write_camera_info(INFO, t0, camera)
        for k in range(-1, n_frames + 1):
            # Flange poses at 100 Hz would be 3 per frame; one before and after suffices here.
            T = make_transform(np.eye(3), [0.4 + 1e-3 * k, 0.0, 0.5])
            writer.write_tf(t0 + k * period, [("panda_link0", "panda_link8", T)])
        for k in range(n_frames):
            stamp = t0 + k * period
            noise = rng.integers(-6, 7, (HEIGHT, WIDTH, 3))
            rgb = np.clip(base_rgb + noise + k, 0, 255).astype(np.uint8)
            depth = (base_depth + rng.integers(-3, 4, (HEIGHT, WIDTH))).astype(np.uint16)
            depth[rng.random((HEIGHT, WIDTH)) < 0.05] = 0
            if compressed:
                writer.write_compressed_image(COLOR + "/compressed", stamp, "camera_optical", rgb)
            else:
                writer.write_image(COLOR, stamp, "camera_optical", rgb)
            writer.write_image(DEPTH, stamp + 2_000_000, "camera_optical", depth)


def time_frames(path: Path, runs: int, *, color_topic: str | None = None) -> tuple[float, int]:
    """Median seconds of one full ``frames()`` pass, and the frame count."""
    from scrapcut_cli.config import RecordingConfig
    from scrapcut_cli.recording.reader import open_recording

    config = RecordingConfig(color_topic=color_topic)
    times = []
    count = 0
    for _ in range(runs):
        with open_recording(path, config) as rec:
            rec.plan()
            start = time.perf_counter()
            count = sum(1 for _ in rec.frames())
            times.append(time.perf_counter() - start)
    return statistics.median(times), count


def time_plan(path: Path, runs: int) -> float:
    """Median seconds of the header pass (``plan()``, no pixels decoded)."""
    from scrapcut_cli.recording.reader import open_recording

    times = []
    for _ in range(runs):
        start = time.perf_counter()
        with open_recording(path) as rec:
            rec.plan()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _rss_mb(field: str = "VmRSS") -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    return float("nan")


def memory_child(path: Path) -> None:
    """Stream every frame, printing resident memory at checkpoints (run in a fresh process)."""
    from scrapcut_cli.recording.reader import open_recording

    _pin_one_core()
    with open_recording(path) as rec:
        n = rec.plan().usable
        checkpoints = {1, n // 4, n // 2, 3 * n // 4, n}
        print(f"rss_after_plan_mb {_rss_mb():.1f}")
        for frame in rec.frames():
            if frame.index + 1 in checkpoints:
                print(f"rss_at_frame {frame.index + 1} {_rss_mb():.1f}")
    print(f"peak_rss_mb {_rss_mb('VmHWM'):.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=300, help="frames in the speed recording")
    parser.add_argument("--memory-frames", type=int, default=1000)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--memory-child", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.memory_child is not None:
        memory_child(args.memory_child)
        return
    _pin_one_core()
    from scrapcut_cli.recording.convert import convert_recording

    with tempfile.TemporaryDirectory(prefix="bench_recording_") as tmp:
        root = Path(tmp)
        raw = root / "raw.mcap"
        write_recording(raw, args.frames)
        jpeg = root / "jpeg.mcap"
        write_recording(jpeg, args.frames, compressed=True)
        convert_recording(raw, root / "raw.bag")
        convert_recording(raw, root / "raw_ros2")
        size_mb = raw.stat().st_size / 1e6
        print(f"# {args.frames} frames {WIDTH}x{HEIGHT}, median of {args.runs} runs, one core")
        print(f"# raw MCAP {size_mb:.0f} MB (zstd chunks)")
        print(f"{'recording':<34} {'frames/s':>9} {'ms/frame':>9}")
        cases = [
            ("MCAP rgb8 + 16UC1", raw, None),
            ("ROS 1 bag rgb8 + 16UC1", root / "raw.bag", None),
            ("ROS 2 bag (mcap) rgb8 + 16UC1", root / "raw_ros2", None),
            ("MCAP jpeg + 16UC1", jpeg, COLOR + "/compressed"),
        ]
        for name, path, color_topic in cases:
            seconds, count = time_frames(path, args.runs, color_topic=color_topic)
            print(f"{name:<34} {count / seconds:>9.0f} {1e3 * seconds / count:>9.2f}")
        plan_s = time_plan(raw, args.runs)
        rate, per_frame = args.frames / plan_s, 1e3 * plan_s / args.frames
        print(f"{'header pass (plan), MCAP':<34} {rate:>9.0f} {per_frame:>9.2f}")

        big = root / "big.mcap"
        write_recording(big, args.memory_frames, seed=1)
        print(f"# memory: {args.memory_frames} frames, {big.stat().st_size / 1e6:.0f} MB MCAP")
        child = subprocess.run(
            [sys.executable, __file__, "--memory-child", str(big)],
            capture_output=True,
            text=True,
            check=True,
        )
        print(child.stdout, end="")


if __name__ == "__main__":
    main()
