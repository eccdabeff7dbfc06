"""Recording writers with ROS 2 message definitions, so Foxglove and ``ros2 bag`` open them.

:class:`McapWriter` writes an MCAP file: schemas are the ``ros2msg`` definitions of rosbags'
ROS 2 Humble typestore under their ROS 2 names (``sensor_msgs/msg/Image``), messages are
little-endian CDR, chunks zstd-compressed. :class:`Ros2BagWriter` writes a ROS 2 bag directory
with rosbags' rosbag2 writer (sqlite3 storage, rosbag2's default, or MCAP): what
``ros2 bag record`` leaves with realsense-ros 4.x; metadata goes into ``metadata.yaml``'s
``custom_data``. Both share :class:`MessageWriter`'s typed ``write_*`` helpers;
:func:`open_writer` picks one by the path. Output is written under a temporary name beside the
target and renamed when the writer closes cleanly; nothing depends on the wall clock, so the
same calls give the same bytes.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import numpy as np
from numpy.typing import ArrayLike

from scrapcut_cli import __version__
from scrapcut_cli._io import atomic_path
from scrapcut_cli.recording import messages as m
from scrapcut_cli.recording.frame import CameraModel
from scrapcut_cli.recording.reader import CUSTOM_DATA_PREFIX

_COMPRESSIONS = ("zstd", "lz4", "none")
#: ROS 2 bag storage plugins: sqlite3 (rosbag2's default up to Iron) or MCAP.
ROS2_STORAGES = ("sqlite3", "mcap")


class MessageWriter:
    """The typed ``write_*`` helpers every writer shares, over its :meth:`write_raw`.

    A context manager: the output appears when the block ends without an error. Every
    ``write_*`` method takes the message's header stamp in integer nanoseconds;
    ``log_time_ns`` (the recorder's receive time, which readers ignore in favour of the header
    stamp) defaults to it.
    """

    path: Path

    def __enter__(self) -> MessageWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
            return
        self.abort(exc_type, exc, tb)
        if isinstance(exc, OSError) and exc.filename is None:
            # A full disk while writing: name the output, not a bare errno.
            raise OSError(exc.errno, exc.strerror, str(self.path)) from None

    def close(self) -> None:
        """Finish the output and move it onto ``path``."""
        raise NotImplementedError

    def abort(
        self,
        exc_type: type[BaseException] | None = None,
        exc: BaseException | None = None,
        tb: TracebackType | None = None,
    ) -> None:
        """Drop the temporary output; ``path`` is left as it was."""
        raise NotImplementedError

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A named map of strings (the simulator's settings...)."""
        raise NotImplementedError

    def write_raw(
        self,
        topic: str,
        msgtype: str,
        data: bytes | memoryview,
        *,
        log_time_ns: int,
        publish_time_ns: int | None = None,
        msgdef: str | None = None,
    ) -> None:
        """Already serialised CDR bytes (``msgdef`` for types the Humble typestore lacks)."""
        raise NotImplementedError

    def write_message(
        self,
        topic: str,
        msgtype: str,
        msg: object,
        *,
        log_time_ns: int,
        publish_time_ns: int | None = None,
    ) -> None:
        """Any message of the ROS 2 Humble typestore (``m.typestore().types[msgtype]``)."""
        self.write_raw(
            topic,
            msgtype,
            m.serialize(msg, msgtype),
            log_time_ns=log_time_ns,
            publish_time_ns=publish_time_ns,
        )

    def write_image(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        image: ArrayLike,
        *,
        encoding: str | None = None,
        log_time_ns: int | None = None,
    ) -> None:
        """``sensor_msgs/Image``: (H, W, 3) uint8 RGB -> rgb8 (``encoding`` bgr8/rgba8/bgra8
        for arrays in that layout); (H, W) uint16 mm -> 16UC1; (H, W) float32 m -> 32FC1."""
        msg = m.image_msg(stamp_ns, frame_id, image, encoding=encoding)
        self._write(topic, m.IMAGE, msg, stamp_ns, log_time_ns)

    def write_compressed_image(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        rgb: ArrayLike,
        *,
        fmt: str = "jpeg",
        quality: int = 90,
        log_time_ns: int | None = None,
    ) -> None:
        """``sensor_msgs/CompressedImage`` (``jpeg`` or ``png``) of an (H, W, 3) uint8 RGB image."""
        msg = m.compressed_image_msg(stamp_ns, frame_id, rgb, fmt=fmt, quality=quality)
        self._write(topic, m.COMPRESSED_IMAGE, msg, stamp_ns, log_time_ns)

    def write_compressed_depth(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        depth_mm_uint16: ArrayLike,
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """image_transport ``compressedDepth`` PNG of (H, W) uint16 millimetres (0 = invalid)."""
        msg = m.compressed_depth_msg(stamp_ns, frame_id, depth_mm_uint16)
        self._write(topic, m.COMPRESSED_IMAGE, msg, stamp_ns, log_time_ns)

    def write_camera_info(
        self,
        topic: str,
        stamp_ns: int,
        camera: CameraModel,
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """``sensor_msgs/CameraInfo`` of ``camera`` (header frame = ``camera.frame_id``)."""
        self._write(
            topic, m.CAMERA_INFO, m.camera_info_msg(stamp_ns, camera), stamp_ns, log_time_ns
        )

    def write_tf(
        self,
        stamp_ns: int,
        transforms: Sequence[tuple[str, str, np.ndarray]],
        *,
        static: bool = False,
        log_time_ns: int | None = None,
    ) -> None:
        """One ``tf2_msgs/TFMessage`` on /tf (or /tf_static) of (parent, child, T_parent_child)."""
        topic = "/tf_static" if static else "/tf"
        self._write(topic, m.TF_MESSAGE, m.tf_msg(stamp_ns, transforms), stamp_ns, log_time_ns)

    def write_path(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        points: ArrayLike,
        orientations_xyzw: ArrayLike | None = None,
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """``nav_msgs/Path`` through (N, 3) points in metres (identity orientations by default)."""
        msg = m.path_msg(stamp_ns, frame_id, points, orientations_xyzw)
        self._write(topic, m.PATH, msg, stamp_ns, log_time_ns)

    def write_pose_array(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        positions: ArrayLike,
        orientations_xyzw: ArrayLike,
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """``geometry_msgs/PoseArray`` of (N, 3) positions and (N, 4) xyzw quaternions."""
        msg = m.pose_array_msg(stamp_ns, frame_id, positions, orientations_xyzw)
        self._write(topic, m.POSE_ARRAY, msg, stamp_ns, log_time_ns)

    def write_pointcloud(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        points: ArrayLike,
        rgb: ArrayLike | None = None,
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """``sensor_msgs/PointCloud2``: float32 x, y, z of (N, 3) metres (+ (N, 3) uint8 rgb)."""
        msg = m.pointcloud_msg(stamp_ns, frame_id, points, rgb)
        self._write(topic, m.POINT_CLOUD2, msg, stamp_ns, log_time_ns)

    def write_marker_array(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        markers: Sequence[m.MarkerSpec],
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """``visualization_msgs/MarkerArray`` of :class:`~.messages.MarkerSpec` markers."""
        msg = m.marker_array_msg(stamp_ns, frame_id, markers)
        self._write(topic, m.MARKER_ARRAY, msg, stamp_ns, log_time_ns)

    def write_string(
        self, topic: str, stamp_ns: int, text: str, *, log_time_ns: int | None = None
    ) -> None:
        """``std_msgs/String`` (it has no header: ``stamp_ns`` is the log time)."""
        self._write(topic, m.STRING, m.string_msg(text), stamp_ns, log_time_ns)

    def write_joint_state(
        self,
        topic: str,
        stamp_ns: int,
        names: Sequence[str],
        positions: ArrayLike,
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """``sensor_msgs/JointState`` with positions (radians / metres) only."""
        msg = m.joint_state_msg(stamp_ns, names, positions)
        self._write(topic, m.JOINT_STATE, msg, stamp_ns, log_time_ns)

    def write_joint_trajectory(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        names: Sequence[str],
        times_s: ArrayLike,
        positions: ArrayLike,
        velocities: ArrayLike | None = None,
        accelerations: ArrayLike | None = None,
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """``trajectory_msgs/JointTrajectory`` (see ``messages.joint_trajectory_msg``)."""
        msg = m.joint_trajectory_msg(
            stamp_ns, frame_id, names, times_s, positions, velocities, accelerations
        )
        self._write(topic, m.JOINT_TRAJECTORY, msg, stamp_ns, log_time_ns)

    # ------------------------------------------------------------------ internals

    def _write(
        self, topic: str, msgtype: str, msg: object, stamp_ns: int, log_time_ns: int | None
    ) -> None:
        self.write_message(
            topic,
            msgtype,
            msg,
            log_time_ns=int(stamp_ns) if log_time_ns is None else int(log_time_ns),
        )


def _check_metadata(name: str, data: dict[str, str]) -> None:
    bad = {k: v for k, v in data.items() if not isinstance(k, str) or not isinstance(v, str)}
    if bad:
        raise ValueError(f"metadata {name!r} must map strings to strings, got {bad!r}")


class McapWriter(MessageWriter):
    """Write a ROS 2 MCAP recording (context manager).

    Parameters
    ----------
    path : str or Path
        Target file (``.mcap``). It appears only when the writer closes without an error.
    chunk_size : int
        Uncompressed bytes per chunk.
    compression : str
        ``zstd`` (default), ``lz4`` or ``none``.

    The typed ``write_*`` methods are :class:`MessageWriter`'s.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        chunk_size: int = 4 << 20,
        compression: str = "zstd",
    ) -> None:
        from mcap.writer import CompressionType, Writer

        if compression not in _COMPRESSIONS:
            raise ValueError(
                f"unknown MCAP compression {compression!r}; known: {', '.join(_COMPRESSIONS)}"
            )
        if chunk_size <= 0:
            raise ValueError(f"chunk_size must be positive, got {chunk_size}")
        self.path = Path(path)
        self._stack = contextlib.ExitStack()
        self._closed = False
        try:
            tmp = self._stack.enter_context(atomic_path(self.path))
            self._stream: IO[bytes] = self._stack.enter_context(open(tmp, "wb"))  # noqa: SIM115
            self._writer = Writer(
                self._stream,
                chunk_size=chunk_size,
                compression=CompressionType[compression.upper()],
            )
            self._writer.start(profile="ros2", library=f"scrapcut {__version__}")
        except BaseException:
            self._stack.__exit__(*sys.exc_info())
            raise
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self._sequence: dict[int, int] = {}

    # ------------------------------------------------------------------ lifecycle

    def __enter__(self) -> McapWriter:
        return self

    def close(self) -> None:
        """Write the summary and footer and move the file onto ``path``."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
            self._stream.flush()
        except BaseException:
            self._stack.__exit__(*sys.exc_info())
            raise
        self._stack.close()

    def abort(
        self,
        exc_type: type[BaseException] | None = None,
        exc: BaseException | None = None,
        tb: TracebackType | None = None,
    ) -> None:
        """Drop the temporary file; ``path`` is left as it was."""
        if self._closed:
            return
        self._closed = True
        if exc_type is None:
            exc_type, exc, tb = RuntimeError, RuntimeError("McapWriter aborted"), None
        with contextlib.suppress(Exception):  # already failing: cleanup must not mask it
            self._stack.__exit__(exc_type, exc, tb)

    # ------------------------------------------------------------------ records

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """An MCAP metadata record (string keys and values), e.g. the simulator's settings."""
        _check_metadata(name, data)
        self._check_open()
        self._writer.add_metadata(name, dict(data))

    def write_raw(
        self,
        topic: str,
        msgtype: str,
        data: bytes | memoryview,
        *,
        log_time_ns: int,
        publish_time_ns: int | None = None,
        msgdef: str | None = None,
    ) -> None:
        """Already serialised CDR bytes (``msgdef`` for types the Humble typestore lacks)."""
        self._check_open()
        channel_id = self._channel(topic, msgtype, msgdef)
        sequence = self._sequence[channel_id]
        self._sequence[channel_id] = sequence + 1
        log_time = int(log_time_ns)
        self._writer.add_message(
            channel_id,
            log_time=log_time,
            data=bytes(data),
            publish_time=log_time if publish_time_ns is None else int(publish_time_ns),
            sequence=sequence,
        )

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"McapWriter for {self.path} is closed")

    def _channel(self, topic: str, msgtype: str, msgdef: str | None) -> int:
        known = self._channels.get(topic)
        if known is not None:
            channel_id, known_type = known
            if known_type != msgtype:
                raise ValueError(f"topic {topic} already carries {known_type}, not {msgtype}")
            return channel_id
        schema_id = self._schemas.get(msgtype)
        if schema_id is None:
            text = m.msgdef_text(msgtype) if msgdef is None else msgdef
            schema_id = self._writer.register_schema(
                name=msgtype, encoding="ros2msg", data=text.encode()
            )
            self._schemas[msgtype] = schema_id
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=schema_id, metadata={}
        )
        self._channels[topic] = (channel_id, msgtype)
        self._sequence[channel_id] = 0
        return channel_id


class Ros2BagWriter(MessageWriter):
    """Write a ROS 2 bag directory (context manager), as ``ros2 bag record`` does.

    Parameters
    ----------
    path : str or Path
        The bag directory. It appears only when the writer closes without an error; an
        existing ROS 2 bag there is replaced, any other non-empty directory is refused.
    storage : str
        ``sqlite3`` (default: rosbag2's) or ``mcap``.

    Metadata maps go into ``metadata.yaml``'s ``custom_data`` as JSON under
    ``scrapcut.metadata.<name>``, where the readers find them; /tf_static is offered with
    transient-local durability (latched), as tf2's static broadcaster does.
    """

    def __init__(self, path: str | os.PathLike[str], *, storage: str = "sqlite3") -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        if storage not in ROS2_STORAGES:
            raise ValueError(
                f"unknown ROS 2 storage {storage!r}; known: {', '.join(ROS2_STORAGES)}"
            )
        self.path = Path(path)
        if self.path.is_file():
            raise ValueError(f"{self.path} is a file; a ROS 2 bag is a directory")
        if is_foreign_directory(self.path):
            raise ValueError(
                f"{self.path} is a directory that is not a ROS 2 bag; it would be replaced whole"
            )
        self._stack = contextlib.ExitStack()
        self._closed = False
        try:
            self._tmp = self._stack.enter_context(atomic_path(self.path, directory=True))
            # rosbags creates the bag directory itself and names the storage file after it:
            # write tmp/<name>/ and lift its files into tmp, which is renamed onto path.
            self._bag = self._tmp / self.path.name
            plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
            self._writer: Any = Writer(self._bag, version=9, storage_plugin=plugin)
            self._writer.open()
        except BaseException:
            self._stack.__exit__(*sys.exc_info())
            raise
        self._connections: dict[str, tuple[Any, str]] = {}

    def __enter__(self) -> Ros2BagWriter:
        return self

    def close(self) -> None:
        """Close the storage, write metadata.yaml and move the directory onto ``path``."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.close()
            for item in self._bag.iterdir():
                shutil.move(str(item), self._tmp / item.name)
            self._bag.rmdir()
        except BaseException:
            self._stack.__exit__(*sys.exc_info())
            raise
        self._stack.close()

    def abort(
        self,
        exc_type: type[BaseException] | None = None,
        exc: BaseException | None = None,
        tb: TracebackType | None = None,
    ) -> None:
        """Drop the temporary directory; ``path`` is left as it was."""
        if self._closed:
            return
        self._closed = True
        if exc_type is None:
            exc_type, exc, tb = RuntimeError, RuntimeError("Ros2BagWriter aborted"), None
        with contextlib.suppress(Exception):  # already failing: cleanup must not mask it
            self._writer.close()
        with contextlib.suppress(Exception):
            self._stack.__exit__(exc_type, exc, tb)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """``custom_data`` entry ``scrapcut.metadata.<name>``: the map as JSON."""
        _check_metadata(name, data)
        self._check_open()
        self._writer.set_custom_data(CUSTOM_DATA_PREFIX + name, json.dumps(dict(data)))

    def write_raw(
        self,
        topic: str,
        msgtype: str,
        data: bytes | memoryview,
        *,
        log_time_ns: int,
        publish_time_ns: int | None = None,
        msgdef: str | None = None,
    ) -> None:
        """Already serialised CDR bytes (``msgdef`` for types the Humble typestore lacks); a
        bag keeps one time per message, the log time."""
        self._check_open()
        known = self._connections.get(topic)
        if known is None:
            from rosbags.convert.converter import LATCH

            conn = self._writer.add_connection(
                topic,
                msgtype,
                typestore=None if msgdef is not None else m.typestore(),
                msgdef=msgdef,
                offered_qos_profiles=LATCH if topic == "/tf_static" else (),
            )
            known = self._connections[topic] = (conn, msgtype)
        elif known[1] != msgtype:
            raise ValueError(f"topic {topic} already carries {known[1]}, not {msgtype}")
        self._writer.write(known[0], int(log_time_ns), bytes(data))

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"Ros2BagWriter for {self.path} is closed")


def is_foreign_directory(path: Path) -> bool:
    """True for an existing, non-empty directory that is not a ROS 2 bag (never replaced)."""
    return path.is_dir() and not (path / "metadata.yaml").is_file() and any(path.iterdir())


def open_writer(path: str | os.PathLike[str], *, storage: str = "sqlite3") -> MessageWriter:
    """A writer for ``path``: an MCAP file for ``*.mcap``, else a ROS 2 bag directory with
    ``storage`` (``sqlite3`` or ``mcap``)."""
    if Path(path).suffix.lower() == ".mcap":
        return McapWriter(path)
    return Ros2BagWriter(path, storage=storage)
