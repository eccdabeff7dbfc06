"""Fuzz tests of the readers: mutated recordings give a one-line error or a valid result.

hypothesis drives structural mutations (``recording_faults``) of three small bases, as the
campaign (``benchmarks/fuzz_campaign.py``) does at length over the fixture: an MCAP with zstd
chunks and CRCs, the same uncompressed without CRCs (nothing but the readers' own checks
between a mutation and the parser), and a ROS 1 bag. Each case reads everything a command
would (summary, every frame, reference, metadata, exploration log) and must end in either a
result or a :class:`ScrapcutError` with a one-line message, within a time bound (SIGALRM) and
a memory bound (tracemalloc peak: a damaged length field must never be allocated).
Deterministic: ``derandomize=True``, no example database.
"""

from __future__ import annotations

import os
import resource
import signal
from collections.abc import Callable, Iterator
from pathlib import Path
from types import FrameType

import pytest
from click.testing import CliRunner
from helpers import synthetic_scan, write_scan
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from recording_faults import MCAP_MAGIC, DrawChoices, mutate, write_bases

from scrapcut_cli.cli import cli
from scrapcut_cli.config import RecordingConfig
from scrapcut_cli.errors import ScrapcutError
from scrapcut_cli.recording.reader import open_recording

#: A case of a recording this small that takes longer, or allocates more, has gone wrong.
CASE_SECONDS = 10
CASE_BYTES = 64 * 1024 * 1024

SETTINGS = settings(
    max_examples=30,
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


class Base:
    """One base recording's bytes, mutation format and file suffix (short repr: hypothesis
    prints its arguments)."""

    def __init__(self, name: str, data: bytes, fmt: str, suffix: str) -> None:
        self.name, self.data, self.fmt, self.suffix = name, data, fmt, suffix

    def __repr__(self) -> str:
        return f"Base({self.name}, {len(self.data)} bytes)"


Bases = dict[str, Base]


@pytest.fixture(scope="module")
def bases(tmp_path_factory: pytest.TempPathFactory) -> Bases:
    folder = tmp_path_factory.mktemp("fuzz_bases")
    scan = folder / "scan.mcap"
    write_scan(scan, synthetic_scan(n_frames=4, width=16, height=12), "mcap")
    return {
        name: Base(name, path.read_bytes(), fmt, path.suffix)
        for name, (path, fmt) in write_bases(scan, folder / "bases").items()
    }


class _Hang(Exception):
    pass


def _alarm(signum: int, frame: FrameType | None) -> None:
    raise _Hang


def _address_space() -> int:
    """Bytes of address space this process maps now (Linux)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")


@pytest.fixture
def bounded() -> Iterator[Callable[[], None]]:
    """SIGALRM as a hang detector, and a function that caps the address space at what is
    mapped now + CASE_BYTES until the test ends: an allocation past it fails (MemoryError),
    even one whose pages would never be touched."""
    previous = signal.signal(signal.SIGALRM, _alarm)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)

    def cap() -> None:
        limit = _address_space() + CASE_BYTES
        resource.setrlimit(resource.RLIMIT_AS, (limit if hard < 0 else min(limit, hard), hard))

    try:
        yield cap
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def read_everything(path: Path, *, salvage: bool = False) -> None:
    """What the commands read of a recording: what ``info`` shows, every frame, the
    reference, the exploration log (one opening: rosbags compiles its decoders per opening)."""
    with open_recording(path, RecordingConfig(salvage=salvage)) as rec:
        plan = rec.plan()
        _ = (rec.topics(), rec.camera, rec.metadata, rec.duration_s, rec.tf.frames)
        rec.tf.time_range(rec.base_frame, rec.camera_frame)
        assert sum(1 for _ in rec.frames()) == plan.usable
        rec.reference()
        rec.exploration_log()


def check_case(path: Path, cap: Callable[[], None], *, salvage: bool = False) -> str:
    """'ok' or 'error' for a case that ended properly; fails the test otherwise."""
    signal.alarm(CASE_SECONDS)
    try:
        cap()
        read_everything(path, salvage=salvage)
        outcome = "ok"
    except ScrapcutError as exc:
        message = str(exc)
        assert message.strip() and "\n" not in message.strip(), repr(message)
        # What an allocation from a damaged length field raises, even when it is wrapped.
        assert "MemoryError" not in message and "OverflowError" not in message, message
        outcome = "error"
    except _Hang:
        pytest.fail(f"reading {path.name} took over {CASE_SECONDS} s")
    except MemoryError:
        pytest.fail(f"reading {path.name} tried to allocate over {CASE_BYTES >> 20} MiB")
    finally:
        signal.alarm(0)
    return outcome


@pytest.mark.parametrize("base", ["mcap", "mcap-plain", "ros1"])
def test_the_unmutated_bases_read(
    bases: Bases, base: str, tmp_path: Path, bounded: Callable[[], None]
) -> None:
    b = bases[base]
    (tmp_path / f"case{b.suffix}").write_bytes(b.data)
    assert check_case(tmp_path / f"case{b.suffix}", bounded) == "ok"


def _fuzz(
    bases: Bases, base: str, folder: Path, data: st.DataObject, cap: Callable[[], None]
) -> str:
    b = bases[base]
    path = folder / f"case{b.suffix}"
    path.write_bytes(mutate(b.data, b.fmt, DrawChoices(data)))
    return check_case(path, cap, salvage=b.fmt == "mcap" and data.draw(st.booleans()))


@SETTINGS
@given(data=st.data())
def test_mutated_mcap_gives_one_line_or_a_result(
    bases: Bases, tmp_path: Path, bounded: Callable[[], None], data: st.DataObject
) -> None:
    _fuzz(bases, "mcap", tmp_path, data, bounded)


@SETTINGS
@given(data=st.data())
def test_mutated_uncompressed_mcap_without_crcs_gives_one_line_or_a_result(
    bases: Bases, tmp_path: Path, bounded: Callable[[], None], data: st.DataObject
) -> None:
    _fuzz(bases, "mcap-plain", tmp_path, data, bounded)


@SETTINGS
@given(data=st.data())
def test_mutated_ros1_bag_gives_one_line_or_a_result(
    bases: Bases, tmp_path: Path, bounded: Callable[[], None], data: st.DataObject
) -> None:
    _fuzz(bases, "ros1", tmp_path, data, bounded)


@settings(SETTINGS, max_examples=12)
@given(cut=st.integers(0, 10**6))
@example(cut=len(MCAP_MAGIC))  # what a recorder killed at once leaves
@example(cut=0)
def test_every_truncation_of_an_mcap_reads_or_fails_in_one_line(
    bases: Bases, tmp_path: Path, bounded: Callable[[], None], cut: int
) -> None:
    raw = bases["mcap-plain"].data
    path = tmp_path / "cut.mcap"
    path.write_bytes(raw[: cut % (len(raw) + 1)])
    assert check_case(path, bounded) == "error" or cut % (len(raw) + 1) == len(raw)
    # --salvage reads what is whole: a cut after the first messages still gives frames.
    check_case(path, bounded, salvage=True)


def test_salvage_reads_a_truncated_mcap_up_to_the_damage(bases: Bases, tmp_path: Path) -> None:
    raw = bases["mcap-plain"].data
    path = tmp_path / "cut.mcap"
    path.write_bytes(raw[: int(0.9 * len(raw))])
    with pytest.raises(ScrapcutError, match=r"truncated .*--salvage"):
        open_recording(path)
    with open_recording(path, RecordingConfig(salvage=True)) as rec:
        assert rec.salvaged is not None and rec.salvaged.stopped is not None
        assert rec.salvaged.messages > 0
        assert rec.plan().usable >= 1  # frames before the damage
        assert len(list(rec.frames())) == rec.plan().usable
    with open_recording(tmp_path / "cut.mcap", RecordingConfig(salvage=True)):
        pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cut.mcap"]  # no copy left behind


def test_the_command_line_reports_damage_in_one_line(bases: Bases, tmp_path: Path) -> None:
    b = bases["ros1"]
    path = tmp_path / f"bad{b.suffix}"
    path.write_bytes(b.data[: len(b.data) // 3])
    result = CliRunner().invoke(cli, ["info", str(path)])
    assert result.exit_code == 1 and "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("scrapcut: error: damaged ROS 1 bag")
    assert "rosbag reindex" in lines[0]
