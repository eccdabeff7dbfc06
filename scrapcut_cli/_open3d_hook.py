"""Make a plain ``import open3d`` work in scrapcut's environment (no system libusb needed).

open3d's Linux wheels link against ``libusb-1.0.so.0``; :mod:`scrapcut_cli._open3d` loads the
copy the ``libusb-package`` wheel ships before open3d is imported. This module extends that to
Python users of the library who write ``import open3d`` themselves: :func:`install` puts a
finder on ``sys.meta_path`` that, the first time ``open3d`` is looked up, preloads libusb and
then steps aside (it finds nothing itself; the normal finders import open3d). Nothing is loaded
until open3d is imported, so the cost at start-up is one list entry.

It is installed by ``import scrapcut_cli`` and, in the venv ``make`` builds, by the
``scrapcut_open3d.pth`` file the Makefile writes into site-packages (so ``python -c "import
open3d"`` works there too; see docs/python.md).
"""

from __future__ import annotations

import importlib.abc
import sys
from collections.abc import Sequence
from importlib.machinery import ModuleSpec
from types import ModuleType


class _Open3dPreload(importlib.abc.MetaPathFinder):
    """Preloads libusb when ``open3d`` is about to be imported; finds nothing itself."""

    def find_spec(
        self,
        fullname: str,
        path: Sequence[str] | None,
        target: ModuleType | None = None,
    ) -> ModuleSpec | None:
        if fullname == "open3d":
            from scrapcut_cli._open3d import _preload_libusb

            _preload_libusb()
        return None


def install() -> None:
    """Add the finder once (idempotent)."""
    if not any(isinstance(f, _Open3dPreload) for f in sys.meta_path):
        sys.meta_path.insert(0, _Open3dPreload())


install()
