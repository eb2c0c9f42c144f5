"""Gesture recognition: P_HMM(A | G_1^t) from 3-D hand trajectories, one HMM per action.

The API other modules use (fusion, services, reproduction, the simulator):

    from beyond_self.cognition.gestures import load_models, StreamingRecognizer, extract_features
    models = load_models("models.json")          # or the article's .mat file
    rec = StreamingRecognizer(models)            # priors=None: equal priors
    for hand, torso in frames:                   # metres, camera frame (x right, y up, z away)
        r = rec.push(extract_features(hand, torso)[0])
        r.posterior                              # P_HMM(A | G_1^t) in models.actions order
    rec.reset()                                  # next gesture

For the article's hand logs: `extract_features(log.xyz, scale=0.001)` (no torso: the logs are
already torso-relative and normalised). `BatchRecognizer` updates many streams at once;
`recognize_sequence` runs a whole gesture; `GestureSegmenter` cuts a continuous stream into
gestures; `synthesize_gesture`/`synthesize_continuous` make seeded skeleton streams.
Heavy dependencies (hmmlearn, scipy.io) are imported only by the functions that need them.
"""

from beyond_self.cognition.gestures.evaluation import (
    EvaluationReport,
    LabelledGesture,
    cross_validate,
    evaluate,
    plot_report,
    plot_stream,
)
from beyond_self.cognition.gestures.features import (
    LOG_SCALE,
    body_scale,
    extract_features,
    features_from_joints,
)
from beyond_self.cognition.gestures.hmm import (
    GestureHMM,
    GestureModels,
    TrainingConfig,
    load_models,
    save_models,
    train_hmm,
    train_models,
)
from beyond_self.cognition.gestures.logs import HandLog, read_hand_log
from beyond_self.cognition.gestures.matlab import load_matlab_models
from beyond_self.cognition.gestures.segmentation import (
    GestureSegmenter,
    Segment,
    SegmenterConfig,
    segment_gestures,
)
from beyond_self.cognition.gestures.streaming import (
    BatchRecognizer,
    BatchResult,
    FrameResult,
    SequenceResult,
    StreamingRecognizer,
    recognize_sequence,
)
from beyond_self.cognition.gestures.synthetic import (
    GestureBounds,
    SkeletonStream,
    SynthesisConfig,
    synthesize_continuous,
    synthesize_dataset,
    synthesize_gesture,
)

__all__ = [
    "LOG_SCALE",
    "BatchRecognizer",
    "BatchResult",
    "EvaluationReport",
    "FrameResult",
    "GestureBounds",
    "GestureHMM",
    "GestureModels",
    "GestureSegmenter",
    "HandLog",
    "LabelledGesture",
    "Segment",
    "SegmenterConfig",
    "SequenceResult",
    "SkeletonStream",
    "StreamingRecognizer",
    "SynthesisConfig",
    "TrainingConfig",
    "body_scale",
    "cross_validate",
    "evaluate",
    "extract_features",
    "features_from_joints",
    "load_matlab_models",
    "load_models",
    "plot_report",
    "plot_stream",
    "read_hand_log",
    "recognize_sequence",
    "save_models",
    "segment_gestures",
    "synthesize_continuous",
    "synthesize_dataset",
    "synthesize_gesture",
    "train_hmm",
    "train_models",
]
