"""Tests of scrapcut_cli.evaluation.sources: path files, CSV references, the eval recipe."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from scrapcut_cli.config import EvaluationConfig
from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.evaluation.sources import (
    evaluate_path_files,
    load_path_file,
    load_reference,
    read_reference_csv,
    resolve_source,
)

MM = 1e-3


def write_path_file(
    path: Path,
    curve: np.ndarray,
    *,
    method: str = "nurbs",
    params: dict[str, Any] | None = None,
    source: str | None = "scan.mcap",
) -> Path:
    """A minimal ``scrapcut.path/v1`` file (docs/path-file.md keys; no set-points needed here)."""
    data = {
        "schema": "scrapcut.path/v1",
        "source": {"path": source},
        "frame_id": "panda_link0",
        "units": "m",
        "method": {"name": method, "params": params or {}},
        "curve": {"points": np.asarray(curve).tolist()},
        "path": {"standoff_m": 0.008, "spacing_m": 0.005, "setpoints": []},
    }
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def write_reference_csv(path: Path, points: np.ndarray) -> Path:
    lines = ["x,y,z"] + [",".join(repr(float(v)) for v in p) for p in points]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


REFERENCE = np.column_stack([np.linspace(0.3, 0.6, 31), np.zeros(31), np.full(31, 0.1)])


def test_csv_reference_round_trip(tmp_path: Path) -> None:
    csv_path = write_reference_csv(tmp_path / "ref.csv", REFERENCE)
    np.testing.assert_array_equal(read_reference_csv(csv_path), REFERENCE)
    ref = load_reference(csv_path)
    assert ref.object is None and ref.origin == csv_path


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("a,b,c\n1,2,3\n4,5,6\n", "must start with the header x,y,z"),
        ("x,y,z\n1,2,3\n", "needs at least two rows"),
        ("x,y,z\n1,2,3\n4,five,6\n", "cannot read reference CSV"),
        ("x,y,z\n", "needs at least two rows"),  # no rows: an error, not a numpy warning
        ("x,y,z\n1,2,3\n4,5,6\n7,nan,9\n", r"1 row\(s\) with NaN or infinite .*line 4\)$"),
    ],
)
def test_bad_csv_references(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "ref.csv"
    path.write_text(text)
    with pytest.raises(EvaluationError, match=message):
        read_reference_csv(path)


def test_csv_reference_with_a_byte_order_mark(tmp_path: Path) -> None:
    # A spreadsheet's "CSV UTF-8" export starts with a BOM; the header is still x,y,z.
    path = write_reference_csv(tmp_path / "ref.csv", REFERENCE)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    np.testing.assert_array_equal(read_reference_csv(path), REFERENCE)


def test_missing_references(tmp_path: Path) -> None:
    with pytest.raises(EvaluationError, match="reference not found"):
        load_reference(tmp_path / "nothing.csv")
    with pytest.raises(EvaluationError, match="reference recording not found"):
        load_reference(tmp_path / "nothing.mcap")


def test_load_path_file_reads_curve_method_and_source(tmp_path: Path) -> None:
    path = write_path_file(
        tmp_path / "p.json", REFERENCE, method="skeleton", params={"leaf_size_m": 0.005}
    )
    pf = load_path_file(path)
    np.testing.assert_array_equal(pf.curve_points, REFERENCE)
    assert (pf.method, pf.params, pf.source, pf.frame_id) == (
        "skeleton",
        {"leaf_size_m": 0.005},
        "scan.mcap",
        "panda_link0",
    )


def test_bad_path_files(tmp_path: Path) -> None:
    with pytest.raises(EvaluationError, match="path file not found"):
        load_path_file(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(EvaluationError, match="cannot read path file"):
        load_path_file(bad)
    bad.write_text(json.dumps({"schema": "other/v2"}))
    with pytest.raises(EvaluationError, match=r"bad\.json: path file: schema is 'other/v2'"):
        load_path_file(bad)
    bad.write_text(json.dumps({"schema": "scrapcut.path/v1", "curve": {}}))
    with pytest.raises(EvaluationError, match=r"bad\.json: path file: missing key 'source'"):
        load_path_file(bad)
    write_path_file(bad, REFERENCE[:1])
    with pytest.raises(EvaluationError, match="at least two"):
        load_path_file(bad)


def test_resolve_source_tries_the_path_files_folder(tmp_path: Path) -> None:
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "scan.mcap").write_bytes(b"")
    pf = load_path_file(write_path_file(tmp_path / "runs" / "p.json", REFERENCE))
    assert resolve_source(pf) == tmp_path / "runs" / "scan.mcap"
    pf = load_path_file(write_path_file(tmp_path / "q.json", REFERENCE, source="gone.mcap"))
    with pytest.raises(EvaluationError, match=r"gone\.mcap was not found; pass --reference"):
        resolve_source(pf)
    pf = load_path_file(write_path_file(tmp_path / "r.json", REFERENCE, source=None))
    with pytest.raises(EvaluationError, match="names no source recording"):
        resolve_source(pf)


def test_evaluate_path_files_against_a_csv(tmp_path: Path) -> None:
    csv_path = write_reference_csv(tmp_path / "ref.csv", REFERENCE)
    a = write_path_file(tmp_path / "cyl_nurbs.json", REFERENCE + np.array([0, 2 * MM, 0]))
    b = write_path_file(
        tmp_path / "cyl_skel.json",
        REFERENCE + np.array([0, 0, 4 * MM]),
        method="skeleton",
        params={"leaf_size_m": 0.005},
    )
    rows = evaluate_path_files([a, b], reference=csv_path)
    assert [r.object for r in rows] == ["cyl_nurbs", "cyl_skel"]
    assert rows[0].error is not None and rows[1].error is not None
    assert rows[0].error.mean_m == pytest.approx(2 * MM, abs=1e-12)
    assert rows[1].error.mean_m == pytest.approx(4 * MM, abs=1e-12)
    assert rows[1].leaf_size_m == 0.005
    assert rows[1].source == str(b)
    strict = EvaluationConfig(coverage_threshold_m=3 * MM)
    rows = evaluate_path_files([a, b], reference=csv_path, config=strict)
    assert [r.error.coverage for r in rows if r.error] == [1.0, 0.0]


def test_evaluate_without_any_reference_names_the_problem(tmp_path: Path) -> None:
    a = write_path_file(tmp_path / "a.json", REFERENCE, source="nowhere.mcap")
    with pytest.raises(EvaluationError, match=r"nowhere\.mcap was not found"):
        evaluate_path_files([a])
    with pytest.raises(EvaluationError, match="no path files"):
        evaluate_path_files([])


def test_reads_a_path_file_written_by_the_tool_path(tmp_path: Path) -> None:
    from scrapcut_cli.fitting.curve import Curve
    from scrapcut_cli.toolpath.path import CuttingPath
    from scrapcut_cli.toolpath.pathfile import path_to_dict, write_path_file

    curve = Curve(points=REFERENCE + np.array([0, 1 * MM, 0]), method="skeleton")
    n = 4
    cutting = CuttingPath(
        positions=REFERENCE[:n] + np.array([0, 0, 0.008]),
        orientations_xyzw=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        normals=np.tile([0.0, 0.0, 1.0], (n, 1)),
        surface_points=REFERENCE[:n],
        arc_length=np.arange(n) * 0.01,
        speed=np.full(n, 0.005),
        time=np.arange(n) * 2.0,
        flags=[[] for _ in range(n)],
        standoff_m=0.008,
        spacing_m=0.01,
    )
    data = path_to_dict(
        curve,
        cutting,
        source={"path": "scan.mcap"},
        method_params={"leaf_size_m": 0.02},
        config={},
        frame_id="panda_link0",
        created="2024-01-01T00:00:00+00:00",
    )
    write_path_file(tmp_path / "p.json", data)
    pf = load_path_file(tmp_path / "p.json")
    np.testing.assert_array_equal(pf.curve_points, curve.points)
    assert (pf.method, pf.params, pf.source) == ("skeleton", {"leaf_size_m": 0.02}, "scan.mcap")
    csv_path = write_reference_csv(tmp_path / "ref.csv", REFERENCE)
    (row,) = evaluate_path_files([tmp_path / "p.json"], reference=csv_path)
    assert row.error is not None and row.error.mean_m == pytest.approx(1 * MM, abs=1e-12)
    assert row.label == "skeleton 20 mm"


def write_reference_recording(path: Path, points: np.ndarray, *, obj: str | None) -> Path:
    """A tiny MCAP holding only /scrapcut/reference (and the simulator's metadata record)."""
    from scrapcut_cli.recording.writer import McapWriter

    with McapWriter(path) as writer:
        if obj is not None:
            writer.add_metadata("scrapcut", {"object": obj, "paint": "orange"})
        writer.write_path("/scrapcut/reference", 1_000_000_000, "panda_link0", points)
    return path


def test_reference_from_a_recording_names_the_object(tmp_path: Path) -> None:
    rec = write_reference_recording(tmp_path / "scan.mcap", REFERENCE, obj="i_beam")
    ref = load_reference(rec)
    np.testing.assert_allclose(ref.points, REFERENCE, atol=1e-12)
    assert ref.object == "i_beam"
    # The default: the recording named in the path file, found beside it.
    a = write_path_file(tmp_path / "a.json", REFERENCE + np.array([0, 0, 2 * MM]))
    b = write_path_file(tmp_path / "b.json", REFERENCE, method="skeleton")
    rows = evaluate_path_files([a, b])
    assert [(r.object, r.method) for r in rows] == [("i_beam", "nurbs"), ("i_beam", "skeleton")]
    assert rows[0].error is not None and rows[0].error.mean_m == pytest.approx(2 * MM, abs=1e-9)


def test_recording_without_reference(tmp_path: Path) -> None:
    from scrapcut_cli.recording.writer import McapWriter

    rec = tmp_path / "real.mcap"
    with McapWriter(rec) as writer:
        writer.write_string("/chatter", 1, "no reference here")
    with pytest.raises(EvaluationError, match="has no /scrapcut/reference; pass --reference"):
        load_reference(rec)
