"""The stroke model's outer envelope (fitting/stroke.py ``_envelope``): on a layered mesh the
path is lifted onto the piece's outer surface; solid pieces and a single perforated sheet are
left where their paint is.

The scenes are height fields seen from above (a camera 0.4 m over them), sampled every 1.5 mm
across x 0-0.3 m, y ±45 mm, as a stitched cloud would hold them: the paint is what lies within
the stroke's half width (12.5 mm) of the line y = 0, the surface everything else within reach,
the stroke's edges where paint meets metal. The line is drawn on the top at z = 0.

The mesh: outer wires (3 mm) running along the line at y = -17 and +21 mm, their tops at
z = 0; under them, wires at 45° to the line 15 mm apart, their tops one wire lower
(z = -3 mm). The stroke lies between the outer wires, so its paint lands on the lower wires
only. A denser variant has the lower wires 9 mm apart.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest

from scrapcut_cli.config import NurbsConfig, SkeletonConfig
from scrapcut_cli.fitting.nurbs import fit_nurbs
from scrapcut_cli.fitting.skeleton import fit_skeleton
from scrapcut_cli.fitting.stroke import StrokeObservations, stroke_model

HALF = 0.0125
STEP = 0.0015
REACH = 0.04
WIRE_R = 0.0015
OUTER_WIRES = (-0.017, 0.021)
LOWER_PITCH = 0.015
#: A denser lower layer: its wires hold 60 % of a full band's 2 mm voxels (under the old
#: perforation share of one half only a fifth of the stations were lifted).
DENSE_PITCH = 0.009
CAMERA = np.array([0.15, 0.0, 0.4])

#: z (N,) of the surface at (x, y), NaN where there is none (a hole).
Height = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _wire_top(offset: np.ndarray) -> np.ndarray:
    """Height below a round wire's top at this distance from its axis (NaN beyond it)."""
    with np.errstate(invalid="ignore"):
        return np.where(
            np.abs(offset) <= WIRE_R, -(WIRE_R - np.sqrt(WIRE_R**2 - offset**2)), np.nan
        )


def mesh_of(pitch: float) -> Height:
    """The two-layer mesh with its lower wires ``pitch`` apart."""

    def height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        outer = np.full_like(x, np.nan)
        for yw in OUTER_WIRES:
            outer = np.fmax(outer, _wire_top(y - yw))
        diagonal = (x - y) / np.sqrt(2.0)
        across = diagonal - pitch * np.round(diagonal / pitch)
        lower = _wire_top(across) - 2.0 * WIRE_R
        return np.asarray(np.fmax(outer, lower))  # seen from above: the higher wire

    return height


mesh = mesh_of(LOWER_PITCH)


def plate(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.zeros_like(x)


def step_beside(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A plate with a 6 mm step up 18 mm to the + side of the line (a flange beside it)."""
    return np.where(y > 0.018, 0.006, 0.0)


def groove(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The line along the flat bottom of a 5 mm deep groove 40 mm wide."""
    return np.where(np.abs(y) > 0.02, 0.005, 0.0)


def perforated(height: Height) -> Height:
    """``height`` with 14 mm round holes every 20 mm in a square grid (one sheet)."""

    def holed(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        dx = x - 0.02 * np.round(x / 0.02)
        dy = y - 0.02 * np.round(y / 0.02) - 0.01
        return np.where(np.hypot(dx, dy) < 0.007, np.nan, height(x, y))

    return holed


def scene(height: Height, seed: int = 0) -> tuple[np.ndarray, StrokeObservations]:
    rng = np.random.default_rng(seed)
    xs = np.arange(0.0, 0.3 + 1e-9, STEP)
    ys = np.arange(-0.045, 0.045 + 1e-9, STEP)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    z = height(gx, gy)
    solid = np.isfinite(z)
    points = np.stack([gx, gy, np.nan_to_num(z)], axis=-1)
    painted = solid & (np.abs(gy) <= HALF)
    # An edge where a paint sample's neighbour across the line is metal left unpainted.
    edge = np.zeros_like(painted)
    for shift in (1, -1):
        beyond = np.roll(solid & ~painted, shift, axis=1)
        edge |= painted & beyond
    paint = points[painted]
    surface = points[solid & ~painted]
    edges = points[edge]
    paint = paint + rng.normal(scale=0.0003, size=paint.shape)
    surface = surface + rng.normal(scale=0.0003, size=surface.shape)
    order = np.argsort(paint[:, 0], kind="stable")
    paint = paint[order]
    observations = StrokeObservations(
        edges=edges,
        surface=surface,
        voxel_m=0.002,
        paint_viewpoints=np.broadcast_to(CAMERA, paint.shape).copy(),
        envelope_reach_m=REACH,
    )
    return paint, observations


def middle(points: np.ndarray) -> np.ndarray:
    """The points away from the line's ends (the round caps)."""
    return points[(points[:, 0] > 0.03) & (points[:, 0] < 0.27)]


@pytest.mark.parametrize("pitch", [LOWER_PITCH, DENSE_PITCH])
@pytest.mark.parametrize("fitter", ["nurbs", "skeleton"])
def test_a_two_layer_mesh_puts_the_path_on_its_outer_envelope(fitter: str, pitch: float) -> None:
    paint, observations = scene(mesh_of(pitch))
    model = stroke_model(paint, observations)
    found = np.isfinite(model.envelope)
    assert found.mean() > 0.8
    # The envelope itself: the outer wires' tops (0) within a millimetre.
    envelope = model.stations[found] + model.envelope[found, None] * model.envelope_normals[found]
    assert np.abs(np.median(envelope[:, 2])) < 0.001
    if fitter == "nurbs":
        curve = fit_nurbs(paint, config=NurbsConfig(), stroke=model)
    else:
        curve = fit_skeleton(paint, config=SkeletonConfig(), stroke=model)
    z = middle(curve.points)[:, 2]
    # On the envelope within 1 mm on average (the paint's own top lies 3 mm below it), and
    # still on the line across it.
    assert abs(z.mean()) < 0.001 and z.min() > -0.002
    assert np.abs(middle(curve.points)[:, 1]).mean() < 0.0015


def test_without_the_envelope_the_path_follows_the_lower_layer() -> None:
    # What the fix is for: the same mesh without the surface around the paint keeps the path
    # on the lower wires, a wire's thickness below the envelope.
    paint, observations = scene(mesh)
    model = stroke_model(paint, replace(observations, envelope_reach_m=0.0))
    assert len(model.envelope) == 0
    z = middle(fit_nurbs(paint, config=NurbsConfig(), stroke=model).points)[:, 2]
    assert z.mean() < -0.002


@pytest.mark.parametrize(
    "name, height",
    [
        ("plate", plate),
        ("step beside the line", step_beside),
        ("groove along the line", groove),
        ("perforated sheet", perforated(plate)),
        ("perforated sheet, step beside", perforated(step_beside)),
    ],
)
def test_solid_pieces_and_a_single_sheet_are_not_lifted(name: str, height: Height) -> None:
    paint, observations = scene(height)
    model = stroke_model(paint, observations)
    assert not np.isfinite(model.envelope).any(), name
    z = middle(fit_nurbs(paint, config=NurbsConfig(), stroke=model).points)[:, 2]
    assert np.abs(z).max() < 0.001, name


def test_a_mesh_seen_only_from_below_is_not_lifted_towards_the_camera_side() -> None:
    # The outside is the cameras' side: a camera under the mesh (looking up through it) sees
    # the outer wires behind the paint, so there is nothing to lift towards it.
    paint, observations = scene(mesh)
    below = np.broadcast_to(CAMERA * [1, 1, -1], paint.shape).copy()
    model = stroke_model(paint, replace(observations, paint_viewpoints=below))
    assert not np.isfinite(model.envelope).any()


def test_the_models_edge_half_width() -> None:
    # The stroke's half width from its two edges, which the end estimate reads a mesh's ends
    # with (fitting.ends: its paint's own profile is the wires'); None when no section saw
    # both edges.
    paint, observations = scene(plate)
    model = stroke_model(paint, observations)
    assert model.edge_half_width == pytest.approx(HALF, abs=0.001)
    blind = replace(model, info={**model.info, "half_width_m": float("nan")})
    assert blind.edge_half_width is None
