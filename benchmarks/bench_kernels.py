"""The per-frame neighbour kernels, compiled (scrapcut_cli/_native.c) against the open3d /
scipy code they replace, on clouds of a 1280x720 frame's sizes (read every 2nd pixel at the
wrist's 0.3 m):

* outlier removal: ~3,000 paint voxels (2 mm) on a bent strip 40 mm wide, noise and 1 %
  outliers, 20 neighbours, ratio 2 (open3d's ``remove_statistical_outlier``);
* surface band: ~7,500 surface samples against ~90 paint centroids, 40 mm
  (scipy's ``cKDTree.query`` with ``distance_upper_bound``).

Milliseconds a call, CPU time, one thread, median of ``--runs`` runs of ``--calls`` calls each
(the two implementations alternate within a run); both must give the same points.

    .venv/bin/python benchmarks/bench_kernels.py [--runs 7] [--calls 30]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy / open3d load their thread pools

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import numpy as np  # noqa: E402
from bench_fit_resolution import cpu_name  # noqa: E402

from scrapcut_cli import _kernels  # noqa: E402


def strip(rng: np.random.Generator, width_m: float, step_m: float) -> np.ndarray:
    s, w = np.meshgrid(np.arange(0, 0.3, step_m), np.arange(-width_m / 2, width_m / 2, step_m))
    s, w = s.ravel(), w.ravel()
    pts = np.c_[0.3 * np.sin(s / 0.3), w, 0.3 * (1 - np.cos(s / 0.3))]
    return pts + rng.normal(0, 0.0004, pts.shape) + [0.45, -0.1, 0.02]


def cpu_ms(fn: Callable[[], object], calls: int) -> float:
    start = time.process_time()
    for _ in range(calls):
        fn()
    return (time.process_time() - start) / calls * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--calls", type=int, default=30)
    args = parser.parse_args()
    if not _kernels.native():
        raise SystemExit(
            "the compiled kernels are not built (or SCRAPCUT_NATIVE=0): nothing to compare"
        )
    rng = np.random.default_rng(0)
    paint = strip(rng, 0.04, 0.002)
    outliers = paint[rng.integers(0, len(paint), len(paint) // 100)]
    paint = np.vstack([paint, outliers + rng.normal(0, 0.01, outliers.shape)])
    paint = paint[rng.permutation(len(paint))]
    surface = strip(rng, 0.12, 0.0022)
    surface[:, 2] += rng.normal(0, 0.01, len(surface))
    centroids = strip(rng, 0.03, 0.01)

    def sor() -> object:
        return _kernels.statistical_inliers(paint, neighbors=20, std_ratio=2.0)

    def band() -> object:
        return _kernels.within_distance(surface, centroids, 0.04)

    native_module = _kernels._native
    rows = []
    for name, fn, size in [
        ("outlier removal", sor, f"{len(paint)} points, k=20"),
        ("surface band", band, f"{len(surface)} against {len(centroids)}"),
    ]:
        times: dict[str, list[float]] = {"compiled": [], "open3d/scipy": []}
        results = {}
        for _ in range(args.runs):
            for label, module in (("compiled", native_module), ("open3d/scipy", None)):
                _kernels._native = module
                results[label] = fn()
                times[label].append(cpu_ms(fn, args.calls))
        _kernels._native = native_module
        same = np.array_equal(results["compiled"], results["open3d/scipy"])
        rows.append((name, size, *(statistics.median(t) for t in times.values()), same))
    print(
        f"# {cpu_name()}, {os.cpu_count()} cores, one thread; "
        f"medians of {args.runs} runs of {args.calls} calls (CPU time)"
    )
    print(f"{'kernel':18s} {'size':22s} {'compiled [ms]':>14s} {'open3d/scipy':>13s} {'same':>5s}")
    for name, size, fast, slow, same in rows:
        print(f"{name:18s} {size:22s} {fast:14.2f} {slow:13.2f} {'yes' if same else 'NO':>5s}")
    if not all(row[-1] for row in rows):
        raise SystemExit("the compiled kernels disagree with open3d/scipy")


if __name__ == "__main__":
    main()
