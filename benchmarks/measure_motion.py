"""Issue 16's acceptance measurement: every simulated piece x both methods, scan to simulated cut.

For each piece and method: ``scrapcut record --mode explore`` (the closed-loop scan, d435i
noise, 640 x 480), ``scrapcut fit``, ``scrapcut trajectory`` (the recording's depth as the
observed surface) and ``scrapcut simulate-cut`` (pybullet, the true piece). Per run it prints:

* set-points and how many the plan reaches as given / tilted / not (with the reasons);
* the share of reachable set-points whose torch tip, by forward kinematics of the trajectory's
  joints with Franka's DH parameters (``tests/helpers.py``, independent of the planner's URDF
  chain), lies within 0.5 mm and 1 degree of the path's set-point (tilted ones: of the tilted
  target) — the issue asks for >= 99 %;
* whether the sampled trajectory stays within the datasheet's position, velocity,
  acceleration and jerk limits (the planner's own check, finite differences at 1 kHz);
* collisions with the observed surface (set-points and trajectory points) and, in the
  simulated cut, with the true piece and the floor; the simulated tip deviation.

    .venv/bin/python benchmarks/measure_motion.py [--objects all] [--methods nurbs,skeleton]
        [--out DIR] [--time-step-ms 2]

Not part of ``make test`` (minutes). Results go to DIR/summary.json as well.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers import panda_dh_flange

from scrapcut_cli.geometry import quat_xyzw_to_matrix
from scrapcut_cli.sim.objects import list_objects
from scrapcut_cli.toolpath.pathfile import read_path_file

SCRAPCUT = str(Path(sys.executable).with_name("scrapcut"))


def run(*args: object) -> str:
    result = subprocess.run(
        [SCRAPCUT, *(str(a) for a in args)], capture_output=True, text=True, check=False
    )
    if result.returncode != 0:
        raise RuntimeError(f"scrapcut {' '.join(map(str, args))}: {result.stderr.strip()}")
    return result.stdout


def dh_accuracy(path_file: Path, traj_file: Path) -> tuple[float, float, float, int]:
    """(share within 0.5 mm / 1 deg, worst tip error mm, worst axis error deg, points) over
    the reachable set-points, by Franka's DH parameters."""
    _, path, _ = read_path_file(path_file)
    data = json.loads(traj_file.read_text())
    T_ft = np.eye(4)
    T_ft[:3, :3] = quat_xyzw_to_matrix(data["T_flange_tool"]["rotation_xyzw"])
    T_ft[:3, 3] = data["T_flange_tool"]["translation_m"]
    status = {sp["index"]: sp for sp in data["setpoints"]}
    axes = quat_xyzw_to_matrix(path.orientations_xyzw)[:, :, 2]
    ok, tips, angles = [], [], []
    done = set()
    for point in data["points"]:
        i = point["setpoint"]
        if i is None or i in done:
            continue
        done.add(i)
        T = panda_dh_flange(point["positions"]) @ T_ft
        sp = status[i]
        target = np.asarray(sp["tip"]) if sp["status"] == "tilted" else path.positions[i]
        axis = np.asarray(sp["axis"]) if sp["status"] == "tilted" else axes[i]
        tip = float(np.linalg.norm(T[:3, 3] - target)) * 1000.0
        angle = float(np.degrees(np.arccos(np.clip(T[:3, 2] @ axis, -1.0, 1.0))))
        tips.append(tip)
        angles.append(angle)
        ok.append(tip < 0.5 and angle < 1.0)
    return float(np.mean(ok)), max(tips), max(angles), len(ok)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", default="all")
    parser.add_argument("--methods", default="nurbs,skeleton")
    parser.add_argument("--out", type=Path, default=Path("motion-measure"))
    parser.add_argument("--time-step-ms", type=float, default=2.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    objects = (
        [name for name, _ in list_objects()] if args.objects == "all" else args.objects.split(",")
    )
    methods = args.methods.split(",")
    args.out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    print(f"load average {os.getloadavg()[0]:.1f}; {len(objects)} pieces x {len(methods)} methods")
    header = (
        f"{'piece':12s} {'method':8s} {'setpts':>6s} {'reach':>5s} {'tilt':>4s} {'unre':>4s} "
        f"{'coll':>4s} {'DH ok':>6s} {'tip mm':>7s} {'ax deg':>6s} {'limits':>6s} "
        f"{'obs hit':>7s} {'true hit':>8s} {'sim tip':>7s} {'ends':>14s} {'plan s':>6s}"
    )
    print(header)
    for name in objects:
        for method in methods:
            base = args.out / f"{name}_{method}"
            rec, path_file, traj = (
                base.with_suffix(".mcap"),
                base.with_suffix(".json"),
                base.with_name(base.name + "_traj.json"),
            )
            row: dict[str, Any] = {"object": name, "method": method}
            try:
                if not rec.exists():
                    run(
                        "record",
                        "--object",
                        name,
                        "--mode",
                        "explore",
                        "--method",
                        method,
                        "--seed",
                        args.seed,
                        "-o",
                        rec,
                    )
                try:
                    run("fit", rec, "--method", method, "-o", path_file)
                except RuntimeError as exc:
                    if method != "skeleton" or "broken into" not in str(exc):
                        raise
                    # As reproduce does (the paper's basket): once more at a 20 mm leaf.
                    run("fit", rec, "--method", method, "--leaf-size", 20, "-o", path_file)
                    row["note"] = "skeleton retried at a 20 mm leaf"
                summary = json.loads(
                    run("trajectory", path_file, "--recording", rec, "-o", traj, "--json")
                )
                start = time.perf_counter()
                sim = json.loads(
                    run(
                        "simulate-cut",
                        traj,
                        "--recording",
                        rec,
                        "--json",
                        "--time-step-ms",
                        args.time_step_ms,
                    )
                )
                sim_s = time.perf_counter() - start
            except RuntimeError as exc:
                row["error"] = str(exc)
                rows.append(row)
                print(f"{name:12s} {method:8s} error: {exc}")
                continue
            share, tip, angle, n = dh_accuracy(path_file, traj)
            row.update(
                summary={k: v for k, v in summary.items() if k != "flagged"},
                dh_share=share,
                dh_tip_max_mm=tip,
                dh_axis_max_deg=angle,
                dh_points=n,
                simulate=sim,
                simulate_s=sim_s,
            )
            rows.append(row)
            ends = f"{summary['start']}/{summary['finish']}"
            print(
                f"{name:12s} {method:8s} {summary['setpoints']:6d} {summary['reached']:5d} "
                f"{summary['tilted']:4d} {summary['unreachable']:4d} {summary['in_collision']:4d} "
                f"{100 * share:5.1f}% {tip:7.3f} {angle:6.3f} "
                f"{'ok' if summary['limits_ok'] else 'NO':>6s} "
                f"{summary['trajectory_collisions']:7d} {sim['collision_count']:8d} "
                f"{sim['tip_error_mm']['max'] or 0:7.3f} {ends:>14s} "
                f"{summary['time_s']['plan']:6.2f}"
            )
            if summary["reasons"]:
                print(f"{'':22s} reasons: {summary['reasons']}")
            if sim["collisions"]:
                print(f"{'':22s} true collisions: {sim['collisions']}")
    (args.out / "summary.json").write_text(json.dumps(rows, indent=1, default=str) + "\n")


if __name__ == "__main__":
    main()
