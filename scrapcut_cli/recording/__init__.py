"""Reading and writing recordings (MCAP, ROS 1 bags, ROS 2 bags); the only code that imports
mcap and rosbags. Import submodules directly: ``from scrapcut_cli.recording.frame import Frame``.

- ``frame``: the data model (CameraModel, Frame); numpy only.
- ``reader``: ``open_recording`` -> Recording (plan, frames, reference, exploration log).
- ``tf``: TfBuffer, /tf interpolation and /tf_static composition.
- ``writer``: McapWriter, ROS 2 MCAP output (simulator, exports).
- ``messages``: ROS message construction and decoding shared by all of the above.
- ``convert``: MCAP <-> ROS 1 bag <-> ROS 2 bag.
- ``summary``: what ``scrapcut info`` reports.
"""
