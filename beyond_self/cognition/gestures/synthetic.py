"""Seeded synthetic skeleton streams of a seated person doing grasp, tap and touch on a table.

The default data set for training and testing without the article's recordings, and the person in
`beyond simulate`. The frame is the depth sensor's (metres, x right, y up, z away; the person
about 2 m away, acting with the right hand on the +x side, as the article's mirrored logs are).
Each gesture goes from rest to rest with minimum-jerk motion between key poses: grasp from above
with a hold and a lift, tap sideways at table height pushing the object along -x, touch from
above with a brief contact. Speed, amplitude, person size and position, object and rest
positions, sensor jitter and drift and tracking glitches vary.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np
from numpy.typing import NDArray

from beyond_self.cognition.gestures.features import MOTION, features_from_joints, gesture_features
from beyond_self.cognition.variables import ACTIONS
from beyond_self.core.errors import InputError, unknown

FloatArray = NDArray[np.float64]

FPS = 30.0
JOINTS: tuple[str, ...] = (
    "head",
    "neck",
    "torso",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_hand",
    "right_hand",
)


@dataclass(frozen=True)
class GestureBounds:
    """One gesture inside a stream: frames [start, stop) (0-based), and its contact frames."""

    action: str
    start: int
    stop: int
    contact_start: int
    contact_stop: int

    @property
    def n_frames(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True, eq=False)
class SkeletonStream:
    """A synthetic skeleton recording: joints (T, 3) in metres, camera frame (module docstring)."""

    fps: float
    joints: dict[str, FloatArray]
    object_xyz: FloatArray
    gestures: tuple[GestureBounds, ...]
    seed: int | None = None
    info: dict[str, float] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.joints["torso"].shape[0])

    @property
    def action(self) -> str | None:
        """The action of a single-gesture stream (None for a continuous one)."""
        return self.gestures[0].action if len(self.gestures) == 1 else None

    @property
    def hand(self) -> FloatArray:
        return self.joints["right_hand"]

    def features(self) -> FloatArray:
        """The hand relative to the torso in body units, every frame (what the segmenter and
        the features start from: `cognition.gestures.features`)."""
        return features_from_joints(self.joints)

    def gesture_span(self, i: int = 0) -> tuple[int, int]:
        """Frames [start, stop) of gesture i as the default segmenter cuts it (what a robot
        watching the stream would recognise), or its true frames if the segmenter missed it."""
        from beyond_self.cognition.gestures.segmentation import segment_gestures

        g = self.gestures[i]
        found = [(s.start, s.stop) for s in segment_gestures(self.features())]
        overlap = [min(b, g.stop) - max(a, g.start) for a, b in found]
        if overlap and max(overlap) > 0:
            return found[int(np.argmax(overlap))]
        return g.start, g.stop

    def gesture_features(self, i: int = 0, space: str = MOTION) -> FloatArray:
        """Features of gesture i, cut as `gesture_span` (what the models are trained on)."""
        start, stop = self.gesture_span(i)
        return gesture_features(space, self.features(), start, stop)


@dataclass(frozen=True)
class SynthesisConfig:
    """Variability of the generator (ranges are uniform; noise in metres)."""

    fps: float = FPS
    speed: tuple[float, float] = (0.75, 1.3)  # global duration factor
    phase_jitter: float = 0.15  # per-phase duration factor 1 +- this
    amplitude: tuple[float, float] = (0.8, 1.2)  # scale of approach heights, lifts, strokes
    hand_noise: tuple[float, float] = (0.005, 0.02)  # white jitter of the hand in depth (z)
    joint_noise: float = 0.004  # white jitter of the other joints
    drift: float = 0.01  # amplitude of slow tracking drift
    glitch_rate: float = 0.01  # chance per frame that the hand's tracking fails for a moment
    rest: tuple[float, float] = (0.8, 1.4)  # s of rest before and after a single gesture
    rest_between: tuple[float, float] = (1.0, 3.0)  # s of rest between gestures (continuous)
    air_taps: float = 0.35  # share of taps held up in the air, with no table under them
    pushes: float = 0.3  # share of touches that push the object forward (the article's touch)


@dataclass
class _Path:
    """Key poses of the hand and when it passes through them (a hold repeats a pose).

    The hand moves through them along a shape-preserving cubic in time (PCHIP): smooth, never
    overshooting a key pose, at rest only where a person is (a hold, a turning point), so
    several key poses make one fluent movement, as in the recordings of people.
    """

    start: FloatArray
    times: list[float] = field(default_factory=lambda: [0.0])
    poses: list[FloatArray] = field(default_factory=list)
    marks: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.poses.append(np.asarray(self.start, dtype=np.float64))

    def to(self, pose: FloatArray, duration: float) -> None:
        self.times.append(self.times[-1] + max(duration, 1e-3))
        self.poses.append(np.asarray(pose, dtype=np.float64))

    def hold(self, duration: float) -> None:
        self.to(self.poses[-1], duration)

    def mark(self, name: str, offset: float = 0.0) -> None:
        self.marks[name] = self.times[-1] + offset

    def extend(self, other: _Path) -> float:
        """Append another path that starts where this one ends; returns its time offset."""
        t0 = self.duration
        for time, pose in zip(other.times[1:], other.poses[1:], strict=True):
            self.times.append(t0 + time)
            self.poses.append(pose)
        return t0

    @property
    def duration(self) -> float:
        return self.times[-1]

    def sample(self, t: FloatArray) -> FloatArray:
        from scipy.interpolate import PchipInterpolator

        curve = PchipInterpolator(np.asarray(self.times), np.stack(self.poses), axis=0)
        return cast(np.ndarray, curve(np.clip(t, 0.0, self.duration)))


@dataclass(frozen=True)
class _Scene:
    torso: FloatArray
    shoulder_width: float
    neck_height: float
    upper_arm: float
    forearm: float
    rest: FloatArray
    obj: FloatArray
    obj_half: float


def _scene(rng: np.random.Generator) -> _Scene:
    """Where the person, the hand's rest and the object are.

    Measured on the article's recordings (torso-relative): the hand rests beside the hip, about
    0.3 m to the right of the torso joint and level with it in depth; the object lies on a table
    0.35-0.45 m below the torso joint, in front of the body (x near 0) and 0.5-0.6 m forward.
    """
    torso = np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.1, 0.1), rng.uniform(1.8, 2.4)])
    size = rng.uniform(0.94, 1.06)  # person size
    table_drop = rng.uniform(0.37, 0.43) * size
    obj_half = rng.uniform(0.025, 0.045)
    obj = torso + np.array(
        [rng.uniform(-0.05, 0.06), -table_drop + obj_half, -rng.uniform(0.48, 0.66) * size]
    )
    rest = torso + np.array(
        [rng.uniform(0.25, 0.33), -rng.uniform(0.28, 0.36) * size, rng.uniform(0.0, 0.12)]
    )
    return _Scene(
        torso=torso,
        shoulder_width=0.33 * size * rng.uniform(0.92, 1.08),
        neck_height=0.23 * size * rng.uniform(0.92, 1.08),
        upper_arm=0.30 * size,
        forearm=0.33 * size,
        rest=rest,
        obj=obj,
        obj_half=obj_half,
    )


_UP = np.array([0.0, 1.0, 0.0])
_RIGHT = np.array([1.0, 0.0, 0.0])
_BACK = np.array([0.0, 0.0, 1.0])  # towards the sensor's far side: away from the object


def _gesture_path(
    action: str, scene: _Scene, start: FloatArray, rng: np.random.Generator, cfg: SynthesisConfig
) -> tuple[_Path, float]:
    """The hand's key poses for one gesture from `start` back to rest; and the push speed.

    Key poses and their timing follow the article's recordings (`beyond gesture compare`
    prints both side by side):
    - grasp (about 5 s): up and forward, across to above the object still high, down onto it,
      a hold while the hand closes, a lift, then up and to the right with it, and back;
    - touch (about 3 s): the same way out, faster, a brief contact, then up and to the right
      and back; with `cfg.pushes` a push instead (the article's stand-in for touch): the arm
      raised in front, down onto the object's near side, and forward;
    - tap (about 4 s): out to the right of the object, then a slow sweep through it to the
      left; with `cfg.air_taps` a tap held up in the air with no table under it (the
      article's "notable" recordings), slower.
    """
    speed = rng.uniform(*cfg.speed)
    amp = rng.uniform(*cfg.amplitude)

    def dur(base: float) -> float:
        return base * speed * rng.uniform(1.0 - cfg.phase_jitter, 1.0 + cfg.phase_jitter)

    top = scene.obj + _UP * scene.obj_half  # where a hand touches the object from above
    depth = top[2] - start[2]  # negative: the object is in front
    across = top[0] - start[0]

    def pose(dx: float, dy: float, dz: float) -> FloatArray:
        return cast(np.ndarray, start + np.array([dx, dy, dz]))

    p = _Path(start=start)
    push_speed = 0.0
    if action == "grasp":
        p.to(pose(0.0, 0.2 * amp, 0.65 * depth), dur(0.7))
        p.to(pose(across * rng.uniform(0.45, 0.65), 0.18 * amp, depth - 0.02), dur(0.5))
        p.to(top, dur(1.0))
        p.mark("contact_start")
        p.hold(dur(0.6))  # the hand closes on the object
        lift = rng.uniform(0.2, 0.3) * amp
        p.to(top + _UP * lift + _RIGHT * 0.03, dur(1.1))
        p.to(top + _UP * (lift + 0.04) + _RIGHT * (-across) * rng.uniform(0.7, 0.9), dur(0.7))
        p.to(scene.rest, dur(1.1))
        p.mark("contact_stop")  # the object travels with the hand
    elif action == "touch" and rng.random() >= cfg.pushes:
        p.to(pose(across * rng.uniform(-0.05, 0.05), 0.25 * amp, 0.85 * depth), dur(0.7))
        p.to(pose(across * rng.uniform(0.7, 0.9), 0.21 * amp, depth - 0.03), dur(0.25))
        p.to(top, dur(0.4))
        p.mark("contact_start")
        p.hold(dur(0.2))
        p.mark("contact_stop")
        away = pose(across * rng.uniform(0.3, 0.5), rng.uniform(0.28, 0.36) * amp, depth)
        p.to(away, dur(0.8))
        p.to(scene.rest, dur(0.8))
    elif action == "touch":  # a push
        high = pose(across * rng.uniform(0.3, 0.5), rng.uniform(0.3, 0.4) * amp, 0.6 * depth)
        near = scene.obj + _BACK * (scene.obj_half + 0.02)
        p.to(high, dur(1.3))
        p.to(near, dur(2.0))
        p.mark("contact_start")
        shove = rng.uniform(0.04, 0.1)
        stroke = dur(0.8)
        p.to(near - _BACK * shove, stroke)
        p.mark("contact_stop")
        push_speed = shove / stroke
        p.to(scene.rest, dur(1.1))
    elif action == "tap":
        air = rng.random() < cfg.air_taps
        reach = scene.obj_half + 0.01
        if air:  # no table: up and forward, then a slow sweep across at that height
            slow = rng.uniform(1.2, 2.2)
            height = start[1] + rng.uniform(0.25, 0.36)
            beside = np.array([start[0] + rng.uniform(-0.03, 0.03), height, top[2]])
            p.to(pose(beside[0] - start[0], height - start[1], 0.8 * depth), dur(1.5 * slow))
            p.to(beside, dur(0.6 * slow))
            stroke = dur(3.0 * slow)
        else:  # out to the right of the object, at its height, then through it to the left
            height = scene.obj[1] + rng.uniform(0.0, 0.06)
            beside = np.array(
                [
                    start[0] + rng.uniform(0.05, 0.12),
                    height,
                    scene.obj[2] + rng.uniform(-0.03, 0.03),
                ]
            )
            out = pose(0.8 * (beside[0] - start[0]), rng.uniform(0.05, 0.16), 0.75 * depth)
            p.to(out, dur(1.0))
            p.to(beside, dur(0.6))
            stroke = dur(1.8)
        through = beside.copy()
        through[0] = scene.obj[0] - reach - amp * rng.uniform(0.05, 0.15)
        if air:
            through[2] += rng.uniform(0.0, 0.1)  # the arm sags back a little as it sweeps
        t_before = p.duration
        p.to(through, stroke)
        p.mark("contact_stop")
        push_speed = 1.875 * (beside[0] - through[0]) / stroke * rng.uniform(0.8, 1.1)
        p.to(scene.rest, dur(1.1))
        # contact when the sweep reaches the object's side (on the whole path: the curve
        # through a key pose depends on the poses around it)
        grid = np.linspace(t_before, p.marks["contact_stop"], 400)
        at = np.flatnonzero(p.sample(grid)[:, 0] <= scene.obj[0] + reach)
        p.marks["contact_start"] = float(grid[at[0]]) if len(at) else p.marks["contact_stop"]
    else:
        raise unknown("action", action, ACTIONS)
    return p, push_speed


def _object_track(
    action: str,
    hand: FloatArray,
    t: FloatArray,
    obj0: FloatArray,
    contact: tuple[float, float],
    push_speed: float,
) -> FloatArray:
    obj = np.repeat(obj0[None, :], len(t), axis=0)
    c0, c1 = contact
    if action == "grasp":
        i0 = int(np.searchsorted(t, c0))
        i1 = int(np.searchsorted(t, c1))
        if i0 < len(t):
            offset = obj0 - hand[i0]
            obj[i0:i1] = hand[i0:i1] + offset
            obj[i1:] = obj[max(i1 - 1, 0)]
    elif action == "touch" and push_speed > 0:  # pushed forward with the hand
        i0 = int(np.searchsorted(t, c0))
        i1 = int(np.searchsorted(t, c1))
        if i0 < len(t):
            obj[i0:i1, 2] += hand[i0:i1, 2] - hand[i0, 2]
            obj[i1:, 2] = obj[max(i1 - 1, 0), 2]
    elif action == "tap":
        tau = 0.5  # s, how long the pushed object keeps going
        dt = np.clip(t - c0, 0.0, None)
        travel = push_speed * tau * (1.0 - np.exp(-dt / tau))
        obj[:, 0] -= travel
    return obj


def _arm(
    shoulder: FloatArray, hand: FloatArray, l1: float, l2: float, pole: FloatArray
) -> FloatArray:
    """Elbow positions from a two-link inverse kinematics with the elbow towards `pole`."""
    v = hand - shoulder
    d = np.linalg.norm(v, axis=1, keepdims=True)
    d = np.clip(d, 1e-6, None)
    u = v / d
    dc = np.clip(d, abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6)
    a = (l1**2 - l2**2 + dc**2) / (2.0 * dc)
    h = np.sqrt(np.clip(l1**2 - a**2, 0.0, None))
    w = pole[None, :] - (pole[None, :] * u).sum(axis=1, keepdims=True) * u
    w /= np.clip(np.linalg.norm(w, axis=1, keepdims=True), 1e-9, None)
    return cast(np.ndarray, shoulder + a * u + h * w)


def _body(
    scene: _Scene,
    hand: FloatArray,
    t: FloatArray,
    rng: np.random.Generator,
    cfg: SynthesisConfig,
) -> dict[str, FloatArray]:
    n = len(t)
    sway = np.stack(
        [
            0.01 * np.sin(2 * np.pi * t / rng.uniform(4, 8) + rng.uniform(0, 2 * np.pi)),
            0.005 * np.sin(2 * np.pi * t / rng.uniform(3, 6) + rng.uniform(0, 2 * np.pi)),
            0.01 * np.sin(2 * np.pi * t / rng.uniform(5, 9) + rng.uniform(0, 2 * np.pi)),
        ],
        axis=1,
    )
    torso = scene.torso + sway
    up = np.array([0.0, 1.0, 0.0])
    right = np.array([1.0, 0.0, 0.0])
    neck = torso + up * scene.neck_height
    shoulders_y = up * (scene.neck_height - 0.03)
    rs = torso + shoulders_y + right * scene.shoulder_width / 2
    ls = torso + shoulders_y - right * scene.shoulder_width / 2
    head = neck + up * 0.2 * scene.neck_height / 0.23
    lh = scene.torso + np.array([-0.25, -0.33, 0.02]) + 0.6 * sway
    pole = np.array([0.3, -1.0, 0.2])
    re = _arm(rs, hand, scene.upper_arm, scene.forearm, pole)
    le = _arm(ls, lh, scene.upper_arm, scene.forearm, pole * np.array([-1, 1, 1]))
    joints = {
        "head": head,
        "neck": neck,
        "torso": torso,
        "left_shoulder": ls,
        "right_shoulder": rs,
        "left_elbow": le,
        "right_elbow": re,
        "left_hand": np.broadcast_to(lh, (n, 3)).copy(),
        "right_hand": hand,
    }
    # a depth sensor's hand is noisiest in depth, least across the image (as in the article's logs)
    hand_sigma = rng.uniform(*cfg.hand_noise) * np.array([0.6, 0.85, 1.0])
    for name in JOINTS:
        sigma = hand_sigma if name == "right_hand" else np.full(3, cfg.joint_noise)
        drift = np.cumsum(rng.normal(0.0, 1.0, (n, 3)), axis=0)
        drift -= np.linspace(0, 1, n)[:, None] * drift[-1]  # bridge: bounded drift
        drift *= cfg.drift / max(float(np.abs(drift).max()), 1e-9)
        joints[name] = joints[name] + rng.normal(0.0, sigma, (n, 3)) + drift
    if cfg.glitch_rate > 0:  # the tracker snaps to something else for 1-4 frames
        hand = joints["right_hand"]
        for i in np.flatnonzero(rng.random(n) < cfg.glitch_rate):
            hand[i : i + int(rng.integers(1, 5))] += rng.normal(0.0, 0.12, 3)
    return joints


def _check_action(action: str) -> None:
    if action not in ACTIONS:
        raise unknown("action", action, ACTIONS)


def _render(
    actions: Sequence[str],
    seed: int,
    cfg: SynthesisConfig,
    first_rest: tuple[float, float],
    between: tuple[float, float],
) -> SkeletonStream:
    rng = np.random.default_rng(seed)
    scene = _scene(rng)
    t_cursor = rng.uniform(*first_rest)
    # the full hand path: rests and gestures chained, with their time bounds
    full = _Path(start=scene.rest)
    full.hold(t_cursor)
    spans: list[tuple[str, float, float, float, float, float]] = []
    for i, action in enumerate(actions):
        path, push_speed = _gesture_path(action, scene, scene.rest, rng, cfg)
        t0 = full.extend(path)
        spans.append(
            (
                action,
                t0,
                full.duration,
                t0 + path.marks["contact_start"],
                t0 + path.marks["contact_stop"],
                push_speed,
            )
        )
        rest = rng.uniform(*between) if i < len(actions) - 1 else rng.uniform(*first_rest)
        full.hold(rest)
    n = int(np.ceil(full.duration * cfg.fps)) + 1
    t = np.arange(n) / cfg.fps
    hand = full.sample(t)
    obj = np.repeat(scene.obj[None, :], n, axis=0)
    for action, _, _, c0, c1, push in spans:
        track = _object_track(action, hand, t, obj[int(np.searchsorted(t, c0)) - 1], (c0, c1), push)
        after = t >= c0 - 1.0 / cfg.fps
        obj[after] = track[after]
    joints = _body(scene, hand.copy(), t, rng, cfg)

    def frame(x: float) -> int:
        return int(np.clip(np.searchsorted(t, x), 0, n))

    bounds = tuple(
        GestureBounds(a, frame(t0), frame(t1), frame(c0), frame(c1))
        for a, t0, t1, c0, c1, _ in spans
    )
    return SkeletonStream(
        fps=cfg.fps,
        joints=joints,
        object_xyz=obj,
        gestures=bounds,
        seed=seed,
        info={
            "shoulder_width": scene.shoulder_width,
            "neck_height": scene.neck_height,
            "object_half_size": scene.obj_half,
        },
    )


def synthesize_gesture(
    action: str, seed: int, config: SynthesisConfig | None = None
) -> SkeletonStream:
    """One gesture between two short rests; `gestures[0]` marks the moving part."""
    _check_action(action)
    cfg = config or SynthesisConfig()
    return _render([action], seed, cfg, cfg.rest, cfg.rest)


def synthesize_continuous(
    actions: Sequence[str] | int, seed: int, config: SynthesisConfig | None = None
) -> SkeletonStream:
    """Several gestures separated by rests (for the segmenter); an int draws that many actions."""
    cfg = config or SynthesisConfig()
    if isinstance(actions, int):
        if actions < 1:
            raise InputError(f"number of gestures {actions}; valid: at least 1")
        rng = np.random.default_rng([seed, 1])
        actions = [ACTIONS[i] for i in rng.integers(len(ACTIONS), size=actions)]
    if not actions:
        raise InputError("no actions to synthesise; valid: at least one of grasp, tap, touch")
    for a in actions:
        _check_action(a)
    return _render(list(actions), seed, cfg, cfg.rest_between, cfg.rest_between)


def synthesize_dataset(
    n_per_action: int,
    seed: int,
    config: SynthesisConfig | None = None,
    actions: Sequence[str] = ACTIONS,
) -> dict[str, list[FloatArray]]:
    """`{action: [gesture features (T_i, D), ...]}`: n_per_action gestures of each action, cut
    by the default segmenter, in the default models' feature space.

    Every gesture has its own seed derived from (seed, action, index), so data sets with
    different seeds share no gesture, and adding gestures does not change the earlier ones.
    """
    if n_per_action < 1:
        raise InputError(f"gestures per action {n_per_action}; valid: at least 1")
    out: dict[str, list[FloatArray]] = {}
    for a_i, action in enumerate(actions):
        _check_action(action)
        out[action] = [
            synthesize_gesture(action, gesture_seed(seed, a_i, i), config).gesture_features()
            for i in range(n_per_action)
        ]
    return out


def gesture_seed(seed: int, action_index: int, i: int) -> int:
    """The seed of gesture i of an action in a data set (so sets extend without changing)."""
    ss = np.random.SeedSequence([seed, action_index, i])
    return int(ss.generate_state(1)[0])
