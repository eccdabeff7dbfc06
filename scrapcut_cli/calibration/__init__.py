"""Hand-eye and clock self-calibration from the scan itself (``scrapcut calibrate``).

Overlapping frames see the same surface and the same paint edges from different poses; with the
right camera mount and clock offset they coincide, with wrong ones they disagree in a way that
depends on the pose. Import submodules directly:

- ``observations``: per frame, surface samples with normals and paint-edge points (camera frame);
- ``residuals``: the problem: frames posed with a candidate mount and clock offset, which
  frames overlap, point-to-plane and paint-edge residuals with analytic Jacobians, weights;
- ``solver``: robust Gauss-Newton, eigen-analysis of the normal equations (observability),
  unobservable directions held at the published values, sigma per parameter;
- ``explain``: why a direction is unobservable, in words;
- ``result``: the Calibration (mount to use, consistent or corrected, ``--json`` keys);
- ``calfile``: CAL.yaml with static_transform_publisher lines; reading it back;
- ``recipe``: ``calibrate_recording`` (reads a recording, the only I/O besides ``calfile``).
"""
