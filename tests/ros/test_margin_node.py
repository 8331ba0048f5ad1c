"""rbe_node with compute_margin: reports carry margin_g and margin_direction (closed form of
two stacked boxes), and -1 once the parameter is off again."""
from __future__ import annotations

import pytest
from rbe_msgs.msg import StabilityReport

from rbe_client import Client, NodeProcess, stacked_boxes, state_msg


def test_compute_margin_parameter(rclpy_context, tmp_path):
    """The top box sits 0.45 m out on a 1 m box: pushed along +x its resultant reaches the
    edge of the lower box when 0.45 + lambda 0.5 = 0.5, so margin_g = 0.1 along +x (the
    pair at the ground needs 0.275, the diagonals 0.141, sliding mu = 0.6)."""
    proc = NodeProcess(["-p", "compute_margin:=true", "-p", "friction_coefficient:=0.6"],
                       tmp_path / "node.log")
    client = Client(rclpy_context)
    try:
        client.wait_ready(proc)
        r = client.call_check(state_msg(stacked_boxes(0.45)))
        assert r.status == StabilityReport.STABLE, r.message
        assert r.margin_g == pytest.approx(0.1, rel=5e-3)
        d = r.margin_direction
        assert (d.x, d.y, d.z) == pytest.approx((1.0, 0.0, 0.0), abs=1e-9)
        r = client.call_check(state_msg(stacked_boxes(0.55)))
        assert r.status == StabilityReport.TENSION_REQUIRED and r.margin_g == 0.0
    finally:
        client.close()
        proc.stop()
