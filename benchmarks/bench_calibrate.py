"""Self-calibration speed and accuracy: ``calibrate`` on 40 frames at 640x480.

The recording is a simulated ``yard`` sweep of the painted cylinder at 640x480: a hand-eye
error of 2 mm / 0.3 deg, image stamps 10-20 ms off the robot's clock and 6 frames per second
while the arm moves (``scrapcut record --noise yard``), recorded once into a temporary folder.
Timed: :func:`scrapcut_cli.calibration.recipe.calibrate_recording` with ``max_frames`` 40 —
the whole command's work: plan the recording (headers and /tf), choose the frames, read and
observe them, solve, analyse observability. Wall and CPU time, median of ``--runs``; the error
of the estimate against the simulator's truth (metadata ``params.truth``, which the pipeline
never reads).

Target (issue 13): < 20 s for 40 frames at 640x480.

    .venv/bin/python benchmarks/bench_calibrate.py [--runs 3] [--frames 40] [--recording REC]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy / open3d load their thread pools

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from scrapcut_cli.calibration.recipe import calibrate_recording  # noqa: E402
from scrapcut_cli.config import ScrapcutConfig, SimConfig  # noqa: E402
from scrapcut_cli.geometry import invert_transform  # noqa: E402
from scrapcut_cli.recording.reader import open_recording  # noqa: E402


def truth_correction(path: Path) -> np.ndarray:
    """The true correction (mm, deg, ms) relative to the published mount, from the metadata."""
    with open_recording(path) as rec:
        truth = json.loads(rec.metadata["scrapcut"]["params"])["truth"]
        published = rec.published_mount()
    C = invert_transform(published.T_moving_camera) @ np.array(truth["T_moving_camera"])
    rotvec = np.degrees(Rotation.from_matrix(C[:3, :3]).as_rotvec())
    return np.r_[1000.0 * C[:3, 3], rotvec, 1000.0 * truth["time_offset_s"]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--recording", type=Path, default=None, help="use this recording")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        path = args.recording
        if path is None:
            from scrapcut_cli.sim import record

            path = Path(tmp) / "yard.mcap"
            t0 = time.perf_counter()
            result = record(SimConfig(object="cylinder", mode="sweep", noise="yard"), path)
            print(
                f"recorded a yard sweep of the cylinder: {result.frames} frames "
                f"({result.moving_frames} while moving), 640x480, {time.perf_counter() - t0:.0f} s"
            )
        config = ScrapcutConfig().override("calibration", max_frames=args.frames)
        calibrate_recording(path, config=config)  # warm-up: imports, caches
        walls, cpus = [], []
        for _ in range(args.runs):
            w, c = time.perf_counter(), time.process_time()
            calibration = calibrate_recording(path, config=config)
            walls.append(time.perf_counter() - w)
            cpus.append(time.process_time() - c)
        truth = truth_correction(path)

    s = calibration.solution
    error = s.correction - truth
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"load average {os.getloadavg()[0]:.1f}, Python {platform.python_version()}"
    )
    print(
        f"frames compared: {s.frames} of {calibration.source['frames']}, {s.pairs} pairs, "
        f"{s.residuals} residuals, {s.iterations} Gauss-Newton steps"
    )
    print(
        f"calibrate, median of {args.runs}: {statistics.median(walls):.1f} s wall, "
        f"{statistics.median(cpus):.1f} s CPU  (target < 20 s)"
    )
    print(
        f"residual RMS {s.residual_before_mm['all']:.2f} -> {s.residual_after_mm['all']:.2f} mm; "
        f"verdict: {calibration.verdict}"
    )
    names = ("x mm", "y mm", "z mm", "rx deg", "ry deg", "rz deg", "dt ms")
    for name, t, x, sigma, ok, e in zip(
        names, truth, s.correction, s.sigma, s.observable, error, strict=True
    ):
        print(
            f"  {name:7s} truth {t:+8.3f}  estimate {x:+8.3f}  sigma {sigma:6.3f}  "
            f"error {e:+7.3f}  {'observable' if ok else 'not observable'}"
        )
    t_err = float(np.linalg.norm(error[:3]))
    r_err = float(np.linalg.norm(error[3:6]))
    print(
        f"mount error {t_err:.2f} mm / {r_err:.3f} deg (goal 0.5 mm / 0.1 deg), "
        f"clock error {abs(error[6]):.2f} ms (goal 2 ms)"
    )


if __name__ == "__main__":
    main()
