"""One job end to end: recording → stitched clouds → curve → cutting path → error → files.

:class:`Pipeline` is the only orchestration of a fit (docs/design.md): ``scrapcut fit`` runs one,
``scrapcut explore`` runs one on the planner's own stitched clouds, ``reproduce`` runs one per
method on each simulated scan, and ``batch`` runs thousands on Dask workers. Its :meth:`run
<Pipeline.run>` reads like a table of contents; each step is a short method, and the reference
(ground truth) is read only in the evaluation step::

    job = Job(Path("scan_01.mcap"), FitMethod.SKELETON, config, output=Path("cut.json"))
    result = Pipeline(job).run()          # raises a ScrapcutError on a known failure
    result = run_job(job)                 # the same, a known failure becomes result.failure

Options other commands add (a calibration, a line selection) travel in ``job.config``; a new
step is a new method called from :meth:`Pipeline.run`.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from scrapcut_cli.config import FitMethod, ScrapcutConfig
from scrapcut_cli.errors import FittingError, ScrapcutError
from scrapcut_cli.pipeline.evaluate import (
    SKIPPED,
    ErrorReport,
    check_reference_given,
    error_report_paths,
    evaluate_path_dict,
    find_reference,
    write_error_report,
)
from scrapcut_cli.pipeline.fit import (
    FitResult,
    StitchedRecording,
    check_fit_options,
    fit_stitched,
    stitch_recording_file,
)

if TYPE_CHECKING:
    from scrapcut_cli.evaluation.report import ReportRow
    from scrapcut_cli.toolpath.speeds import SpeedTable

ProgressFn = Callable[[int, int], None]


@dataclass(frozen=True)
class Job:
    """What one job is asked to do.

    Attributes
    ----------
    recording : Path
        An ``.mcap`` file, a ROS 1 ``.bag`` or a ROS 2 bag directory.
    method : FitMethod
        The curve model.
    config : ScrapcutConfig
        Every stage's parameters (the path file saves them).
    output : Path, optional
        The path file to write (``scrapcut.path/v1``); None: nothing is written.
    reference : Path, optional
        A CSV ``x,y,z`` or a recording to measure against; None: the recording's own
        /scrapcut/reference if it has one.
    evaluate : bool
        False skips the error report (``--no-eval``).
    csv, mcap, tum : bool
        Also write ``PATH.csv`` (set-points), ``PATH.mcap`` (Foxglove) and ``PATH.tum`` (the
        torch poses for evo).
    nurbs_json : Path, optional
        Also write the NURBS in geomdl's JSON (NURBS only).
    source_name : str, optional
        The recording's name in the path file (default: ``recording`` as given).
    object_name : str, optional
        The report row's object (default: the reference's, else the path file's stem).
    retry_leaf_size_m : float, optional
        A skeleton that breaks at its leaf size is fitted once more at this one (the paper's
        basket); the result's note says so.
    line : int
        Which of the picked lines to fit (``selection.pick = "all"`` picks several; 0: the
        first, the one the scan follows by default).
    """

    recording: Path
    method: FitMethod
    config: ScrapcutConfig
    output: Path | None = None
    reference: Path | None = None
    evaluate: bool = True
    csv: bool = False
    mcap: bool = False
    tum: bool = False
    nurbs_json: Path | None = None
    source_name: str | None = None
    object_name: str | None = None
    retry_leaf_size_m: float | None = None
    line: int = 0

    def exports(self) -> list[Path]:
        """Every file the job writes besides the error report: path file first."""
        if self.output is None:
            return []
        extra = [
            self.output.with_suffix(".csv") if self.csv else None,
            self.output.with_suffix(".mcap") if self.mcap else None,
            self.output.with_suffix(".tum") if self.tum else None,
            self.nurbs_json,
        ]
        return [self.output, *(p for p in extra if p is not None)]


@dataclass(frozen=True, eq=False)
class JobResult:
    """What a job produced: the fit, its error report, the files written, or why it failed.

    ``config`` is the configuration the fit ran with (a retry changes the leaf size); ``note``
    says what the figures alone do not (a retry at a larger leaf); ``timings_s`` wall time per
    step, seconds; ``extras`` further per-job figures for the report rows (name → value).
    """

    job: Job
    config: ScrapcutConfig
    fit: FitResult | None
    report: ErrorReport
    written: list[Path] = field(default_factory=list)
    failure: str | None = None
    note: str = ""
    timings_s: dict[str, float] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.failure is None

    @property
    def method_params(self) -> dict[str, Any]:
        """The method's parameters as used (its config section, JSON-ready)."""
        section = getattr(self.config, str(self.job.method))
        return dict(json.loads(json.dumps(dataclasses.asdict(section))))

    def row(self, object_name: str) -> ReportRow:
        """The Table I row: the error report's, or a failed row naming why."""
        from scrapcut_cli.evaluation.report import ReportRow

        if self.report.row is not None:
            return replace(self.report.row, note=self.note, extras=dict(self.extras))
        return ReportRow(
            object_name,
            str(self.job.method),
            None,
            params=self.method_params,
            note=self.note,
            failure=self.failure or self.report.status,
            extras=dict(self.extras),
        )

    def summary(self) -> dict[str, Any]:
        """JSON-ready: the fit's figures, the error (or why there is none), the files."""
        data: dict[str, Any] = {} if self.fit is None else self.fit.summary()
        error_json = error_report_paths(self.job.output)[0] if self.job.output else None
        data["error"] = self.report.summary()
        data["error_status"] = self.report.status
        data["error_report"] = (
            str(error_json) if error_json is not None and self.report.row is not None else None
        )
        data["note"] = self.note
        data["failure"] = self.failure
        data["outputs"] = [str(p) for p in self.written]
        return data


class Pipeline:
    """Run one :class:`Job`. Give ``stitched`` to start from clouds already stitched (several
    methods on one scan, or an exploration's own clouds); ``progress(done, total)`` follows the
    frames while stitching."""

    def __init__(
        self,
        job: Job,
        *,
        stitched: StitchedRecording | None = None,
        speeds: SpeedTable | None = None,
        progress: ProgressFn | None = None,
    ) -> None:
        self.job = job
        self.config = job.config
        self.stitched = stitched
        self.speeds = speeds
        self.progress = progress
        self.fit: FitResult | None = None
        self.path_dict: dict[str, Any] | None = None
        self.report = ErrorReport(SKIPPED)
        self.note = ""
        self.written: list[Path] = []
        self.timings_s: dict[str, float] = {}

    # Public interface ------
    def run(self) -> JobResult:
        """Every step in order; a known failure raises its ScrapcutError (one line)."""
        self._check_options()
        self._read_and_stitch()
        self._fit_curve_and_path()
        self._make_path_file()
        self._evaluate()
        self._write_outputs()
        return self._result()

    # Steps ------
    def _check_options(self) -> None:
        """Everything that can be refused without reading the recording."""
        self.speeds = check_fit_options(self.job.method, self.config, self.speeds)
        if self.job.evaluate:
            check_reference_given(self.job.reference)
        if self.job.nurbs_json is not None and self.job.method != FitMethod.NURBS:
            raise FittingError("a geomdl NURBS export needs the nurbs method")

    def _read_and_stitch(self) -> None:
        if self.stitched is not None:
            return
        self.stitched = stitch_recording_file(
            self.job.recording, config=self.config, progress=self.progress
        )

    def _fit_curve_and_path(self) -> None:
        """The curve and the torch set-points; a broken skeleton is retried once at
        ``retry_leaf_size_m`` when the job allows it."""
        assert self.stitched is not None
        try:
            self.fit = self._fit(self.config)
        except FittingError as exc:
            retry = self.job.retry_leaf_size_m
            leaf = self.config.skeleton.leaf_size_m
            if self.job.method != FitMethod.SKELETON or retry is None or np.isclose(leaf, retry):
                raise
            self.config = self.config.override("skeleton", leaf_size_m=retry)
            # The fitter's message ends with advice for the command line; the note needs the why.
            why = str(exc).split(";")[0]
            self.note = f"{leaf * 1000:g} mm leaf broke ({why}); retried at {retry * 1000:g} mm"
            self.fit = self._fit(self.config)

    def _fit(self, config: ScrapcutConfig) -> FitResult:
        assert self.stitched is not None
        job = self.job
        return fit_stitched(
            self.stitched, method=job.method, config=config, speeds=self.speeds, line=job.line
        )

    def _make_path_file(self) -> None:
        """The ``scrapcut.path/v1`` dictionary, naming its error report when there will be one."""
        assert self.fit is not None
        data = self.fit.to_path_dict()
        if self.job.source_name is not None:
            data["source"]["path"] = self.job.source_name
        self.path_dict = data

    def _evaluate(self) -> None:
        """The only step that reads the reference."""
        assert self.path_dict is not None
        if not self.job.evaluate:
            return
        t0 = time.perf_counter()
        # The reference in the path's frame: a recording's own /scrapcut/reference is usually
        # already there, and then its /tf need not be read again.
        frame = None if self.fit is None else self.fit.frame_id
        recording_config = replace(self.config.recording, base_frame=frame)
        reference = find_reference(self.job.recording, self.job.reference, config=recording_config)
        target = self.job.output or Path(f"{self.job.recording.stem}_{self.job.method}.json")
        self.report = evaluate_path_dict(
            self.path_dict,
            target,
            reference,
            config=self.config,
            object_name=self.job.object_name,
            note=self.note,
        )
        if self.report.row is not None and self.job.output is not None:
            self.path_dict["error_report"] = error_report_paths(self.job.output)[0].name
        self.timings_s["evaluate"] = time.perf_counter() - t0

    def _write_outputs(self) -> None:
        """Path file, error report and exports, each written atomically."""
        from scrapcut_cli.toolpath.pathfile import (
            write_path_csv,
            write_path_file,
            write_path_tum,
        )
        from scrapcut_cli.toolpath.review import ReviewPath, write_review_mcap

        job, fit = self.job, self.fit
        if job.output is None or fit is None or self.path_dict is None:
            return
        write_path_file(job.output, self.path_dict)
        self.written.append(job.output)
        self.written += write_error_report(self.report, job.output)
        if job.csv:
            write_path_csv(fit.path, job.output.with_suffix(".csv"), frame_id=fit.frame_id)
            self.written.append(job.output.with_suffix(".csv"))
        if job.tum:
            write_path_tum(fit.path, job.output.with_suffix(".tum"), frame_id=fit.frame_id)
            self.written.append(job.output.with_suffix(".tum"))
        if job.mcap:
            row = self.report.row
            write_review_mcap(
                job.output.with_suffix(".mcap"),
                [
                    ReviewPath(
                        job.output.name,
                        fit.curve.points,
                        fit.path.positions,
                        fit.path.orientations_xyzw,
                        fit.path.flags,
                    )
                ],
                frame_id=fit.frame_id,
                stamp_ns=fit.start_ns,
                reference=None if row is None else row.reference_points,
                paint_points=fit.line_points,
                surface_points=fit.stitch.surface_points,
                error_scale_m=fit.config.evaluation.coverage_threshold_m,
            )
            self.written.append(job.output.with_suffix(".mcap"))
        if job.nurbs_json is not None:
            from scrapcut_cli._io import write_text_atomic
            from scrapcut_cli.fitting.nurbs import nurbs_to_geomdl_json

            assert fit.curve.nurbs is not None  # nurbs method, checked first
            write_text_atomic(job.nurbs_json, nurbs_to_geomdl_json(fit.curve.nurbs))
            self.written.append(job.nurbs_json)

    def _result(self, failure: str | None = None) -> JobResult:
        """read_stitch, fit, toolpath (the fit's own timings), evaluate; seconds."""
        timings = {} if self.fit is None else dict(self.fit.timings_s)
        timings.pop("total", None)
        timings.update(self.timings_s)
        return JobResult(
            job=self.job,
            config=self.config,
            fit=self.fit,
            report=self.report,
            written=list(self.written),
            failure=failure,
            note=self.note,
            timings_s=timings,
        )


def run_job(
    job: Job,
    *,
    stitched: StitchedRecording | None = None,
    speeds: SpeedTable | None = None,
    progress: ProgressFn | None = None,
) -> JobResult:
    """:meth:`Pipeline.run`, with a known failure (ScrapcutError) returned as
    ``result.failure`` instead of raised: one job of many must not stop the others."""
    pipeline = Pipeline(job, stitched=stitched, speeds=speeds, progress=progress)
    try:
        return pipeline.run()
    except ScrapcutError as exc:
        return pipeline._result(failure=str(exc))
