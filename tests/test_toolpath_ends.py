"""How a cut starts and finishes: edges seen in the surface cloud, reversal, run-out."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import surface_patch

from scrapcut_cli.config import ToolpathConfig
from scrapcut_cli.fitting.curve import Curve
from scrapcut_cli.toolpath.ends import EDGE, PIERCE, RUN_OUT, STOP, end_evidence
from scrapcut_cli.toolpath.setpoints import make_cutting_path

PLATE_Z = 0.1
#: The plate spans x in [0.30, 0.60] m.
X0, X1 = 0.30, 0.60


def _plate(noise_m: float = 0.0005, x0: float = X0, x1: float = X1) -> np.ndarray:
    return surface_patch(
        (x0, -0.08, PLATE_Z),
        (x1 - x0, 0.0, 0.0),
        (0.0, 0.16, 0.0),
        spacing_m=0.004,
        noise_m=noise_m,
        seed=3,
    )


def _line(a: float, b: float, *, trims: tuple[float, float] = (0.0, 0.0)) -> Curve:
    x = np.linspace(a, b, 301)
    pts = np.column_stack([x, 0.01 * np.sin(20 * x), np.full_like(x, PLATE_Z)])
    info = {"end_trim_start_m": trims[0], "end_trim_end_m": trims[1]}
    return Curve(pts, "test", info=info)


def _path(curve: Curve, cloud: np.ndarray, **overrides: object):  # type: ignore[no-untyped-def]
    views = cloud + np.array([0.0, 0.0, 0.3])
    return make_cutting_path(
        curve,
        cloud,
        views,
        config=ToolpathConfig(**overrides),  # type: ignore[arg-type]
    )


def test_a_line_on_the_surface_is_pierced_and_stops() -> None:
    path = _path(_line(0.36, 0.54), _plate())
    ends = path.info["ends"]
    assert (ends["start"]["kind"], ends["finish"]["kind"], ends["reversed"]) == (
        PIERCE,
        STOP,
        False,
    )
    assert ends["start"]["surface_past_m"] is None  # the plate goes on past both ends
    assert path.positions[0, 0] == pytest.approx(0.36, abs=1e-3)


def test_a_line_reaching_the_far_edge_is_cut_backwards_from_that_edge() -> None:
    path = _path(_line(0.40, X1), _plate())
    ends = path.info["ends"]
    assert (ends["start"]["kind"], ends["finish"]["kind"], ends["reversed"]) == (EDGE, STOP, True)
    assert "edge" in ends["start"]["reason"]
    # Cutting order: from the edge at x = 0.60 towards 0.40, arc length from 0 there.
    assert path.surface_points[0, 0] == pytest.approx(X1, abs=1e-3)
    assert path.surface_points[-1, 0] == pytest.approx(0.40, abs=1e-3)
    assert path.arc_length[0] == 0.0 and np.all(np.diff(path.arc_length) > 0)
    x_axes = path.surface_points[1:] - path.surface_points[:-1]
    assert np.all(x_axes[:, 0] < 0)  # travelling towards -x
    assert path.info["dwell_s"] == pytest.approx(path.time[0])


def test_a_line_across_the_plate_starts_at_one_edge_and_runs_out_past_the_other() -> None:
    path = _path(_line(X0, X1), _plate())
    ends = path.info["ends"]
    assert (ends["start"]["kind"], ends["finish"]["kind"], ends["reversed"]) == (
        EDGE,
        RUN_OUT,
        False,
    )


def test_paint_running_off_an_edge_counts_even_when_the_fitter_trimmed_a_cap() -> None:
    # The fitter took the end for a round cap and ended the curve 12 mm before the paint's
    # (and the plate's) end: the surface ends where the paint ends, so this is an edge.
    path = _path(_line(0.40, X1 - 0.012, trims=(0.012, 0.012)), _plate())
    assert path.info["ends"]["start"]["kind"] == EDGE
    # ... while a line whose cap ends 18 mm short of an edge stops on the surface.
    path = _path(_line(0.40, X1 - 0.03, trims=(0.012, 0.012)), _plate())
    ends = path.info["ends"]
    assert (ends["start"]["kind"], ends["finish"]["kind"]) == (PIERCE, STOP)
    assert ends["finish"]["surface_past_m"] == pytest.approx(0.03, abs=0.006)
    assert "no edge" in ends["finish"]["reason"]


def test_an_end_the_camera_did_not_observe_is_not_taken_for_an_edge() -> None:
    cloud = _plate()
    near_end = np.abs(cloud[:, 0] - X1) < 0.03
    path = _path(_line(0.40, X1), cloud[~near_end])
    ends = path.info["ends"]
    assert ends["start"]["kind"] == PIERCE and ends["finish"]["kind"] == STOP
    assert ends["finish"]["evidence"] == "not_observed"


def test_edge_start_can_be_switched_off() -> None:
    path = _path(_line(0.40, X1), _plate(), edge_start=False)
    assert "ends" not in path.info
    assert path.surface_points[0, 0] == pytest.approx(0.40, abs=1e-3)


def test_evidence_is_invariant_to_the_direction_conventions() -> None:
    cloud = _plate()
    end = np.array([X1, 0.0, PLATE_Z])
    for normal in ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0]):
        ev = end_evidence(
            end,
            [1.0, 0.0, 0.0],
            normal,
            cloud,
            paint_past_m=0.0,
            gap_m=0.006,
            probe_m=0.03,
            corridor_m=0.01,
        )
        assert ev.kind == EDGE and ev.surface_past_m is not None
        assert ev.surface_past_m <= 0.006
