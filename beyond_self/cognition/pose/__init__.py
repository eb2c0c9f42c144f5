"""A camera as a body tracker: frames from a video or a camera through a real pose model
(MediaPipe's BlazePose, bundled with the `camera` extra) into the skeleton the gesture models
expect. No bus here: `beyond video`, the ingest's camera source and the benchmark use it.

- `skeleton`: the pose model's 33 landmarks -> the Kinect/OpenNI joints of the article's
  recordings (names, axes, units), with per-joint confidence. Pure numpy.
- `estimator`: the model itself (imports MediaPipe when built).
- `video`: frames and their times from a video file or a camera (OpenCV).
"""

from beyond_self.cognition.pose.skeleton import (
    JOINT_LANDMARKS,
    LANDMARKS,
    PoseEstimate,
    kinect_joints,
    pixel_joints,
)

__all__ = ["JOINT_LANDMARKS", "LANDMARKS", "PoseEstimate", "kinect_joints", "pixel_joints"]
