"""Wall time of ``scrapcut reproduce`` with the defaults of ``make demo`` (target: < 180 s for
5 objects × 2 methods on a local Dask cluster of 2 workers on a 2-core machine), the time of
each stage per object, and the Table I figures it produced.

    .venv/bin/python benchmarks/bench_reproduce.py [--repeat N] [--workers N] [--objects a,b]
                                                   [--width W --height H] [--leaf-sweep-mm L]

Prints the median wall time over ``--repeat`` runs (default 1: one run takes up to minutes) and the
per-object stage times of the last run.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from scrapcut_cli.commands.reproduce import DEFAULT_LEAF_SWEEP
from scrapcut_cli.config import ScrapcutConfig, SimConfig
from scrapcut_cli.pipeline.engine import Engine, default_workers
from scrapcut_cli.pipeline.reproduce import (
    PAPER_OBJECTS,
    ReproduceResult,
    machine_description,
    reproduce,
)

TARGET_S = 180.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--workers", type=int, default=default_workers())
    parser.add_argument("--objects", default=",".join(PAPER_OBJECTS))
    parser.add_argument("--methods", default="nurbs,skeleton")
    parser.add_argument("--width", type=int, default=SimConfig().width)
    parser.add_argument("--height", type=int, default=SimConfig().height)
    parser.add_argument("--leaf-sweep-mm", default=DEFAULT_LEAF_SWEEP, help="'none' to skip")
    parser.add_argument(
        "--mode", default="explore", choices=("explore", "sweep"), help="as make demo: explore"
    )
    args = parser.parse_args()

    config = ScrapcutConfig().override("sim", width=args.width, height=args.height, mode=args.mode)
    objects = args.objects.split(",")
    methods = args.methods.split(",")
    sweep = (
        ()
        if args.leaf_sweep_mm == "none"
        else tuple(float(v) / 1000.0 for v in args.leaf_sweep_mm.split(","))
    )
    print(f"machine: {machine_description()}")
    print(
        f"reproduce: {len(objects)} objects x {len(methods)} methods, {args.width}x{args.height}"
        f" px, {args.mode} mode, workers {args.workers}, leaf sweep {args.leaf_sweep_mm} mm,"
        f" {args.repeat} run(s)"
    )
    walls = []
    result: ReproduceResult | None = None
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            with Engine(workers=args.workers) as engine:  # the cluster's start-up is counted
                result = reproduce(
                    Path(tmp) / "out",
                    objects=objects,
                    methods=methods,
                    config=config,
                    engine=engine,
                    leaf_sweep_m=sweep,
                )
            walls.append(time.perf_counter() - t0)
    assert result is not None
    print("\nstage times of the last run [s]:")
    for run in result.runs:
        stages = "  ".join(f"{k} {v:6.1f}" for k, v in run.timings_s.items())
        views = "+".join(str(s.get("views", "?")) for s in run.scans)
        print(f"  {run.object:<12} views {views!s:>3}  {stages}")
    print("\nTable I of the last run [mm]:")
    for row in result.rows:
        if row.error is None:
            print(f"  {row.object:<12} {row.label:<15} failed: {row.failure}")
        else:
            f = row.error.summary_mm()
            print(
                f"  {row.object:<12} {row.label:<15} mean {f['mean_mm']:6.2f}  sd {f['sd_mm']:6.2f}"
                f"  min {f['min_mm']:6.2f}  max {f['max_mm']:6.2f}  cov {100 * f['coverage']:5.1f}%"
            )
    median = statistics.median(walls)
    verdict = "meets" if median < TARGET_S else "MISSES"
    print(
        f"\nwall time: median {median:.1f} s over {len(walls)} run(s); "
        f"{verdict} the {TARGET_S:.0f} s target"
    )


if __name__ == "__main__":
    main()
