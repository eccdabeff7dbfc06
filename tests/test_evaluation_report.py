"""Tests of scrapcut_cli.evaluation.report: the paper's table, rows and the four renderers."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.evaluation.metrics import path_error
from scrapcut_cli.evaluation.report import (
    TABLE1_FIELDS,
    WORSE_MARK,
    ReportRow,
    load_paper_table,
    paper_summary,
    render_csv,
    render_json,
    render_markdown,
    rich_table,
    rows_to_records,
    sort_rows,
    worse_than_paper,
)

ROOT = Path(__file__).resolve().parents[1]
MM = 1e-3


def offset_row(obj: str, method: str, offset_mm: float, **params: float) -> ReportRow:
    """A row whose curve runs parallel to a 300 mm straight reference at ``offset_mm``."""
    reference = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0]])
    curve = reference + np.array([0.0, offset_mm * MM, 0.0])
    return ReportRow(
        object=obj,
        method=method,
        error=path_error(curve, reference),
        params=dict(params),
        source=f"{obj}_{method}.json",
        curve_points=curve,
        reference_points=reference,
    )


def test_bundled_paper_table_matches_the_fixture_and_the_paper() -> None:
    bundled = (ROOT / "scrapcut_cli" / "data" / "paper_table1.csv").read_bytes()
    assert (ROOT / "fixtures" / "paper_table1.csv").read_bytes() == bundled
    shared = ROOT.parent / "shared" / "reference" / "paper_table1.csv"
    if shared.exists():
        assert shared.read_bytes() == bundled
    table = load_paper_table()
    assert len(table) == 10
    assert {o for o, _ in table} == {"air_chamber", "basket", "cylinder", "i_beam", "t_piece"}
    cyl = table[("cylinder", "nurbs")]
    assert (cyl.mean_mm, cyl.sd_mm, cyl.min_mm, cyl.max_mm) == (3.01, 1.89, 0.30, 7.03)
    assert table[("i_beam", "nurbs")].max_mm == 37.23
    assert "20 mm" in table[("basket", "skeleton")].note


def test_paper_table_errors(tmp_path: Path) -> None:
    with pytest.raises(EvaluationError, match="cannot read the paper table"):
        load_paper_table(tmp_path / "missing.csv")
    bad = tmp_path / "bad.csv"
    bad.write_text("object,method,mean\ncylinder,nurbs,1\n")
    with pytest.raises(EvaluationError, match="expected columns"):
        load_paper_table(bad)
    bad.write_text("object,method,mean_mm,sd_mm,min_mm,max_mm\ncylinder,nurbs,x,1,1,1\n")
    with pytest.raises(EvaluationError, match="non-numeric"):
        load_paper_table(bad)


def test_worse_than_paper_compares_at_the_papers_precision() -> None:
    paper = load_paper_table()[("cylinder", "nurbs")]  # 3.01 1.89 0.30 7.03
    assert worse_than_paper(offset_row("cylinder", "nurbs", 3.012), paper) == ["min_mm"]
    assert worse_than_paper(offset_row("cylinder", "nurbs", 3.02), paper) == ["mean_mm", "min_mm"]
    assert worse_than_paper(offset_row("cylinder", "nurbs", 0.2), paper) == []
    failed = ReportRow("cylinder", "nurbs", None, failure="skeleton broken")
    assert worse_than_paper(failed, paper) == list(TABLE1_FIELDS)


def test_rows_sort_by_object_method_and_leaf_size() -> None:
    rows = [
        offset_row("t_piece", "nurbs", 1.0),
        offset_row("basket", "skeleton", 1.0, leaf_size_m=0.02),
        offset_row("basket", "skeleton", 1.0, leaf_size_m=0.005),
        offset_row("basket", "nurbs", 1.0),
    ]
    ordered = [(r.object, r.label) for r in sort_rows(rows)]
    assert ordered == [
        ("basket", "nurbs"),
        ("basket", "skeleton 5 mm"),
        ("basket", "skeleton 20 mm"),
        ("t_piece", "nurbs"),
    ]


def test_json_rows_have_the_fixed_keys_in_millimetres() -> None:
    rows = [
        offset_row("cylinder", "nurbs", 2.0),
        ReportRow("basket", "skeleton", None, failure="skeleton broken into 3 pieces"),
    ]
    data = json.loads(render_json(rows, paper=load_paper_table()))
    assert data["schema"] == "scrapcut.eval/v1" and data["tool_version"]
    records = data["rows"]
    assert [(r["object"], r["method"]) for r in records] == [
        ("basket", "skeleton"),
        ("cylinder", "nurbs"),
    ]
    basket, cylinder = records
    for key in ("object", "method", "mean_mm", "sd_mm", "min_mm", "max_mm", "coverage"):
        assert key in cylinder and key in basket
    assert cylinder["mean_mm"] == pytest.approx(2.0, abs=1e-9)
    assert cylinder["max_mm"] == pytest.approx(2.0, abs=1e-9)
    assert cylinder["coverage"] == 1.0
    assert cylinder["reference_length_mm"] == pytest.approx(300.0)
    assert cylinder["paper"]["mean_mm"] == 3.01
    assert cylinder["worse_than_paper"] == ["min_mm"]
    assert basket["mean_mm"] is None and basket["coverage"] is None
    assert basket["failure"] == "skeleton broken into 3 pieces"
    assert basket["worse_than_paper"] == list(TABLE1_FIELDS)
    # Without --paper the comparison keys are absent.
    assert "paper" not in rows_to_records(rows)[0]


def test_csv_round_trips_through_the_csv_module() -> None:
    rows = [offset_row("cylinder", "skeleton", 4.0, leaf_size_m=0.005)]
    parsed = list(csv.DictReader(io.StringIO(render_csv(rows, paper=load_paper_table()))))
    assert len(parsed) == 1
    (line,) = parsed
    assert float(line["mean_mm"]) == pytest.approx(4.0)
    assert float(line["leaf_size_mm"]) == pytest.approx(5.0)
    assert float(line["paper_mean_mm"]) == 3.10
    assert line["worse_than_paper"] == "mean_mm;min_mm"
    plain = list(csv.DictReader(io.StringIO(render_csv(rows))))
    assert "paper_mean_mm" not in plain[0]


def test_markdown_marks_exactly_the_figures_worse_than_the_paper() -> None:
    rows = [offset_row("i_beam", "nurbs", 5.0), offset_row("planar_box", "nurbs", 1.0)]
    text = render_markdown(rows, paper=load_paper_table())
    lines = [ln for ln in text.splitlines() if ln.startswith("| i_beam")]
    assert len(lines) == 1
    cells = [c.strip() for c in lines[0].strip("|").split("|")]
    # i_beam nurbs in the paper: 12.9 10.66 3.40 37.23 — only our min (5.00) is worse.
    assert cells[2:10] == ["5.00", "12.90", "0.00", "10.66", f"5.00 {WORSE_MARK}", "3.40",
                           "5.00", "37.23"]  # fmt: skip
    box = next(ln for ln in text.splitlines() if ln.startswith("| planar_box"))
    assert WORSE_MARK not in box and "—" in box  # no paper figures for planar_box
    assert "Worse than the paper on 1 of 4 shared figures: i_beam nurbs (min)." in text
    header = text.splitlines()[0]
    assert "Mean [mm]" in header and "Mean paper" in header and "Coverage" in header


def test_markdown_without_paper_has_no_paper_columns() -> None:
    text = render_markdown([offset_row("cylinder", "nurbs", 1.0)], title="Table I")
    assert text.startswith("### Table I")
    assert "paper" not in text.split("\n")[2]
    assert "| cylinder | nurbs | 1.00 | 0.00 | 1.00 | 1.00 | 100.0% |" in text


def test_paper_summary_when_all_better() -> None:
    rows = [offset_row("cylinder", "skeleton", 0.44)]
    assert paper_summary(rows, load_paper_table()) == (
        "All 4 shared Table I figures are at or below the paper's."
    )
    assert "No object" in paper_summary([offset_row("box", "nurbs", 1.0)], load_paper_table())


def test_rich_table_renders_every_row() -> None:
    rows = [offset_row("cylinder", "nurbs", 3.5), offset_row("cylinder", "skeleton", 1.0)]
    console = Console(file=io.StringIO(), width=250, color_system=None)
    console.print(rich_table(rows, paper=load_paper_table(), title="Table I"))
    text = console.file.getvalue()  # type: ignore[attr-defined]
    assert "Table I" in text
    assert f"3.50 {WORSE_MARK}" in text  # worse than the paper's 3.01 mean
    lines = text.splitlines()
    nurbs = next(i for i, ln in enumerate(lines) if "│ nurbs" in ln)
    # The paper's figures sit in the row right below ours.
    assert "paper" in lines[nurbs + 1] and "3.01" in lines[nurbs + 1] and "7.03" in lines[nurbs + 1]
    assert any("skeleton" in ln for ln in lines)
    assert "Worse than the paper on 3 of 8 shared figures" in text


def test_oracle_rows_are_labelled_in_every_rendering() -> None:
    from dataclasses import replace

    row = replace(offset_row("cylinder", "skeleton", 2.0, leaf_size_m=0.005), oracle_views=True)
    assert row.label == "skeleton 5 mm (oracle views)"
    assert "| cylinder | skeleton 5 mm (oracle views) |" in render_markdown([row])
    (record,) = json.loads(render_json([row]))["rows"]
    assert record["oracle_views"] is True and record["label"] == row.label
    (line,) = csv.DictReader(io.StringIO(render_csv([row])))
    assert line["oracle_views"] == "True"


def test_self_calibrated_rows_are_labelled_and_kept_apart_from_the_plain_ones() -> None:
    from dataclasses import replace

    from scrapcut_cli.evaluation.report import aggregate_records, aggregate_rows

    plain = [offset_row("cylinder", "nurbs", mm) for mm in (2.0, 3.0)]
    calibrated = [replace(offset_row("cylinder", "nurbs", mm), self_calibrated=True)
                  for mm in (0.5, 0.7)]  # fmt: skip
    assert calibrated[0].label == "nurbs, self-calibrated"
    oracle = replace(calibrated[0], oracle_views=True)
    assert oracle.label == "nurbs, self-calibrated (oracle views)"
    # The plain row first, then the self-calibrated one (Table I's order).
    assert [r.self_calibrated for r in sort_rows(calibrated[:1] + plain[:1])] == [False, True]
    markdown = render_markdown([plain[0], calibrated[0]], paper=load_paper_table())
    assert "| cylinder | nurbs | 2.00 |" in markdown
    assert "| cylinder | nurbs, self-calibrated | 0.50 |" in markdown
    records = json.loads(render_json([plain[0], calibrated[0]]))["rows"]
    assert [r.get("self_calibrated", False) for r in records] == [False, True]
    lines = list(csv.DictReader(io.StringIO(render_csv([plain[0], calibrated[0]]))))
    assert [line["self_calibrated"] for line in lines] == ["", "True"]
    assert "self_calibrated" not in render_csv(plain)  # no column for runs without them
    aggregates = aggregate_rows(plain + calibrated)
    assert [(a.label, a.runs) for a in aggregates] == [
        ("nurbs", 2),
        ("nurbs, self-calibrated", 2),
    ]
    assert [a.mean["mean_mm"] for a in aggregates] == pytest.approx([2.5, 0.6], abs=1e-9)
    assert [r.get("self_calibrated", False) for r in aggregate_records(aggregates)] == [
        False,
        True,
    ]


def test_aggregates_over_seeds_skip_failed_runs_and_give_t_intervals() -> None:
    from scrapcut_cli.evaluation.report import aggregate_records, aggregate_rows

    rows = [offset_row("cylinder", "nurbs", mm) for mm in (1.0, 2.0, 3.0, 4.0)]
    rows.append(ReportRow("cylinder", "nurbs", None, failure="no paint"))
    (agg,) = aggregate_rows(rows)
    assert (agg.runs, agg.failed) == (5, 1)
    assert agg.mean["mean_mm"] == pytest.approx(2.5, abs=1e-9)
    # SD of 1..4 is 1.291; t(0.975, 3 dof) = 3.182; half width 3.182 * 1.291 / 2 = 2.054.
    assert agg.half_width["mean_mm"] == pytest.approx(2.054, abs=1e-3)
    assert agg.interval_text("mean_mm") == "2.50 ± 2.05"
    assert agg.interval_text("coverage", percent=True) == "100.0 ± 0.0%"
    (record,) = aggregate_records([agg], paper=load_paper_table())
    assert record["worse_than_paper"] == ["min_mm"]  # 1 mm offsets and more: min 2.5 > 0.30
    assert record["notes"] == ["no paint"]


def test_marked_sections_are_replaced_or_refused() -> None:
    from scrapcut_cli.evaluation.report import replace_marked_section

    begin = "<!-- scrapcut:t begin (generated: do not edit by hand) -->"
    end = "<!-- scrapcut:t end -->"
    text = f"a\n{begin}\nold\n{end}\nb\n"
    assert replace_marked_section(text, "t", "new") == f"a\n{begin}\nnew\n{end}\nb\n"
    for bad in (f"a\n{end}\n{begin}\n", f"{begin}\n{begin}\n{end}\n", "no markers\n"):
        with pytest.raises(EvaluationError, match="expected one"):
            replace_marked_section(bad, "t", "new")
