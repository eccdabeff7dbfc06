"""Tests of scrapcut_cli.sim.recorder: what a simulated recording holds, read back by our reader.

Recordings here are tiny (≤ 160×120 px, a few views) so the module runs in seconds.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from recording_content import assert_same_content

from scrapcut_cli.cell import Decision, PlannerContext, ReachQuery
from scrapcut_cli.config import ScrapcutConfig, SimConfig
from scrapcut_cli.errors import SimError
from scrapcut_cli.exploration.planner import planner_factory
from scrapcut_cli.geometry import (
    PolylineDistance,
    invert_transform,
    look_at,
    rotation_angle,
    transform_points,
)
from scrapcut_cli.perception.paint import HsvRange, paint_mask, rgb_to_hsv_deg
from scrapcut_cli.recording.frame import Frame
from scrapcut_cli.recording.mount import CameraMount
from scrapcut_cli.recording.reader import open_recording
from scrapcut_cli.sim import list_objects, record
from scrapcut_cli.sim.camera import T_CAMLINK_OPTICAL, T_HAND_CAMLINK
from scrapcut_cli.sim.recorder import (
    COLOR_TOPIC,
    DEPTH_TOPIC,
    INFO_TOPIC,
    RecordResult,
    place_object,
    planned_views,
    validate,
    worker_start_view,
)
from scrapcut_cli.sim.robot import Q_READY, PandaSim
from scrapcut_cli.sim.views import PrePlannedPlanner, views_along

NAMES = [name for name, _ in list_objects()]


class CapturingPlanner:
    """Wraps a planner and keeps every frame the recorder hands it."""

    def __init__(self, inner: PrePlannedPlanner) -> None:
        self.inner = inner
        self.frames: list[Frame] = []
        self.total = inner.total

    def start(self) -> Decision:
        return self.inner.start()

    def observe(self, frame: Frame) -> Decision:
        self.frames.append(frame)
        return self.inner.observe(frame)

    def skip(self, reason: str) -> Decision:
        return self.inner.skip(reason)


def capture(config: SimConfig, path: Path) -> tuple[RecordResult, list[Frame]]:
    planner = CapturingPlanner(PrePlannedPlanner(planned_views(config, place_object(config))))
    return record(config, path, planner=planner), planner.frames


def header_stamp(msg: Any) -> int:
    """Header stamp in ns (a TFMessage has one per transform; they are equal here)."""
    header = msg.transforms[0].header if hasattr(msg, "transforms") else msg.header
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def log_and_header_stamps(path: Path, topic: str) -> tuple[np.ndarray, np.ndarray]:
    with path.open("rb") as f:
        log = [m.log_time for _, ch, m in make_reader(f).iter_messages() if ch.topic == topic]
    with open_recording(path) as rec:
        header = [header_stamp(msg) for _, _, msg in rec.messages([topic])]
    return np.array(log), np.array(header)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, RecordResult, list[Frame]]:
    path = tmp_path_factory.mktemp("sim") / "cylinder.mcap"
    config = SimConfig(width=160, height=120, views=4, frames_per_view=2, seed=3)
    result, frames = capture(config, path)
    return path, result, frames


def test_recording_has_every_topic_at_its_rate(sweep: tuple[Path, RecordResult, Any]) -> None:
    path, result, _ = sweep
    assert (result.views, result.frames, result.infeasible_views, result.collisions) == (4, 8, 0, 0)
    with open_recording(path) as rec:
        counts = {t.name: t.count for t in rec.topics()}
        assert counts[COLOR_TOPIC] == counts[DEPTH_TOPIC] == counts[INFO_TOPIC] == 8
        assert counts["/tf_static"] == 2 and counts["/scrapcut/reference"] == 1
        assert "/scrapcut/exploration" not in counts
        tf = np.array([header_stamp(msg) for _, _, msg in rec.messages(["/tf"])])
        joints = [msg for _, _, msg in rec.messages(["/joint_states"])]
        images = np.array([stamp for _, stamp, _ in rec.messages([COLOR_TOPIC])])
    assert np.all(np.diff(tf) == 10_000_000)  # 100 Hz throughout, motion included
    assert tf[0] < images[0] - 100_000_000 and tf[-1] > images[-1] + 100_000_000
    assert len(joints) == len(tf) and list(joints[0].name[:2]) == ["panda_joint1", "panda_joint2"]
    positions = np.array([j.position[:7] for j in joints])
    moving = np.linalg.norm(np.diff(positions, axis=0), axis=1) > 1e-9
    assert moving.sum() > 10 * result.views  # /tf follows the motion, not only image stamps
    assert np.diff(images).min() > 0
    assert result.camera_travel_m > 0.1 and result.duration_s == pytest.approx(
        (tf[-1] - tf[0]) / 1e9, abs=0.02
    )


def test_static_transforms_come_from_two_publishers_with_old_stamps(
    sweep: tuple[Path, RecordResult, Any],
) -> None:
    path, _, _ = sweep
    with open_recording(path) as rec:
        static = [header_stamp(msg) for _, _, msg in rec.messages(["/tf_static"])]
        edges = [
            [(t.header.frame_id, t.child_frame_id) for t in msg.transforms]
            for _, _, msg in rec.messages(["/tf_static"])
        ]
        first_tf = next(header_stamp(msg) for _, _, msg in rec.messages(["/tf"]))
        assert rec.base_frame == "panda_link0"
        assert rec.camera_frame == "camera_color_optical_frame"
    assert sorted(edges) == sorted(
        [
            [("panda_link8", "panda_hand")],
            [("panda_hand", "camera_link"), ("camera_link", "camera_color_optical_frame")],
        ]
    )
    assert all(stamp < first_tf - 1_000_000_000 for stamp in static)


def test_log_times_trail_header_stamps_and_the_file_is_in_log_order(
    sweep: tuple[Path, RecordResult, Any],
) -> None:
    path, _, _ = sweep
    for topic, low, high in ((COLOR_TOPIC, 20e6, 40e6), ("/tf", 0.3e6, 2e6)):
        log, header = log_and_header_stamps(path, topic)
        lag = log - header
        assert lag.min() >= low and lag.max() <= high
        assert len(np.unique(lag)) > len(lag) // 2  # seeded jitter, not a constant
    with path.open("rb") as f:
        file_order = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=False)]
    assert np.all(np.diff(file_order) >= 0)


def test_metadata_describes_the_run(sweep: tuple[Path, RecordResult, Any]) -> None:
    path, result, _ = sweep
    with open_recording(path) as rec:
        meta = rec.metadata["scrapcut"]
        summary = rec.metadata["scrapcut_result"]
    assert {k: meta[k] for k in ("object", "mode", "noise", "paint", "seed")} == {
        "object": "cylinder",
        "mode": "sweep",
        "noise": "d435i",
        "paint": "orange",
        "seed": "3",
    }
    assert float(meta["stroke_width_m"]) == 0.025 and meta["tool_version"]
    params = json.loads(meta["params"])
    assert params["sim"]["frames_per_view"] == 2 and params["noise_preset"]["subpixel"] == 0.08
    assert np.allclose(params["hand_eye_nominal"], T_HAND_CAMLINK)
    assert summary["views"] == str(result.views) and summary["stop_reason"] == "done"


def test_reader_returns_exactly_what_the_planner_saw(
    sweep: tuple[Path, RecordResult, list[Frame]],
) -> None:
    path, _, seen = sweep
    with open_recording(path) as rec:
        frames = list(rec.frames())
        reference = rec.reference()
    assert len(frames) == 8 and len(seen) == 4  # the planner sees the last image of a view
    for mine, read in zip(seen, frames[1::2], strict=True):
        assert read.stamp_ns == mine.stamp_ns and read.index == mine.index
        assert np.array_equal(read.color, mine.color)
        assert np.array_equal(read.depth, mine.depth, equal_nan=True)
        assert np.allclose(read.T_base_cam, mine.T_base_cam, atol=1e-9)
        # Nothing a reader would not produce (no true pose, no view index).
        assert mine.extras == read.extras
        assert (mine.base_frame, mine.camera_frame) == (read.base_frame, read.camera_frame)
    assert reference is not None
    assert np.allclose(reference, place_object(SimConfig()).reference, atol=1e-12)


def paint_distances(path: Path, mount: CameraMount | None = None) -> tuple[np.ndarray, float]:
    """Distances (m) of back-projected pixels of the can's colour to the reference; the
    stroke's max half width.

    The can's own colour (hue ±12°, at least 85 % of its saturation), not the orange preset's
    range: that takes rust too, which is perception's problem, not the recorder's. ``mount``:
    pose the frames with this camera mount and clock offset (default: as recorded).
    """
    with open_recording(path, mount=mount) as rec:
        reference = rec.reference()
        assert reference is not None
        params = json.loads(rec.metadata["scrapcut"]["params"])
        h, s, _ = rgb_to_hsv_deg(np.array([params["scene"]["can_rgb"]], dtype=np.uint8))[0]
        can = HsvRange((h - 12.0) % 360.0, (h + 12.0) % 360.0, 0.85 * s, 0.25)
        distance = PolylineDistance(reference)
        out = []
        for frame in rec.frames():
            mask = paint_mask(frame.color, can) & np.isfinite(frame.depth)
            v, u = np.nonzero(mask)
            points = frame.camera.unproject(u, v, frame.depth[v, u])
            out.append(distance.distance(transform_points(frame.T_base_cam, points)))
    return np.concatenate(out), params["stroke"]["max_half_width_m"]


def test_paint_back_projects_onto_the_reference(
    sweep: tuple[Path, RecordResult, Any], tmp_path: Path
) -> None:
    """Orange pixels, back-projected with the recorded poses, lie on the stroke.

    ideal: every one within the widest half width + 0.6 mm (the 1 mm depth step along a ray);
    d435i: 95 % within it + 2 mm (σ_z, flying pixels), the rest are overspray specks (within
    the 25 mm overspray band) and flying pixels.
    """
    ideal = tmp_path / "ideal.mcap"
    record(SimConfig(width=160, height=120, views=3, noise="ideal", seed=3), ideal)
    d_ideal, half = paint_distances(ideal)
    assert len(d_ideal) > 500
    assert d_ideal.max() <= half + 0.0006
    d_noisy, half = paint_distances(sweep[0])
    assert np.median(d_noisy) < 0.5 * 0.025
    assert np.mean(d_noisy <= half + 0.002) >= 0.95


def test_yard_records_the_nominal_hand_eye_but_renders_the_true_one(tmp_path: Path) -> None:
    config = SimConfig(object="planar_box", noise="yard", width=48, height=36, views=2, seed=5)
    _, frames = capture(config, tmp_path / "yard.mcap")
    with open_recording(tmp_path / "yard.mcap") as rec:
        params = json.loads(rec.metadata["scrapcut"]["params"])
    nominal = np.asarray(params["hand_eye_nominal"]) @ T_CAMLINK_OPTICAL
    true_mount = np.asarray(params["hand_eye_true"]) @ T_CAMLINK_OPTICAL
    for frame in frames:
        recorded = frame.T_base_cam
        true = recorded @ invert_transform(nominal) @ true_mount
        # Hand-eye error of 2 mm and 0.3 deg, seen through the flange; the rotation about
        # camera_link moves the optical centre (15 mm away) by at most 0.08 mm more.
        assert np.degrees(rotation_angle(true[:3, :3], recorded[:3, :3])) == pytest.approx(0.3)
        offset = np.linalg.norm(true[:3, 3] - recorded[:3, 3])
        assert offset == pytest.approx(0.002, abs=0.015 * np.radians(0.3) + 1e-9)


def test_frames_while_moving_are_rendered_at_the_capture_time_the_truth_names(
    tmp_path: Path,
) -> None:
    """Explicit hand-eye error and clock offset, images streamed while the arm moves.

    Exact images (ideal, float depth): posed with the true mount and clock offset kept in the
    metadata, every paint pixel of every frame, moving or not, lies on the stroke (as the ideal
    test above: half width + 0.6 mm); posed as the recording publishes them it does not.
    """
    path = tmp_path / "moving.mcap"
    config = SimConfig(
        width=80,
        height=60,
        views=2,
        noise="ideal",
        depth_encoding="32FC1",
        seed=4,
        hand_eye_error_m=0.001,
        hand_eye_error_deg=0.2,
        stamp_offset_s=0.012,
        motion_frames_hz=2.0,
    )
    result = record(config, path)
    assert result.moving_frames >= 5 and result.frames == result.views + result.moving_frames
    with open_recording(path) as rec:
        truth = json.loads(rec.metadata["scrapcut"]["params"])["truth"]
        published = rec.published_mount()
        stamps = rec.plan().stamps_ns
    assert truth["time_offset_s"] == -0.012 and truth["moving_frame"] == "panda_link8"
    # On the camera's clock: 500 ms apart while moving (the rest frames interleave).
    assert np.count_nonzero(np.diff(stamps) == 500_000_000) >= result.moving_frames - 3
    true_mount = CameraMount(
        published.moving_frame,
        published.camera_frame,
        np.array(truth["T_moving_camera"]),
        truth["time_offset_s"],
    )
    d_true, half = paint_distances(path, true_mount)
    assert len(d_true) > 300
    assert d_true.max() <= half + 0.0006
    d_published, _ = paint_distances(path)
    # The can's solid colour stops short of the stroke's thin edge (~1.6 mm here): compare with
    # the same pixels posed with the truth.
    assert d_published.max() > d_true.max() + 0.001


def test_same_seed_same_bytes(tmp_path: Path) -> None:
    """Same command, same machine: the same bytes. Another seed: content the comparison of
    the cross-machine promise tells apart (it is not blind to real differences)."""
    config = SimConfig(object="slanted", width=48, height=36, views=2, seed=7, noise="yard")
    a, b, c = tmp_path / "a.mcap", tmp_path / "b.mcap", tmp_path / "c.mcap"
    record(config, a)
    record(config, b)
    record(replace(config, seed=8), c)
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != c.read_bytes()
    assert_same_content(a, b)
    with pytest.raises(AssertionError):
        assert_same_content(a, c)


@pytest.mark.parametrize("name", NAMES)
def test_every_object_records_in_every_mode_on_the_default_placement(
    name: str, tmp_path: Path
) -> None:
    """All default sweep views are executable; sweep, survey and explore (Algorithm 1 from the
    worker's start, planning only with what the camera observed) run clean: no infeasible view,
    no crash into the true piece at a view or on a move."""
    config = SimConfig(object=name, width=32, height=24)
    obj = place_object(config)
    with PandaSim(obj.mesh, T_hand_camlink_nominal=T_HAND_CAMLINK) as robot:
        q = np.asarray(Q_READY)
        for T in planned_views(config, obj):
            solution = robot.plan_view(T, q)
            assert solution.feasible, solution.answer.describe()
            assert solution.q is not None
            q = solution.q
    for mode in ("sweep", "survey"):
        result = record(replace(config, mode=mode, views=2), tmp_path / f"{mode}.mcap")
        assert (result.views, result.infeasible_views, result.collisions) == (2, 0, 0)
        assert result.motion_collisions == 0 and result.planned_with == "truth"
        assert result.stop_reason == "done"
    explore = record(
        replace(config, mode="explore", width=160, height=120),
        tmp_path / "explore.mcap",
        planner_factory=planner_factory(ScrapcutConfig()),
    )
    assert explore.views >= 1 and not explore.stop_reason.startswith("infeasible")
    assert (explore.infeasible_views, explore.collisions, explore.motion_collisions) == (0, 0, 0)
    assert explore.planned_with == "observed" and explore.min_clearance_m > 0.02
    with open_recording(tmp_path / "explore.mcap") as rec:
        assert rec.metadata["scrapcut_result"]["collisions"] == "0"


class ToyExplorer:
    """A closed-loop planner: three views stepping along +y from the start view, then stop."""

    def __init__(self, context: PlannerContext) -> None:
        self.context = context
        self.steps = 0
        self.checked: list[bool] = []
        self.frames: list[Frame] = []

    def start(self) -> Decision:
        return Decision(self.context.start_view, "extrapolate", info={"step": 0})

    def observe(self, frame: Frame) -> Decision:
        self.steps += 1
        self.frames.append(frame)
        if self.steps == 3:
            return Decision(None, "done", stop=True, info={"pose": frame.T_base_cam})
        T = self.context.start_view.copy()
        T[1, 3] += 0.03 * self.steps
        self.checked.append(self.context.reachable(ReachQuery(T)).feasible)
        return Decision(T, "extrapolate", info={"k": self.steps})


def test_explore_mode_runs_a_closed_loop_planner_and_logs_it(tmp_path: Path) -> None:
    made: list[ToyExplorer] = []

    def factory(context: PlannerContext) -> ToyExplorer:
        made.append(ToyExplorer(context))
        return made[-1]

    config = SimConfig(object="air_chamber", mode="explore", width=32, height=24)
    result = record(config, tmp_path / "explore.mcap", planner_factory=factory)
    assert result.views == 3 and result.stop_reason == "done"
    assert made[0].checked == [True, True]
    context = made[0].context
    assert context.camera.width == 32 and context.paint == "orange"
    assert np.array_equal(context.start_view, worker_start_view(config, place_object(config)))
    # The planner sees the frames as a reader returns them: no true pose, nothing extra.
    assert all(set(f.extras) == {"depth_stamp_ns"} for f in made[0].frames)
    with open_recording(tmp_path / "explore.mcap") as rec:
        log = rec.exploration_log()
        params = json.loads(rec.metadata["scrapcut"]["params"])
    assert [step["reason"] for step in log] == ["extrapolate", "extrapolate", "done"]
    assert log[-1]["stop"] is True and np.asarray(log[-1]["pose"]).shape == (4, 4)
    assert np.allclose(params["start_view"], context.start_view)
    assert params["observed"]["voxel_m"] == pytest.approx(0.01)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_the_start_view_is_where_a_worker_points_the_robot(seed: int) -> None:
    """Near the line's view at the start fraction, not on it: within 20 mm along each axis,
    the optical axis within 10 degrees, the roll about it within 10 degrees; seeded."""
    config = SimConfig(object="slanted", mode="explore", seed=seed)
    obj = place_object(config)
    start = worker_start_view(config, obj)
    exact = views_along(obj, [0.2], distance_m=0.3, min_elevation_deg=35.0)[0]
    offset = np.abs(start[:3, 3] - exact[:3, 3])
    assert np.all(offset <= 0.02 + 1e-12) and np.max(offset) > 0.001
    tilt = np.degrees(np.arccos(np.clip(start[:3, 2] @ exact[:3, 2], -1.0, 1.0)))
    assert 0.0 < tilt <= 10.0 + 1e-9
    assert np.degrees(rotation_angle(start[:3, :3], exact[:3, :3])) <= 10.0 * np.sqrt(2) + 1e-9
    assert np.array_equal(start, worker_start_view(config, obj))
    other = worker_start_view(replace(config, seed=seed + 10), obj)
    assert not np.allclose(start, other)


class IntoThePiece:
    """A planner whose first view puts the camera inside the planar box (10 cm over the floor,
    the box is 15 cm high): a cell that had not looked yet cannot know."""

    def start(self) -> Decision:
        inside = look_at((0.5, 0.0, 0.10), (0.5, 0.0, 0.0), up_hint=(-1.0, 0.0, 0.0))
        return Decision(inside, "extrapolate")

    def observe(self, frame: Frame) -> Decision:
        return Decision(None, "done", stop=True)


def test_a_crash_into_the_unseen_piece_is_counted_not_prevented(tmp_path: Path) -> None:
    """Explore mode plans only with what the camera observed, so nothing stops the first move
    into an unseen piece; the true mesh then counts the crash (view and move) and it is
    reported. An oracle mode, planning with the true mesh, backs the camera out of it."""
    config = SimConfig(object="planar_box", mode="explore", width=32, height=24)
    blind = record(config, tmp_path / "blind.mcap", planner_factory=lambda c: IntoThePiece())
    assert blind.views == 1 and blind.planned_with == "observed"
    assert blind.collisions == 2 and blind.motion_collisions == 1  # at the view, on the way
    assert blind.min_clearance_m < 0.0
    assert blind.view_log[0]["collision"].endswith("/object")
    with open_recording(tmp_path / "blind.mcap") as rec:
        summary = rec.metadata["scrapcut_result"]
    assert (summary["collisions"], summary["motion_collisions"]) == ("2", "1")
    oracle = record(replace(config, mode="sweep"), tmp_path / "oracle.mcap", planner=IntoThePiece())
    assert oracle.views == 1 and oracle.planned_with == "truth"
    assert oracle.collisions == 0 and oracle.min_clearance_m > 0.0
    assert oracle.view_log[0]["backoff_m"] >= 0.1  # backed out of the piece along the axis


def test_explore_mode_without_a_planner_says_what_is_missing(tmp_path: Path) -> None:
    with pytest.raises(SimError, match="explore mode needs the exploration planner"):
        record(SimConfig(mode="explore"), tmp_path / "x.mcap")
    assert not (tmp_path / "x.mcap").exists()


class FarPlanner:
    def start(self) -> Decision:
        T = np.eye(4)
        T[:3, 3] = (2.0, 0.0, 0.5)
        return Decision(T, "extrapolate")

    def observe(self, frame: Frame) -> Decision:
        raise AssertionError("never reached")


def test_an_infeasible_view_stops_a_planner_that_cannot_skip(tmp_path: Path) -> None:
    path = tmp_path / "far.mcap"
    result = record(SimConfig(width=32, height=24), path, planner=FarPlanner())
    assert result.views == 0 and result.infeasible_views == 1
    assert result.stop_reason.startswith("infeasible view")
    with open_recording(path) as rec:
        assert rec.reference() is not None


class BrokenPlanner(FarPlanner):
    def start(self) -> Decision:
        raise RuntimeError("planner crashed")


def test_a_failing_run_leaves_no_file(tmp_path: Path) -> None:
    path = tmp_path / "broken.mcap"
    with pytest.raises(RuntimeError, match="planner crashed"):
        record(SimConfig(width=32, height=24), path, planner=BrokenPlanner())
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"object": "anvil"}, "unknown object"),
        ({"mode": "wander"}, "unknown mode"),
        ({"noise": "foggy"}, "unknown noise preset"),
        ({"paint": "mauve"}, "unknown paint preset"),
        ({"depth_encoding": "8UC1"}, "unknown depth encoding"),
        ({"width": 0}, "resolution"),
        ({"frames_per_view": 0}, "frames per view"),
        ({"speed_scale": 1.5}, "speed scale"),
    ],
)
def test_bad_parameters_are_named(change: dict[str, Any], message: str) -> None:
    with pytest.raises(SimError, match=message):
        validate(replace(SimConfig(), **change))


FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "sim_cylinder_small.mcap"


def test_committed_fixture_is_a_small_simulated_scan() -> None:
    assert FIXTURE.stat().st_size <= 5_000_000
    with open_recording(FIXTURE) as rec:
        meta = rec.metadata["scrapcut"]
        assert (meta["object"], meta["mode"], meta["noise"], meta["seed"]) == (
            "cylinder",
            "sweep",
            "d435i",
            "0",
        )
        assert rec.plan().usable == 6 and rec.camera.width == 320
        assert rec.reference() is not None


@pytest.mark.slow
def test_committed_fixture_regenerates_with_the_same_content(tmp_path: Path) -> None:
    """The command in fixtures/README.md reproduces the committed file's content: bytes may
    differ on another CPU (numpy's SIMD paths, pybullet), decoded content may not, beyond the
    tolerances of the README's determinism promise."""
    config = SimConfig(object="cylinder", noise="d435i", width=320, height=240, views=6, seed=0)
    again = tmp_path / "again.mcap"
    record(config, again)
    assert_same_content(again, FIXTURE)


def _simd_found() -> list[str]:
    from numpy._core._multiarray_umath import __cpu_features__ as features

    return [name for name in ("X86_V3", "AVX2", "FMA3") if features.get(name)]


@pytest.mark.skipif(not _simd_found(), reason="no AVX2/FMA3 path to switch off on this CPU")
def test_another_simd_path_gives_the_same_content(tmp_path: Path) -> None:
    """A recording made with numpy's AVX2/FMA paths switched off (what another CPU runs) has
    the same content within the determinism promise, though not always the same bytes."""
    import os
    import subprocess
    import sys

    config = SimConfig(object="t_piece", width=64, height=48, views=3, seed=3, noise="d435i")
    here, other = tmp_path / "here.mcap", tmp_path / "other.mcap"
    record(config, here)
    code = (
        "import sys\nfrom scrapcut_cli.config import SimConfig\n"
        "from scrapcut_cli.sim import record\n"
        f"record(SimConfig(**{dataclasses.asdict(config)!r}), sys.argv[1])"
    )
    env = dict(
        os.environ,
        NPY_DISABLE_CPU_FEATURES=" ".join(_simd_found()),
        OPENBLAS_CORETYPE="Sandybridge",
    )
    subprocess.run([sys.executable, "-c", code, str(other)], check=True, env=env)
    assert_same_content(here, other)
