"""rbe_ros: rigid-block equilibrium (Kao et al. 2021) checks of block assemblies.

The core (scene, geometry, rbe, analysis, io, cli) never imports rclpy;
the ROS 2 node in :mod:`rbe_ros.ros` is a thin shell around it.
"""
