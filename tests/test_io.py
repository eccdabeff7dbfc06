"""Atomic outputs: a file or folder appears whole or not at all, and never eats its parent."""

from __future__ import annotations

import errno
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import under_file_size_limit

from scrapcut_cli._io import STALE_AFTER_S, atomic_path, check_input_file, write_text_atomic
from scrapcut_cli.errors import FileError


def test_file_appears_only_on_success_with_normal_permissions(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "out.txt"
    write_text_atomic(target, "hello")
    assert target.read_text() == "hello"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "hello"
    assert sorted(p.name for p in target.parent.iterdir()) == ["out.txt"]


def test_folder_replaces_an_earlier_one_whole(tmp_path: Path) -> None:
    target = tmp_path / "clouds"
    target.mkdir()
    (target / "old.ply").write_text("old")
    with atomic_path(target, directory=True) as tmp:
        (tmp / "new.ply").write_text("new")
    assert sorted(p.name for p in target.iterdir()) == ["new.ply"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clouds"]


def test_a_folder_where_a_file_should_go_is_refused_before_writing(tmp_path: Path) -> None:
    (tmp_path / "taken").mkdir()  # a file cannot replace a folder
    with pytest.raises(FileError, match="is a folder"), atomic_path(tmp_path / "taken"):
        pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]
    (tmp_path / "file").write_text("x")
    with (
        pytest.raises(FileError, match="not a folder"),
        atomic_path(tmp_path / "file", directory=True),
    ):
        pass


def test_a_failed_rename_leaves_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def refuse(src: object, dst: object) -> None:
        raise OSError(errno.EXDEV, "Invalid cross-device link", str(dst))

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(OSError, match="cross-device"), atomic_path(tmp_path / "out") as tmp:
        tmp.write_text("data")
    assert list(tmp_path.iterdir()) == []


def test_the_current_folder_is_never_replaced(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "recording.mcap").write_text("precious")
    monkeypatch.chdir(tmp_path)
    for target in (".", ".."):
        with (
            pytest.raises(ValueError, match="holds its own temporary"),
            atomic_path(target, directory=True),
        ):
            pass
    assert (tmp_path / "recording.mcap").read_text() == "precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recording.mcap"]


def test_a_file_in_the_way_of_the_folder_is_named(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(NotADirectoryError) as info, atomic_path(blocker / "out.json"):
        pass
    assert info.value.filename == str(blocker)


# --------------------------------------------------------------------------- writes that cannot lie


@pytest.mark.parametrize("special", ["/dev/null", "fifo"])
def test_special_files_are_never_replaced(tmp_path: Path, special: str) -> None:
    target = Path(special)
    if special == "fifo":
        target = tmp_path / "fifo"
        os.mkfifo(target)
    before = os.stat(target).st_mode
    with pytest.raises(FileError, match="scrapcut writes regular files"):
        write_text_atomic(target, "data")
    assert os.stat(target).st_mode == before  # still the device / the pipe
    assert [p for p in tmp_path.iterdir() if p.name != "fifo"] == []


def test_a_link_is_written_through_and_a_link_loop_is_named(tmp_path: Path) -> None:
    real = tmp_path / "real.json"
    real.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(real)
    write_text_atomic(link, "new")
    assert link.is_symlink() and real.read_text() == "new"
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    with pytest.raises(FileError, match="symbolic link loop"):
        write_text_atomic(loop, "x")


def test_inputs_must_be_regular_files(tmp_path: Path) -> None:
    fifo = tmp_path / "rec.mcap"
    os.mkfifo(fifo)
    with pytest.raises(FileError, match=r"is a named pipe \(FIFO\), not a regular file"):
        check_input_file(fifo, "recording")  # returns at once: nothing opened the pipe
    with pytest.raises(FileError, match="is a folder"):
        check_input_file(tmp_path, "recording")
    with pytest.raises(FileError, match="not found"):
        check_input_file(tmp_path / "missing", "recording")
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(FileError, match="symbolic link loop"):
        check_input_file(tmp_path / "loop", "recording")
    (tmp_path / "ok").write_text("x")
    assert check_input_file(tmp_path / "ok") == tmp_path / "ok"


def test_a_disk_error_while_writing_names_the_output(tmp_path: Path) -> None:
    target = tmp_path / "out.json"
    with pytest.raises(OSError) as info, atomic_path(target):
        raise OSError(errno.ENOSPC, "No space left on device")  # as a full disk raises it
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(target)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(FileError, match="nothing was written"), atomic_path(target):
        pass  # a writer that wrote nothing
    assert list(tmp_path.iterdir()) == []


def test_a_file_too_large_for_the_disk_is_one_error_and_no_file(tmp_path: Path) -> None:
    import numpy as np

    from scrapcut_cli.commands.stitch import write_cloud
    from scrapcut_cli.recording.writer import McapWriter

    points = np.random.default_rng(0).random((5000, 3))

    def check() -> None:
        with pytest.raises(OSError) as info:
            write_text_atomic(tmp_path / "path.json", "x" * 50_000)
        assert info.value.errno == errno.EFBIG
        assert info.value.filename == str(tmp_path / "path.json")
        for name in ("cloud.ply", "cloud.pcd"):  # open3d reports success on a short file
            with pytest.raises(FileError, match="written incompletely"):
                write_cloud(tmp_path / name, points)
        with pytest.raises(OSError) as info, McapWriter(tmp_path / "x.mcap") as writer:
            writer.write_pointcloud("/p", 0, "base", points)
        assert info.value.filename == str(tmp_path / "x.mcap")

    under_file_size_limit(20_000, check)
    assert list(tmp_path.iterdir()) == []


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_stale_temporaries_of_killed_runs_are_removed_by_the_next_write(tmp_path: Path) -> None:
    dead, alive = _dead_pid(), os.getppid()
    old = time.time() - 2 * STALE_AFTER_S
    names = {
        f".out.json.{dead}.abcd1234.tmp": old,  # killed long ago: removed
        f".cloud.ply.{dead}.abcd_234.tmp.ply": old,  # open3d's staging name: removed
        f".young.json.{dead}.abcd1234.tmp": time.time(),  # may be in use: kept
        f".busy.json.{alive}.abcd1234.tmp": old,  # its process runs: kept
        ".notes.txt.tmp": old,  # not our pattern: kept
    }
    for name, mtime in names.items():
        (tmp_path / name).write_text("partial")
        os.utime(tmp_path / name, (mtime, mtime))
    folder = tmp_path / f".clouds.{dead}.zz99zz99.tmp"
    folder.mkdir()
    (folder / "paint_000001.ply").write_text("partial")
    for p in (folder / "paint_000001.ply", folder):
        os.utime(p, (old, old))
    write_text_atomic(tmp_path / "result.json", "{}")
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted(
        [
            ".young.json." + str(dead) + ".abcd1234.tmp",
            f".busy.json.{alive}.abcd1234.tmp",
            ".notes.txt.tmp",
            "result.json",
        ]
    )


SLOW_COMMAND = """
import time, click
from scrapcut_cli._io import atomic_path

@click.command("slow")
@click.argument("out")
def slow(out):
    with atomic_path(out) as tmp:
        tmp.write_text("half")
        print("writing", flush=True)
        time.sleep(60)
"""


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_a_termination_signal_removes_the_temporary(tmp_path: Path, signum: int) -> None:
    (tmp_path / "slowcmd.py").write_text(SLOW_COMMAND)
    script = (
        "import sys; sys.path.insert(0, sys.argv[1])\n"
        "from scrapcut_cli import cli\n"
        "cli.COMMANDS['slow'] = ('slowcmd', 'slow', 'test')\n"
        "sys.argv = ['scrapcut', 'slow', sys.argv[2]]\n"
        "cli.main()\n"
    )
    out = tmp_path / "out" / "result.json"
    child = subprocess.Popen(
        [sys.executable, "-c", script, str(tmp_path), str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None and child.stdout.readline().strip() == "writing"
    assert len(list(out.parent.iterdir())) == 1  # the temporary
    child.send_signal(signum)
    _, stderr = child.communicate(timeout=30)
    assert child.returncode == 128 + signum
    assert stderr.strip().splitlines() == [
        f"scrapcut: stopped by {signal.Signals(signum).name}; unfinished outputs were removed"
    ]
    assert list(out.parent.iterdir()) == []
