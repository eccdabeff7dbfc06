"""The ``scrapcut`` command group.

Subcommands live in ``scrapcut_cli.commands.<name>`` and are imported only when run, so
``scrapcut --help`` does not pay for numpy, open3d or pybullet. A :class:`ScrapcutError` becomes
one line on stderr and exit code 1, as does an OS error on a named file (permission denied, disk
full); usage errors exit with 2 (click's default). SIGTERM and SIGHUP (what ``timeout``, systemd
and schedulers send) unwind like Ctrl-C, so unfinished outputs are removed, and exit with
128 + the signal number. numpy's RuntimeWarnings are not shown: results are checked where
they are made (a non-finite number never reaches an output file).
"""

from __future__ import annotations

import importlib
import importlib.util
import signal
import sys
import warnings
from types import FrameType
from typing import Any

import click

from scrapcut_cli import __version__
from scrapcut_cli.errors import ScrapcutError

# name -> (module, function, one-line help shown by `scrapcut --help`)
COMMANDS: dict[str, tuple[str, str, str]] = {
    "info": ("scrapcut_cli.commands.info", "info", "Describe a recording: topics, camera, frames."),
    "record": (
        "scrapcut_cli.commands.record",
        "record",
        "Simulate a scan of a painted scrap piece into an MCAP.",
    ),
    "filter": (
        "scrapcut_cli.commands.filter",
        "filter_cmd",
        "Per-frame paint clouds (MCAP or PLY folder).",
    ),
    "stitch": (
        "scrapcut_cli.commands.stitch",
        "stitch",
        "Stitched paint cloud of a recording (PLY/PCD).",
    ),
    "fit": ("scrapcut_cli.commands.fit", "fit", "Fit the cut curve and write the cutting path."),
    "explore": (
        "scrapcut_cli.commands.explore",
        "explore",
        "Replay Algorithm 1 over a recording (or tune it with --what-if).",
    ),
    "eval": (
        "scrapcut_cli.commands.eval",
        "eval_cmd",
        "Path error against the painted reference (Table I).",
    ),
    "reproduce": (
        "scrapcut_cli.commands.reproduce",
        "reproduce",
        "The paper's Table I end to end on the simulator.",
    ),
    "calibrate": (
        "scrapcut_cli.commands.calibrate",
        "calibrate",
        "Camera mount and clock offset, estimated from the scan.",
    ),
    "convert": (
        "scrapcut_cli.commands.convert",
        "convert",
        "Convert a recording to MCAP, a ROS 1 bag or a ROS 2 bag.",
    ),
    "batch": (
        "scrapcut_cli.commands.batch",
        "batch",
        "Fit many recordings × a parameter grid on Dask; one table of results.",
    ),
    "trajectory": (
        "scrapcut_cli.commands.trajectory",
        "trajectory",
        "Joint trajectory of the Panda that cuts a path.",
    ),
    "simulate-cut": (
        "scrapcut_cli.commands.simulate_cut",
        "simulate_cut",
        "Play a joint trajectory in pybullet and measure it.",
    ),
}


class KnownError(click.ClickException):
    """A ScrapcutError on its way out: one line, exit code 1."""

    exit_code = 1

    def show(self, file: Any = None) -> None:
        click.echo(f"scrapcut: error: {self.format_message()}", err=True)


class LazyGroup(click.Group):
    """A group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [name for name in COMMANDS if _available(name)]

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in COMMANDS or not _available(cmd_name):
            return None
        module_name, attr, _ = COMMANDS[cmd_name]
        command = getattr(importlib.import_module(module_name), attr)
        assert isinstance(command, click.Command)
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][2]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except ScrapcutError as exc:
            message = str(exc).strip().splitlines()
            raise KnownError(message[0] if message else type(exc).__name__) from exc
        except OSError as exc:
            # The file system refused a named file (no permission, disk full, a folder where a
            # file should go): the user's to fix, not a bug. Other OS errors keep the traceback.
            if exc.filename is None:
                raise
            reason = exc.strerror or type(exc).__name__
            raise KnownError(f"{reason}: {exc.filename}") from exc


def _available(name: str) -> bool:
    """True if the command's module exists (commands land one issue at a time)."""
    module_name = COMMANDS[name][0]
    return importlib.util.find_spec(module_name) is not None


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="scrapcut")
def cli() -> None:
    """scrapcut: cutting paths for robotic metal scrap cutting.

    Reads eye-in-hand RGB-D recordings (MCAP, ROS 1 bags, ROS 2 bags) of a spray-painted line,
    fits the line in 3-D (open NURBS or skeletonisation), generates torch set-points, and
    measures the path against the painted reference.
    """


class Terminated(BaseException):
    """A termination signal arrived: unwinds the command like Ctrl-C (``finally`` blocks and
    the atomic writers' cleanup run), never caught by ``except Exception``."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _terminate(signum: int, frame: FrameType | None) -> None:
    # Once is enough: a second signal must not interrupt the cleanup the first one started.
    for sig in _TERMINATING:
        signal.signal(sig, signal.SIG_IGN)
    raise Terminated(signum)


_TERMINATING = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))


def main() -> None:
    """Console-script entry point."""
    for sig in _TERMINATING:
        signal.signal(sig, _terminate)
    warnings.simplefilter("ignore", RuntimeWarning)
    try:
        cli(prog_name="scrapcut")
    except Terminated as exc:
        name = signal.Signals(exc.signum).name
        click.echo(f"scrapcut: stopped by {name}; unfinished outputs were removed", err=True)
        sys.exit(128 + exc.signum)
