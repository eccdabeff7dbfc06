"""Tests of scrapcut_cli.perception.candidates: the marked line among the stitched paint.

Synthetic stitched clouds (one point per 2 mm voxel, colours as the voxels' mean sRGB): a
painted S-curve on a plate with rust touching it, an old faded mark crossing it, a paint-coloured
crate's top beside the plate, and the scan's view centres along the line.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import apply_se3, line_on_plane, painted_stroke, random_se3, s_curve_on_plane

from scrapcut_cli.config import SelectionConfig
from scrapcut_cli.errors import PerceptionError
from scrapcut_cli.geometry import PolylineDistance
from scrapcut_cli.perception.candidates import KIND_BLOB, KIND_LINE, select_line
from scrapcut_cli.perception.paint import paint_core, saturation_splits

VOXEL = 0.002
PAINT = (0.93, 0.40, 0.03)  # fluorescent orange, S 0.97
FADED = (0.60, 0.40, 0.22)  # an old orange mark, S 0.63
RUST = (0.50, 0.26, 0.14)  # iron oxide, S 0.72


def voxelise(points: np.ndarray) -> np.ndarray:
    """One point per 2 mm voxel (the first), as the stitcher leaves a cloud."""
    _, first = np.unique(np.floor(points / VOXEL).astype(np.int64), axis=0, return_index=True)
    return np.asarray(points[np.sort(first)])


def patch(centre: tuple[float, float, float], half: tuple[float, float], seed: int) -> np.ndarray:
    """A flat rectangle of points on z = centre[2], 2 mm apart, with 0.5 mm noise."""
    rng = np.random.default_rng(seed)
    x = np.arange(-half[0], half[0], VOXEL)
    y = np.arange(-half[1], half[1], VOXEL)
    xx, yy = np.meshgrid(x, y)
    pts = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)]) + np.asarray(centre)
    return np.asarray(pts + rng.normal(scale=0.0005, size=pts.shape))


def colour(n: int, rgb: tuple[float, float, float], seed: int, sd: float = 0.01) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(np.asarray(rgb) + rng.normal(scale=sd, size=(n, 3)), 0.0, 1.0)


def assemble(
    parts: dict[str, np.ndarray], rgbs: dict[str, tuple[float, float, float]], seed: int
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(points, rgb, {part: indices}) of the named parts stacked in order, each coloured."""
    points, rgb, index = [], [], {}
    start = 0
    for k, (name, p) in enumerate(parts.items()):
        points.append(p)
        rgb.append(colour(len(p), rgbs[name], seed + 10 + k))
        index[name] = np.arange(start, start + len(p))
        start += len(p)
    return np.vstack(points), np.vstack(rgb), index


def scene(*, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(points, rgb, view centres, {part: indices}) of the test scene."""
    curve, normals = s_curve_on_plane(0.4)
    line = voxelise(painted_stroke(curve, normals, caps=True, noise_m=0.0005, seed=seed))
    # Rust touching the line's edge, an old mark crossing it at 60 degrees.
    disc = patch((0.12, 0.05, 0.0), (0.03, 0.02), seed + 1)
    cross = np.array([[0.3, -0.05, 0.0], [0.3 + 0.1 * np.cos(1.05), -0.05 + 0.1 * np.sin(1.05), 0]])
    cross = np.linspace(cross[0], cross[1], 200)
    faded = voxelise(painted_stroke(cross, np.tile([0, 0, 1.0], (200, 1)), seed=seed + 2))
    # Fresh paint covers what lies under it (the ragged band reaches 14.4 mm).
    band = PolylineDistance(curve)
    disc = disc[band.distance(disc) > 0.0155]
    faded = faded[band.distance(faded) > 0.0155]
    # A crate beside the plate: its paint-coloured top, 0.15 m up and 0.25 m aside.
    crate = patch((0.2, 0.26, 0.15), (0.10, 0.06), seed + 3)
    parts = {"line": line, "rust": disc, "faded": faded, "crate": crate}
    rgbs = {"line": PAINT, "rust": RUST, "faded": FADED, "crate": (0.95, 0.38, 0.02)}
    points, rgb, index = assemble(parts, rgbs, seed)
    return points, rgb, curve[::100], index


def test_the_line_is_picked_and_the_rest_reported() -> None:
    points, rgb, centres, parts = scene()
    before = points.copy()
    selection = select_line(points, rgb, centres, voxel_m=VOXEL)
    assert np.array_equal(points, before)
    line = selection.line.points
    assert selection.line.kind == KIND_LINE
    assert np.isin(line, parts["line"]).mean() > 0.97  # a thin rim of rust may join
    assert np.isin(parts["line"], line).mean() > 0.95
    for other in ("rust", "faded", "crate"):
        assert np.isin(parts[other], line).mean() < 0.05, other
    kinds = {c.kind for c in selection.rejected}
    assert KIND_BLOB in kinds  # the crate
    assert kinds & {"faded", "dull"}  # the old mark and the rust: another colour
    crate = max(selection.rejected, key=lambda c: np.isin(c.points, parts["crate"]).sum())
    assert crate.kind == KIND_BLOB
    report = selection.to_dict()
    assert report["lines"][0]["kind"] == "line"
    row = next(r for r in report["rejected"] if r["kind"] == KIND_BLOB)
    assert row["points"] == len(crate.points)
    assert row["position_m"] == pytest.approx([0.2, 0.26, 0.15], abs=0.01)
    assert {"length_mm", "width_mm", "saturation", "reason"} <= set(row)
    assert not selection.warnings


def test_the_pick_is_the_same_after_a_rigid_motion() -> None:
    points, rgb, centres, _ = scene(seed=3)
    a = select_line(points, rgb, centres, voxel_m=VOXEL)
    T = random_se3(4, max_translation=0.5)
    b = select_line(apply_se3(T, points), rgb, apply_se3(T, centres), voxel_m=VOXEL)
    sym = np.setxor1d(a.line.points, b.line.points)
    assert len(sym) <= 0.01 * len(a.line.points)


def test_two_lines_the_scan_follows_one_and_pick_chooses() -> None:
    curve, normals = line_on_plane(0.3)
    a = voxelise(painted_stroke(curve, normals, seed=1))
    longer, n2 = line_on_plane(0.45)
    b = voxelise(painted_stroke(longer + np.array([0.0, 0.08, 0.0]), n2, seed=2))
    points = np.vstack([a, b])
    rgb = colour(len(points), PAINT, 5)
    centres = curve[::100]
    scan = select_line(points, rgb, centres, voxel_m=VOXEL)
    assert np.isin(scan.line.points, np.arange(len(a))).all()
    assert len(scan.warnings) == 1 and "2 line-like candidates" in scan.warnings[0]
    assert [c.kind for c in scan.rejected].count("other_line") == 1

    def pick(mode: str, starts: np.ndarray = centres) -> list[np.ndarray]:
        chosen = select_line(points, rgb, starts, voxel_m=VOXEL, config=SelectionConfig(pick=mode))
        return [c.points for c in chosen.lines]

    (longest,) = pick("longest")
    assert np.isin(longest, np.arange(len(a), len(points))).all()
    # The scan started on the second line (and came back along the first).
    (nearest,) = pick(
        "nearest-start", np.vstack([longer[:1] + np.array([0.0, 0.08, 0.0]), centres])
    )
    assert np.isin(nearest, np.arange(len(a), len(points))).all()
    both = pick("all")
    assert len(both) == 2 and sum(len(p) for p in both) == len(points)


def test_without_colours_the_shape_decides() -> None:
    points, _, centres, parts = scene()
    keep = np.concatenate([parts["line"], parts["crate"]])
    selection = select_line(points[keep], None, centres, voxel_m=VOXEL)
    assert np.isin(selection.line.points, np.arange(len(parts["line"]))).mean() > 0.99
    assert [c.kind for c in selection.rejected] == [KIND_BLOB]


def test_no_stroke_is_one_line_listing_what_was_found() -> None:
    points, rgb, centres, parts = scene()
    crate = parts["crate"]
    with pytest.raises(PerceptionError) as info:
        select_line(points[crate], rgb[crate], centres, voxel_m=VOXEL)
    message = str(info.value)
    assert "no stroke-like paint" in message and "\n" not in message
    assert "selection.min_elongation" in message


def test_saturation_modes_split_only_at_a_real_dip() -> None:
    rng = np.random.default_rng(0)
    paint = rng.normal(0.95, 0.015, 3000)
    rust = rng.normal(0.70, 0.03, 2000)
    (split,) = saturation_splits(np.concatenate([paint, rust]))
    assert 0.75 < split < 0.9
    # A stroke's own desaturated edge is a tail, not a second mode.
    tail = 0.95 - np.abs(rng.normal(0.0, 0.08, 1000))
    assert saturation_splits(np.concatenate([paint, tail])) == []
    # Too few to be a cluster.
    assert saturation_splits(np.concatenate([paint, rust[:20]])) == []
    # The paint's core: within a few spreads below its mode, the most saturated mode first.
    core = paint_core(np.concatenate([paint, rust]))
    assert 0.85 < core < 0.93
    assert np.isnan(paint_core(np.full(5, np.nan)))


def overspray_scene(
    *, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(points, rgb, sight lines, {part: indices}): heavy overspray on rust, as the yard preset
    sprays it. The line's fresh paint is a 25 mm band; around it, to 45 mm from the curve,
    paint mixed with rust (S ~0.88, the paint's own saturation layer) widens its candidate to
    ~90 mm, past a stroke's width, until the paint's core is set apart; rust (S 0.72) lies under
    it all. Off the piece, 6 cm above it and never looked at, a short dull stroke (S 0.72) is the
    only stroke-like candidate before the core is set apart."""
    curve, normals = line_on_plane(0.4)
    line = voxelise(painted_stroke(curve, normals, noise_m=0.0005, seed=seed))
    band = PolylineDistance(curve)
    plate = patch((0.2, 0.0, 0.0), (0.26, 0.10), seed + 1)
    d = band.distance(plate)
    rng = np.random.default_rng(seed + 2)
    spray = plate[(d > 0.0155) & (d < 0.045) & (rng.random(len(plate)) < 0.8)]
    rust = plate[d >= 0.045]
    stub, n2 = line_on_plane(0.07)
    junk = voxelise(painted_stroke(stub + np.array([0.15, 0.075, 0.06]), n2, width_m=0.015, seed=3))
    parts = {"line": line, "spray": spray, "rust": rust, "junk": junk}
    mixed = (0.715, 0.33, 0.085)  # half paint, half rust: S 0.88
    rgbs = {"line": PAINT, "spray": mixed, "rust": RUST, "junk": RUST}
    points, rgb, index = assemble(parts, rgbs, seed)
    # Sight lines from a camera 0.3 m above each view centre along the line.
    ends = curve[::40]
    sights = np.stack([ends + np.array([0.0, 0.0, 0.3]), ends], axis=1)
    return points, rgb, sights, index


def test_overspray_past_a_strokes_width_still_finds_the_line() -> None:
    points, rgb, sights, parts = overspray_scene()
    # Paint and overspray together are wider than a stroke (the case this test is about).
    band = np.concatenate([parts["line"], parts["spray"]])
    loose = SelectionConfig(max_width_m=1.0)
    assert select_line(points[band], None, sights, voxel_m=VOXEL, config=loose).line.width_m > 0.08
    selection = select_line(points, rgb, sights, voxel_m=VOXEL)
    line = selection.line
    # The fresh paint's core, not the dull stroke off the piece the shape alone would leave.
    assert np.isin(parts["line"], line.points).mean() > 0.95
    assert np.isin(line.points, parts["junk"]).sum() == 0
    assert line.width_m < 0.06 and line.follow > 0.9
    assert line.hsv[1] > 0.9
    junk = [c for c in selection.rejected if np.isin(c.points, parts["junk"]).mean() > 0.5]
    assert junk and junk[0].kind in ("faded", "dull", "off_surface")


def test_a_followed_blob_is_not_traded_for_a_stroke_the_scan_never_saw() -> None:
    points, _, sights, parts = overspray_scene()
    # Colours unknown: the paint's core cannot be set apart, so the band stays ~90 mm wide
    # (a blob); the only stroke-like candidate is the stub the scan never followed.
    keep = np.concatenate([parts["line"], parts["spray"], parts["junk"]])
    with pytest.raises(PerceptionError) as info:
        select_line(points[keep], None, sights, voxel_m=VOXEL)
    message = str(info.value)
    assert "the scan follows paint that is not shaped like a stroke" in message
    assert "selection.max_width_m" in message and "\n" not in message


def test_a_cut_out_drawn_round_on_a_plate_is_a_line() -> None:
    # A closed circle 150 mm across (a cut-out drawn on a plate), a 25 mm stroke, and a crate
    # beside it. Its geodesic diameter runs only half way round, and the other half lies up to
    # 150 mm from it: measured along its loop it is a 470 mm stroke 25 mm wide, the line.
    theta = np.linspace(0.0, 2.0 * np.pi, 1200)
    circle = np.column_stack([0.075 * np.cos(theta), 0.075 * np.sin(theta), np.zeros_like(theta)])
    normals = np.tile([0.0, 0.0, 1.0], (len(circle), 1))
    ring = voxelise(painted_stroke(circle, normals, noise_m=0.0005, seed=4))
    crate = patch((0.0, 0.26, 0.15), (0.10, 0.06), 5)
    points, rgb, parts = assemble(
        {"ring": ring, "crate": crate}, {"ring": PAINT, "crate": (0.95, 0.38, 0.02)}, 4
    )
    selection = select_line(points, rgb, circle[::50], voxel_m=VOXEL)
    assert selection.line.kind == KIND_LINE
    assert np.isin(parts["ring"], selection.line.points).mean() > 0.95
    row = selection.to_dict()["lines"][0]
    assert 440.0 < row["length_mm"] < 500.0
    assert 20.0 < row["width_mm"] < 32.0
    assert any(c.kind == KIND_BLOB for c in selection.rejected)
