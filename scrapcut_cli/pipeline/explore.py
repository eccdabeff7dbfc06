"""The global fit of an exploration run, as one pipeline job on the planner's own clouds.

``scrapcut explore`` replays Algorithm 1 (:mod:`scrapcut_cli.exploration.replay`), which keeps
the paint and surface the planner stitched. The fit over them — curve, cutting path, path file,
error against the reference — is the same :class:`~scrapcut_cli.pipeline.job.Pipeline` job as
``scrapcut fit``, started from those clouds instead of re-reading the recording.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from scrapcut_cli.config import FitMethod, ScrapcutConfig
from scrapcut_cli.errors import ExplorationError
from scrapcut_cli.exploration.replay import ExplorationRun
from scrapcut_cli.pipeline.fit import StitchedRecording, stitch_recording_file
from scrapcut_cli.pipeline.job import Job, JobResult, Pipeline, run_job


def stitched_from_run(run: ExplorationRun) -> StitchedRecording:
    """The planner's stitched clouds, with the path file's "source" block: the recording and
    the frames the planner used."""
    from scrapcut_cli.recording.reader import sha256_first_mib

    if run.stitch is None:
        raise ExplorationError("this exploration run kept no stitched clouds to fit")
    tally = run.stitch.tally
    return StitchedRecording(
        stitch=run.stitch,
        source={
            "path": run.source,
            "sha256_first_mib": sha256_first_mib(run.source),
            "frames_used": int(tally.frames_with_paint),
            "frames_skipped": int(tally.frames - tally.frames_with_paint),
        },
        frame_id=run.stitch.base_frame,
        reader_skipped=0,
        reader_skip_reasons={},
        stamp_ns=max((s.stamp_ns for s in run.steps), default=0),
        time_s=0.0,
    )


def _calibrated(config: ScrapcutConfig) -> bool:
    return config.calibration.file is not None or config.calibration.self_calibrate


def fit_exploration(
    run: ExplorationRun,
    *,
    config: ScrapcutConfig | None = None,
    output: Path | None = None,
    reference: Path | None = None,
    evaluate: bool = True,
) -> JobResult:
    """``scrapcut fit``'s job on what the run observed: global fit, cutting path, error.

    The planner's perception and stitching are the run's (``run.settings``); the fitters', the
    tool path's and the evaluation's parameters come from ``config`` (default the run's own).
    A calibration in ``config`` poses the frames of a replay again for the fit (a what-if run
    was posed with it from the start).
    With ``output`` the path file and its error report are written, and a known failure raises;
    without, a failure (the global fit broke) is returned as ``result.failure``.
    """
    if run.settings is None:
        raise ExplorationError("this exploration run kept no configuration to fit with")
    settings = run.settings
    if config is not None:
        settings = replace(
            settings,
            recording=config.recording,
            nurbs=config.nurbs,
            skeleton=config.skeleton,
            toolpath=config.toolpath,
            evaluation=config.evaluation,
        )
    job = Job(
        Path(run.source),
        FitMethod(run.method),
        settings,
        output=output,
        reference=reference,
        evaluate=evaluate,
    )
    stitched = stitched_from_run(run)
    if config is not None and run.mode == "replay" and _calibrated(config):
        # The replay checks the decisions with the poses the planner had; the global fit
        # poses the same frames with the calibration.
        settings = replace(settings, calibration=config.calibration)
        job = replace(job, config=settings)
        stitched = stitch_recording_file(
            run.source, config=settings, stamps_ns={s.stamp_ns for s in run.steps}
        )
    elif config is not None and config.calibration.file is not None:
        # A what-if run read its frames through the calibration already: record which.
        from scrapcut_cli.calibration.recipe import camera_mount_for

        stitched = replace(stitched, calibration=camera_mount_for(run.source, config)[1])
    if output is not None:
        return Pipeline(job, stitched=stitched).run()
    return run_job(job, stitched=stitched)
