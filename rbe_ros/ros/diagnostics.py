"""``/diagnostics`` of rbe_node (diagnostic_msgs/DiagnosticArray, about once a second): what
a cell supervisor watches, as the ROS diagnostics tools (rqt_robot_monitor, the diagnostic
aggregator) expect it.

Levels, the first that applies: ERROR when recording to the bag failed or a check raised an
unexpected error (the node goes on, but a log is lost or a report is not a verdict); STALE,
message "inactive", while a managed node is inactive (nothing is checked; what arrives is
counted as dropped); WARN when states were dropped under overload since the last message, or
the last report had no verdict (SOLVER_FAILED: a solver failure, the time limit, a
superseded sequence) or its verdict was INFEASIBLE (no admissible forces: the assembly the
cell sees would fall); STALE, message "stale", when no input has been checked for
:data:`STALE_AFTER_S`; OK otherwise.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from ..rbe.result import Report, Status

TOPIC = "/diagnostics"
PERIOD_S = 1.0
#: No report for this long: the cell's view of the assembly is not being checked.
STALE_AFTER_S = 10.0
#: Last statuses that make the node WARN: no verdict, or a verdict that the assembly falls.
_WARN_STATUSES = (Status.SOLVER_FAILED.name, Status.INFEASIBLE.name)


@dataclass
class NodeHealth:
    """Counters the node updates as it works (thread-safe)."""

    checks: int = 0                 # reports published
    last_duration_s: float = 0.0    # of the last report's check
    last_status: str = ""
    last_message: str = ""
    dropped: int = 0                # states dropped unchecked so far
    bag_bytes: int = 0              # message bytes written to the bag
    last_error: str = ""
    failed: bool = False            # an unexpected error or a recording failure happened
    active: bool = False            # checking (the interfaces are open)
    last_report_at: float = field(default_factory=time.monotonic)   # or since active
    _dropped_seen: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def reported(self, report: Report) -> None:
        with self._lock:
            self.checks += 1
            self.last_report_at = time.monotonic()
            self.last_duration_s = report.solve_time
            self.last_status = report.status.name
            self.last_message = report.message
            self.dropped = max(self.dropped, report.dropped_states)
            if report.status == Status.SOLVER_FAILED:
                self.last_error = report.message
                self.failed |= report.message.startswith("check failed")

    def set_active(self, active: bool) -> None:
        with self._lock:
            self.active = active
            self.last_report_at = time.monotonic()

    def dropped_count(self, dropped: int) -> None:
        """Dropped states counted before a report carries them (messages while inactive)."""
        with self._lock:
            self.dropped = max(self.dropped, dropped)

    def recorded(self, size: int) -> None:
        with self._lock:
            self.bag_bytes += size

    def error(self, text: str) -> None:
        """An error that is not a report (recording stopped)."""
        with self._lock:
            self.last_error, self.failed = text, True

    def message(self, name: str, stamp) -> DiagnosticArray:
        """The DiagnosticArray of now (``stamp``: builtin_interfaces/Time)."""
        with self._lock:
            newly_dropped = self.dropped > self._dropped_seen
            self._dropped_seen = self.dropped
            if self.failed:
                level, summary = DiagnosticStatus.ERROR, f"error: {self.last_error}"
            elif not self.active:
                level, summary = DiagnosticStatus.STALE, "inactive: nothing is checked"
            elif newly_dropped or self.last_status in _WARN_STATUSES:
                level = DiagnosticStatus.WARN
                summary = "states dropped under overload" if newly_dropped else \
                    f"last check without a verdict: {self.last_error}" \
                    if self.last_status == Status.SOLVER_FAILED.name else \
                    f"last verdict {self.last_status}: {self.last_message}"
            elif (idle := time.monotonic() - self.last_report_at) > STALE_AFTER_S:
                level, summary = DiagnosticStatus.STALE, \
                    f"stale: no input checked for {idle:.0f} s"
            else:
                level, summary = DiagnosticStatus.OK, "ok"
            values = {"checks done": str(self.checks),
                      "last check duration s": f"{self.last_duration_s:.6f}",
                      "last status": self.last_status, "dropped states": str(self.dropped),
                      "bag bytes written": str(self.bag_bytes), "last error": self.last_error}
        status = DiagnosticStatus(level=level, name=name, message=summary,
                                  hardware_id="rbe_ros",
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        array = DiagnosticArray(status=[status])
        array.header.stamp = stamp
        return array
