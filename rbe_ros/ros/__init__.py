"""The ROS 2 layer of rbe_ros: message conversion, RViz markers and the ``rbe_node`` node.

Everything that imports rclpy or generated interfaces lives here; the core (``rbe_ros`` outside
this package) stays ROS-free.
"""
