"""Path error against the painted reference (the paper's Table I), reports and plots.

- :mod:`.metrics` — :func:`~.metrics.path_error`: the Table I metric plus coverage, reverse
  distance and length ratio, on arrays (no I/O);
- :mod:`.report` — rows of object × method, the paper's Table I, markdown/CSV/JSON/rich;
- :mod:`.plots` — the figures (error along the curve, paths, leaf-size sweep), matplotlib Agg;
- :mod:`.sources` — reading path files and references, and the ``scrapcut eval`` recipe.

No orchestration lives here: ``scrapcut reproduce`` and the error report every fit writes are
the pipeline's (:mod:`scrapcut_cli.pipeline`).

Import submodules directly: ``from scrapcut_cli.evaluation.metrics import path_error``.
"""
