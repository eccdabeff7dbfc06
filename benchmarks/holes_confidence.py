"""How well the set-points' confidence matches the simulator's truth (issue 14's criteria).

    .venv/bin/python benchmarks/holes_confidence.py RESULTS_DIR [RESULTS_DIR...]

For every path file of ``scrapcut reproduce`` output folders (``DIR/paths/*.json``), rebuilds the
simulated piece its recording names and asks, for each set-point, whether the painted line runs
over a hole there: the reference point nearest to the set-point's surface point lies more than
``HOLE_GAP_M`` from the piece's mesh (a perforated plate's slot, the gap between a basket's
wires). Prints per path: the set-points over holes, the share of them flagged ``bridged_gap``
(goal >= 80 %), the share of the others flagged (goal < 10 %), σ's median and the share of
reference samples within 2σ of the path (from the path's error report; goal >= 90 %).

Simulator truth is read here only, after the fact: nothing in scrapcut sees it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from scrapcut_cli._open3d import o3d
from scrapcut_cli.evaluation.sources import recording_reference
from scrapcut_cli.geometry import resample_polyline
from scrapcut_cli.sim import make_object
from scrapcut_cli.toolpath.pathfile import read_path_file

#: A reference point this far from the piece's surface lies over a hole.
HOLE_GAP_M = 0.001


def distance_to_mesh(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    scene: Any = o3d().t.geometry.RaycastingScene()
    core = o3d().core
    scene.add_triangles(
        core.Tensor(vertices.astype(np.float32)), core.Tensor(faces.astype(np.uint32))
    )
    return np.asarray(
        scene.compute_distance(core.Tensor(points.astype(np.float32))).numpy(), dtype=np.float64
    )


def measure(path_file: Path) -> dict[str, Any] | None:
    _, path, meta = read_path_file(path_file)
    source = Path(meta["source"]["path"])
    if not source.is_absolute() and not source.exists():
        source = path_file.parent.parent / "recordings" / source.name
    reference = recording_reference(source)
    if reference is None or reference.object is None:
        return None
    params = json.loads(reference.metadata.get("params", "{}"))
    placement = None
    if "object_x_m" in params:
        placement = (params["object_x_m"], params["object_y_m"], params["object_yaw_deg"])
    piece = make_object(reference.object, placement=placement)
    samples = resample_polyline(reference.points, 0.001)
    over = distance_to_mesh(piece.vertices, piece.faces, samples) > HOLE_GAP_M
    nearest = np.argmin(
        np.linalg.norm(path.surface_points[:, None, :] - samples[None, :, :], axis=2), axis=1
    )
    truth = over[nearest]
    flagged = np.array(["bridged_gap" in f for f in path.flags], dtype=bool)
    report = path_file.with_suffix(".error.json")
    figures = json.loads(report.read_text()) if report.is_file() else {}
    return {
        "path": path_file.name,
        "object": reference.object,
        "setpoints": len(path),
        "over_holes": int(truth.sum()),
        "flagged_over_holes": float(flagged[truth].mean()) if truth.any() else None,
        "flagged_elsewhere": float(flagged[~truth].mean()) if (~truth).any() else None,
        "sigma_median_mm": None if path.sigma_m is None else 1000 * float(np.median(path.sigma_m)),
        "within_2sigma": figures.get("within_2sigma"),
        "mean_mm": figures.get("mean_mm"),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folders", nargs="+", type=Path)
    args = parser.parse_args()
    rows = []
    for folder in args.folders:
        for path_file in sorted((folder / "paths").glob("*.json")):
            if path_file.name.endswith(".error.json"):
                continue
            row = measure(path_file)
            if row is not None:
                rows.append(row)
    fmt = "{:<36} {:>6} {:>6} {:>9} {:>9} {:>7} {:>7} {:>7}"
    print(fmt.format("path", "setpts", "holes", "flag@hole", "flag@else", "σ mm", "≤2σ", "mean"))

    def pct(v: float | None) -> str:
        return "—" if v is None else f"{100 * v:.1f}%"

    for r in rows:
        print(
            fmt.format(
                r["path"],
                r["setpoints"],
                r["over_holes"],
                pct(r["flagged_over_holes"]),
                pct(r["flagged_elsewhere"]),
                "—" if r["sigma_median_mm"] is None else f"{r['sigma_median_mm']:.2f}",
                pct(r["within_2sigma"]),
                "—" if r["mean_mm"] is None else f"{r['mean_mm']:.2f}",
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
