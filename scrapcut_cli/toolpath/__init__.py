"""Cutting set-points: normals, standoff, torch orientation, collision check, speeds, timing."""
