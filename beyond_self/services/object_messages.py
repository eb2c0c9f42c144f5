"""The object segmenter's per-gesture results as bus messages (services/objects.py): the object a
gesture is about, and the effects of the action on it."""

from __future__ import annotations

from beyond_self.cognition.episodes import GestureEffects, ObjectAtStart
from beyond_self.schemas import GestureObject, Header, ObjectEffect, ObjectEffects


def gesture_object(header: Header, out: ObjectAtStart[Header]) -> GestureObject:
    """The object a gesture is about, as the reasoner joins it to the gesture's beliefs."""
    return GestureObject(
        header=header,
        segment_id=out.segment_id,
        frame=out.frame,
        labels=out.labels,
        reason=out.reason,
    )


def effects_message(header: Header, out: GestureEffects[Header]) -> ObjectEffects:
    effects: list[ObjectEffect] = []
    if out.analysis is not None:
        eff = out.analysis.effects
        effects.append(
            ObjectEffect(
                object_id=0,
                object_velocity=float(eff.object_speed),
                hand_velocity=_optional(eff.hand_speed),
                object_hand_velocity=_optional(eff.relative_speed),
                contact=int(out.analysis.contact_flags.sum()) > 0,
                contact_duration=_optional(eff.contact_s),
                labels=out.effect_labels,
                object_labels=out.object_labels,
            )
        )
    return ObjectEffects(
        header=header,
        frame=out.frame,
        segment_id=out.segment_id,
        effects=effects,
        measured=out.analysis is not None,
        reason=out.reason,
    )


def _optional(x: float | None) -> float | None:
    return None if x is None else float(x)
