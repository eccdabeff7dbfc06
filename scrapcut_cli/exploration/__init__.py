"""Algorithm 1: the next-view planner, its stopping criterion, and replay over recordings.

- ``decision``: the contract between a planner and whoever moves the camera (``Decision``,
  ``ViewPlanner``, ``Reachability``).
- ``planner``: :class:`~scrapcut_cli.exploration.planner.ExplorationPlanner` (pure,
  deterministic), ``perceive`` (one frame's clouds), ``planner_factory`` (for the simulator's
  explore mode).
- ``occupancy``: the planner's obstacle map, built only from observed depth.
- ``views``: camera poses from a target, a direction, a distance and a roll.
- ``replay``: ``replay_exploration`` (verify a recorded run against its log) and ``what_if``
  (run the planner over a dense recording's frames).

Nothing is imported here: the simulator imports ``decision`` and must not pull in the rest.
"""
