"""An Intel RealSense D435i on the Panda's hand: intrinsics, frames, and its depth/colour noise.

Numbers and their sources
-------------------------
Intrinsics
    Colour stream 640×480, fx ≈ fy ≈ 615 px: the colour sensor sees 69.4° × 42.5° in its 16:9
    modes (Intel D400 datasheet, doc. 337029): at 1280×720 fx = 640 / tan 34.7° ≈ 923 px and
    fy = 360 / tan 21.25° ≈ 923 px; a 4:3 stream keeps the 42.5° vertical field,
    fy = 240 / tan 21.25° ≈ 615 px, and is 55° wide. A typical factory calibration, principal
    point a few pixels off centre.
    realsense-ros publishes ``plumb_bob`` with zero coefficients for the D435i colour stream.
Depth RMS error
    σ_z = z² · s / (f · B) (Grunnet-Jepsen et al., "Tuning depth cameras for best performance",
    Intel RealSense D400 white paper, 2019), subpixel s = 0.08 (the paper's "typical" value),
    baseline B = 50 mm (D435/D435i), depth focal length f = 447 px (87° horizontal field of
    view at 848 px: 424 / tan 43.5°). At 0.3 m σ_z = 0.32 mm; at 0.6 m 1.29 mm.
Valid range
    Invalid below min-Z 0.17 m and beyond 3 m (issue 3; the datasheet's min-Z shrinks with the
    depth resolution, and 0.3–3 m is its "ideal range"). Stored as 16UC1 millimetres, so values
    are quantised to 1 mm (±0.29 mm RMS) on top of σ_z.
Grazing incidence
    Stereo matching fails where the surface is seen almost edge-on (the projected pattern and
    texture foreshorten to nothing). A hole chance rises linearly from 0 at 70° to 1 at 85°
    incidence (assumed; the white paper shows fill rate collapsing past ~75°).
Random drop-out
    0.3 % of pixels (assumed; isolated holes that the D4xx hole filter would otherwise fill).
Flying pixels
    At a depth discontinuity (neighbour ≥ 20 mm + 5 % of z farther) a pixel takes, with chance
    0.5, a depth between foreground and background ("edge artefacts", same white paper).
Colour noise
    Gaussian, σ = 2 DN per channel at 8 bits (assumed: read and shot noise of a small CMOS
    sensor under workshop light); ``yard`` 3 DN.
Hand-eye error (``yard``)
    2 mm and 0.3°, random directions (issue 3; a typical residual of a hand-eye calibration).
    /tf_static publishes the nominal transform while the image is rendered from the perturbed
    one, as on a real robot with an imperfect calibration.
Clock offset and frames while moving (``yard``)
    A D435i streams all the time; a recording holds the frames taken while the arm moves
    between views too (``motion_frames_hz``; ``yard`` 6 Hz, the D435i's slowest colour rate,
    to keep recordings small). Its header stamps come from the camera's clock, not the robot's:
    ``yard`` stamps images 10–20 ms off the capture time (issue 13: 5–30 ms on real cells),
    early or late at random. That only matters while the arm moves.
Lighting variation (``yard``)
    Per view: gain 0.75–1.15, a warm/cool tint of ±4 % on red and blue, and a linear brightness
    ramp of ±15 % across the image (sun, clouds and shadows of an outdoor yard; assumed).
Glare holes (glints)
    Where a mirror-like spot reflects the light into the lens (specular highlight above 0.5),
    it mirrors the projected IR pattern away too: depth is missing there with chance 0.7
    (assumed; the D400 white paper lists specular surfaces among the causes of holes).
Scene (``yard``; ``sim.scene``)
    Presets also say what lies in the scene besides the piece: the can's colour varies around
    the paint preset (all but ``ideal``); ``yard`` adds an old faded mark near the line,
    distractors of paint-like colour on the floor (a crate, a traffic cone, a glove) and glints
    on the steel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from scrapcut_cli.errors import SimError
from scrapcut_cli.geometry import make_transform
from scrapcut_cli.recording.frame import CameraModel

FloatArray = NDArray[np.float64]

#: TF frame names (realsense-ros 4.x and franka_description).
BASE_FRAME = "panda_link0"
FLANGE_FRAME = "panda_link8"
HAND_FRAME = "panda_hand"
CAMERA_LINK = "camera_link"
OPTICAL_FRAME = "camera_color_optical_frame"


def d435i_color_camera(width: int = 640, height: int = 480) -> CameraModel:
    """The D435i colour camera (depth is aligned to it) at ``width`` × ``height`` pixels.

    16:9 modes (1280×720, realsense-ros 4.x's default, 848×480, 640×360...) see 69.4° × 42.5°
    with square pixels (fx ≈ fy ≈ 923 px at 1280×720); 4:3 modes keep the vertical field and
    crop the sides (615 px at 640×480). Other aspect ratios stretch the 4:3 calibration.
    """
    if width <= 0 or height <= 0:
        raise SimError(f"camera resolution must be positive, got {width}x{height}")
    wide = CameraModel(
        width=1280,
        height=720,
        fx=923.4,
        fy=922.9,
        cx=643.1,
        cy=357.6,
        distortion_model="plumb_bob",
        distortion=(0.0, 0.0, 0.0, 0.0, 0.0),
        frame_id=OPTICAL_FRAME,
    )
    base = CameraModel(
        width=640,
        height=480,
        fx=615.3,
        fy=615.1,
        cx=321.7,
        cy=238.4,
        distortion_model="plumb_bob",
        distortion=(0.0, 0.0, 0.0, 0.0, 0.0),
        frame_id=OPTICAL_FRAME,
    )
    if width * 9 == height * 16:
        return wide if (width, height) == (1280, 720) else wide.scaled(width, height)
    return base if (width, height) == (640, 480) else base.scaled(width, height)


#: panda_hand -> camera_link: the camera on the side of the hand, 65 mm off its axis and 40 mm
#: towards the fingers, looking along the hand's approach axis (camera_link x = hand z).
T_HAND_CAMLINK = make_transform(
    np.column_stack([(0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (-1.0, 0.0, 0.0)]), (0.065, 0.0, 0.040)
)

#: camera_link -> camera_color_optical_frame: the colour imager 15 mm to the left of the depth
#: origin (D435 datasheet), optical axes z forward, x right, y down (REP-103).
T_CAMLINK_OPTICAL = make_transform(
    np.column_stack([(0.0, -1.0, 0.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0)]), (0.0, 0.015, 0.0)
)

#: The D435i housing (90 × 25 × 25 mm) as a box in camera_link: centre and half extents.
HOUSING_CENTRE_CAMLINK = (-0.0125, -0.0175, 0.0)
HOUSING_HALF_EXTENTS = (0.0125, 0.045, 0.0125)


@dataclass(frozen=True)
class NoisePreset:
    """Depth and colour imperfections of one preset (see the module docstring for sources)."""

    name: str
    subpixel: float = 0.08
    baseline_m: float = 0.050
    depth_focal_px: float = 447.0
    min_z_m: float = 0.17
    max_z_m: float = 3.0
    grazing_start_deg: float = 70.0
    grazing_end_deg: float = 85.0
    dropout: float = 0.003
    flying_jump_m: float = 0.020
    flying_jump_rel: float = 0.05
    flying_chance: float = 0.5
    color_sigma_dn: float = 2.0
    hand_eye_translation_m: float = 0.0
    hand_eye_rotation_deg: float = 0.0
    stamp_offset_ms: tuple[float, float] = (0.0, 0.0)  # |offset| drawn in this range, either sign
    motion_frames_hz: float = 0.0  # images per second recorded while the arm moves
    lighting_variation: bool = False
    overspray: str = "light"
    glare_hole_level: float = 0.5
    glare_hole_chance: float = 0.7
    # What lies in the scene (sim.scene): the can's colour spread, old marks, distractors,
    # glints. SimConfig's fields of the same names override these when given.
    paint_variation: bool = True
    faded_marks: int = 0
    distractors: tuple[str, ...] = ()
    glints: bool = False

    def depth_sigma_m(self, z_m: ArrayLike) -> FloatArray:
        """RMS depth error (same shape as ``z_m``) in metres: z²·s/(f·B)."""
        z = np.asarray(z_m, dtype=np.float64)
        return np.asarray(z * z * self.subpixel / (self.depth_focal_px * self.baseline_m))


NOISE_PRESETS: dict[str, NoisePreset] = {
    "ideal": NoisePreset(
        "ideal",
        subpixel=0.0,
        min_z_m=0.0,
        max_z_m=np.inf,
        grazing_start_deg=90.0,
        grazing_end_deg=90.0,
        dropout=0.0,
        flying_chance=0.0,
        color_sigma_dn=0.0,
        overspray="none",
        glare_hole_chance=0.0,
        paint_variation=False,
    ),
    "d435i": NoisePreset("d435i"),
    "yard": NoisePreset(
        "yard",
        color_sigma_dn=3.0,
        hand_eye_translation_m=0.002,
        hand_eye_rotation_deg=0.3,
        stamp_offset_ms=(10.0, 20.0),
        motion_frames_hz=6.0,
        lighting_variation=True,
        overspray="heavy",
        faded_marks=1,
        distractors=("box", "cone", "glove"),
        glints=True,
    ),
}


def noise_preset(name: str) -> NoisePreset:
    """The preset called ``name`` (ideal, d435i, yard)."""
    preset = NOISE_PRESETS.get(name)
    if preset is None:
        raise SimError(f"unknown noise preset {name!r}; presets: {', '.join(NOISE_PRESETS)}")
    return preset


def perturb_hand_eye(
    T_hand_camlink: ArrayLike,
    preset: NoisePreset,
    rng: np.random.Generator,
    *,
    translation_m: float | None = None,
    rotation_deg: float | None = None,
) -> FloatArray:
    """The true hand-eye transform: the nominal one moved by a calibration error.

    A translation of exactly ``translation_m`` and a rotation of exactly ``rotation_deg``
    (default: the preset's ``hand_eye_translation_m`` / ``hand_eye_rotation_deg``), each about
    a random direction, applied in the camera_link frame.
    """
    T = np.asarray(T_hand_camlink, dtype=np.float64)
    if translation_m is None:
        translation_m = preset.hand_eye_translation_m
    if rotation_deg is None:
        rotation_deg = preset.hand_eye_rotation_deg
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    delta = make_transform(
        Rotation.from_rotvec(np.radians(rotation_deg) * axis).as_matrix(),
        translation_m * direction,
    )
    return np.asarray(T @ delta)


def draw_stamp_offset(preset: NoisePreset, rng: np.random.Generator) -> float:
    """Seconds the camera's header stamps lie after the capture time (negative: before)."""
    low, high = preset.stamp_offset_ms
    if high <= 0.0:
        return 0.0
    magnitude = rng.uniform(low, high) / 1000.0
    return float(magnitude if rng.random() < 0.5 else -magnitude)


# --------------------------------------------------------------------------- depth


def simulate_depth(
    depth_m: ArrayLike,
    cos_incidence: ArrayLike,
    preset: NoisePreset,
    rng: np.random.Generator,
    *,
    glare: ArrayLike | None = None,
) -> NDArray[np.float32]:
    """A D435i-like depth image (H, W) float32 metres, NaN where invalid, before quantisation.

    Parameters
    ----------
    depth_m : (H, W) float
        Exact z depth along the optical axis in metres; inf or NaN where the ray hit nothing.
    cos_incidence : (H, W) float
        Cosine of the angle between the viewing ray and the surface normal (1 = head on).
    preset : NoisePreset
        Which imperfections to apply.
    rng : numpy.random.Generator
        Source of all random draws (the same generator state gives the same image).
    glare : (H, W) float, optional
        Specular highlight per pixel (``RenderedView.glare``): holes where it is strong.
    """
    z = np.array(depth_m, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError(f"depth must be (H, W), got shape {z.shape}")
    cos = np.asarray(cos_incidence, dtype=np.float64)
    finite = np.isfinite(z)
    # Flying pixels from the exact depth: mix towards the farther neighbour across a jump.
    flying_target = _farther_neighbour(z, preset.flying_jump_m, preset.flying_jump_rel)
    draws = rng.random((3, *z.shape), dtype=np.float32)
    normal = rng.standard_normal(z.shape, dtype=np.float32)
    out = z.copy()
    has_jump = np.isfinite(flying_target) & finite
    fly = has_jump & (draws[0] < preset.flying_chance)
    out[fly] = z[fly] + draws[1][fly] * (flying_target[fly] - z[fly])
    if preset.subpixel > 0:
        out = out + np.where(finite, preset.depth_sigma_m(np.where(finite, z, 0.0)), 0.0) * normal
    invalid = ~finite | (out < preset.min_z_m) | (out > preset.max_z_m)
    if preset.grazing_end_deg < 90.0:
        angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        span = max(preset.grazing_end_deg - preset.grazing_start_deg, 1e-9)
        hole_chance = np.clip((angle - preset.grazing_start_deg) / span, 0.0, 1.0)
        invalid |= draws[2] < hole_chance
    if preset.dropout > 0:
        invalid |= rng.random(z.shape, dtype=np.float32) < preset.dropout
    if glare is not None and preset.glare_hole_chance > 0:
        glaring = np.flatnonzero(np.asarray(glare).reshape(-1) > preset.glare_hole_level)
        if glaring.size:  # no draw without glare: recordings without glints keep their bytes
            holes = glaring[rng.random(glaring.size) < preset.glare_hole_chance]
            invalid.reshape(-1)[holes] = True
    out[invalid] = np.nan
    return out.astype(np.float32)


def _farther_neighbour(z: FloatArray, jump_m: float, jump_rel: float) -> FloatArray:
    """Depth (H, W) of the farthest 4-neighbour across a jump, NaN where there is none."""
    best = np.full(z.shape, np.nan)
    best_gap = np.zeros(z.shape)
    padded = np.pad(z, 1, constant_values=np.nan)
    h, w = z.shape
    for dv, du in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        nb = padded[1 + dv : 1 + dv + h, 1 + du : 1 + du + w]
        with np.errstate(invalid="ignore"):
            gap = nb - z
            jump = np.isfinite(gap) & (gap > jump_m + jump_rel * np.where(np.isfinite(z), z, 0.0))
            better = jump & (gap > best_gap)
        best = np.where(better, nb, best)
        best_gap = np.where(better, gap, best_gap)
    return best


def depth_to_millimetres(depth_m: ArrayLike) -> NDArray[np.uint16]:
    """16UC1 millimetres (H, W) from metres: rounded, 0 where invalid or out of range."""
    z = np.asarray(depth_m, dtype=np.float64)
    mm = np.where(np.isfinite(z), np.rint(z * 1000.0), 0.0)
    mm = np.where((mm > 0) & (mm <= 65535), mm, 0.0)
    return mm.astype(np.uint16)


# --------------------------------------------------------------------------- colour


@dataclass(frozen=True)
class Lighting:
    """Per-view light: colour gain (3,) and a linear ramp across the image (gx, gy per width)."""

    gain: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ramp: tuple[float, float] = (0.0, 0.0)

    def field(self, width: int, height: int) -> FloatArray:
        """(H, W, 3) multiplicative light field."""
        u = (np.arange(width) - 0.5 * (width - 1)) / width
        v = (np.arange(height) - 0.5 * (height - 1)) / width
        ramp = 1.0 + 2.0 * (self.ramp[0] * u[None, :] + self.ramp[1] * v[:, None])
        return np.asarray(ramp[:, :, None] * np.asarray(self.gain)[None, None, :])


def draw_lighting(preset: NoisePreset, rng: np.random.Generator) -> Lighting:
    """The lighting of one view: constant for presets without variation."""
    if not preset.lighting_variation:
        return Lighting()
    level = rng.uniform(0.75, 1.15)
    tint = rng.uniform(-0.04, 0.04)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    strength = rng.uniform(0.0, 0.15)
    return Lighting(
        gain=(level * (1.0 + tint), level, level * (1.0 - tint)),
        ramp=(strength * np.cos(angle), strength * np.sin(angle)),
    )


def simulate_color(
    rgb: ArrayLike, preset: NoisePreset, rng: np.random.Generator
) -> NDArray[np.uint8]:
    """(H, W, 3) uint8 from linear-in-bytes colour (H, W, 3) in 0–1 plus the preset's noise."""
    c = np.asarray(rgb, dtype=np.float32) * np.float32(255.0)
    if preset.color_sigma_dn > 0:
        c += np.float32(preset.color_sigma_dn) * rng.standard_normal(c.shape, dtype=np.float32)
    np.rint(c, out=c)
    np.clip(c, 0, 255, out=c)
    return c.astype(np.uint8)
