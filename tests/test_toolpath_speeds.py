"""The oxy-fuel cutting look-up table: bundled data, interpolation, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scrapcut_cli.errors import ToolpathError
from scrapcut_cli.toolpath.speeds import load_speed_table, parse_speed_table

ROOT = Path(__file__).resolve().parents[1]
MM_MIN = 1.0 / 1000.0 / 60.0  # 1 mm/min in m/s


def test_package_copy_and_fixture_are_identical() -> None:
    package = ROOT / "scrapcut_cli" / "data" / "cutting_speeds.csv"
    fixture = ROOT / "fixtures" / "cutting_speeds.csv"
    assert package.read_bytes() == fixture.read_bytes()
    assert load_speed_table(fixture).charts.keys() == load_speed_table().charts.keys()


def test_bundled_table_cites_its_sources_and_has_several_materials() -> None:
    text = (ROOT / "fixtures" / "cutting_speeds.csv").read_text()
    header = [line for line in text.splitlines() if line.startswith("#")]
    assert any("Victor" in line for line in header) and any("Harris" in line for line in header)
    table = load_speed_table()
    assert {"mild_steel", "mild_steel_propane", "low_alloy_steel"} <= set(table.materials)
    assert table.chart("mild_steel").fuel == "acetylene"
    assert table.chart("mild_steel_propane").fuel == "propane"


@pytest.mark.parametrize("material", ["mild_steel", "mild_steel_propane", "low_alloy_steel"])
def test_charts_are_physically_ordered(material: str) -> None:
    chart = load_speed_table().chart(material)
    assert np.all(np.diff(chart.thickness_mm) > 0)
    assert np.all(np.diff(chart.speed_m_s) < 0)  # thicker plate: slower
    assert np.all(np.diff(chart.pierce_s) > 0)  # thicker plate: longer preheat


def test_rows_are_returned_exactly_and_interpolated_linearly_between() -> None:
    table = load_speed_table()
    assert table.lookup("mild_steel", 25.4) == (pytest.approx(395 * MM_MIN), 12.0)
    speed, pierce = table.lookup("mild_steel", 11.1)  # half way between 9.5 and 12.7 mm
    assert speed == pytest.approx(0.5 * (560 + 485) * MM_MIN)
    assert pierce == pytest.approx(7.0)
    speeds, pierces = table.speeds("mild_steel", [3.2, 304.8])
    np.testing.assert_allclose(speeds, [635 * MM_MIN, 90 * MM_MIN])
    np.testing.assert_allclose(pierces, [4.0, 70.0])


def test_derived_low_alloy_rows_follow_their_stated_rule() -> None:
    table = load_speed_table()
    mild, alloy = table.chart("mild_steel"), table.chart("low_alloy_steel")
    np.testing.assert_array_equal(alloy.thickness_mm, mild.thickness_mm)
    # speed x 0.85 rounded to 5 mm/min, pierce x 1.5 (the file header says so)
    np.testing.assert_allclose(alloy.speed_m_s, 0.85 * mild.speed_m_s, atol=2.5 * MM_MIN)
    np.testing.assert_allclose(alloy.pierce_s, 1.5 * mild.pierce_s)


def test_unknown_material_lists_the_known_ones() -> None:
    with pytest.raises(ToolpathError, match=r"unknown material 'steel'.*low_alloy_steel, mild"):
        load_speed_table().lookup("steel", 10.0)


@pytest.mark.parametrize("thickness", [1.0, 400.0, float("nan")])
def test_thickness_outside_the_chart_is_refused(thickness: float) -> None:
    with pytest.raises(ToolpathError, match=r"outside the mild_steel chart \(3.2-304.8 mm\)"):
        load_speed_table().lookup("mild_steel", thickness)


def test_custom_table_file(tmp_path: Path) -> None:
    path = tmp_path / "speeds.csv"
    path.write_text(
        "# my torch\nmaterial,thickness_mm,speed_mm_min,pierce_s\nx,10,600,3\nx,5,900,2\n"
    )
    table = load_speed_table(path)
    assert table.materials == ["x"]
    assert table.lookup("x", 7.5) == (pytest.approx(750 * MM_MIN), pytest.approx(2.5))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("material,thickness_mm,speed_mm_min\nx,1,2\n", "lacks column.*pierce_s"),
        ("material,thickness_mm,speed_mm_min,pierce_s\nx,1,fast,2\n", "row 1 .*non-numeric"),
        ("material,thickness_mm,speed_mm_min,pierce_s\nx,1,-5,2\n", "speed > 0"),
        (
            "material,thickness_mm,speed_mm_min,pierce_s\nx,1,5,2\nx,1,4,2\n",
            "x lists a thickness twice",
        ),
        ("material,thickness_mm,speed_mm_min,pierce_s\n", "no rows"),
    ],
)
def test_bad_tables_raise_one_clear_line(text: str, message: str) -> None:
    with pytest.raises(ToolpathError, match=message):
        parse_speed_table(text)


def test_missing_table_file(tmp_path: Path) -> None:
    with pytest.raises(ToolpathError, match="speed table not found"):
        load_speed_table(tmp_path / "nope.csv")
