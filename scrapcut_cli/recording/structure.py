"""Structural checks of MCAP files and ROS 1 bags before a library reads them.

rosbags (and the mcap library) trust the length and offset fields of a recording: a damaged
length makes them allocate whatever it says (a MemoryError or OverflowError for 2**60 bytes), a
damaged offset makes them parse the wrong bytes. These checks walk the top-level records with
seeks, reading only record headers (a few bytes each; chunks and messages are not decoded),
and refuse a file whose lengths or offsets do not fit inside it, or whose index points at
anything but the record it names. What passes is safe to hand to the readers: every length they
will use is bounded by the file's size. What the walk cannot see (bytes inside compressed
chunks, message payloads) the readers check themselves, and :mod:`.reader` wraps whatever they
raise.

Formats: MCAP (https://mcap.dev/spec): magic, records ``opcode u8 | length u64 | content``,
footer, magic. ROS 1 bag v2.0 (http://wiki.ros.org/Bags/Format/2.0): ``#ROSBAG V2.0``, records
``header_len u32 | header (fields: len u32, name=value) | data_len u32 | data``.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from scrapcut_cli.errors import RecordingError

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROS1_MAGIC = b"#ROSBAG V2.0\n"

# MCAP opcodes
_HEADER, _FOOTER, _SCHEMA, _CHANNEL, _MESSAGE, _CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
_MESSAGE_INDEX, _CHUNK_INDEX, _ATTACHMENT, _ATTACHMENT_INDEX = 0x07, 0x08, 0x09, 0x0A
_STATISTICS, _METADATA, _METADATA_INDEX, _SUMMARY_OFFSET, _DATA_END = 0x0B, 0x0C, 0x0D, 0x0E, 0x0F
#: Schema encodings the ROS readers understand (rosbags' table; anything else fails there).
SCHEMA_ENCODINGS = ("ros2msg", "ros2idl", "omgidl", "")
CHUNK_COMPRESSIONS = ("", "zstd", "lz4")
ROS1_COMPRESSIONS = ("none", "bz2", "lz4")
#: A chunk larger than this is no recorder's (they write KiB to a few MiB); decompressing what a
#: damaged size field claims could take the machine's memory.
MAX_CHUNK_BYTES = 1 << 32


class Damaged(RecordingError):
    """The recording's structure is damaged; the message says where."""


@dataclass
class McapLayout:
    """What the walk found: record offsets by opcode, the footer, whether the file ends
    properly (``complete``), and where the last whole record ends."""

    size: int
    records: dict[int, int] = field(default_factory=dict)  # offset -> opcode
    lengths: dict[int, int] = field(default_factory=dict)  # offset -> content length
    chunks: dict[int, tuple[int, int, str]] = field(default_factory=dict)  # offset -> sizes
    complete: bool = False
    end_of_records: int = 0
    summary_start: int = 0


class _Reader:
    """Bounded reads of a file: every read names the offset it failed at."""

    def __init__(self, f: BinaryIO, size: int) -> None:
        self.f, self.size = f, size

    def read(self, offset: int, n: int, what: str) -> bytes:
        if offset < 0 or n < 0 or offset + n > self.size:
            raise Damaged(f"{what} at byte {offset} runs past the end of the file")
        self.f.seek(offset)
        data = self.f.read(n)
        if len(data) != n:
            raise Damaged(f"{what} at byte {offset} is cut off")
        return data


def _u(fmt: str, data: bytes, offset: int = 0) -> tuple[int, ...]:
    return struct.unpack_from("<" + fmt, data, offset)


def _string(content: bytes, pos: int, what: str) -> tuple[str, int]:
    """A u32-prefixed string inside a record's content; (text, next position)."""
    if pos + 4 > len(content):
        raise Damaged(f"{what} is cut off")
    (n,) = _u("I", content, pos)
    if pos + 4 + n > len(content):
        raise Damaged(f"{what} is longer than its record")
    try:
        return content[pos + 4 : pos + 4 + n].decode("utf-8"), pos + 4 + n
    except UnicodeDecodeError:
        raise Damaged(f"{what} is not UTF-8") from None


def check_mcap(path: str | os.PathLike[str], *, allow_truncated: bool = False) -> McapLayout:
    """Walk an MCAP file's records; raise :class:`Damaged` naming the first inconsistency.

    With ``allow_truncated`` a file that ends inside a record or without its footer (a recorder
    that was killed) is returned with ``complete=False`` and ``end_of_records`` at the end of
    the last whole record, instead of raising.
    """
    path = Path(path)
    size = path.stat().st_size
    layout = McapLayout(size)
    with path.open("rb") as f:
        r = _Reader(f, size)
        if size < len(MCAP_MAGIC) or r.read(0, len(MCAP_MAGIC), "magic") != MCAP_MAGIC:
            raise Damaged("it does not start with the MCAP magic")
        pos = len(MCAP_MAGIC)
        try:
            pos = _walk_mcap_records(r, layout, pos)
        except Damaged:
            if not allow_truncated:
                raise
            return layout
        if not layout.complete:
            if allow_truncated:
                return layout
            raise Damaged("it ends without a footer (the recorder was cut off)")
        if pos + len(MCAP_MAGIC) != size or r.read(pos, 8, "closing magic") != MCAP_MAGIC:
            raise Damaged("it does not end with the MCAP magic after its footer")
        _check_mcap_summary(r, layout)
    return layout


def _walk_mcap_records(r: _Reader, layout: McapLayout, pos: int) -> int:
    """Every top-level record up to and including the footer; returns the position after it."""
    first = True
    while pos < r.size:
        if pos + 9 > r.size:
            raise Damaged(f"a record at byte {pos} is cut off")
        opcode, length = _u("BQ", r.read(pos, 9, "record header"))
        if first and opcode != _HEADER:
            raise Damaged("its first record is not the MCAP header")
        first = False
        if length > r.size - pos - 9:
            raise Damaged(
                f"record 0x{opcode:02x} at byte {pos} claims {length} bytes, more than the "
                "file holds"
            )
        layout.records[pos] = opcode
        layout.lengths[pos] = length
        if opcode == _FOOTER:
            if length != 20:
                raise Damaged(f"the footer at byte {pos} has length {length}, not 20")
            summary_start, summary_offset_start, _ = _u("QQI", r.read(pos + 9, 20, "footer"))
            layout.summary_start = summary_start
            layout.complete = True
            layout.end_of_records = pos + 29
            for name, offset in (
                ("summary", summary_start),
                ("summary offsets", summary_offset_start),
            ):
                if offset and layout.records.get(offset) is None:
                    raise Damaged(f"the footer's {name} offset {offset} is no record")
            return pos + 29
        if opcode == _CHUNK:
            _check_chunk_header(r, layout, pos, length)
        elif opcode in _FIELDS:
            # Strings, maps and arrays inside a record must fit in it: the mcap library reads
            # them from the file with the lengths they state. Large payloads (attachments,
            # messages) are checked from their head, their data by its declared length.
            _check_fields(r.read(pos + 9, min(length, 1 << 20), "record"), opcode, pos, length)
        pos += 9 + length
        layout.end_of_records = pos
    return pos


def _check_chunk_header(r: _Reader, layout: McapLayout, pos: int, length: int) -> None:
    head = r.read(pos + 9, min(length, 32), "chunk header")
    if len(head) < 32:
        raise Damaged(f"the chunk at byte {pos} is too short for its header")
    _, _, uncompressed, _, name_len = _u("QQQII", head)
    if 32 + name_len + 8 > length:
        raise Damaged(f"the chunk at byte {pos} has a compression name longer than the chunk")
    tail = r.read(pos + 9 + 32, name_len + 8, "chunk header")
    try:
        compression = tail[:name_len].decode("utf-8")
    except UnicodeDecodeError:
        raise Damaged(f"the chunk at byte {pos} names no compression") from None
    (records_len,) = _u("Q", tail, name_len)
    if compression not in CHUNK_COMPRESSIONS:
        raise Damaged(f"the chunk at byte {pos} uses unknown compression {compression!r}")
    if records_len != length - 40 - name_len:
        raise Damaged(f"the chunk at byte {pos} has a data length that does not fill it")
    if uncompressed > MAX_CHUNK_BYTES or (compression == "" and uncompressed != records_len):
        raise Damaged(f"the chunk at byte {pos} claims {uncompressed} bytes uncompressed")
    layout.chunks[pos] = (records_len, uncompressed, compression)


#: The layout of each MCAP record: B/H/I/Q fixed integers, s a u32-prefixed string, b a
#: u32-prefixed byte array, d a u64-prefixed byte array, m a u32-byte-length map of strings,
#: a a u32-byte-length array of (u64, u64). A record may hold more (later spec versions).
_FIELDS = {
    _HEADER: "ss",
    _SCHEMA: "Hssb",
    _CHANNEL: "HHssm",
    _MESSAGE: "HIQQ",
    _MESSAGE_INDEX: "Ha",
    _ATTACHMENT: "QQssd",
    _ATTACHMENT_INDEX: "QQQQQss",
    _METADATA: "sm",
    _METADATA_INDEX: "QQs",
    _DATA_END: "I",
}
_FIXED = {"B": 1, "H": 2, "I": 4, "Q": 8}


def _check_fields(head: bytes, opcode: int, pos: int, length: int) -> None:
    """Every length-prefixed field of the record at ``pos`` ends inside it (``head``: its first
    bytes, the whole record unless it is over 1 MiB)."""
    k = 0
    for kind in _FIELDS[opcode]:
        if kind in _FIXED:
            k += _FIXED[kind]
            if k > length:
                raise Damaged(f"record 0x{opcode:02x} at byte {pos} is too short for its fields")
            continue
        width = 8 if kind == "d" else 4
        if k + width > len(head):
            raise Damaged(f"record 0x{opcode:02x} at byte {pos} is cut off inside a field")
        (n,) = _u("Q" if width == 8 else "I", head, k)
        k += width + n
        if k > length:
            raise Damaged(
                f"a field of record 0x{opcode:02x} at byte {pos} claims {n} bytes, more than "
                "its record holds"
            )
        if kind == "m" and k <= len(head):
            _check_string_map(head[k - n : k], opcode, pos)
    if opcode == _SCHEMA and length <= len(head):
        _check_schema_or_channel(head, opcode, pos)


def _check_string_map(data: bytes, opcode: int, pos: int) -> None:
    k = 0
    while k < len(data):
        for _ in range(2):  # key, value
            if k + 4 > len(data):
                raise Damaged(f"a map in record 0x{opcode:02x} at byte {pos} is cut off")
            (n,) = _u("I", data, k)
            k += 4 + n
            if k > len(data):
                raise Damaged(f"a map entry in record 0x{opcode:02x} at byte {pos} overruns it")


def _check_schema_or_channel(content: bytes, opcode: int, pos: int) -> None:
    if opcode == _SCHEMA:
        if len(content) < 2:
            raise Damaged(f"the schema at byte {pos} is cut off")
        _, p = _string(content, 2, f"the schema name at byte {pos}")
        encoding, p = _string(content, p, f"the schema encoding at byte {pos}")
        if encoding not in SCHEMA_ENCODINGS:
            raise Damaged(f"the schema at byte {pos} has unknown encoding {encoding!r}")
        _string(content, p, f"the schema data at byte {pos}")
    else:
        if len(content) < 4:
            raise Damaged(f"the channel at byte {pos} is cut off")
        _, p = _string(content, 4, f"the channel topic at byte {pos}")
        _, p = _string(content, p, f"the channel encoding at byte {pos}")
        _string(content, p, f"the channel metadata at byte {pos}")


def _check_mcap_summary(r: _Reader, layout: McapLayout) -> None:
    """Index records must point at the records they describe, with their sizes."""
    for pos, opcode in layout.records.items():
        if pos < layout.summary_start or not layout.summary_start:
            continue
        length = layout.lengths[pos]
        if length > 1 << 24:
            raise Damaged(f"summary record 0x{opcode:02x} at byte {pos} is implausibly long")
        content = r.read(pos + 9, length, "summary record")
        try:
            if opcode == _CHUNK_INDEX:
                _check_chunk_index(content, layout, pos)
            elif opcode in (_METADATA_INDEX, _ATTACHMENT_INDEX):
                offset, size = _u("QQ", content)
                want = _METADATA if opcode == _METADATA_INDEX else _ATTACHMENT
                if layout.records.get(offset) != want or layout.lengths[offset] + 9 != size:
                    raise Damaged(f"the index at byte {pos} points at no matching record")
            elif opcode == _SUMMARY_OFFSET:
                _, start, size = _u("BQQ", content)
                if start not in layout.records or start + size > layout.size:
                    raise Damaged(f"the summary offset at byte {pos} points outside the summary")
            elif opcode == _STATISTICS:
                (n,) = _u("I", content, 42)
                if 46 + n != len(content) or n % 10:
                    raise Damaged(f"the statistics at byte {pos} do not fit their record")
            elif opcode in _FIELDS:
                _check_fields(content, opcode, pos, length)
        except struct.error:
            raise Damaged(f"summary record 0x{opcode:02x} at byte {pos} is cut off") from None


def _check_chunk_index(content: bytes, layout: McapLayout, pos: int) -> None:
    _, _, start, length, map_len = _u("QQQQI", content)
    if 36 + map_len + 8 > len(content) or map_len % 10:
        raise Damaged(f"the chunk index at byte {pos} does not fit its record")
    offsets = [o for _, o in struct.iter_unpack("<HQ", content[36 : 36 + map_len])]
    (index_len,) = _u("Q", content, 36 + map_len)
    compression, p = _string(content, 36 + map_len + 8, f"the chunk index at byte {pos}")
    compressed, uncompressed = _u("QQ", content, p)
    chunk = layout.chunks.get(start)
    if chunk is None or layout.lengths[start] + 9 != length:
        raise Damaged(f"the chunk index at byte {pos} points at no chunk of its length")
    if chunk != (compressed, uncompressed, compression):
        raise Damaged(f"the chunk index at byte {pos} disagrees with its chunk's sizes")
    if start + length + index_len > layout.size:
        raise Damaged(f"the chunk index at byte {pos} claims message indexes past the end")
    for offset in offsets:
        if layout.records.get(offset) != _MESSAGE_INDEX:
            raise Damaged(f"the chunk index at byte {pos} points at no message index")


# --------------------------------------------------------------------------- ROS 1


def check_ros1(path: str | os.PathLike[str]) -> None:
    """Walk a ROS 1 bag's records; raise :class:`Damaged` naming the first inconsistency."""
    path = Path(path)
    size = path.stat().st_size
    with path.open("rb") as f:
        r = _Reader(f, size)
        if size < len(ROS1_MAGIC) or r.read(0, len(ROS1_MAGIC), "magic") != ROS1_MAGIC:
            raise Damaged("it does not start with #ROSBAG V2.0")
        pos = len(ROS1_MAGIC)
        records: dict[int, dict[str, bytes]] = {}
        order: list[int] = []
        while pos < size:
            try:
                header, data_pos, data_len = _ros1_record(r, pos)
            except _PastTheEnd:
                raise Damaged(
                    f"it is cut off inside the record at byte {pos} (the index at the bag's end "
                    "is lost)"
                ) from None
            records[pos] = header
            order.append(pos)
            _check_ros1_record(header, pos, data_len, r, data_pos)
            pos = data_pos + 4 + data_len
        index = {p: i for i, p in enumerate(order)}
        if not order or _op(records[order[0]]) != 0x03:
            raise Damaged("its first record is not the bag header")
        bag = records[order[0]]
        index_pos = _field(bag, "index_pos", "Q", order[0])
        conns = _field(bag, "conn_count", "I", order[0])
        chunks = _field(bag, "chunk_count", "I", order[0])
        if index_pos == 0:
            raise Damaged("it has no index (the recorder was cut off; run `rosbag reindex`)")
        if index_pos not in records:
            raise Damaged(f"its index position {index_pos} is no record")
        tail = order[index[index_pos] :]
        ops = [_op(records[p]) for p in tail]
        if ops[:conns] != [0x07] * conns or ops[conns : conns + chunks] != [0x06] * chunks:
            raise Damaged(
                f"its index does not hold {conns} connection and {chunks} chunk-info records"
            )
        for p in tail[conns : conns + chunks]:
            chunk_pos = _field(records[p], "chunk_pos", "Q", p)
            if _op(records.get(chunk_pos, {})) != 0x05:
                raise Damaged(f"the chunk info at byte {p} points at no chunk")
            count = _field(records[p], "count", "I", p)
            following = order[index[chunk_pos] + 1 : index[chunk_pos] + 1 + count]
            if [_op(records[q]) for q in following] != [0x04] * count:
                raise Damaged(f"the chunk at byte {chunk_pos} lacks its {count} index records")


class _PastTheEnd(Damaged):
    """A record that does not fit in what is left of the file."""


def _ros1_record(r: _Reader, pos: int) -> tuple[dict[str, bytes], int, int]:
    if pos + 4 > r.size:
        raise _PastTheEnd("")
    (header_len,) = _u("I", r.read(pos, 4, "record header length"))
    if pos + 4 + header_len + 4 > r.size:
        raise _PastTheEnd("")
    raw = r.read(pos + 4, header_len, "record header")
    header: dict[str, bytes] = {}
    k = 0
    while k < header_len:
        if k + 4 > header_len:
            raise Damaged(f"a header field at byte {pos + 4 + k} is cut off")
        (n,) = _u("I", raw, k)
        if k + 4 + n > header_len:
            raise Damaged(f"a header field at byte {pos + 4 + k} is longer than its header")
        name, sep, value = raw[k + 4 : k + 4 + n].partition(b"=")
        if not sep:
            raise Damaged(f"a header field at byte {pos + 4 + k} has no name=value")
        header[name.decode("latin-1")] = value
        k += 4 + n
    data_pos = pos + 4 + header_len
    (data_len,) = _u("I", r.read(data_pos, 4, "record data length"))
    if data_pos + 4 + data_len > r.size:
        raise _PastTheEnd("")
    return header, data_pos, data_len


def _op(header: dict[str, bytes]) -> int:
    op = header.get("op", b"")
    return op[0] if len(op) == 1 else -1


def _field(header: dict[str, bytes], name: str, fmt: str, pos: int) -> int:
    value = header.get(name, b"")
    if len(value) != struct.calcsize("<" + fmt):
        raise Damaged(f"the record at byte {pos} lacks a valid {name!r} field")
    return int(_u(fmt, value)[0])


def _check_ros1_record(
    header: dict[str, bytes], pos: int, data_len: int, r: _Reader, data_pos: int
) -> None:
    op = _op(header)
    if op == 0x05:
        compression = header.get("compression", b"").decode("latin-1")
        if compression not in ROS1_COMPRESSIONS:
            raise Damaged(f"the chunk at byte {pos} uses unknown compression {compression!r}")
        uncompressed = _field(header, "size", "I", pos)
        if compression == "none" and uncompressed != data_len:
            raise Damaged(f"the chunk at byte {pos} claims {uncompressed} bytes, holds {data_len}")
    elif op == 0x04:
        if len(header) != 4 or sum(4 + len(k) + 1 + len(v) for k, v in header.items()) != 47:
            raise Damaged(f"the index record at byte {pos} has an unexpected header")
        if _field(header, "ver", "I", pos) != 1:
            raise Damaged(f"the index record at byte {pos} has an unknown version")
        if data_len != 12 * _field(header, "count", "I", pos):
            raise Damaged(f"the index record at byte {pos} does not hold its count of entries")
        _field(header, "conn", "I", pos)
    elif op == 0x06:
        if _field(header, "ver", "I", pos) != 1:
            raise Damaged(f"the chunk info at byte {pos} has an unknown version")
        if data_len != 8 * _field(header, "count", "I", pos):
            raise Damaged(f"the chunk info at byte {pos} does not hold its count of entries")
        _field(header, "start_time", "Q", pos)
        _field(header, "end_time", "Q", pos)
    elif op == 0x07:
        _field(header, "conn", "I", pos)
        if "topic" not in header:
            raise Damaged(f"the connection at byte {pos} names no topic")
        if data_len > 1 << 24:
            raise Damaged(f"the connection at byte {pos} is implausibly long")
        raw = r.read(data_pos + 4, data_len, "connection")
        fields = _header_fields(raw, pos)
        if "type" not in fields or "md5sum" not in fields or "message_definition" not in fields:
            raise Damaged(f"the connection at byte {pos} lacks its type, md5sum or definition")
    elif op == 0x03:
        for name, fmt in (("index_pos", "Q"), ("conn_count", "I"), ("chunk_count", "I")):
            _field(header, name, fmt, pos)
    elif op != 0x02:
        raise Damaged(f"the record at byte {pos} has unknown op {op}")


def _header_fields(raw: bytes, pos: int) -> dict[str, bytes]:
    fields: dict[str, bytes] = {}
    k = 0
    while k < len(raw):
        if k + 4 > len(raw):
            raise Damaged(f"a connection field at byte {pos} is cut off")
        (n,) = _u("I", raw, k)
        if k + 4 + n > len(raw):
            raise Damaged(f"a connection field at byte {pos} is longer than its record")
        name, sep, value = raw[k + 4 : k + 4 + n].partition(b"=")
        if not sep:
            raise Damaged(f"a connection field at byte {pos} has no name=value")
        fields[name.decode("latin-1")] = value
        k += 4 + n
    return fields
