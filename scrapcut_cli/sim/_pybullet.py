"""The one place pybullet is imported, with its C-level chatter kept off stdout.

pybullet prints its build time when imported and a few lines when connecting or loading URDFs,
straight to the C-level standard streams; a library must not print, and a command's stderr
carries one line per error. Both descriptors are redirected while those calls run.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterator
from types import ModuleType


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Send file descriptors 1 and 2 to /dev/null for the duration (C printf included)."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = (os.dup(1), os.dup(2))
    except OSError:  # no standard descriptors (embedded interpreters): nothing to hide
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        _flush_c_stdio()  # C printf buffers; flush while the descriptors still point nowhere
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])
        os.close(devnull)


def _flush_c_stdio() -> None:
    # No C library handle (unusual platforms): nothing buffered we could reach.
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).fflush(None)


def pybullet() -> ModuleType:
    """The ``pybullet`` module, imported quietly."""
    if "pybullet" not in sys.modules:
        with quiet_stdout():
            import pybullet  # noqa: F401
    return sys.modules["pybullet"]
