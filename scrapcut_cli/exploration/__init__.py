"""Algorithm 1: the next-view planner, its stopping criterion, and replay over recordings."""
