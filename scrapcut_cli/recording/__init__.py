"""Reading and writing recordings (MCAP, ROS 1 bags, ROS 2 bags); the only code that imports
mcap and rosbags. Import submodules directly: ``from scrapcut_cli.recording.frame import Frame``.
"""
