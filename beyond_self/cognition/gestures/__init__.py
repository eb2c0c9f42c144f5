"""Gesture recognition: P_HMM(A | G_1^t) from 3-D hand trajectories, one HMM per action.

`load_models` (ours or the article's .mat; `default_models()`), `extract_features` and
`gesture_features` (the models' feature space), `StreamingRecognizer` (one `push` per frame,
`posterior` in `models.actions` order), `BatchRecognizer` (many streams at once),
`recognize_sequence` (a whole gesture), `synthesize_gesture`/`synthesize_continuous` (seeded
skeleton streams). For a live or recorded stream, `cognition.episodes.GestureTracker` does it all
frame by frame, with the segmenter. The article's hand logs are in mm (`hand_log_stream` scales
them). hmmlearn and scipy.io are imported only by the functions that need them.
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
from beyond_self.cognition.gestures.hmm import GestureHMM, GestureModels
from beyond_self.cognition.gestures.logs import HandLog, read_hand_log
from beyond_self.cognition.gestures.matlab import load_matlab_models
from beyond_self.cognition.gestures.model_files import load_models, save_models
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
from beyond_self.cognition.gestures.training import TrainingConfig, train_hmm, train_models

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
