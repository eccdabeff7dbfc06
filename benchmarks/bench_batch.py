"""Batch throughput on Dask: 20 runs with 2 local workers against 1 (goal: at least 1.7x).

    .venv/bin/python benchmarks/bench_batch.py [--repeat N] [--runs N] [--recording REC]

Each run fits the committed fixture recording (320x240, 6 views) with another grid point
(NURBS smoothness and skeleton leaf size), so all 20 are real, different jobs of about the same
size. Each measurement uses a fresh output folder (a batch run twice does no work) and a fresh
local cluster; "work" is the batch alone (cluster started, worker imports included), "total"
adds the cluster's start and stop. Prints the medians over ``--repeat`` alternating
measurements, the ratio, and the load average (other processes on the machine lower it).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from scrapcut_cli.config import ScrapcutConfig
from scrapcut_cli.pipeline.batch import batch
from scrapcut_cli.pipeline.batch_inputs import collect_inputs
from scrapcut_cli.pipeline.engine import Engine
from scrapcut_cli.pipeline.reproduce import machine_description

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "sim_cylinder_small.mcap"
GOAL = 1.7


def grid_of(runs: int) -> dict[str, list[object]]:
    """``runs`` grid points: half NURBS smoothness values, half skeleton leaf sizes."""
    half = runs // 2
    return {
        "method": ["nurbs", "skeleton"],
        "nurbs.smoothness": [round(0.25 + 0.25 * i, 2) for i in range(runs - half)],
        "skeleton.leaf_size_m": [round(0.004 + 0.0005 * i, 4) for i in range(half)],
    }


def measure(workers: int, runs: int, recording: Path) -> tuple[float, float, int]:
    inputs = collect_inputs([recording])
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        with Engine(workers=workers) as engine:
            engine.start()
            t1 = time.perf_counter()
            result = batch(
                inputs,
                out_dir=Path(tmp) / "out",
                grid=grid_of(runs),
                config=ScrapcutConfig(),
                engine=engine,
                plots=False,
            )
            work = time.perf_counter() - t1
        total = time.perf_counter() - t0
    assert result.failed == 0 and result.cached == 0, result.rows
    return work, total, len(result.rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--recording", type=Path, default=FIXTURE)
    args = parser.parse_args()
    print(f"machine: {machine_description()}")
    print(f"batch: {args.runs} runs of {args.recording.name}, {args.repeat} measurement(s) each")
    times: dict[int, list[tuple[float, float]]] = {1: [], 2: []}
    for _ in range(args.repeat):
        for workers in (1, 2):
            work, total, n = measure(workers, args.runs, args.recording)
            assert n == args.runs, n
            times[workers].append((work, total))
            print(
                f"  {workers} worker(s): work {work:6.1f} s, total {total:6.1f} s, "
                f"load average {os.getloadavg()[0]:.1f}"
            )
    med = {
        w: (statistics.median(t[0] for t in v), statistics.median(t[1] for t in v))
        for w, v in times.items()
    }
    ratio_work, ratio_total = med[1][0] / med[2][0], med[1][1] / med[2][1]
    print(
        f"median work: 1 worker {med[1][0]:.1f} s, 2 workers {med[2][0]:.1f} s -> "
        f"{ratio_work:.2f}x (goal {GOAL}x: {'met' if ratio_work >= GOAL else 'MISSED'})"
    )
    print(
        f"median total with cluster start/stop: {med[1][1]:.1f} s vs {med[2][1]:.1f} s -> "
        f"{ratio_total:.2f}x"
    )


if __name__ == "__main__":
    main()
