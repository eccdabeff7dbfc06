"""``scrapcut fit`` throughput at 1280x720 JPEG (realsense-ros 4.x's default) next to 640x480.

Two simulated sweeps of the cylinder (d435i noise, 9 views, ``--frames-per-view`` images at
30 Hz at each view, as a camera streaming while the arm rests):

* 640x480, raw rgb8 colour, MCAP;
* 1280x720, colour JPEG-compressed only (quality 95), a ROS 2 bag with sqlite3 storage.

Timed on one core (thread pools pinned to 1), median of ``--runs``:

* ``fit`` — everything ``scrapcut fit --method nurbs`` does after start-up: read and decode
  every frame, perceive and stitch it, select the line, fit, make the cutting path; frames per
  second of CPU time;
* ``perception`` — the per-frame part alone on frames decoded beforehand (colour split, solid
  paint, depth gate, back-projection, downsampling, outlier removal, surface band, stitching).

Goal (issue 12): fit >= 30 frames/s at 1280x720, the camera's own rate.

    .venv/bin/python benchmarks/bench_fit_resolution.py [--runs 5] [--frames-per-view 10]
        [--out DIR]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy / open3d load their thread pools

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

from scrapcut_cli.config import ScrapcutConfig, SimConfig  # noqa: E402
from scrapcut_cli.perception.stitch import stitch_recording  # noqa: E402
from scrapcut_cli.pipeline.fit import (  # noqa: E402
    fit_stitched,
    paint_for_recording,
    stitch_recording_file,
)
from scrapcut_cli.recording.reader import open_recording  # noqa: E402
from scrapcut_cli.sim import record  # noqa: E402

CASES = {
    "640x480 rgb8 MCAP": (SimConfig(width=640, height=480), "cylinder_640.mcap"),
    "1280x720 JPEG ROS2 sqlite3": (
        SimConfig(width=1280, height=720, color_encoding="jpeg"),
        "cylinder_1280_jpeg",
    ),
}


def cpu_seconds(run: object) -> float:
    t = time.process_time()
    run()  # type: ignore[operator]
    return time.process_time() - t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--frames-per-view", type=int, default=10)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_fit_resolution_"))
    out.mkdir(parents=True, exist_ok=True)
    config = ScrapcutConfig()
    print(
        f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, one "
        f"thread; medians of {args.runs} runs (CPU time); recordings in {out}"
    )
    print(f"{'recording':28s} {'frames':>6s} {'fit [frames/s]':>15s} {'perception':>11s}")
    for name, (sim, file) in CASES.items():
        path = out / file
        if not path.exists():
            record(SimConfig(**{**sim.__dict__, "frames_per_view": args.frames_per_view}), path)
        with open_recording(path) as rec:
            frames = list(rec.frames())
            hsv, _ = paint_for_recording(rec, config)

        def fit(path: Path = path) -> None:
            stitched = stitch_recording_file(path, config=config)
            fit_stitched(stitched, method="nurbs", config=config)

        def perceive(frames: list[Any] = frames, hsv: Any = hsv) -> None:
            stitch_recording(frames, hsv, config)

        fit()  # warm: imports, cached ray grids
        fit_s = statistical_median([cpu_seconds(fit) for _ in range(args.runs)])
        perceive_s = statistical_median([cpu_seconds(perceive) for _ in range(args.runs)])
        n = len(frames)
        print(f"{name:28s} {n:6d} {n / fit_s:15.1f} {n / perceive_s:11.1f}")


def statistical_median(values: list[float]) -> float:
    return float(statistics.median(values))


if __name__ == "__main__":
    main()
