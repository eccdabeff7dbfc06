"""What ``scrapcut info`` reports about a recording, as a plain result object."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scrapcut_cli.config import RecordingConfig
from scrapcut_cli.recording.frame import CameraModel
from scrapcut_cli.recording.reader import (
    EXPLORATION_TOPIC,
    REFERENCE_TOPIC,
    FramePlan,
    TopicInfo,
    open_recording,
)


@dataclass(frozen=True)
class RecordingSummary:
    """Format, topics, camera, frame plan and frames of one recording (headers only)."""

    path: Path
    format: str
    duration_s: float
    topics: list[TopicInfo]
    color_topic: str
    depth_topic: str
    info_topic: str
    camera: CameraModel
    plan: FramePlan
    base_frame: str
    camera_frame: str
    tf_frames: list[str]
    pose_time_range_ns: tuple[int, int] | None
    has_reference: bool
    has_exploration_log: bool
    metadata: dict[str, dict[str, str]]
    salvaged: str | None = None  # what --salvage kept of a damaged MCAP

    def to_json(self) -> dict[str, Any]:
        """The fixed keys of docs/design.md (``format`` ... ``has_exploration_log``) plus extras."""
        cam = self.camera
        return {
            "path": str(self.path),
            "format": self.format,
            "duration_s": self.duration_s,
            "topics": [{"name": t.name, "type": t.msgtype, "count": t.count} for t in self.topics],
            "camera": {
                "width": cam.width,
                "height": cam.height,
                "fx": cam.fx,
                "fy": cam.fy,
                "cx": cam.cx,
                "cy": cam.cy,
                "distortion_model": cam.distortion_model,
                "distortion": list(cam.distortion),
                "frame_id": cam.frame_id,
            },
            "frames": {
                "usable": self.plan.usable,
                "skipped": self.plan.skipped,
                "skip_reasons": dict(self.plan.skip_reasons),
                "unpaired_depth": self.plan.unpaired_depth,
            },
            "base_frame": self.base_frame,
            "camera_frame": self.camera_frame,
            "has_reference": self.has_reference,
            "has_exploration_log": self.has_exploration_log,
            "streams": {
                "color": self.color_topic,
                "depth": self.depth_topic,
                "camera_info": self.info_topic,
            },
            "tf_frames": self.tf_frames,
            "pose_time_range_ns": (
                None if self.pose_time_range_ns is None else list(self.pose_time_range_ns)
            ),
            "metadata": self.metadata,
            "salvaged": self.salvaged,
        }


def summarize_recording(
    path: str | os.PathLike[str], config: RecordingConfig | None = None
) -> RecordingSummary:
    """Read a recording's index, TF and image headers and summarise it (the only pixels
    decoded are the first colour and depth image, as a check)."""
    with open_recording(path, config) as rec:
        plan = rec.plan()
        counts = {t.name: t.count for t in rec.topics()}
        return RecordingSummary(
            path=rec.path,
            format=rec.format,
            duration_s=rec.duration_s,
            topics=rec.topics(),
            color_topic=rec.color_topic,
            depth_topic=rec.depth_topic,
            info_topic=rec.info_topic,
            camera=rec.camera,
            plan=plan,
            base_frame=rec.base_frame,
            camera_frame=rec.camera_frame,
            tf_frames=rec.tf.frames,
            pose_time_range_ns=rec.tf.time_range(rec.base_frame, rec.camera_frame),
            has_reference=counts.get(REFERENCE_TOPIC, 0) > 0,
            has_exploration_log=counts.get(EXPLORATION_TOPIC, 0) > 0,
            metadata=rec.metadata,
            salvaged=None if rec.salvaged is None else rec.salvaged.describe(),
        )
