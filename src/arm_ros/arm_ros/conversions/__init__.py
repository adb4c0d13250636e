"""numpy <-> ROS message conversions shared by every node (no cv_bridge on this platform), one
module per message family: images (Image, CameraInfo, depth encodings), poses, meshes (Mesh,
ReconstructedObject) and frames (the camera topics and SegmentedFrame <-> arm_core.frames.RgbdFrame).

Only message classes are imported, never rclpy, so the conversions stay testable without a ROS graph.
"""


class ConversionError(ValueError):
    """A message could not be converted: unknown encoding, wrong sizes, non-finite values."""
