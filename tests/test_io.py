"""Atomic outputs: a file or folder appears whole or not at all, and never eats its parent."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from scrapcut_cli._io import atomic_path, write_text_atomic


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


def test_a_failed_rename_leaves_no_temporary(tmp_path: Path) -> None:
    (tmp_path / "taken").mkdir()  # a file cannot replace a folder
    with pytest.raises(IsADirectoryError), atomic_path(tmp_path / "taken") as tmp:
        tmp.write_text("data")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


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
