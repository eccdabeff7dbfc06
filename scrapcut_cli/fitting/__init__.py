"""Curve fitters: open NURBS and 3-D skeletonisation."""
