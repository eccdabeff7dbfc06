"""The oxy-fuel cutting look-up table: torch travel speed and pierce time by material and thickness.

The paper converts the set-points into a trajectory "by imposing tool speed constraints based on
the scrap piece's properties ... the robot can use a look-up table". The bundled table
(``scrapcut_cli/data/cutting_speeds.csv``, a copy in ``fixtures/``) cites the charts its rows come
from in its header comment rows; ``load_speed_table(path)`` reads any file of the same shape.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scrapcut_cli._io import read_text_input
from scrapcut_cli.errors import FileError, ToolpathError

#: Package-data name of the bundled table.
BUNDLED_TABLE = "cutting_speeds.csv"

_COLUMNS = ("material", "thickness_mm", "speed_mm_min", "pierce_s")


@dataclass(frozen=True, eq=False)
class MaterialChart:
    """One material's chart: rows sorted by thickness.

    Attributes
    ----------
    thickness_mm : (K,) float64, millimetres, strictly increasing
    speed_m_s : (K,) float64, torch travel speed in m/s
    pierce_s : (K,) float64, preheat plus pierce dwell at the start of a cut, seconds
    fuel : str, preheat fuel gas ("acetylene", "propane", ...)
    """

    thickness_mm: NDArray[np.float64]
    speed_m_s: NDArray[np.float64]
    pierce_s: NDArray[np.float64]
    fuel: str


@dataclass(frozen=True, eq=False)
class SpeedTable:
    """Cutting speed and pierce time by material, interpolated linearly in plate thickness."""

    charts: dict[str, MaterialChart]
    source: str

    @property
    def materials(self) -> list[str]:
        """Material keys, sorted."""
        return sorted(self.charts)

    def chart(self, material: str) -> MaterialChart:
        """The chart of ``material``; unknown names raise ToolpathError listing the known ones."""
        try:
            return self.charts[material]
        except KeyError:
            raise ToolpathError(
                f"unknown material {material!r}; the speed table {self.source} has: "
                f"{', '.join(self.materials)}"
            ) from None

    def thickness_range_mm(self, material: str) -> tuple[float, float]:
        """(thinnest, thickest) plate of ``material``'s chart, millimetres."""
        t = self.chart(material).thickness_mm
        return float(t[0]), float(t[-1])

    def speeds(
        self, material: str, thickness_mm: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Travel speeds (m/s) and pierce times (s) for an array of thicknesses (mm).

        Linear interpolation between chart rows; a thickness outside the chart raises
        ToolpathError (extrapolating a cutting chart is guesswork).
        """
        chart = self.chart(material)
        t = np.asarray(thickness_mm, dtype=np.float64)
        lo, hi = float(chart.thickness_mm[0]), float(chart.thickness_mm[-1])
        if t.size and (not np.all(np.isfinite(t)) or t.min() < lo or t.max() > hi):
            bad = t[~((t >= lo) & (t <= hi))].ravel()[0]
            raise ToolpathError(
                f"thickness {bad:g} mm is outside the {material} chart ({lo:g}-{hi:g} mm)"
            )
        speed = np.interp(t, chart.thickness_mm, chart.speed_m_s)
        pierce = np.interp(t, chart.thickness_mm, chart.pierce_s)
        return np.asarray(speed, dtype=np.float64), np.asarray(pierce, dtype=np.float64)

    def lookup(self, material: str, thickness_mm: float) -> tuple[float, float]:
        """(travel speed in m/s, pierce time in s) for one plate thickness in millimetres."""
        speed, pierce = self.speeds(material, np.array([thickness_mm], dtype=np.float64))
        return float(speed[0]), float(pierce[0])


def load_speed_table(path: str | Path | None = None) -> SpeedTable:
    """Read a cutting-speed table; ``None`` reads the bundled one.

    The file is CSV with ``#`` comment rows and the columns ``material, thickness_mm,
    speed_mm_min, pierce_s`` (more columns allowed; ``fuel`` is kept). Speeds are converted to
    m/s. Raises ToolpathError naming the file and row when it is unreadable or inconsistent.
    """
    if path is None:
        source = f"(bundled {BUNDLED_TABLE})"
        text = resources.files("scrapcut_cli").joinpath("data", BUNDLED_TABLE).read_text("utf-8")
    else:
        source = str(path)
        try:
            text = read_text_input(path, "speed table", max_bytes=1 << 24)
        except FileError as exc:
            raise ToolpathError(str(exc)) from None
    return parse_speed_table(text, source=source)


def parse_speed_table(text: str, *, source: str = "(text)") -> SpeedTable:
    """Parse the CSV text of a speed table (see :func:`load_speed_table`)."""
    lines = [
        line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")
    ]
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    missing = [c for c in _COLUMNS if c not in (reader.fieldnames or [])]
    if missing:
        raise ToolpathError(f"speed table {source} lacks column(s): {', '.join(missing)}")
    rows: dict[str, list[tuple[float, float, float]]] = {}
    fuels: dict[str, str] = {}
    for number, row in enumerate(reader, start=1):
        material = (row["material"] or "").strip()
        try:
            values = tuple(float(row[c]) for c in _COLUMNS[1:])
        except (TypeError, ValueError):
            raise ToolpathError(
                f"speed table {source}: data row {number} ({material}) has a non-numeric value"
            ) from None
        thickness, speed, pierce = values
        if not material or thickness <= 0 or speed <= 0 or pierce < 0:
            raise ToolpathError(
                f"speed table {source}: data row {number} needs a material, thickness > 0, "
                f"speed > 0 and pierce >= 0"
            )
        rows.setdefault(material, []).append((thickness, speed, pierce))
        fuels.setdefault(material, (row.get("fuel") or "").strip())
    if not rows:
        raise ToolpathError(f"speed table {source} has no rows")
    charts: dict[str, MaterialChart] = {}
    for material, entries in rows.items():
        data = np.array(sorted(entries), dtype=np.float64)
        if np.any(np.diff(data[:, 0]) <= 0):
            raise ToolpathError(f"speed table {source}: {material} lists a thickness twice")
        charts[material] = MaterialChart(
            thickness_mm=data[:, 0],
            speed_m_s=data[:, 1] / 1000.0 / 60.0,
            pierce_s=data[:, 2],
            fuel=fuels[material],
        )
    return SpeedTable(charts=charts, source=source)
