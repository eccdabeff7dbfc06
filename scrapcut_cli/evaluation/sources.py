"""What gets evaluated: path files and references, read from disk, and the evaluation recipe.

This is the evaluation's input layer (as ``recording/`` is the pipeline's): path files are
``scrapcut.path/v1`` JSON (docs/path-file.md); a reference is a recording with
/scrapcut/reference or a CSV with the header ``x,y,z`` (metres, base frame, ordered along
the curve).

A closed reference (a ring, a cut-out) is scored as a loop. A recording says so in its
``scrapcut_reference`` metadata (the simulator writes ``closed`` and the arcs no image showed,
``unseen_arcs``); a CSV says so with a comment line ``# closed: true`` anywhere before the
rows (e.g. above the header), or by ending on its first point again (within 0.1 mm; the
repeated row is dropped).
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli._io import check_input_file, real_path
from scrapcut_cli.config import EvaluationConfig, RecordingConfig, ScanMode
from scrapcut_cli.errors import EvaluationError, FileError, ScrapcutError, ToolpathError
from scrapcut_cli.evaluation.checks import check_scale, row_warnings
from scrapcut_cli.evaluation.metrics import path_error, setpoint_error
from scrapcut_cli.evaluation.report import ReportRow
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.geometry import MAX_COORDINATE_M, closed_polyline, cumulative_length
from scrapcut_cli.toolpath.path import CuttingPath


@dataclass(frozen=True, eq=False)
class PathFile:
    """The parts of a path file the evaluation needs.

    ``curve_points`` : (N, 3) float64, metres, base frame — the fitted curve on the surface.
    ``source`` is the recording named in the file (as written, may be relative), or None.
    ``setpoint_surface_points`` : (K, 3) float64, metres — where each set-point's torch axis
    meets the piece (K may be 0); ``setpoint_flags`` their flags; ``setpoint_positions`` and
    ``setpoint_orientations_xyzw`` (K, 3), (K, 4) the torch tip poses (for the review file).
    ``curve_sigma_m`` : (N,) float64 or None — the set-points' σ (metres) carried to the curve
    points by arc length, when the file has it.
    """

    path: Path
    curve_points: NDArray[np.float64]
    method: str
    params: dict[str, Any]
    frame_id: str
    source: str | None
    setpoint_surface_points: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    setpoint_flags: list[list[str]] = field(default_factory=list)
    setpoint_positions: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    setpoint_orientations_xyzw: NDArray[np.float64] = field(
        default_factory=lambda: np.zeros((0, 4))
    )
    source_start_ns: int | None = None
    closed: bool = False
    unobserved_arcs_m: tuple[tuple[float, float], ...] = ()
    setpoints: NDArray[np.float64] | None = None  # (K, 3) surface points of the cut
    setpoint_unobserved: NDArray[np.bool_] | None = None  # (K,)
    curve_sigma_m: NDArray[np.float64] | None = None

    @property
    def name(self) -> str:
        """The file's name, the label of its row."""
        return self.path.name


@dataclass(frozen=True, eq=False)
class Reference:
    """A painted reference curve: ``points`` (M, 3) float64, metres, base frame, ordered.

    ``object`` is the simulated object's name when the recording says it; ``origin`` the file;
    ``metadata`` the recording's simulator settings (``object``, ``mode``, ``seed``...);
    ``frame_id`` the frame of the points when known (a recording's; a CSV names none).
    """

    points: NDArray[np.float64]
    origin: Path
    object: str | None = None
    metadata: dict[str, Any] = field(default_factory=dict)
    frame_id: str | None = None
    closed: bool = False
    unseen_arcs_m: tuple[tuple[float, float], ...] | None = None  # truth; None: unknown

    @property
    def oracle_views(self) -> bool:
        """True for a simulator sweep: its views followed this very line (an oracle)."""
        return str(self.metadata.get("mode", "")) == ScanMode.SWEEP


def load_path_file(path: str | Path) -> PathFile:
    """Read a ``scrapcut.path/v1`` file (validated by the tool path's reader).

    Raises EvaluationError naming the file when it is missing, not a path file, or malformed.
    """
    from scrapcut_cli.toolpath.pathfile import read_path_file

    path = Path(path)
    try:
        curve, cutting, meta = read_path_file(path)
    except ToolpathError as exc:
        raise EvaluationError(str(exc)) from None
    return _path_file(path, curve, cutting, meta)


def path_file_from_dict(data: dict[str, Any], path: str | Path) -> PathFile:
    """A path file's dictionary (before or after it is written to ``path``) as :class:`PathFile`:
    what :func:`load_path_file` returns for the written file, number for number (the path file
    keeps every float's shortest round-trip repr), so a report computed before writing equals
    ``scrapcut eval`` on the file."""
    from scrapcut_cli.toolpath.pathfile import path_from_dict

    path = Path(path)
    try:
        curve, cutting, meta = path_from_dict(data)
    except ToolpathError as exc:
        raise EvaluationError(f"{path}: {exc}") from None
    return _path_file(path, curve, cutting, meta)


def _path_file(path: Path, curve: Curve, cutting: CuttingPath, meta: dict[str, Any]) -> PathFile:
    if len(curve.points) < 2:
        raise EvaluationError(f"{path}: curve.points must hold at least two [x, y, z] points")
    method = meta.get("method") or {}
    params = method.get("params") if isinstance(method, dict) else None
    source = meta.get("source")
    source_path = source.get("path") if isinstance(source, dict) else None
    start = source.get("start_ns") if isinstance(source, dict) else None
    arcs = _arc_pairs(curve.info.get("unobserved_arcs_m"), f"{path}: curve.info.unobserved_arcs_m")
    cut = [i for i, g in enumerate(cutting.segments or ["cut"] * len(cutting)) if g != "lead_in"]
    return PathFile(
        path=path,
        curve_points=np.asarray(curve.points, dtype=np.float64),
        method=curve.method,
        params=dict(params) if isinstance(params, dict) else {},
        frame_id=str(meta.get("frame_id", "")),
        source=None if source_path is None else str(source_path),
        setpoint_surface_points=np.asarray(cutting.surface_points, dtype=np.float64).reshape(-1, 3),
        setpoint_flags=[list(f) for f in cutting.flags],
        setpoint_positions=np.asarray(cutting.positions, dtype=np.float64).reshape(-1, 3),
        setpoint_orientations_xyzw=np.asarray(cutting.orientations_xyzw).reshape(-1, 4),
        source_start_ns=start if isinstance(start, int) and not isinstance(start, bool) else None,
        closed=curve.closed,
        unobserved_arcs_m=arcs,
        setpoints=cutting.surface_points[cut],
        setpoint_unobserved=np.array(["unobserved" in cutting.flags[i] for i in cut], dtype=bool),
        curve_sigma_m=_curve_sigma(curve, cutting),
    )


def _arc_pairs(value: Any, where: str) -> tuple[tuple[float, float], ...]:
    """[[start, end], ...] of finite numbers as a tuple of pairs (EvaluationError otherwise)."""
    if value is None:
        return ()
    try:
        arcs = np.asarray(value, dtype=np.float64).reshape(-1, 2)
    except (TypeError, ValueError):
        raise EvaluationError(f"{where} must be a list of [start, end] pairs") from None
    if not np.isfinite(arcs).all():
        raise EvaluationError(f"{where} holds NaN or infinite values")
    return tuple((float(a), float(b)) for a, b in arcs)


def _curve_sigma(curve: Curve, cutting: CuttingPath) -> NDArray[np.float64] | None:
    """The set-points' σ at the curve's points, by arc length (set-point ``s`` runs along the
    curve's polyline); None without σ or with fewer than two set-points."""
    if cutting.sigma_m is None or len(cutting) < 2:
        return None
    s = cumulative_length(np.asarray(curve.points, dtype=np.float64))
    order = np.argsort(cutting.arc_length, kind="stable")
    return np.asarray(np.interp(s, cutting.arc_length[order], cutting.sigma_m[order]))


def read_reference_csv(path: str | Path) -> NDArray[np.float64]:
    """(M, 3) reference points from a CSV with header ``x,y,z`` (metres, base frame)."""
    return read_reference_csv_loop(path)[0]


#: A CSV reference ending this close to its first point is closed (its last row repeats it).
CLOSING_TOLERANCE_M = 1e-4


def read_reference_csv_loop(path: str | Path) -> tuple[NDArray[np.float64], bool]:
    """(M, 3) reference points from a CSV with header ``x,y,z`` (metres, base frame), and
    whether the reference is closed (a ``# closed: true`` line, or the last row back on the
    first; the repeated row is dropped). Other ``#`` lines are comments."""
    path = Path(path)
    closed = False
    try:
        check_input_file(path, "reference CSV")
        # utf-8-sig: a spreadsheet's export starts with a byte-order mark.
        with path.open(encoding="utf-8-sig") as f:
            line = f.readline()
            while line.lstrip().startswith("#"):
                closed |= _closed_marker(line)
                line = f.readline()
            header = [h.strip().lower() for h in line.split(",")]
            with warnings.catch_warnings():
                # A header without rows is reported below (one line), not warned about.
                warnings.simplefilter("ignore", UserWarning)
                rest = f.read()
    except FileError as exc:
        if "not found" in str(exc):
            raise EvaluationError(f"reference not found: {path}") from None
        raise EvaluationError(str(exc)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise EvaluationError(f"cannot read reference CSV {path}: {exc}") from None
    lines = rest.splitlines()
    closed |= any(_closed_marker(text) for text in lines if text.lstrip().startswith("#"))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            rows = np.loadtxt(lines, delimiter=",", dtype=np.float64, ndmin=2, comments="#")
    except ValueError as exc:
        raise EvaluationError(f"cannot read reference CSV {path}: {exc}") from None
    if header[:3] != ["x", "y", "z"]:
        raise EvaluationError(f"reference CSV {path} must start with the header x,y,z (metres)")
    if rows.shape[0] < 2 or rows.shape[1] < 3:
        raise EvaluationError(f"reference CSV {path} needs at least two rows of x,y,z")
    bad = np.flatnonzero(~(np.abs(rows[:, :3]) <= MAX_COORDINATE_M).all(axis=1))
    if len(bad):
        raise EvaluationError(
            f"reference CSV {path}: {len(bad)} row(s) with NaN or infinite coordinates or "
            f"beyond {MAX_COORDINATE_M:g} m (first: line {int(bad[0]) + 2})"
        )
    points = np.ascontiguousarray(rows[:, :3])
    if len(points) > 3 and np.linalg.norm(points[-1] - points[0]) <= CLOSING_TOLERANCE_M:
        points, closed = points[:-1].copy(), True
    return points, closed


def _closed_marker(line: str) -> bool:
    key, _, value = line.lstrip().lstrip("#").partition(":")
    return key.strip().lower() == "closed" and value.strip().lower() in ("true", "yes", "1")


def load_reference(path: str | Path, *, config: RecordingConfig | None = None) -> Reference:
    """A reference from a CSV (``.csv``) or from a recording's /scrapcut/reference."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        points, closed = read_reference_csv_loop(path)
        return Reference(points=points, origin=path, closed=closed)
    reference = recording_reference(path, config=config)
    if reference is None:
        raise EvaluationError(
            f"{path} has no /scrapcut/reference; pass --reference with a recording or CSV x,y,z"
        )
    return reference


def recording_reference(
    path: str | Path, *, config: RecordingConfig | None = None
) -> Reference | None:
    """A recording's own /scrapcut/reference, or None when it has none (a real scan)."""
    path = Path(path)
    if not path.exists():
        raise EvaluationError(f"reference recording not found: {path}")
    from scrapcut_cli.recording.reader import open_recording

    with open_recording(path, config) as rec:
        found = rec.reference_in_frame()
        metadata = dict(rec.metadata.get("scrapcut", {}))
        loop = dict(rec.metadata.get("scrapcut_reference", {}))
    if found is None or len(found[0]) < 2:
        return None
    name = metadata.get("object")
    closed = str(loop.get("closed", "false")).lower() == "true"
    unseen = None
    if closed and "unseen_arcs" in loop:
        try:
            unseen = _arc_pairs(json.loads(loop["unseen_arcs"]), f"{path}: unseen_arcs")
        except json.JSONDecodeError:
            raise EvaluationError(f"{path}: scrapcut_reference.unseen_arcs is not JSON") from None
    return Reference(
        points=np.asarray(found[0], dtype=np.float64),
        origin=path,
        object=str(name) if name else None,
        metadata=metadata,
        frame_id=found[1] or None,
        closed=closed,
        unseen_arcs_m=unseen,
    )


def resolve_source(path_file: PathFile) -> Path:
    """The recording a path file names: as written, else relative to the path file's folder."""
    if path_file.source is None:
        raise EvaluationError(
            f"{path_file.path} names no source recording; pass --reference REC|CSV"
        )
    source = Path(path_file.source)
    candidates = [source]
    if not source.is_absolute():
        candidates.append(path_file.path.parent / source)
        candidates.append(path_file.path.parent / source.name)
    for candidate in candidates:
        if candidate.exists():
            return candidate
    raise EvaluationError(
        f"{path_file.path}: its recording {path_file.source} was not found; "
        "pass --reference REC|CSV"
    )


def evaluate_path_files(
    paths: Sequence[str | Path],
    *,
    reference: str | Path | None = None,
    config: EvaluationConfig | None = None,
    recording_config: RecordingConfig | None = None,
    align: bool = False,
) -> list[ReportRow]:
    """Evaluate path files: each against ``reference`` or the recording it names.

    A recording named by several path files is read once. The object name is the recording's
    ``metadata["scrapcut"]["object"]``, else the path file's stem. ``align``: also the shape
    error after a rigid alignment (:mod:`~scrapcut_cli.evaluation.align`).
    """
    if not paths:
        raise EvaluationError("no path files given")
    config = EvaluationConfig() if config is None else config
    cache: dict[Path, Reference] = {}
    shared = None if reference is None else load_reference(reference, config=recording_config)
    rows = []
    for p in paths:
        path_file = load_path_file(p)
        if shared is not None:
            ref = shared
        else:
            origin = real_path(resolve_source(path_file))
            if origin not in cache:
                cache[origin] = load_reference(origin, config=recording_config)
            ref = cache[origin]
        rows.append(evaluate_path_file(path_file, ref, config=config, align=align))
    return rows


def loop_summary(figures: dict[str, Any]) -> str:
    """One phrase on a closed reference's figures: the observed arcs' error and coverage, the
    unobserved arcs reported against the true ones."""
    parts = []
    if figures.get("observed_mean_mm") is not None and figures.get("observed_share", 1.0) < 1.0:
        parts.append(
            f"observed arcs ({100.0 * figures['observed_share']:.0f} % of the loop): mean "
            f"{figures['observed_mean_mm']:.2f} mm, max {figures['observed_max_mm']:.2f} mm, "
            f"coverage {100.0 * figures['observed_coverage']:.1f} %"
        )
    reported, true = figures.get("unobserved_arcs", 0), figures.get("unobserved_true_arcs", 0)
    if reported or true:
        text = f"unobserved {figures['unobserved_reported_mm']:.0f} mm reported"
        if figures.get("observed_from") == "truth":
            text += f", {figures['unobserved_true_mm']:.0f} mm true"
            if figures.get("unobserved_extent_error_mm") is not None:
                text += f" (ends within {figures['unobserved_extent_error_mm']:.1f} mm)"
            on, off = (
                figures.get("unobserved_flagged_on_arcs"),
                figures.get("unobserved_flagged_elsewhere"),
            )
            if on is not None:
                text += f"; {100.0 * on:.0f} % of set-points on them flagged"
                if off is not None:
                    text += f", {100.0 * off:.0f} % elsewhere"
        parts.append(text)
    return "closed" + ("; " + "; ".join(parts) if parts else "")


def evaluate_path_file(
    path_file: PathFile,
    reference: Reference,
    *,
    config: EvaluationConfig,
    object_name: str | None = None,
    note: str = "",
    align: bool = False,
) -> ReportRow:
    """One report row: ``path_file``'s curve and set-points against ``reference``.

    Raises EvaluationError when the two are in different frames (each known): distances
    between a path in ``panda_link4`` and a reference in ``panda_link0`` mean nothing; and
    when one is about 1000× the other's size (millimetres read as metres). The row carries
    warnings (:func:`~scrapcut_cli.evaluation.checks.row_warnings`) and, with ``align``, the
    rigid alignment separating shape error from calibration error.
    """
    if reference.frame_id and path_file.frame_id and reference.frame_id != path_file.frame_id:
        raise EvaluationError(
            f"{path_file.path} is in frame {path_file.frame_id!r} but the reference from "
            f"{reference.origin} is in {reference.frame_id!r}; they cannot be compared (fit "
            f"again with --base-frame {reference.frame_id}, or give a reference in "
            f"{path_file.frame_id!r})"
        )
    check_scale(
        path_file.curve_points,
        reference.points,
        path_name=str(path_file.path),
        reference_name=str(reference.origin),
    )
    alignment = aligned = None
    try:
        error = path_error(
            path_file.curve_points,
            reference.points,
            config=config,
            curve_closed=path_file.closed,
            reference_closed=reference.closed,
            true_unseen_arcs_m=reference.unseen_arcs_m,
            reported_unobserved_m=path_file.unobserved_arcs_m,
            setpoints=path_file.setpoints,
            setpoint_unobserved=path_file.setpoint_unobserved,
            sigma_m=path_file.curve_sigma_m,
        )
        setpoints = setpoint_error(
            path_file.setpoint_surface_points,
            path_file.setpoint_flags,
            closed_polyline(reference.points) if reference.closed else reference.points,
            config=config,
        )
        if align:
            from scrapcut_cli.evaluation.align import align_curve

            alignment = align_curve(
                path_file.curve_points, reference.points, sample_spacing_m=config.sample_spacing_m
            )
            aligned = path_error(
                alignment.aligned_points,
                reference.points,
                config=config,
                sigma_m=path_file.curve_sigma_m,
            )
    except ScrapcutError as exc:
        raise EvaluationError(f"{path_file.path}: {exc}") from None
    loop_note = loop_summary(error.summary_mm()) if error.loop is not None else ""
    if reference.closed and not path_file.closed:
        loop_note = "; ".join(n for n in ("the path is open, the reference a loop", loop_note) if n)
    return ReportRow(
        object=object_name or reference.object or path_file.path.stem,
        method=path_file.method,
        error=error,
        params=path_file.params,
        note="; ".join(n for n in (note, loop_note) if n),
        source=str(path_file.path),
        curve_points=path_file.curve_points,
        reference_points=reference.points,
        oracle_views=reference.oracle_views,
        name=path_file.name,
        setpoints=setpoints,
        warnings=tuple(row_warnings(error, setpoints)),
        alignment=alignment,
        aligned_error=aligned,
        frame_id=path_file.frame_id or reference.frame_id or "",
        setpoint_surface_points=path_file.setpoint_surface_points,
        setpoint_flags=tuple(tuple(f) for f in path_file.setpoint_flags),
    )
