"""Damaged recordings on purpose: structural mutations of MCAP files and ROS 1 bags.

Used by the fuzz tests (``test_fuzz_readers.py``, driven by hypothesis) and the longer campaign
(``benchmarks/fuzz_campaign.py``, driven by a seeded ``random.Random``). A mutation works on the
file's records, as a damaged disk, a killed recorder or a buggy writer would leave them: records
dropped, duplicated, swapped or cut off; length, offset, count and opcode fields set to values
that do not fit; strings replaced; bytes flipped. Records inside an uncompressed chunk are
mutated the same way (without CRCs, nothing but the readers' own checks stands between them and
the damage).
"""

from __future__ import annotations

import random
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROS1_MAGIC = b"#ROSBAG V2.0\n"


class Choices(Protocol):
    """A source of choices: hypothesis' ``data.draw`` or a seeded ``random.Random``."""

    def integer(self, lo: int, hi: int) -> int: ...


class RandomChoices:
    """:class:`Choices` from a seeded ``random.Random``."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)

    def integer(self, lo: int, hi: int) -> int:
        return self.rng.randint(lo, hi)


class DrawChoices:
    """:class:`Choices` from hypothesis (``st.data()``)."""

    def __init__(self, data: Any) -> None:
        from hypothesis import strategies as st

        self.data, self.st = data, st

    def integer(self, lo: int, hi: int) -> int:
        return int(self.data.draw(self.st.integers(lo, hi)))


def _special(c: Choices, size: int) -> int:
    """A value a length, offset or count field should never hold, or a near miss."""
    values = [0, 1, 7, 8, 9, 40, size // 2, size - 1, size, size + 1, 2 * size, 2**31 - 1]
    values += [2**32 - 1, 2**32, 2**40, 2**60, 2**63 - 1, 2**64 - 1]
    k = c.integer(0, len(values) + 1)
    if k < len(values):
        return values[k]
    return c.integer(0, 2 * size + 64)


# --------------------------------------------------------------------------- MCAP


@dataclass
class _Record:
    start: int  # offset of the opcode (MCAP) / header length (ROS 1)
    end: int  # one past the record


def mcap_records(data: bytes) -> list[_Record]:
    """Top-level records after the leading magic (up to the closing magic)."""
    out, pos = [], len(MCAP_MAGIC)
    while pos + 9 <= len(data) - len(MCAP_MAGIC):
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        end = pos + 9 + length
        if end > len(data):
            break
        out.append(_Record(pos, end))
        pos = end
    return out


def _chunk_inner(data: bytes, record: _Record) -> tuple[int, int, str] | None:
    """(start, end, compression) of an MCAP chunk's records area."""
    if data[record.start] != 0x06:
        return None
    base = record.start + 9
    (name_len,) = struct.unpack_from("<I", data, base + 28)
    compression = data[base + 32 : base + 32 + name_len].decode("utf-8", "replace")
    start = base + 32 + name_len + 8
    return start, record.end, compression


def mutate_mcap(data: bytes, c: Choices) -> bytes:
    """One structural mutation of an MCAP file."""
    buf = bytearray(data)
    records = mcap_records(data)
    if not records:
        return bytes(buf[: c.integer(0, len(buf))])
    kind = c.integer(0, 11)
    r = records[c.integer(0, len(records) - 1)]
    if kind == 0:  # cut off anywhere (a killed recorder, a partial copy)
        return bytes(buf[: c.integer(0, len(buf) - 1)])
    if kind == 1:  # cut off at a record boundary
        return bytes(buf[: r.start])
    if kind == 2:  # a record dropped
        return bytes(buf[: r.start] + buf[r.end :])
    if kind == 3:  # a record duplicated (an index written twice)
        at = records[c.integer(0, len(records) - 1)].start
        return bytes(buf[:at] + buf[r.start : r.end] + buf[at:])
    if kind == 4:  # two records swapped
        s = records[c.integer(0, len(records) - 1)]
        a, b = sorted((r, s), key=lambda x: x.start)
        if a.end > b.start:
            return bytes(buf)
        return bytes(buf[: a.start] + buf[b.start : b.end] + buf[a.end : b.start]) + bytes(
            buf[a.start : a.end] + buf[b.end :]
        )
    if kind == 5:  # a record's length field
        struct.pack_into("<Q", buf, r.start + 1, _special(c, len(data)) % 2**64)
        return bytes(buf)
    if kind == 6:  # a record's opcode
        buf[r.start] = c.integer(0, 0x12)
        return bytes(buf)
    if kind in (7, 8):  # a u64 / u32 field inside a record (offsets, sizes, counts, ids)
        width = 8 if kind == 7 else 4
        if r.end - (r.start + 9) < width:
            return bytes(buf)
        at = c.integer(r.start + 9, r.end - width)
        value = _special(c, len(data)) % (2 ** (8 * width))
        struct.pack_into("<Q" if width == 8 else "<I", buf, at, value)
        return bytes(buf)
    if kind == 9:  # bytes flipped
        for _ in range(c.integer(1, 8)):
            at = c.integer(0, len(buf) - 1)
            buf[at] ^= 1 << c.integer(0, 7)
        return bytes(buf)
    if kind == 10:  # a string replaced (schema encoding, compression, topic)
        for needle in (b"ros2msg", b"zstd", b"cdr", b"/tf", b"ros2"):
            at = data.find(needle, r.start, r.end)
            if at >= 0:
                replacement = [b"x" * len(needle), b"\xff" * len(needle), needle.upper()][
                    c.integer(0, 2)
                ]
                buf[at : at + len(needle)] = replacement
                return bytes(buf)
        return bytes(buf)
    # kind 11: a record inside an uncompressed chunk
    chunks = [x for x in records if data[x.start] == 0x06]
    if not chunks:
        return bytes(buf)
    inner = _chunk_inner(data, chunks[c.integer(0, len(chunks) - 1)])
    if inner is None or inner[2] != "":
        return bytes(buf)
    start, end, _ = inner
    pos, inner_records = start, []
    while pos + 9 <= end:
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if pos + 9 + length > end:
            break
        inner_records.append(_Record(pos, pos + 9 + length))
        pos += 9 + length
    if not inner_records:
        return bytes(buf)
    x = inner_records[c.integer(0, len(inner_records) - 1)]
    what = c.integer(0, 3)
    if what == 0:
        struct.pack_into("<Q", buf, x.start + 1, _special(c, end - start) % 2**64)
    elif what == 1:
        buf[x.start] = c.integer(0, 0x12)
    elif what == 2 and x.end - x.start >= 9 + 2:  # a channel or schema id
        struct.pack_into("<H", buf, x.start + 9, c.integer(0, 70))
    elif x.end - x.start > 9 + 4:
        at = c.integer(x.start + 9, x.end - 4)
        struct.pack_into("<I", buf, at, _special(c, end - start) % 2**32)
    return bytes(buf)


# --------------------------------------------------------------------------- ROS 1


@dataclass
class _BagRecord(_Record):
    header_start: int
    header_end: int
    fields: dict[str, tuple[int, int]]  # name -> (value start, value end)
    data_start: int


def ros1_records(data: bytes) -> list[_BagRecord]:
    """Top-level records of a ROS 1 bag after its magic line."""
    out, pos = [], len(ROS1_MAGIC)
    while pos + 4 <= len(data):
        (header_len,) = struct.unpack_from("<I", data, pos)
        h0, h1 = pos + 4, pos + 4 + header_len
        if h1 + 4 > len(data):
            break
        fields, k = {}, h0
        while k + 4 <= h1:
            (n,) = struct.unpack_from("<I", data, k)
            name, _, _ = data[k + 4 : k + 4 + n].partition(b"=")
            fields[name.decode("latin-1")] = (k + 4 + len(name) + 1, k + 4 + n)
            k += 4 + n
        (data_len,) = struct.unpack_from("<I", data, h1)
        end = h1 + 4 + data_len
        if end > len(data):
            break
        out.append(_BagRecord(pos, end, h0, h1, fields, h1 + 4))
        pos = end
    return out


def mutate_ros1(data: bytes, c: Choices) -> bytes:
    """One structural mutation of a ROS 1 bag."""
    buf = bytearray(data)
    records = ros1_records(data)
    if not records:
        return bytes(buf[: c.integer(0, len(buf))])
    kind = c.integer(0, 9)
    r = records[c.integer(0, len(records) - 1)]
    if kind == 0:
        return bytes(buf[: c.integer(0, len(buf) - 1)])
    if kind == 1:
        return bytes(buf[: r.start])
    if kind == 2:
        return bytes(buf[: r.start] + buf[r.end :])
    if kind == 3:
        at = records[c.integer(0, len(records) - 1)].start
        return bytes(buf[:at] + buf[r.start : r.end] + buf[at:])
    if kind == 4:  # header or data length
        at = r.start if c.integer(0, 1) == 0 else r.header_end
        struct.pack_into("<I", buf, at, _special(c, len(data)) % 2**32)
        return bytes(buf)
    if kind == 5:  # a header field's value (op, conn, count, ver, index_pos, chunk_pos, size...)
        if not r.fields:
            return bytes(buf)
        names = sorted(r.fields)
        v0, v1 = r.fields[names[c.integer(0, len(names) - 1)]]
        width = v1 - v0
        if width in (1, 4, 8):
            value = _special(c, len(data)) % (2 ** (8 * width))
            buf[v0:v1] = value.to_bytes(width, "little")
        elif width > 0:
            buf[v0 + c.integer(0, width - 1)] = c.integer(0, 255)
        return bytes(buf)
    if kind == 6:  # bytes flipped
        for _ in range(c.integer(1, 8)):
            at = c.integer(0, len(buf) - 1)
            buf[at] ^= 1 << c.integer(0, 7)
        return bytes(buf)
    if kind == 7:  # a u32 inside a record's data (inner lengths, conn ids, counts, offsets)
        if r.end - r.data_start < 4:
            return bytes(buf)
        at = c.integer(r.data_start, r.end - 4)
        struct.pack_into("<I", buf, at, _special(c, len(data)) % 2**32)
        return bytes(buf)
    if kind == 8:  # two records swapped
        s = records[c.integer(0, len(records) - 1)]
        a, b = sorted((r, s), key=lambda x: x.start)
        if a.end > b.start:
            return bytes(buf)
        return bytes(buf[: a.start] + buf[b.start : b.end] + buf[a.end : b.start]) + bytes(
            buf[a.start : a.end] + buf[b.end :]
        )
    # kind 9: a string replaced
    for needle in (b"none", b"sensor_msgs", b"/tf", b"tf2_msgs", b"md5sum"):
        at = data.find(needle, r.start, r.end)
        if at >= 0:
            buf[at : at + len(needle)] = [b"x" * len(needle), needle.upper()][c.integer(0, 1)]
            break
    return bytes(buf)


MUTATORS: dict[str, Callable[[bytes, Choices], bytes]] = {"mcap": mutate_mcap, "ros1": mutate_ros1}


def mutate(data: bytes, fmt: str, c: Choices, *, max_mutations: int = 3) -> bytes:
    """1 to ``max_mutations`` mutations of a recording's bytes (``fmt``: mcap | ros1)."""
    for _ in range(c.integer(1, max_mutations)):
        data = MUTATORS[fmt](data, c)
    return data


# --------------------------------------------------------------------------- bases


def write_uncompressed_mcap(source: Path, target: Path, *, chunk_size: int = 1 << 16) -> None:
    """``source`` rewritten as MCAP with uncompressed chunks and no CRCs (nothing but the
    readers' structure checks stands between a mutation and the parser)."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with source.open("rb") as f, target.open("wb") as out:
        reader = make_reader(f)
        writer = Writer(
            out,
            chunk_size=chunk_size,
            compression=CompressionType.NONE,
            enable_crcs=False,
            enable_data_crcs=False,
        )
        writer.start(profile="ros2", library="scrapcut tests")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for meta in reader.iter_metadata():
            writer.add_metadata(meta.name, dict(meta.metadata))
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic,
                    channel.message_encoding,
                    schemas.get(channel.schema_id, 0),
                    dict(channel.metadata),
                )
            writer.add_message(
                channels[channel.id],
                message.log_time,
                message.data,
                message.publish_time,
                message.sequence,
            )
        writer.finish()


def write_bases(source: Path, folder: Path) -> dict[str, tuple[Path, str]]:
    """The three bases of the fuzz runs from one MCAP recording: as it is, uncompressed without
    CRCs, and as a ROS 1 bag. Returns name -> (path, mutation format)."""
    from scrapcut_cli.recording.convert import convert_recording

    folder.mkdir(parents=True, exist_ok=True)
    plain = folder / "plain.mcap"
    write_uncompressed_mcap(source, plain)
    bag = folder / "base.bag"
    convert_recording(source, bag)
    return {"mcap": (source, "mcap"), "mcap-plain": (plain, "mcap"), "ros1": (bag, "ros1")}


# --------------------------------------------------------------------------- edited recordings

#: edit(topic, msgtype, message) -> the message to write (edited in place or new), or None to
#: drop it.
Edit = Callable[[str, str, Any], Any]


def rewrite_mcap(source: Path, target: Path, edit: Edit) -> Path:
    """``source`` rewritten message by message through ``edit`` (metadata kept)."""
    from scrapcut_cli.recording.reader import open_recording
    from scrapcut_cli.recording.writer import McapWriter

    with open_recording(source) as rec, McapWriter(target) as writer:
        for name, data in sorted(rec.metadata.items()):
            writer.add_metadata(name, data)
        for topic, msgtype, log_time, raw in rec.raw_messages():
            msg = edit(topic, msgtype, rec.deserialize(raw, msgtype))
            if msg is not None:
                writer.write_message(topic, msgtype, msg, log_time_ns=log_time)
    return target


def without_tf_link(child: str) -> Edit:
    """Drop every /tf transform to ``child`` (a link the recorder missed)."""

    def edit(topic: str, msgtype: str, msg: Any) -> Any:
        if topic == "/tf":
            msg.transforms = [t for t in msg.transforms if t.child_frame_id != child]
        return msg

    return edit


def without_topic(name: str) -> Edit:
    def edit(topic: str, msgtype: str, msg: Any) -> Any:
        return None if topic == name else msg

    return edit


def images_stamped(stamp_ns: int) -> Edit:
    """Every image and camera info stamped with one time (a driver without a clock)."""
    from scrapcut_cli.recording import messages as m

    def edit(topic: str, msgtype: str, msg: Any) -> Any:
        if topic.startswith("/camera"):
            msg.header.stamp = m.stamp_from_ns(stamp_ns)
        return msg

    return edit


def colour_filled(rgb: tuple[int, int, int]) -> Edit:
    """Every colour image one colour (paint sprayed over the lens, a paint-coloured wall)."""
    import numpy as np

    def edit(topic: str, msgtype: str, msg: Any) -> Any:
        if topic.endswith("/color/image_raw"):
            pixels = np.empty((int(msg.height), int(msg.width), 3), np.uint8)
            pixels[:] = rgb
            msg.encoding, msg.step = "rgb8", int(msg.width) * 3
            msg.data = pixels.reshape(-1)
        return msg

    return edit


# --------------------------------------------------------------------------- a tiny arm scan

ARM_COLOR_TOPIC = "/camera/camera/color/image_raw"
ARM_DEPTH_TOPIC = "/camera/camera/aligned_depth_to_color/image_raw"
ARM_INFO_TOPIC = "/camera/camera/color/camera_info"


def arm_scan(
    path: Path,
    *,
    drop_link: str | None = None,
    with_tf: bool = True,
    same_stamp: bool = False,
    nan_intrinsics: bool = False,
    frames: int = 4,
    repeat_frame: int | None = None,
) -> Path:
    """A tiny eye-in-hand scan as a robot records it: base -> link1 -> link2 move (/tf at
    100 Hz), link2 -> cam is the hand-eye calibration (/tf_static); ``frames`` 32 x 24 colour
    and depth images that change as the camera moves.

    Faults on request: a /tf link never recorded (``drop_link``), no /tf at all
    (``with_tf=False``), every image stamped alike (``same_stamp``), NaN focal lengths, image
    ``repeat_frame`` stamped as the one before it (a driver re-publishing a frame).
    """
    import numpy as np
    from scipy.spatial.transform import Rotation

    from scrapcut_cli.recording import messages as m
    from scrapcut_cli.recording.frame import CameraModel
    from scrapcut_cli.recording.writer import McapWriter

    rng = np.random.default_rng(7)
    t0 = 1_700_000_000_000_000_000
    camera = CameraModel(32, 24, 28.0, 28.0, 15.5, 11.5, frame_id="cam")
    stamps = [t0 + k * 33_333_333 for k in range(frames)]
    if repeat_frame is not None:
        stamps[repeat_frame] = stamps[repeat_frame - 1]
    with McapWriter(path) as writer:
        writer.write_tf(t0 - 50_000_000, [("link2", "cam", np.eye(4))], static=True)
        info = m.camera_info_msg(t0, camera)
        if nan_intrinsics:
            info.k = np.array([np.nan, 0, 15.5, 0, np.nan, 11.5, 0, 0, 1], dtype=np.float64)
        writer.write_message(ARM_INFO_TOPIC, m.CAMERA_INFO, info, log_time_ns=t0 - 40_000_000)
        items: list[tuple[int, str, Any]] = []
        if with_tf:
            for stamp in range(t0 - 20_000_000, stamps[-1] + 30_000_000, 10_000_000):
                t = (stamp - t0) / 1e9
                link1 = np.eye(4)
                link1[:3, :3] = Rotation.from_euler("z", 0.5 * t).as_matrix()
                link2 = np.eye(4)
                link2[:3, 3] = [0.3 + 0.2 * t, 0.0, 0.4]
                links = [("base", "link1", link1), ("link1", "link2", link2)]
                items.append((stamp, "tf", [x for x in links if x[1] != drop_link]))
        for stamp in stamps:
            rgb = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
            depth = rng.integers(300, 900, (24, 32)).astype(np.uint16)
            items.append((stamp, "image", (t0 if same_stamp else stamp, rgb, depth)))
        for log_time, kind, payload in sorted(items, key=lambda item: item[0]):
            if kind == "tf":
                writer.write_tf(log_time, payload)
            else:
                stamp, rgb, depth = payload
                writer.write_image(ARM_COLOR_TOPIC, stamp, "cam", rgb, log_time_ns=log_time)
                writer.write_image(ARM_DEPTH_TOPIC, stamp, "cam", depth, log_time_ns=log_time)
    return path
