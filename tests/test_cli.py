"""Tests of the command group itself: help, version, lazy imports, error mapping."""

from __future__ import annotations

import subprocess
import sys

import click
from click.testing import CliRunner

from scrapcut_cli import __version__
from scrapcut_cli.cli import LazyGroup, cli
from scrapcut_cli.errors import RecordingError


def test_version() -> None:
    result = CliRunner().invoke(cli, ["--version"])
    assert result.exit_code == 0
    assert __version__ in result.output


def test_help_does_not_import_heavy_libraries() -> None:
    code = (
        "import sys; from scrapcut_cli.cli import cli\n"
        "try:\n    cli(['--help'], standalone_mode=False)\nexcept SystemExit:\n    pass\n"
        "heavy = [m for m in ('numpy', 'open3d', 'pybullet', 'scipy', 'matplotlib', 'rosbags')"
        " if m in sys.modules]\n"
        "print('HEAVY:' + ','.join(heavy))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "HEAVY:"


def test_python_m_entry_point() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "scrapcut_cli", "--version"], capture_output=True, text=True
    )
    assert out.returncode == 0 and __version__ in out.stdout


def test_known_error_is_one_line_exit_1() -> None:
    @click.group(cls=LazyGroup)
    def group() -> None:
        pass

    @group.command()
    def boom() -> None:
        raise RecordingError("no topic /x; image topics: /a, /b\nsecond line dropped")

    # LazyGroup.get_command only knows registered modules; register the test command directly.
    group.get_command = lambda ctx, name: boom if name == "boom" else None  # type: ignore[method-assign]
    group.list_commands = lambda ctx: ["boom"]  # type: ignore[method-assign]
    result = CliRunner().invoke(group, ["boom"])
    assert result.exit_code == 1
    assert result.output.strip() == "scrapcut: error: no topic /x; image topics: /a, /b"
    assert "Traceback" not in result.output


def _group_raising(exc: BaseException) -> click.Group:
    @click.group(cls=LazyGroup)
    def group() -> None:
        pass

    @group.command()
    def boom() -> None:
        raise exc

    group.get_command = lambda ctx, name: boom if name == "boom" else None  # type: ignore[method-assign]
    group.list_commands = lambda ctx: ["boom"]  # type: ignore[method-assign]
    return group


def test_os_error_on_a_named_file_is_one_line_exit_1() -> None:
    denied = PermissionError(13, "Permission denied", "/results/path.json")
    result = CliRunner().invoke(_group_raising(denied), ["boom"])
    assert result.exit_code == 1
    assert result.output.strip() == "scrapcut: error: Permission denied: /results/path.json"
    # Without a file name it is no user error: the exception escapes (a traceback).
    result = CliRunner().invoke(_group_raising(OSError("socket trouble")), ["boom"])
    assert isinstance(result.exception, OSError) and result.exit_code != 0


def test_unknown_command_is_usage_error() -> None:
    result = CliRunner().invoke(cli, ["frobnicate"])
    assert result.exit_code == 2
