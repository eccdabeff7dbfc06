"""A picture of what the paint filter did to one frame, to tune it by eye (``filter --overlay``).

:func:`overlay_image` composes, side by side:

* **the frame** dimmed to 60 %, with the colour filter's pixels in green where they were kept
  (solid paint with usable depth) and yellow where they were dropped (isolated pixels, small
  blobs, no depth); the stitched line's voxels that this camera sees are drawn as cyan dots,
  each rejected candidate's as red dots labelled with its kind;
* **a hue-saturation histogram** (hue 0-360° across, saturation 0-1 up) of the frame's
  pixels: the background in grey, the filter's pixels in green (log scale each), and the
  filter's range drawn as a white box (hue interval, saturation bound), so a user sees where
  the paint's cluster lies against rust, primer and everything else.

Pure numpy and Pillow's drawing (lines, text): no plotting library per frame, so a recording's
worth of PNGs takes seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from scrapcut_cli.config import PerceptionConfig
from scrapcut_cli.geometry import invert_transform, transform_points
from scrapcut_cli.perception.cloud import backproject_paint
from scrapcut_cli.perception.paint import HsvRange, paint_pixel_indices, rgb_to_hsv_deg
from scrapcut_cli.recording.frame import Frame

FloatArray = NDArray[np.float64]

KEPT = (60, 230, 60)
DROPPED = (250, 220, 40)
LINE = (40, 230, 250)
REJECTED = (250, 60, 60)
#: Histogram panel: bins of hue (degrees) and saturation.
_HUE_BINS = 180
_SAT_BINS = 100
#: A projected voxel is drawn when the depth image agrees within this much (not occluded).
_VISIBLE_M = 0.02


@dataclass(frozen=True)
class Marked:
    """Points (N, 3), metres, base frame, drawn as dots with a label (candidates)."""

    points: FloatArray
    label: str
    line: bool = False


def overlay_image(
    frame: Frame,
    hsv: HsvRange,
    config: PerceptionConfig,
    marked: Sequence[Marked] = (),
) -> NDArray[np.uint8]:
    """(H, W + H, 3) uint8 RGB: the annotated frame and its hue-saturation histogram."""
    from PIL import Image, ImageDraw

    image = np.asarray(frame.color)
    h, w = image.shape[:2]
    filtered = paint_pixel_indices(image, hsv)
    _, kept, _ = backproject_paint(frame, hsv, config)
    left = (0.6 * image).astype(np.uint8).reshape(-1, 3)
    left[filtered] = DROPPED
    left[kept] = KEPT
    canvas = Image.fromarray(left.reshape(h, w, 3))
    draw = ImageDraw.Draw(canvas)
    for item in marked:
        uv = _visible_pixels(frame, item.points)
        if len(uv) == 0:
            continue
        colour = LINE if item.line else REJECTED
        for u, v in uv[:: max(1, len(uv) // 2000)]:
            draw.rectangle((float(u) - 1, float(v) - 1, float(u) + 1, float(v) + 1), fill=colour)
        cu, cv = np.median(uv, axis=0)
        draw.text((float(cu) + 4, float(cv) - 6), item.label, fill=colour)
    draw.text(
        (4, 4),
        f"{hsv.describe()}  kept {len(kept)} / filtered {len(filtered)} px",
        fill=(255, 255, 255),
    )
    panel = _histogram_panel(image, filtered, hsv, size=h)
    return np.concatenate([np.asarray(canvas), panel], axis=1)


def _visible_pixels(frame: Frame, points_base: FloatArray) -> FloatArray:
    """Pixels (K, 2) of the points the camera sees (in front, inside, not occluded)."""
    if len(points_base) == 0:
        return np.zeros((0, 2))
    camera = frame.camera
    cam = transform_points(invert_transform(frame.T_base_cam), points_base)
    cam = cam[cam[:, 2] > 1e-3]
    if len(cam) == 0:
        return np.zeros((0, 2))
    uv = camera.project(cam)
    u, v = np.rint(uv[:, 0]).astype(int), np.rint(uv[:, 1]).astype(int)
    inside = (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)
    u, v, z = u[inside], v[inside], cam[inside, 2]
    depth = frame.depth[v, u]
    seen = ~np.isfinite(depth) | (np.abs(depth - z) <= _VISIBLE_M)
    return np.column_stack([u[seen], v[seen]]).astype(np.float64)


def _histogram_panel(
    image: NDArray[np.uint8], filtered: NDArray[np.intp], hsv: HsvRange, *, size: int
) -> NDArray[np.uint8]:
    """(size, size, 3) hue (across) x saturation (up) counts: background grey, paint green."""
    from PIL import Image, ImageDraw

    pixels = image.reshape(-1, 3)
    step = max(1, len(pixels) // 200_000)  # a sample is enough for the background
    mask = np.zeros(len(pixels), dtype=bool)
    mask[filtered] = True
    sample = np.arange(0, len(pixels), step)
    back = sample[~mask[sample]]
    panel = np.zeros((_SAT_BINS, _HUE_BINS, 3), dtype=np.float64)
    for idx, colour, weight in (
        (back, np.array([170.0, 170.0, 170.0]), step),
        (filtered, np.array(KEPT, dtype=np.float64), 1),
    ):
        if len(idx) == 0:
            continue
        h_s_v = rgb_to_hsv_deg(pixels[idx])
        counts, _, _ = np.histogram2d(
            h_s_v[:, 1], h_s_v[:, 0], bins=(_SAT_BINS, _HUE_BINS), range=((0, 1), (0, 360))
        )
        level = np.log1p(counts * weight) / np.log1p(max(float(counts.max()) * weight, 1.0))
        panel = np.maximum(panel, level[:, :, None] * colour[None, None, :])
    panel = panel[::-1]  # saturation up
    picture = Image.fromarray(panel.astype(np.uint8)).resize((size, size), Image.Resampling.NEAREST)
    draw = ImageDraw.Draw(picture)
    x0 = hsv.hue_min_deg / 360.0 * size
    x1 = hsv.hue_max_deg / 360.0 * size
    y = (1.0 - hsv.sat_min) * size
    box = (255, 255, 255)
    if hsv.wraps:
        draw.rectangle((x0, 0, size - 1, y), outline=box)
        draw.rectangle((0, 0, x1, y), outline=box)
    else:
        draw.rectangle((x0, 0, x1, y), outline=box)
    draw.text((4, size - 14), "hue 0-360 deg ->   saturation up", fill=box)
    return np.asarray(picture)
