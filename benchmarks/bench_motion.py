"""Joint-trajectory planning speed: a 0.5 m cutting path, set-points every 5 mm.

The path: a 0.5 m line that curves across a plate 0.1 m above the floor in front of the Panda
(y from -0.25 m across, 0.5 m ahead with a 60 mm sine), set-points from the tool-path recipe
(standoff 8 mm, torch perpendicular), the plate's observed surface a 3 mm grid of 0.3 x 0.6 m
(20,000 points). Timed, median of several runs, wall and CPU time (one core):
:func:`scrapcut_cli.motion.plan.plan_trajectory` with the default torch mount and motion
parameters — IK of every set-point with redundancy resolution and collision checks, approach,
pierce dwell, cut, retreat, timing and the final checks. Target: < 2 s.

    .venv/bin/python benchmarks/bench_motion.py [--runs 5]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy loads its thread pools

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from scrapcut_cli.config import MotionConfig, ToolpathConfig  # noqa: E402
from scrapcut_cli.fitting.curve import Curve  # noqa: E402
from scrapcut_cli.motion.plan import plan_trajectory  # noqa: E402
from scrapcut_cli.motion.tool import default_mount  # noqa: E402
from scrapcut_cli.toolpath.setpoints import make_cutting_path  # noqa: E402

TARGET_S = 2.0


def plate_path() -> tuple[object, np.ndarray]:
    """(CuttingPath of a 0.5 m line, the plate's observed cloud (N, 3)), metres."""
    y = np.linspace(-0.25, 0.3, 2200)
    x = 0.5 + 0.03 * np.sin(2 * np.pi * (y + 0.25) / 0.5)
    pts = np.column_stack([x, y, np.full_like(x, 0.1)])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    pts = pts[s <= 0.5]
    gx, gy = np.meshgrid(np.arange(0.35, 0.65, 0.003), np.arange(-0.3, 0.3, 0.003))
    cloud = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 0.1)])
    path = make_cutting_path(
        Curve(pts, "bench"), cloud, cloud + np.array([0.0, 0.0, 0.3]), config=ToolpathConfig()
    )
    return path, cloud


def cpu_model() -> str:
    """The CPU's model name (Linux), else the machine type."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    path, cloud = plate_path()
    wall, cpu = [], []
    summary: dict[str, object] = {}
    for _ in range(args.runs):
        start, start_cpu = time.perf_counter(), time.process_time()
        traj = plan_trajectory(
            path,  # type: ignore[arg-type]
            base_frame="panda_link0",
            surface_base=cloud,
            mount=default_mount(),
            config=MotionConfig(),
        )
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
        summary = traj.summary
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; load average {os.getloadavg()[0]:.1f}"
    )
    print(
        f"path: {summary['setpoints']} set-points over {path.arc_length[-1]:.3f} m, "  # type: ignore[attr-defined]
        f"{len(cloud)} observed points; runs: {args.runs}"
    )
    print(
        f"plan_trajectory: median {statistics.median(wall):.3f} s wall, "
        f"{statistics.median(cpu):.3f} s CPU (target < {TARGET_S:.0f} s: "
        f"{'met' if statistics.median(cpu) < TARGET_S else 'MISSED'})"
    )
    print(
        f"result: reached {summary['reached']}, tilted {summary['tilted']}, unreachable "
        f"{summary['unreachable']}, collisions {summary['trajectory_collisions']}, tip error "
        f"{summary['tip_error_max_mm']:.3f} mm, duration {summary['duration_s']:.1f} s, "
        f"{summary['points']} points, limits {'ok' if summary['limits_ok'] else 'EXCEEDED'}"
    )


if __name__ == "__main__":
    main()
