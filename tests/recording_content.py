"""Compare two recordings by their decoded content, within the cross-machine tolerances.

scrapcut promises the same bytes for the same command on the same machine; across machines
(other CPUs, other SIMD paths in numpy, open3d and pybullet) it promises the same content
within stated tolerances (README, "Determinism"). :func:`assert_same_content` checks that
promise: the same topics, message counts, message types, header stamps and log times; poses
and other floats within ``atol`` (1e-6 m / 1e-6 rad); colour within ±1 level on at most
``pixel_share`` of the pixels; depth within ±1 mm on at most ``pixel_share`` of the pixels;
the same metadata, numbers within a relative 1e-6.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scrapcut_cli.recording import messages as m
from scrapcut_cli.recording.reader import open_recording


@dataclass(frozen=True)
class Tolerances:
    """What "the same content" allows across machines."""

    atol: float = 1e-6  # metres, radians, quaternion components, seconds
    rtol: float = 1e-6  # for metadata numbers (camera travel, durations)
    color_levels: int = 1
    depth_m: float = 0.001 + 1e-6  # one millimetre step of 16UC1
    pixel_share: float = 0.001  # of an image's pixels that may differ within the above


def assert_same_content(a: Path, b: Path, tol: Tolerances | None = None) -> None:
    """Raise AssertionError naming the first difference between recordings ``a`` and ``b``."""
    tol = tol or Tolerances()
    with open_recording(a) as ra, open_recording(b) as rb:
        topics_a = {(t.name, t.msgtype, t.count) for t in ra.topics()}
        topics_b = {(t.name, t.msgtype, t.count) for t in rb.topics()}
        assert topics_a == topics_b, f"topics differ: {topics_a ^ topics_b}"
        _same_metadata(ra.metadata, rb.metadata, tol)
        msgs_a = _by_topic(ra)
        msgs_b = _by_topic(rb)
    for topic in sorted(msgs_a):
        for k, (x, y) in enumerate(zip(msgs_a[topic], msgs_b[topic], strict=True)):
            where = f"{topic}[{k}]"
            (type_x, log_x, msg_x), (type_y, log_y, msg_y) = x, y
            assert type_x == type_y, f"{where}: type {type_x} != {type_y}"
            assert log_x == log_y, f"{where}: log time {log_x} != {log_y}"
            if type_x in m.IMAGE_TYPES:
                _same_image(msg_x, msg_y, type_x, where, tol)
            else:
                _same_value(msg_x, msg_y, where, tol)


def _by_topic(rec: Any) -> dict[str, list[tuple[str, int, Any]]]:
    out: dict[str, list[tuple[str, int, Any]]] = defaultdict(list)
    for topic, msgtype, log_time, raw in rec.raw_messages():
        out[topic].append((msgtype, log_time, rec.deserialize(raw, msgtype)))
    return out


def _same_image(x: Any, y: Any, msgtype: str, where: str, tol: Tolerances) -> None:
    _same_value(x.header, y.header, f"{where}.header", tol)
    encoding = getattr(x, "encoding", None) or getattr(x, "format", "")
    assert encoding == (getattr(y, "encoding", None) or getattr(y, "format", "")), where
    if str(encoding) in m.DEPTH_ENCODINGS or "compressedDepth" in str(encoding):
        da, db = m.decode_depth(x, msgtype), m.decode_depth(y, msgtype)
        assert da.shape == db.shape, f"{where}: depth shape {da.shape} != {db.shape}"
        valid_a, valid_b = np.isfinite(da), np.isfinite(db)
        both = valid_a & valid_b
        diff = np.zeros(da.shape, dtype=bool)
        diff[both] = np.abs(da[both] - db[both]) > 0
        far = np.zeros(da.shape, dtype=bool)
        far[both] = np.abs(da[both] - db[both]) > tol.depth_m
        assert not far.any(), f"{where}: depth differs by more than {tol.depth_m} m"
        changed = int(diff.sum() + (valid_a != valid_b).sum())
        what = "depth pixels (±1 mm or validity)"
    else:
        ca, cb = m.decode_color(x, msgtype), m.decode_color(y, msgtype)
        assert ca.shape == cb.shape, f"{where}: colour shape {ca.shape} != {cb.shape}"
        delta = np.abs(ca.astype(np.int16) - cb.astype(np.int16)).max(axis=-1)
        assert int(delta.max()) <= tol.color_levels, f"{where}: colour differs by {delta.max()}"
        changed = int((delta > 0).sum())
        what = f"colour pixels (±{tol.color_levels})"
        da = ca
    limit = tol.pixel_share * da.shape[0] * da.shape[1]
    assert changed <= limit, f"{where}: {changed} {what} differ (at most {limit:.0f})"


def _same_value(x: Any, y: Any, where: str, tol: Tolerances) -> None:
    if is_dataclass(x) and not isinstance(x, type):
        # Each reader builds its own message classes: compare the type names.
        assert type(x).__name__ == type(y).__name__, f"{where}: {type(x).__name__}"
        for f in fields(x):
            _same_value(getattr(x, f.name), getattr(y, f.name), f"{where}.{f.name}", tol)
    elif isinstance(x, np.ndarray):
        assert isinstance(y, np.ndarray) and x.shape == y.shape, f"{where}: shape"
        if np.issubdtype(x.dtype, np.floating):
            np.testing.assert_allclose(x, y, rtol=0, atol=tol.atol, err_msg=where)
        else:
            assert np.array_equal(x, y), f"{where}: values differ"
    elif isinstance(x, list | tuple):
        assert len(x) == len(y), f"{where}: length {len(x)} != {len(y)}"
        for k, (u, v) in enumerate(zip(x, y, strict=True)):
            _same_value(u, v, f"{where}[{k}]", tol)
    elif isinstance(x, float):
        assert math.isclose(x, y, rel_tol=0, abs_tol=tol.atol), f"{where}: {x} != {y}"
    elif isinstance(x, str) and where.endswith(".data") and x[:1] == "{":
        _same_json(json.loads(x), json.loads(y), where, tol)  # exploration log entries
    else:
        assert x == y, f"{where}: {x!r} != {y!r}"


def _same_metadata(a: dict[str, dict[str, str]], b: dict[str, dict[str, str]], tol: Any) -> None:
    assert sorted(a) == sorted(b), f"metadata records differ: {sorted(a)} != {sorted(b)}"
    for name in a:
        assert sorted(a[name]) == sorted(b[name]), f"metadata {name}: keys differ"
        for key, text in a[name].items():
            _same_json(_parse(text), _parse(b[name][key]), f"metadata {name}.{key}", tol)


def _parse(text: str) -> Any:
    try:
        return json.loads(text)
    except ValueError:
        return text


def _same_json(x: Any, y: Any, where: str, tol: Tolerances) -> None:
    if isinstance(x, dict):
        assert isinstance(y, dict) and sorted(x) == sorted(y), f"{where}: keys differ"
        for key in x:
            _same_json(x[key], y[key], f"{where}.{key}", tol)
    elif isinstance(x, list):
        assert isinstance(y, list) and len(x) == len(y), f"{where}: length differs"
        for k, (u, v) in enumerate(zip(x, y, strict=True)):
            _same_json(u, v, f"{where}[{k}]", tol)
    elif isinstance(x, float) or isinstance(y, float):
        ok = math.isclose(float(x), float(y), rel_tol=tol.rtol, abs_tol=tol.atol)
        assert ok, f"{where}: {x} != {y}"
    else:
        assert x == y, f"{where}: {x!r} != {y!r}"
