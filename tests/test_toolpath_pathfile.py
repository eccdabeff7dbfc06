"""The path file (scrapcut.path/v1): schema keys, exact round trip, validation, CSV export."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import arc_on_cylinder, cylinder_surface

from scrapcut_cli.config import ScrapcutConfig, ToolpathConfig
from scrapcut_cli.errors import ToolpathError
from scrapcut_cli.fitting.curve import Curve, NurbsModel
from scrapcut_cli.toolpath.path import CuttingPath
from scrapcut_cli.toolpath.pathfile import (
    CSV_COLUMNS,
    SCHEMA,
    path_from_dict,
    path_to_dict,
    read_path_file,
    write_path_csv,
    write_path_file,
)
from scrapcut_cli.toolpath.setpoints import make_cutting_path

SOURCE = {"path": "rec.mcap", "sha256_first_mib": "ab" * 32, "frames_used": 12, "frames_skipped": 1}


def _example() -> tuple[Curve, CuttingPath]:
    points, _ = arc_on_cylinder(radius=0.08, angle=np.pi / 2, n=200)
    surface, viewpoints = cylinder_surface(0.08, angle=np.pi / 2, seed=0)
    nurbs = NurbsModel(
        degree=3,
        knots=np.array([0, 0, 0, 0, 0.5, 1, 1, 1, 1], dtype=float),
        control_points=points[[0, 40, 80, 120, 199]],
        weights=np.ones(5),
    )
    curve = Curve(
        points, "nurbs", nurbs=nurbs, spacing_m=0.001,
        info={"rms_m": np.float64(0.0004), "iterations": np.int64(7), "big": np.zeros((500, 3))},
    )  # fmt: skip
    path = make_cutting_path(curve, surface, viewpoints, config=ToolpathConfig())
    path.flags[3].append("tilted")
    return curve, path


def _dict(created: str = "2024-01-01T00:00:00+00:00") -> dict[str, Any]:
    curve, path = _example()
    return path_to_dict(
        curve,
        path,
        source=SOURCE,
        method_params={"smoothness": 1.0, "control_points": None},
        config=ScrapcutConfig().to_dict(),
        frame_id="panda_link0",
        created=created,
    )


def test_schema_keys_are_the_design_ones() -> None:
    data = _dict()
    assert data["schema"] == SCHEMA == "scrapcut.path/v1"
    fixed = {"schema", "tool_version", "created", "source", "frame_id", "units", "method"}
    assert fixed | {"curve", "path", "config"} <= set(data)
    assert set(data["source"]) >= {"path", "sha256_first_mib", "frames_used", "frames_skipped"}
    assert data["frame_id"] == "panda_link0" and data["units"] == "m"
    assert data["method"] == {
        "name": "nurbs",
        "params": {"smoothness": 1.0, "control_points": None},
    }
    assert set(data["curve"]["nurbs"]) == {"degree", "knots", "control_points", "weights"}
    assert {"standoff_m", "spacing_m", "setpoints"} <= set(data["path"])
    sp = data["path"]["setpoints"][3]
    assert {"s", "position", "orientation_xyzw", "normal", "speed_m_s", "t_s", "flags"} <= set(sp)
    assert sp["flags"] == ["tilted"]
    assert data["config"]["toolpath"]["standoff_m"] == 0.008
    # Diagnostics: numpy scalars become plain numbers, bulky arrays stay out of the file.
    assert data["curve"]["info"] == {"rms_m": 0.0004, "iterations": 7}
    json.dumps(data, allow_nan=False)


def test_round_trip_is_exact(tmp_path: Path) -> None:
    curve, path = _example()
    target = tmp_path / "out" / "path.json"
    write_path_file(target, _dict())
    curve2, path2, meta = read_path_file(target)
    np.testing.assert_array_equal(curve2.points, curve.points)
    assert curve2.method == "nurbs" and curve2.spacing_m == curve.spacing_m
    assert curve.nurbs is not None and curve2.nurbs is not None
    np.testing.assert_array_equal(curve2.nurbs.knots, curve.nurbs.knots)
    np.testing.assert_array_equal(curve2.nurbs.control_points, curve.nurbs.control_points)
    for field in ("positions", "orientations_xyzw", "normals", "surface_points"):
        np.testing.assert_array_equal(getattr(path2, field), getattr(path, field))
    for field in ("arc_length", "speed", "time"):
        np.testing.assert_array_equal(getattr(path2, field), getattr(path, field))
    assert path2.flags == path.flags
    assert (path2.standoff_m, path2.spacing_m) == (path.standoff_m, path.spacing_m)
    assert path2.info["setpoints"] == len(path)
    assert meta["source"] == SOURCE and meta["frame_id"] == "panda_link0"
    assert meta["config"] == ScrapcutConfig().to_dict()
    assert sorted(p.name for p in target.parent.iterdir()) == ["path.json"]  # no temp left


def test_same_inputs_and_time_stamp_give_the_same_bytes(tmp_path: Path) -> None:
    write_path_file(tmp_path / "a.json", _dict())
    write_path_file(tmp_path / "b.json", _dict())
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


def test_skeleton_curve_without_nurbs_and_old_files_without_surface_points() -> None:
    data = _dict()
    data["curve"]["nurbs"] = None
    del data["curve"]["spacing_m"]
    for sp in data["path"]["setpoints"]:
        del sp["surface_point"]
    curve, path, _ = path_from_dict(data)
    assert curve.nurbs is None
    assert curve.spacing_m == pytest.approx(curve.length / (len(curve.points) - 1))
    _, original = _example()
    # Derived from the pose: standoff metres along the torch z axis from the tip.
    np.testing.assert_allclose(path.surface_points, original.surface_points, atol=1e-12)


def _broken(edit: str) -> dict[str, Any]:
    data = _dict()
    sp = data["path"]["setpoints"]
    if edit == "schema":
        data["schema"] = "scrapcut.path/v0"
    elif edit == "units":
        data["units"] = "mm"
    elif edit == "missing":
        del data["frame_id"]
    elif edit == "points":
        data["curve"]["points"][2] = [0.0, 1.0]
    elif edit == "quaternion":
        sp[5]["orientation_xyzw"] = [0.0, 0.0, 0.0, 2.0]
    elif edit == "setpoint_key":
        del sp[1]["t_s"]
    elif edit == "flags":
        sp[0]["flags"] = "tilted"
    elif edit == "standoff":
        data["path"]["standoff_m"] = "8mm"
    elif edit == "nurbs":
        data["curve"]["nurbs"]["knots"] = [0.0, 1.0]
    return data


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ("schema", "schema is 'scrapcut.path/v0', this scrapcut reads 'scrapcut.path/v1'"),
        ("units", "units must be 'm'"),
        ("missing", "missing key 'frame_id'"),
        ("points", "curve.points must be rows of 3 numbers"),
        ("quaternion", r"setpoints\[5\].orientation_xyzw is not a unit quaternion"),
        ("setpoint_key", r"setpoints\[1\] lacks 't_s'"),
        ("flags", r"setpoints\[0\].flags must be a list of strings"),
        ("standoff", "path.standoff_m must be a finite number"),
        ("nurbs", "bad curve.nurbs"),
    ],
)
def test_bad_files_raise_one_line_naming_the_key(edit: str, message: str) -> None:
    with pytest.raises(ToolpathError, match=message) as info:
        path_from_dict(_broken(edit))
    assert "\n" not in str(info.value)


def test_read_errors(tmp_path: Path) -> None:
    with pytest.raises(ToolpathError, match="path file not found"):
        read_path_file(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ToolpathError, match="cannot read path file"):
        read_path_file(bad)
    bad.write_text("[1, 2]")
    with pytest.raises(ToolpathError, match=r"bad\.json: path file: expected a JSON object"):
        read_path_file(bad)


def test_nan_is_refused_and_leaves_no_file(tmp_path: Path) -> None:
    data = _dict()
    data["path"]["setpoints"][0]["t_s"] = float("nan")
    with pytest.raises(ToolpathError, match="path file"):
        write_path_file(tmp_path / "p.json", data)
    assert list(tmp_path.iterdir()) == []


def test_csv_export(tmp_path: Path) -> None:
    _, path = _example()
    target = tmp_path / "path.csv"
    write_path_csv(path, target, frame_id="panda_link0")
    with target.open(newline="") as fh:
        assert fh.readline() == "# frame_id: panda_link0\n"
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == (*CSV_COLUMNS, "flags")
    assert ",".join(rows[0]) == "s,x,y,z,qx,qy,qz,qw,nx,ny,nz,speed_m_s,t_s,flags"  # docs/
    assert [r[13] for r in rows[1:]] == [";".join(f) for f in path.flags]
    values = np.array([r[:13] for r in rows[1:]], dtype=float)
    assert values.shape == (len(path), 13)
    np.testing.assert_array_equal(values[:, 0], path.arc_length)
    np.testing.assert_array_equal(values[:, 1:4], path.positions)
    np.testing.assert_array_equal(values[:, 4:8], path.orientations_xyzw)
    np.testing.assert_array_equal(values[:, 8:11], path.normals)
    np.testing.assert_array_equal(values[:, 11], path.speed)
    np.testing.assert_array_equal(values[:, 12], path.time)


def _with_confidence() -> tuple[Curve, CuttingPath]:
    """The example curve with a confidence: a 'hole' over its second quarter."""
    from dataclasses import replace

    from scrapcut_cli.fitting.curve import CurveConfidence

    curve, _ = _example()
    n = len(curve.points)
    hole = (np.arange(n) >= n // 4) & (np.arange(n) < n // 2)
    confidence = CurveConfidence(
        support=np.where(hole, 0.1, 0.9),
        frames=np.where(hole, 0, 4).astype(np.int64),
        sigma_m=np.where(hole, 0.002, 0.0005) + 1e-6 * np.arange(n),
        bridged_gap=hole,
        low_support=hole,
    )
    curve = replace(curve, confidence=confidence)
    surface, viewpoints = cylinder_surface(0.08, angle=np.pi / 2, seed=0)
    return curve, make_cutting_path(curve, surface, viewpoints, config=ToolpathConfig())


def test_confidence_reaches_set_points_file_and_csv(tmp_path: Path) -> None:
    curve, path = _with_confidence()
    assert path.sigma_m is not None and path.support is not None and path.frames is not None
    # Set-points take the confidence of the curve where they sit.
    s = np.linspace(0.0, 1.0, len(path)) * path.arc_length[-1] / curve.length
    hole = (s > 0.27) & (s < 0.48)
    solid = (s < 0.22) | (s > 0.53)
    flags = np.array(["bridged_gap" in f for f in path.flags])
    low = np.array(["low_support" in f for f in path.flags])
    assert flags[hole].all() and not flags[solid].any() and np.array_equal(flags, low)
    assert np.all(path.sigma_m[hole] > 0.0019) and np.all(path.sigma_m[solid] < 0.0008)
    assert np.all(path.frames[hole] == 0) and np.all(path.frames[solid] == 4)
    assert path.info["bridged_gap"] == int(flags.sum())
    data = path_to_dict(
        curve, path, source=SOURCE, method_params={}, config={}, frame_id="panda_link0",
        created="2024-01-01T00:00:00+00:00",
    )  # fmt: skip
    sp = data["path"]["setpoints"][0]
    assert {"support", "frames", "sigma_m"} <= set(sp) and isinstance(sp["frames"], int)
    write_path_file(tmp_path / "p.json", data)
    _, back, _ = read_path_file(tmp_path / "p.json")
    assert back.sigma_m is not None and back.frames is not None and back.support is not None
    np.testing.assert_array_equal(back.sigma_m, path.sigma_m)
    np.testing.assert_array_equal(back.frames, path.frames)
    np.testing.assert_array_equal(back.support, path.support)
    assert back.flags == path.flags
    target = tmp_path / "path.csv"
    write_path_csv(path, target)
    values = np.genfromtxt(target, delimiter=",", comments="#", skip_header=2)[:, :-1]
    with target.open(newline="") as fh:
        rows = list(csv.reader(fh))[1:]
    assert rows[0][-6:] == ["support", "frames", "sigma_m", "bridged_gap", "low_support", "flags"]
    assert [r[-1] for r in rows[1:]] == [";".join(f) for f in path.flags]
    np.testing.assert_array_equal(values[:, 15], path.sigma_m)
    np.testing.assert_array_equal(values[:, 16].astype(bool), flags)


def test_a_file_without_confidence_reads_without_it_and_bad_sigma_is_refused() -> None:
    data = _dict()
    _, path, _ = path_from_dict(data)
    assert path.sigma_m is None and path.support is None and path.frames is None
    curve, with_conf = _with_confidence()
    data = path_to_dict(curve, with_conf, source=SOURCE, method_params={}, config={},
                        frame_id="panda_link0")  # fmt: skip
    data["path"]["setpoints"][2]["sigma_m"] = -0.001
    with pytest.raises(ToolpathError, match="sigma_m"):
        path_from_dict(data)
