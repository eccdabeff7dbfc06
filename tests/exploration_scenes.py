"""Closed-loop scenes for the exploration tests: a camera that renders any pose, no robot.

``CylinderScan`` renders the perception tests' analytic painted cylinder (numpy only);
``ObjectScan`` renders a simulator piece with the simulator's ray caster and its D435i noise
(open3d, no pybullet). ``explore`` runs a planner against either; ``write_exploration_recording``
writes the frames and the planner's log as a small MCAP that ``scrapcut explore`` can replay.
``reach_if`` answers a planner's reachability queries from a test of the pose, as a cell would
(``REACH_ALL``, ``REACH_NONE``).
Small images keep every loop under a few seconds. Seeded: the same calls give the same bytes.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from perception_scenes import SceneNoise, cylinder_top_line, render_cylinder, small_camera, top_view

from scrapcut_cli.cell import Decision, Reach, Reachability, ReachAnswer, ReachQuery, ViewPlanner
from scrapcut_cli.recording.frame import CameraModel, Frame

FloatArray = NDArray[np.float64]


def reach_if(test: Callable[[FloatArray], bool]) -> Reachability:
    """A cell (no robot) that can place the camera exactly where ``test(T_base_cam)`` says."""

    def answer(query: ReachQuery) -> ReachAnswer:
        if test(query.T_base_cam):
            return ReachAnswer(True, Reach.OK, T_base_cam=query.T_base_cam.copy())
        return ReachAnswer(False, Reach.IK)

    return answer


#: Cells that can reach every pose, and none.
REACH_ALL = reach_if(lambda T: True)
REACH_NONE = reach_if(lambda T: False)


@dataclass
class CylinderScan:
    """The painted pipe of ``perception_scenes`` (axis along x, infinite) seen from any pose.

    The line runs along the pipe's top from x = -length/2 to +length/2, so the surface goes on
    past both ends of the paint (a real end, confirmed by the surface).
    """

    length_m: float = 0.6
    width: int = 160
    height: int = 120
    depth_sigma_m: float = 0.0005
    seed: int = 0
    frames: int = 0
    reference: FloatArray = field(init=False)
    camera: CameraModel = field(init=False)

    def __post_init__(self) -> None:
        self.reference = cylinder_top_line(600, length_m=self.length_m)
        self.camera = small_camera(self.width, self.height)

    @property
    def initial_view(self) -> FloatArray:
        """Looking down at the middle of the line from 0.25 m."""
        return top_view(0.0, height_m=0.25)

    def capture(self, T_base_cam: FloatArray) -> Frame:
        frame = render_cylinder(
            self.camera,
            T_base_cam,
            self.reference,
            noise=SceneNoise(depth_sigma_m=self.depth_sigma_m),
            seed=self.seed + self.frames,
            index=self.frames,
        )
        self.frames += 1
        # As a recording gives it back: 16UC1 millimetres.
        return replace(frame, depth=quantise_depth(frame.depth))


def quantise_depth(depth_m: NDArray[np.float32]) -> NDArray[np.float32]:
    """Depth (H, W) float32 metres as a 16UC1 recording returns it (1 mm steps, NaN = 0)."""
    mm = np.nan_to_num(np.rint(depth_m * 1000.0), nan=0.0).clip(0, 65535).astype(np.uint16)
    out = mm.astype(np.float32)
    out *= np.float32(0.001)
    out[mm == 0] = np.nan
    return out


class ObjectScan:
    """A simulator piece (``sim.make_object``) rendered with the simulator's camera model.

    ``start`` picks the initial view along the reference (0 = its start, 1 = its end), as the
    simulator's sweep would look at that point.
    """

    def __init__(
        self,
        name: str,
        *,
        noise: str = "d435i",
        width: int = 160,
        height: int = 120,
        start: float = 0.5,
        seed: int = 0,
    ) -> None:
        from scrapcut_cli.perception.paint import PAINT_PRESETS
        from scrapcut_cli.sim.camera import d435i_color_camera, noise_preset
        from scrapcut_cli.sim.objects import make_object
        from scrapcut_cli.sim.render import SceneRenderer
        from scrapcut_cli.sim.surface import OVERSPRAY_PRESETS, PaintStroke
        from scrapcut_cli.sim.views import sweep_views

        self.object = make_object(name, seed=seed)
        self.reference = self.object.reference
        self.preset = noise_preset(noise)
        stroke = PaintStroke(
            self.object.painted_line,  # a closed line's first point repeated: painted round
            width_m=0.025,
            rgb=PAINT_PRESETS["orange"].rgb,
            overspray=OVERSPRAY_PRESETS[self.preset.overspray],
            seed=seed,
        )
        self.renderer = SceneRenderer(self.object, stroke, seed=seed)
        self.camera = d435i_color_camera(width, height)
        views = sweep_views(self.object, distance_m=0.3, count=21)
        self.initial_view = views[round(start * 20)]
        self.seed = seed
        self.frames = 0

    def capture(self, T_base_cam: FloatArray) -> Frame:
        from scrapcut_cli.sim.camera import simulate_color, simulate_depth

        view = self.renderer.render(T_base_cam, self.camera)
        rng = np.random.default_rng([self.seed, self.frames])
        depth = simulate_depth(view.depth, view.cos_incidence, self.preset, rng)
        color = simulate_color(view.color, self.preset, rng)
        frame = Frame(
            index=self.frames,
            stamp_ns=1_000_000_000 + self.frames * 500_000_000,
            color=color,
            depth=quantise_depth(depth),
            camera=self.camera,
            T_base_cam=np.asarray(T_base_cam, dtype=np.float64).copy(),
        )
        self.frames += 1
        return frame


@dataclass
class LoopResult:
    """Frames captured and decisions made by one closed loop."""

    frames: list[Frame]
    decisions: list[Decision]

    @property
    def log(self) -> list[dict[str, Any]]:
        return [d.info for d in self.decisions]

    @property
    def final(self) -> Decision:
        return self.decisions[-1]


def explore(
    planner: ViewPlanner, scan: CylinderScan | ObjectScan, *, limit: int = 80
) -> LoopResult:
    """Run ``planner`` against ``scan`` as the simulator's recorder would (no robot)."""
    decision = planner.start()
    frames: list[Frame] = []
    decisions: list[Decision] = []
    while not decision.stop:
        assert decision.T_base_cam is not None
        assert len(frames) < limit, "the planner did not stop"
        frame = scan.capture(decision.T_base_cam)
        frames.append(frame)
        decision = planner.observe(frame)
        decisions.append(decision)
    return LoopResult(frames, decisions)


def write_exploration_recording(
    path: Path,
    frames: list[Frame],
    log: list[dict[str, Any]],
    *,
    reference: FloatArray | None = None,
) -> None:
    """Frames (realsense-ros topics, 16UC1 depth, /tf) and the log on /scrapcut/exploration."""
    from scrapcut_cli.recording.writer import McapWriter

    base, link = "panda_link0", "camera_link"
    optical = frames[0].camera.frame_id or "camera_color_optical_frame"
    with McapWriter(path) as writer:
        writer.add_metadata(
            "scrapcut", {"paint": "orange", "object": "synthetic", "mode": "explore"}
        )
        writer.write_tf(frames[0].stamp_ns - 10**8, [(link, optical, np.eye(4))], static=True)
        if reference is not None:
            writer.write_path("/scrapcut/reference", frames[0].stamp_ns - 10**8, base, reference)
        for frame, entry in zip(frames, log, strict=True):
            t = frame.stamp_ns
            for dt in (-5_000_000, 0, 5_000_000):
                writer.write_tf(t + dt, [(base, link, frame.T_base_cam)])
            writer.write_camera_info("/camera/camera/color/camera_info", t, frame.camera)
            writer.write_image("/camera/camera/color/image_raw", t, optical, frame.color)
            depth_mm = np.nan_to_num(np.rint(frame.depth * 1000.0), nan=0.0).astype(np.uint16)
            writer.write_image(
                "/camera/camera/aligned_depth_to_color/image_raw", t, optical, depth_mm
            )
            writer.write_string("/scrapcut/exploration", t + 10_000_000, json.dumps(entry))
