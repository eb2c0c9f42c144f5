"""A synthetic tabletop camera: one object, a hand that acts on it, frames a segmenter can read.

The object segmenter is tested and its clusters learned on frames whose truth is known, and
`beyond simulate` needs camera frames that agree with the effects the network was trained on:
the renderer animates object and hand with `cognition.world.simulate_effects`' speeds and
contact, so measuring the frames gives back the world's labels. A fixed pinhole camera 1 m above
the table looks straight down (320 px/m at the table for the default 320×240 view of a 1 m wide
table); objects are shaded spheres or rotated boxes of the network's colours and sizes, the hand
a skin-coloured ellipse that taps, grasps or touches. README.md in this folder gives the geometry.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import cast

import numpy as np

# scipy is imported in the functions that use it: a process that only needs this module's types
# (`beyond up` checking the object segmenter's options) then does not load it (1.3 s of CPU)
from beyond_self.cognition.variables import ACTIONS, AFFORDANCE_VARIABLES
from beyond_self.cognition.world import Effects, simulate_effects
from beyond_self.core.errors import InputError, unknown

# Base colours (sRGB) of the four colour clusters; both greens are greenish but far apart in CIELAB
# (green1 ≈ L*64 a*-40 b*+57, yellowish; green2 ≈ L*52 a*-42 b*+18, bluish).
COLOR_RGB: dict[str, tuple[int, int, int]] = {
    "green1": (112, 172, 40),
    "green2": (30, 138, 92),
    "yellow": (232, 200, 32),
    "blue": (42, 82, 192),
}
SKIN_RGB = (222, 168, 138)
TABLE_RGB = (176, 178, 182)
# Equivalent diameter (m) of each size: a sphere's diameter; a box has the same footprint area.
SIZE_DIAMETER_M: dict[str, float] = {"small": 0.045, "medium": 0.065, "big": 0.09}
HAND_SEMI_AXES_M = (0.045, 0.035)  # along / across the approach direction
HAND_HEIGHT_M = 0.05  # palm centre above the table while it acts
_LIGHT = np.array([-0.35, 0.45, 1.0]) / np.linalg.norm([-0.35, 0.45, 1.0])  # towards the light
_CONTACT_OVERLAP_M = 0.004  # hand silhouette overlaps the object's by ~1 px so they touch
_POST_S = 0.55  # recorded after contact ends
_PUSH_S = 0.3  # after contact the pushed object keeps its speed this long, then brakes
_BRAKE_S = 0.2
_APPROACH_FRACTION = 0.87  # where the reach meets the object, as a fraction of its aim
_PRE_FRAMES = 4  # still frames before the hand moves (what the object features are read from)
# A grasped object is carried mostly towards the far side and a little up: lifting it much
# towards the camera would, by perspective, pull it apart from the hand in the image.
LIFT_DIRECTION = np.array([0.0, 0.97, 0.24]) / np.linalg.norm([0.0, 0.97, 0.24])
_GRASP_OVERLAP_M = 0.01  # the fingers wrap over the grasped object's edge (~3 px)


@dataclass(frozen=True)
class Camera:
    """The fixed overhead pinhole camera (see the module docstring for the projection)."""

    width: int = 320
    height: int = 240
    elevation_m: float = 1.0
    view_width_m: float = 1.0

    def __post_init__(self) -> None:
        if self.width < 32 or self.height < 24:
            raise InputError(f"camera size {self.width}x{self.height} too small; valid: ≥ 32x24")
        if not 0.05 < self.elevation_m < 100 or not 0.01 < self.view_width_m < 100:
            raise InputError("camera elevation and view width must be positive distances in metres")

    @property
    def cx(self) -> float:
        """Principal point; pixel (row i, column j) is centred on (u, v) = (j, i)."""
        return (self.width - 1) / 2.0

    @property
    def cy(self) -> float:
        return (self.height - 1) / 2.0

    @property
    def focal_px(self) -> float:
        return self.width * self.elevation_m / self.view_width_m

    def px_per_m(self, z: float = 0.0) -> float:
        """Image scale of something at height z above the table."""
        return self.focal_px / (self.elevation_m - z)

    def project(self, xyz: np.ndarray) -> np.ndarray:
        """Table-frame points (..., 3) in metres -> pixel coordinates (..., 2) as (u, v)."""
        p = np.asarray(xyz, dtype=np.float64)
        s = self.focal_px / (self.elevation_m - p[..., 2])
        return np.stack([self.cx + s * p[..., 0], self.cy - s * p[..., 1]], axis=-1)

    def table_point(self, uv: np.ndarray, z: float | np.ndarray = 0.0) -> np.ndarray:
        """Pixel coordinates (..., 2) -> table-frame (x, y) at height z (a number, or one per
        point), the inverse of `project`."""
        q = np.asarray(uv, dtype=np.float64)
        s = self.focal_px / (self.elevation_m - np.asarray(z, dtype=np.float64))
        return np.stack([(q[..., 0] - self.cx) / s, (self.cy - q[..., 1]) / s], axis=-1)


def kinect_to_table(track: np.ndarray) -> np.ndarray:
    """A hand track in the depth sensor's frame (x right, y up, z away from the sensor; metres) ->
    table-frame axes. The sensor stands on the robot's side of the table looking at the human
    opposite, so its z (away) is the table's y (towards the far side) and its y (up) the table's z.
    Only axes are changed; the caller places the track (see `simulate_experiment`)."""
    t = np.asarray(track, dtype=np.float64)
    return np.stack([t[..., 0], t[..., 2], t[..., 1]], axis=-1)


@dataclass(frozen=True)
class ObjectSpec:
    """One object as rendered: its labels and the physical parameters drawn for it."""

    color: str
    shape: str
    size: str
    rgb: tuple[float, float, float]
    diameter_m: float  # equivalent diameter of the footprint
    aspect: float = 1.0  # box: long side / short side
    angle: float = 0.0  # box: rotation in the image (radians)

    @property
    def sides_m(self) -> tuple[float, float]:
        """Box footprint (long, short) with the same area as a disc of `diameter_m`."""
        area = np.pi * self.diameter_m**2 / 4.0
        short = float(np.sqrt(area / self.aspect))
        return short * self.aspect, short

    @property
    def height_m(self) -> float:
        return self.diameter_m if self.shape == "circle" else 0.6 * float(np.mean(self.sides_m))

    def reach_m(self, direction: np.ndarray) -> float:
        """Distance from the footprint centre to its outline along a unit table direction."""
        if self.shape == "circle":
            return self.diameter_m / 2.0
        a, b = self.sides_m
        c, s = np.cos(self.angle), np.sin(self.angle)
        # box axes in table coordinates (image v points against table y, so the angle flips)
        e1, e2 = np.array([c, -s]), np.array([s, c])
        return float(abs(direction @ e1) * a / 2.0 + abs(direction @ e2) * b / 2.0)


def random_object(
    color: str, shape: str, size: str, rng: np.random.Generator, jitter: bool = True
) -> ObjectSpec:
    """An object of the given labels with per-object variation of colour, size, aspect, angle."""
    _check("Color", color)
    _check("Shape", shape)
    _check("Size", size)
    base = np.asarray(COLOR_RGB[color], dtype=np.float64)
    if jitter:
        rgb = base * rng.uniform(0.93, 1.07) + rng.normal(0.0, 4.0, 3)
        diameter = SIZE_DIAMETER_M[size] * rng.uniform(0.94, 1.06)
    else:
        rgb, diameter = base, SIZE_DIAMETER_M[size]
    aspect = float(rng.uniform(1.0, 1.35)) if shape == "box" and jitter else 1.0
    angle = float(rng.uniform(-np.pi / 4, np.pi / 4)) if shape == "box" and jitter else 0.0
    rgb_t = tuple(float(x) for x in np.clip(rgb, 0.0, 255.0))
    return ObjectSpec(color, shape, size, (rgb_t[0], rgb_t[1], rgb_t[2]), diameter, aspect, angle)


def _check(variable: str, value: str) -> None:
    if value not in AFFORDANCE_VARIABLES[variable]:
        raise unknown(f"{variable} value", value, AFFORDANCE_VARIABLES[variable])


# ---------------------------------------------------------------- drawing


def make_table(camera: Camera, rng: np.random.Generator, gain: float = 1.0) -> np.ndarray:
    """The empty table as float32 (H, W, 3) sRGB: base colour, illumination fall-off towards the
    corners, faint smooth stains and a fixed fine texture."""
    from scipy import ndimage

    h, w = camera.height, camera.width
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((xx - w / 2) / (w / 2)) ** 2 + ((yy - h / 2) / (h / 2)) ** 2
    light = gain * (1.0 - 0.12 * r2 + 0.05 * (xx / w - 0.5))
    small = rng.normal(0.0, 1.0, (max(h // 16, 2), max(w // 16, 2))).astype(np.float32)
    stains = ndimage.zoom(
        ndimage.gaussian_filter(small, 1.0), (h / small.shape[0], w / small.shape[1]), order=1
    )
    stains = stains[:h, :w]
    light = light * (1.0 + 0.025 * stains / max(float(np.abs(stains).max()), 1e-6))
    table = np.asarray(TABLE_RGB, dtype=np.float32) * light[:, :, None]
    table += rng.normal(0.0, 2.0, table.shape).astype(np.float32)
    return cast(np.ndarray, table)


def _patch(
    shape: tuple[int, int], center: np.ndarray, radius: float
) -> tuple[tuple[slice, slice], np.ndarray, np.ndarray] | None:
    h, w = shape
    x0, x1 = int(np.floor(center[0] - radius)), int(np.ceil(center[0] + radius)) + 1
    y0, y1 = int(np.floor(center[1] - radius)), int(np.ceil(center[1] + radius)) + 1
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    if x0 >= x1 or y0 >= y1:
        return None
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    # pixel (i, j) is centred on the integer coordinates (x = j, y = i), as in the segmenter
    return (slice(y0, y1), slice(x0, x1)), xx, yy


def _coverage(distance: np.ndarray, softness: float = 1.0) -> np.ndarray:
    """Anti-aliased coverage from a signed distance in pixels (negative inside)."""
    return np.clip(0.5 - distance / softness, 0.0, 1.0)


def _ellipse_distance(
    xx: np.ndarray, yy: np.ndarray, c: np.ndarray, a: float, b: float, angle: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Approximate signed distance (px) to an ellipse, and the local coordinates normalised by the
    semi-axes (used for shading)."""
    ca, sa = np.cos(angle), np.sin(angle)
    dx, dy = xx - c[0], yy - c[1]
    lx = (dx * ca + dy * sa) / a
    ly = (-dx * sa + dy * ca) / b
    rho = np.sqrt(lx * lx + ly * ly)
    return (rho - 1.0) * min(a, b), lx, ly


def _box_distance(
    xx: np.ndarray, yy: np.ndarray, c: np.ndarray, a: float, b: float, angle: float
) -> np.ndarray:
    ca, sa = np.cos(angle), np.sin(angle)
    dx, dy = xx - c[0], yy - c[1]
    qx = np.abs(dx * ca + dy * sa) - a / 2.0
    qy = np.abs(-dx * sa + dy * ca) - b / 2.0
    outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
    return cast(np.ndarray, outside + np.minimum(np.maximum(qx, qy), 0.0))


def _shadow_offset(height_m: float) -> np.ndarray:
    """Where the shadow of something `height_m` above the table falls (table metres)."""
    return cast(np.ndarray, -_LIGHT[:2] / _LIGHT[2] * height_m)


def _draw_shadow(
    img: np.ndarray,
    camera: Camera,
    center_xy: np.ndarray,
    height_m: float,
    semi_axes_m: tuple[float, float],
    angle: float,
    box: bool,
    strength: float = 0.33,
) -> None:
    ground = np.array([*(center_xy + _shadow_offset(height_m)), 0.0])
    c = camera.project(ground)
    s = camera.px_per_m(0.0)
    a, b = semi_axes_m[0] * s, semi_axes_m[1] * s
    soft = 1.5 + 0.05 * height_m * s
    patch = _patch(img.shape[:2], c, max(a, b) + 3 * soft)
    if patch is None:
        return
    sl, xx, yy = patch
    if box:
        d = _box_distance(xx, yy, c, 2 * a, 2 * b, angle)
    else:
        d = _ellipse_distance(xx, yy, c, a, b, angle)[0]
    img[sl] *= (1.0 - strength * _coverage(d, 2.0 * soft))[:, :, None]


def _draw_object(
    img: np.ndarray, camera: Camera, obj: ObjectSpec, xyz: np.ndarray, shadow: bool
) -> None:
    """Draw the object whose footprint centre is at xyz (z = lift above the table)."""
    top = xyz[2] + obj.height_m / 2.0 if obj.shape == "circle" else xyz[2] + obj.height_m
    if shadow:
        half = (
            (obj.diameter_m / 2.0, obj.diameter_m / 2.0)
            if obj.shape == "circle"
            else (obj.sides_m[0] / 2.0, obj.sides_m[1] / 2.0)
        )
        _draw_shadow(img, camera, xyz[:2], top * 0.6 + xyz[2], half, obj.angle, obj.shape == "box")
    c = camera.project(np.array([xyz[0], xyz[1], top]))
    s = camera.px_per_m(top)
    rgb = np.asarray(obj.rgb, dtype=np.float32)
    if obj.shape == "circle":
        r = obj.diameter_m / 2.0 * s
        patch = _patch(img.shape[:2], c, r + 2)
        if patch is None:
            return
        sl, xx, yy = patch
        d, lx, ly = _ellipse_distance(xx, yy, c, r, r, 0.0)
        nz = np.sqrt(np.clip(1.0 - lx * lx - ly * ly, 0.0, 1.0))
        # image v points against table y
        lambert = np.clip(lx * _LIGHT[0] - ly * _LIGHT[1] + nz * _LIGHT[2], 0.0, 1.0)
        shade = 0.55 + 0.5 * lambert
        spec = 40.0 * np.clip(lambert, 0.0, 1.0) ** 30
        color = rgb[None, None, :] * shade[:, :, None] + spec[:, :, None]
    else:
        a, b = (side * s for side in obj.sides_m)
        patch = _patch(img.shape[:2], c, 0.5 * float(np.hypot(a, b)) + 2)
        if patch is None:
            return
        sl, xx, yy = patch
        d = _box_distance(xx, yy, c, a, b, obj.angle)
        bevel = np.clip(-d / 2.5, 0.0, 1.0)  # edges a little darker
        shade = 0.82 + 0.16 * bevel + 0.04 * (xx - c[0]) / max(a, b)
        color = rgb[None, None, :] * shade[:, :, None]
    cov = _coverage(d)[:, :, None]
    img[sl] = img[sl] * (1.0 - cov) + color * cov


def _draw_hand(
    img: np.ndarray, camera: Camera, xyz: np.ndarray, direction: np.ndarray, rgb: np.ndarray
) -> None:
    ang = float(np.arctan2(-direction[1], direction[0]))  # image angle of the approach direction
    _draw_shadow(img, camera, xyz[:2], xyz[2], HAND_SEMI_AXES_M, ang, False, strength=0.25)
    c = camera.project(xyz)
    s = camera.px_per_m(xyz[2])
    a, b = HAND_SEMI_AXES_M[0] * s, HAND_SEMI_AXES_M[1] * s
    patch = _patch(img.shape[:2], c, a + 2)
    if patch is None:
        return
    sl, xx, yy = patch
    d, lx, ly = _ellipse_distance(xx, yy, c, a, b, ang)
    shade = 0.8 + 0.2 * np.sqrt(np.clip(1.0 - lx * lx - ly * ly, 0.0, 1.0))
    cov = _coverage(d)[:, :, None]
    img[sl] = img[sl] * (1.0 - cov) + rgb[None, None, :] * shade[:, :, None] * cov


def render_frame(
    camera: Camera,
    table: np.ndarray,
    objects: list[tuple[ObjectSpec, np.ndarray]],
    rng: np.random.Generator,
    hand: tuple[np.ndarray, np.ndarray] | None = None,
    hand_rgb: np.ndarray | None = None,
    noise: float = 2.0,
) -> np.ndarray:
    """One uint8 RGB frame: the table, each (object, footprint centre xyz), the hand as
    (palm centre xyz, approach direction in the table plane), shadows and sensor noise."""
    img = table.copy()
    for obj, xyz in objects:
        _draw_object(img, camera, obj, np.asarray(xyz, dtype=np.float64), shadow=True)
    if hand is not None:
        skin = np.asarray(SKIN_RGB if hand_rgb is None else hand_rgb, dtype=np.float32)
        _draw_hand(img, camera, np.asarray(hand[0], np.float64), np.asarray(hand[1]), skin)
    if noise > 0:
        img += rng.standard_normal(img.shape, dtype=np.float32) * np.float32(noise)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def render_still(
    objects: list[tuple[ObjectSpec, np.ndarray]],
    rng: np.random.Generator,
    camera: Camera | None = None,
) -> np.ndarray:
    """A frame of the table with the given objects at table positions (x, y) or (x, y, z)."""
    cam = camera or Camera()
    table = make_table(cam, rng, gain=float(rng.uniform(0.95, 1.05)))
    placed = []
    for obj, position in objects:
        xyz = np.zeros(3)
        given = np.asarray(position, dtype=np.float64).ravel()[:3]
        xyz[: given.size] = given
        placed.append((obj, xyz))
    return render_frame(cam, table, placed, rng)


# ---------------------------------------------------------------- experiments


@dataclass
class Experiment:
    """One simulated action on one object: the frames and everything true about them."""

    action: str
    obj: ObjectSpec
    effects: Effects
    fps: float
    camera: Camera
    frames: np.ndarray  # (N, H, W, 3) uint8
    hand_px: np.ndarray  # (N, 2) projected palm centre (what a skeleton stream would give)
    hand_xyz: np.ndarray  # (N, 3) palm centre, table frame, metres
    object_px: np.ndarray  # (N, 2) projected object centre
    object_xyz: np.ndarray  # (N, 3) object footprint centre, table frame, metres
    contact: tuple[int, int]  # frames [start, end) in contact
    hand_track: np.ndarray | None = None  # the given sensor-frame track, if any
    labels: dict[str, str] = field(default_factory=dict)  # Color, Shape, Size and the effects

    @property
    def features_frame(self) -> int:
        """A frame with the hand far from the object (object features are read here)."""
        return 0


def min_jerk(tau: np.ndarray) -> np.ndarray:
    """The minimum-jerk profile: how far along (0 to 1) a reach is at time fraction `tau` (clipped
    to 0..1), starting and ending at rest (Flash and Hogan, 1985)."""
    t = np.clip(tau, 0.0, 1.0)
    return cast(np.ndarray, 10 * t**3 - 15 * t**4 + 6 * t**5)


def _trajectories(
    action: str,
    obj: ObjectSpec,
    eff: Effects,
    fps: float,
    start_xy: np.ndarray,
    u: np.ndarray,
    approach: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Per-frame object footprint centre and palm centre (table frame) and the contact frames."""
    dt = 1.0 / fps
    u3 = np.array([u[0], u[1], 0.0])
    obj0 = np.array([start_xy[0], start_xy[1], 0.0])
    overlap = _GRASP_OVERLAP_M if action == "grasp" else _CONTACT_OVERLAP_M
    contact_palm = obj0 - u3 * (obj.reach_m(u) + HAND_SEMI_AXES_M[0] - overlap)
    contact_palm[2] = HAND_HEIGHT_M
    if approach is None:
        # A minimum-jerk reach aimed a little beyond the object and cut where it touches it, so
        # the hand arrives moving (about half its peak speed) as a real hand does.
        duration = float(np.clip(0.55 + 0.1 * np.sin(7 * eff.hand_speed), 0.4, 0.7))
        aim = eff.hand_speed * duration / 1.875  # min-jerk peak speed = 1.875 * D / T
        dist = aim * _APPROACH_FRACTION
        start = contact_palm - u3 * dist
        start[2] = HAND_HEIGHT_M
        n_full = max(round(duration * fps), 4)
        s = min_jerk(np.arange(1, n_full + 1) / n_full) * aim
        s = s[s < dist]
        hand_app = np.vstack([start + u3 * s[:, None], contact_palm[None]])
        hand_pre = np.repeat(start[None], _PRE_FRAMES, axis=0)
    else:
        hand_app = approach - approach[-1] + contact_palm
        hand_pre = np.repeat(hand_app[:1], _PRE_FRAMES, axis=0)
    n_contact = max(round(eff.contact_s * fps), 1)
    n_post = round(_POST_S * fps)
    hands = [*hand_pre, *hand_app]
    objs = [obj0.copy() for _ in hands]
    c0 = len(hands)
    hand, pos = contact_palm.copy(), obj0.copy()
    perp = np.array([-u[1], u[0], 0.0])
    period = n_contact * dt / 2.0
    amp = eff.relative_speed * period / (2 * np.pi)
    carry = np.zeros(3)
    for k in range(1, n_contact + 1):
        t = k * dt
        if action == "grasp":
            carry = carry + LIFT_DIRECTION * eff.object_speed * dt
            hand = contact_palm + carry
            pos = obj0 + carry + perp * amp * np.sin(2 * np.pi * t / period)
        else:
            pos = pos + u3 * eff.object_speed * dt
            hand = hand + u3 * eff.object_speed * dt
        hands.append(hand.copy())
        objs.append(pos.copy())
    c1 = len(hands)
    # the last contact frame is where the grasped object is put down: keep its lift
    for k in range(1, n_post + 1):
        t = k * dt
        if action == "grasp":
            hand = hand - u3 * eff.relative_speed * dt
        else:
            if t <= _PUSH_S:
                v_obj = eff.object_speed
                hand = hand + u3 * (eff.object_speed - eff.relative_speed) * dt
            else:
                v_obj = eff.object_speed * max(0.0, 1.0 - (t - _PUSH_S) / _BRAKE_S)
            pos = pos + u3 * v_obj * dt
        hands.append(hand.copy())
        objs.append(pos.copy())
    return np.asarray(objs), np.asarray(hands), (c0, c1)


def simulate_experiment(
    action: str,
    color: str,
    shape: str,
    size: str,
    rng: np.random.Generator,
    fps: float = 30.0,
    hand_track: np.ndarray | None = None,
    camera: Camera | None = None,
    effects: Effects | None = None,
) -> Experiment:
    """Simulate and render one experiment: `action` by a hand on an object of the given labels.

    Effects are drawn from `cognition.world.simulate_effects` (unless given). `hand_track`: the
    approach as hand positions (T, 3) in the depth sensor's frame (metres, x right, y up, z away
    from the sensor) sampled at `fps`, ending at the moment of contact; it is re-axed with
    `kinect_to_table` and translated so that its last point touches the object. The hand speed
    then is the track's own (its peak speed replaces the drawn one, and the HandVel label follows
    it). Without a track the hand follows a minimum-jerk approach from the far side whose peak
    speed is the drawn hand speed.
    """
    if action not in ACTIONS:
        raise unknown("action", action, ACTIONS)
    if not 5.0 <= fps <= 240.0:
        raise InputError(f"fps {fps} out of range; valid: 5..240")
    cam = camera or Camera()
    obj = random_object(color, shape, size, rng)
    eff = effects or simulate_effects(action, shape, size, rng)
    approach = None
    if hand_track is not None:
        track = np.asarray(hand_track, dtype=np.float64)
        if track.ndim != 2 or track.shape[1] != 3 or len(track) < 2:
            raise InputError(f"hand_track has shape {track.shape}; valid: (T ≥ 2, 3) metres")
        if not np.all(np.isfinite(track)):
            raise InputError("hand_track holds NaN or infinite values; valid: finite metres")
        approach = kinect_to_table(track)
        peak = float(np.max(np.linalg.norm(np.diff(approach, axis=0), axis=1)) * fps)
        eff = dataclasses.replace(eff, hand_speed=peak)
        d = approach[-1, :2] - approach[0, :2]
        u = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-6 else np.array([0.0, -1.0])
    else:
        phi = rng.uniform(-0.6, 0.6)
        u = np.array([np.sin(phi), -np.cos(phi)])  # from the far side towards the robot
    # room for the effect: a grasped object is carried up the image, a tapped one pushed down it
    y_range = (-0.13, -0.06) if action == "grasp" else (0.0, 0.07)
    start_xy = np.array([rng.uniform(-0.1, 0.1), rng.uniform(*y_range)])
    objs, hands, contact = _trajectories(action, obj, eff, fps, start_xy, u, approach)
    gain = float(rng.uniform(0.92, 1.06))
    table = make_table(cam, rng, gain=gain)
    lit = dataclasses.replace(obj, rgb=tuple(float(min(c * gain, 255.0)) for c in obj.rgb))  # type: ignore[arg-type]
    skin = np.asarray(SKIN_RGB, dtype=np.float32) * np.float32(gain * rng.uniform(0.95, 1.05))
    frames = np.stack(
        [
            render_frame(cam, table, [(lit, o)], rng, hand=(h, u), hand_rgb=skin)
            for o, h in zip(objs, hands, strict=True)
        ]
    )
    top = np.array([0.0, 0.0, obj.height_m / 2 if shape == "circle" else obj.height_m])
    labels = {"Color": color, "Shape": shape, "Size": size, **eff.labels()}
    return Experiment(
        action=action,
        obj=obj,
        effects=eff,
        fps=fps,
        camera=cam,
        frames=frames,
        hand_px=cam.project(hands),
        hand_xyz=hands,
        object_px=cam.project(objs + top),
        object_xyz=objs,
        contact=contact,
        hand_track=None if hand_track is None else np.asarray(hand_track, dtype=np.float64),
        labels=labels,
    )


def balanced_conditions(n: int, rng: np.random.Generator) -> list[tuple[str, str, str, str]]:
    """n (action, color, shape, size) tuples cycling through all 72 combinations in shuffled
    rounds, so any prefix of the exploration is close to balanced."""
    combos = [
        (a, c, s, z)
        for a in ACTIONS
        for c in AFFORDANCE_VARIABLES["Color"]
        for s in AFFORDANCE_VARIABLES["Shape"]
        for z in AFFORDANCE_VARIABLES["Size"]
    ]
    out: list[tuple[str, str, str, str]] = []
    while len(out) < n:
        order = rng.permutation(len(combos))
        out.extend(combos[i] for i in order)
    return out[:n]


def exploration(
    n: int, seed: int, camera: Camera | None = None, fps: float = 30.0
) -> Iterator[Experiment]:
    """The robot's preliminary exploration phase: n simulated experiments, balanced over the
    actions and object labels, reproducible from `seed`."""
    rng = np.random.default_rng(seed)
    for action, color, shape, size in balanced_conditions(n, rng):
        yield simulate_experiment(action, color, shape, size, rng, fps=fps, camera=camera)
