"""Message building and decoding: every colour and depth encoding, CameraInfo, raw headers."""

from __future__ import annotations

import io
import struct
import sys
from typing import Any

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

from scrapcut_cli.errors import RecordingError
from scrapcut_cli.recording import messages as m
from scrapcut_cli.recording.frame import CameraModel

_V, _U = np.mgrid[0:6, 0:8]
RGB = np.stack([_U * 30, _V * 40, np.full((6, 8), 7)], axis=-1).astype(np.uint8)
DEPTH_MM = (np.arange(48, dtype=np.uint16).reshape(6, 8) * 37) % 3000
DEPTH_MM[0, :3] = 0


def _roundtrip(msg: object, msgtype: str) -> object:
    """Serialise to CDR and back, as a reader would see the message."""
    store = m.typestore()
    return store.deserialize_cdr(m.serialize(msg, msgtype), msgtype)


def _expected_depth_m() -> np.ndarray:
    expected = DEPTH_MM.astype(np.float32) * np.float32(0.001)
    expected[DEPTH_MM == 0] = np.nan
    return expected


@pytest.mark.parametrize(
    ("encoding", "array"),
    [
        ("rgb8", RGB),
        ("bgr8", RGB[:, :, ::-1]),
        ("rgba8", np.dstack([RGB, np.full((6, 8), 255, np.uint8)])),
        ("bgra8", np.dstack([RGB[:, :, ::-1], np.full((6, 8), 9, np.uint8)])),
    ],
)
def test_color_encodings_decode_to_rgb(encoding: str, array: np.ndarray) -> None:
    msg = _roundtrip(m.image_msg(5, "cam", array, encoding=encoding), m.IMAGE)
    rgb = m.decode_color(msg, m.IMAGE)
    assert rgb.dtype == np.uint8
    assert not rgb.flags.writeable
    np.testing.assert_array_equal(rgb, RGB)


def test_mono8_becomes_grey_rgb() -> None:
    grey = RGB[:, :, 0].copy()
    msg = _roundtrip(m.image_msg(5, "cam", grey, encoding="mono8"), m.IMAGE)
    np.testing.assert_array_equal(m.decode_color(msg, m.IMAGE), np.dstack([grey] * 3))


def test_row_padding_in_step_is_skipped() -> None:
    msg = m.image_msg(5, "cam", RGB)
    padded = np.zeros((6, 8 * 3 + 4), np.uint8)
    padded[:, :24] = RGB.reshape(6, 24)
    msg.step = 28
    msg.data = padded.reshape(-1)
    np.testing.assert_array_equal(m.decode_color(_roundtrip(msg, m.IMAGE), m.IMAGE), RGB)


def test_compressed_png_is_lossless() -> None:
    msg = _roundtrip(m.compressed_image_msg(5, "cam", RGB, fmt="png"), m.COMPRESSED_IMAGE)
    rgb = m.decode_color(msg, m.COMPRESSED_IMAGE)
    assert not rgb.flags.writeable
    np.testing.assert_array_equal(rgb, RGB)


def test_compressed_jpeg_is_close_on_a_smooth_picture() -> None:
    v, u = np.mgrid[0:48, 0:64]
    smooth = np.stack([u * 4, v * 5, 255 - u * 2 - v * 2], axis=-1).astype(np.uint8)
    msg = m.compressed_image_msg(5, "cam", smooth, fmt="jpeg", quality=95)
    rgb = m.decode_color(_roundtrip(msg, m.COMPRESSED_IMAGE), m.COMPRESSED_IMAGE)
    assert rgb.shape == smooth.shape
    assert np.abs(rgb.astype(int) - smooth).mean() < 2.0


@pytest.mark.parametrize(("mode", "subsampling"), [("RGB", 2), ("RGB", 0), ("L", -1), ("CMYK", 0)])
def test_jpeg_decodes_to_pillow_s_pixels(mode: str, subsampling: int) -> None:
    # Colour, grey and CMYK JPEGs all come out as Pillow's RGB conversion of them.
    noisy = np.random.default_rng(3).integers(0, 256, (37, 53, 3), dtype=np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(noisy).convert(mode).save(
        buffer, format="JPEG", quality=90, subsampling=subsampling
    )
    msg = m.compressed_image_msg(5, "cam", noisy, fmt="jpeg")
    msg.data = np.frombuffer(buffer.getvalue(), np.uint8)
    rgb = m.decode_color(_roundtrip(msg, m.COMPRESSED_IMAGE), m.COMPRESSED_IMAGE)
    with Image.open(io.BytesIO(buffer.getvalue())) as img:
        expected = np.asarray(img.convert("RGB"))
    assert rgb.dtype == np.uint8 and rgb.shape == (37, 53, 3)
    assert not rgb.flags.writeable
    # Colour and grey JPEGs are decoded by simplejpeg's libjpeg-turbo, CMYK by Pillow's: two
    # builds of one decoder, which may round an upsampled chroma value differently.
    assert np.abs(rgb.astype(int) - expected).max() <= 1


@pytest.mark.parametrize("mode", ["RGB", "L"])
def test_jpeg_decodes_alike_without_simplejpeg(mode: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # simplejpeg is the fast path; Pillow alone gives the same image.
    noisy = np.random.default_rng(5).integers(0, 256, (40, 64, 3), dtype=np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(noisy).convert(mode).save(buffer, format="JPEG", quality=85)
    msg = m.compressed_image_msg(5, "cam", noisy, fmt="jpeg")
    msg.data = np.frombuffer(buffer.getvalue(), np.uint8)
    fast = m.decode_color(msg, m.COMPRESSED_IMAGE)
    monkeypatch.setitem(sys.modules, "simplejpeg", None)  # import fails
    slow = m.decode_color(msg, m.COMPRESSED_IMAGE)
    assert fast.shape == slow.shape == (40, 64, 3)
    assert np.abs(fast.astype(int) - slow).max() <= 1
    assert np.abs(fast.astype(int) - slow).mean() < 0.05


@pytest.mark.parametrize("damage", ["garbage", "truncated"])
def test_a_damaged_jpeg_is_one_recording_error(damage: str) -> None:
    noisy = np.random.default_rng(4).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    msg = m.compressed_image_msg(5, "cam", noisy, fmt="jpeg")
    data = np.asarray(msg.data, np.uint8).tobytes()
    if damage == "garbage":
        data = b"\xff\xd8\xff\xe0 not a jpeg after all"
    msg.data = np.frombuffer(data[: len(data) // 2] if damage == "truncated" else data, np.uint8)
    with pytest.raises(RecordingError, match="cannot decode compressed image"):
        m.decode_color(msg, m.COMPRESSED_IMAGE)


def test_a_jpeg_claiming_a_huge_size_is_one_recording_error() -> None:
    # A damaged size field (60000 x 60000) is not decoded into gigabytes.
    buffer = io.BytesIO()
    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(buffer, format="JPEG")
    data = bytearray(buffer.getvalue())
    sof = data.find(b"\xff\xc0")
    data[sof + 5 : sof + 9] = struct.pack(">HH", 60000, 60000)
    msg = m.compressed_image_msg(5, "cam", np.zeros((16, 16, 3), np.uint8), fmt="jpeg")
    msg.data = np.frombuffer(bytes(data), np.uint8)
    with pytest.raises(RecordingError, match=r"cannot decode compressed image.*pixels"):
        m.decode_color(msg, m.COMPRESSED_IMAGE)


def test_depth_16uc1_is_millimetres_with_zero_invalid() -> None:
    msg = _roundtrip(m.image_msg(5, "cam", DEPTH_MM), m.IMAGE)
    depth = m.decode_depth(msg, m.IMAGE)
    assert depth.dtype == np.float32
    np.testing.assert_array_equal(depth, _expected_depth_m())


def test_depth_16uc1_big_endian() -> None:
    msg = m.image_msg(5, "cam", DEPTH_MM)
    msg.is_bigendian = 1
    msg.data = DEPTH_MM.astype(">u2").reshape(-1).view(np.uint8)
    np.testing.assert_array_equal(m.decode_depth(msg, m.IMAGE), _expected_depth_m())


def test_depth_32fc1_marks_zero_inf_and_negative_invalid() -> None:
    metres = DEPTH_MM.astype(np.float32) / 1000
    metres[1, 0] = np.inf
    metres[1, 1] = -0.5
    metres[1, 2] = np.nan
    depth = m.decode_depth(_roundtrip(m.image_msg(5, "cam", metres), m.IMAGE), m.IMAGE)
    expected = metres.copy()
    expected[(DEPTH_MM == 0) | ~np.isfinite(metres) | (metres <= 0)] = np.nan
    np.testing.assert_array_equal(depth, expected)


def test_compressed_depth_png() -> None:
    msg = _roundtrip(m.compressed_depth_msg(5, "cam", DEPTH_MM), m.COMPRESSED_IMAGE)
    np.testing.assert_array_equal(m.decode_depth(msg, m.COMPRESSED_IMAGE), _expected_depth_m())


def test_compressed_depth_32fc1_inverse_depth_quantisation() -> None:
    # image_transport stores 32FC1 as quantised inverse depth: value = A / depth + B.
    quant_a, quant_b = 100.0, 10.0
    metres = np.array([[0.5, 1.0], [2.0, 0.0]], dtype=np.float32)
    values = np.where(metres > 0, quant_a / np.where(metres > 0, metres, 1) + quant_b, 0)
    buffer = io.BytesIO()
    buffer.write(struct.pack("<iff", 0, quant_a, quant_b))
    Image.fromarray(values.astype(np.uint16)).save(buffer, format="PNG")
    msg = m.compressed_depth_msg(5, "cam", np.zeros((2, 2), np.uint16))
    msg.format = "32FC1; compressedDepth png"
    msg.data = np.frombuffer(buffer.getvalue(), np.uint8)
    depth = m.decode_depth(msg, m.COMPRESSED_IMAGE)
    np.testing.assert_allclose(depth, [[0.5, 1.0], [2.0, np.nan]], rtol=1e-6)


def test_unsupported_encodings_are_named() -> None:
    msg = m.image_msg(5, "cam", RGB)
    msg.encoding = "yuv422"
    with pytest.raises(RecordingError, match="unsupported colour encoding 'yuv422'"):
        m.decode_color(msg, m.IMAGE)
    with pytest.raises(RecordingError, match="unsupported depth encoding 'yuv422'"):
        m.decode_depth(msg, m.IMAGE)
    short = m.image_msg(5, "cam", RGB)
    short.data = short.data[:10]
    with pytest.raises(RecordingError, match="image data too short"):
        m.decode_color(short, m.IMAGE)
    rvl = m.compressed_depth_msg(5, "cam", DEPTH_MM)
    rvl.format = "16UC1; compressedDepth rvl"
    with pytest.raises(RecordingError, match="unsupported compressed depth format"):
        m.decode_depth(rvl, m.COMPRESSED_IMAGE)
    broken = m.compressed_image_msg(5, "cam", RGB)
    broken.data = np.zeros(20, np.uint8)
    with pytest.raises(RecordingError, match="cannot decode compressed image"):
        m.decode_color(broken, m.COMPRESSED_IMAGE)


@pytest.mark.parametrize(
    ("model", "distortion"),
    [
        ("plumb_bob", (0.1, -0.05, 0.001, 0.002, 0.01)),
        ("equidistant", (0.1, 0.01, -0.002, 0.0005)),
        ("rational_polynomial", (0.1, -0.05, 0.0, 0.0, 0.01, 0.02, 0.0, 0.001)),
        ("none", ()),
    ],
)
def test_camera_info_round_trip_keeps_the_distortion_model(
    model: str, distortion: tuple[float, ...]
) -> None:
    camera = CameraModel(640, 480, 610.0, 611.0, 321.5, 239.5, model, distortion, "optical")
    msg = _roundtrip(m.camera_info_msg(7, camera), m.CAMERA_INFO)
    assert m.camera_from_info(msg) == camera


def test_camera_info_aliases_and_missing_size() -> None:
    camera = CameraModel(64, 48, 60.0, 61.0, 31.5, 23.5, "plumb_bob", (0.1,) * 5, "optical")
    msg = m.camera_info_msg(7, camera)
    msg.distortion_model = "inverse_brown_conrady"  # librealsense's name for the D435 colour lens
    msg.width = msg.height = 0
    read = m.camera_from_info(msg, width=64, height=48)
    assert read == camera
    msg.distortion_model = "cubic_spline"
    with pytest.raises(RecordingError, match="unsupported distortion model 'cubic_spline'"):
        m.camera_from_info(msg, width=64, height=48)


@pytest.mark.parametrize("frame_id", ["", "camera_color_optical_frame", "abc"])
def test_raw_header_and_size_without_deserialising(frame_id: str) -> None:
    stamp = 1_700_000_000_123_456_789
    for msg, msgtype in [
        (m.image_msg(stamp, frame_id, DEPTH_MM), m.IMAGE),
        (m.compressed_image_msg(stamp, frame_id, RGB, fmt="png"), m.COMPRESSED_IMAGE),
        (m.compressed_depth_msg(stamp, frame_id, DEPTH_MM), m.COMPRESSED_IMAGE),
    ]:
        raw = m.serialize(msg, msgtype)
        got_stamp, got_frame, _ = m.raw_header(raw, cdr=True)
        assert (got_stamp, got_frame) == (stamp, frame_id)
        assert m.raw_image_size(raw, msgtype, cdr=True) == (6, 8)


def test_raw_header_of_ros1_serialisation() -> None:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types
    stamp = 1_700_000_000_000_000_042
    header = types["std_msgs/msg/Header"](
        seq=99,
        stamp=types["builtin_interfaces/msg/Time"](sec=stamp // 10**9, nanosec=stamp % 10**9),
        frame_id="/cam",
    )
    msg = types["sensor_msgs/msg/Image"](
        header=header,
        height=6,
        width=8,
        encoding="16UC1",
        is_bigendian=0,
        step=16,
        data=DEPTH_MM.reshape(-1).view(np.uint8),
    )
    raw = bytes(store.serialize_ros1(msg, "sensor_msgs/msg/Image"))
    assert m.raw_header(raw, cdr=False)[:2] == (stamp, "/cam")
    assert m.raw_image_size(raw, m.IMAGE, cdr=False) == (6, 8)


def test_tf_message_round_trip_and_leading_slashes() -> None:
    T = np.eye(4)
    T[:3, 3] = [1, 2, 3]
    msg = _roundtrip(m.tf_msg(-5, [("/base", "tool", T)]), m.TF_MESSAGE)
    [(parent, child, stamp, t, q)] = m.tf_transforms(msg)
    assert (parent, child, stamp, t, q) == ("base", "tool", -5, (1.0, 2.0, 3.0), (0, 0, 0, 1))


def test_negative_and_large_stamps() -> None:
    for stamp in (-1, 0, 1, 2**62):
        assert m.stamp_to_ns(m.stamp_from_ns(stamp)) == stamp


def test_path_points_and_stamp_helpers() -> None:
    pts = np.array([[0.1, 0.2, 0.3], [1.0, 2.0, 3.0]])
    msg = _roundtrip(m.path_msg(9, "/base", pts), m.PATH)
    np.testing.assert_array_equal(m.path_points(msg), pts)
    assert m.frame_id_of(msg) == "base"
    assert m.message_stamp_ns(msg) == 9
    assert m.message_stamp_ns(m.string_msg("x")) is None


def test_damaged_bytes_are_a_recording_error() -> None:
    raw = m.serialize(m.image_msg(5, "camera", DEPTH_MM), m.IMAGE)
    with pytest.raises(RecordingError, match="damaged message header"):
        m.raw_header(raw[:10], cdr=True)
    with pytest.raises(RecordingError, match="damaged sensor_msgs/msg/Image message"):
        m.raw_image_size(raw[:26], m.IMAGE, cdr=True)


def _tf_sample() -> object:
    rng = np.random.default_rng(7)
    transforms = []
    for k, (parent, child) in enumerate(
        [("/world", "base"), ("base", "link_1"), ("link_1", "caméra_optical"), ("a", "")]
    ):
        T = np.eye(4)
        T[:3, :3] = Rotation.random(random_state=k).as_matrix()
        T[:3, 3] = rng.normal(size=3)
        transforms.append((parent, child, T))
    return m.tf_msg(1_700_000_000_123_456_789, transforms)


@pytest.mark.parametrize("encoding", ["cdr_le", "cdr_be", "ros1"])
def test_raw_tf_transforms_match_the_deserialised_message(encoding: str) -> None:
    store = m.typestore()
    msg = _tf_sample()
    if encoding == "ros1":
        raw, decoded = _ros1_tf(msg)
    else:
        raw = bytes(store.serialize_cdr(msg, m.TF_MESSAGE, little_endian=encoding == "cdr_le"))
        decoded = store.deserialize_cdr(raw, m.TF_MESSAGE)
    fast = m.raw_tf_transforms(raw, cdr=encoding != "ros1")
    assert fast == m.tf_transforms(decoded)
    assert fast is not None and len(fast) == 4
    assert all(type(x) is float for item in fast for x in (*item[3], *item[4]))
    empty = m.tf_msg(5, [])
    raw_empty = _ros1_tf(empty)[0] if encoding == "ros1" else m.serialize(empty, m.TF_MESSAGE)
    assert m.raw_tf_transforms(raw_empty, cdr=encoding != "ros1") == []


def _ros1_tf(msg: Any) -> tuple[bytes, Any]:
    """A ROS 2 TFMessage as a ROS 1 bag holds it (a header with ``seq``), and rosbags'
    ROS 1 decoding of those bytes."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", m.TF_MESSAGE))
    t = store.types
    items = [
        t["geometry_msgs/msg/TransformStamped"](
            header=t["std_msgs/msg/Header"](
                seq=k,
                stamp=t["builtin_interfaces/msg/Time"](
                    sec=item.header.stamp.sec, nanosec=item.header.stamp.nanosec
                ),
                frame_id=item.header.frame_id,
            ),
            child_frame_id=item.child_frame_id,
            transform=item.transform,
        )
        for k, item in enumerate(msg.transforms)
    ]
    raw = bytes(store.serialize_ros1(t[m.TF_MESSAGE](transforms=items), m.TF_MESSAGE))
    return raw, store.deserialize_ros1(raw, m.TF_MESSAGE)


def test_raw_tf_transforms_leave_anything_else_to_rosbags() -> None:
    raw = m.serialize(_tf_sample(), m.TF_MESSAGE)
    assert m.raw_tf_transforms(raw, cdr=True) is not None
    damaged = [
        raw[:-60],  # cut short
        raw + bytes(8),  # trailing bytes beyond the alignment
        b"\x02" + raw[1:],  # unknown encapsulation
        raw[:4] + struct.pack("<I", 10**6) + raw[8:],  # more transforms than bytes
        raw[:16] + b"\xff" + raw[17:],  # the first frame id's length
        raw[:20] + b"\xff" + raw[21:],  # the first frame id no longer UTF-8
        b"",
    ]
    # the terminator of the first frame id (its length, at offset 16, counts it)
    (length,) = struct.unpack_from("<I", raw, 16)
    damaged.append(raw[: 20 + length - 1] + b"x" + raw[20 + length :])
    for bad in damaged:
        assert m.raw_tf_transforms(bad, cdr=True) is None
    ros1 = _ros1_tf(_tf_sample())[0]
    for bad in (ros1[:-1], ros1 + b"\x00", ros1[:4]):
        assert m.raw_tf_transforms(bad, cdr=False) is None


def test_raw_tf_transforms_name_cache_gives_the_same_names() -> None:
    """Frame names are looked up by their bytes once decoded: a second read of the same
    message (and of names with a leading slash) gives what rosbags' decoding gives."""
    T = np.eye(4)
    msg = m.tf_msg(7, [("/world", "/base", T), ("base", "tool", T), ("/world", "cam", T)])
    raw = m.serialize(msg, m.TF_MESSAGE)
    expected = m.tf_transforms(m.typestore().deserialize_cdr(raw, m.TF_MESSAGE))
    m._TF_NAMES.clear()
    first = m.raw_tf_transforms(raw, cdr=True)
    second = m.raw_tf_transforms(raw, cdr=True)
    assert first == second == expected
    assert [t[:2] for t in expected] == [("world", "base"), ("base", "tool"), ("world", "cam")]
