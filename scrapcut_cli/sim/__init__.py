"""The bundled simulator: procedural scrap pieces with painted reference lines, a D435i model,
a Panda in pybullet, and the recorder. The only code that imports pybullet.

Public API::

    list_objects() -> [(name, description)]
    make_object(name, *, seed=0) -> ScrapObject
    record(config: SimConfig, out_path, *, planner=None, planner_factory=None, progress=None)
        -> RecordResult

A closed-loop planner meets the simulator only through ``scrapcut_cli.cell`` (the planner
contract); ``sim`` never imports ``exploration``.

pybullet and open3d load only when a function needs them.
"""

from __future__ import annotations

from scrapcut_cli.sim.objects import ScrapObject, list_objects, make_object
from scrapcut_cli.sim.recorder import RecordResult, record

__all__ = ["RecordResult", "ScrapObject", "list_objects", "make_object", "record"]
