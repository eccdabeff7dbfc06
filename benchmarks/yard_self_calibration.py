"""The yard table with and without self-calibration, on the recordings of a reproduce run.

Takes the output folder of a one-seed ``scrapcut reproduce`` (its recordings, report.json and
config.toml). A run made with ``--self-calibrate`` holds the self-calibrated rows and their
path files already; otherwise every recording is fitted again with ``fit --self-calibrate``'s
job (the same pipeline, the same stage parameters, ``calibration.self_calibrate`` on), measured
against the painted reference as ``scrapcut eval`` does. Prints, per object and method:

- the reproduce run's row and the self-calibrated row (mean, SD, max, coverage, reverse max,
  length ratio: the README's yard-table columns) and the change in mean error;
- what the calibration found: the verdict, which parameters it reports observable, and its
  error against the simulator's truth (metadata ``params.truth``, which the pipeline never
  reads) for the mount (mm, deg) and the clock (ms).

Then the means over all rows and the issue's goals (mean path error <= 1.2 mm; mount within
0.5 mm / 0.1 deg and clock within 2 ms where observable; clean recordings changed <= 0.1 mm).

    scrapcut reproduce --objects all --noise yard --leaf-sweep-mm none --self-calibrate -o yard
    .venv/bin/python benchmarks/yard_self_calibration.py yard
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from scrapcut_cli.config import FitMethod, load_config  # noqa: E402
from scrapcut_cli.geometry import invert_transform  # noqa: E402
from scrapcut_cli.pipeline.job import Job, run_job  # noqa: E402
from scrapcut_cli.recording.reader import open_recording  # noqa: E402

COLUMNS = ("mean_mm", "sd_mm", "max_mm", "coverage", "reverse_max_mm", "length_ratio")


def _truth(path: Path) -> tuple[np.ndarray, float] | None:
    """(true correction: translation mm (3), rotation deg (3); true clock offset ms)."""
    with open_recording(path) as rec:
        params = json.loads(rec.metadata.get("scrapcut", {}).get("params", "{}"))
        truth = params.get("truth")
        if truth is None:
            return None
        published = rec.published_mount()
    C = invert_transform(published.T_moving_camera) @ np.array(truth["T_moving_camera"])
    rot = np.degrees(Rotation.from_matrix(C[:3, :3]).as_rotvec())
    return np.r_[1000.0 * C[:3, 3], rot], 1000.0 * float(truth["time_offset_s"])


def _rows(
    report: dict[str, Any], *, self_calibrated: bool
) -> dict[tuple[str, str], dict[str, Any]]:
    """The plain (or the self-calibrated) rows by object and method."""
    return {
        (r["object"], r["method"]): r
        for r in report.get("rows", [])
        if bool(r.get("self_calibrated")) == self_calibrated
    }


def _fmt(row: dict[str, Any] | None) -> str:
    if row is None or row.get("mean_mm") is None:
        return " | ".join(["-"] * len(COLUMNS))
    cells = []
    for key in COLUMNS:
        value = row.get(key)
        if value is None:
            cells.append("-")
        elif key == "coverage":
            cells.append(f"{100 * value:.1f}%")
        elif key == "length_ratio":
            cells.append(f"{value:.3f}")
        else:
            cells.append(f"{value:.2f}")
    return " | ".join(cells)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a scrapcut reproduce output folder")
    args = parser.parse_args()
    folder: Path = args.folder
    report = json.loads((folder / "report.json").read_text())
    config = load_config(folder / "config.toml").override("calibration", self_calibrate=True)
    before = _rows(report, self_calibrated=False)
    done = _rows(report, self_calibrated=True)
    lines = []
    deltas, means, t_errs, r_errs, c_errs = [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for (obj, method), row in sorted(before.items()):
            recording = _recording_of(folder, obj, method)
            if (obj, method) in done:  # reproduce --self-calibrate fitted it already
                after = done[(obj, method)]
                calibration = _path_calibration(folder, after)
                when = "reproduce"
                if after.get("mean_mm") is None:
                    after = None
            else:
                t0 = time.perf_counter()
                job = Job(
                    recording,
                    FitMethod(method.split()[0]),
                    config,
                    output=Path(tmp) / f"{obj}_{method.split()[0]}.json",
                    object_name=obj,
                    retry_leaf_size_m=0.020,
                )
                result = run_job(job)
                when = f"{time.perf_counter() - t0:.0f} s"
                after = None if result.report.row is None else _row_dict(result.report.row)
                calibration = None if result.fit is None else result.fit.calibration
            truth = _truth(recording)
            found = "-"
            if calibration is not None and truth is not None:
                correction = calibration["correction"]
                est = np.r_[
                    1000.0 * np.array(correction["translation_m"]), correction["rotation_deg"]
                ]
                obs = calibration["observable"]
                ok = np.r_[obs["translation"], obs["rotation"]]
                e = est - truth[0]
                t_err = float(np.linalg.norm(e[:3][ok[:3]])) if ok[:3].any() else float("nan")
                r_err = float(np.linalg.norm(e[3:][ok[3:]])) if ok[3:].any() else float("nan")
                c_err = (
                    abs(1000.0 * correction["time_offset_s"] - truth[1])
                    if obs["time_offset"]
                    else float("nan")
                )
                t_errs.append(t_err)
                r_errs.append(r_err)
                c_errs.append(c_err)
                found = (
                    f"{'consistent' if calibration['consistent'] else 'corrected'}, observable "
                    f"{int(ok.sum()) + int(obs['time_offset'])}/7, error {t_err:.2f} mm / "
                    f"{r_err:.3f} deg / {c_err:.2f} ms"
                )
            delta = "-"
            if after is not None and row.get("mean_mm") is not None:
                d = after["mean_mm"] - row["mean_mm"]
                deltas.append(d)
                means.append(after["mean_mm"])
                delta = f"{d:+.2f}"
            lines.append(
                f"| {obj} | {method} | {_fmt(row)} | {_fmt(after)} | {delta} | {found} | {when} |"
            )
            print(lines[-1], flush=True)
    print()
    header = " | ".join(COLUMNS)
    print(
        f"| object | method | before: {header} | self-calibrated: {header} | Δ mean [mm] | "
        "calibration vs truth | fitted in |"
    )
    print("|" + "---|" * (2 * len(COLUMNS) + 5))
    print("\n".join(lines))
    if means:
        print(
            f"\nmean path error, self-calibrated: {np.mean(means):.2f} mm over {len(means)} "
            f"rows (goal <= 1.2 mm); change of the mean: {np.mean(deltas):+.2f} mm, largest "
            f"|change| {np.max(np.abs(deltas)):.2f} mm"
        )
    if t_errs:
        print(
            f"calibration error where observable: mount max {np.nanmax(t_errs):.2f} mm / "
            f"{np.nanmax(r_errs):.3f} deg (goal 0.5 mm / 0.1 deg), clock max "
            f"{np.nanmax(c_errs) if np.isfinite(c_errs).any() else float('nan'):.2f} ms "
            "(goal 2 ms)"
        )


def _path_calibration(folder: Path, record: dict[str, Any]) -> dict[str, Any] | None:
    """The ``calibration`` a self-calibrated row's path file recorded."""
    if not record.get("path"):
        return None
    data = json.loads((folder / record["path"]).read_text())
    calibration = data.get("calibration")
    return calibration if isinstance(calibration, dict) else None


def _recording_of(folder: Path, obj: str, method: str) -> Path:
    """The recording of a row: ``<object>_<method>.mcap`` when exploring, else ``<object>``."""
    name = method.split()[0]
    explored = folder / "recordings" / f"{obj}_{name}.mcap"
    return explored if explored.exists() else folder / "recordings" / f"{obj}.mcap"


def _row_dict(row: Any) -> dict[str, Any]:
    from scrapcut_cli.evaluation.report import rows_to_records

    return dict(rows_to_records([row])[0])


if __name__ == "__main__":
    main()
