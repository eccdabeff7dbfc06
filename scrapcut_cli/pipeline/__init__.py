"""The pipeline: one job end to end (recording → path → error), and the engine that runs many.

This package is the only orchestration (docs/design.md): ``fit``, ``explore`` replay, ``reproduce``
and ``batch`` all run :class:`~scrapcut_cli.pipeline.job.Pipeline` jobs; the stage packages
(``perception``, ``fitting``, ``toolpath``, ``evaluation``) know nothing of each other.

- :mod:`.job` — :class:`~.job.Job`, :class:`~.job.Pipeline` (``run()`` reads like a table of
  contents), :class:`~.job.JobResult`, :func:`~.job.run_job`;
- :mod:`.fit` — the first steps: read and stitch a recording, fit the curve, make the path;
- :mod:`.evaluate` — the last step: the error report (``PATH.error.json``/``.md``) against the
  reference, read only there;
- :mod:`.explore` — the global fit of an exploration replay, a job on the planner's clouds;
- :mod:`.engine` — :class:`~.engine.Engine`: tasks on Dask distributed (a local cluster, a
  scheduler address) or inline;
- :mod:`.reproduce` — ``scrapcut reproduce``: simulated scans × seeds → Table I;
- :mod:`.batch` — ``scrapcut batch``: recordings × a parameter grid → one table, resumable
  (:mod:`.batch_inputs` reads recordings, manifests and grids; :mod:`.batch_report` writes the
  table and the report).

Import submodules directly: ``from scrapcut_cli.pipeline.job import Job, Pipeline``.
"""
