"""Read a truncated or damaged MCAP up to the damage (``--salvage``).

A recorder that is killed leaves an MCAP without its summary and footer, often ending inside a
chunk. The mcap library's stream reader does not need the summary: it reads records front to
back and yields the messages of every complete (CRC-valid) chunk. :func:`salvage_mcap` copies
what it yields (schemas, channels, messages, metadata) into a new, complete MCAP, as ``mcap
recover`` does, and stops at the first record it cannot read; the copy is what the readers then
open. What was lost is reported, never guessed.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, cast

from scrapcut_cli.errors import RecordingError


@dataclass(frozen=True)
class SalvageReport:
    """What a salvage kept: messages, and how far into the file it read before the damage.

    ``stopped`` is None when the file was read to its end, else what stopped the reading.
    """

    messages: int
    bytes_read: int
    bytes_total: int
    stopped: str | None

    def describe(self) -> str:
        """One line for the user."""
        share = 100.0 * self.bytes_read / max(self.bytes_total, 1)
        text = f"salvaged {self.messages} messages from the first {share:.1f} % of the file"
        return text + (f" (then: {self.stopped})" if self.stopped else "")


def salvage_mcap(source: str | os.PathLike[str], target: str | os.PathLike[str]) -> SalvageReport:
    """Copy every readable record of the MCAP ``source`` into a new MCAP ``target``.

    Raises RecordingError if not even the header and one message could be read.
    """
    from mcap.records import Channel, Chunk, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk
    from mcap.writer import CompressionType, Writer

    source, target = Path(source), Path(target)
    total = source.stat().st_size
    messages = 0
    stopped: str | None = None
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    with source.open("rb") as raw, target.open("wb") as out:
        f = _Bounded(raw, total)
        writer = Writer(out, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="scrapcut salvage")
        # Chunks are opened here, after their claimed size is checked: the mcap library would
        # allocate whatever a damaged size field says.
        reader = StreamReader(
            cast(IO[bytes], f), validate_crcs=True, record_size_limit=total, emit_chunks=True
        )
        position = 0
        try:
            for record in _unchunked(reader.records, Chunk, breakup_chunk):
                if isinstance(record, Schema):
                    if record.id not in schema_ids:
                        schema_ids[record.id] = writer.register_schema(
                            record.name, record.encoding, record.data
                        )
                elif isinstance(record, Channel):
                    if record.id not in channel_ids and record.schema_id in schema_ids:
                        channel_ids[record.id] = writer.register_channel(
                            record.topic,
                            record.message_encoding,
                            schema_ids[record.schema_id],
                            record.metadata,
                        )
                elif isinstance(record, Message):
                    if record.channel_id in channel_ids:
                        writer.add_message(
                            channel_ids[record.channel_id],
                            record.log_time,
                            record.data,
                            record.publish_time,
                            record.sequence,
                        )
                        messages += 1
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, dict(record.metadata))
                position = raw.tell()
        except Exception as exc:  # whatever the damage looks like, stop there
            stopped = _reason(exc)
        writer.finish()
    if messages == 0:
        raise RecordingError(
            f"nothing could be salvaged from {source}: {stopped or 'it holds no messages'}"
        )
    return SalvageReport(messages, position, total, stopped)


#: No recorder writes chunks this large (they write KiB to a few MiB).
MAX_CHUNK_BYTES = 1 << 28


class _Bounded:
    """A binary file whose reads never ask for more than the file holds: the mcap library
    sizes its buffers by the length fields it reads, damaged or not."""

    def __init__(self, f: Any, size: int) -> None:
        self.f, self.size = f, size

    def read(self, n: int = -1) -> bytes:
        left = max(self.size - self.f.tell(), 0)
        return bytes(self.f.read(left if n is None or n < 0 else min(n, left)))

    def tell(self) -> int:
        return int(self.f.tell())


def _unchunked(records: Any, chunk_type: type, breakup: Any) -> Any:
    """Records with each chunk replaced by its records, once its claimed size is checked."""
    for record in records:
        if isinstance(record, chunk_type):
            size = int(record.uncompressed_size)  # type: ignore[attr-defined]
            compression = record.compression  # type: ignore[attr-defined]
            if size > MAX_CHUNK_BYTES or compression not in ("", "zstd", "lz4"):
                raise ValueError(f"a chunk claims {size} bytes ({compression or 'plain'})")
            if compression == "" and size != len(record.data):  # type: ignore[attr-defined]
                raise ValueError("a chunk's size disagrees with its data")
            yield from breakup(record, validate_crc=True)
        else:
            yield record


def _reason(exc: Any) -> str:
    text = " ".join(str(exc).split())
    name = type(exc).__name__
    if "EndOfFile" in name or not text:
        return "the file ends inside a record" if "EndOfFile" in name else name
    return f"{name}: {text}"[:200]
