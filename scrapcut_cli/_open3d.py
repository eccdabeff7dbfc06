"""The one place open3d is imported.

open3d's Linux wheels link against ``libusb-1.0.so.0`` (for RealSense support), which a bare
machine lacks. The ``libusb-package`` wheel ships that library; loading it with RTLD_GLOBAL
before open3d's extension module is loaded satisfies the dependency without a system package.
"""

from __future__ import annotations

import ctypes
import functools
from types import ModuleType


@functools.cache
def _preload_libusb() -> None:
    try:
        import libusb_package

        path = libusb_package.get_library_path()
    except Exception:  # fall back to a system libusb if the wheel is odd
        return
    if path is not None:
        ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)


def o3d() -> ModuleType:
    """Return the ``open3d`` module, loading its libusb dependency first."""
    _preload_libusb()
    import open3d

    open3d.utility.set_verbosity_level(open3d.utility.VerbosityLevel.Error)
    return open3d
