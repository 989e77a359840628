"""AprilTag tracking: the tag's pose in each camera frame, as the AR session's view matrix."""
