"""Gesture recognition: P_HMM(A | G_1^t) from 3-D hand trajectories, one HMM per action.

The API other modules use (fusion, services, reproduction, the simulator):

    from beyond_self.cognition.gestures import load_models, StreamingRecognizer, gesture_features
    models = load_models("models.json")          # or the article's .mat; default_models()
    x = extract_features(hand, torso)            # (T, 3): the hand in body units (metres in)
    features = gesture_features(models.features, x, start, stop)   # the models' feature space
    rec = StreamingRecognizer(models)            # priors=None: equal priors
    for f in features:
        r = rec.push(f)
        r.posterior                              # P_HMM(A | G_1^t) in models.actions order

For a live or recorded stream, `cognition.episodes.GestureTracker` does it all frame by frame:
the segmenter (`GestureSegmenter`: one gesture per execution, rest, drift and tracker failures
withdrawn), the features as the gesture unfolds, and a cancel for a movement no model fits. For
the article's hand logs: positions = the logged values times 0.001 (`hand_log_stream`).
`BatchRecognizer` updates many streams at once; `recognize_sequence` runs a whole gesture;
`synthesize_gesture`/`synthesize_continuous` make seeded skeleton streams. Heavy dependencies
(hmmlearn, scipy.io) are imported only by the functions that need them.
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
    MOTION,
    POSITION,
    body_scale,
    extract_features,
    features_from_joints,
    gesture_features,
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
    Discarded,
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
    "MOTION",
    "POSITION",
    "BatchRecognizer",
    "BatchResult",
    "Discarded",
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
    "gesture_features",
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
