"""Tool-path timing: set-points, normals, collision check and timing for a 0.5 m cut.

Scenes are stitched-like clouds: paint at a 2 mm voxel in a 25 mm band plus the surface band
(40 mm each side) at a 4 mm voxel, 0.5 mm noise — the sizes `scrapcut fit` hands over. Prints
the median of several runs per scene. Run: ``.venv/bin/python benchmarks/bench_toolpath.py``.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from helpers import (
    arc_on_cylinder,
    corner_on_beam,
    line_on_plane,
    painted_stroke,
    surface_patch,
)

from scrapcut_cli.config import ToolpathConfig
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.toolpath.setpoints import make_cutting_path

RUNS = 7


def _band(curve: np.ndarray, normals: np.ndarray, seed: int) -> np.ndarray:
    """Surface band: a 105 mm wide stroke-like patch at a 4 mm voxel."""
    return painted_stroke(curve, normals, width_m=0.105, spacing_m=0.004, noise_m=0.0005, seed=seed)


def _scene(name: str) -> tuple[Curve, np.ndarray, np.ndarray]:
    if name == "plane 0.5 m":
        curve, normals = line_on_plane(0.5)
    elif name == "pipe r=0.16 m":
        curve, normals = arc_on_cylinder(radius=0.16, angle=0.5 / 0.16)
    else:
        curve, normals = corner_on_beam(arm=0.25)
    paint = painted_stroke(curve, normals, noise_m=0.0005, seed=1)
    surface = _band(curve, normals, seed=2)
    cloud = np.vstack([paint, surface])
    # Each point seen from 0.3 m along the local normal of the nearest centre-line vertex.
    nearest = np.argmin(np.linalg.norm(cloud[:, None, :] - curve[None, ::10, :], axis=2), axis=1)
    viewpoints = cloud + 0.3 * normals[::10][nearest]
    if name == "beam joint 0.5 m + wall":
        wall = surface_patch([-0.1, 0.01, 0.0], [0.05, 0, 0], [0, 0, 0.1], spacing_m=0.004)
        cloud = np.vstack([cloud, wall])
        viewpoints = np.vstack([viewpoints, wall - np.array([0.0, 0.3, 0.0])])
    return Curve(curve, "bench"), cloud, viewpoints


def main() -> None:
    config = ToolpathConfig()
    print(f"make_cutting_path, median of {RUNS} runs (spacing 5 mm, torch 150 x 12 mm)")
    print(f"{'scene':<26} {'cloud pts':>9} {'set-pts':>8} {'flagged':>8} {'median ms':>10}")
    for name in ("plane 0.5 m", "pipe r=0.16 m", "beam joint 0.5 m + wall"):
        curve, cloud, viewpoints = _scene(name)
        times = []
        for _ in range(RUNS):
            t0 = time.perf_counter()
            path = make_cutting_path(curve, cloud, viewpoints, config=config)
            times.append(time.perf_counter() - t0)
        ms = 1000 * statistics.median(times)
        print(f"{name:<26} {len(cloud):>9} {len(path):>8} {path.flagged:>8} {ms:>10.1f}")


if __name__ == "__main__":
    main()
