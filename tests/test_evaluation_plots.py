"""Tests of scrapcut_cli.evaluation.plots: which figures are written, and that they are PNGs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.evaluation.metrics import path_error
from scrapcut_cli.evaluation.plots import plot_leaf_sweep, write_plots
from scrapcut_cli.evaluation.report import ReportRow

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def arc_rows(obj: str, leaves: tuple[float, ...], *, seed: int = 0) -> list[ReportRow]:
    """NURBS plus one skeleton row per leaf size, noisy copies of a 3-D arc (seeded)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, np.pi, 300)
    reference = np.column_stack([0.5 + 0.1 * np.cos(t), 0.1 * np.sin(t), 0.2 + 0.02 * t])
    rows = []
    for method, leaf in [("nurbs", None), *(("skeleton", leaf) for leaf in leaves)]:
        curve = reference + rng.normal(scale=0.002 if leaf is None else leaf / 3, size=(300, 3))
        rows.append(
            ReportRow(
                obj,
                method,
                path_error(curve, reference),
                params={} if leaf is None else {"leaf_size_m": leaf},
                curve_points=curve,
                reference_points=reference,
            )
        )
    return rows


def test_write_plots_makes_one_set_per_object(tmp_path: Path) -> None:
    rows = arc_rows("basket", (0.005, 0.01, 0.02)) + arc_rows("cylinder", (0.005,), seed=1)
    rows.append(ReportRow("basket", "skeleton", None, params={"leaf_size_m": 0.003}))
    written = write_plots(rows, tmp_path / "plots")
    names = sorted(p.name for p in written)
    assert names == [
        "error_along_basket.png",
        "error_along_cylinder.png",
        "leaf_sweep_basket.png",  # only the basket has two or more leaf sizes
        "paths_basket.png",
        "paths_cylinder.png",
    ]
    for path in written:
        data = path.read_bytes()
        assert data.startswith(PNG_MAGIC)
        assert len(data) > 10_000  # a real figure, not an empty canvas
    assert not list((tmp_path / "plots").glob("*.tmp"))


def test_same_rows_give_identical_png_bytes(tmp_path: Path) -> None:
    a = write_plots(arc_rows("cylinder", (0.005, 0.01)), tmp_path / "a")
    b = write_plots(arc_rows("cylinder", (0.005, 0.01)), tmp_path / "b")
    for pa, pb in zip(a, b, strict=True):
        assert pa.read_bytes() == pb.read_bytes()


def test_failed_rows_only_write_no_error_plot(tmp_path: Path) -> None:
    rows = [ReportRow("basket", "skeleton", None, failure="broken")]
    assert write_plots(rows, tmp_path) == []


def test_leaf_sweep_needs_leaf_sizes(tmp_path: Path) -> None:
    rows = arc_rows("cylinder", ())
    with pytest.raises(EvaluationError, match="needs rows with a leaf size"):
        plot_leaf_sweep(rows, tmp_path / "x.png", title="x")
    assert not (tmp_path / "x.png").exists()
