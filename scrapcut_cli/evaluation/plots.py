"""Figures of the evaluation (PNG, matplotlib's Agg backend, imported inside each function).

- :func:`plot_error_along` — error along the normalised reference, one line per method (the
  paper's Fig. 5);
- :func:`plot_paths` — reference and fitted curves, top (x–y) and side views, equal aspect;
- :func:`plot_leaf_sweep` — skeleton mean error against leaf size, with the NURBS mean for
  comparison (the paper's Fig. 3);
- :func:`plot_parameter_study` — mean error against any parameter, one line per method (the
  per-parameter figures of ``scrapcut batch``);
- :func:`write_plots` — all that apply to a set of report rows, one file per object.

Each method has its colour in every figure; when several path files of one method are plotted
together (four fits of one object), each file gets its own colour and its name in the legend.

Axes are millimetres; positions are in the base frame.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from scrapcut_cli._io import atomic_path
from scrapcut_cli.errors import EvaluationError
from scrapcut_cli.evaluation.report import ReportRow, sort_rows

#: One colour per method, the same in every figure (matplotlib's tab10 entries).
METHOD_COLOURS = {"nurbs": "tab:blue", "skeleton": "tab:orange"}
_FALLBACK = ("tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive")
#: One colour per file when several files share a method (tab10 without its grey).
_DISTINCT = (
    "tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple",
    "tab:brown", "tab:pink", "tab:olive", "tab:cyan",
)  # fmt: skip


def plot_error_along(rows: Sequence[ReportRow], out_path: str | Path, *, title: str) -> Path:
    """Error (mm) against normalised position along the reference, one line per row."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8.0, 4.5), layout="constrained")
    for row in (r for r in sort_rows(rows) if r.error is not None):
        assert row.error is not None
        ax.plot(
            row.error.sample_s,
            row.error.sample_errors_m * 1000.0,
            color=_colour(row, rows),
            linestyle=_dash(row, rows),
            linewidth=1.4,
            label=f"{_legend(row, rows)} (mean {row.error.mean_m * 1000.0:.2f} mm, "
            f"max {row.error.max_m * 1000.0:.2f} mm)",
        )
    threshold = _first_threshold_mm(rows)
    if threshold is not None:
        ax.axhline(threshold, color="0.5", linestyle=":", linewidth=1.0)
        ax.annotate(
            f"coverage threshold {threshold:g} mm",
            xy=(0.5, threshold),
            xytext=(0, 2),
            textcoords="offset points",
            ha="center",
            fontsize=8,
            color="0.4",
        )
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("position along the reference curve (normalised arc length, 0–1)")
    ax.set_ylabel("distance to the fitted curve [mm]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=9)
    return _save(fig, out_path)


def plot_paths(
    reference: np.ndarray,
    rows: Sequence[ReportRow],
    out_path: str | Path,
    *,
    title: str,
) -> Path:
    """Reference (black) and each row's curve, top view (x–y) and side view, in mm.

    The side view looks along the horizontal axis of least extent of the reference (x–z or
    y–z), so the curve's height profile is seen broadside.
    """
    plt = _pyplot()
    ref = np.asarray(reference, dtype=np.float64) * 1000.0
    extent = np.ptp(ref, axis=0)
    side_axis = 0 if extent[0] >= extent[1] else 1
    views = [((0, 1), "top view"), ((side_axis, 2), "side view")]
    fig, axes = plt.subplots(1, 2, figsize=(11.0, 5.0), layout="constrained")
    names = "xyz"
    for ax, ((a, b), view) in zip(axes, views, strict=True):
        ax.plot(ref[:, a], ref[:, b], color="black", linewidth=3.0, alpha=0.35, label="reference")
        for row in (r for r in sort_rows(rows) if r.curve_points is not None):
            assert row.curve_points is not None
            curve = np.asarray(row.curve_points) * 1000.0
            ax.plot(
                curve[:, a],
                curve[:, b],
                color=_colour(row, rows),
                linestyle=_dash(row, rows),
                linewidth=1.3,
                label=_legend(row, rows),
            )
        ax.plot(ref[0, a], ref[0, b], "o", color="black", markersize=5, label="reference start")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"{names[a]} [mm] (base frame)")
        ax.set_ylabel(f"{names[b]} [mm] (base frame)")
        ax.set_title(view)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=9)
    fig.suptitle(title)
    return _save(fig, out_path)


def plot_leaf_sweep(rows: Sequence[ReportRow], out_path: str | Path, *, title: str) -> Path:
    """Skeleton mean error (± SD) against leaf size, and the NURBS mean as a line (Fig. 3).

    Rows with a leaf size (skeleton) make the curve; a failed row is marked at the bottom
    with an ✗ at its leaf size; rows without one (NURBS) draw horizontal lines.
    """
    plt = _pyplot()
    sweep = [r for r in sort_rows(rows) if r.leaf_size_m is not None]
    if not sweep:
        raise EvaluationError("a leaf-size plot needs rows with a leaf size (skeleton fits)")
    fig, ax = plt.subplots(figsize=(7.0, 4.5), layout="constrained")
    ok = [r for r in sweep if r.error is not None]
    if ok:
        leaf = np.array([r.leaf_size_m for r in ok], dtype=np.float64) * 1000.0
        mean = np.array([r.error.mean_m for r in ok if r.error]) * 1000.0
        sd = np.array([r.error.sd_m for r in ok if r.error]) * 1000.0
        ax.errorbar(
            leaf,
            mean,
            yerr=sd,
            marker="o",
            capsize=3,
            color=METHOD_COLOURS["skeleton"],
            label="skeleton mean ± SD",
        )
    failed = [r for r in sweep if r.error is None]
    if failed:
        ax.plot(
            [1000.0 * (r.leaf_size_m or 0.0) for r in failed],
            np.zeros(len(failed)),
            "x",
            color="tab:red",
            markersize=10,
            clip_on=False,
            label="skeleton failed (broke into pieces)",
        )
    for row in (r for r in sort_rows(rows) if r.leaf_size_m is None):
        if row.error is not None:
            ax.axhline(
                row.error.mean_m * 1000.0,
                color=_colour(row, rows),
                linestyle="--",
                label=f"{row.method} mean ({row.error.mean_m * 1000.0:.2f} mm)",
            )
    ax.set_xlim(left=0.0)
    ax.set_xlabel("skeleton leaf size [mm]")
    ax.set_ylabel("mean distance to the fitted curve [mm]")
    ax.set_ylim(bottom=0.0)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    # Below the axes: error bars and reference lines can be anywhere inside them.
    fig.legend(loc="outside lower center", ncols=3, fontsize=9)
    return _save(fig, out_path)


def plot_parameter_study(
    series: Mapping[str, tuple[Sequence[float], Sequence[float], Sequence[float]]],
    out_path: str | Path,
    *,
    xlabel: str,
    ylabel: str = "mean distance to the fitted curve [mm]",
    title: str,
) -> Path:
    """Error against a parameter's value, one line per series (Fig. 3 generalised to any grid
    parameter of ``scrapcut batch``): ``series[label] = (values, means, spreads)``, the means
    drawn with ± spread error bars. A series named after a method takes its colour."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 4.5), layout="constrained")
    for i, (label, (x, y, spread)) in enumerate(sorted(series.items())):
        method = label.split()[0] if label else ""
        colour = METHOD_COLOURS.get(method, _FALLBACK[i % len(_FALLBACK)])
        ax.errorbar(
            np.asarray(x, dtype=np.float64),
            np.asarray(y, dtype=np.float64),
            yerr=np.asarray(spread, dtype=np.float64),
            marker="o",
            capsize=3,
            color=colour,
            label=label,
        )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_ylim(bottom=0.0)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if series:
        fig.legend(loc="outside lower center", ncols=3, fontsize=9)
    return _save(fig, out_path)


def write_plots(rows: Sequence[ReportRow], out_dir: str | Path) -> list[Path]:
    """Every figure that applies, per object: ``error_along_<object>.png``,
    ``paths_<object>.png`` and, when one object has skeleton rows at two or more leaf sizes,
    ``leaf_sweep_<object>.png``. Returns the files written.
    """
    out_dir = Path(out_dir)
    written: list[Path] = []
    objects = sorted({r.object for r in rows})
    for name in objects:
        mine = [r for r in rows if r.object == name]
        slug = _slug(name)
        if any(r.error is not None for r in mine):
            written.append(
                plot_error_along(
                    mine,
                    out_dir / f"error_along_{slug}.png",
                    title=f"{name}: error along the reference curve",
                )
            )
        reference = next((r.reference_points for r in mine if r.reference_points is not None), None)
        if reference is not None:
            written.append(
                plot_paths(
                    reference,
                    mine,
                    out_dir / f"paths_{slug}.png",
                    title=f"{name}: reference and fitted curves",
                )
            )
        leaves = {r.leaf_size_m for r in mine if r.leaf_size_m is not None}
        if len(leaves) >= 2:
            written.append(
                plot_leaf_sweep(
                    mine,
                    out_dir / f"leaf_sweep_{slug}.png",
                    title=f"{name}: skeleton error against leaf size",
                )
            )
    return written


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, out_path: str | Path) -> Path:
    import matplotlib.pyplot as plt

    out_path = Path(out_path)
    try:
        with atomic_path(out_path) as tmp:
            # No "Software" text chunk: the same figures give the same bytes across versions.
            fig.savefig(tmp, format="png", dpi=120, metadata={"Software": None})
    finally:
        plt.close(fig)
    return out_path


def _several_files(rows: Sequence[ReportRow]) -> bool:
    """True when two rows share a method and leaf size but come from different files (four
    path files of one object and method): each then gets its own colour and its file name."""
    seen: dict[tuple[str, float], str] = {}
    for r in rows:
        key = (r.method, r.leaf_size_m or 0.0)
        if key in seen and seen[key] != _file(r):
            return True
        seen.setdefault(key, _file(r))
    return False


def _file(row: ReportRow) -> str:
    return row.name or Path(row.source).name


def _colour(row: ReportRow, rows: Sequence[ReportRow]) -> str:
    """The method's colour; one colour per row when several files share a method."""
    if _several_files(rows):
        ordered = sort_rows(rows)
        index = next(i for i, r in enumerate(ordered) if r is row)
        return _DISTINCT[index % len(_DISTINCT)]
    others = sorted({r.method for r in rows if r.method not in METHOD_COLOURS})
    if row.method in METHOD_COLOURS:
        return METHOD_COLOURS[row.method]
    return _FALLBACK[others.index(row.method) % len(_FALLBACK)]


def _legend(row: ReportRow, rows: Sequence[ReportRow]) -> str:
    """The row's label, with its file's name when several files share a method."""
    return f"{_file(row)}: {row.label}" if _several_files(rows) else row.label


def _dash(row: ReportRow, rows: Sequence[ReportRow]) -> Any:
    """Distinguish rows of the same method (a leaf-size sweep) by dash pattern."""
    if _several_files(rows):
        return "-"
    same = sorted(
        {r.leaf_size_m or 0.0 for r in rows if r.method == row.method},
    )
    styles = ["-", "--", "-.", ":", (0, (5, 1)), (0, (3, 1, 1, 1, 1, 1))]
    return styles[same.index(row.leaf_size_m or 0.0) % len(styles)]


def _first_threshold_mm(rows: Sequence[ReportRow]) -> float | None:
    for r in rows:
        if r.error is not None:
            return r.error.coverage_threshold_m * 1000.0
    return None


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name) or "object"
