"""/diagnostics of rbe_node over DDS: checks done, last check duration, dropped states, bag
bytes written, last error and the level, about once a second."""
from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rbe_msgs.msg import StabilityReport
from rclpy.serialization import serialize_message

from rbe_ros.rbe.result import Report, Status
from rbe_ros.ros.diagnostics import STALE_AFTER_S, NodeHealth
from rbe_ros.ros.live import NodeProcess

from rbe_client import Client, stacked_boxes, state_msg
from test_robustness import set_parameter


@pytest.fixture(scope="module")
def rbe(rclpy_context, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rbe_diagnostics")
    proc = NodeProcess(["-p", f"mcap_path:={tmp / 'bag'}"], tmp / "node.log")
    client = Client(rclpy_context, markers=False)
    seen: list[DiagnosticArray] = []
    lock = threading.Condition()

    def keep(msg):
        with lock:
            seen.append(msg)
            lock.notify_all()

    client.node.create_subscription(DiagnosticArray, "/diagnostics", keep, 10)
    try:
        client.wait_ready(proc)
        yield SimpleNamespace(proc=proc, client=client, seen=seen, lock=lock, bag=tmp / "bag")
    finally:
        client.close()
        proc.stop()


def values_after(rbe, since: float, predicate, timeout: float = 30.0) -> tuple[dict, int]:
    """The key-values and level of the first rbe_node status received after ``since``
    (time.time()) that satisfies ``predicate(values)``."""
    end = time.monotonic() + timeout
    with rbe.lock:
        while True:
            for msg in rbe.seen:
                stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
                for status in msg.status:
                    values = {kv.key: kv.value for kv in status.values}
                    if status.name.endswith("rbe_node") and stamp >= since \
                            and predicate(values):
                        return values, status.level
            left = end - time.monotonic()
            assert left > 0, "no matching /diagnostics message"
            rbe.lock.wait(left)


def test_diagnostics_count_checks_and_bag_bytes(rbe):
    start = time.time()
    values, level = values_after(rbe, start, lambda v: True)
    assert level == DiagnosticStatus.OK and values["checks done"] == "0"
    states = [state_msg(stacked_boxes(0.0)), state_msg(stacked_boxes(0.6))]
    for state in states:
        rbe.client.publish(state)
        rbe.client.report_for(state)
    values, level = values_after(rbe, time.time(), lambda v: v["checks done"] == "2")
    assert level == DiagnosticStatus.OK
    assert values["last status"] == "TENSION_REQUIRED" and values["dropped states"] == "0"
    assert 0 < float(values["last check duration s"]) < 5.0
    # the two states as they came, their reports and markers
    states_bytes = sum(len(serialize_message(s)) for s in states)
    reports_bytes = sum(len(serialize_message(rbe.client.report_for(s))) for s in states)
    assert int(values["bag bytes written"]) > states_bytes + reports_bytes
    # about once a second: on average (a timer late under load is followed by one on time)
    values_after(rbe, time.time() + 3.0, lambda v: True, timeout=30.0)
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in rbe.seen[-4:]]
    assert 0.5 < (stamps[-1] - stamps[0]) / 3 < 3.0


def test_invalid_input_is_a_verdict_and_a_time_limit_warns(rbe):
    state = state_msg(stacked_boxes(0.0))
    state.blocks[1].pose.orientation.w = float("nan")     # refused: INVALID_INPUT, a verdict
    rbe.client.publish(state)
    assert rbe.client.report_for(state).status == StabilityReport.INVALID_INPUT
    values, level = values_after(rbe, time.time(), lambda v: v["last status"] == "INVALID_INPUT")
    assert level == DiagnosticStatus.OK and values["last error"] == ""
    assert set_parameter(rbe.client, "check_time_limit", 1e-7).successful
    try:
        state = state_msg(stacked_boxes(0.0))
        rbe.client.publish(state)
        report = rbe.client.report_for(state)
    finally:
        assert set_parameter(rbe.client, "check_time_limit", 0.0).successful
    assert report.status == StabilityReport.SOLVER_FAILED
    values, level = values_after(rbe, time.time(), lambda v: v["last status"] == "SOLVER_FAILED")
    assert level == DiagnosticStatus.WARN and values["last error"] == report.message


def test_stale_when_nothing_checked_for_a_while_and_inactive_first():
    health = NodeHealth()

    def level() -> tuple[int, str]:
        status = health.message("rbe_node", Time()).status[0]
        return status.level, status.message

    assert level() == (DiagnosticStatus.STALE, "inactive: nothing is checked")
    health.set_active(True)
    assert level() == (DiagnosticStatus.OK, "ok")
    health.last_report_at -= STALE_AFTER_S + 1.0        # as if no report came for so long
    assert level()[0] == DiagnosticStatus.STALE and level()[1].startswith("stale: no input")
    health.reported(Report(Status.STABLE, "stands"))
    assert level() == (DiagnosticStatus.OK, "ok")
    health.dropped_count(3)                             # counted in a pause, then inactive
    health.set_active(False)
    assert level()[0] == DiagnosticStatus.STALE
    health.set_active(True)
    assert level() == (DiagnosticStatus.OK, "ok")      # the pause's drops are not overload


def test_warn_while_the_last_verdict_is_infeasible():
    """A supervisor watching /diagnostics learns that the assembly the cell sees would fall:
    WARN while the last verdict is INFEASIBLE, OK again once a verdict stands."""
    health = NodeHealth()
    health.set_active(True)

    def level() -> tuple[int, str]:
        status = health.message("rbe_node", Time()).status[0]
        return status.level, status.message

    health.reported(Report(Status.INFEASIBLE, "not connected: b3"))
    assert level() == (DiagnosticStatus.WARN, "last verdict INFEASIBLE: not connected: b3")
    health.reported(Report(Status.FRICTION_EXCEEDED, "friction needed 0.7"))
    assert level() == (DiagnosticStatus.OK, "ok")      # a verdict with forces: not an alarm
    health.reported(Report(Status.STABLE, "stands"))
    assert level() == (DiagnosticStatus.OK, "ok")
