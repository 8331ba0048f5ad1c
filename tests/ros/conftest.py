"""ROS 2 tests: own DDS domain per run, discovery on this host only; skipped without ROS.

ROS_DOMAIN_ID comes from the Makefile (``make test``) or is drawn here (1..50) when unset;
each pytest-xdist worker N (``make test`` runs two) adds 50 N to it, so the workers' nodes never
meet. ROS_AUTOMATIC_DISCOVERY_RANGE is LOCALHOST. Both are set before rclpy is initialised
and are inherited by the node processes the tests start.
"""
from __future__ import annotations

import os
import random

import pytest

if not os.environ.get("ROS_DOMAIN_ID", "").strip():
    os.environ["ROS_DOMAIN_ID"] = str(random.randint(1, 50))
_WORKER = os.environ.get("PYTEST_XDIST_WORKER", "gw0")  # "gwN" under pytest-xdist
os.environ["ROS_DOMAIN_ID"] = str((int(os.environ["ROS_DOMAIN_ID"]) - 1) % 50 + 1
                                  + 50 * int(_WORKER.removeprefix("gw") or 0))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"


def _ros_missing() -> str | None:
    try:
        import rbe_msgs.action
        import rbe_msgs.msg
        import rbe_msgs.srv  # noqa: F401
        import rclpy  # noqa: F401
        import visualization_msgs.msg  # noqa: F401
    except Exception as exc:  # ModuleNotFoundError, or a missing native library (OSError)
        return f"{type(exc).__name__}: {exc}"
    return None


_MISSING = _ros_missing()
SKIP_REASON = ("ROS 2 tests need rclpy and the built rbe_msgs interfaces (run `make setup`); "
               f"import failed: {_MISSING}")

if _MISSING:
    # Each test module of this directory is reported as skipped, without importing it (a
    # pytest.skip here would be an error when this directory is pytest's argument).
    class _SkippedModule(pytest.Module):
        def collect(self):
            pytest.skip(SKIP_REASON, allow_module_level=True)

    def pytest_pycollect_makemodule(module_path, parent):
        return _SkippedModule.from_parent(parent, path=module_path)


def pytest_report_header(config):
    return (f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']} "
            f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}")


@pytest.fixture(scope="session")
def rclpy_context():
    """rclpy initialised once for the test process (its default context)."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)  # Ctrl-C is pytest's
    yield rclpy.get_default_context()
    rclpy.try_shutdown()


@pytest.fixture
def make_node(rclpy_context, request):
    """Make in-process RbeNodes with parameter overrides, in the test module's NAMESPACE (apart
    from other modules' nodes); destroyed after the test."""
    from rclpy.parameter import Parameter

    from rbe_ros.ros.node import RbeNode

    nodes = []

    def make(**overrides):
        node = RbeNode(namespace=request.module.NAMESPACE, context=rclpy_context,
                       parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        nodes.append(node)
        return node

    yield make
    for node in nodes:
        node.destroy_node()
