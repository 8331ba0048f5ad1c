"""Input and output of the core: scene JSON, COMPAS JSON, message dicts, CDR, bags, replay
and the bag regression-test helper. ROS-free: messages are plain dicts here; only
:mod:`rbe_ros.ros` turns them into rclpy objects."""
