"""Path error against the painted reference (the paper's Table I), reports and plots.

- :mod:`.metrics` — :func:`~.metrics.path_error`: the Table I metric plus coverage, reverse
  distance and length ratio, on arrays (no I/O);
- :mod:`.report` — rows of object × method, the paper's Table I, markdown/CSV/JSON/rich;
- :mod:`.plots` — the figures (error along the curve, paths, leaf-size sweep), matplotlib Agg;
- :mod:`.sources` — reading path files and references, and the ``scrapcut eval`` recipe;
- :mod:`.reproduce` — ``scrapcut reproduce``: simulate → fit → evaluate → report.

Import submodules directly: ``from scrapcut_cli.evaluation.metrics import path_error``.
"""
