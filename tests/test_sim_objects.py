"""Tests of scrapcut_cli.sim.objects: the pieces, their placement and their painted references."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from scrapcut_cli._open3d import o3d as _o3d
from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import cumulative_length
from scrapcut_cli.sim import list_objects, make_object
from scrapcut_cli.sim.mesh import TriMesh, box
from scrapcut_cli.sim.surface import metal_albedo

NAMES = (
    "cylinder",
    "i_beam",
    "t_piece",
    "basket",
    "air_chamber",
    "perforated_plate",
    "slanted",
    "planar_box",
    "pipe_ring",
    "plate_hole",
)
#: Where the line of a piece with holes was drawn: the envelope over the basket's wires, the
#: perforated plate's top face (placed at its default spot).
PAINTED = {
    "basket": box((0.35, -0.2, 0.0), (0.65, 0.2, 0.15)),
    "perforated_plate": box((0.28, -0.16, 0.122), (0.72, 0.16, 0.125)),
}


def distance_to_mesh(mesh: TriMesh, points: np.ndarray) -> np.ndarray:
    o3d = _o3d()
    scene: Any = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(mesh.vertices.astype(np.float32)),
        o3d.core.Tensor(mesh.faces.astype(np.uint32)),
    )
    query = o3d.core.Tensor(points.astype(np.float32))
    return np.asarray(scene.compute_distance(query).numpy(), dtype=np.float64)


def turning_angles_deg(points: np.ndarray, step_m: float = 0.005) -> np.ndarray:
    """Direction change (deg) between chords ``step_m`` long, every vertex."""
    s = cumulative_length(points)
    fwd = np.searchsorted(s, s + step_m).clip(max=len(s) - 1)
    back = np.searchsorted(s, s - step_m).clip(min=0)
    a = points - points[back]
    b = points[fwd] - points
    ok = (np.linalg.norm(a, axis=1) > 1e-9) & (np.linalg.norm(b, axis=1) > 1e-9)
    cos = np.einsum("ij,ij->i", a[ok], b[ok]) / (
        np.linalg.norm(a[ok], axis=1) * np.linalg.norm(b[ok], axis=1)
    )
    return np.asarray(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def test_catalogue_lists_every_piece_with_a_description() -> None:
    listed = list_objects()
    assert tuple(name for name, _ in listed) == NAMES
    assert all(len(text) > 10 and "\n" not in text for _, text in listed)


def test_unknown_object_names_the_known_ones() -> None:
    with pytest.raises(SimError, match=r"unknown object 'anvil'.*cylinder"):
        make_object("anvil")


@pytest.mark.parametrize("name", NAMES)
def test_reference_is_ordered_on_the_surface_and_in_reach(name: str) -> None:
    obj = make_object(name)
    ref = obj.reference
    # 0.3-0.6 m long, ordered: about a millimetre between vertices, no jumps or repeats.
    assert 0.3 <= obj.reference_length_m <= 0.6
    steps = np.linalg.norm(np.diff(ref, axis=0), axis=1)
    assert steps.min() > 1e-7 and steps.max() < 0.0015
    # On the painted surface (the basket's and the plate's lines run over their holes).
    surface = PAINTED.get(name, obj.mesh)
    assert distance_to_mesh(surface, ref).max() < 1e-6
    # Placed on the floor, in front of the robot, within the Panda's comfortable reach.
    lo, hi = obj.vertices.min(axis=0), obj.vertices.max(axis=0)
    assert lo[2] == pytest.approx(0.0, abs=1e-9)
    assert lo[0] >= 0.25 and hi[0] <= 0.8 and np.abs([lo[1], hi[1]]).max() <= 0.35
    # Normals: unit, and facing up or sideways (every line is seen from above), but for the
    # ring round a pipe, whose underside faces the floor.
    n = obj.reference_normals
    assert n.shape == ref.shape
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    if name == "pipe_ring":
        assert n[:, 2].min() < -0.99 and n[:, 2].max() > 0.99
    else:
        assert n[:, 2].min() > -0.05
    # A closed line does not repeat its first point; its length includes the closing step.
    assert obj.closed == (name in ("pipe_ring", "plate_hole"))
    if obj.closed:
        assert 1e-7 < np.linalg.norm(ref[-1] - ref[0]) < 0.0015
        assert obj.reference_length_m == pytest.approx(
            steps.sum() + np.linalg.norm(ref[-1] - ref[0])
        )


def test_cylinder_normals_are_radial() -> None:
    obj = make_object("cylinder")
    radial = obj.reference - np.array([0.0, 0.0, 0.08])
    radial[:, 0] = 0.0  # the pipe's axis runs along x at height 0.08
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", radial, obj.reference_normals).min() > np.cos(np.radians(2.0))


def test_i_beam_line_turns_twice_by_about_ninety_degrees() -> None:
    angles = turning_angles_deg(make_object("i_beam").reference)
    sharp = angles > 45.0
    turns = np.count_nonzero(np.diff(sharp.astype(int)) == 1)
    assert turns == 2
    assert 75.0 <= angles.max() <= 105.0


def test_air_chamber_line_dips_through_the_groove() -> None:
    obj = make_object("air_chamber")
    axis_point = np.array([0.5, 0.0, 0.13])  # axis along y
    d = obj.reference - axis_point
    radius = np.hypot(d[:, 0], d[:, 2])
    body = np.abs(obj.reference[:, 1]) < 0.18
    assert radius[body].max() == pytest.approx(0.13, abs=1e-3)
    assert radius[body].min() < 0.13 - 0.010  # the 12 mm groove
    assert turning_angles_deg(obj.reference).max() > 30.0


def test_slanted_line_crosses_the_ridge() -> None:
    ref = make_object("slanted").reference
    assert ref[:, 2].max() == pytest.approx(0.22, abs=1e-3)
    assert ref[0, 1] < -0.05 and ref[-1, 1] > 0.05
    assert turning_angles_deg(ref).max() > 45.0


def test_t_piece_line_runs_from_the_branch_over_the_main_pipe() -> None:
    ref = make_object("t_piece").reference
    assert ref[0, 1] > 0.2  # on the branch
    assert ref[-1, 1] < -0.04  # down the far side of the main pipe
    assert ref[:, 2].max() == pytest.approx(0.14, abs=1e-3)  # over the main pipe's crown


def test_seed_changes_the_rust_not_the_geometry() -> None:
    a, b = make_object("t_piece", seed=0), make_object("t_piece", seed=5)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.reference, b.reference)
    points = np.random.default_rng(0).uniform(
        a.vertices.min(axis=0), a.vertices.max(axis=0), (20000, 3)
    )
    rust_a = metal_albedo(points, a.material, a.seed)[1]
    rust_b = metal_albedo(points, b.material, b.seed)[1]
    assert np.array_equal(rust_a, metal_albedo(points, a.material, 0)[1])  # seeded
    # Same share of rust (the material's), in other places.
    assert rust_a.mean() == pytest.approx(rust_b.mean(), abs=0.1)
    assert np.mean(rust_a != rust_b) > 0.2


def test_placement_moves_piece_and_reference_rigidly() -> None:
    home = make_object("planar_box")
    moved = make_object("planar_box", placement=(0.45, 0.1, 90.0))
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    expected = (home.reference - [0.5, 0.0, 0.0]) @ R.T + [0.45, 0.1, 0.0]
    assert np.allclose(moved.reference, expected, atol=1e-12)
    assert moved.reference_length_m == pytest.approx(home.reference_length_m, rel=1e-12)
    assert np.allclose(moved.reference_normals, home.reference_normals @ R.T, atol=1e-6)


def test_perforated_plate_line_crosses_slots_and_round_holes() -> None:
    obj = make_object("perforated_plate")
    ref = obj.reference
    mesh = TriMesh(obj.vertices, obj.faces)
    over_hole = distance_to_mesh(mesh, ref) > 1e-3
    # Holes take a good part of the line's centre, in separate crossings, on both halves (slots
    # on one side of the plain middle strip, round holes on the other); others take only a
    # side of the stroke.
    assert 0.08 <= over_hole.mean() <= 0.6
    starts = np.flatnonzero(np.diff(over_hole.astype(int)) == 1)
    assert len(starts) >= 3
    x = ref[over_hole, 0] - 0.5
    assert (x < -0.02).sum() > 20 and (x > 0.02).sum() > 20
    # Through a hole the floor is 125 mm below: nothing of the plate under the line there.
    assert distance_to_mesh(mesh, ref[over_hole] - [0.0, 0.0, 0.01]).min() > 1e-3
