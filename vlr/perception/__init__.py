"""The estimator's only sensor: the POM pose from one palm-camera image.

    obs = observe(image, calibration, tag_id, tag_size)   # Observation | None

`observe` (pipeline.py) detects the object's AprilTag 36h11 (detect.py), refines its corners
and solves its pose in the object frame O (pose.py), then maps it to the palm frame. Shared by
the simulator and the real hand; imports neither.
"""

from vlr.perception.detect import Detection, DetectorConfig, detect_tags, refine_edges
from vlr.perception.pipeline import Observation, observe, to_gray
from vlr.perception.pose import R_MARKER_TO_OBJECT, marker_to_object, solve_tag_pose

__all__ = [
    "Observation",
    "observe",
    "to_gray",
    "Detection",
    "DetectorConfig",
    "detect_tags",
    "refine_edges",
    "R_MARKER_TO_OBJECT",
    "marker_to_object",
    "solve_tag_pose",
]
