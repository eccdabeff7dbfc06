"""Curve fitting speed on a stitched-like paint cloud of a 0.5 m line, against geomdl.

The cloud: a 0.5 m painted line that curves gently across a bent plate (radius 0.3 m in the
plane, then over a 90-degree fold), a ragged 25 mm band with round caps (the paint reaches
about 12 mm past each end, as a spray stroke does), 1 mm noise, 1 % stray points, thinned as
the stitcher does (one point per 2 mm voxel), in stitching order (along the line). About 8,000
points.

Timed, median of several runs, wall and CPU time (one core):

* NURBS — :func:`scrapcut_cli.fitting.nurbs.fit_nurbs`, default options (both initialisations,
  refinement, corner kinks); target < 100 ms;
* skeleton at 5 mm and 2 mm — :func:`scrapcut_cli.fitting.skeleton.fit_skeleton`; targets
  < 300 ms and < 1 s;
* geomdl — ``geomdl.fitting.approximate_curve`` (least squares with fixed chord-length
  parameters, The NURBS Book 9.4.1) on the same points ordered along our NURBS, with as many
  control points as ours. It needs the order handed to it and fits the band's points as given.

Each line also reports the fitted curve's error against the painted centre line (mean / max,
reference to curve, mm) and how far its ends lie from the line's (start / end, mm). The NURBS
is also timed without the end estimate (``end_trim="none"``, the curve then runs to the caps'
tips), which gives the estimate's cost.

    .venv/bin/python benchmarks/bench_fit.py [--runs 7] [--geomdl-runs 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy loads its thread pools

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from scrapcut_cli.config import NurbsConfig, SkeletonConfig  # noqa: E402
from scrapcut_cli.fitting.nurbs import fit_nurbs  # noqa: E402
from scrapcut_cli.fitting.skeleton import fit_skeleton  # noqa: E402
from scrapcut_cli.geometry import PolylineDistance, cumulative_length  # noqa: E402

FloatArray = NDArray[np.float64]


def painted_line(seed: int = 0) -> tuple[FloatArray, FloatArray]:
    """(stitched-like paint cloud (N, 3) in scan order, centre line (K, 3)), metres."""
    rng = np.random.default_rng(seed)
    # Centre line: 0.35 m arc of radius 0.3 m on the plate z = 0, then 0.15 m straight down
    # the folded side; the band's cross direction is the plate's in-plane normal to the line.
    s = np.linspace(0.0, 0.5, 2001)
    arc = np.minimum(s, 0.35)
    phi = arc / 0.3
    x = 0.3 * np.sin(phi)
    y = 0.3 * (1.0 - np.cos(phi))
    z = -np.maximum(s - 0.35, 0.0)
    centre = np.column_stack([x, y, z])
    across = np.column_stack([-np.sin(phi), np.cos(phi), np.zeros_like(phi)])
    n = 25_000
    t = rng.uniform(0.0, 0.5, n)
    k = np.minimum((t / 0.5 * (len(s) - 1)).astype(int), len(s) - 1)
    half = 0.0125 * (1.0 + 0.15 * np.sin(t / 0.02 + 1.0))
    pts = centre[k] + rng.uniform(-1.0, 1.0, n)[:, None] * half[:, None] * across[k]
    # Round caps: half discs of the band's half width centred on the line's ends, as dense.
    caps, cap_t = [], []
    for at, inner, sign in ((0, 1, -1.0), (-1, -2, 1.0)):
        h = 0.0125 * (1.0 + 0.15 * np.sin(s[at] / 0.02 + 1.0))
        out = centre[at] - centre[inner]
        out /= np.linalg.norm(out)
        m = round(n * 0.5 * np.pi * h**2 / (0.5 * 2.0 * 0.0125))
        r = h * np.sqrt(rng.uniform(0.0, 1.0, m))
        a = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, m)
        caps.append(
            centre[at] + (r * np.cos(a))[:, None] * out + (r * np.sin(a))[:, None] * across[at]
        )
        cap_t.append(s[at] + sign * r * np.cos(a))
    pts = np.vstack([pts, *caps])
    t = np.concatenate([t, *cap_t])
    n = len(pts)
    pts += rng.normal(scale=0.001, size=pts.shape)
    stray = rng.random(n) < 0.01
    pts[stray] += rng.uniform(-0.04, 0.04, (int(stray.sum()), 3))
    # The stitcher keeps one point per 2 mm voxel (the first seen), in scan order.
    order = np.argsort(t)
    pts = pts[order]
    _, first = np.unique(np.floor(pts / 0.002).astype(np.int64), axis=0, return_index=True)
    return pts[np.sort(first)], centre


def time_it(fn: Callable[[], object], runs: int) -> tuple[float, float, object]:
    """(median wall time, median CPU time of this process, last result) over ``runs``.

    On a shared machine the wall time includes waiting for a core; the CPU time does not.
    """
    result = fn()  # warm-up (imports, caches)
    wall, cpu = [], []
    for _ in range(runs):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = fn()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return statistics.median(wall), statistics.median(cpu), result


def error_mm(curve_points: FloatArray, centre: FloatArray) -> tuple[float, float, float, float]:
    """(mean, max) distance line -> curve, and the distances of the curve's start and end from
    the line's, mm."""
    d = PolylineDistance(curve_points).distance(centre)
    if np.linalg.norm(curve_points[0] - centre[0]) > np.linalg.norm(curve_points[-1] - centre[0]):
        curve_points = curve_points[::-1]
    start = float(np.linalg.norm(curve_points[0] - centre[0]))
    end = float(np.linalg.norm(curve_points[-1] - centre[-1]))
    return 1e3 * float(d.mean()), 1e3 * float(d.max()), 1e3 * start, 1e3 * end


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--geomdl-runs", type=int, default=3)
    args = parser.parse_args()

    pts, centre = painted_line()
    print(f"cloud: {len(pts)} points, 0.5 m line, 25 mm band, 1 mm noise, 1 % stray")
    rows = []
    wall, cpu, curve = time_it(lambda: fit_nurbs(pts, config=NurbsConfig()), args.runs)
    nurbs = curve
    rows.append(("NURBS (ours)", wall, cpu, 0.100, error_mm(curve.points, centre)))
    wall, cpu, curve = time_it(
        lambda: fit_nurbs(pts, config=NurbsConfig(end_trim="none")), args.runs
    )
    rows.append(("NURBS, ends at the tips (ours)", wall, cpu, None, error_mm(curve.points, centre)))
    for leaf, target in ((0.005, 0.300), (0.002, 1.000)):
        config = SkeletonConfig(leaf_size_m=leaf)
        wall, cpu, curve = time_it(lambda c=config: fit_skeleton(pts, config=c), args.runs)
        label = f"skeleton {leaf * 1e3:g} mm (ours)"
        rows.append((label, wall, cpu, target, error_mm(curve.points, centre)))

    from geomdl import fitting

    # The same points, ordered along our NURBS, as geomdl needs them ordered.
    _, _, u = PolylineDistance(nurbs.points).query(pts)
    ordered = pts[np.argsort(u, kind="stable")].tolist()
    n_ctrl = len(nurbs.nurbs.control_points)
    wall, cpu, g = time_it(
        lambda: fitting.approximate_curve(ordered, 3, ctrlpts_size=n_ctrl), args.geomdl_runs
    )
    g_points = np.asarray(g.evaluate_list(np.linspace(0.0, 1.0, 2000).tolist()))
    rows.append(
        (f"geomdl approximate_curve ({n_ctrl} cp)", wall, cpu, None, error_mm(g_points, centre))
    )

    print(
        f"{'method':34s} {'wall ms':>8s} {'cpu ms':>8s} {'target':>8s} "
        f"{'mean mm':>8s} {'max mm':>7s} {'ends mm':>11s}"
    )
    for label, wall, cpu, target, (mean, worst, start, end) in rows:
        tgt = f"<{target * 1e3:.0f}" if target is not None else "-"
        print(
            f"{label:34s} {wall * 1e3:8.1f} {cpu * 1e3:8.1f} {tgt:>8s} {mean:8.2f} {worst:7.2f} "
            f"{start:5.1f} {end:5.1f}"
        )
    length = float(cumulative_length(nurbs.points)[-1])
    print(
        f"NURBS: {n_ctrl} control points, {nurbs.info['corners']} corner(s), "
        f"length {length:.3f} m (true 0.500 m), stroke half width "
        f"{1e3 * nurbs.info['stroke_half_width_m']:.1f} mm, ends trimmed "
        f"{1e3 * nurbs.info['end_trim_m'][0]:.1f} / {1e3 * nurbs.info['end_trim_m'][1]:.1f} mm"
    )


if __name__ == "__main__":
    main()
