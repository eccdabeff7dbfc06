"""The path file (``scrapcut.path/v1`` JSON, docs/path-file.md) and its CSV and TUM exports.

Fixed keys are the ones docs/path-file.md lists (docs/path.schema.json); this module adds
``curve.spacing_m``, ``curve.info``, ``path.summary`` and a per-set-point ``surface_point`` (all
optional when reading). Floats are
written with Python's shortest round-trip repr, so a file read back gives the same numbers.

A set-point's ``flags`` are empty or name what the operator should look at: ``tilted`` (the
perpendicular torch would hit the observed piece; the pose is tilted within the bound and the
speed lowered for the longer cut), ``collision`` (no tilt within the bound is free; the pose
stays perpendicular), ``no_surface`` (too little observed surface around it, e.g. a gap in a
wire mesh; the normal is interpolated along the path), ``bridged_gap`` (no observed surface
under it: the curve bridges a hole or a mesh's gap there), ``low_support`` (less than half of the
stroke's band around it holds paint). Time stamps ``t_s`` start at the pierce
time: the torch dwells at the first set-point from 0 to ``t_s[0]``.

Confidence, per set-point when the fit estimated it (``fitting.stroke``): ``support`` (share 0-1
of the stroke's band around it that holds paint), ``frames`` (how many frames saw paint there),
``sigma_m`` (estimated lateral uncertainty, metres).
"""

from __future__ import annotations

import csv
import datetime
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli import __version__
from scrapcut_cli._io import atomic_path, read_text_input, write_text_atomic
from scrapcut_cli.errors import FileError, ToolpathError
from scrapcut_cli.fitting.curve import Curve, NurbsModel
from scrapcut_cli.geometry import polyline_length, quat_xyzw_to_matrix
from scrapcut_cli.toolpath.path import CuttingPath

SCHEMA = "scrapcut.path/v1"
CSV_COLUMNS = ("s", "x", "y", "z", "qx", "qy", "qz", "qw", "nx", "ny", "nz", "speed_m_s", "t_s")
#: Columns a path with confidence adds after :data:`CSV_COLUMNS` (flags as 0/1).
CONFIDENCE_COLUMNS = ("support", "frames", "sigma_m", "bridged_gap", "low_support")
#: Arrays in ``info`` dictionaries longer than this are left out of the file (e.g. a skeleton's
#: vertices): the file keeps diagnostics, not intermediate data.
MAX_INFO_ARRAY = 16


def path_to_dict(
    curve: Curve,
    path: CuttingPath,
    *,
    source: Mapping[str, Any],
    method_params: Mapping[str, Any],
    config: Mapping[str, Any],
    frame_id: str,
    created: str | None = None,
    calibration: Mapping[str, Any] | None = None,
    selection: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The path file as a JSON-ready dictionary.

    ``source``: path, sha256_first_mib, frames_used, frames_skipped of the recording.
    ``config``: every parameter used (``ScrapcutConfig.to_dict()``). ``created``: ISO-8601
    time stamp; default now (UTC) — pass a fixed one for byte-identical files.
    ``calibration``: the camera mount and clock offset the frames were posed with, when not
    the recording's own (``--calibration`` / ``--self-calibrate``); stored as ``calibration``.
    ``selection``: the line-selection report (the line, every rejected candidate); stored as
    ``selection``.
    """
    if created is None:
        created = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    setpoints = [
        {
            "s": float(path.arc_length[i]),
            "position": _floats(path.positions[i]),
            "orientation_xyzw": _floats(path.orientations_xyzw[i]),
            "normal": _floats(path.normals[i]),
            "speed_m_s": float(path.speed[i]),
            "t_s": float(path.time[i]),
            "flags": [str(f) for f in path.flags[i]],
            "surface_point": _floats(path.surface_points[i]),
            **({"segment": path.segments[i]} if path.segments else {}),
            **_confidence(path, i),
        }
        for i in range(len(path))
    ]
    return {
        "schema": SCHEMA,
        "tool_version": __version__,
        "created": created,
        "source": _jsonable(dict(source)),
        "frame_id": frame_id,
        "units": "m",
        "method": {"name": curve.method, "params": _jsonable(dict(method_params))},
        "curve": {
            "points": [_floats(p) for p in curve.points],
            "nurbs": None if curve.nurbs is None else curve.nurbs.to_dict(),
            "spacing_m": float(curve.spacing_m),
            "length_m": float(curve.length),
            "closed": bool(curve.closed),
            "info": _jsonable(dict(curve.info)),
        },
        "path": {
            "standoff_m": float(path.standoff_m),
            "spacing_m": float(path.spacing_m),
            "setpoints": setpoints,
            "summary": _jsonable(dict(path.info)),
        },
        "config": _jsonable(dict(config)),
        **({} if calibration is None else {"calibration": _jsonable(dict(calibration))}),
        **({} if selection is None else {"selection": _jsonable(dict(selection))}),
    }


def path_from_dict(data: Any) -> tuple[Curve, CuttingPath, dict[str, Any]]:
    """Curve, cutting path and the rest (schema, source, method, config...) of a path file.

    Validates the schema name, the fixed keys, array shapes and finiteness; raises ToolpathError
    naming the first bad key.
    """
    if not isinstance(data, dict):
        raise ToolpathError("path file: expected a JSON object at the top level")
    schema = data.get("schema")
    if schema != SCHEMA:
        raise ToolpathError(f"path file: schema is {schema!r}, this scrapcut reads {SCHEMA!r}")
    for key in ("source", "frame_id", "units", "method", "curve", "path"):
        if key not in data:
            raise ToolpathError(f"path file: missing key {key!r}")
    if data["units"] != "m":
        raise ToolpathError(f"path file: units must be 'm', got {data['units']!r}")
    method = _get(data, "method", dict)
    name = _get(method, "name", str, where="method")
    curve_d = _get(data, "curve", dict)
    points = _array(curve_d.get("points"), 3, "curve.points")
    if len(points) == 0:
        raise ToolpathError("path file: curve.points is empty")
    nurbs = None
    if curve_d.get("nurbs") is not None:
        try:
            nurbs = NurbsModel.from_dict(curve_d["nurbs"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ToolpathError(f"path file: bad curve.nurbs ({exc})") from None
    spacing = curve_d.get("spacing_m")
    if spacing is None:
        spacing = polyline_length(points) / max(len(points) - 1, 1)
    curve_info = curve_d.get("info") or {}
    closed = curve_d.get("closed", False)
    if not isinstance(closed, bool):
        raise ToolpathError("path file: curve.closed must be true or false")
    curve = Curve(
        points=points,
        method=name,
        nurbs=nurbs,
        spacing_m=_number(spacing, "curve.spacing_m"),
        info=dict(curve_info) if isinstance(curve_info, dict) else {},
        closed=closed,
    )

    path_d = _get(data, "path", dict)
    standoff = _number(path_d.get("standoff_m"), "path.standoff_m")
    path_spacing = _number(path_d.get("spacing_m"), "path.spacing_m")
    setpoints = _get(path_d, "setpoints", list, where="path")
    for i, sp in enumerate(setpoints):
        if not isinstance(sp, dict):
            raise ToolpathError(f"path file: path.setpoints[{i}] must be an object")
        for key in ("s", "position", "orientation_xyzw", "normal", "speed_m_s", "t_s", "flags"):
            if key not in sp:
                raise ToolpathError(f"path file: path.setpoints[{i}] lacks {key!r}")

    def column(key: str, width: int) -> NDArray[np.float64]:
        return _array([sp[key] for sp in setpoints], width, f"path.setpoints[*].{key}")

    positions = column("position", 3)
    orientations = column("orientation_xyzw", 4)
    norms = np.linalg.norm(orientations, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-6):
        i = int(np.argmax(np.abs(norms - 1.0)))
        raise ToolpathError(
            f"path file: path.setpoints[{i}].orientation_xyzw is not a unit quaternion"
        )
    normals = column("normal", 3)
    scalars = _array(
        [[sp["s"], sp["speed_m_s"], sp["t_s"]] for sp in setpoints], 3, "setpoint s/speed/t"
    )
    flags: list[list[str]] = []
    for i, sp in enumerate(setpoints):
        f = sp["flags"]
        if not isinstance(f, list) or not all(isinstance(x, str) for x in f):
            raise ToolpathError(f"path file: path.setpoints[{i}].flags must be a list of strings")
        flags.append(list(f))
    if all("surface_point" in sp for sp in setpoints):
        surface_points = column("surface_point", 3)
    else:
        # The jet hits the surface standoff metres along the torch z axis from the tip.
        z_axes = quat_xyzw_to_matrix(orientations)[:, :, 2] if len(setpoints) else positions
        surface_points = positions + standoff * z_axes
    segments = [sp.get("segment", "cut") for sp in setpoints]
    if not all(isinstance(g, str) for g in segments):
        raise ToolpathError("path file: path.setpoints[*].segment must be a string")
    summary = path_d.get("summary") or {}
    confidence = _read_confidence(setpoints)
    path = CuttingPath(
        positions=positions,
        orientations_xyzw=orientations,
        normals=normals,
        surface_points=surface_points,
        arc_length=scalars[:, 0].copy(),
        speed=scalars[:, 1].copy(),
        time=scalars[:, 2].copy(),
        flags=flags,
        standoff_m=standoff,
        spacing_m=path_spacing,
        info=dict(summary) if isinstance(summary, dict) else {},
        segments=segments if any(g != "cut" for g in segments) else [],
        **confidence,
    )
    meta = {k: v for k, v in data.items() if k not in ("curve", "path")}
    return curve, path, meta


def write_path_file(target: str | Path, data: Mapping[str, Any]) -> None:
    """Write a path dictionary as JSON, atomically (NaN/inf refused)."""
    try:
        text = json.dumps(data, indent=1, allow_nan=False)
    except ValueError as exc:
        raise ToolpathError(f"path file: {exc}") from None
    write_text_atomic(target, text + "\n")


def read_path_file(source: str | Path) -> tuple[Curve, CuttingPath, dict[str, Any]]:
    """Read and validate a path file (see :func:`path_from_dict`)."""
    source = Path(source)
    try:
        data = json.loads(read_text_input(source, "path file"))
    except FileError as exc:
        raise ToolpathError(str(exc)) from None
    except json.JSONDecodeError as exc:
        raise ToolpathError(f"cannot read path file {source}: {exc}") from None
    except RecursionError:  # json nests by recursion: 100,000 brackets exhaust the stack
        raise ToolpathError(f"cannot read path file {source}: JSON nested too deep") from None
    try:
        return path_from_dict(data)
    except ToolpathError as exc:
        raise ToolpathError(f"{source}: {exc}") from None


def write_path_csv(path: CuttingPath, out: str | Path, *, frame_id: str = "") -> None:
    """One row per set-point: ``s,x,y,z,qx,qy,qz,qw,nx,ny,nz,speed_m_s,t_s`` (SI units), then
    ``support,frames,sigma_m,bridged_gap,low_support`` when the path has confidence (frames a
    count, the two flags 0 or 1), then ``flags`` (all of the set-point's flags joined by
    ``;``, empty for a clean set-point); after one ``# frame_id: NAME`` line
    (``comment="#"`` in numpy/pandas skips it)."""
    table = np.column_stack(
        [
            path.arc_length,
            path.positions,
            path.orientations_xyzw,
            path.normals,
            path.speed,
            path.time,
        ]
    )
    rows = [[repr(float(v)) for v in row] for row in table]
    columns = list(CSV_COLUMNS)
    if path.sigma_m is not None and path.support is not None and path.frames is not None:
        columns += CONFIDENCE_COLUMNS
        for i, row in enumerate(rows):
            row += [
                repr(float(path.support[i])),
                str(int(path.frames[i])),
                repr(float(path.sigma_m[i])),
                str(int("bridged_gap" in path.flags[i])),
                str(int("low_support" in path.flags[i])),
            ]
    with atomic_path(out) as tmp, tmp.open("w", newline="", encoding="utf-8") as fh:
        fh.write(f"# frame_id: {frame_id}\n")
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow([*columns, "flags"])
        writer.writerows(
            [*row, ";".join(flags)] for row, flags in zip(rows, path.flags, strict=True)
        )


def write_path_tum(path: CuttingPath, out: str | Path, *, frame_id: str = "") -> None:
    """The torch tip poses in the TUM trajectory format, which ``evo_traj tum`` reads.

    One line per set-point, space-separated: ``t x y z qx qy qz qw`` — ``t`` the set-point's
    time along the cut (``t_s``, seconds, increasing), the position in metres and the
    orientation (torch frame: z into the surface, x along the travel) in ``frame_id``, named
    on a leading ``#`` line (TUM readers skip comments).
    """
    table = np.column_stack([path.time, path.positions, path.orientations_xyzw])
    lines = [f"# frame_id: {frame_id}", "# t x y z qx qy qz qw"]
    lines += [" ".join(repr(float(v)) for v in row) for row in table]
    write_text_atomic(out, "\n".join(lines) + "\n")


# --------------------------------------------------------------------------- helpers


def _confidence(path: CuttingPath, i: int) -> dict[str, Any]:
    """Set-point ``i``'s confidence keys (none when the path has no confidence)."""
    if path.sigma_m is None or path.support is None or path.frames is None:
        return {}
    return {
        "support": float(path.support[i]),
        "frames": int(path.frames[i]),
        "sigma_m": float(path.sigma_m[i]),
    }


def _read_confidence(setpoints: list[dict[str, Any]]) -> dict[str, Any]:
    """``support``, ``frames`` and ``sigma_m`` arrays when every set-point has them."""
    keys = ("support", "frames", "sigma_m")
    if not setpoints or not all(all(k in sp for k in keys) for sp in setpoints):
        return {}
    values = _array([[sp[k] for k in keys] for sp in setpoints], 3, "setpoint confidence")
    if np.any(values[:, 2] < 0.0) or np.any(values[:, 1] < 0.0):
        raise ToolpathError("path file: a set-point's sigma_m or frames is negative")
    return {
        "support": values[:, 0].copy(),
        "frames": values[:, 1].astype(np.int64),
        "sigma_m": values[:, 2].copy(),
    }


def _floats(values: Sequence[float] | NDArray[np.float64]) -> list[float]:
    return [float(v) for v in values]


def _jsonable(value: Any) -> Any:
    """JSON-safe copy of diagnostics: numpy scalars to Python, small arrays to lists,
    large arrays and non-finite floats left out (None)."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            converted = _jsonable(v)
            if converted is not _DROP:
                out[str(k)] = converted
        return out
    if isinstance(value, np.ndarray):
        if value.size > MAX_INFO_ARRAY:
            return _DROP
        return _jsonable(value.tolist())
    if isinstance(value, list | tuple):
        if len(value) > MAX_INFO_ARRAY and not all(isinstance(v, str) for v in value):
            return _DROP
        return [v for v in (_jsonable(v) for v in value) if v is not _DROP]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if value is None or isinstance(value, str | bool | int | float):
        return value
    if isinstance(value, Path):
        return str(value)
    return _DROP


_DROP = object()


def _get(data: dict[str, Any], key: str, kind: type, *, where: str = "") -> Any:
    name = f"{where}.{key}" if where else key
    if key not in data:
        raise ToolpathError(f"path file: missing key {name!r}")
    value = data[key]
    if not isinstance(value, kind):
        raise ToolpathError(f"path file: {name} must be a {kind.__name__}")
    return value


def _number(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ToolpathError(f"path file: {name} must be a finite number, got {value!r}")
    return float(value)


def _array(values: Any, width: int, name: str) -> NDArray[np.float64]:
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ToolpathError(f"path file: {name} must be rows of {width} numbers") from None
    if arr.size == 0:
        return np.zeros((0, width))
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ToolpathError(f"path file: {name} must be rows of {width} numbers")
    if not np.all(np.isfinite(arr)):
        raise ToolpathError(f"path file: {name} contains NaN or infinite values")
    return arr
