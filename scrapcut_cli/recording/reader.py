"""Read recordings: MCAP files, ROS 1 ``.bag`` files and ROS 2 bag directories, one code path.

All three go through rosbags' ``AnyReader`` (it reads a bare ``.mcap`` as well as bag
directories with MCAP or sqlite3 storage), which deserialises with the message definitions
stored in the recording. On top of it:

- a first pass reads /tf, /tf_static and only the header bytes of the colour and depth images
  (stamp, frame id, size) to pair colour with depth by header stamp and pose each colour
  stamp (:meth:`Recording.plan`) without decoding pixels (only the first colour and depth
  image are decoded, so a topic of the wrong kind fails before any frame is counted);
- a second pass streams the planned frames (:meth:`Recording.frames`), holding only the
  images whose partner has not arrived yet.

Header stamps, not log times, define frame times: real recorders log tens of ms late.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import os
import stat
import struct
import tempfile
from collections.abc import Collection, Generator, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli._io import check_input_file, file_kind
from scrapcut_cli.config import RecordingConfig
from scrapcut_cli.errors import FileError, RecordingError
from scrapcut_cli.geometry import transform_points
from scrapcut_cli.recording import messages as m
from scrapcut_cli.recording.frame import CameraModel, Frame
from scrapcut_cli.recording.mount import CameraMount
from scrapcut_cli.recording.salvage import SalvageReport, salvage_mcap
from scrapcut_cli.recording.structure import Damaged, check_mcap, check_ros1
from scrapcut_cli.recording.tf import TfBuffer

#: Default topics, first that exists wins (docs/design.md: realsense-ros 4.x, then ROS 1 names).
COLOR_TOPICS = (
    "/camera/camera/color/image_raw",
    "/camera/color/image_raw",
    "/camera/camera/color/image_raw/compressed",
    "/camera/color/image_raw/compressed",
)
DEPTH_TOPICS = (
    "/camera/camera/aligned_depth_to_color/image_raw",
    "/camera/aligned_depth_to_color/image_raw",
    "/camera/camera/aligned_depth_to_color/image_raw/compressedDepth",
    "/camera/aligned_depth_to_color/image_raw/compressedDepth",
)
INFO_TOPICS = ("/camera/camera/color/camera_info", "/camera/color/camera_info")
REFERENCE_TOPIC = "/scrapcut/reference"
EXPLORATION_TOPIC = "/scrapcut/exploration"
#: ROS 1 bags have no metadata records; converted recordings keep theirs on this topic.
METADATA_TOPIC = "/scrapcut/metadata"
#: ROS 2 bag directories keep metadata in metadata.yaml's custom_data under this prefix.
CUSTOM_DATA_PREFIX = "scrapcut.metadata."

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_ROS1_MAGIC = b"#ROSBAG V2.0\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_KIND = {".mcap": "an MCAP file", ".bag": "a ROS 1 bag", ".db3": "a ROS 2 sqlite3 bag file"}


@dataclass(frozen=True)
class TopicInfo:
    """One topic: its name, ROS 2 style message type and message count."""

    name: str
    msgtype: str
    count: int


@dataclass(frozen=True)
class FramePlan:
    """Which colour images become frames, decided from headers only.

    Attributes
    ----------
    usable, skipped : int
        Colour images that become frames / that do not.
    skip_reasons : dict[str, int]
        ``no_depth`` (no depth image within the sync tolerance), ``duplicate_stamp`` (an
        earlier colour image has the same stamp), ``pose_out_of_range`` (the stamp lies
        outside the sampled TF time range), ``outside_crop`` (left out by ``--frames`` /
        ``--time``); only reasons that occur.
    unpaired_depth : int
        Depth images no colour image was paired with.
    stamps_ns : (usable,) int64
        Colour header stamps of the usable frames, in recording order.
    depth_stamps_ns : (usable,) int64
        Header stamps of the depth images paired with them.
    T_base_cam : (usable, 4, 4) float64
        Camera poses at ``stamps_ns``, base frame.
    color_index, depth_index : (usable,) int64
        Position of each frame's colour / depth message on its topic.
    """

    usable: int
    skipped: int
    skip_reasons: dict[str, int]
    unpaired_depth: int
    stamps_ns: NDArray[np.int64]
    depth_stamps_ns: NDArray[np.int64]
    T_base_cam: NDArray[np.float64]
    color_index: NDArray[np.int64]
    depth_index: NDArray[np.int64]


@dataclass
class _ImageHeaders:
    """Header stamps, frame ids and sizes of one image topic, in stream order."""

    topic: str
    stamps: list[int] = field(default_factory=list)
    frame_id: str | None = None
    size: tuple[int, int] | None = None


def detect_format(path: Path) -> str:
    """``mcap``, ``ros1`` or ``ros2`` from the path's contents (not only its name).

    Only regular files and folders are opened: a named pipe or a device is refused at once.
    """
    try:
        st = path.stat()
    except (FileNotFoundError, NotADirectoryError):
        raise RecordingError(f"recording not found: {path}") from None
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode) and not stat.S_ISDIR(st.st_mode):
        raise RecordingError(
            f"{path} is {file_kind(st.st_mode)}, not a recording file; copy it to a file first"
        )
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return "ros2"
        hint = ""
        storage = sorted(f for f in path.iterdir() if f.suffix in (".mcap", ".db3"))
        if storage:
            # An interrupted `ros2 bag record` leaves its storage files but no metadata.yaml.
            hint = "; run `ros2 bag reindex` on it"
            if storage[0].suffix == ".mcap":
                hint = f"; open {storage[0]} itself, or run `ros2 bag reindex` on the directory"
        raise RecordingError(
            f"{path} is a directory but not a ROS 2 bag (it has no metadata.yaml){hint}"
        )
    try:
        with path.open("rb") as f:
            head = f.read(16)
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror}") from None
    if head.startswith(_MCAP_MAGIC):
        fmt, suffix = "mcap", ".mcap"
    elif head.startswith(_ROS1_MAGIC):
        fmt, suffix = "ros1", ".bag"
    elif head.startswith(_SQLITE_MAGIC):
        fmt, suffix = "ros2", ".db3"
    else:
        raise RecordingError(
            f"{path} is not a recording (expected an MCAP file, a ROS 1 .bag or a ROS 2 bag "
            "directory)"
        )
    if path.suffix != suffix:
        # rosbags picks its storage reader by file name.
        raise RecordingError(
            f"{path} is {_KIND[suffix]} but is not named *{suffix}; rename it to "
            f"{path.with_suffix(suffix).name}"
        )
    return fmt


def open_recording(
    path: str | os.PathLike[str],
    config: RecordingConfig | None = None,
    *,
    mount: CameraMount | None = None,
) -> Recording:
    """Open a recording for reading (a context manager; close it when done).

    Only the index is read here; topics, camera and TF are resolved when first needed, so a
    recording without camera topics still serves :meth:`Recording.reference`. With ``mount``
    (a calibration) frames are posed with its camera mount and clock offset instead of the
    recording's /tf_static and header stamps alone.
    """
    return Recording(Path(path), config or RecordingConfig(), mount=mount)


class Recording:
    """An open recording. See the module docstring for what each pass reads."""

    def __init__(
        self, path: Path, config: RecordingConfig, *, mount: CameraMount | None = None
    ) -> None:
        from rosbags.highlevel import AnyReader

        if path.name == "metadata.yaml" and path.is_file():
            path = path.parent
        self.path = path
        self.config = config
        self.mount = mount
        self.format = detect_format(path)
        #: What ``--salvage`` kept of a damaged MCAP (None: the file was read as it is).
        self.salvaged: SalvageReport | None = None
        self._scratch: tempfile.TemporaryDirectory[str] | None = None
        self._source = self._checked_source()
        try:
            self._reader = AnyReader([self._source], default_typestore=m.typestore())
            self._reader.open()
        except Exception as exc:  # whatever rosbags raises on a file that passed the checks
            self._drop_scratch()
            raise RecordingError(self._open_error(exc)) from None
        _map_sqlite_storage(self._reader)
        self._connections: dict[str, list[Any]] = {}
        for conn in self._reader.connections:
            self._connections.setdefault(conn.topic, []).append(conn)
        self._tf: TfBuffer | None = None
        self._plan: FramePlan | None = None
        self._headers: tuple[_ImageHeaders, _ImageHeaders] | None = None
        self._published_mount: CameraMount | None = None

    def _checked_source(self) -> Path:
        """The file or folder to hand to rosbags, after the structure checks (a salvaged copy
        of a damaged MCAP with ``--salvage``)."""
        if self.format == "ros1":
            try:
                check_ros1(self.path)
            except Damaged as exc:
                raise RecordingError(
                    f"damaged ROS 1 bag {self.path}: {exc}; a bag cut off while recording can be "
                    "rebuilt with `rosbag reindex`"
                ) from None
            return self.path
        files = [self.path] if self.format == "mcap" else self._storage_files()
        for file in files:
            try:
                check_mcap(file)
            except Damaged as exc:
                if self.format == "mcap" and self.config.salvage:
                    return self._salvage()
                if not _has_mcap_footer(file):
                    what = "truncated (no footer; the recorder was cut off)"
                    raise RecordingError(
                        f"MCAP file {file} is {what}; `mcap recover` can salvage its complete "
                        f"chunks{self._salvage_hint}"
                    ) from None
                raise RecordingError(
                    f"damaged recording {file}: {exc} (try `mcap recover`{self._salvage_hint})"
                ) from None
        return self.path

    @property
    def _salvage_hint(self) -> str:
        return ", or --salvage to read up to the damage" if self.format == "mcap" else ""

    def _storage_files(self) -> list[Path]:
        """A ROS 2 bag's MCAP storage files (each must be a regular file)."""
        files = []
        for file in sorted(self.path.iterdir()):
            if file.suffix in (".mcap", ".db3") or file.name == "metadata.yaml":
                try:
                    check_input_file(file, "bag file")
                except FileError as exc:
                    raise RecordingError(str(exc)) from None
                if file.suffix == ".mcap":
                    files.append(file)
        return files

    def _salvage(self) -> Path:
        self._scratch = tempfile.TemporaryDirectory(prefix="scrapcut-salvage-")
        copy = Path(self._scratch.name) / self.path.name
        try:
            self.salvaged = salvage_mcap(self.path, copy)
        except BaseException:
            self._drop_scratch()
            raise
        return copy

    def _drop_scratch(self) -> None:
        if self._scratch is not None:
            self._scratch.cleanup()
            self._scratch = None

    def _damaged(self, exc: BaseException) -> str:
        """One line for whatever a reading library raised on damaged content."""
        from rosbags.rosbag1 import ReaderError as Reader1Error
        from rosbags.rosbag2 import ReaderError as Reader2Error

        text = one_line(str(exc))
        if not isinstance(exc, Reader1Error | Reader2Error) or not text:
            text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
        hint = {
            "mcap": "try `mcap recover`, or --salvage to read up to the damage",
            "ros1": "try `rosbag reindex`",
            "ros2": "try `ros2 bag reindex`",
        }[self.format]
        return f"damaged recording {self.path}: {text} ({hint})"

    def _open_error(self, exc: BaseException) -> str:
        reason = one_line(str(exc)) or type(exc).__name__
        mcap_file = self.path
        if self.format == "ros2" and self.path.is_dir():
            storage = sorted(self.path.glob("*.mcap"), key=_split_number)
            mcap_file = storage[0] if storage else self.path
        if mcap_file.suffix == ".mcap" and not _has_mcap_footer(mcap_file):
            return (
                f"MCAP file {mcap_file} is truncated (no footer; the recorder was cut off); "
                "`mcap recover` can salvage its complete chunks"
            )
        if self.format == "ros1" and "index" in reason.lower():
            return (
                f"cannot read ROS 1 bag {self.path}: {reason}; a bag cut off while recording "
                "can be rebuilt with `rosbag reindex`"
            )
        if not isinstance(exc, OSError | ValueError) or isinstance(exc, UnicodeDecodeError):
            return self._damaged(exc)
        return f"cannot read {self.format} recording {self.path}: {reason}"

    # ------------------------------------------------------------------ lifecycle

    def close(self) -> None:
        if self._reader.stack is not None:
            self._reader.close()
        self._drop_scratch()

    def __enter__(self) -> Recording:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ summary

    def topics(self) -> list[TopicInfo]:
        """Every topic with its type and message count, sorted by name."""
        out = []
        for name, conns in sorted(self._connections.items()):
            types = sorted({c.msgtype for c in conns})
            out.append(TopicInfo(name, " | ".join(types), sum(c.msgcount for c in conns)))
        return out

    @property
    def duration_s(self) -> float:
        """Seconds from the first to the last logged message."""
        if not self._reader.message_count:
            return 0.0
        # rosbags reports end_time one past the last message.
        return max(self._reader.end_time - 1 - self._reader.start_time, 0) / 1e9

    @property
    def start_ns(self) -> int:
        """Log time of the first message (0 for an empty recording)."""
        return int(self._reader.start_time) if self._reader.message_count else 0

    @property
    def typestore(self) -> Any:
        """rosbags typestore built from the recording's own message definitions."""
        return self._reader.typestore

    @functools.cached_property
    def metadata(self) -> dict[str, dict[str, str]]:
        """Named string maps: MCAP metadata records, a ROS 2 bag's custom_data entries, or a
        ROS 1 bag's /scrapcut/metadata topic (see :func:`convert_recording`)."""
        out: dict[str, dict[str, str]] = {}
        if self.format == "mcap":
            out.update(self._mcap_metadata())
        elif self.format == "ros2":
            out.update(self._custom_data_metadata())
        if METADATA_TOPIC in self._connections:
            for _, _, msg in self.messages([METADATA_TOPIC]):
                records = _json_object(str(msg.data), METADATA_TOPIC)
                out.update({k: _string_map(v, METADATA_TOPIC) for k, v in records.items()})
        return out

    def _mcap_metadata(self) -> dict[str, dict[str, str]]:
        from mcap.exceptions import McapError
        from mcap.reader import make_reader

        try:
            with self._source.open("rb") as f:
                return {md.name: dict(md.metadata) for md in make_reader(f).iter_metadata()}
        except (McapError, Exception) as exc:  # a damaged metadata record, whatever it raises
            text = one_line(f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__)
            raise RecordingError(f"cannot read the metadata of {self.path}: {text}") from None

    def _custom_data_metadata(self) -> dict[str, dict[str, str]]:
        storage = getattr(self._reader.readers[0], "storage", None)
        custom = getattr(getattr(storage, "metadata", None), "custom", None) or {}
        out: dict[str, dict[str, str]] = {}
        for key, value in custom.items():
            if key.startswith(CUSTOM_DATA_PREFIX):
                out[key[len(CUSTOM_DATA_PREFIX) :]] = _string_map(_json_object(value, key), key)
        return out

    def has_topic(self, topic: str) -> bool:
        return topic in self._connections

    # ------------------------------------------------------------------ topics

    @functools.cached_property
    def color_topic(self) -> str:
        """The colour image topic (``--color-topic`` or the first default that exists)."""
        return self._resolve("colour", self.config.color_topic, COLOR_TOPICS, "--color-topic")

    @functools.cached_property
    def depth_topic(self) -> str:
        """The depth image topic, aligned to colour."""
        return self._resolve("depth", self.config.depth_topic, DEPTH_TOPICS, "--depth-topic")

    @functools.cached_property
    def info_topic(self) -> str:
        """The colour CameraInfo topic."""
        return self._resolve("camera_info", self.config.info_topic, INFO_TOPICS, "--info-topic")

    def _resolve(self, what: str, given: str | None, defaults: Sequence[str], option: str) -> str:
        wanted = (m.CAMERA_INFO,) if what == "camera_info" else m.IMAGE_TYPES
        if given is not None:
            if given not in self._connections:
                raise RecordingError(
                    f"{what} topic {given} is not in {self.path.name}; "
                    f"{self._candidates_text(wanted)}; pick one with {option}"
                )
            candidates = [given]
        else:
            candidates = [t for t in defaults if t in self._connections]
            if not candidates:
                raise RecordingError(
                    f"no {what} topic in {self.path.name} (looked for {', '.join(defaults[:2])}); "
                    f"{self._candidates_text(wanted)}; pick one with {option}"
                )
        topic = candidates[0]
        types = {c.msgtype for c in self._connections[topic]}
        if not types <= set(wanted):
            raise RecordingError(
                f"{what} topic {topic} carries {', '.join(sorted(types))}, not "
                f"{' or '.join(wanted)}; pick another with {option}"
            )
        return topic

    def _candidates_text(self, msgtypes: Sequence[str]) -> str:
        found = [
            name
            for name, conns in sorted(self._connections.items())
            if any(c.msgtype in msgtypes for c in conns)
        ]
        kind = "CameraInfo" if m.CAMERA_INFO in msgtypes else "image"
        if not found:
            return f"it has no {kind} topics at all"
        return f"{kind} topics present: {', '.join(found)}"

    def _conns(self, topics: Iterable[str]) -> list[Any]:
        return [c for t in topics for c in self._connections.get(t, [])]

    # ------------------------------------------------------------------ raw access

    def raw_messages(
        self, topics: Iterable[str] | None = None
    ) -> Generator[tuple[str, str, int, bytes], None, None]:
        """(topic, msgtype, log_time_ns, serialised bytes) in log-time order (all topics if
        None); bytes are CDR for MCAP / ROS 2, ROS 1 serialisation for ``.bag``."""
        for conn, log_time, raw in self.raw_connection_messages(topics):
            yield conn.topic, conn.msgtype, log_time, raw

    def raw_connection_messages(
        self, topics: Iterable[str] | None = None
    ) -> Generator[tuple[Any, int, bytes], None, None]:
        """As :meth:`raw_messages`, with rosbags' Connection (publisher details) per message."""
        conns = self._reader.connections if topics is None else self._conns(topics)
        if not conns:
            return
        try:
            for conn, log_time, raw in self._reader.messages(connections=conns):
                yield conn, int(log_time), raw
        except Exception as exc:  # rosbags on damaged data: KeyError, AssertionError, zstd...
            raise RecordingError(self._damaged(exc)) from None

    def deserialize(self, raw: bytes | memoryview, msgtype: str) -> Any:
        """A message object from its bytes (ROS 1 field names for ``.bag`` recordings)."""
        try:
            return self._reader.deserialize(bytes(raw), msgtype)
        except Exception as exc:  # a damaged payload, whatever the deserialiser raises
            text = one_line(str(exc), 200) or type(exc).__name__
            raise RecordingError(
                f"damaged recording {self.path}: cannot decode a {msgtype} message ({text})"
            ) from None

    def messages(self, topics: Iterable[str]) -> Iterator[tuple[str, int, Any]]:
        """(topic, stamp_ns, message) for the given topics, in log-time order.

        The stamp is the header stamp if the message has one, else the log time.
        """
        topics = list(topics)
        missing = [t for t in topics if t not in self._connections]
        if missing:
            raise RecordingError(
                f"topic {', '.join(missing)} not in {self.path.name}; topics: "
                f"{', '.join(sorted(self._connections))}"
            )
        for topic, msgtype, log_time, raw in self.raw_messages(topics):
            msg = self.deserialize(raw, msgtype)
            stamp = m.message_stamp_ns(msg)
            yield topic, log_time if stamp is None else stamp, msg

    # ------------------------------------------------------------------ camera and TF

    @functools.cached_property
    def camera(self) -> CameraModel:
        """Intrinsics from the first CameraInfo (size from the colour images if it has none)."""
        topic = self.info_topic
        first = self._first_raw(topic)
        if first is None:
            raise RecordingError(f"camera_info topic {topic} has no messages")
        msg = self.deserialize(first[1], first[0])
        width, height = int(msg.width), int(msg.height)
        if not (width and height):
            image = self._first_raw(self.color_topic)
            size = None if image is None else m.raw_image_size(image[1], image[0], cdr=self._cdr)
            if size is None:
                raise RecordingError(
                    f"CameraInfo on {topic} has no image size and none can be read from "
                    f"{self.color_topic}"
                )
            height, width = size
        try:
            return m.camera_from_info(msg, width=width, height=height)
        except RecordingError as exc:
            raise RecordingError(
                f"{exc} (CameraInfo on {topic}; pick another with --info-topic)"
            ) from None

    def _first_raw(self, topic: str) -> tuple[str, bytes] | None:
        """(msgtype, bytes) of the first message on ``topic``, reading no further."""
        stream = self.raw_messages([topic])
        try:
            for _, msgtype, _, raw in stream:
                return msgtype, raw
        finally:
            stream.close()
        return None

    @property
    def _cdr(self) -> bool:
        """Serialisation: CDR for MCAP and ROS 2, ROS 1's own for ``.bag``."""
        return self.format != "ros1"

    @property
    def tf(self) -> TfBuffer:
        """Every /tf and /tf_static transform of the recording."""
        if self._tf is None:
            self._index(with_images=False)
        assert self._tf is not None
        return self._tf

    @property
    def camera_frame(self) -> str:
        """The colour images' header frame id (the optical frame)."""
        headers = self._image_headers()[0]
        if headers.frame_id is None:
            raise RecordingError(f"colour topic {self.color_topic} has no messages")
        return headers.frame_id

    @functools.cached_property
    def base_frame(self) -> str:
        """``--base-frame`` or the root of the TF tree that holds the camera frame."""
        if self.config.base_frame:
            base = self.config.base_frame.lstrip("/")
            if not self.tf.has_frame(base):
                raise RecordingError(
                    f"base frame {base!r} is not in the TF tree; TF frames: {_frames_text(self.tf)}"
                )
            moving = self.tf.moving_links(base)
            if moving:
                # A path in a frame that moves during the scan is no path at all.
                root = self.tf.root(base)
                raise RecordingError(
                    f"--base-frame {base} moves during the scan (its TF chain to {root!r} has "
                    f"the time-varying link {moving[-1][0]} -> {moving[-1][1]}); pass the robot's "
                    f"fixed base ({root}) or a frame fixed to it"
                )
            return base
        camera = self.camera_frame
        if not self.tf.has_frame(camera):
            raise RecordingError(
                f"no TF path from image frame {camera!r} to a base frame: {camera!r} is not in "
                f"/tf or /tf_static; TF frames: {_frames_text(self.tf)}"
            )
        root = self.tf.root(camera)
        # Another tree of moving frames means the robot's chain is split: the camera's tree
        # then hangs from a link of the arm, not from its base (a transform not recorded).
        split = [r for r in self.tf.roots if r != root and self.tf.moving_frames(r)]
        if split:
            others = self.tf.moving_frames(split[0])
            raise RecordingError(
                f"the TF tree is split: image frame {camera!r} hangs from {root!r}, apart from "
                f"the tree of {split[0]!r} (moving: {', '.join(others[:3])}); a transform "
                f"joining them is missing from /tf or /tf_static; record it, or pass "
                f"--base-frame {root} if {root!r} is the fixed base"
            )
        return root

    def _image_headers(self) -> tuple[_ImageHeaders, _ImageHeaders]:
        if self._headers is None:
            self._index(with_images=True)
        assert self._headers is not None
        return self._headers

    def _index(self, *, with_images: bool) -> None:
        """One pass over TF (unless already read) and, if asked, the image headers."""
        read_tf = self._tf is None
        tf = TfBuffer() if read_tf else self._tf
        assert tf is not None
        tf_topics = {"/tf": False, "/tf_static": True} if read_tf else {}
        topics = list(tf_topics)
        color = depth = None
        if with_images:
            color, depth = _ImageHeaders(self.color_topic), _ImageHeaders(self.depth_topic)
            if color.topic == depth.topic:
                raise RecordingError(f"colour and depth topics are the same: {color.topic}")
            topics += [color.topic, depth.topic]
        image_headers = {h.topic: h for h in (color, depth) if h is not None}
        # A raw image's header and size lie in its first bytes: from a sqlite3 bag only those
        # are read (a 1280x720 depth image is 1.8 MB), the messages in the same order.
        heads = self._sqlite_image_heads(list(image_headers)) if image_headers else None
        messages: Iterable[tuple[str, str, int, bytes]] = self.raw_messages(
            list(tf_topics) if heads is not None else topics
        )
        if heads is not None:
            messages = itertools.chain(messages, heads)
        for topic, msgtype, _, raw in messages:
            if topic in tf_topics:
                if msgtype in m.TF_TYPES:
                    transforms = m.raw_tf_transforms(raw, cdr=self._cdr)
                    if transforms is None:  # not the standard layout: rosbags decides
                        transforms = m.tf_transforms(self.deserialize(raw, msgtype))
                    tf.add_transforms(transforms, static=tf_topics[topic])
                continue
            headers = image_headers[topic]
            stamp, frame_id, _ = m.raw_header(raw, cdr=self._cdr)
            headers.stamps.append(stamp)
            if headers.frame_id is None:
                headers.frame_id = frame_id.lstrip("/")
            size = m.raw_image_size(raw, msgtype, cdr=self._cdr)
            if headers.size is None:
                headers.size = size
            elif size is not None and size != headers.size:
                raise RecordingError(
                    f"image size changes on {topic}: {_size_text(headers.size)} then "
                    f"{_size_text(size)}"
                )
        self._tf = tf
        if color is not None and depth is not None:
            if color.size and depth.size and color.size != depth.size:
                raise RecordingError(
                    f"colour images on {color.topic} are {_size_text(color.size)} but depth "
                    f"images on {depth.topic} are {_size_text(depth.size)}; use the depth topic "
                    "aligned to colour (--depth-topic)"
                )
            self._headers = (color, depth)

    def _sqlite_image_heads(
        self, topics: Sequence[str]
    ) -> Iterator[tuple[str, str, int, bytes]] | None:
        """:meth:`raw_messages` of image topics for the index pass, reading only the head
        (:data:`IMAGE_HEAD_BYTES`) of a raw Image that holds its header and size; None when
        the recording is not a single-file, uncompressed ROS 2 sqlite3 bag (read as usual).

        rosbags' own query with the message's row id for its data, then SQLite's incremental
        blob reads: the same messages in the same order, the heads' bytes the messages'.
        """
        storages = _sqlite_storages(self._reader)
        if storages is None or not self._cdr:
            return None
        conns = self._conns(topics)
        if not conns:
            return None
        return self._read_sqlite_heads(storages, conns)

    def _read_sqlite_heads(
        self, storages: list[Any], conns: list[Any]
    ) -> Iterator[tuple[str, str, int, bytes]]:
        try:
            for storage in storages:
                wanted = {}
                for x in storage.connections:
                    y = next((c for c in conns if _same_connection(x, c)), None)
                    if y is not None:
                        wanted[x.id] = y
                if not wanted:
                    continue
                ids = tuple(wanted)
                query = (
                    "SELECT topics.id,messages.timestamp,messages.id "
                    "FROM messages JOIN topics ON messages.topic_id=topics.id "
                    f"WHERE topics.id IN ({','.join('?' for _ in ids)}) ORDER BY timestamp"
                )
                db = storage.dbconn
                for cid, log_time, rowid in list(db.execute(query, ids)):
                    conn = wanted[cid]
                    with db.blob_open("main", "messages", "data", rowid, False) as blob:
                        raw = blob.read(IMAGE_HEAD_BYTES if conn.msgtype == m.IMAGE else -1)
                        if conn.msgtype == m.IMAGE and not _image_head_complete(raw):
                            blob.seek(0)
                            raw = blob.read()
                    yield conn.topic, conn.msgtype, int(log_time), raw
        except RecordingError:
            raise
        except Exception as exc:  # apsw on damaged data
            raise RecordingError(self._damaged(exc)) from None

    # ------------------------------------------------------------------ frames

    def plan(self) -> FramePlan:
        """Pair colour with depth and pose every colour stamp, from headers (and the first
        colour and depth image, decoded as a check)."""
        if self._plan is None:
            self._plan = self._make_plan()
        return self._plan

    def _make_plan(self) -> FramePlan:
        color, depth = self._image_headers()
        if not color.stamps:
            raise RecordingError(f"colour topic {color.topic} has no messages")
        if not depth.stamps:
            raise RecordingError(f"depth topic {depth.topic} has no messages")
        self._check_first_images()
        camera = self.camera
        if color.size is not None and color.size != (camera.height, camera.width):
            raise RecordingError(
                f"CameraInfo on {self.info_topic} is {camera.width}x{camera.height} but colour "
                f"images on {color.topic} are {_size_text(color.size)}; pick the matching "
                "--info-topic"
            )
        c = np.asarray(color.stamps, dtype=np.int64)
        d = np.asarray(depth.stamps, dtype=np.int64)
        repeated = _repeated_stamps(c)
        if np.count_nonzero(repeated) > MAX_REPEATED_STAMPS * len(c):
            raise RecordingError(
                f"{np.count_nonzero(repeated) + 1} of {len(c)} colour images on {color.topic} "
                f"share a header stamp ({int(c[np.argmax(repeated)])} ns): the driver did not "
                "stamp each image with its capture time, so they cannot be posed; record with "
                "per-image stamps"
            )
        tolerance = round(self.config.sync_tolerance_s * 1e9)
        depth_index, paired = _pair_nearest(c, d, tolerance)
        fresh = paired & ~repeated

        base, camera_frame = self.base_frame, self.camera_frame
        T, in_range = self._poses(base, camera_frame, c[fresh])
        usable_color = np.flatnonzero(fresh)[in_range]
        if self.tf.is_static(base, camera_frame) and len(usable_color) > 1:
            self._refuse_static_chain_if_images_move(base, camera_frame, usable_color)
        T = T[in_range]
        keep = self._crop(c[usable_color])
        outside = int(np.count_nonzero(~keep))
        usable_color, T = usable_color[keep], T[keep]
        reasons = {
            "no_depth": int(np.count_nonzero(~paired)),
            "duplicate_stamp": int(np.count_nonzero(paired & repeated)),
            "pose_out_of_range": int(np.count_nonzero(~in_range)),
            "outside_crop": outside,
        }
        used_depth = depth_index[usable_color]
        return FramePlan(
            usable=len(usable_color),
            skipped=len(c) - len(usable_color),
            skip_reasons={k: v for k, v in reasons.items() if v},
            unpaired_depth=len(d) - len(np.unique(depth_index[paired])),
            stamps_ns=c[usable_color],
            depth_stamps_ns=d[used_depth],
            T_base_cam=T,
            color_index=usable_color.astype(np.int64),
            depth_index=used_depth.astype(np.int64),
        )

    def _crop(self, stamps_ns: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Which usable frames (their colour stamps, in order) ``--frames A:B`` and
        ``--time A:B`` keep; a crop that keeps none is an error naming what there is."""
        keep = np.ones(len(stamps_ns), dtype=bool)
        frames, times = self.config.frames, self.config.time_s
        if frames is not None:
            index = np.arange(len(stamps_ns))
            keep &= (index >= frames[0]) & (index < frames[1])
        if times is not None:
            t = (stamps_ns - self.start_ns) / 1e9
            keep &= (t >= times[0]) & (t < times[1])
        if len(stamps_ns) and not keep.any():
            t0 = (int(stamps_ns[0]) - self.start_ns) / 1e9
            t1 = (int(stamps_ns[-1]) - self.start_ns) / 1e9
            raise RecordingError(
                f"--frames/--time keep no frame: the recording has {len(stamps_ns)} usable "
                f"frames (0:{len(stamps_ns)}) between {t0:.2f} and {t1:.2f} s"
            )
        return keep

    def _refuse_static_chain_if_images_move(
        self, base: str, camera_frame: str, color_index: NDArray[np.int64]
    ) -> None:
        """Every frame gets the same pose when no link between base and camera moves: right
        for a fixed camera, wrong for a camera on the arm whose /tf was not recorded."""
        spread = np.linspace(0, len(color_index) - 1, 4).round().astype(int)
        picks = sorted({int(color_index[k]) for k in spread})
        c = np.asarray(self._image_headers()[0].stamps, dtype=np.int64)[picks]
        d = np.asarray(self._image_headers()[1].stamps, dtype=np.int64)
        tolerance = round(self.config.sync_tolerance_s * 1e9)
        depth_picks = sorted({int(i) for i in _pair_nearest(c, d, tolerance)[0]})
        colors = [m.decode_color(*x) for x in self._pick(self.color_topic, picks)]
        depths = [m.decode_depth(*x) for x in self._pick(self.depth_topic, depth_picks)]
        if any(images_differ(colors[0], other) for other in colors[1:]) or any(
            depths_differ(depths[0], other) for other in depths[1:]
        ):
            raise RecordingError(
                f"the TF chain from {base!r} to image frame {camera_frame!r} has no time-varying "
                "link (only /tf_static) but the images move: every frame would get one pose; "
                "record /tf (the robot's joint transforms)"
            )

    def _pick(self, topic: str, indices: list[int]) -> list[tuple[Any, str]]:
        """(message, msgtype) of the messages at ``indices`` (sorted) on ``topic``."""
        out = []
        stream = self.raw_messages([topic])
        try:
            for k, (_, msgtype, _, raw) in enumerate(stream):
                if k in indices:
                    out.append((self.deserialize(raw, msgtype), msgtype))
                if k >= indices[-1]:
                    break
        finally:
            stream.close()
        return out

    def _check_first_images(self) -> None:
        """Decode the first colour and depth image: a topic of the wrong kind (a colour image
        as depth, JPEG depth) fails here, before a plan counts its frames as usable."""
        checks = (
            (self.color_topic, m.decode_color, "--color-topic"),
            (self.depth_topic, m.decode_depth, "--depth-topic"),
        )
        for topic, decode, option in checks:
            first = self._first_raw(topic)
            if first is None:
                continue
            msgtype, raw = first
            try:
                decode(self.deserialize(raw, msgtype), msgtype)
            except RecordingError as exc:
                raise RecordingError(f"{topic}: {exc}; pick another with {option}") from None

    def _poses(
        self, base: str, camera_frame: str, stamps: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        if self.mount is not None:
            mount = self._checked_mount(self.mount)
            T, valid = self.moving_poses(stamps + mount.time_offset_ns)
            return T @ mount.T_moving_camera, valid
        try:
            return self.tf.lookup(base, camera_frame, stamps)
        except RecordingError as exc:
            raise RecordingError(
                f"no TF path from image frame {camera_frame!r} to base frame {base!r}: {exc}"
            ) from None

    # ------------------------------------------------------------------ camera mount

    def published_mount(self) -> CameraMount:
        """The camera mount as the recording publishes it (time offset 0).

        The moving frame is the child of the last /tf transform between the base frame and
        the image's frame; the mount composes the /tf_static links below it.
        """
        if self._published_mount is None:
            base, camera = self.base_frame, self.camera_frame
            try:
                moving = self.tf.moving_frame(base, camera)
                T = self.tf.lookup_one(moving, camera, 0)  # static links only: any stamp
            except RecordingError as exc:
                raise RecordingError(
                    f"no TF path from image frame {camera!r} to base frame {base!r}: {exc}"
                ) from None
            self._published_mount = CameraMount(moving, camera, T, 0.0)
        return self._published_mount

    def moving_poses(
        self, stamps_ns: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """T_base_moving (N, 4, 4) of the mount's moving frame at TF-clock stamps (N,) int64 ns,
        and whether each is inside the /tf time range (poses interpolated, never extrapolated)."""
        moving = self.published_mount().moving_frame
        return self.tf.lookup(self.base_frame, moving, np.asarray(stamps_ns, dtype=np.int64))

    def _checked_mount(self, mount: CameraMount) -> CameraMount:
        """``mount`` if it fits this recording's TF chain; RecordingError naming the mismatch."""
        camera, base = self.camera_frame, self.base_frame
        if mount.camera_frame != camera:
            raise RecordingError(
                f"the calibration is for camera frame {mount.camera_frame!r} but the images of "
                f"{self.path.name} are in {camera!r}"
            )
        published = self.published_mount()
        if mount.moving_frame != published.moving_frame:
            raise RecordingError(
                f"the calibration mounts the camera on {mount.moving_frame!r} but in "
                f"{self.path.name} the last frame /tf moves above {camera!r} is "
                f"{published.moving_frame!r} (base {base!r})"
            )
        return mount

    def frames(self, only: Collection[int] | None = None) -> Iterator[Frame]:
        """Stream exactly the planned frames, index 0 .. usable-1, in recording order.

        ``only``: the indices of the frames wanted (the others are not decoded). Memory stays
        bounded: an image is held only until its partner arrives.
        """
        plan = self.plan()
        if plan.usable == 0:
            return
        camera, base, camera_frame = self.camera, self.base_frame, self.camera_frame
        color_topic, depth_topic = self.color_topic, self.depth_topic
        frame_of_color = {int(ci): k for k, ci in enumerate(plan.color_index)}
        depth_users: dict[int, int] = {}
        for di in plan.depth_index:
            depth_users[int(di)] = depth_users.get(int(di), 0) + 1
        pending_color: dict[int, tuple[bytes, str]] = {}
        pending_depth: dict[int, tuple[bytes, str]] = {}
        next_frame = 0
        n_color = n_depth = 0
        for topic, msgtype, _, raw in self.raw_messages([color_topic, depth_topic]):
            if topic == color_topic:
                k = frame_of_color.get(n_color)
                n_color += 1
                if k is not None:
                    pending_color[k] = (raw, msgtype)
            else:
                if n_depth in depth_users:
                    pending_depth[n_depth] = (raw, msgtype)
                n_depth += 1
            while next_frame < plan.usable and next_frame in pending_color:
                di = int(plan.depth_index[next_frame])
                if di not in pending_depth:
                    break
                color_raw, color_type = pending_color.pop(next_frame)
                depth_raw, depth_type = pending_depth[di]
                depth_users[di] -= 1
                if depth_users[di] == 0:
                    del pending_depth[di]
                if only is not None and next_frame not in only:
                    next_frame += 1
                    continue
                yield Frame(
                    index=next_frame,
                    stamp_ns=int(plan.stamps_ns[next_frame]),
                    color=m.decode_color(self.deserialize(color_raw, color_type), color_type),
                    depth=self._checked_depth(
                        m.decode_depth(self.deserialize(depth_raw, depth_type), depth_type),
                        camera,
                    ),
                    camera=camera,
                    T_base_cam=plan.T_base_cam[next_frame].copy(),
                    base_frame=base,
                    camera_frame=camera_frame,
                    extras={"depth_stamp_ns": int(plan.depth_stamps_ns[next_frame])},
                )
                next_frame += 1
        if next_frame != plan.usable:
            raise RecordingError(
                f"{self.path} changed while reading: {plan.usable} frames planned, "
                f"{next_frame} read"
            )

    def _checked_depth(
        self, depth: NDArray[np.float32], camera: CameraModel
    ) -> NDArray[np.float32]:
        if depth.shape != (camera.height, camera.width):
            raise RecordingError(
                f"depth image is {depth.shape[1]}x{depth.shape[0]} but the camera is "
                f"{camera.width}x{camera.height}; use the depth topic aligned to colour"
            )
        return depth

    # ------------------------------------------------------------------ simulator topics

    def reference(self) -> NDArray[np.float64] | None:
        """The painted reference curve (N, 3) float64, metres, base frame; None if absent.

        Read from the last ``nav_msgs/Path`` on /scrapcut/reference; a path expressed in
        another TF frame is transformed into the base frame (``--base-frame`` or its TF root).
        """
        found = self.reference_in_frame()
        return None if found is None else found[0]

    def reference_in_frame(self) -> tuple[NDArray[np.float64], str] | None:
        """:meth:`reference` and the frame its points are in ("" if the message names none)."""
        if REFERENCE_TOPIC not in self._connections:
            return None
        last = None
        for _, stamp, msg in self.messages([REFERENCE_TOPIC]):
            last = (stamp, msg)
        if last is None:
            return None
        stamp, msg = last
        points = m.path_points(msg)
        frame = m.frame_id_of(msg).lstrip("/")
        wanted = (self.config.base_frame or "").lstrip("/")
        if not frame or frame == wanted:  # already in the base frame: no need to read /tf
            return points, frame
        if not self.tf.has_frame(frame):
            return points, frame
        base = wanted or self.tf.root(frame)
        if base == frame:
            return points, frame
        T = self.tf.lookup_one(base, frame, stamp)
        return transform_points(T, points), base

    def exploration_log(self) -> list[dict[str, Any]]:
        """The simulator's exploration steps: one JSON object per /scrapcut/exploration message."""
        if EXPLORATION_TOPIC not in self._connections:
            return []
        steps = []
        for _, _, msg in self.messages([EXPLORATION_TOPIC]):
            try:
                step = json.loads(str(msg.data))
            except (json.JSONDecodeError, RecursionError) as exc:
                raise RecordingError(f"{EXPLORATION_TOPIC} holds invalid JSON: {exc}") from None
            if not isinstance(step, dict):
                raise RecordingError(f"{EXPLORATION_TOPIC} messages must be JSON objects")
            steps.append(step)
        return steps


#: How much of a ROS 2 bag's sqlite3 file its connection may memory-map (SQLite caps it at
#: its compile-time limit, 2 GiB by default; beyond the mapped part it reads as before).
SQLITE_MMAP_BYTES = 1 << 30


def _map_sqlite_storage(reader: Any) -> None:
    """Let SQLite read a ROS 2 bag's sqlite3 files through a memory map.

    An image is a BLOB of several hundred 4 KiB overflow pages; read page by page (a system
    call each) two passes over a 1280x720 recording's images cost ~0.7 ms an image, mapped
    ~0.4 ms. rosbags opens the files read-only and immutable, which is what mapping needs; the
    bytes read are the same. Storage other than sqlite3, or a rosbags without these
    attributes, is left alone.
    """
    for bag in getattr(reader, "readers", ()):
        for storage in getattr(getattr(bag, "storage", None), "storages", ()):
            connection = getattr(storage, "dbconn", None)
            if connection is None or not hasattr(connection, "execute"):
                continue
            try:
                for _ in connection.execute(f"PRAGMA mmap_size={SQLITE_MMAP_BYTES}"):
                    pass
            except Exception:  # an optimisation only: read as before
                continue


#: Bytes of a raw Image read in the index pass: CDR header, frame id, height and width.
IMAGE_HEAD_BYTES = 4096


def _image_head_complete(head: bytes) -> bool:
    """True if the first bytes of a CDR Image hold its whole header and its height and width
    (a frame id of up to ~4000 characters), or are the whole message."""
    if len(head) < IMAGE_HEAD_BYTES:
        return True  # the message itself
    order = "<" if head[1] else ">"
    (size,) = struct.unpack_from(order + "I", head, 12)  # the frame id's length
    return 16 + size + 3 + 8 <= len(head)


def _sqlite_storages(reader: Any) -> list[Any] | None:
    """The sqlite3 storages (apsw connections) of a ROS 2 bag rosbags reads from one folder
    without per-message compression; None for anything else."""
    readers: list[Any] = list(getattr(reader, "readers", None) or [])
    if len(readers) != 1:
        return None
    directory = getattr(readers[0], "storage", None)
    storages = getattr(directory, "storages", None)
    metadata = getattr(directory, "metadata", None)
    if not storages or getattr(metadata, "compression_mode", "message") == "message":
        return None
    for storage in storages:
        db = getattr(storage, "dbconn", None)
        if not (hasattr(db, "blob_open") and hasattr(db, "execute")):
            return None
        if not hasattr(storage, "connections"):
            return None
    return list(storages)


def _same_connection(x: Any, y: Any) -> bool:
    """rosbags' match of a storage's connection to the reader's (rosbag2 DirectoryReader)."""
    return bool(
        y.topic == x.topic
        and y.msgtype == x.msgtype
        and y.ext == x.ext
        and (not x.digest or not y.digest or y.digest == x.digest)
    )


def _has_mcap_footer(path: Path) -> bool:
    """True if the file ends with a footer and the MCAP magic (False if unreadable): the magic
    alone, as a recorder killed at once leaves it, is no complete file."""
    try:
        with path.open("rb") as f:
            if f.seek(0, os.SEEK_END) < 2 * len(_MCAP_MAGIC) + 29:  # magic, footer, magic
                return False
            f.seek(-len(_MCAP_MAGIC), os.SEEK_END)
            return f.read() == _MCAP_MAGIC
    except OSError:
        return False


def one_line(text: str, limit: int = 300) -> str:
    """A library's message as one line of at most ``limit`` characters (rosbags quotes whole
    message definitions, over several lines, in its parse errors)."""
    flat = " ".join(text.split())
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."


#: Above this share of colour images sharing a stamp, stamps are not capture times at all.
MAX_REPEATED_STAMPS = 0.1


def _repeated_stamps(stamps: NDArray[np.int64]) -> NDArray[np.bool_]:
    """True for each stamp an earlier image already carries (the first of a group is kept:
    a driver re-publishing a frame now and then is harmless)."""
    order = np.argsort(stamps, kind="stable")
    repeated = np.zeros(len(stamps), dtype=bool)
    repeated[order[1:]] = stamps[order[1:]] == stamps[order[:-1]]
    return repeated


def images_differ(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> bool:
    """True if two (H, W, 3) uint8 colour images show different views: more than a quarter
    of the pixels change by over 24 grey levels (sensor noise and flicker change a few)."""
    if a.shape != b.shape:
        return True
    ga = a.astype(np.int16).sum(axis=2)
    gb = b.astype(np.int16).sum(axis=2)
    return float(np.mean(np.abs(ga - gb) > 3 * 24)) > 0.25


def depths_differ(a: NDArray[np.float32], b: NDArray[np.float32]) -> bool:
    """True if two (H, W) depth images (metres, NaN invalid) show different views: more than a
    quarter of the pixels valid in both change by over 3 % of their depth or 10 mm (the D435i's
    noise is under 1 % at wrist range), or validity itself changes over a quarter of them."""
    if a.shape != b.shape:
        return True
    va, vb = np.isfinite(a), np.isfinite(b)
    both = va & vb
    if np.mean(va != vb) > 0.25:
        return True
    if not both.any():
        return False
    za, zb = a[both].astype(np.float64), b[both].astype(np.float64)
    changed = np.abs(za - zb) > np.maximum(0.01, 0.03 * np.abs(za))
    return float(np.mean(changed)) > 0.25


def _pair_nearest(
    color: NDArray[np.int64], depth: NDArray[np.int64], tolerance_ns: int
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """For each colour stamp the index of the nearest depth stamp, and whether it is within
    ``tolerance_ns`` (ties go to the earlier depth image)."""
    order = np.argsort(depth, kind="stable")
    sorted_depth = depth[order]
    right = np.clip(np.searchsorted(sorted_depth, color), 0, len(depth) - 1)
    left = np.clip(right - 1, 0, len(depth) - 1)
    d_left = np.abs(color - sorted_depth[left])
    d_right = np.abs(sorted_depth[right] - color)
    pick = np.where(d_left <= d_right, left, right)
    gap = np.minimum(d_left, d_right)
    return order[pick].astype(np.int64), gap <= tolerance_ns


def _size_text(size: tuple[int, int]) -> str:
    return f"{size[1]}x{size[0]}"


def _frames_text(tf: TfBuffer) -> str:
    frames = tf.frames
    return ", ".join(frames) if frames else "(none: no /tf or /tf_static messages)"


def _json_object(text: str, where: str) -> dict[str, Any]:
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise RecordingError(f"{where} holds invalid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise RecordingError(f"{where} must hold a JSON object, got {type(data).__name__}")
    return data


def _string_map(value: Any, where: str) -> dict[str, str]:
    if not isinstance(value, dict) or not all(isinstance(v, str) for v in value.values()):
        raise RecordingError(f"metadata in {where} must map names to strings")
    return {str(k): v for k, v in value.items()}


def sha256_first_mib(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of the first MiB of a recording file; of a bag directory's first storage
    file (as metadata.yaml lists it)."""
    p = Path(path)
    if p.is_dir():
        p = _first_storage_file(p)
    digest = hashlib.sha256()
    try:
        with p.open("rb") as f:
            digest.update(f.read(1 << 20))
    except OSError as exc:
        raise RecordingError(f"cannot read {p}: {exc.strerror}") from None
    return digest.hexdigest()


def _first_storage_file(directory: Path) -> Path:
    # ros2 bag names its storage files <bag>_0, <bag>_1, ...: the first by split number.
    files = [
        f
        for f in directory.iterdir()
        if f.is_file() and f.name.endswith((".mcap", ".db3", ".mcap.zstd", ".db3.zstd"))
    ]
    if not files:
        raise RecordingError(f"{directory} holds no bag storage file (.mcap or .db3)")
    return min(files, key=_split_number)


def _split_number(path: Path) -> tuple[int, str]:
    stem = path.name.split(".")[0]
    tail = stem.rsplit("_", 1)[-1]
    return (int(tail) if tail.isdigit() else 1 << 30, path.name)
