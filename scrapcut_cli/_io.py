"""Outputs that cannot lie, inputs that cannot hang.

Every output is written under a temporary name beside the target and renamed onto it only when
the writer finished, the data reached the disk (``fsync``) and the file passed its size check,
so a failed, interrupted or disk-full command never leaves a half-written output, and never
reports one as written. Outputs are regular files or folders (or new paths): a device, a FIFO or
a socket is refused rather than replaced. Inputs must be regular files (a FIFO would block the
reader forever).

Temporaries are named ``.<target name>.<pid>.<random>.tmp[<suffix>]``. A SIGINT or SIGTERM
(``cli.main`` turns it into an exception) removes them on the way out; a SIGKILL cannot, so
:func:`atomic_path` also removes stale ones of this pattern in the folder it writes to: older
than :data:`STALE_AFTER_S` and whose process is gone.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import stat
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from scrapcut_cli.errors import FileError

#: A temporary older than this whose process is gone is left over from a killed run.
STALE_AFTER_S = 600.0
_TMP_NAME = re.compile(r"\.(?P<name>.+)\.(?P<pid>\d+)\.[a-z0-9_]{8}\.tmp(\.[A-Za-z0-9]+)?")
_swept: set[str] = set()


def real_path(path: str | os.PathLike[str]) -> Path:
    """``path`` with every link resolved, absolute; unlike ``Path.resolve`` (Python 3.11) it
    does not raise on a symbolic link loop (the loop is reported where the path is opened)."""
    return Path(os.path.realpath(path))


def file_kind(mode: int) -> str:
    """What a stat mode describes, for messages ("a named pipe (FIFO)", "a folder"...)."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a regular file" if stat.S_ISREG(mode) else "not a regular file"


def _stat(path: Path, what: str) -> os.stat_result | None:
    """``os.stat`` following links; None if nothing is there; FileError for a link loop."""
    try:
        return path.stat()
    except (FileNotFoundError, NotADirectoryError):  # a file where a folder should be: the
        return None  # caller's mkdir names it
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise FileError(f"{what} {path} is a symbolic link loop") from None
        if exc.errno == errno.ENAMETOOLONG:
            raise FileError(f"{what} name is too long: {str(path)[:80]}...") from None
        raise OSError(exc.errno, exc.strerror, str(path)) from None


def check_input_file(path: str | os.PathLike[str], what: str = "input") -> Path:
    """``path`` if it is an existing regular file (links followed), else FileError naming it.

    A named pipe, a device or a socket is refused before anything opens it: reading a FIFO
    blocks until a writer appears, which for a recording means forever.
    """
    path = Path(path)
    st = _stat(path, what)
    if st is None:
        raise FileError(f"{what} not found: {path}")
    if not stat.S_ISREG(st.st_mode):
        raise FileError(f"{what} {path} is {file_kind(st.st_mode)}, not a regular file")
    return path


def read_text_input(
    path: str | os.PathLike[str], what: str = "input", *, max_bytes: int = 1 << 28
) -> str:
    """The UTF-8 text of a regular file (a byte-order mark is dropped), or FileError naming
    ``what``: missing, not a regular file, larger than ``max_bytes``, unreadable, not UTF-8."""
    path = check_input_file(path, what)
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise FileError(f"{what} {path} is {size} bytes, more than a {what} holds")
        data = path.read_bytes()
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileError(
            f"{what} {path} is not UTF-8 text ({exc.reason} at byte {exc.start})"
        ) from None
    except OSError as exc:
        raise FileError(f"cannot read {what} {path}: {exc.strerror or exc}") from None


def check_output_path(target: str | os.PathLike[str], *, directory: bool = False) -> Path:
    """Where ``target`` really is (symbolic links followed), if it may be (re)written.

    A file output may replace a regular file or create a new one; a folder output may replace
    a folder. Devices (``/dev/null``), FIFOs and sockets are refused: renaming onto them would
    replace the node itself.
    """
    target = Path(target)
    st = _stat(target, "output")
    if st is None:
        if target.is_symlink():  # a dangling link: write where it points
            return Path(os.path.realpath(target))
        return target
    if directory:
        if not stat.S_ISDIR(st.st_mode):
            raise FileError(f"output {target} is {file_kind(st.st_mode)}, not a folder")
    elif not stat.S_ISREG(st.st_mode):
        raise FileError(
            f"output {target} is {file_kind(st.st_mode)}; scrapcut writes regular files "
            "(give a file name)"
        )
    return Path(os.path.realpath(target)) if target.is_symlink() else target


@contextlib.contextmanager
def atomic_path(
    target: str | os.PathLike[str],
    *,
    directory: bool = False,
    verify: Callable[[Path], None] | None = None,
) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; rename it onto ``target`` on success.

    After the block the temporary is flushed to disk and checked: a file must not be empty,
    and ``verify(tmp)`` (if given) may raise to refuse it (a writer that reports success on
    a full disk). On any exception, SIGTERM included, the temporary is removed and ``target``
    is untouched. An OS error without a file name (a full disk while writing) is re-raised
    naming ``target``.
    """
    target = check_output_path(target, directory=directory)
    parent = target.parent if str(target.parent) else Path(".")
    if directory and (
        real_path(target) == real_path(parent) or real_path(target) in real_path(parent).parents
    ):
        # "." or ".." as a folder output: replacing it would delete the temporary inside it.
        raise ValueError(f"cannot replace {target}: it holds its own temporary")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(parent)
        prefix = f".{target.name}.{os.getpid()}."
        if directory:
            tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=".tmp", dir=parent))
            # mkdtemp creates 0700 folders; outputs get the user's normal permissions (0755).
            os.chmod(tmp, 0o777 & ~_umask())
        else:
            fd, name = tempfile.mkstemp(prefix=prefix, suffix=".tmp", dir=parent)
            os.close(fd)
            tmp = Path(name)
    except FileExistsError:  # mkdir met a file where a folder should be
        raise NotADirectoryError(errno.ENOTDIR, "Not a folder", str(parent)) from None
    except OSError as exc:  # name the output the user asked for, not our temporary
        raise OSError(exc.errno, exc.strerror, str(target)) from None
    try:
        try:
            yield tmp
            _sync(tmp, target, directory=directory)
            if verify is not None:
                verify(tmp)
        except OSError as exc:
            if exc.filename is None or str(tmp) in str(exc.filename):
                raise OSError(exc.errno, exc.strerror, str(target)) from None
            raise
        if directory and target.is_dir():
            shutil.rmtree(target)
        os.replace(tmp, target)  # fails, e.g., onto an existing folder: no temporary is left
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise
    _sync_folder(parent)
    if not directory:
        # mkstemp creates 0600 files; outputs should get the user's normal permissions.
        os.chmod(target, 0o666 & ~_umask())


def _umask() -> int:
    """The process's file mode creation mask (read without changing it for long)."""
    umask = os.umask(0)
    os.umask(umask)
    return umask


def prepare_output(
    target: str | os.PathLike[str],
    *,
    force: bool = False,
    parents: bool = False,
    directory: bool = False,
    option: str = "-o",
) -> Path:
    """Check a user-named output before any work, as good command-line tools do.

    - an existing ``target`` is replaced only with ``force`` (the message says so); an empty
      folder, as a folder output, is not in the way;
    - a missing parent folder is an error unless ``parents``, which creates it (0755, like
      ``mkdir -p``): a typo in a folder name must not silently grow a tree;
    - then :func:`check_output_path` (no devices, FIFOs, link loops).

    Returns where the output really is. Raises FileError naming ``option``.
    """
    path = Path(target)
    parent = path.parent if str(path.parent) else Path(".")
    if _stat(parent, "output folder") is None:
        if not parents:
            raise FileError(
                f"{option} {path}: folder {parent} does not exist (create it, or add --parents)"
            )
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            raise FileError(f"{option} {path}: {parent} is not a folder") from None
    elif not parent.is_dir():
        raise FileError(f"{option} {path}: {parent} is not a folder")
    real = check_output_path(path, directory=directory)
    empty_folder = directory and path.is_dir() and not any(path.iterdir())
    if not force and not empty_folder and (path.exists() or path.is_symlink()):
        kind = "folder" if path.is_dir() else "file"
        raise FileError(f"{option} {path}: the {kind} exists; add --force to replace it")
    return real


def _sync(tmp: Path, target: Path, *, directory: bool) -> None:
    """fsync the temporary (every file of a folder); an empty file is a failed write."""
    files = [p for p in tmp.rglob("*") if p.is_file()] if directory else [tmp]
    for path in files:
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
            size = os.fstat(fd).st_size
        finally:
            os.close(fd)
        if size == 0 and not directory:
            raise FileError(f"nothing was written to {target} (is the disk full?)")


def _sync_folder(folder: Path) -> None:
    """fsync a folder, so a rename into it survives a crash (not every file system can)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def remove_stale_temporaries(folder: Path, *, now: float | None = None) -> list[Path]:
    """Remove our temporaries left in ``folder`` by killed runs; return what was removed.

    Only names of our pattern are touched, and only when older than :data:`STALE_AFTER_S`
    and their process no longer runs on this machine. Each folder is swept once per process.
    """
    key = os.path.abspath(folder)
    if now is None and key in _swept:
        return []
    _swept.add(key)
    now = time.time() if now is None else now
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    for entry in entries:
        match = _TMP_NAME.fullmatch(entry.name)
        if match is None or int(match["pid"]) == os.getpid() or _alive(int(match["pid"])):
            continue
        try:
            if now - _newest_mtime(Path(entry.path)) < STALE_AFTER_S:
                continue
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
        except OSError:
            continue
        removed.append(Path(entry.path))
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True  # another user's process, or a number we cannot judge: keep the file
    return True


def _newest_mtime(path: Path) -> float:
    """Modification time of a file, or the newest of a folder and its direct entries (a
    folder being filled by a live writer changes within)."""
    newest = path.lstat().st_mtime
    if path.is_dir() and not path.is_symlink():
        for entry in os.scandir(path):
            newest = max(newest, entry.stat(follow_symlinks=False).st_mtime)
    return newest


@contextlib.contextmanager
def quiet_stderr() -> Iterator[None]:
    """Silence file descriptor 2 for a block: C libraries (open3d's PLY writer) print their
    own complaints there, which would break the one-line error a command reports instead."""
    import sys

    with contextlib.suppress(ValueError, OSError):
        sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all
        yield
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, 2)
        finally:
            os.close(devnull)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def write_text_atomic(target: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``target`` atomically (UTF-8), checking the size that reached disk."""
    data = text.encode("utf-8")

    def verify(tmp: Path) -> None:
        if tmp.stat().st_size != len(data):
            raise FileError(f"{target} was written incompletely (is the disk full?)")

    with atomic_path(target, verify=verify) as tmp, tmp.open("wb") as f:
        f.write(data)
