"""Convert a recording between MCAP, ROS 1 ``.bag`` and ROS 2 bag directories.

Every topic is copied with its log times. Between ROS 2 flavours (MCAP and ROS 2 bags) the CDR
bytes pass unchanged; to or from ROS 1 each message is deserialised and migrated field by field
(rosbags' ``migrate_message``: ``k`` <-> ``K``, a header ``seq``), so ROS 1 tools see ROS 1
messages. Metadata travels as MCAP metadata records, a ROS 2 bag's ``custom_data``, or a
/scrapcut/metadata string on ROS 1. Output is written under a temporary name and renamed.

Output is compressed by default, as the recorders write it (:data:`DEFAULT_COMPRESSION`):
zstd chunks in MCAP (and in a ROS 2 bag's MCAP storage), zstd messages in a ROS 2 sqlite3 bag,
lz4 chunks in a ROS 1 bag (ROS 1 knows only bz2 and lz4). ``topics`` keeps only the topics
named (a long real recording cut down to the camera and /tf).
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from scrapcut_cli._io import atomic_path, check_output_path, real_path
from scrapcut_cli.errors import RecordingError
from scrapcut_cli.recording import messages as m
from scrapcut_cli.recording.reader import (
    CUSTOM_DATA_PREFIX,
    METADATA_TOPIC,
    Recording,
    open_recording,
)
from scrapcut_cli.recording.writer import McapWriter, is_foreign_directory

FORMATS = ("mcap", "ros1", "ros2")
ROS2_STORAGES = ("mcap", "sqlite3")
#: Compressions a user can ask for, and those each output can hold.
COMPRESSIONS = ("zstd", "lz4", "bz2", "none")
_SUPPORTED = {
    "mcap": ("zstd", "lz4", "none"),
    "ros1": ("lz4", "bz2", "none"),
    "ros2": ("zstd", "none"),
}
#: Each format's usual compression (what its recorders write).
DEFAULT_COMPRESSION = {"mcap": "zstd", "ros1": "lz4", "ros2": "zstd"}


def format_for_path(path: str | os.PathLike[str]) -> str:
    """The output format a path asks for: ``.mcap`` -> mcap, ``.bag`` -> ros1, else ros2."""
    suffix = Path(path).suffix.lower()
    return {".mcap": "mcap", ".bag": "ros1"}.get(suffix, "ros2")


def convert_recording(
    src: str | os.PathLike[str],
    dst: str | os.PathLike[str],
    *,
    fmt: str | None = None,
    storage: str = "mcap",
    compression: str | None = None,
    topics: Sequence[str] | None = None,
) -> None:
    """Write the recording ``src`` to ``dst`` as ``fmt`` (default: from ``dst``'s suffix).

    ``storage`` picks the ROS 2 bag's storage plugin (``mcap`` or ``sqlite3``);
    ``compression`` one of :data:`COMPRESSIONS` the format holds (default: the format's usual
    one, :data:`DEFAULT_COMPRESSION`); ``topics`` the topics to keep (default: all; each must
    exist). ``dst`` is replaced only when the conversion succeeds.
    """
    fmt = fmt or format_for_path(dst)
    if fmt not in FORMATS:
        raise RecordingError(f"unknown recording format {fmt!r}; known: {', '.join(FORMATS)}")
    compression = compression or DEFAULT_COMPRESSION[fmt]
    if compression not in _SUPPORTED[fmt]:
        kind = {"mcap": "an MCAP file", "ros1": "a ROS 1 bag", "ros2": "a ROS 2 bag"}[fmt]
        raise RecordingError(
            f"{kind} cannot be compressed with {compression}; it takes {', '.join(_SUPPORTED[fmt])}"
        )
    if storage not in ROS2_STORAGES:
        raise RecordingError(
            f"unknown ROS 2 storage {storage!r}; known: {', '.join(ROS2_STORAGES)}"
        )
    src_path, dst_path = Path(src), Path(dst)
    suffix = {"mcap": ".mcap", "ros1": ".bag"}.get(fmt)
    if suffix is not None and dst_path.suffix.lower() != suffix:
        # Readers (ours, rosbags, ros2 bag) tell a file's format by its name: a mismatch
        # would write a file nothing opens.
        kind = {"mcap": "an MCAP file", "ros1": "a ROS 1 bag"}[fmt]
        raise RecordingError(
            f"{kind} must be named *{suffix}, not {dst_path.name!r}; "
            f"use -o {dst_path.with_suffix(suffix).name}"
        )
    if dst_path.exists() and src_path.exists() and real_path(dst_path) == real_path(src_path):
        raise RecordingError(f"output {dst_path} is the input; choose another -o")
    if fmt == "ros2" and dst_path.is_file():
        raise RecordingError(f"{dst_path} is a file; a ROS 2 bag is a directory")
    if fmt == "ros2" and is_foreign_directory(dst_path):
        # The bag replaces the directory whole: never delete a folder of other files.
        raise RecordingError(
            f"{dst_path} is a directory that is not a ROS 2 bag; choose a new -o (an existing "
            "ROS 2 bag is replaced, any other directory is left alone)"
        )
    if fmt != "ros2" and dst_path.is_dir():
        raise RecordingError(f"{dst_path} is a directory; an {fmt} recording is a file")
    check_output_path(dst_path, directory=fmt == "ros2")
    with open_recording(src_path) as rec:
        kept = _kept_topics(rec, topics)
        translate = _Translator(rec, to_ros1=fmt == "ros1")
        if fmt == "mcap":
            _write_mcap(rec, dst_path, translate, kept, compression)
        elif fmt == "ros2":
            _write_ros2(rec, dst_path, translate, kept, storage, compression)
        else:
            _write_ros1(rec, dst_path, translate, kept, compression)


def _kept_topics(rec: Recording, wanted: Sequence[str] | None) -> list[str]:
    """The topics to copy: all but the ROS 1 metadata topic, or those ``wanted`` (each must be
    in the recording)."""
    present = [t.name for t in rec.topics() if t.name != METADATA_TOPIC]
    if wanted is None:
        return present
    missing = [t for t in wanted if t not in present]
    if missing:
        raise RecordingError(
            f"no topic {', '.join(missing)} in {rec.path}; it has {', '.join(present)}"
        )
    return [t for t in present if t in set(wanted)]


class _Translator:
    """Turns source message bytes into destination bytes and supplies destination types."""

    def __init__(self, rec: Recording, *, to_ros1: bool) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.rec = rec
        self.src_store = rec.typestore
        self.src_is_ros1 = rec.format == "ros1"
        self.to_ros1 = to_ros1
        self.migrate = self.src_is_ros1 != to_ros1
        if not self.migrate:
            self.store = self.src_store
        else:
            self.store = get_typestore(Stores.ROS1_NOETIC if to_ros1 else Stores.ROS2_HUMBLE)
            # Types the destination store lacks (tf2_msgs in Noetic, custom messages) come
            # from the source definitions; the Header stays the destination's own.
            missing = {
                name: fields
                for name, fields in self.src_store.fielddefs.items()
                if name not in self.store.fielddefs and name != "std_msgs/msg/Header"
            }
            if missing:
                self.store.register(missing)
        self._cache: dict[str, object] = {}
        self._seq: dict[str, int] = {}

    def __call__(self, topic: str, msgtype: str, raw: bytes) -> bytes:
        if not self.migrate:
            return raw
        from rosbags.convert.converter import migrate_message

        msg = self.rec.deserialize(raw, msgtype)
        out: Any = migrate_message(self.src_store, self.store, msgtype, msgtype, self._cache, msg)
        if self.to_ros1:
            header = getattr(out, "header", None)
            if header is not None and hasattr(header, "seq"):
                self._seq[topic] = self._seq.get(topic, 0) + 1
                header.seq = self._seq[topic]
            return bytes(self.store.serialize_ros1(out, msgtype))
        return bytes(self.store.serialize_cdr(out, msgtype, little_endian=True))


def _copied(rec: Recording, topics: list[str]) -> Iterator[tuple[str, str, int, bytes]]:
    """Every message of ``topics`` (metadata is re-emitted natively, not copied)."""
    for conn, log_time, raw in rec.raw_connection_messages(topics):
        yield conn.topic, conn.msgtype, log_time, raw


def _write_mcap(
    rec: Recording, dst: Path, translate: _Translator, topics: list[str], compression: str
) -> None:
    msgdefs: dict[str, str] = {}
    with McapWriter(dst, compression=compression) as writer:
        for name, data in sorted(rec.metadata.items()):
            writer.add_metadata(name, data)
        for topic, msgtype, log_time, raw in _copied(rec, topics):
            if msgtype not in msgdefs:
                msgdefs[msgtype] = m.msgdef_text(msgtype, translate.store)
            writer.write_raw(
                topic,
                msgtype,
                translate(topic, msgtype, raw),
                log_time_ns=log_time,
                msgdef=msgdefs[msgtype],
            )


def _write_ros2(
    rec: Recording,
    dst: Path,
    translate: _Translator,
    topics: list[str],
    storage: str,
    compression: str,
) -> None:
    from rosbags.convert.converter import LATCH
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    # MCAP storage compresses its chunks (what `ros2 bag record` does by default); sqlite3
    # storage can only compress message by message.
    mode = CompressionMode.NONE
    if compression == "zstd":
        mode = CompressionMode.STORAGE if storage == "mcap" else CompressionMode.MESSAGE
    with atomic_path(dst, directory=True) as tmp:
        # rosbags creates the bag directory itself and names the storage file after it:
        # write tmp/<name>/ and lift its files into tmp, which is renamed onto dst.
        bag = tmp / dst.name
        try:
            writer = Writer(bag, version=9, storage_plugin=plugin)
            writer.set_compression(mode, CompressionFormat.ZSTD)
            with writer:
                for name, data in sorted(rec.metadata.items()):
                    writer.set_custom_data(CUSTOM_DATA_PREFIX + name, json.dumps(data))
                connections: dict[str, Any] = {}
                for topic, msgtype, log_time, raw in _copied(rec, topics):
                    conn = connections.get(topic)
                    if conn is None:
                        conn = writer.add_connection(
                            topic,
                            msgtype,
                            typestore=translate.store,
                            offered_qos_profiles=LATCH if topic == "/tf_static" else (),
                        )
                        connections[topic] = conn
                    writer.write(conn, log_time, translate(topic, msgtype, raw))
        except WriterError as exc:
            raise RecordingError(f"cannot write ROS 2 bag {dst}: {exc}") from None
        for item in bag.iterdir():
            shutil.move(str(item), tmp / item.name)
        bag.rmdir()


def _write_ros1(
    rec: Recording, dst: Path, translate: _Translator, topics: list[str], compression: str
) -> None:
    from rosbags.interfaces import ConnectionExtRosbag1
    from rosbags.rosbag1 import Writer, WriterError

    with atomic_path(dst) as tmp:
        tmp.unlink()  # rosbags refuses to overwrite; it creates the file itself
        try:
            writer = Writer(tmp)
            if compression != "none":
                writer.set_compression(Writer.CompressionFormat[compression.upper()])
            with writer:
                connections: dict[tuple[str, str | None], Any] = {}
                if rec.metadata:
                    _write_ros1_metadata(writer, rec, translate)
                for source, log_time, raw in rec.raw_connection_messages(topics):
                    topic, msgtype = source.topic, source.msgtype
                    # A ROS 1 bag keeps one connection per publisher (two /tf_static nodes
                    # must stay two latched connections); other formats do not know them.
                    ext = source.ext
                    callerid = ext.callerid if isinstance(ext, ConnectionExtRosbag1) else None
                    key = (topic, callerid)
                    conn = connections.get(key)
                    if conn is None:
                        conn = writer.add_connection(
                            topic,
                            msgtype,
                            typestore=translate.store,
                            callerid=key[1],
                            latching=int(topic == "/tf_static"),
                        )
                        connections[key] = conn
                    writer.write(conn, log_time, translate(topic, msgtype, raw))
        except WriterError as exc:
            raise RecordingError(f"cannot write ROS 1 bag {dst}: {exc}") from None


def _write_ros1_metadata(writer: Any, rec: Recording, translate: _Translator) -> None:
    conn = writer.add_connection(METADATA_TOPIC, m.STRING, typestore=translate.store, latching=1)
    text = json.dumps(rec.metadata, sort_keys=True)
    msg = translate.store.types[m.STRING](data=text)
    writer.write(conn, rec.start_ns, bytes(translate.store.serialize_ros1(msg, m.STRING)))
