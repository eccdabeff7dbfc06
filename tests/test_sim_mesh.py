"""Tests of scrapcut_cli.sim.mesh: procedural meshes are closed, outward and the right size."""

from __future__ import annotations

import numpy as np
import pytest

from scrapcut_cli.sim import mesh as m


def signed_volume(mesh: m.TriMesh) -> float:
    """Divergence theorem: positive for a closed mesh with outward normals."""
    v = mesh.vertices[mesh.faces]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def test_box_is_closed_outward_with_exact_volume_and_area() -> None:
    b = m.box((0.1, -0.2, 0.0), (0.4, 0.2, 0.15))
    assert signed_volume(b) == pytest.approx(0.3 * 0.4 * 0.15, rel=1e-12)
    assert b.area() == pytest.approx(2 * (0.3 * 0.4 + 0.3 * 0.15 + 0.4 * 0.15), rel=1e-12)
    centre = np.array([0.25, 0.0, 0.075])
    tri_centres = b.vertices[b.faces].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", b.face_normals(), tri_centres - centre) > 0)


def test_box_keeps_edges_sharp() -> None:
    """Vertex normals of a box are its face normals (vertices are not shared across edges)."""
    b = m.box((0, 0, 0), (1, 1, 1))
    vn = b.vertex_normals()
    assert np.allclose(np.abs(vn).max(axis=1), 1.0)


def test_box_rejects_inverted_corners() -> None:
    with pytest.raises(ValueError, match="lower < upper"):
        m.box((0, 0, 0), (1, -1, 1))


def test_extrude_prism_volume_and_orientation() -> None:
    triangle = [(-0.12, 0.0), (0.12, 0.0), (0.0, 0.22)]
    prism = m.extrude(triangle, -0.1, 0.1)
    assert signed_volume(prism) == pytest.approx(0.5 * 0.24 * 0.22 * 0.2, rel=1e-12)
    with pytest.raises(ValueError, match="convex"):
        m.extrude(triangle[::-1], 0.0, 1.0)


def test_revolve_closed_solid_volume_matches_faceted_cylinder() -> None:
    r, h, n = 0.1, 0.3, 64
    solid = m.revolve([(0.0, 0.0), (r, 0.0), (r, h), (0.0, h)], segments=n, sharp=(1, 2))
    polygon_area = 0.5 * n * r * r * np.sin(2 * np.pi / n)
    assert signed_volume(solid) == pytest.approx(polygon_area * h, rel=1e-9)


def test_revolve_tube_has_a_hollow_core() -> None:
    outer, inner, h, n = 0.08, 0.074, 0.4, 96
    loop = [(outer, 0.0), (outer, h), (inner, h), (inner, 0.0), (outer, 0.0)]
    tube = m.revolve(loop, segments=n, sharp=(1, 2, 3))
    k = 0.5 * n * np.sin(2 * np.pi / n)
    assert signed_volume(tube) == pytest.approx(k * (outer**2 - inner**2) * h, rel=1e-9)


def test_smooth_revolve_normals_are_radial() -> None:
    """Inside a smooth run (the middle ring) the averaged normals are exactly radial."""
    tube = m.revolve([(0.05, 0.0), (0.05, 0.05), (0.05, 0.1)], segments=32)
    middle = np.isclose(tube.vertices[:, 2], 0.05)
    vn = tube.vertex_normals()[middle]
    radial = tube.vertices[middle].copy()
    radial[:, 2] = 0.0
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert middle.sum() == 32
    assert np.allclose(vn, radial, atol=1e-9)


def test_cylinder_between_spans_its_end_points() -> None:
    a, b = np.array([0.1, 0.2, 0.3]), np.array([0.4, -0.1, 0.5])
    bar = m.cylinder_between(a, b, 0.002, segments=8)
    axis = (b - a) / np.linalg.norm(b - a)
    along = (bar.vertices - a) @ axis
    assert along.min() == pytest.approx(0.0, abs=1e-12)
    assert along.max() == pytest.approx(np.linalg.norm(b - a), abs=1e-12)
    radial = np.linalg.norm((bar.vertices - a) - np.outer(along, axis), axis=1)
    assert radial.max() == pytest.approx(0.002, abs=1e-12)
    assert signed_volume(bar) > 0


def test_merge_and_transform_keep_geometry() -> None:
    a = m.box((0, 0, 0), (1, 1, 1))
    b = m.box((2, 0, 0), (3, 1, 1))
    both = m.merge([a, b])
    assert len(both.faces) == 24 and signed_volume(both) == pytest.approx(2.0)
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    T[:3, 3] = (5, 0, 0)
    moved = both.transformed(T)
    assert signed_volume(moved) == pytest.approx(2.0)
    assert np.allclose(moved.bounds[0], (4, 0, 0))
    assert np.array_equal(both.vertices, m.merge([a, b]).vertices)  # input untouched


def test_perforated_sheet_is_closed_with_its_holes_cut_out() -> None:
    holes = [
        m.Hole((-0.02, -0.02), "rect", (0.014, 0.03)),
        m.Hole((0.02, 0.02), "round", (0.024, 0.024)),
    ]
    sheet = m.perforated_sheet((0.08, 0.08), 0.04, holes, thickness=0.003)
    outlines = [h.outline(0.001) for h in holes]
    open_area = sum(m._polygon_area(o) for o in outlines)
    assert open_area == pytest.approx(0.014 * 0.03 + np.pi * 0.012**2, rel=2e-3)
    # Closed and outward: the signed volume is the solid's, holes taken out.
    assert signed_volume(sheet) == pytest.approx((0.08**2 - open_area) * 0.003, rel=1e-9)
    # Every edge is shared by exactly two triangles (no cracks, no T-junctions).
    v = np.round(sheet.vertices / 1e-7).astype(np.int64)
    _, ids = np.unique(v, axis=0, return_inverse=True)
    f = ids.reshape(-1)[sheet.faces]
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert set(counts.tolist()) == {2}


def test_perforated_sheet_refuses_a_hole_that_leaves_its_cell() -> None:
    with pytest.raises(ValueError, match="does not fit"):
        m.perforated_sheet(
            (0.08, 0.04), 0.04, [m.Hole((-0.02, 0.0), "round", (0.05, 0.05))], thickness=0.003
        )
    with pytest.raises(ValueError, match="divide"):
        m.perforated_sheet((0.09, 0.04), 0.04, [], thickness=0.003)
