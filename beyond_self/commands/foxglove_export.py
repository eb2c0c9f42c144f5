"""`beyond foxglove --export`: a recording plus its Foxglove views, with the pipeline's analysis.

A shipped recording holds the sensor streams alone, so its views would be the scene and nothing
else: the layout's objects, posterior, affordance and log panels would stay empty. The export
runs the offline analysis over it (`beyond analyse`'s library, cognition.episodes.offline: what
`beyond up` prints for the same recording) and writes what the services would have published,
stamped as they stamp it, with their views. A stream the recording already holds (one recorded
during `beyond up`) is copied, never derived again. A view still empty is said in one line.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from beyond_self.cognition.bn import learn_network, synthetic_dataset
from beyond_self.cognition.episodes.join import Anticipation, Outcome
from beyond_self.cognition.episodes.offline import CameraInput, SkeletonInput, analyse_stream
from beyond_self.cognition.episodes.tracker import Belief
from beyond_self.cognition.gestures.default_models import default_models
from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.pipeline import describe_frame
from beyond_self.core.errors import InputError
from beyond_self.runtime.foxglove.views import VIEWS
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.runtime.recording.writer import RecordingWriter
from beyond_self.schemas import (
    ActionPosterior,
    AffordancePrediction,
    Description,
    DetectedObjects,
    Evidence,
    Header,
    Message,
    ScoredSentence,
)
from beyond_self.schemas.keys import STREAMS, split_key
from beyond_self.services.objects import detected_object

# the derived streams, by the service that publishes them
DERIVED = {
    "objects": "objects",
    "gesture_posterior": "gestures",
    "affordance": "reasoner",
    "description": "describer",
}


@dataclass
class Export:
    copied: int = 0
    derived: dict[str, int] = field(default_factory=dict)  # stream -> messages added
    empty: dict[str, str] = field(default_factory=dict)  # view -> why it holds nothing


def _header(cls: type[Message], service: str, seq: int, stamp: int) -> Header:
    return Header(version=cls.VERSION, source=service, seq=seq, stamp=stamp)


def _analysis(
    inputs: Iterator[SkeletonInput | CameraInput], actions: list[str]
) -> Iterator[tuple[str, Message]]:
    """What the pipeline publishes for `inputs`, stream by stream (in stamp order per stream):
    the gesture streamer's posteriors, the reasoner's predictions, the describer's
    descriptions (the default models, as `beyond analyse` without --config), and the object
    segmenter's objects of every camera frame."""
    clusters = ClusterModel.load()
    cameras: list[CameraInput] = []
    events: list[Belief[None] | Anticipation[int] | Outcome[int]] = []

    def kept(items: Iterator[SkeletonInput | CameraInput]) -> Iterator[SkeletonInput | CameraInput]:
        for item in items:
            if isinstance(item, CameraInput):
                cameras.append(item)
            yield item

    run = analyse_stream(
        kept(inputs),
        gesture_models=default_models(),
        clusters=clusters,
        network=learn_network(synthetic_dataset()),
        on_event=events.append,
    )
    for camera in cameras:
        found = describe_frame(camera.image, clusters, require_objects=False).objects
        header = _header(DetectedObjects, "objects", camera.frame, camera.stamp)
        objects = [detected_object(o) for o in found]
        yield "objects", DetectedObjects(header=header, frame=camera.frame, objects=objects)
    for seq, ev in enumerate(events):
        if isinstance(ev, Belief):
            r = ev.result
            yield (
                "gesture_posterior",
                ActionPosterior(
                    header=_header(ActionPosterior, "gestures", seq, ev.stamp),
                    segment_id=ev.segment_id,
                    frame=ev.frame,
                    actions=actions,
                    posterior=ev.posterior,
                    log_likelihood=r.loglik.tolist(),
                    normalised_log_likelihood=r.normalized.tolist(),
                    final=ev.final,
                ),
            )
            continue
        p = ev.prediction
        final = isinstance(ev, Outcome)
        yield (
            "affordance",
            AffordancePrediction(
                header=_header(AffordancePrediction, "reasoner", seq, ev.ref),
                segment_id=ev.segment_id,
                frame=ev.frame,
                action_belief=p.action_belief,
                evidence=p.evidence,
                effects=p.effects,
                final=final,
            ),
        )
        if final:
            sentences = run.sentences.get(ev.segment_id, [])
            yield (
                "description",
                Description(
                    header=_header(Description, "describer", seq, ev.ref),
                    segment_id=ev.segment_id,
                    sentences=[ScoredSentence(text=t, score=round(s, 6)) for t, s in sentences],
                    evidence=Evidence(
                        hard=dict(p.evidence), soft={"Action": dict(p.action_belief)}
                    ),
                ),
            )


def export(
    source: str, target: str, inputs: Callable[[Path], Iterator[SkeletonInput | CameraInput]]
) -> Export:
    """Copy `source` into `target` with the Foxglove views and the views of the pipeline's
    analysis of `inputs(source)` (the frames the ingest would play)."""
    if Path(target).resolve() == Path(source).resolve():
        raise InputError(f"--export would overwrite its input {source}; give another -o")
    info = inspect_recording(source)
    if info.error:
        raise InputError(info.damage())
    result = Export()
    refused = ""
    topics = [c.topic for c in info.channels if c.count]
    held = {stream for stream, (suffix, _) in STREAMS.items() for topic in topics
            if topic.endswith("/" + suffix)}  # fmt: skip
    robots = {split[0] for topic in topics if (split := split_key(topic)) is not None}
    with RecordingWriter(target, metadata=info.metadata.get("beyond"), foxglove_views=True) as w:
        for item in read_recording(source):
            if item.cls is None:
                w.write_raw(item.key, item.data, item.encoding, item.log_time)
            else:
                w.write(item.key, item.message(), log_time=item.log_time)
            result.copied += 1
        wanted = set(DERIVED) - held
        if wanted and len(robots) == 1 and "skeleton" in held:
            root = f"beyond/{next(iter(robots))}"
            actions = list(default_models().actions)
            try:  # analysed whole before the first message is written
                derived = [
                    (stream, message)
                    for stream, message in _analysis(inputs(Path(source)), actions)
                    if stream in wanted
                ]
            except InputError as exc:  # a recording the pipeline cannot analyse: copied as is
                derived, refused = [], str(exc)
            # in stamp order (stable): a gesture's final belief, stamped at its end, is found
            # after later frames', and a channel's log times (its stamps) must not step back
            for stream, message in sorted(derived, key=lambda d: d[1].header.stamp):
                w.write(f"{root}/{STREAMS[stream][0]}", message)
                result.derived[stream] = result.derived.get(stream, 0) + 1
    result.empty = _empty_views(held | set(result.derived), held, robots, refused)
    return result


def _empty_views(
    written: set[str], held: set[str], robots: set[str], refused: str
) -> dict[str, str]:
    """Why each view of the layout holds nothing, in a few words."""
    why: dict[str, str] = {}
    source_of = {v.name: v.source for v in VIEWS}
    stream_of = {cls: name for name, (_, cls) in STREAMS.items()}
    for view, cls in source_of.items():
        stream = stream_of[cls]
        if stream in written:
            continue
        if stream == "person_pose":
            why[view] = "the recording has no person pose (only a camera source makes one)"
        elif len(robots) > 1:
            why[view] = f"a fleet's recording ({len(robots)} robots): analyse it robot by robot"
        elif refused:
            why[view] = f"the pipeline could not analyse the recording ({refused})"
        elif "skeleton" not in held:
            why[view] = "the recording has no skeleton frames to analyse"
        elif stream == "objects":
            why[view] = "the recording has no tabletop camera frames"
        else:
            why[view] = "the analysis found no gesture in the recording"
    return why
