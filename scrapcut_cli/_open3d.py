"""The one place open3d is imported.

open3d's Linux wheels link against ``libusb-1.0.so.0`` (for RealSense support), which a bare
machine lacks. The ``libusb-package`` wheel ships that library; loading it with RTLD_GLOBAL
before open3d's extension module is loaded satisfies the dependency without a system package.

open3d (0.20 on) parallelises with oneAPI TBB, which does not read ``OMP_NUM_THREADS``: its
statistical outlier removal ran on every core even in a Dask worker whose nanny had set that
variable to 1, so two workers on two cores ran four threads there. The variable, when set, is
passed on (``open3d.utility.set_max_threads``, where the version has it).
"""

from __future__ import annotations

import ctypes
import functools
import os
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
    """Return the ``open3d`` module, loading its libusb dependency first, quiet and with at
    most ``OMP_NUM_THREADS`` threads when that is set."""
    _preload_libusb()
    import open3d

    open3d.utility.set_verbosity_level(open3d.utility.VerbosityLevel.Error)
    _limit_threads(open3d, os.environ.get("OMP_NUM_THREADS", ""))
    return open3d


@functools.cache
def _limit_threads(open3d: ModuleType, value: str) -> None:
    """``open3d.utility.set_max_threads(int(value))`` for a positive whole number of threads
    (once per value); nothing for anything else, or where open3d has no such call."""
    setter = getattr(open3d.utility, "set_max_threads", None)
    threads = int(value) if value.strip().isdecimal() else 0
    if setter is not None and threads > 0:
        setter(threads)
