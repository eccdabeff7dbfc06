"""McapWriter: ROS 2 schemas, CDR, zstd chunks, atomic output, identical bytes for identical calls.

Files are read back with mcap's own reader and mcap-ros2-support's decoder (what Foxglove-style
tools do), independently of scrapcut's readers.
"""

from __future__ import annotations

import io
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image

from scrapcut_cli.geometry import make_transform, quat_xyzw_to_matrix
from scrapcut_cli.recording.frame import CameraModel
from scrapcut_cli.recording.writer import McapWriter

CAMERA = CameraModel(
    width=32,
    height=24,
    fx=30.0,
    fy=31.0,
    cx=15.5,
    cy=11.5,
    distortion_model="plumb_bob",
    distortion=(0.1, -0.02, 0.001, 0.0005, 0.003),
    frame_id="camera_color_optical_frame",
)
RNG_SEED = 7


def _images() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(RNG_SEED)
    # A smooth picture (JPEG is lossy on noise) with distinct channels.
    v, u = np.mgrid[0:24, 0:32]
    rgb = np.stack([u * 8, v * 10, 255 - u * 4 - v * 3], axis=-1).astype(np.uint8)
    depth_mm = rng.integers(0, 2000, (24, 32), dtype=np.uint16)
    return rgb, depth_mm


def _write_everything(path: Path) -> None:
    rgb, depth_mm = _images()
    T = make_transform(quat_xyzw_to_matrix([0.1, 0.2, 0.3, 0.9]), [0.4, -0.5, 0.6])
    with McapWriter(path) as writer:
        writer.add_metadata("scrapcut", {"paint": "orange", "seed": "3"})
        writer.write_camera_info("/info", 1_000, CAMERA)
        writer.write_tf(500, [("panda_link0", "panda_link8", T)], static=True)
        writer.write_tf(1_000, [("panda_link8", "camera_link", T)], log_time_ns=1_040)
        writer.write_image("/rgb", 1_000, "cam", rgb)
        writer.write_image("/bgr", 1_000, "cam", rgb[:, :, ::-1], encoding="bgr8")
        writer.write_image("/depth", 1_000, "cam", depth_mm)
        writer.write_image("/depth_m", 1_000, "cam", depth_mm.astype(np.float32) / 1000)
        writer.write_compressed_image("/jpeg", 1_000, "cam", rgb, quality=95)
        writer.write_compressed_image("/png", 1_000, "cam", rgb, fmt="png")
        writer.write_compressed_depth("/cdepth", 1_000, "cam", depth_mm)
        writer.write_path("/scrapcut/reference", 2_000, "panda_link0", [[0, 0, 0], [1, 2, 3]])
        writer.write_pose_array("/poses", 2_000, "panda_link0", [[1, 2, 3]], [[0.0, 0.0, 0.6, 0.8]])
        writer.write_pointcloud(
            "/cloud", 2_000, "panda_link0", [[0.1, 0.2, 0.3], [1, 2, 3]], [[255, 128, 1], [0, 0, 0]]
        )
        writer.write_string("/scrapcut/exploration", 3_000, '{"step": 0}')
        writer.write_joint_state("/joints", 3_000, ["a", "b"], [0.5, -0.25])


def _read(path: Path) -> dict[str, list[tuple[Any, Any, Any, Any]]]:
    out: dict[str, list[tuple[Any, Any, Any, Any]]] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            out.setdefault(channel.topic, []).append((schema, channel, message, decoded))
    return out


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("writer") / "all.mcap"
    _write_everything(path)
    return path


def test_same_calls_give_identical_bytes(written: Path, tmp_path: Path) -> None:
    again = tmp_path / "again.mcap"
    _write_everything(again)
    assert again.read_bytes() == written.read_bytes()


def test_schemas_are_ros2_msg_definitions_with_cdr_and_zstd_chunks(written: Path) -> None:
    with written.open("rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        names = {s.name for s in summary.schemas.values()}
        assert {"sensor_msgs/msg/Image", "tf2_msgs/msg/TFMessage", "nav_msgs/msg/Path"} <= names
        assert all(s.encoding == "ros2msg" for s in summary.schemas.values())
        image_schema = next(s for s in summary.schemas.values() if s.name.endswith("/Image"))
        assert b"MSG: std_msgs/Header" in image_schema.data
        assert all(c.message_encoding == "cdr" for c in summary.channels.values())
        assert summary.chunk_indexes
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        metadata = list(reader.iter_metadata())
    assert [(md.name, md.metadata) for md in metadata] == [
        ("scrapcut", {"paint": "orange", "seed": "3"})
    ]


def test_images_decode_with_an_independent_reader(written: Path) -> None:
    rgb, depth_mm = _images()
    msgs = _read(written)
    image = msgs["/rgb"][0][3]
    assert (image.encoding, image.height, image.width, image.step) == ("rgb8", 24, 32, 96)
    np.testing.assert_array_equal(
        np.frombuffer(bytes(image.data), np.uint8).reshape(rgb.shape), rgb
    )
    bgr = msgs["/bgr"][0][3]
    assert bgr.encoding == "bgr8"
    np.testing.assert_array_equal(
        np.frombuffer(bytes(bgr.data), np.uint8).reshape(rgb.shape)[:, :, ::-1], rgb
    )
    depth = msgs["/depth"][0][3]
    assert (depth.encoding, depth.step, depth.is_bigendian) == ("16UC1", 64, 0)
    np.testing.assert_array_equal(np.frombuffer(bytes(depth.data), "<u2").reshape(24, 32), depth_mm)
    depth_m = msgs["/depth_m"][0][3]
    assert depth_m.encoding == "32FC1"
    np.testing.assert_allclose(
        np.frombuffer(bytes(depth_m.data), "<f4").reshape(24, 32), depth_mm / 1000, rtol=1e-6
    )
    png = msgs["/png"][0][3]
    assert "png" in png.format
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(bytes(png.data)))), rgb)
    jpeg = msgs["/jpeg"][0][3]
    assert "jpeg" in jpeg.format
    decoded = np.asarray(Image.open(io.BytesIO(bytes(jpeg.data))).convert("RGB"), dtype=float)
    assert np.abs(decoded - rgb).mean() < 2.0  # lossy, but close on a smooth picture


def test_compressed_depth_is_image_transport_layout(written: Path) -> None:
    _, depth_mm = _images()
    msg = _read(written)["/cdepth"][0][3]
    assert msg.format == "16UC1; compressedDepth png"
    data = bytes(msg.data)
    fmt, quant_a, quant_b = struct.unpack_from("<iff", data, 0)
    assert (fmt, quant_a, quant_b) == (0, 0.0, 0.0)
    assert data[12:20] == b"\x89PNG\r\n\x1a\n"
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(data[12:]))), depth_mm)


def test_camera_info_tf_and_geometry_messages(written: Path) -> None:
    msgs = _read(written)
    info = msgs["/info"][0][3]
    assert (info.width, info.height, info.distortion_model) == (32, 24, "plumb_bob")
    np.testing.assert_allclose(info.k, CAMERA.K.ravel())
    np.testing.assert_allclose(info.d, CAMERA.distortion)
    np.testing.assert_allclose(np.reshape(info.p, (3, 4))[:, :3], CAMERA.K)
    assert info.header.frame_id == "camera_color_optical_frame"

    static = msgs["/tf_static"][0]
    transform = static[3].transforms[0]
    assert (transform.header.frame_id, transform.child_frame_id) == ("panda_link0", "panda_link8")
    q = np.array([0.1, 0.2, 0.3, 0.9]) / np.linalg.norm([0.1, 0.2, 0.3, 0.9])
    r = transform.transform.rotation
    np.testing.assert_allclose([r.x, r.y, r.z, r.w], q, atol=1e-12)
    t = transform.transform.translation
    np.testing.assert_allclose([t.x, t.y, t.z], [0.4, -0.5, 0.6])

    dynamic = msgs["/tf"][0]
    assert dynamic[2].log_time == 1_040  # explicit receive time
    assert dynamic[2].publish_time == 1_040
    assert dynamic[3].transforms[0].header.stamp.nanosec == 1_000  # header keeps the stamp
    assert msgs["/rgb"][0][2].log_time == 1_000  # log time defaults to the stamp

    path = msgs["/scrapcut/reference"][0][3]
    assert [(p.pose.position.x, p.pose.position.y, p.pose.position.z) for p in path.poses] == [
        (0.0, 0.0, 0.0),
        (1.0, 2.0, 3.0),
    ]
    assert path.poses[0].pose.orientation.w == 1.0
    pose = msgs["/poses"][0][3].poses[0]
    assert (pose.orientation.z, pose.orientation.w) == (0.6, 0.8)
    assert msgs["/scrapcut/exploration"][0][3].data == '{"step": 0}'
    joints = msgs["/joints"][0][3]
    assert list(joints.name) == ["a", "b"]
    np.testing.assert_array_equal(joints.position, [0.5, -0.25])


def test_pointcloud_packs_rgb_as_float32_bits(written: Path) -> None:
    cloud = _read(written)["/cloud"][0][3]
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "rgb"]
    assert [f.offset for f in cloud.fields] == [0, 4, 8, 12]
    assert {f.datatype for f in cloud.fields} == {7}  # FLOAT32, as Foxglove expects for rgb
    assert (cloud.width, cloud.height, cloud.point_step, cloud.row_step) == (2, 1, 16, 32)
    records = np.frombuffer(bytes(cloud.data), dtype="<f4").reshape(2, 4)
    np.testing.assert_allclose(records[:, :3], [[0.1, 0.2, 0.3], [1, 2, 3]], rtol=1e-7)
    packed = records[:, 3].copy().view("<u4")
    assert packed.tolist() == [(255 << 16) | (128 << 8) | 1, 0]


def test_sequence_numbers_count_per_channel(written: Path) -> None:
    msgs = _read(written)
    assert [entry[2].sequence for entry in msgs["/tf"]] == [0]
    assert [entry[2].sequence for entry in msgs["/rgb"]] == [0]


def test_exception_leaves_no_file_and_keeps_the_old_one(tmp_path: Path) -> None:
    target = tmp_path / "out.mcap"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError, match="boom"), McapWriter(target) as writer:
        writer.write_string("/s", 1, "x")
        raise RuntimeError("boom")
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.mcap"]


def test_no_output_until_closed(tmp_path: Path) -> None:
    target = tmp_path / "out.mcap"
    writer = McapWriter(target)
    writer.write_string("/s", 1, "x")
    assert not target.exists()
    writer.close()
    assert target.read_bytes().endswith(b"\x89MCAP0\r\n")
    with pytest.raises(ValueError, match="closed"):
        writer.write_string("/s", 2, "y")


def test_abort_drops_the_output(tmp_path: Path) -> None:
    target = tmp_path / "out.mcap"
    writer = McapWriter(target)
    writer.write_string("/s", 1, "x")
    writer.abort()
    writer.close()  # a no-op after abort
    assert list(tmp_path.iterdir()) == []


def test_sequence_and_order_are_kept(tmp_path: Path) -> None:
    target = tmp_path / "out.mcap"
    with McapWriter(target, chunk_size=256) as writer:
        for k in range(5):
            writer.write_string("/a", 10 * k, f"a{k}")
            writer.write_string("/b", 10 * k + 5, f"b{k}")
    msgs = _read(target)
    assert [e[2].sequence for e in msgs["/a"]] == [0, 1, 2, 3, 4]
    assert [e[3].data for e in msgs["/b"]] == [f"b{k}" for k in range(5)]
    assert [e[2].log_time for e in msgs["/b"]] == [5, 15, 25, 35, 45]


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_other_compressions(tmp_path: Path, compression: str) -> None:
    target = tmp_path / "out.mcap"
    with McapWriter(target, compression=compression, chunk_size=64) as writer:
        for k in range(3):
            writer.write_string("/s", k, str(k))
    with target.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        assert {c.compression for c in summary.chunk_indexes} == {
            "" if compression == "none" else compression
        }
        assert [d.data for *_, d in reader.iter_decoded_messages()] == ["0", "1", "2"]


def test_bad_arguments_are_named(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="compression 'gzip'"):
        McapWriter(tmp_path / "a.mcap", compression="gzip")
    with McapWriter(tmp_path / "b.mcap") as writer:
        with pytest.raises(ValueError, match="bgr8 needs a \\(H, W, 3\\) uint8"):
            writer.write_image("/c", 0, "cam", np.zeros((2, 2), np.uint16), encoding="bgr8")
        with pytest.raises(ValueError, match="cannot infer an image encoding"):
            writer.write_image("/c", 0, "cam", np.zeros((2, 2, 3), np.float64))
        writer.write_string("/s", 0, "x")
        with pytest.raises(ValueError, match="already carries std_msgs/msg/String"):
            writer.write_image("/s", 0, "cam", np.zeros((2, 2, 3), np.uint8))
        with pytest.raises(ValueError, match="strings to strings"):
            writer.add_metadata("bad", {"seed": 3})  # type: ignore[dict-item]


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_ros2_bag_writer_round_trip_with_metadata(tmp_path: Path, storage: str) -> None:
    """A ROS 2 bag directory as ros2 bag record leaves it, read back by scrapcut's reader."""
    from scrapcut_cli.recording.reader import open_recording
    from scrapcut_cli.recording.writer import Ros2BagWriter, open_writer

    rgb, depth_mm = _images()
    bag = tmp_path / "scan"
    T = make_transform(np.eye(3), [0.4, 0.0, 0.5])
    with open_writer(bag, storage=storage) as writer:
        assert isinstance(writer, Ros2BagWriter)
        writer.add_metadata("scrapcut", {"paint": "green", "seed": "3"})
        writer.write_tf(500, [("camera_link", "cam", np.eye(4))], static=True)
        for stamp in (1_000, 40_000_000):
            writer.write_tf(stamp, [("panda_link0", "camera_link", T)])
            writer.write_camera_info("/camera/camera/color/camera_info", stamp, CAMERA)
            writer.write_compressed_image(
                "/camera/camera/color/image_raw/compressed", stamp, "cam", rgb, quality=95
            )
            writer.write_image(
                "/camera/camera/aligned_depth_to_color/image_raw", stamp, "cam", depth_mm
            )
    assert (bag / "metadata.yaml").is_file()
    suffix = ".db3" if storage == "sqlite3" else ".mcap"
    assert [p.suffix for p in bag.iterdir() if p.name != "metadata.yaml"] == [suffix]
    with open_recording(bag) as rec:
        assert rec.format == "ros2"
        assert rec.metadata["scrapcut"] == {"paint": "green", "seed": "3"}
        frames = list(rec.frames())
    assert len(frames) == 2
    assert np.abs(frames[0].color.astype(int) - rgb).max() <= 12  # JPEG at quality 95
    assert np.allclose(frames[0].depth[depth_mm > 0], depth_mm[depth_mm > 0] / 1000.0)


def test_ros2_bag_writer_is_atomic_and_refuses_foreign_folders(tmp_path: Path) -> None:
    from scrapcut_cli.recording.writer import Ros2BagWriter

    bag = tmp_path / "scan"
    with pytest.raises(RuntimeError), Ros2BagWriter(bag) as writer:
        writer.write_string("/x", 1, "half")
        raise RuntimeError("crash")
    assert not bag.exists() and list(tmp_path.iterdir()) == []
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "a.jpg").write_bytes(b"x")
    with pytest.raises(ValueError, match="not a ROS 2 bag"):
        Ros2BagWriter(folder)
    assert (folder / "a.jpg").read_bytes() == b"x"
    with pytest.raises(ValueError, match="unknown ROS 2 storage"):
        Ros2BagWriter(tmp_path / "y", storage="parquet")
