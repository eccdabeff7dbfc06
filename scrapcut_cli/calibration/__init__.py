"""Hand-eye and clock self-calibration from the scan itself (``scrapcut calibrate``).

Overlapping frames see the same surface and the same paint edges from different poses; with the
right camera mount and clock offset they coincide, with wrong ones they disagree in a way that
depends on the pose. Import submodules directly:

- ``observations``: per frame, surface samples with normals and paint-edge points (camera frame);
- ``solver``: pairs of overlapping frames, point-to-plane and paint-edge residuals, robust
  Gauss-Newton, eigen-analysis of the normal equations (observability), sigma per parameter;
- ``result``: the Calibration (mount to use, consistent or corrected, ``--json`` keys);
- ``calfile``: CAL.yaml with static_transform_publisher lines; reading it back;
- ``recipe``: ``calibrate_recording`` (reads a recording, the only I/O besides ``calfile``).
"""
