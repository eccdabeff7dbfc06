"""Atomic output: every file is written under a temporary name and renamed at the end."""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str], *, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; rename it onto ``target`` on success.

    On any exception the temporary file (or directory) is removed and ``target`` is untouched,
    so a failed command never leaves a half-written output.
    """
    target = Path(target)
    parent = target.parent if str(target.parent) else Path(".")
    if directory and (
        target.resolve() == parent.resolve() or target.resolve() in parent.resolve().parents
    ):
        # "." or ".." as a folder output: replacing it would delete the temporary inside it.
        raise ValueError(f"cannot replace {target}: it holds its own temporary")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        if directory:
            tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=parent))
        else:
            fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=parent)
            os.close(fd)
            tmp = Path(name)
    except FileExistsError:  # mkdir met a file where a folder should be
        raise NotADirectoryError(errno.ENOTDIR, "Not a folder", str(parent)) from None
    except OSError as exc:  # name the output the user asked for, not our temporary
        raise OSError(exc.errno, exc.strerror, str(target)) from None
    try:
        yield tmp
        if directory and target.is_dir():
            shutil.rmtree(target)
        os.replace(tmp, target)  # fails, e.g., onto an existing folder: no temporary is left
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise
    if not directory:
        # mkstemp creates 0600 files; outputs should get the user's normal permissions.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(target, 0o666 & ~umask)


def write_text_atomic(target: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``target`` atomically (UTF-8)."""
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
