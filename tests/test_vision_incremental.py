"""The incremental analyser equals the batch analysis, also when frames past the end were pushed."""

from __future__ import annotations

import numpy as np

from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.pipeline import RecordingAnalyser, analyse_frames
from beyond_self.cognition.vision.tabletop import simulate_experiment


def test_prefix_of_an_incremental_analysis_equals_the_batch_analysis() -> None:
    clusters = ClusterModel.load()
    exp = simulate_experiment("tap", "blue", "box", "medium", np.random.default_rng(4))
    n = len(exp.frames) - 12
    batch = analyse_frames(exp.frames[:n], exp.fps, clusters)
    analyser = RecordingAnalyser(exp.fps, clusters)
    for frame in exp.frames:  # twelve frames more than the batch saw
        analyser.push(frame)
    inc = analyser.finish(n)
    assert inc.labels == batch.labels
    assert inc.effects == batch.effects
    np.testing.assert_array_equal(inc.contact_flags, batch.contact_flags)
    np.testing.assert_array_equal(inc.object_track[1], batch.object_track[1])
    full = analyser.finish()
    assert len(full.contact_flags) == len(exp.frames)
