"""``scrapcut fit`` throughput at 1280x720 JPEG (realsense-ros 4.x's default) next to 640x480.

Two simulated sweeps of the cylinder (d435i noise, 9 views, ``--frames-per-view`` images at
30 Hz at each view, as a camera streaming while the arm rests):

* 640x480, raw rgb8 colour, MCAP;
* 1280x720, colour JPEG-compressed only (quality 95), a ROS 2 bag with sqlite3 storage (read
  like 640x360 at the wrist's 0.3 m by the default ``--max-decimation 8``); again with
  ``--max-decimation 1``, every pixel.

Timed on one core (thread pools pinned to 1), median of ``--runs``:

* ``fit`` — everything ``scrapcut fit --method nurbs`` does after start-up: read and decode
  every frame, perceive and stitch it, select the line, fit, make the cutting path; frames per
  second of CPU time over the whole recording;
* ``per frame`` — what one more frame costs, the rate a live camera would have to be met at:
  the same sweep is recorded again with twice the frames at each view, and the difference of
  the two fits' times (timed one after the other in each run) is divided by the difference of
  their frame counts (the views, the stitched cloud and the fit are the same, so the fixed
  part cancels);
* ``fixed`` — the rest of the first recording's fit time, seconds: opening the recording,
  the index pass, selecting the line, the fit and the cutting path; a longer recording
  spreads it over more frames;
* ``perception`` — the per-frame part alone on frames decoded beforehand (colour split, solid
  paint, depth gate, back-projection, downsampling, outlier removal, surface band, stitching),
  frames per second.

Each run times every case in turn (the cases' medians compare: the machine's drift falls on
all alike).

Goal (issue 12): fit >= 30 frames/s at 1280x720, the camera's own rate. This virtual machine's
speed drifts by tens of per cent within hours: only figures from back-to-back runs compare.
The last row, ``SCRAPCUT_NATIVE=0``, is the 1280x720 case again with the compiled neighbour
searches switched off (open3d and scipy instead; ``bench_kernels.py``), timed in turn with the
others; ``SCRAPCUT_NATIVE=0`` in the environment switches them off in every row.

    .venv/bin/python benchmarks/bench_fit_resolution.py [--runs 5] [--frames-per-view 10]
        [--out DIR]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy / open3d load their thread pools

import argparse  # noqa: E402
import functools  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

from scrapcut_cli import _kernels  # noqa: E402
from scrapcut_cli.config import ScrapcutConfig, SimConfig  # noqa: E402
from scrapcut_cli.perception.stitch import stitch_recording  # noqa: E402
from scrapcut_cli.pipeline.fit import (  # noqa: E402
    fit_stitched,
    paint_for_recording,
    stitch_recording_file,
)
from scrapcut_cli.recording.reader import open_recording  # noqa: E402
from scrapcut_cli.sim import record  # noqa: E402

#: name: (the sweep's simulator settings, its file name, perception.max_decimation, whether the
#: compiled neighbour searches are on)
CASES = {
    "640x480 rgb8 MCAP": (SimConfig(width=640, height=480), "cylinder_640.mcap", 8, True),
    "1280x720 JPEG ROS2 sqlite3": (
        SimConfig(width=1280, height=720, color_encoding="jpeg"),
        "cylinder_1280_jpeg",
        8,
        True,
    ),
    "  --max-decimation 1": (
        SimConfig(width=1280, height=720, color_encoding="jpeg"),
        "cylinder_1280_jpeg",
        1,
        True,
    ),
    "  SCRAPCUT_NATIVE=0": (
        SimConfig(width=1280, height=720, color_encoding="jpeg"),
        "cylinder_1280_jpeg",
        8,
        False,
    ),
}


def cpu_seconds(run: object) -> float:
    t = time.process_time()
    run()  # type: ignore[operator]
    return time.process_time() - t


def cpu_name() -> str:
    """The CPU's model name (Linux), else what ``platform`` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--frames-per-view", type=int, default=10)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_fit_resolution_"))
    out.mkdir(parents=True, exist_ok=True)
    print(
        f"# {cpu_name()}, {os.cpu_count()} cores, one thread; medians of {args.runs} runs "
        f"(CPU time); recordings in {out}"
    )
    print(
        f"{'recording':28s} {'frames':>6s} {'fit [frames/s]':>15s} {'per frame':>10s} "
        f"{'fixed [s]':>10s} {'perception':>11s}"
    )
    cases = []
    compiled = _kernels._native
    for name, (sim, file, max_decimation, native) in CASES.items():
        if native and compiled is None:
            print(f"# {name.strip()}: the compiled neighbour searches are off or not built")
        config = ScrapcutConfig().override("perception", max_decimation=max_decimation)
        paths = [recording(out, sim, file, k * args.frames_per_view) for k in (1, 2)]
        counts = []
        for path in paths:
            with open_recording(path) as rec:
                counts.append(rec.plan().usable)
            fit(path, config)  # warm: imports, cached ray grids
        cases.append((name, config, paths, counts, decoded(paths[0]), compiled if native else None))
    # Every case's recordings are timed one after the other in each run, so that the
    # machine's drift falls on all alike; the per-frame cost is the median of the runs'
    # differences between a case's two recordings.
    times: list[list[list[float]]] = [[] for _ in cases]
    perception: list[list[float]] = [[] for _ in cases]
    for _ in range(args.runs):
        for k, (_, config, paths, _, (frames, hsv), kernels) in enumerate(cases):
            _kernels._native = kernels  # the compiled searches, or open3d / scipy
            times[k].append([cpu_seconds(lambda p=p, c=config: fit(p, c)) for p in paths])
            perception[k].append(
                cpu_seconds(lambda f=frames, h=hsv, c=config: stitch_recording(f, h, c))
            )
    _kernels._native = compiled
    for (name, _, _, counts, _, _), runs, perceive in zip(cases, times, perception, strict=True):
        fit_s = statistical_median([t[0] for t in runs])
        per_frame_s = statistical_median([(t[1] - t[0]) / (counts[1] - counts[0]) for t in runs])
        n = counts[0]
        # The VM's noise can exceed a frame's cost on a short recording: no rate then.
        rate = f"{1.0 / per_frame_s:10.1f}" if per_frame_s > 0 else f"{'n/a':>10s}"
        print(
            f"{name:28s} {n:6d} {n / fit_s:15.1f} {rate} {fit_s - n * per_frame_s:10.2f} "
            f"{n / statistical_median(perceive):11.1f}",
            flush=True,
        )


def fit(path: Path, config: ScrapcutConfig) -> None:
    """What ``scrapcut fit --method nurbs`` does after start-up."""
    fit_stitched(stitch_recording_file(path, config=config), method="nurbs", config=config)


def recording(out: Path, sim: SimConfig, file: str, per_view: int) -> Path:
    """The sweep recorded with ``per_view`` frames at each view (made once per ``out``)."""
    stem, dot, ext = file.partition(".")
    path = out / f"{stem}_{per_view}fpv{dot}{ext}"
    if not path.exists():
        record(SimConfig(**{**sim.__dict__, "frames_per_view": per_view}), path)
    return path


@functools.cache
def decoded(path: Path) -> tuple[list[Any], Any]:
    """The recording's frames, decoded, and its paint: what perception is timed on (once per
    recording: the 1280x720 cases share theirs)."""
    config = ScrapcutConfig()
    with open_recording(path) as rec:
        return list(rec.frames()), paint_for_recording(rec, config)[0]


def statistical_median(values: list[float]) -> float:
    return float(statistics.median(values))


if __name__ == "__main__":
    main()
