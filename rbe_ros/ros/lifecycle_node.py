"""``rbe_lifecycle_node``: :mod:`rbe_ros.ros.node` as a managed (lifecycle) node.

The same parameters, topics, service and action as ``rbe_node``, under the standard lifecycle
(``ros2 lifecycle set /rbe_node configure``, then ``activate``), so that a cell's launch
system brings the checks up only once the rest is ready:

* configure: the parameters are validated, the bag of ``mcap_path`` opened and the design of
  ``design_file`` read; a bad one fails the transition with one error line (the node stays
  unconfigured);
* activate: ``~/assembly``, ``~/design``, ``~/poses``, ``~/check``, ``~/check_sequence`` and
  ``~/plan`` open (the design of ``design_file`` is sent on, as by ``rbe_node``, at the first
  activate after configure); deactivate closes the service and the actions and stops the
  checks (a running check ends after its current step, a running plan at its next candidate
  check), but keeps the design and the poses measured so
  far (the next activate goes on from them) and the topic subscriptions: what arrives while
  inactive is recorded, designs and poses are merged into the as-built state (an incremental
  camera's blocks measured in a pause are not lost), and the newest message is checked first
  at the next activate, the others counted as dropped (``dropped_states``, /diagnostics, a
  warning at activate), as under overload;
* cleanup: the bag is closed, the design and measured poses forgotten; shutdown: everything
  is closed.

Run: ``rbe_lifecycle_node --ros-args -p mcap_path:=bags/run`` (or
``python -m rbe_ros.ros.lifecycle_node``).
"""
from __future__ import annotations

from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn

from ..io.execution import Execution
from ..io.poses import AsBuilt
from ..scene import SceneError
from .node import NODE_NAME, ConfigurationError, RbeChecks, spin


class RbeLifecycleNode(RbeChecks, LifecycleNode):
    """The checks of ``rbe_node`` behind the lifecycle transitions."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._setup()
        self._design = None

    def on_configure(self, state) -> TransitionCallbackReturn:
        path = self.get_parameter("design_file").value
        try:
            self.check_options()
            self._open_bag()
            self._design = (*self.design_message(path), self.design_cell(path)) if path \
                else None
            self._asbuilt = AsBuilt()
            self._execution = Execution()
            self._plan_cell = None
        except (ConfigurationError, SceneError, ValueError) as exc:
            self.close_bag()
            self.get_logger().error(f"configure failed: {exc}")
            return TransitionCallbackReturn.FAILURE
        self._record_settings()
        self._start_foxglove()
        self.get_logger().info("configured")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self._start_interfaces()
        if self._design is not None:    # once: a second activate keeps the measured poses
            design, self._design = self._design, None
            state, name, cell = design
            self._send_design(state, cell, name=name)
        self.get_logger().info("activated")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self._stop_interfaces(pause=True)
        self.get_logger().info("deactivated: the design and the measured poses are kept")
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        self._stop_interfaces()
        self._close_outputs()
        self._design = None
        self.get_logger().info("cleaned up: the bag closed, the design forgotten")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        self._stop_interfaces()
        self._close_outputs()
        return TransitionCallbackReturn.SUCCESS


def main(args=None) -> None:
    """Run :class:`RbeLifecycleNode` (unconfigured until told to configure)."""
    spin(RbeLifecycleNode, args)


if __name__ == "__main__":
    main()
