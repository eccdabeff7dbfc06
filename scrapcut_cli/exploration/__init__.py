"""Algorithm 1: the next-view planner, its stopping criterion, and replay over recordings.

- ``planner``: :class:`~scrapcut_cli.exploration.planner.ExplorationPlanner` (pure,
  deterministic; a ``cell.ViewPlanner``), ``perceive`` (one frame's clouds), ``planner_factory``
  (for a cell's explore mode: the simulator's, or a robot driver's).
- ``occupancy``: the planner's obstacle map, built only from observed depth.
- ``evidence``: whether a frame taken so far observed a line's end.
- ``views``: camera poses from a target, a direction, a distance and a roll.
- ``replay``: ``replay_exploration`` (verify a recorded run against its log) and ``what_if``
  (run the planner over a dense recording's frames).

The contract with whoever moves the camera (``Decision``, ``ViewPlanner``, the reachability
query and answer, the planner's context) lives in :mod:`scrapcut_cli.cell`, which neither this
package nor ``sim`` owns. Nothing is imported here.
"""
