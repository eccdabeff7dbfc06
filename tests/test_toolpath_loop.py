"""The cut of a loop: pierce, lead-in, once round, overlap; unobserved set-points; the path file."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import surface_patch

from scrapcut_cli.config import ToolpathConfig
from scrapcut_cli.errors import ToolpathError
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.toolpath.loop import parse_start
from scrapcut_cli.toolpath.pathfile import path_from_dict, path_to_dict
from scrapcut_cli.toolpath.setpoints import make_cutting_path

RADIUS = 0.075
CENTRE = np.array([0.5, 0.0, 0.1])


def ring_curve(arcs: list[list[float]] | None = None, *, tilt_deg: float = 0.0) -> Curve:
    """A 150 mm circle (1 mm vertices, not repeating the first) about CENTRE in a plane tilted
    ``tilt_deg`` about x, starting at angle 0, counter-clockwise seen from above."""
    phi = np.arange(0.0, 2.0 * np.pi, 0.001 / RADIUS)
    local = np.column_stack([RADIUS * np.cos(phi), RADIUS * np.sin(phi), np.zeros_like(phi)])
    points = local @ _tilt(tilt_deg).T + CENTRE
    info = {} if arcs is None else {"unobserved_arcs_m": arcs}
    return Curve(points=points, method="nurbs", spacing_m=0.001, info=info, closed=True)


def _tilt(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])


def plate(tilt_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The plate around the ring (points, viewpoints 0.3 m above each along its normal)."""
    local = surface_patch((-0.12, -0.12, 0.0), (0.24, 0.0, 0.0), (0.0, 0.24, 0.0))
    R = _tilt(tilt_deg)
    points = local @ R.T + CENTRE
    return points, points + 0.3 * R[:, 2]


def test_a_loop_is_pierced_led_in_cut_once_round_and_overlapped() -> None:
    curve = ring_curve(tilt_deg=20.0)
    surface, viewpoints = plate(20.0)
    config = ToolpathConfig(lead_in_m=0.006, overlap_m=0.012)
    path = make_cutting_path(curve, surface, viewpoints, config=config)
    segments = np.asarray(path.segments)
    lead, cut, over = (segments == "lead_in"), (segments == "cut"), (segments == "overlap")
    # In that order, each a block.
    assert segments[0] == "lead_in" and segments[-1] == "overlap"
    assert np.all(np.diff(np.select([lead, cut, over], [0, 1, 2])) >= 0)
    s = path.arc_length
    first_cut = int(np.flatnonzero(cut)[0])
    # The lead-in from the pierce, 6 mm off the line, to the start on it.
    pierce = path.surface_points[0]
    start = path.surface_points[first_cut]
    assert abs(np.linalg.norm(pierce - start) - 0.006) < 1e-6
    assert abs(np.linalg.norm(start - CENTRE) - RADIUS) < 1e-4
    # The pierce lies inside the cut-out (its drop) and on the plate.
    assert np.linalg.norm(pierce - CENTRE) < RADIUS
    normal = _tilt(20.0)[:, 2]
    assert abs((pierce - CENTRE) @ normal) < 1e-6
    # Start "top": the highest point of the tilted ring.
    top = CENTRE + RADIUS * (_tilt(20.0) @ np.array([0.0, 1.0, 0.0]))
    # (the nearest set-point: within half a spacing)
    assert np.linalg.norm(start - top) < 0.5 * config.spacing_m + 1e-4
    # Once round (back on the start), then 12 mm further.
    last_cut = int(np.flatnonzero(cut)[-1])
    assert np.linalg.norm(path.surface_points[last_cut] - start) < 1e-6
    loop_length = s[last_cut] - s[first_cut]
    assert abs(loop_length - 2 * np.pi * RADIUS) < 0.001
    assert 0.012 <= s[-1] - s[last_cut] < 0.012 + config.spacing_m
    # The overlap retraces the start of the cut.
    k = int(over.sum())
    assert np.allclose(
        path.surface_points[-k:], path.surface_points[first_cut + 1 : first_cut + 1 + k]
    )
    # Torch over the standoff along the plate's normal; time runs on.
    axis = (path.positions - path.surface_points) / config.standoff_m
    assert np.allclose(axis @ normal, 1.0, atol=1e-3)
    assert np.all(np.diff(path.time) > 0)
    loop = path.info["loop"]
    assert isinstance(loop, dict) and loop["start"] == "top"
    assert abs(loop["lead_in_m"] - 0.006) < 1e-6
    assert path.info["unobserved"] == 0 and path.info["unobserved_arcs"] == []


def test_set_points_on_an_unobserved_arc_are_flagged_and_the_arc_reported() -> None:
    total = 2 * np.pi * RADIUS
    arc = [0.6 * total, 0.75 * total]
    curve = ring_curve([arc])
    surface, viewpoints = plate()
    path = make_cutting_path(curve, surface, viewpoints, config=ToolpathConfig(overlap_m=0.0))
    flagged = np.array(["unobserved" in f for f in path.flags])
    angle = np.mod(np.arctan2(*(path.surface_points[:, 1::-1] - CENTRE[1::-1]).T), 2 * np.pi)
    on_arc = (angle >= 2 * np.pi * 0.6) & (angle <= 2 * np.pi * 0.75)
    assert flagged[on_arc].mean() > 0.95
    assert not flagged[~on_arc].any()
    assert path.info["unobserved"] == int(flagged.sum())
    (reported,) = path.info["unobserved_arcs"]  # type: ignore[misc]
    assert abs(reported["length_m"] - 0.15 * total) < 1e-6
    # Arc lengths along the path bracket the flagged set-points (within a spacing).
    s = path.arc_length[flagged]
    assert 0.0 <= s.min() - reported["start_s_m"] < path.spacing_m
    assert 0.0 <= reported["end_s_m"] - s.max() < path.spacing_m
    # The start is chosen off the unobserved arc.
    assert not flagged[path.segments.index("cut")]


@pytest.mark.parametrize(
    ("start", "expected_angle_deg"), [("reachable", 180.0), ("0.5,-0.2,0.1", 270.0)]
)
def test_start_choices(start: str, expected_angle_deg: float) -> None:
    surface, viewpoints = plate()
    config = ToolpathConfig(start=start, lead_in_m=0.0)
    path = make_cutting_path(ring_curve(), surface, viewpoints, config=config)
    p = path.surface_points[0] - CENTRE
    angle = np.degrees(np.mod(np.arctan2(p[1], p[0]), 2 * np.pi))
    # The nearest set-point: within half a spacing.
    assert abs(angle - expected_angle_deg) < np.degrees(0.5 * config.spacing_m / RADIUS) + 0.1
    assert path.segments[0] == "cut"


def test_bad_start_is_one_clear_error() -> None:
    with pytest.raises(ToolpathError, match=r"toolpath\.start must be"):
        parse_start("1,2")
    assert parse_start(" TOP ") == "top"
    assert np.allclose(parse_start("1,2,3"), [1.0, 2.0, 3.0])  # type: ignore[arg-type]


def test_a_loop_round_trips_through_the_path_file() -> None:
    total = 2 * np.pi * RADIUS
    curve = ring_curve([[0.1 * total, 0.2 * total]])
    surface, viewpoints = plate()
    path = make_cutting_path(curve, surface, viewpoints, config=ToolpathConfig())
    data = path_to_dict(curve, path, source={}, method_params={}, config={}, frame_id="panda_link0")
    assert data["curve"]["closed"] is True
    assert len(data["curve"]["points"]) == len(curve.points)
    assert {sp["segment"] for sp in data["path"]["setpoints"]} == {"lead_in", "cut", "overlap"}
    curve2, path2, _ = path_from_dict(data)
    assert curve2.closed and path2.segments == path.segments
    assert abs(curve2.length - curve.length) < 1e-9
    assert list(path2.flags) == path.flags
    data["curve"]["closed"] = "yes"
    with pytest.raises(ToolpathError, match=r"curve\.closed must be true or false"):
        path_from_dict(data)
