"""scrapcut: cutting paths for robotic metal scrap cutting from scans of a spray-painted line.

Importing the package makes a later ``import open3d`` work without a system libusb
(:mod:`scrapcut_cli._open3d_hook`).
"""

import scrapcut_cli._open3d_hook  # noqa: F401  (installs the open3d preload finder)

__version__ = "0.1.0"
