"""scrapcut: cutting paths for robotic metal scrap cutting from scans of a spray-painted line."""

__version__ = "0.1.0"
