"""ROS message construction and decoding, shared by the writer, the readers and the converter.

Messages are rosbags typestore objects (``Stores.ROS2_HUMBLE`` names: ``sensor_msgs/msg/Image``).
Decoders accept both ROS 2 objects and ROS 1 objects read from a ``.bag`` (``K``/``D`` versus
``k``/``d``, a ``seq`` in the header). Stamps are integer nanoseconds, lengths metres, depth
images millimetres (16UC1) or metres (32FC1) on the wire and float32 metres in memory.
"""

from __future__ import annotations

import functools
import io
import struct
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from scrapcut_cli.errors import RecordingError
from scrapcut_cli.geometry import matrix_to_quat_xyzw
from scrapcut_cli.recording.frame import CameraModel

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TF_MESSAGE_ROS1_LEGACY = "tf/msg/tfMessage"
PATH = "nav_msgs/msg/Path"
POSE_ARRAY = "geometry_msgs/msg/PoseArray"
POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
STRING = "std_msgs/msg/String"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
JOINT_STATE = "sensor_msgs/msg/JointState"

IMAGE_TYPES = (IMAGE, COMPRESSED_IMAGE)
TF_TYPES = (TF_MESSAGE, TF_MESSAGE_ROS1_LEGACY)

#: Colour encodings: channels and the order that turns them into RGB.
COLOR_ENCODINGS: dict[str, tuple[int, tuple[int, ...]]] = {
    "rgb8": (3, (0, 1, 2)),
    "bgr8": (3, (2, 1, 0)),
    "rgba8": (4, (0, 1, 2)),
    "bgra8": (4, (2, 1, 0)),
    "mono8": (1, (0, 0, 0)),
}
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")

# image_transport's compressedDepth prepends a 12-byte ConfigHeader (int32 format, float32[2]
# inverse-depth quantisation) to the PNG.
_COMPRESSED_DEPTH_HEADER = struct.Struct("<iff")
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

_POINTFIELD_FLOAT32 = 7


@functools.cache
def typestore() -> Typestore:
    """The ROS 2 Humble typestore every scrapcut message is built from."""
    return get_typestore(Stores.ROS2_HUMBLE)


def msgdef_text(msgtype: str, store: Typestore | None = None) -> str:
    """The ``ros2msg`` definition (with dependencies) of ``msgtype``, as MCAP schemas carry it."""
    return (store or typestore()).generate_msgdef(msgtype, ros_version=2)[0]


def serialize(msg: object, msgtype: str) -> bytes:
    """Little-endian CDR bytes of a typestore message (the same on every machine)."""
    return bytes(typestore().serialize_cdr(msg, msgtype, little_endian=True))


# --------------------------------------------------------------------------- building


def _type(name: str) -> Any:
    return typestore().types[name]


def stamp_from_ns(stamp_ns: int) -> Any:
    """``builtin_interfaces/Time`` for integer nanoseconds (negative stamps floor correctly)."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return _type("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def header(stamp_ns: int, frame_id: str) -> Any:
    """``std_msgs/Header``."""
    return _type("std_msgs/msg/Header")(stamp=stamp_from_ns(stamp_ns), frame_id=frame_id)


def image_msg(
    stamp_ns: int, frame_id: str, image: ArrayLike, *, encoding: str | None = None
) -> Any:
    """``sensor_msgs/Image`` from an array.

    image : (H, W, 3) uint8 RGB -> ``rgb8`` (or ``bgr8`` with ``encoding="bgr8"``; (H, W, 4)
        uint8 with ``rgba8`` / ``bgra8``); (H, W) uint16 millimetres -> ``16UC1``; (H, W) float32
        metres -> ``32FC1``. The array is written as given; ``encoding`` only names its layout.
    """
    arr = np.ascontiguousarray(image)
    if encoding is None:
        encoding = _default_encoding(arr)
    expected = _encoding_layout(encoding)
    if expected is None:
        raise ValueError(
            f"unsupported image encoding {encoding!r}; "
            f"known: {', '.join([*COLOR_ENCODINGS, *DEPTH_ENCODINGS])}"
        )
    channels, dtype = expected
    shape_ok = arr.ndim == 2 if channels == 1 else arr.ndim == 3 and arr.shape[2] == channels
    if not shape_ok or arr.dtype != dtype:
        want = "(H, W)" if channels == 1 else f"(H, W, {channels})"
        raise ValueError(
            f"encoding {encoding} needs a {want} {np.dtype(dtype).name} array, "
            f"got {arr.shape} {arr.dtype}"
        )
    height, width = arr.shape[:2]
    little = arr.dtype.byteorder == "<" or (
        arr.dtype.byteorder == "=" and sys.byteorder == "little"
    )
    return _type(IMAGE)(
        header=header(stamp_ns, frame_id),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0 if (little or arr.dtype.itemsize == 1) else 1,
        step=width * channels * arr.dtype.itemsize,
        data=arr.reshape(-1).view(np.uint8),
    )


def _default_encoding(arr: NDArray[Any]) -> str:
    if arr.ndim == 3 and arr.shape[2] == 3 and arr.dtype == np.uint8:
        return "rgb8"
    if arr.ndim == 2 and arr.dtype == np.uint16:
        return "16UC1"
    if arr.ndim == 2 and arr.dtype == np.float32:
        return "32FC1"
    raise ValueError(
        "cannot infer an image encoding for a "
        f"{arr.shape} {arr.dtype} array; pass (H, W, 3) uint8, (H, W) uint16 or (H, W) float32, "
        "or name the encoding"
    )


def _encoding_layout(encoding: str) -> tuple[int, type[np.generic]] | None:
    if encoding in COLOR_ENCODINGS:
        return COLOR_ENCODINGS[encoding][0], np.uint8
    if encoding in ("16UC1", "mono16"):
        return 1, np.uint16
    if encoding == "32FC1":
        return 1, np.float32
    return None


def compressed_image_msg(
    stamp_ns: int, frame_id: str, rgb: ArrayLike, *, fmt: str = "jpeg", quality: int = 90
) -> Any:
    """``sensor_msgs/CompressedImage`` (JPEG or PNG) of an (H, W, 3) uint8 RGB image."""
    from PIL import Image

    arr = np.ascontiguousarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
        raise ValueError(f"compressed images need (H, W, 3) uint8 RGB, got {arr.shape} {arr.dtype}")
    if fmt not in ("jpeg", "png"):
        raise ValueError(f"compressed image format must be 'jpeg' or 'png', got {fmt!r}")
    buffer = io.BytesIO()
    if fmt == "jpeg":
        Image.fromarray(arr, mode="RGB").save(buffer, format="JPEG", quality=int(quality))
    else:
        Image.fromarray(arr, mode="RGB").save(buffer, format="PNG")
    return _type(COMPRESSED_IMAGE)(
        header=header(stamp_ns, frame_id),
        # image_transport's convention: "<raw encoding>; <codec> compressed <encoding>".
        format=f"rgb8; {fmt} compressed rgb8",
        data=np.frombuffer(buffer.getvalue(), dtype=np.uint8),
    )


def compressed_depth_msg(stamp_ns: int, frame_id: str, depth_mm: ArrayLike) -> Any:
    """``sensor_msgs/CompressedImage`` in image_transport's ``compressedDepth`` PNG form.

    depth_mm : (H, W) uint16, millimetres, 0 = invalid.
    """
    from PIL import Image

    arr = np.ascontiguousarray(depth_mm)
    if arr.ndim != 2 or arr.dtype != np.uint16:
        raise ValueError(
            f"compressedDepth needs (H, W) uint16 millimetres, got {arr.shape} {arr.dtype}"
        )
    buffer = io.BytesIO()
    buffer.write(_COMPRESSED_DEPTH_HEADER.pack(0, 0.0, 0.0))
    Image.fromarray(arr.astype("<u2", copy=False)).save(buffer, format="PNG")
    return _type(COMPRESSED_IMAGE)(
        header=header(stamp_ns, frame_id),
        format="16UC1; compressedDepth png",
        data=np.frombuffer(buffer.getvalue(), dtype=np.uint8),
    )


def camera_info_msg(stamp_ns: int, camera: CameraModel, *, frame_id: str | None = None) -> Any:
    """``sensor_msgs/CameraInfo`` of a camera model (no rectification: R = I, P = [K | 0])."""
    model = "" if camera.distortion_model == "none" else camera.distortion_model
    p = np.zeros((3, 4))
    p[:, :3] = camera.K
    return _type(CAMERA_INFO)(
        header=header(stamp_ns, camera.frame_id if frame_id is None else frame_id),
        height=camera.height,
        width=camera.width,
        distortion_model=model,
        d=np.asarray(camera.distortion, dtype=np.float64),
        k=camera.K.reshape(-1),
        r=np.eye(3).reshape(-1),
        p=p.reshape(-1),
        binning_x=0,
        binning_y=0,
        roi=_type("sensor_msgs/msg/RegionOfInterest")(
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )


def _pose(position: ArrayLike, quat_xyzw: ArrayLike) -> Any:
    p = np.asarray(position, dtype=np.float64)
    q = np.asarray(quat_xyzw, dtype=np.float64)
    return _type("geometry_msgs/msg/Pose")(
        position=_type("geometry_msgs/msg/Point")(x=float(p[0]), y=float(p[1]), z=float(p[2])),
        orientation=_quaternion(q),
    )


def _quaternion(q: NDArray[np.float64]) -> Any:
    return _type("geometry_msgs/msg/Quaternion")(
        x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])
    )


def tf_msg(stamp_ns: int, transforms: Sequence[tuple[str, str, ArrayLike]]) -> Any:
    """``tf2_msgs/TFMessage`` of (parent_frame, child_frame, T_parent_child (4, 4)) triples."""
    items = []
    for parent, child, T in transforms:
        T = np.asarray(T, dtype=np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"transform {parent} -> {child} must be (4, 4), got {T.shape}")
        t = T[:3, 3]
        items.append(
            _type("geometry_msgs/msg/TransformStamped")(
                header=header(stamp_ns, parent),
                child_frame_id=child,
                transform=_type("geometry_msgs/msg/Transform")(
                    translation=_type("geometry_msgs/msg/Vector3")(
                        x=float(t[0]), y=float(t[1]), z=float(t[2])
                    ),
                    rotation=_quaternion(matrix_to_quat_xyzw(T[:3, :3])),
                ),
            )
        )
    return _type(TF_MESSAGE)(transforms=items)


def _poses(
    positions: ArrayLike, orientations_xyzw: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    pts = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if orientations_xyzw is None:
        quats = np.tile([0.0, 0.0, 0.0, 1.0], (len(pts), 1))
    else:
        quats = np.asarray(orientations_xyzw, dtype=np.float64).reshape(-1, 4)
        if len(quats) != len(pts):
            raise ValueError(f"{len(pts)} positions but {len(quats)} orientations")
    return pts, quats


def path_msg(
    stamp_ns: int, frame_id: str, points: ArrayLike, orientations_xyzw: ArrayLike | None = None
) -> Any:
    """``nav_msgs/Path`` through ``points`` (N, 3) metres (identity orientations by default)."""
    pts, quats = _poses(points, orientations_xyzw)
    pose_stamped = _type("geometry_msgs/msg/PoseStamped")
    poses = [
        pose_stamped(header=header(stamp_ns, frame_id), pose=_pose(p, q))
        for p, q in zip(pts, quats, strict=True)
    ]
    return _type(PATH)(header=header(stamp_ns, frame_id), poses=poses)


def pose_array_msg(
    stamp_ns: int, frame_id: str, positions: ArrayLike, orientations_xyzw: ArrayLike
) -> Any:
    """``geometry_msgs/PoseArray`` of (N, 3) positions and (N, 4) xyzw quaternions."""
    pts, quats = _poses(positions, orientations_xyzw)
    poses = [_pose(p, q) for p, q in zip(pts, quats, strict=True)]
    return _type(POSE_ARRAY)(header=header(stamp_ns, frame_id), poses=poses)


@dataclass(frozen=True)
class MarkerSpec:
    """One ``visualization_msgs/Marker`` to draw, in the message's frame (identity pose).

    ``kind`` is the Marker type name (``ARROW``, ``LINE_STRIP``, ``SPHERE_LIST``...);
    ``points`` (N, 3) metres; ``rgba`` the colour (0-1) or ``colors`` (N, 4) one per point;
    ``scale`` the marker's x, y, z (an arrow given by two points: shaft and head diameters,
    head length; a line: its width; spheres: their diameter).
    """

    ns: str
    id: int
    kind: str
    points: NDArray[np.float64]
    scale: tuple[float, float, float]
    rgba: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    colors: NDArray[np.float64] | None = None
    text: str = ""


def marker_array_msg(stamp_ns: int, frame_id: str, markers: Sequence[MarkerSpec]) -> Any:
    """``visualization_msgs/MarkerArray`` of ``markers`` (lifetime 0: they stay)."""
    marker_type = _type("visualization_msgs/msg/Marker")
    point, rgba = _type("geometry_msgs/msg/Point"), _type("std_msgs/msg/ColorRGBA")
    out = []
    for spec in markers:
        pts = np.asarray(spec.points, dtype=np.float64).reshape(-1, 3)
        colors = np.zeros((0, 4)) if spec.colors is None else np.reshape(spec.colors, (-1, 4))
        out.append(
            marker_type(
                header=header(stamp_ns, frame_id),
                ns=spec.ns,
                id=int(spec.id),
                type=int(getattr(marker_type, spec.kind)),
                action=int(marker_type.ADD),
                pose=_pose([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]),
                scale=_type("geometry_msgs/msg/Vector3")(*(float(v) for v in spec.scale)),
                color=rgba(*(float(v) for v in spec.rgba)),
                lifetime=_type("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
                frame_locked=False,
                points=[point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in pts],
                colors=[rgba(*(float(v) for v in c)) for c in colors],
                texture_resource="",
                texture=_type("sensor_msgs/msg/CompressedImage")(
                    header=header(0, ""), format="", data=np.zeros(0, dtype=np.uint8)
                ),
                uv_coordinates=[],
                text=spec.text,
                mesh_resource="",
                mesh_file=_type("visualization_msgs/msg/MeshFile")(
                    filename="", data=np.zeros(0, dtype=np.uint8)
                ),
                mesh_use_embedded_materials=False,
            )
        )
    return _type(MARKER_ARRAY)(markers=out)


def pointcloud_msg(
    stamp_ns: int, frame_id: str, points: ArrayLike, rgb: ArrayLike | None = None
) -> Any:
    """``sensor_msgs/PointCloud2`` with float32 x, y, z (+ ``rgb`` packed in a float32).

    points : (N, 3) metres. rgb : (N, 3) uint8. The packed colour is the PCL / Foxglove
    convention: the bytes of uint32 ``r << 16 | g << 8 | b`` read as a float32.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    names = ["x", "y", "z"]
    formats: list[Any] = ["<f4", "<f4", "<f4"]
    if rgb is not None:
        colors = np.asarray(rgb)
        integral = np.issubdtype(colors.dtype, np.integer)
        if (
            colors.shape != (len(pts), 3)
            or not integral
            or (colors.size and (colors.min() < 0 or colors.max() > 255))
        ):
            raise ValueError(
                f"rgb must be ({len(pts)}, 3) integers in 0-255, got {colors.shape} {colors.dtype}"
            )
        names.append("rgb")
        formats.append("<u4")
    records = np.zeros(len(pts), dtype=np.dtype({"names": names, "formats": formats}))
    for k, axis in enumerate("xyz"):
        records[axis] = pts[:, k]
    if rgb is not None:
        c = colors.astype(np.uint32)
        records["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    point_field = _type("sensor_msgs/msg/PointField")
    fields = [
        point_field(name=name, offset=4 * k, datatype=_POINTFIELD_FLOAT32, count=1)
        for k, name in enumerate(names)
    ]
    step = records.dtype.itemsize
    return _type(POINT_CLOUD2)(
        header=header(stamp_ns, frame_id),
        height=1,
        width=len(pts),
        fields=fields,
        is_bigendian=False,
        point_step=step,
        row_step=step * len(pts),
        data=records.view(np.uint8).reshape(-1),
        is_dense=True,
    )


def string_msg(text: str) -> Any:
    """``std_msgs/String``."""
    return _type(STRING)(data=text)


def joint_state_msg(stamp_ns: int, names: Sequence[str], positions: ArrayLike) -> Any:
    """``sensor_msgs/JointState`` with positions only (radians or metres per joint)."""
    q = np.asarray(positions, dtype=np.float64).reshape(-1)
    if len(q) != len(names):
        raise ValueError(f"{len(names)} joint names but {len(q)} positions")
    return _type(JOINT_STATE)(
        header=header(stamp_ns, ""),
        name=list(names),
        position=q,
        velocity=np.zeros(0),
        effort=np.zeros(0),
    )


# --------------------------------------------------------------------------- decoding


def stamp_to_ns(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time`` (ROS 1 or ROS 2)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def message_stamp_ns(msg: Any) -> int | None:
    """The header stamp of a message, or None if it has no header."""
    head = getattr(msg, "header", None)
    stamp = getattr(head, "stamp", None)
    return None if stamp is None else stamp_to_ns(stamp)


def raw_header(raw: bytes | memoryview, *, cdr: bool) -> tuple[int, str, int]:
    """(stamp_ns, frame_id, end offset) of a serialised message that starts with a Header.

    Reads the few header bytes instead of deserialising (and copying) a whole image: in CDR
    the stamp follows the 4-byte encapsulation, in ROS 1 it follows ``seq``. The end offset is
    where the next field starts (before CDR alignment), counted from the start of ``raw``.
    """
    buf = memoryview(raw)
    try:
        if cdr:
            order = "<" if buf[1] else ">"
            sec, nanosec, size = struct.unpack_from(order + "iII", buf, 4)
            start = 16
            frame_id = bytes(buf[start : start + max(size - 1, 0)]).decode()
        else:
            sec, nanosec, size = struct.unpack_from("<IIi", buf, 4)
            start = 16
            frame_id = bytes(buf[start : start + size]).decode()
    except (struct.error, UnicodeDecodeError, IndexError) as exc:
        raise RecordingError(f"damaged message header: {exc}") from None
    return sec * 1_000_000_000 + nanosec, frame_id, start + size


def raw_image_size(raw: bytes | memoryview, msgtype: str, *, cdr: bool) -> tuple[int, int] | None:
    """(height, width) of a serialised Image or CompressedImage, without decoding pixels.

    For compressed images only the codec header is parsed (Pillow opens lazily). None when
    the size cannot be told from the bytes.
    """
    buf = memoryview(raw)
    _, _, pos = raw_header(buf, cdr=cdr)
    order = "<" if (not cdr or buf[1]) else ">"
    base = 4 if cdr else 0

    def align(offset: int) -> int:
        # CDR aligns 4-byte fields relative to the end of the encapsulation header.
        return base + ((offset - base + 3) & ~3) if cdr else offset

    try:
        if msgtype == IMAGE:
            height, width = struct.unpack_from(order + "II", buf, align(pos))
            return int(height), int(width)
        if msgtype != COMPRESSED_IMAGE:
            return None
        pos = align(pos)
        (size,) = struct.unpack_from(order + "I", buf, pos)  # the format string
        pos = align(pos + 4 + size)
        (length,) = struct.unpack_from(order + "I", buf, pos)
    except struct.error as exc:
        raise RecordingError(f"damaged {msgtype} message: {exc}") from None
    return _codec_size(buf[pos + 4 : pos + 4 + length])


def _codec_size(data: memoryview) -> tuple[int, int] | None:
    from PIL import Image, UnidentifiedImageError

    offset = _png_offset(data)
    try:
        with Image.open(io.BytesIO(data[offset:])) as img:
            width, height = img.size
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError):
        return None
    return int(height), int(width)


def _png_offset(data: memoryview | bytes) -> int:
    """0 for a plain image, 12 when a compressedDepth ConfigHeader precedes the PNG."""
    head = bytes(data[: 12 + len(_PNG_MAGIC)])
    if not head.startswith(_PNG_MAGIC) and head[12:] == _PNG_MAGIC:
        return 12
    return 0


def _readonly(arr: NDArray[Any]) -> NDArray[Any]:
    arr.setflags(write=False)
    return arr


def _image_pixels(msg: Any, channels: int, dtype: str) -> NDArray[Any]:
    """(H, W[, C]) view of an Image's pixel buffer honouring ``step`` and byte order."""
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    item = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    row = width * channels * item.itemsize
    data = np.asarray(msg.data, dtype=np.uint8)
    if step < row or data.size < step * height:
        raise RecordingError(
            f"image data too short: {data.size} bytes for {width}x{height} {msg.encoding} "
            f"(step {step})"
        )
    rows = data[: step * height].reshape(height, step)[:, :row]
    pixels = np.ascontiguousarray(rows).view(item)
    shape = (height, width) if channels == 1 else (height, width, channels)
    return pixels.reshape(shape)


def decode_color(msg: Any, msgtype: str) -> NDArray[np.uint8]:
    """(H, W, 3) uint8 RGB, read-only, from an Image (rgb8/bgr8/rgba8/bgra8/mono8) or a
    CompressedImage (JPEG or PNG)."""
    if msgtype == COMPRESSED_IMAGE:
        return _readonly(_decode_compressed_color(msg))
    encoding = str(msg.encoding)
    if encoding not in COLOR_ENCODINGS:
        raise RecordingError(
            f"unsupported colour encoding {encoding!r}; "
            f"supported: {', '.join(COLOR_ENCODINGS)} and CompressedImage jpeg/png"
        )
    channels, order = COLOR_ENCODINGS[encoding]
    pixels = _image_pixels(msg, channels, "u1")
    if encoding == "rgb8":
        rgb = pixels
    elif channels == 1:
        rgb = np.repeat(pixels[:, :, None], 3, axis=2)
    else:
        rgb = np.ascontiguousarray(pixels[:, :, list(order)])
    return _readonly(np.ascontiguousarray(rgb))


#: A JPEG's first bytes: start of image, then a marker.
_JPEG_MAGIC = b"\xff\xd8\xff"


def _decode_compressed_color(msg: Any) -> NDArray[np.uint8]:
    from PIL import Image, UnidentifiedImageError

    data = np.asarray(msg.data, dtype=np.uint8).tobytes()
    if data.startswith(_JPEG_MAGIC):
        rgb = _decode_jpeg(data)
        if rgb is not None:
            return rgb
    try:
        with Image.open(io.BytesIO(data)) as img:
            # convert() copies even when the image is RGB already (a colour JPEG always is).
            rgb = np.asarray(img if img.mode == "RGB" else img.convert("RGB"))
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError) as exc:
        raise RecordingError(f"cannot decode compressed image ({msg.format!r}): {exc}") from None
    return np.ascontiguousarray(rgb)


def _decode_jpeg(data: bytes) -> NDArray[np.uint8] | None:
    """(H, W, 3) RGB of a colour or grey JPEG, decoded by libjpeg-turbo straight into the
    array (simplejpeg): the pixels Pillow decodes, in about 60 % of its time at 1280x720,
    which copies the decoded image once more into numpy. None when simplejpeg declines (a
    CMYK JPEG, damaged data: Pillow then decodes it or says what is wrong)."""
    try:
        import simplejpeg
    except ImportError:  # pragma: no cover - a dependency; Pillow decodes alike
        return None
    from PIL import Image

    try:
        height, width, colorspace, _ = simplejpeg.decode_jpeg_header(data)
    except ValueError:
        return None
    if colorspace not in ("YCbCr", "Gray"):
        return None  # CMYK, YCCK: Pillow's conversion (Adobe's inverted CMYK) is the one
    limit = Image.MAX_IMAGE_PIXELS
    if limit is not None and int(height) * int(width) > limit:
        return None  # a damaged header's size: Pillow's decompression-bomb check says so
    try:
        return np.asarray(simplejpeg.decode_jpeg(data, colorspace="RGB", strict=True))
    except ValueError:
        return None


def decode_depth(msg: Any, msgtype: str) -> NDArray[np.float32]:
    """(H, W) float32 metres, read-only, NaN where invalid.

    Image ``16UC1`` (millimetres, 0 = invalid), Image ``32FC1`` (metres; 0, inf, NaN invalid),
    or a CompressedImage in image_transport's ``compressedDepth`` PNG form (16UC1 or the
    inverse-depth quantised 32FC1).
    """
    if msgtype == COMPRESSED_IMAGE:
        return _readonly(_decode_compressed_depth(msg))
    encoding = str(msg.encoding)
    if encoding in ("16UC1", "mono16"):
        mm = _image_pixels(msg, 1, "u2")
        return _readonly(_depth_from_mm(mm))
    if encoding == "32FC1":
        metres = _image_pixels(msg, 1, "f4").astype(np.float32)
        metres[~np.isfinite(metres) | (metres <= 0)] = np.nan
        return _readonly(metres)
    raise RecordingError(
        f"unsupported depth encoding {encoding!r}; supported: 16UC1 (mm), 32FC1 (m), "
        "compressedDepth png"
    )


def _depth_from_mm(mm: NDArray[Any]) -> NDArray[np.float32]:
    # One pass: the cast to float32 happens inside the multiplication; the holes are then
    # written by a masked copy (a boolean index would gather their positions first).
    metres = np.multiply(mm, np.float32(0.001), dtype=np.float32)
    np.copyto(metres, np.float32(np.nan), where=mm == 0)
    return metres


def _decode_compressed_depth(msg: Any) -> NDArray[np.float32]:
    from PIL import Image, UnidentifiedImageError

    fmt = str(msg.format)
    if "compressedDepth" not in fmt or "rvl" in fmt.lower():
        raise RecordingError(
            f"unsupported compressed depth format {fmt!r}; supported: 'compressedDepth' PNG"
        )
    data = np.asarray(msg.data, dtype=np.uint8).tobytes()
    offset = _png_offset(data)
    try:
        with Image.open(io.BytesIO(data[offset:])) as img:
            values = np.asarray(img)
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError) as exc:
        raise RecordingError(f"cannot decode compressedDepth PNG: {exc}") from None
    if fmt.startswith("32FC1"):
        if offset != 12:
            raise RecordingError("compressedDepth 32FC1 image without its quantisation header")
        _, quant_a, quant_b = _COMPRESSED_DEPTH_HEADER.unpack_from(data, 0)
        inv = values.astype(np.float32)
        with np.errstate(divide="ignore"):
            metres = np.float32(quant_a) / (inv - np.float32(quant_b))
        metres[(values == 0) | ~np.isfinite(metres) | (metres <= 0)] = np.nan
        return metres.astype(np.float32)
    return _depth_from_mm(values.astype(np.uint16))


def camera_from_info(
    msg: Any, *, width: int | None = None, height: int | None = None
) -> CameraModel:
    """A :class:`CameraModel` from ``sensor_msgs/CameraInfo`` (ROS 2 ``k``/``d`` or ROS 1
    ``K``/``D``). ``width``/``height`` fill in a CameraInfo that leaves its size at 0."""
    k = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, dtype=np.float64)
    d = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, dtype=np.float64)
    model = _DISTORTION_ALIASES.get(str(msg.distortion_model).strip().lower())
    if model is None:
        raise RecordingError(
            f"unsupported distortion model {msg.distortion_model!r} in CameraInfo; "
            f"supported: {', '.join(sorted(_DISTORTION_ALIASES))}"
        )
    w = int(msg.width) or (width or 0)
    h = int(msg.height) or (height or 0)
    try:
        return CameraModel(
            width=w,
            height=h,
            fx=float(k[0]),
            fy=float(k[4]),
            cx=float(k[2]),
            cy=float(k[5]),
            distortion_model=model,
            distortion=tuple(float(x) for x in d) if model != "none" else (),
            frame_id=str(msg.header.frame_id),
        )
    except (ValueError, IndexError) as exc:
        raise RecordingError(f"unusable CameraInfo: {exc}") from None


_DISTORTION_ALIASES = {
    "": "none",
    "none": "none",
    "plumb_bob": "plumb_bob",
    "brown_conrady": "plumb_bob",
    "inverse_brown_conrady": "plumb_bob",
    "rational_polynomial": "rational_polynomial",
    "equidistant": "equidistant",
    "fisheye": "equidistant",
    "kannala_brandt4": "equidistant",
}


def tf_transforms(
    msg: Any,
) -> list[tuple[str, str, int, tuple[float, float, float], tuple[float, float, float, float]]]:
    """(parent, child, stamp_ns, translation xyz metres, quaternion xyzw) of a TFMessage."""
    out = []
    for item in msg.transforms:
        t = item.transform.translation
        q = item.transform.rotation
        out.append(
            (
                _strip_slash(str(item.header.frame_id)),
                _strip_slash(str(item.child_frame_id)),
                stamp_to_ns(item.header.stamp),
                (float(t.x), float(t.y), float(t.z)),
                (float(q.x), float(q.y), float(q.z), float(q.w)),
            )
        )
    return out


_TF_LE = (struct.Struct("<I"), struct.Struct("<iI"), struct.Struct("<7d"))
_TF_BE = (struct.Struct(">I"), struct.Struct(">iI"), struct.Struct(">7d"))
_TF_ROS1_HEAD = struct.Struct("<IiI")  # seq, sec, nanosec


TfTransform = tuple[str, str, int, tuple[float, float, float], tuple[float, float, float, float]]


def raw_tf_transforms(raw: bytes | memoryview, *, cdr: bool) -> list[TfTransform] | None:
    """:func:`tf_transforms` of a serialised TFMessage, read straight from its bytes.

    A recording's /tf holds thousands of messages; rosbags builds eight message objects per
    transform (a quarter of a millisecond a message). None when the bytes are anything but a
    well-formed TFMessage of the standard layout: the caller then deserialises them, and so
    gets rosbags' own result or error.
    """
    buf = memoryview(raw)
    n_bytes = len(buf)
    out: list[TfTransform] = []
    names = _TF_NAMES
    if len(names) > _TF_NAMES_MAX:  # frame names are few; anything else must not pile up
        names.clear()
    try:
        if cdr:
            if n_bytes < 4 or buf[0] != 0 or buf[2] != 0 or buf[3] != 0 or buf[1] > 1:
                return None
            u32, stamp, floats = _TF_LE if buf[1] else _TF_BE
            data = buf[4:]
            size = n_bytes - 4
            (count,) = u32.unpack_from(data, 0)
            pos = 4
            for _ in range(count):
                sec, nanosec = stamp.unpack_from(data, pos)
                pos = (pos + 11) & ~3
                (length,) = u32.unpack_from(data, pos)
                end = pos + 4 + length
                if length < 1 or end > size or data[end - 1] != 0:
                    return None
                key = bytes(data[pos + 4 : end - 1])
                parent = names.get(key)
                if parent is None:
                    parent = names[key] = _strip_slash(key.decode())
                pos = (end + 3) & ~3
                (length,) = u32.unpack_from(data, pos)
                end = pos + 4 + length
                if length < 1 or end > size or data[end - 1] != 0:
                    return None
                key = bytes(data[pos + 4 : end - 1])
                child = names.get(key)
                if child is None:
                    child = names[key] = _strip_slash(key.decode())
                pos = (end + 7) & ~7
                v = floats.unpack_from(data, pos)
                pos += 56
                out.append((parent, child, sec * 1_000_000_000 + nanosec, v[:3], v[3:]))
            if pos + 3 < size:  # rosbags' size check: at most the alignment padding after
                return None
        else:
            u32, floats = _TF_LE[0], _TF_LE[2]
            (count,) = u32.unpack_from(buf, 0)
            pos = 4
            for _ in range(count):
                _, sec, nanosec = _TF_ROS1_HEAD.unpack_from(buf, pos)
                pos += 12
                pair = []
                for _ in range(2):
                    (length,) = u32.unpack_from(buf, pos)
                    end = pos + 4 + length
                    if end > n_bytes:
                        return None
                    pair.append(bytes(buf[pos + 4 : end]).decode())
                    pos = end
                v = floats.unpack_from(buf, pos)
                pos += 56
                out.append(_tf_entry(pair, sec, nanosec, v))
            if pos != n_bytes:
                return None
    except (struct.error, UnicodeDecodeError, IndexError):
        return None
    return out


#: Frame names of /tf transforms by their bytes, leading slash removed (a recording's /tf
#: repeats the same few names thousands of times).
_TF_NAMES: dict[bytes, str] = {}
_TF_NAMES_MAX = 4096


def _tf_entry(names: list[str], sec: int, nanosec: int, values: tuple[float, ...]) -> TfTransform:
    """(parent, child, stamp_ns, translation, quaternion xyzw) of a transform read by
    :func:`raw_tf_transforms`: its two frame names, stamp and seven doubles."""
    return (
        _strip_slash(names[0]),
        _strip_slash(names[1]),
        sec * 1_000_000_000 + nanosec,
        (values[0], values[1], values[2]),
        (values[3], values[4], values[5], values[6]),
    )


def _strip_slash(frame_id: str) -> str:
    """tf2 ignores a leading slash (ROS 1 tf used ``/base_link``)."""
    return frame_id[1:] if frame_id.startswith("/") else frame_id


def path_points(msg: Any) -> NDArray[np.float64]:
    """(N, 3) float64 positions of a ``nav_msgs/Path``, metres, in its header frame."""
    pts = np.array(
        [(p.pose.position.x, p.pose.position.y, p.pose.position.z) for p in msg.poses],
        dtype=np.float64,
    )
    return pts.reshape(-1, 3)


def frame_id_of(msg: Any) -> str:
    """Header frame id (leading slash removed)."""
    return _strip_slash(str(msg.header.frame_id))


JOINT_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"


def joint_trajectory_msg(
    stamp_ns: int,
    frame_id: str,
    names: Sequence[str],
    times_s: ArrayLike,
    positions: ArrayLike,
    velocities: ArrayLike | None = None,
    accelerations: ArrayLike | None = None,
) -> Any:
    """``trajectory_msgs/JointTrajectory``: (T,) times from start (s) and (T, J) positions
    (rad), optional velocities (rad/s) and accelerations (rad/s²)."""
    t = np.asarray(times_s, dtype=np.float64).reshape(-1)
    q = np.asarray(positions, dtype=np.float64).reshape(len(t), len(names))
    qd = None if velocities is None else np.asarray(velocities, dtype=np.float64).reshape(q.shape)
    qdd = (
        None
        if accelerations is None
        else np.asarray(accelerations, dtype=np.float64).reshape(q.shape)
    )
    point = _type("trajectory_msgs/msg/JointTrajectoryPoint")
    duration = _type("builtin_interfaces/msg/Duration")
    empty = np.zeros(0)
    points = []
    for k in range(len(t)):
        sec, nanosec = divmod(round(float(t[k]) * 1e9), 1_000_000_000)
        points.append(
            point(
                positions=q[k].copy(),
                velocities=empty if qd is None else qd[k].copy(),
                accelerations=empty if qdd is None else qdd[k].copy(),
                effort=empty,
                time_from_start=duration(sec=int(sec), nanosec=int(nanosec)),
            )
        )
    return _type(JOINT_TRAJECTORY)(
        header=header(stamp_ns, frame_id), joint_names=list(names), points=points
    )
