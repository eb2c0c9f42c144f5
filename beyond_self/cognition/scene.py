"""A seeded synthetic scene: a person acting on objects on a table, seen by a body tracker and an
overhead camera at once; the library behind `beyond simulate` (which adds the messages and file).

The services need recordings whose truth is known and whose two sensor streams agree, built from
the generators the models were built on: the skeleton from `cognition.gestures.synthetic`, the
object's physics from `cognition.vision.tabletop` with `cognition.world`'s effects. On one clock,
gesture k acts on object k, the hand in the image approaching along the skeleton's own track (so
contact happens at the same instant in both); objects are swapped between gestures early enough
that the object segmenter's window for each gesture opens on its object alone (`_blocks`).
`check_scene` runs what the services run and compares with the truth.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from beyond_self.cognition.gestures.synthetic import (
    GestureBounds,
    SkeletonStream,
    SynthesisConfig,
    synthesize_continuous,
)
from beyond_self.cognition.variables import ACTIONS, AFFORDANCE_VARIABLES
from beyond_self.cognition.vision.tabletop import (
    SKIN_RGB,
    Camera,
    Experiment,
    ObjectSpec,
    make_table,
    min_jerk,
    render_frame,
    simulate_experiment,
)
from beyond_self.core.errors import InputError, unknown

# Every recording starts at this instant (2019-01-01T00:00:00Z), so files are deterministic.
EPOCH_NS = 1_546_300_800 * 1_000_000_000
CAMERA_FPS_RANGE = (5.0, 30.0)
# the person acts on an object on a table: taps at its height, touches that touch it
SCENE_GESTURES = SynthesisConfig(air_taps=0.0, pushes=0.0)
SWITCH_LEAD_S = 0.5  # the next object is on the table this long before its gesture starts
WINDOW_LEAD_S = 0.3  # the object segmenter's window opens this long before a gesture's start
LINGER_S = 0.6  # the hand keeps its last velocity this long after the experiment, then withdraws
WITHDRAW_S = 0.9  # duration of the withdrawal (minimum jerk)
WITHDRAW_BEYOND_M = 0.25  # it ends this far beyond where the approach began (out of view)
# simulate_experiment renders frames we do not use (the scene renders its own, over one table):
# its physics do not depend on the camera, so it gets the smallest one to stay cheap.
_PHYSICS_CAMERA = Camera(width=32, height=24)

SPEC_HELP = "action:color:shape:size[,action:color:shape:size...]"


@dataclass(frozen=True)
class SceneItem:
    """One action on one object, named as in the network (`cognition.variables`)."""

    action: str
    color: str
    shape: str
    size: str

    def __post_init__(self) -> None:
        if self.action not in ACTIONS:
            raise unknown("action", self.action, ACTIONS)
        for variable, value in (("Color", self.color), ("Shape", self.shape), ("Size", self.size)):
            if value not in AFFORDANCE_VARIABLES[variable]:
                raise unknown(f"{variable.lower()}", value, AFFORDANCE_VARIABLES[variable])

    @property
    def spec(self) -> str:
        return f"{self.action}:{self.color}:{self.shape}:{self.size}"

    @property
    def object_labels(self) -> dict[str, str]:
        return {"Color": self.color, "Shape": self.shape, "Size": self.size}


def _items(*specs: str) -> tuple[SceneItem, ...]:
    return tuple(SceneItem(*s.split(":")) for s in specs)


PRESETS: dict[str, tuple[SceneItem, ...]] = {
    # the bundled demo (`make demo`): a small yellow ball tapped (it rolls away fast), then a big
    # blue box grasped (lifted, carried, put down)
    "tap-ball-grasp-box": _items("tap:yellow:circle:small", "grasp:blue:box:big"),
    "touch-box": _items("touch:green2:box:medium"),
    "three-actions": _items(
        "grasp:green1:circle:big", "tap:blue:box:medium", "touch:yellow:circle:small"
    ),
}


def parse_scene(text: str) -> tuple[SceneItem, ...]:
    """A preset name or a spec `action:color:shape:size[,...]` -> the scene's items."""
    name = text.strip()
    if name in PRESETS:
        return PRESETS[name]
    if ":" not in name:
        raise InputError(
            f"unknown scene {text!r}; valid: a preset ({', '.join(PRESETS)}) or {SPEC_HELP}"
        )
    items = []
    for part in name.split(","):
        fields = [f.strip() for f in part.split(":")]
        if len(fields) != 4 or not all(fields):
            raise InputError(f"scene item {part.strip()!r} is not {SPEC_HELP.split('[')[0]}")
        items.append(SceneItem(*fields))
    return tuple(items)


@dataclass(frozen=True)
class SceneGesture:
    """One gesture of the scene and everything true about it.

    `bounds`: skeleton frames (`GestureBounds`, 0-based, stop exclusive). `block`: camera frames
    [first, stop) showing this gesture's object. `experiment`: camera frames [first, stop) the
    simulated experiment covers (approach, contact, what follows); `contact`: its contact frames
    [start, stop) on the camera's numbering. `labels`: Color, Shape, Size and the effects, as the
    world made them (HandVel follows the skeleton's approach speed)."""

    item: SceneItem
    bounds: GestureBounds
    block: tuple[int, int]
    experiment: tuple[int, int]
    contact: tuple[int, int]
    labels: dict[str, str]
    effects: dict[str, float]


@dataclass(frozen=True, eq=False)
class Scene:
    """A simulated scene: the skeleton stream, the camera plan and the truth.

    Camera frames are rendered lazily by `frames()` (a few MB each as arrays); `hand_xyz` (NaN
    rows: hand off the table), `object_xyz` and `object_index` give, per camera frame, what is
    drawn (table frame, metres; see `cognition.vision.tabletop`)."""

    items: tuple[SceneItem, ...]
    seed: int
    camera_fps: float
    skeleton: SkeletonStream
    gestures: tuple[SceneGesture, ...]
    camera: Camera
    object_index: np.ndarray  # (N,) which item's object is on the table (-1: none)
    object_xyz: np.ndarray  # (N, 3)
    hand_xyz: np.ndarray  # (N, 3), NaN when the hand is not in the scene
    hand_direction: np.ndarray  # (N, 2) approach direction in the table plane
    objects: tuple[ObjectSpec, ...]
    render_seed: int

    @property
    def n_skeleton_frames(self) -> int:
        return self.skeleton.n_frames

    @property
    def n_camera_frames(self) -> int:
        return len(self.object_index)

    def skeleton_stamps(self, t0_ns: int = EPOCH_NS) -> np.ndarray:
        """Nanosecond stamps of the skeleton frames (frame i at t0 + i / 30 s)."""
        return t0_ns + _stamps(self.n_skeleton_frames, self.skeleton.fps)

    def camera_stamps(self, t0_ns: int = EPOCH_NS) -> np.ndarray:
        """Nanosecond stamps of the camera frames (frame n at t0 + n / camera_fps s)."""
        return t0_ns + _stamps(self.n_camera_frames, self.camera_fps)

    def frames(self) -> Iterator[np.ndarray]:
        """The camera frames in order, uint8 (H, W, 3) RGB; the same every time."""
        rng = np.random.default_rng(self.render_seed)
        gain = float(rng.uniform(0.92, 1.06))
        table = make_table(self.camera, rng, gain=gain)
        skin = np.asarray(SKIN_RGB, dtype=np.float32) * np.float32(gain * rng.uniform(0.95, 1.05))
        lit = [dataclasses.replace(o, rgb=_brighter(o.rgb, gain)) for o in self.objects]
        for n in range(self.n_camera_frames):
            hand = None
            if np.all(np.isfinite(self.hand_xyz[n])):
                hand = (self.hand_xyz[n], self.hand_direction[n])
            k = int(self.object_index[n])
            placed = [(lit[k], self.object_xyz[n])] if k >= 0 else []
            yield render_frame(self.camera, table, placed, rng, hand=hand, hand_rgb=skin)

    def truth(self) -> list[dict[str, object]]:
        """Per gesture: the item, its skeleton and camera frames, and its true labels (JSON)."""
        return [
            {
                "item": g.item.spec,
                "skeleton_frames": [g.bounds.start, g.bounds.stop],
                "skeleton_contact": [g.bounds.contact_start, g.bounds.contact_stop],
                "camera_frames": list(g.experiment),
                "camera_contact": list(g.contact),
                "labels": dict(g.labels),
                "effects": {k: round(v, 4) for k, v in g.effects.items()},
            }
            for g in self.gestures
        ]

    def gesture_truth(self) -> list[GestureTruth]:
        return [
            GestureTruth(g.item.action, (g.bounds.start, g.bounds.stop), g.labels)
            for g in self.gestures
        ]


def _brighter(rgb: tuple[float, float, float], gain: float) -> tuple[float, float, float]:
    r, g, b = (float(min(c * gain, 255.0)) for c in rgb)
    return r, g, b


def _stamps(n: int, fps: float) -> np.ndarray:
    return cast(np.ndarray, np.rint(np.arange(n) * (1e9 / fps)).astype(np.int64))


def _child_seeds(seed: int, n: int) -> list[int]:
    return [int(s) for s in np.random.SeedSequence([seed, 5]).generate_state(n)]


def _resample(track: np.ndarray, fps: float, times: np.ndarray) -> np.ndarray:
    """Positions (T, 3) sampled at `fps` from time 0, linearly interpolated at `times` (s)."""
    t = np.arange(len(track)) / fps
    return np.stack([np.interp(times, t, track[:, i]) for i in range(3)], axis=1)


def simulate_scene(
    items: Sequence[SceneItem], seed: int, camera_fps: float = 15.0, camera: Camera | None = None
) -> Scene:
    """Simulate the scene (see the module docstring); the same arguments give the same scene."""
    if not items:
        raise InputError(f"the scene has no items; valid: a preset or {SPEC_HELP}")
    lo, hi = CAMERA_FPS_RANGE
    if not lo <= camera_fps <= hi:
        raise InputError(f"camera fps {camera_fps:g} out of range; valid: {lo:g}..{hi:g}")
    if seed < 0:
        raise InputError(f"seed {seed} is negative; valid: an integer >= 0")
    cam = camera or Camera()
    seeds = _child_seeds(seed, 2 + len(items))
    skel = synthesize_continuous([it.action for it in items], seed=seeds[0], config=SCENE_GESTURES)
    hand = skel.joints["right_hand"]
    fps_s = skel.fps
    duration = (skel.n_frames - 1) / fps_s
    n_cam = int(np.floor(duration * camera_fps + 1e-9)) + 1
    cam_t = np.arange(n_cam) / camera_fps

    detected = _default_segments(skel)
    blocks = _blocks(skel, cam_t, camera_fps, detected)
    object_index = np.full(n_cam, -1, dtype=np.int64)
    object_xyz = np.zeros((n_cam, 3))
    hand_xyz = np.full((n_cam, 3), np.nan)
    hand_dir = np.zeros((n_cam, 2))
    gestures = []
    objects = []
    for k, (item, g) in enumerate(zip(items, skel.gestures, strict=True)):
        # the approach at the camera's rate: from the first camera frame at or after the
        # gesture's start to the one nearest its contact (the track's last point is contact)
        n_contact = int(np.floor(g.contact_start * camera_fps / fps_s + 0.5))
        # the hand comes into the camera's view once it is on its way: not before the gesture
        # segmenter finds the gesture's start (the hand leaving its rest)
        found = detected[k]
        first = max(g.start, found[0]) if found is not None else g.start
        n_start = int(np.ceil(first * camera_fps / fps_s - 1e-9))
        n_start = min(n_start, n_contact - 1)
        track = _resample(hand, fps_s, cam_t[n_start : n_contact + 1])
        rng = np.random.default_rng(seeds[2 + k])
        exp = simulate_experiment(
            item.action,
            item.color,
            item.shape,
            item.size,
            rng,
            fps=camera_fps,
            hand_track=track,
            camera=_PHYSICS_CAMERA,
        )
        objects.append(exp.obj)
        j_contact = exp.contact[0] - 1  # the experiment's frame of the track's last point
        j_first = j_contact - (n_contact - n_start)  # ... and of its first one
        offset = n_contact - j_contact  # camera frame = experiment frame + offset
        b0, b1 = blocks[k]
        object_index[b0:b1] = k
        u = exp.hand_xyz[j_contact, :2] - exp.hand_xyz[j_first, :2]
        u = u / max(float(np.linalg.norm(u)), 1e-9)
        hand_dir[b0:b1] = u
        withdraw = _withdrawal(exp, j_first, camera_fps)
        for n in range(b0, b1):
            j = n - offset
            if j < len(exp.frames):
                object_xyz[n] = exp.object_xyz[max(j, 0)]
                if j >= j_first:
                    hand_xyz[n] = exp.hand_xyz[j]
            else:
                object_xyz[n] = exp.object_xyz[-1]
                hand_xyz[n] = withdraw(j - len(exp.frames) + 1)
        eff = exp.effects
        gestures.append(
            SceneGesture(
                item=item,
                bounds=g,
                block=(b0, b1),
                experiment=(n_start, min(offset + len(exp.frames), b1)),
                contact=(exp.contact[0] + offset, exp.contact[1] + offset),
                labels=dict(exp.labels),
                effects={
                    "object_speed": eff.object_speed,
                    "hand_speed": eff.hand_speed,
                    "relative_speed": eff.relative_speed,
                    "contact_s": eff.contact_s,
                },
            )
        )
    return Scene(
        items=tuple(items),
        seed=seed,
        camera_fps=camera_fps,
        skeleton=skel,
        gestures=tuple(gestures),
        camera=cam,
        object_index=object_index,
        object_xyz=object_xyz,
        hand_xyz=hand_xyz,
        hand_direction=hand_dir,
        objects=tuple(objects),
        render_seed=seeds[1],
    )


def _blocks(
    skel: SkeletonStream,
    cam_t: np.ndarray,
    fps: float,
    detected: Sequence[tuple[int, int] | None],
) -> list[tuple[int, int]]:
    """Camera frames [first, stop) showing each item's object (frames between blocks: an empty
    table).

    The object segmenter analyses, per gesture, the camera frames from `WINDOW_LEAD_S` before the
    start the gesture segmenter reports to its reported end, and learns the table from the first
    one. So object k must be on the table, alone, before that window opens. Where the person
    rests long enough, the swap happens `SWITCH_LEAD_S` before the gesture starts. When the
    rest is short the segmenter may start a gesture well before the hand moves (up to where it
    ended the previous one), and the two windows may overlap: the swap then happens before the
    new window opens, with an empty table for a few frames first, so the object tracker of the
    previous window retires the old object's track instead of jumping to the new object."""
    n_cam = len(cam_t)
    fps_s = skel.fps
    margin = 1.0 / fps
    empty = (int(fps // 3) + 2) / fps  # longer than the tracker keeps a lost object
    first, last = [0], []
    for k in range(1, len(skel.gestures)):
        prev, this = skel.gestures[k - 1], skel.gestures[k]
        start, gap = this.start / fps_s, (this.start - prev.stop) / fps_s
        place = start - min(SWITCH_LEAD_S, gap / 2.0)
        found, found_prev = detected[k], detected[k - 1]
        if found is not None:
            place = min(place, found[0] / fps_s - WINDOW_LEAD_S - margin)
        prev_end = (
            (found_prev[1] - 1) / fps_s
            if found_prev is not None
            else prev.stop / fps_s + WINDOW_LEAD_S
        )
        remove = place if place > prev_end + margin else place - empty
        last.append(max(int(np.searchsorted(cam_t, remove - 1e-9)), first[-1]))
        first.append(max(int(np.searchsorted(cam_t, place - 1e-9)), last[-1]))
    last.append(n_cam)
    return list(zip(first, last, strict=True))


def _default_segments(skel: SkeletonStream) -> list[tuple[int, int] | None]:
    """Per gesture, the frames [start, stop) the default gesture segmenter reports for it (the
    found segment overlapping it most), or None."""
    from beyond_self.cognition.gestures.segmentation import segment_gestures

    found = segment_gestures(skel.features())
    out: list[tuple[int, int] | None] = []
    for g in skel.gestures:
        overlap = [max(0, min(s.stop, g.stop) - max(s.start, g.start)) for s in found]
        best = int(np.argmax(overlap)) if overlap else -1
        out.append((found[best].start, found[best].stop) if best >= 0 and overlap[best] else None)
    return out


def _withdrawal(exp: Experiment, j_first: int, fps: float) -> Callable[[int], np.ndarray]:
    """The hand after the experiment's last frame: frame m >= 1 after it -> position (NaN once
    it has left). For `LINGER_S` it keeps the velocity it ended with (a grasping hand is still
    leaving the object at the world's slow relative speed: a faster exit within the 0.3 s the
    segmenter measures after contact would make it look fast), then it goes back the way it came,
    past its starting point, with a minimum-jerk profile."""
    end = exp.hand_xyz[-1]
    velocity = exp.hand_xyz[-1] - exp.hand_xyz[-2]  # per frame
    origin = exp.hand_xyz[j_first]
    back = origin[:2] - exp.hand_xyz[exp.contact[0] - 1, :2]
    back = back / max(float(np.linalg.norm(back)), 1e-9)
    linger = round(LINGER_S * fps)
    leave = end + velocity * linger
    target = origin.copy()
    target[:2] += back * WITHDRAW_BEYOND_M
    steps = max(round(WITHDRAW_S * fps), 1)

    def at(m: int) -> np.ndarray:
        if m <= linger:
            return cast(np.ndarray, end + velocity * m)
        if m - linger > steps:
            return np.full(3, np.nan)
        s = float(min_jerk(np.asarray((m - linger) / steps)))
        return cast(np.ndarray, leave + (target - leave) * s)

    return at


# ---------------------------------------------------------------- checking a scene end to end


@dataclass(frozen=True)
class GestureTruth:
    """What is true of one gesture: its action, skeleton frames [start, stop) and labels."""

    action: str
    frames: tuple[int, int]
    labels: dict[str, str]

    @classmethod
    def from_json(cls, d: dict[str, object]) -> GestureTruth:
        """From one entry of `Scene.truth()` (as stored in a recording's metadata)."""
        try:
            item = str(d["item"])
            frames = d["skeleton_frames"]
            labels_in = d["labels"]
            if not isinstance(frames, list | tuple) or len(frames) != 2:
                raise ValueError("skeleton_frames is not [start, stop]")
            if not isinstance(labels_in, dict):
                raise ValueError("labels is not an object")
            a, b = int(frames[0]), int(frames[1])
            labels = {str(k): str(v) for k, v in labels_in.items()}
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(
                f"scene truth entry is malformed ({exc}); valid: Scene.truth()"
            ) from None
        return cls(item.split(":")[0], (a, b), labels)


@dataclass(frozen=True)
class GestureCheck:
    """What the pipeline made of one gesture it found, next to the truth of the item it matches."""

    index: int  # scene item, or -1 for a segment that overlaps none
    segment: tuple[int, int]  # skeleton frames [start, stop) found by the segmenter
    action: str  # recognised
    labels: dict[str, str]  # measured on the camera window (Color, Shape, Size, effects)
    truth: dict[str, str]  # Action and the true labels
    camera_frames: int  # in the window

    def agrees(self, variable: str) -> bool:
        got = self.action if variable == "Action" else self.labels.get(variable)
        return got is not None and got == self.truth.get(variable)


def check_scene(
    skeleton: dict[str, np.ndarray],
    skeleton_stamps: np.ndarray,
    camera_stamps: np.ndarray,
    images: Sequence[np.ndarray],
    truth: Sequence[GestureTruth],
    lead_s: float = 0.3,
) -> list[GestureCheck]:
    """Run what the services run on a recording's two streams and compare with the truth.

    `skeleton`: joint -> (T, 3) metres (needs right_hand and torso); `images`: the camera frames
    in stamp order. The streams go, in stamp order, through the classes the gesture streamer and
    the object segmenter run (`cognition.episodes.GestureTracker` and `ObjectWatch`, default
    models and shipped clusters): each gesture's action is the argmax of its final belief, its
    labels are the object at its start and the effects measured over its frames. A found gesture
    is matched to the item whose true frames it overlaps most."""
    from beyond_self.cognition.episodes import (
        Belief,
        Ended,
        GestureEffects,
        GestureTracker,
        ObjectWatch,
        Started,
    )
    from beyond_self.cognition.gestures import extract_features
    from beyond_self.cognition.gestures.default_models import default_models
    from beyond_self.cognition.vision.clusters import ClusterModel

    for joint in ("right_hand", "torso"):
        if joint not in skeleton:
            raise InputError(f"skeleton has no joint {joint!r}; joints: {', '.join(skeleton)}")
    features = extract_features(skeleton["right_hand"], skeleton["torso"])
    models = default_models()
    tracker: GestureTracker[int] = GestureTracker(models)
    watch: ObjectWatch[int] = ObjectWatch(ClusterModel.load(), lead_s=lead_s)
    skel_s = np.asarray(skeleton_stamps, dtype=np.int64)
    cam_s = np.asarray(camera_stamps, dtype=np.int64)
    action: dict[int, str] = {}
    span: dict[int, tuple[int, int]] = {}
    effects: dict[int, GestureEffects[int]] = {}

    def watched(outputs: Sequence[object]) -> None:
        for out in outputs:
            if isinstance(out, GestureEffects):
                effects[out.segment_id] = out

    def tracked(events: Sequence[object]) -> None:
        for ev in events:
            if isinstance(ev, Belief) and ev.final:
                action[ev.segment_id] = str(models.actions[int(np.argmax(ev.result.posterior))])
            elif isinstance(ev, Ended):
                first = int(np.searchsorted(skel_s, ev.start_stamp))
                span[ev.segment_id] = (first, ev.ref + 1)
                watched(watch.ended(ev.segment_id, ev.start_stamp, ev.end_stamp, ev.frame, ev.ref))
            elif isinstance(ev, Started):
                watched(watch.started(ev.segment_id, ev.stamp, ev.ref))

    i = j = 0
    while i < len(skel_s) or j < len(cam_s):
        if j >= len(cam_s) or (i < len(skel_s) and skel_s[i] <= cam_s[j]):
            tracked(tracker.push(int(skel_s[i]), i + 1, features[i], i))
            watched(watch.gestures_complete(int(skel_s[i])))
            i += 1
        else:
            watched(watch.camera(int(cam_s[j]), j + 1, images[j]))
            j += 1
    tracked(tracker.finish())
    watched(watch.camera_ended(int(cam_s[-1]) if len(cam_s) else None))
    checks: list[GestureCheck] = []
    for segment_id in sorted(span):
        start, stop = span[segment_id]
        eff = effects.get(segment_id)
        labels: dict[str, str] = {}
        if eff is not None and eff.analysis is not None:
            labels = dict(eff.analysis.labels)
        lo = int(skel_s[start]) - round(lead_s * 1e9)
        n_frames = int(np.count_nonzero((cam_s >= lo) & (cam_s <= int(skel_s[stop - 1]))))
        overlaps = [max(0, min(stop, t.frames[1]) - max(start, t.frames[0])) for t in truth]
        index = int(np.argmax(overlaps)) if overlaps and max(overlaps) > 0 else -1
        truth_k = {"Action": truth[index].action, **truth[index].labels} if index >= 0 else {}
        checks.append(
            GestureCheck(index, (start, stop), action[segment_id], labels, truth_k, n_frames)
        )
    return checks
