"""``rbe_node``: rigid-block equilibrium checks of assemblies over ROS 2.

Interfaces (relative to the node, e.g. ``/rbe_node/report``):

* subscribes ``~/assembly`` (rbe_msgs/AssemblyState, reliable, depth 1): a state without a
  sequence is checked as a whole (one report); with a sequence every insertion step is checked
  and each step's report is published as soon as it is done. States are checked by a worker
  thread from a single-slot buffer: when states arrive faster than they can be checked, the
  newest replaces the waiting one, and the dropped ones are counted (``dropped_states`` of
  every report, a throttled warning in the log), so memory stays bounded and the newest state
  is always answered. A state that arrives while a sequence is checked supersedes it between
  two steps: the sequence's last report (SOLVER_FAILED, "superseded: ...") names the first
  step not checked, and the newer state is checked next;
* publishes ``~/report`` (rbe_msgs/StabilityReport, reliable, transient_local, depth 1) and
  ``~/markers`` (visualization_msgs/MarkerArray, same QoS: the blocks, forces and verdict,
  :mod:`rbe_ros.io.markers`) for every report the node makes, whatever asked for it (topic,
  service or action); with ``foxglove_port`` the markers also go to Foxglove as SceneUpdates
  (:mod:`rbe_ros.io.foxglove_scene`);
* serves ``~/check`` (rbe_msgs/srv/CheckAssembly): the assembly as a whole, sequence ignored;
* serves the action ``~/check_sequence`` (rbe_msgs/action/CheckSequence): feedback per step,
  all reports and the first failing step as result; cancellable between steps;
* serves the action ``~/plan`` (rbe_msgs/action/PlanSequence): plans an insertion order with
  at most ``max_held`` blocks held (as ``rbe-ros plan``, through the same
  :func:`rbe_ros.io.plans.plan_state`), feedback after each placed step, the plan, its holds
  and each step's report as result. Cancellable between candidate checks (the result is the
  best partial plan, status CANCELED); a newer goal preempts a running one (ABORTED, "stopped
  after K of N blocks"); plans run one at a time. A goal that cannot be planned (invalid
  input) SUCCEEDS with ``feasible`` false and the reason, as an infeasible plan does. Plans
  (and repairs) run in worker processes (:mod:`rbe_ros.ros.workers`), so the checks keep
  their pace meanwhile;
* publishes ``~/execution`` (rbe_msgs/ExecutionState) and ``~/plan_update``
  (rbe_msgs/PlanUpdate), both latched: the plan under execution (a design with a sequence, or
  a ~/plan result of the design) for each design or poses message checked, the steps
  ahead at the measured poses, and a repaired plan when one of them fails
  (:mod:`rbe_ros.io.execution`, its own thread, begun with the check of the message:
  :class:`rbe_ros.io.execution.NodeReport`; parameters ``lookahead_steps``,
  ``min_margin_g``). A plan for a robot cell (a ``design_file`` written by ``rbe-ros plan
  --cell -o``, a ``~/plan`` result for a cell; a design sent on ``~/design`` carries none) is
  executed as its timeline, the cell recorded with the settings, and its robots drawn on
  ``~/markers`` after each execution state.

Bad input never stops the node: a state that cannot be checked (outside the limits of
:class:`rbe_ros.scene.ValidationLimits`, ``max_blocks`` among them) gives a report with status
INVALID_INPUT and the reason, a solver failure or a solve over ``check_time_limit`` gives
SOLVER_FAILED naming the solver's status or the stage, and any other error in a callback is
logged and gives SOLVER_FAILED with the exception text. With ``mcap_path`` set, every checked
state and every report is recorded (CDR, receive/publish time) in a rosbag2 MCAP bag, each
message flushed before the report is published (a report seen on DDS is on disk, even after
SIGKILL); the bag is closed on shutdown (SIGINT, SIGTERM). A ``~/plan`` goal and its result
are recorded on ``~/plan/goal`` and ``~/plan/result`` (rbe_msgs/action/PlanSequence_Goal,
_Result), and ``rbe-ros replay`` re-plans the goal.

Run: ``rbe_node --ros-args -p friction_coefficient:=0.5 -p mcap_path:=bags/run``
(or ``python -m rbe_ros.ros.node``).
"""
from __future__ import annotations

import os
import math
import signal
import struct
import json
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.signals import SignalHandlerOptions
from rbe_msgs.action import CheckSequence, PlanSequence
from rbe_msgs.msg import AssemblyState, BlockPoses, ExecutionState, PlanUpdate, StabilityReport
from rbe_msgs.srv import CheckAssembly
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from ..analysis.option_spec import BY_PARAM, OPTIONS, Option, from_outer
from ..analysis.options import CheckOptions
from ..analysis.pipeline import StateCheck, check_state
from ..analysis.lookahead import check_plan_design
from ..analysis.planning import STOPPED, Plan
from ..analysis.steps import sequence_step
from ..io import cdr, lmgc90
from ..io.bag import BagWriter, typestore
from ..io.inputs import load_design
from ..io.foxglove_scene import SceneServer
from ..io.markers import MARKER_TYPE, cell_markers, run_markers, step_markers
from ..io.messages import (plan_feedback_to_dict, plan_goal_from_dict, plan_result_to_dict,
                           poses_to_dict, report_header, report_to_dict, state_to_dict)
from ..io.cell_file import read_cell
from ..io.plan_export import plan_cell
from ..io.plans import INVALID_CELL
from ..io.execution import (EXECUTION, LOOKAHEAD_STEPS, MIN_MARGIN_G, Execution,
                             NodeReport, Settings)
from ..io.poses import AsBuilt
from ..io.replay import (DESIGN, EXECUTION_TYPE, OPTIONS_KEY, PLAN_GOAL_TYPE, PLAN_RESULT_TYPE,
                         PLAN_UPDATE_TYPE, POSES, SETTINGS_TYPE, asbuilt_check, merge_message,
                         options_to_json, settings_dict)
from ..rbe.result import Report, Status
from ..cell import CellError, cell_to_dict
from ..scene import Scene, SceneError
from .convert import dict_to_message, message_to_dict, scene_from_msg
from .diagnostics import PERIOD_S as DIAGNOSTICS_PERIOD_S
from .diagnostics import TOPIC as DIAGNOSTICS_TOPIC
from .diagnostics import NodeHealth
from .workers import Workers

NODE_NAME = "rbe_node"
#: At most one INFO line per this many seconds sums up the reports (a line per report at
#: 10 Hz buries what matters); unstable verdicts are WARN lines of their own.
LOG_SUMMARY_S = 10.0

#: Depth 1: under overload only the newest state matters (see the single-slot buffer).
STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: Measured poses: every update counts (the node merges each into the as-built state).
POSES_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: Reports and markers are latched: a late subscriber gets the last verdict.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


_PARAMETER_TYPES = {float: ParameterType.PARAMETER_DOUBLE, int: ParameterType.PARAMETER_INTEGER,
                    bool: ParameterType.PARAMETER_BOOL, str: ParameterType.PARAMETER_STRING}


def _descriptor(option: Option) -> ParameterDescriptor:
    """The parameter descriptor of a check option (type, range or choices, help)."""
    descriptor = ParameterDescriptor(type=_PARAMETER_TYPES[option.kind],
                                     description=option.help)
    if option.choices:
        descriptor.additional_constraints = "one of: " + ", ".join(option.choices)
    elif option.kind is float:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(option.low), to_value=float(option.high), step=0.0)]
    elif option.kind is int:
        descriptor.integer_range = [IntegerRange(from_value=int(option.low),
                                                 to_value=int(option.high), step=1)]
    return descriptor


def _string(value: str, description: str, *, read_only: bool = False) -> tuple:
    return value, ParameterDescriptor(type=ParameterType.PARAMETER_STRING,
                                      description=description, read_only=read_only)


def _double(low: float, high: float, description: str, *, read_only: bool = False) -> tuple:
    """A float parameter from ``low`` (its default: off) to ``high``."""
    return low, ParameterDescriptor(
        type=ParameterType.PARAMETER_DOUBLE, description=description, read_only=read_only,
        floating_point_range=[FloatingPointRange(from_value=low, to_value=high, step=0.0)])


#: The node's parameters: every check option with a parameter (rbe_ros.analysis.option_spec),
#: and those of the node itself.
PARAMETERS = {
    **{o.param: (o.default, _descriptor(o)) for o in OPTIONS if o.param},
    "design_file": _string("", "design (a scene JSON or a COMPAS Assembly JSON, *.gz too) "
                           "whose blocks ~/poses places, as if sent on ~/design at start; "
                           "empty: none until one comes on ~/design", read_only=True),
    "cell_file": _string("", "robot cell (JSON or YAML, rbe-ros plan --cell) of every ~/plan "
                         "goal whose cell is empty; empty: K holds plus one placing robot"),
    "mcap_path": _string("", "directory of a rosbag2 MCAP bag recording every received state "
                         "and every report; empty: no recording. An existing directory gets "
                         "a timestamp suffix", read_only=True),
    "frame_id": _string("world", "frame of reports and markers when a received state has an "
                        "empty header frame_id"),
    "foxglove_port": (0, ParameterDescriptor(
        type=ParameterType.PARAMETER_INTEGER, read_only=True,
        description="TCP port of a Foxglove WebSocket server sending the markers of every "
        "report as SceneUpdates on /rbe_node/scene (foxglove-sdk); 0: no server",
        integer_range=[IntegerRange(from_value=0, to_value=65535, step=1)])),
    "foxglove_host": _string("127.0.0.1", "address the Foxglove WebSocket server listens on "
                             "(0.0.0.0: every interface)", read_only=True),
    "record_markers": (True, ParameterDescriptor(
        type=ParameterType.PARAMETER_BOOL, description="with mcap_path: record the markers of "
        "every report too (false: a lean log of states and reports)")),
    "marker_rate_hz": _double(
        0.0, 1000.0, "markers of at most this many reports a second are drawn, published and "
        "recorded (the newest report's always, at most 1/rate s late); 0: every report's"),
    "max_bag_size_mb": _double(
        0.0, 1e6, "with mcap_path: begin the next file of the bag (name_1.mcap, ...) when one "
        "reaches this many MB (10^6 bytes); each file replays alone (settings, design and the "
        "poses measured so far written again at its start); 0: no split by size",
        read_only=True),
    "max_bag_duration_s": _double(
        0.0, 1e7, "with mcap_path: begin the next file of the bag when one spans this many "
        "seconds; 0: no split by duration", read_only=True),
    "lookahead_steps": (LOOKAHEAD_STEPS, ParameterDescriptor(
        type=ParameterType.PARAMETER_INTEGER,
        description="~/execution: the next this many steps of the plan are checked with the "
        "placed blocks at their measured poses and the rest at design; 0: to the end",
        integer_range=[IntegerRange(from_value=0, to_value=100000, step=1)])),
    "min_margin_g": _double(
        MIN_MARGIN_G, 10.0, "~/execution: a look-ahead step whose stability margin (share of "
        "g) is below this fails, and the plan is repaired; 0: off"),
}

#: How often a report's markers held back by ``marker_rate_hz`` are looked at.
MARKER_POLL_S = 0.05


class ConfigurationError(Exception):
    """The node cannot start with its parameters (a bag that cannot be created)."""


class RbeChecks:
    """What the plain and the managed node share (mixed into an rclpy Node): parameters,
    publishers, recording, and the check interfaces that :meth:`_start_interfaces` opens and
    :meth:`_stop_interfaces` closes; the checks themselves."""

    def _setup(self) -> None:
        """Declare the parameters; the state, publishers and diagnostics of the node."""
        self._closing = False
        self._destroyed = False
        self._actions: list = []
        # ~/plan: one plan at a time; the newest goal preempts the one running
        self._plan_lock = threading.Lock()
        self._plan_newest = None
        self._interfaces: list = []     # subscriptions and service, while open
        self._bag = None
        self._bag_lock = threading.Lock()
        # bag topics not added yet: type, latched, whether a file may begin with one
        self._later_topics: dict[str, tuple[str, bool, bool]] = {}
        # Overload: the subscription callback only puts the state in this one slot (a newer
        # state replaces a waiting one, counted in _dropped); the worker thread checks it.
        # CDR of the newest unchecked state, or an as-built state: (header, scene or error)
        self._slot: bytes | tuple | None = None
        self._slot_cond = threading.Condition()
        self._dropped = 0
        # a managed node keeps its topic subscriptions while inactive: what arrives in a
        # pause is recorded, designs and poses merged (an incremental camera's blocks are not
        # lost), and the newest waits in the slot, checked first at the next activate
        self._paused = False
        self._paused_messages = 0
        self._topics: list = []         # the topic subscriptions, while open
        self._worker: threading.Thread | None = None
        # the design and the poses measured so far (~/design, ~/poses): updated in the
        # callbacks, so that no measurement is lost when its check is dropped under overload
        self._asbuilt = AsBuilt()
        self._asbuilt_lock = threading.RLock()
        self.foxglove = None
        # ~/execution: the plan under execution, advanced by its own thread from the as-built
        # states the worker checked (the newest; a design never dropped), so that looking
        # ahead and repairing hold up no as-built check but that of a state with a block
        # placed since (which waits for the plan's holds at its step: _holding); repairs
        # run in a process
        self._execution = Execution()
        self._designs = 0               # designs merged; the one the execution follows
        self._plan_cell = None          # the robot cell of the plan sent last with a design
        self._design_name = ""          # the name of the design sent last ("": its frame)
        self._exec_design = 0
        self._exec_slot: dict = {}
        self._exec_running: tuple = (None, None)     # (design, as-built scene) advanced now
        self._exec_cond = threading.Condition()
        self._exec_thread: threading.Thread | None = None
        self._workers: Workers | None = None    # plans and repairs: processes of their own

        self.add_on_set_parameters_callback(self._validate_parameters)
        for name, (value, descriptor) in PARAMETERS.items():
            self._declare(name, value, descriptor)

        # States on the topic are checked in order; the service has its own group so that a
        # long sequence on the topic does not block it; action callbacks are reentrant so a
        # cancel request (and other goals) are served while a goal executes.
        self._topic_group = MutuallyExclusiveCallbackGroup()
        self._service_group = MutuallyExclusiveCallbackGroup()
        self._action_group = ReentrantCallbackGroup()

        # reports go out as CDR bytes made from their message dicts (rbe_ros.io.cdr), without
        # building the rclpy message (an object per Point) and serialising it
        self._encode_report = cdr.encoder(typestore(), "rbe_msgs/msg/StabilityReport")
        self._encode_markers = cdr.encoder(typestore(), MARKER_TYPE)
        self._encode_plan = cdr.encoder(typestore(), PLAN_RESULT_TYPE)
        self._encode_execution = cdr.encoder(typestore(), EXECUTION_TYPE)
        self._encode_update = cdr.encoder(typestore(), PLAN_UPDATE_TYPE)
        self._execution_pub = self.create_publisher(ExecutionState, "~/execution", LATCHED_QOS)
        self._update_pub = self.create_publisher(PlanUpdate, "~/plan_update", LATCHED_QOS)
        self._report_pub = self.create_publisher(StabilityReport, "~/report", LATCHED_QOS)
        self._marker_pub = self.create_publisher(MarkerArray, "~/markers", LATCHED_QOS)

        # /diagnostics about once a second, from the counters the node keeps as it works
        self.health = NodeHealth()
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, 10)
        self._diagnostics_timer = self.create_timer(
            DIAGNOSTICS_PERIOD_S, self._publish_diagnostics,
            callback_group=MutuallyExclusiveCallbackGroup())

        self.state_topic = self.resolve_topic_name("~/assembly")
        self.report_topic = self._report_pub.topic_name
        self.design_topic = self.resolve_topic_name("~/design")
        self.poses_topic = self.resolve_topic_name("~/poses")
        self.marker_topic = self._marker_pub.topic_name
        self.plan_goal_topic = self.resolve_topic_name("~/plan/goal")
        self.plan_result_topic = self.resolve_topic_name("~/plan/result")
        self.execution_topic = self._execution_pub.topic_name
        self.plan_update_topic = self._update_pub.topic_name
        # marker_rate_hz: the markers of the newest report held back, sent when their time
        # comes (polled while one waits)
        self._marker_lock = threading.Lock()
        self._markers_at = -math.inf
        self._markers_waiting: tuple | None = None
        # a cell plan under execution: the robots (drawn at the last as-built state) go with
        # every report's markers, and the last report's blocks with the robots' (each array
        # begins with a DELETEALL: either alone would wipe the other in a viewer)
        self._report_markers: list[dict] = []
        self._robot_markers: list[dict] = []
        self._marker_timer = self.create_timer(MARKER_POLL_S, self._markers_due,
                                               callback_group=MutuallyExclusiveCallbackGroup())
        self._marker_timer.cancel()
        self.add_post_set_parameters_callback(self._parameters_set)
        # the report log (_log_report): verdict counts since the last summary line
        self._log_lock = threading.Lock()
        self._log_counts: dict[str, int] = {}
        self._log_since = time.monotonic() - LOG_SUMMARY_S     # the first report: a line
        self._last_verdict = None

    def _declare(self, name: str, value, descriptor: ParameterDescriptor) -> None:
        """Declare a parameter; an integer given for a float one (``-p
        max_bag_duration_s:=120``: the launch line cannot say 120.0) is taken as that float,
        not refused with a FATAL at start."""
        given = self._parameter_overrides.get(name)
        if descriptor.type == ParameterType.PARAMETER_DOUBLE and given is not None and \
                given.type_ == Parameter.Type.INTEGER:
            self._parameter_overrides[name] = Parameter(name, value=float(given.value))
        self.declare_parameter(name, value, descriptor)

    def _start_foxglove(self) -> None:
        if self.get_parameter("foxglove_port").value:
            self.foxglove = SceneServer(self.get_parameter("foxglove_port").value,
                                        self.get_parameter("foxglove_host").value, NODE_NAME)
            self.get_logger().info(f"Foxglove WebSocket server on port {self.foxglove.port}")

    def _start_interfaces(self) -> None:
        """Subscribe the state topics, serve ~/check, ~/check_sequence and ~/plan, start the
        worker."""
        self._closing = False
        # raw: the callback gets the CDR bytes; a state is converted to a message only when
        # the worker checks it (converting every state that arrives would hold the GIL and
        # starve the checks at high rates)
        if not self._topics:
            self._topics = [
                self.create_subscription(AssemblyState, "~/assembly", self._on_state,
                                         STATE_QOS, callback_group=self._topic_group, raw=True),
                self.create_subscription(AssemblyState, "~/design", self._on_design,
                                         LATCHED_QOS, callback_group=self._topic_group,
                                         raw=True),
                # deep: each update carries measurements that later checks build on
                self.create_subscription(BlockPoses, "~/poses", self._on_poses, POSES_QOS,
                                         callback_group=self._topic_group, raw=True)]
        self._interfaces = [self.create_service(CheckAssembly, "~/check", self._on_check,
                                                callback_group=self._service_group)]
        self._actions = [ActionServer(
            self, action, name, execute_callback=execute,
            goal_callback=lambda _goal: GoalResponse.ACCEPT,
            cancel_callback=lambda _goal: CancelResponse.ACCEPT,
            callback_group=self._action_group)
            for action, name, execute in ((CheckSequence, "~/check_sequence",
                                           self._execute_sequence),
                                          (PlanSequence, "~/plan", self._execute_plan))]
        with self._slot_cond, self._exec_cond:
            if self._slot is not None:      # a newer state waits: its execution comes next
                self._exec_slot.pop("state", None)
        self._worker = threading.Thread(target=self._work, name="rbe_state_worker", daemon=True)
        self._worker.start()
        self._exec_thread = threading.Thread(target=self._execute_work, name="rbe_execution",
                                             daemon=True)
        self._exec_thread.start()
        with self._slot_cond:
            self._paused, paused = False, self._paused_messages
            self._paused_messages = 0
        self.health.set_active(True)
        if paused:
            self.get_logger().warning(
                f"{paused} messages on {self.state_topic}, {self.design_topic} or "
                f"{self.poses_topic} arrived while inactive: designs and poses merged, the "
                "newest message checked first now (the others counted in dropped_states)")
        self.get_logger().info(
            f"ready: {self.state_topic} -> {self.report_topic}, service "
            f"{self._interfaces[-1].service_name}, "
            f"mu {self.get_parameter('friction_coefficient').value}")

    def _stop_interfaces(self, pause: bool = False) -> None:
        """Stop the worker (a running check ends after its current step) and close what
        :meth:`_start_interfaces` opened. Idempotent. ``pause``: keep the topic
        subscriptions, counting what arrives until the next start (deactivate keeps the
        latched design from coming again, and the measured poses with it)."""
        with self._slot_cond:
            self._paused = pause
        self.health.set_active(False)
        self.stop()
        for name in ("_worker", "_exec_thread"):
            worker = getattr(self, name)
            setattr(self, name, None)
            if worker is not None and worker is not threading.current_thread():
                worker.join(timeout=10.0)
                if worker.is_alive():
                    self.get_logger().warning(f"{worker.name} is still working; closing anyway")
        for service in self._interfaces:
            self.destroy_service(service)
        self._interfaces = []
        if not pause:
            for subscription in self._topics:
                self.destroy_subscription(subscription)
            self._topics = []
        for action in self._actions:
            action.destroy()
        self._actions = []

    # --- parameters -------------------------------------------------------------------------

    def _validate_parameters(self, params) -> SetParametersResult:
        for p in params:
            option = BY_PARAM.get(p.name)
            problem = option.problem(p.value) if option is not None else None
            if problem is not None:
                return SetParametersResult(successful=False, reason=f"{p.name} {problem}")
        return SetParametersResult(successful=True)

    def _parameters_set(self, params) -> None:
        """Record the new settings (for replay) and say in the log what changed."""
        self._record_settings()
        self.get_logger().info("parameters set: " + ", ".join(f"{p.name} = {p.value!r}"
                                                              for p in params))

    def check_options(self) -> CheckOptions:
        """The core's options from the current parameter values."""
        return from_outer({o: self.get_parameter(o.param).value for o in OPTIONS if o.param})

    # --- recording --------------------------------------------------------------------------

    def _open_bag(self) -> None:
        raw = self.get_parameter("mcap_path").value
        if not raw:
            return
        path = Path(raw).expanduser()
        if path.exists():
            stem, k = f"{path.name}_{time.strftime('%Y%m%d-%H%M%S')}", 0
            path = path.with_name(stem)
            while path.exists():
                k += 1
                path = path.with_name(f"{stem}_{k}")
        # the options at the start, so that `rbe-ros replay` re-checks the same way
        try:
            self._bag = BagWriter(
                path, custom_data={OPTIONS_KEY: options_to_json(self.check_options())},
                max_bytes=int(self.get_parameter("max_bag_size_mb").value * 1e6),
                max_duration_ns=int(self.get_parameter("max_bag_duration_s").value * 1e9))
        except OSError as exc:
            raise ConfigurationError(f"mcap_path {raw!r}: cannot create the bag {path}: "
                                     f"{exc.strerror or exc}") from None
        self._bag.add_topic(self.state_topic, "rbe_msgs/msg/AssemblyState")
        # a report and its markers stay in the file of their state (a split file replays)
        self._bag.add_topic(self.report_topic, "rbe_msgs/msg/StabilityReport",
                            transient_local=True, splits=False)
        self._bag.add_topic(self.marker_topic, MARKER_TYPE, transient_local=True, splits=False)
        # added with their first message: a bag of states alone has only their topics
        self.settings_topic = f"{self.get_fully_qualified_name()}/settings"
        self._bag.add_topic(self.settings_topic, SETTINGS_TYPE, transient_local=True)
        # an execution state or plan update stays in the file of its poses, as a report
        self._later_topics = {self.design_topic: ("rbe_msgs/msg/AssemblyState", True, True),
                              self.poses_topic: ("rbe_msgs/msg/BlockPoses", False, True),
                              self.plan_goal_topic: (PLAN_GOAL_TYPE, False, True),
                              self.plan_result_topic: (PLAN_RESULT_TYPE, False, True),
                              self.execution_topic: (EXECUTION_TYPE, True, False),
                              self.plan_update_topic: (PLAN_UPDATE_TYPE, True, False)}
        self.bag_path = path
        self.get_logger().info(f"recording states and reports to {path}")

    def _record(self, topic: str, msg, stamp_ns: int | None = None) -> None:
        """Write ``msg`` (a message, or its CDR bytes) to the bag, if recording."""
        if self._bag is None:
            return
        data = msg if isinstance(msg, (bytes, bytearray)) else serialize_message(msg)
        stamp = self.get_clock().now().nanoseconds if stamp_ns is None else stamp_ns
        with self._bag_lock:
            if self._bag is None:
                return
            try:
                if topic in self._later_topics:
                    msgtype, latched, splits = self._later_topics.pop(topic)
                    self._bag.add_topic(topic, msgtype, transient_local=latched, splits=splits)
                self._bag.write(topic, data, stamp)
                self.health.recorded(len(data))
            except Exception as exc:  # a full disk must not stop the checks
                self.get_logger().error(f"recording to {self.bag_path} failed, stopped: {exc}")
                self.health.error(f"recording to {self.bag_path} failed, stopped: {exc}")
                self._close_bag_locked()

    def _carry(self, topic: str, message) -> None:
        """Write ``message`` (CDR bytes, or a callable making a message dict) again at the
        start of every later file of a split bag, so that one file alone replays."""
        with self._bag_lock:
            if self._bag is not None and topic not in self._later_topics:
                self._bag.carry(topic, message)

    def _record_settings(self) -> None:
        """Record the check options and frame_id now in force (at the start and after every
        parameter change), so that a replay checks each state with what it was checked with."""
        if self._bag is None:
            return
        settings = settings_dict(self.check_options(), self.get_parameter("frame_id").value,
                                 self._execution_settings(), self._plan_cell,
                                 self._design_name)
        data = serialize_message(String(data=json.dumps(settings, sort_keys=True)))
        self._record(self.settings_topic, data)
        self._carry(self.settings_topic, data)

    def _publish_diagnostics(self) -> None:
        self._diagnostics_pub.publish(self.health.message(
            self.get_fully_qualified_name(), self.get_clock().now().to_msg()))

    def _close_bag_locked(self) -> None:
        bag, self._bag = self._bag, None
        if bag is not None:
            try:
                bag.close()
            except Exception as exc:
                self.get_logger().error(f"closing the bag {self.bag_path} failed: {exc}")

    def stop(self) -> None:
        """Ask running checks to stop after their current step (shutdown); the state
        worker exits, a state still waiting is dropped."""
        self._closing = True
        with self._slot_cond:
            self._slot_cond.notify_all()
        with self._exec_cond:
            self._exec_cond.notify_all()

    def _close_workers(self) -> None:
        workers, self._workers = self._workers, None
        if workers is not None:
            workers.close()

    def close_bag(self) -> None:
        with self._bag_lock:
            self._close_bag_locked()

    def _close_outputs(self) -> None:
        """Close the bag, the Foxglove server and the worker processes. Idempotent."""
        self._close_workers()
        self.close_bag()
        server, self.foxglove = self.foxglove, None
        if server is not None:
            server.stop()

    def destroy_node(self):
        """Close the interfaces, the bag and the Foxglove server, then the node. Idempotent."""
        self._stop_interfaces()
        self._close_outputs()
        if self._destroyed:
            return
        self._destroyed = True
        super().destroy_node()

    # --- checks -----------------------------------------------------------------------------

    def _received(self, state, raw: bytes | None = None, topic: str | None = None) -> dict:
        """Record ``state`` (its CDR bytes ``raw`` if given) on ``topic`` (default: the
        state topic) and return the header dict its reports carry."""
        self._record(topic or self.state_topic, state if raw is None else raw)
        return report_header(message_to_dict(state.header), self.get_parameter("frame_id").value)

    def _publish(self, scene: Scene | None, report: Report, header: dict,
                 state: AssemblyState | None = None) -> bytes:
        """Record, then publish ``report`` and its markers; returns the report's CDR bytes
        (``deserialize_message(data, StabilityReport)`` where a message is needed). Recorded
        first, so that a report anyone received is in the bag even if the node is killed.
        ``state``: the state of a check that failed, drawn as it came (the blocks at fault
        of invalid input highlighted)."""
        report = replace(report, dropped_states=self._dropped)
        self.health.reported(report)
        data = self._encode_report(report_to_dict(report, header, arrays=True))
        self._record(self.report_topic, data)
        self._report_pub.publish(data)
        self._markers_of(scene, report, header, state)
        where = f" step {report.step_index} ({report.block_placed})" \
            if report.step_index >= 0 else ""
        # the scene's own name where the node knows one (a design file's), with the frame
        frame = header["frame_id"]
        name = frame if scene is None or scene.name in (frame, "assembly") else \
            f"{scene.name} ({frame})"
        self._log_report(f"{name}{where}: {report.status.name}: {report.message}", report)
        return data

    def _markers_of(self, scene: Scene | None, report: Report, header: dict,
                    state: AssemblyState | None) -> None:
        """Send the markers of ``report`` now, or with ``marker_rate_hz`` when their time
        comes (a newer report's replace them while they wait: drawing, sending and recording
        a 300-block wall's markers at 10 Hz is most of a bag and of the node's time)."""
        rate = self.get_parameter("marker_rate_hz").value
        with self._marker_lock:
            now = time.monotonic()
            if rate > 0 and now < self._markers_at + 1.0 / rate:
                self._markers_waiting = (scene, report, header, state)
                self._marker_timer.reset()
                return
            self._markers_at, self._markers_waiting = now, None
        self._send_markers(scene, report, header, state)

    def _markers_due(self) -> None:
        """Timer: send the markers waiting once their time has come."""
        rate = self.get_parameter("marker_rate_hz").value
        with self._marker_lock:
            now = time.monotonic()
            waiting = self._markers_waiting
            if waiting is not None and rate > 0 and now < self._markers_at + 1.0 / rate:
                return
            self._markers_at, self._markers_waiting = now, None
            self._marker_timer.cancel()
        if waiting is None:
            return
        try:
            self._send_markers(*waiting)
        except Exception as exc:    # never out of a timer callback (it would end the spin)
            self.get_logger().error(f"markers not sent: {type(exc).__name__}: {exc}")

    def _send_markers(self, scene: Scene | None, report: Report, header: dict,
                      state: AssemblyState | None) -> None:
        """Draw, publish (and record) the markers of ``report`` (``state``: drawn as it
        came, a check that failed)."""
        if state is None:
            markers = step_markers(scene, report, header)
        else:
            [markers] = run_markers(self._drawable(state), [report_to_dict(report, header)],
                                    self.check_options())
        with self._marker_lock:
            self._report_markers = markers["markers"]
            if self._robot_markers:
                markers = {"markers": [*markers["markers"], *self._robot_markers]}
        self._publish_markers(markers)

    def _publish_markers(self, markers: dict) -> None:
        """Publish (and record, and send to Foxglove) a MarkerArray dict."""
        if self.foxglove is not None:
            self.foxglove.publish(markers)
        markers = self._encode_markers(markers)
        if self.get_parameter("record_markers").value:
            self._record(self.marker_topic, markers)
        self._marker_pub.publish(markers)

    def _log_report(self, text: str, report: Report) -> None:
        """A failed check at ERROR, an unstable verdict at WARN when it differs from the
        previous report's (a wall that keeps falling at 10 Hz is one line), and at most every
        :data:`LOG_SUMMARY_S` one INFO line counting the verdicts since the last one."""
        # one call site per severity: rclpy refuses a call site whose severity changes
        # ("Logger severity cannot be changed between calls")
        verdict = (report.status, report.step_index, report.message)
        with self._log_lock:
            changed, self._last_verdict = verdict != self._last_verdict, verdict
            self._log_counts[report.status.name] = self._log_counts.get(report.status.name,
                                                                        0) + 1
            now = time.monotonic()
            summary = None
            if now - self._log_since >= LOG_SUMMARY_S:
                counts = ", ".join(f"{n} {k}" for k, n in sorted(self._log_counts.items()))
                summary = f"{sum(self._log_counts.values())} reports in " \
                    f"{now - self._log_since:.0f} s ({counts}); last: {text}"
                self._log_counts, self._log_since = {}, now
        if report.status == Status.SOLVER_FAILED:
            self.get_logger().error(text)
        elif not report.stable and changed:
            self.get_logger().warning(text)
        if summary is not None:
            self.get_logger().info(summary)

    def _drawable(self, state: AssemblyState) -> dict:
        """The message dict of an unchecked ``state`` to draw, if within the block limit."""
        within = len(state.blocks) <= self.get_parameter("max_blocks").value
        return message_to_dict(state) if within else {}

    def check(self, state: AssemblyState, header: dict, sequence: bool, *,
              cancelled=None, on_step=None) -> tuple[StateCheck, list[bytes]]:
        """Check ``state`` (every step, or the whole assembly: ``sequence``) through the
        dispatch replay uses too (:func:`check_state`), publishing each report; never raises.
        ``on_step(report, data, total)`` gets each step's report and its CDR bytes once
        published. Returns the check and the CDR bytes of every report published."""
        sent: list[bytes] = []

        def read(with_sequence: bool) -> Scene:
            return self._repaired(scene_from_msg(state, sequence=with_sequence,
                                                 limits=options.limits))

        def publish(report: Report, scene: Scene, total: int) -> None:
            report = self._second_opinion(scene, report, sequence, options)
            sent.append(self._publish(scene, report, header))
            if on_step is not None:
                on_step(report, sent[-1], total)

        def stop() -> bool:
            return self._closing or (cancelled is not None and cancelled())

        options = self.check_options()
        result = check_state(read, sequence, options, on_step=publish, cancelled=stop)
        if result.error is not None:
            sent.append(self._publish(result.scene, result.error, header, state))
        return result, sent

    def _second_opinion(self, scene: Scene, report: Report, sequence: bool,
                        options) -> Report:
        """``report`` with the second opinion (parameter ``second_opinion``) of its state at
        the end of its message, logged (a warning where it disagrees or is unavailable);
        StabilityReport has no field for it."""
        if options.second_opinion == "none":
            return report
        try:
            opinion = lmgc90.second_opinions(scene, [report], options, sequence)[0]
            line = lmgc90.describe(opinion, report.solve_time, report.status.name)
            agrees = opinion["agrees"]
        except lmgc90.NotInstalled as exc:
            line, agrees = f"second opinion unavailable: {exc}", None
        (self.get_logger().info if agrees else self.get_logger().warning)(
            f"step {report.step_index}: {line}")
        return replace(report, message=f"{report.message} | {line}")

    def check_whole(self, state: AssemblyState, header: dict) -> bytes:
        """Check the assembly of ``state`` as it is (sequence ignored); publish the report
        and return its CDR bytes."""
        return self.check(state, header, False)[1][-1]

    def _on_state(self, data: bytes) -> None:
        """Subscription callback (raw CDR): put the state in the slot for the worker (never
        blocks on a check)."""
        self._put(data)

    def _put(self, data: bytes | tuple) -> None:
        """Put a state (CDR) or an as-built state in the slot for the worker; one still
        waiting there is dropped and counted. While inactive the newest waits there for the
        next activate (the robot's first verdict is of its newest state, not of one that
        waited through the pause)."""
        with self._slot_cond:
            stale, self._slot = self._slot, data
            paused = self._paused
            self._paused_messages += paused
            if stale is not None:
                self._dropped += 1
                dropped = self._dropped
                self.health.dropped_count(dropped)
            self._slot_cond.notify()
        if stale is not None and not paused:
            stamp = _cdr_stamp(stale) if isinstance(stale, bytes) else _stamp(stale[0])
            self.get_logger().warning(
                f"overload: state of stamp {stamp} dropped unchecked, a newer one"
                f" arrived first ({dropped} dropped so far)", throttle_duration_sec=1.0)

    def _work(self) -> None:
        """The state worker: check the newest waiting state, until the node stops."""
        while True:
            with self._slot_cond:
                while self._slot is None and not self._closing:
                    self._slot_cond.wait()
                if self._closing:
                    return
                data, self._slot = self._slot, None
            try:
                if isinstance(data, tuple):
                    self._check_asbuilt(*data)
                    continue
                try:
                    state = deserialize_message(data, AssemblyState)
                except Exception as exc:
                    self.get_logger().error(f"state of stamp {_cdr_stamp(data)} not readable:"
                                            f" {type(exc).__name__}: {exc}")
                    continue
                self.check_state(state, data)
            except Exception:   # only logging can fail here (shutdown): keep the thread quiet
                pass

    def check_state(self, state: AssemblyState, raw: bytes | None = None) -> None:
        """Check a state from the topic (as a whole, or every step of its sequence) and
        publish the reports; never raises. ``raw``: its CDR bytes, recorded as they came.
        A newer state waiting in the slot supersedes a sequence between two steps: its last
        report says so (:func:`superseded_report`), and the newer state is checked next."""
        try:
            header = self._received(state, raw)
            result, _ = self.check(state, header, bool(state.sequence),
                                   cancelled=self._superseded)
            if result.error is None and not result.finished and self._superseded():
                self._publish(result.scene, superseded_report(result), header)
        except Exception as exc:  # publishing itself failed (e.g. during shutdown)
            self.get_logger().error(f"state not handled: {type(exc).__name__}: {exc}")

    def _superseded(self) -> bool:
        """Whether a newer state (or as-built update) waits for the worker."""
        return self._slot is not None

    # --- design and measured poses (rbe_ros.poses) -------------------------------------------

    def _on_design(self, data: bytes) -> None:
        """A design (raw CDR): recorded, the poses measured so far forgotten; the supports
        alone are checked (nothing measured yet)."""
        self._on_asbuilt(data, AssemblyState, self.design_topic, DESIGN)

    def _on_poses(self, data: bytes) -> None:
        """Measured poses (raw CDR): recorded, merged into the as-built state (an update
        that cannot be merged changes nothing and is answered INVALID_INPUT)."""
        self._on_asbuilt(data, BlockPoses, self.poses_topic, POSES)

    def _on_asbuilt(self, data: bytes, msg_type, topic: str, kind: str, cell=None,
                    unread: str = "", name: str = "") -> None:
        """Record a design or poses message, merge it into the as-built state
        (:func:`rbe_ros.replay.merge_message`) and put the result in the slot, inactive too
        (merged as an overload's dropped updates are); never raises. A design with a
        sequence is a plan for ``cell`` (recorded first with the settings, for its replay);
        one without keeps the plan's. ``unread``: the (empty) design stands for a design
        file that could not be read, and this is why: its report and those of the poses
        after it say so (a replay of the bag says the design has no blocks). ``name``: the
        design's (a message has none: "" names it after its frame), recorded with the
        settings."""
        try:
            msg = deserialize_message(data, msg_type)
            # recorded in the order merged (a replay merges them so): the topic callbacks
            # run one at a time, and a plan's design (_adopt) comes from another thread
            with self._asbuilt_lock:
                if kind == DESIGN and ((msg.sequence and cell != self._plan_cell)
                                       or name != self._design_name):
                    self._plan_cell = cell if msg.sequence else self._plan_cell
                    self._design_name = name
                    self._record_settings()
                header = self._received(msg, data, topic)
                try:
                    scene = self._asbuilt.set_design(None, unread) if unread else \
                        merge_message(self._asbuilt, kind, message_to_dict(msg),
                                      {"design_name": self._design_name})
                except SceneError as exc:
                    scene = exc
                # a later file of a split bag begins with the design and the poses measured
                # so far (stamp 0: no report answers it), so that it replays alone
                if kind == DESIGN:
                    self._carry(topic, data)
                    self._designs += 1
                    with self._exec_cond:
                        self._exec_slot["design"] = (self._designs, self._asbuilt.design,
                                                     self._plan_cell)
                        self._exec_cond.notify_all()    # taken at once (_holding)
                else:
                    self._carry(topic, self._measured_poses)
                self._put((header, scene, self._designs))
        except Exception as exc:
            self.get_logger().error(f"{topic}: message not handled: {type(exc).__name__}: "
                                    f"{exc}")

    def _measured_poses(self) -> dict:
        """The poses measured so far as one BlockPoses dict (stamp 0)."""
        return poses_to_dict(self._asbuilt.measured, self.get_parameter("frame_id").value)

    def _check_asbuilt(self, header: dict, scene, design: int) -> None:
        """Check an as-built scene (or report why there is none) as a whole for ~/report,
        handed to the plan's execution as it is made (``design``: the number of the design
        it was merged on): the execution begins at once, checking the first step ahead
        while this thread checks the state, then its repair while this thread asks the
        state's tolerance question (:class:`rbe_ros.io.execution.NodeReport`)."""
        options = self.check_options()
        held = self._holding(scene, design)
        made = NodeReport()
        with self._exec_cond:
            self._exec_slot["state"] = (header, scene, made, design, options)
            self._exec_cond.notify()
        report = None
        try:
            result = asbuilt_check(held, options,
                                   on_verdict=lambda verdict: made.decide(verdict, header))
            if result.error is None:
                report = result.reports[0]
                self._publish(result.scene, report, header)
            else:
                # drawn as a state that failed: what could be merged, the blocks at fault
                state = AssemblyState() if result.scene is None else \
                    dict_to_message(state_to_dict(result.scene), AssemblyState)
                report = result.error
                self._publish(None, report, header, state)
        finally:
            made.send(report, header)

    # --- plan execution (rbe_ros.io.execution) ----------------------------------------------

    def _holding(self, scene, design: int):
        """``scene`` with the holds of the plan under execution at its step
        (:meth:`Execution.holding`), once the execution has reached the design ``design``
        and advanced the states before it that place fewer blocks: a repair there may change
        the holds of this state's step (one of the blocks placed since), not of its own or
        an earlier one. So the plan is the one the replay, which executes each state before
        checking the next, has then (but for a state of a design that a newer one replaced
        before the execution took it: checked with the newer one's plan); the look-ahead
        and repair of a state with as many blocks placed (a cell's same poses at 10 Hz)
        hold nothing up."""
        placed = _free(scene)
        with self._exec_cond:
            while not self._closing and self._behind(design, placed):
                self._exec_cond.wait(0.5)
        return self._execution.holding(scene)

    def _behind(self, design: int, placed: int) -> bool:
        """Whether the execution has yet to reach the design ``design`` (a newer one may
        replace it in the slot: then that one), or to advance a state before (waiting or
        under way) with fewer than ``placed`` free blocks (called with ``_exec_cond``)."""
        if self._exec_design < design:
            return True
        waiting = self._exec_slot.get("state")
        states = [self._exec_running, (waiting[3], waiting[1]) if waiting else (None, None)]
        return any(built is not None and (d != design or _free(built) < placed)
                   for d, built in states)

    def _execution_settings(self) -> Settings:
        return Settings(self.get_parameter("lookahead_steps").value,
                        self.get_parameter("min_margin_g").value)

    def _execute_work(self) -> None:
        """The execution thread: advance the plan on the newest as-built state checked
        (a new design first), until the node stops."""
        while True:
            with self._exec_cond:
                while not self._exec_slot and not self._closing:
                    self._exec_cond.wait()
                if self._closing:
                    return
                slot, self._exec_slot = self._exec_slot, {}
                if "state" in slot:
                    self._exec_running = (slot["state"][3], slot["state"][1])
            try:
                if "design" in slot:
                    self._exec_design, design, cell = slot["design"]
                    self._execution.set_design(design, cell)
                    if self._execution.cell is None:
                        with self._marker_lock:
                            self._robot_markers = []
                    if self._execution.plan is not None:
                        self._pool().warm()     # a repair may come: its process ready
                if "state" in slot:
                    header, scene, report, design, options = slot["state"]
                    if design == self._exec_design:    # not of a design replaced since
                        self._advance(header, scene, report, options)
            except Exception as exc:   # publishing failed (shutdown): say so, go on
                self.get_logger().error(f"execution not advanced: {type(exc).__name__}: {exc}")
            finally:
                with self._exec_cond:   # the as-built checks waiting for it (_holding)
                    self._exec_running = (None, None)
                    self._exec_cond.notify_all()

    def _advance(self, header: dict, scene, report: NodeReport, options: CheckOptions
                 ) -> None:
        """Publish (and record) what the as-built state means for the plan: its
        ExecutionState, and a repaired plan when a step ahead fails (WARN); under the
        options ``report`` (~/report, as it is made) was checked with (whole: the look-ahead
        takes it as its check of the state, its interfaces too)."""
        self._execution.advance(scene, report, header, options, self._execution_settings(),
                                self._repair, self._send_execution)

    def _send_execution(self, kind: str, message: dict) -> None:
        """Record, then publish an ExecutionState or a PlanUpdate (the latter logged)."""
        if kind == EXECUTION:
            data = self._encode_execution(message)
            self._record(self.execution_topic, data)
            self._execution_pub.publish(data)
            if self._execution.cell is not None and message["active"]:
                self._send_cell_markers(message["header"])
        else:
            data = self._encode_update(message)
            self._record(self.plan_update_topic, data)
            self._update_pub.publish(data)
            self.get_logger().warning(
                f"plan repaired ({message['repair']}) from step {message['changed_step']}: "
                f"{message['reason']}; new order {' '.join(message['order'])}"
                if message["feasible"] else
                f"no repair found: {message['reason']}; {message['message']}")

    def _send_cell_markers(self, header: dict) -> None:
        """The robots of the cell plan under execution at the as-built state (bases, the
        busy robots' gripper boxes, the last action's force; :func:`rbe_ros.io.markers.
        cell_markers`, as the HTML view draws them) on ~/markers."""
        ex = self._execution
        if not ex.timeline:
            return
        centres = np.array([b.position for b in ex.plan.blocks])
        length = 0.3 * max(float(np.linalg.norm(np.ptp(centres, axis=0))), 0.5)
        robots = cell_markers(ex.cell, ex.timeline, ex.timeline_done, header, length)
        with self._marker_lock:
            self._robot_markers = robots
            markers = {"markers": [*self._report_markers, *robots]}
        self._publish_markers(markers)

    def _repair(self, plan: Scene, built: Scene, options: CheckOptions, settings: Settings,
                cell, checked):
        """The repair in a worker process (:mod:`rbe_ros.ros.workers`), the look-ahead's
        ``checked`` states sent with it."""
        return self._pool().repair(plan, built, options, settings, cell, checked)

    def _pool(self) -> Workers:
        """The worker processes (each spawned at its first use)."""
        if self._workers is None:
            self._workers = Workers()
        return self._workers

    def _repaired(self, scene: Scene) -> Scene:
        """``scene``, its repaired meshes logged (WARN, each naming the block)."""
        for warning in scene.warnings:
            self.get_logger().warning(warning)
        return scene

    def design_message(self, path: str) -> tuple[AssemblyState, str]:
        """The design of ``design_file`` as the message a pipeline would send on ~/design,
        and its scene name (a message has none; SceneError if it cannot be read)."""
        scene, _ = load_design(path)
        for warning in scene.warnings:
            self.get_logger().warning(f"design_file {path!r}: {warning}")
        if scene.pose_uncertainty is not None:
            self.get_logger().warning(
                f"design_file {path!r} declares pose_uncertainty {list(scene.pose_uncertainty)}"
                ": the node declares its own (parameters pose_uncertainty_m, _deg), which its "
                "bag records for replay")
        return dict_to_message(state_to_dict(scene, self.get_parameter("frame_id").value,
                                             self.get_clock().now().nanoseconds),
                               AssemblyState), scene.name

    def design_cell(self, path: str):
        """The robot cell a planned scene at ``path`` was planned for (``rbe-ros plan --cell
        -o``), None without one or when it cannot be read (logged: the plan is then executed
        with K holds)."""
        try:
            return plan_cell(path)
        except (SceneError, OSError, ValueError) as exc:
            self.get_logger().error(f"design_file {path!r}: its cell: {exc}; executed "
                                    "without a cell")
            return None

    def _send_design(self, state: AssemblyState, cell=None, *, name: str = "",
                     unread: str = "") -> None:
        """Through :meth:`_on_design`, so that it is recorded, and replayed, like one sent
        (``cell``: the robot cell a plan with a sequence is for; ``name``: the design's, a
        design file's scene name; ``unread``: why the design file could not be read, the
        design empty)."""
        self._on_asbuilt(serialize_message(state), AssemblyState, self.design_topic, DESIGN,
                         cell, unread, name)

    def _on_check(self, request: CheckAssembly.Request, response: CheckAssembly.Response):
        try:
            data = self.check_whole(request.assembly, self._received(request.assembly))
            response.report = deserialize_message(data, StabilityReport)
        except Exception as exc:
            self.get_logger().error(f"request not handled: {type(exc).__name__}: {exc}")
            response.report = StabilityReport(
                header=request.assembly.header, status=int(Status.SOLVER_FAILED), stable=False,
                message=f"check failed: {type(exc).__name__}: {exc}")
        return response

    def _execute_sequence(self, goal_handle) -> CheckSequence.Result:
        result = CheckSequence.Result(first_failing_step=-1)
        reports: list[StabilityReport] = []

        def on_step(report: Report, data: bytes, total: int) -> None:
            msg = deserialize_message(data, StabilityReport)
            reports.append(msg)
            if result.first_failing_step < 0 and not report.stable:
                result.first_failing_step = report.step_index
            goal_handle.publish_feedback(CheckSequence.Feedback(
                steps_done=len(reports), steps_total=total, last_report=msg))

        try:
            state = goal_handle.request.assembly
            check, sent = self.check(state, self._received(state), True, on_step=on_step,
                                     cancelled=lambda: goal_handle.is_cancel_requested)
            if check.error is not None:
                reports.append(deserialize_message(sent[-1], StabilityReport))
        except Exception as exc:
            self.get_logger().error(f"goal not handled: {type(exc).__name__}: {exc}")
            result.reports = reports
            goal_handle.abort()
            return result
        result.reports = reports
        if check.finished:
            goal_handle.succeed()
        elif check.error is None and goal_handle.is_cancel_requested:
            self.get_logger().info(f"sequence check canceled after {len(reports)}/"
                                   f"{check.total} steps")
            goal_handle.canceled()
        else:  # the state could not be checked, or shutting down
            goal_handle.abort()
        return result

    def _execute_plan(self, goal_handle) -> PlanSequence.Result:
        """Plan the goal's assembly (the goal and its result recorded), one plan at a time:
        a newer goal stops this one between two candidate checks (ABORTED), as a cancel does
        (CANCELED); the result is then the best partial plan."""
        try:
            return self._plan_goal(goal_handle)
        except Exception as exc:   # publishing or recording failed (e.g. during shutdown)
            message = f"plan failed: {type(exc).__name__}: {exc}"
            self.get_logger().error(f"plan goal not handled: {message}")
            goal_handle.abort()
            return PlanSequence.Result(message=message, failed_step=0)

    def _plan_goal(self, goal_handle) -> PlanSequence.Result:
        self._plan_newest = goal_handle
        goal = goal_handle.request
        path = self.get_parameter("cell_file").value
        if not goal.cell.strip() and path:
            # the goal is recorded with the cell it is planned for, so that its replay is too
            try:
                goal.cell = json.dumps(cell_to_dict(read_cell(path)))
            except CellError as exc:
                self._record(self.plan_goal_topic, goal)
                self.get_logger().error(f"plan goal aborted: cell_file {path!r}: {exc}")
                goal_handle.abort()
                return PlanSequence.Result(message=f"invalid input: {exc} (cell_file)",
                                           failed_step=0)
        self._record(self.plan_goal_topic, goal)
        header = report_header(message_to_dict(goal.assembly.header),
                               self.get_parameter("frame_id").value)
        _, limits = plan_goal_from_dict(message_to_dict(goal))

        def stopped() -> bool:
            return self._closing or goal_handle.is_cancel_requested or \
                self._plan_newest is not goal_handle

        def progress(p) -> None:
            goal_handle.publish_feedback(
                dict_to_message(plan_feedback_to_dict(p), PlanSequence.Feedback))

        with self._plan_lock:
            start = time.monotonic()
            # in a worker process: the as-built checks keep their pace meanwhile
            plan = self._pool().plan(serialize_message(goal.assembly), limits,
                                     self.check_options(), progress=progress,
                                     should_stop=stopped)
            data = self._encode_plan(plan_result_to_dict(plan, header))
            self._record(self.plan_result_topic, data)
        self.get_logger().info(f"plan of {header['frame_id']} ({len(goal.assembly.blocks)} "
                               f"blocks, at most {limits.max_held} held) in "
                               f"{time.monotonic() - start:.1f} s: {plan.message}")
        self._adopt(plan, header)       # only a feasible plan: never one refused for its cell
        if plan.message.startswith(INVALID_CELL):
            goal_handle.abort()         # a cell the plan cannot use: the reason in the result
        elif not plan.message.startswith(STOPPED) or not stopped():
            goal_handle.succeed()       # planned, infeasible, invalid, or its time limit
        elif goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.abort()         # preempted by a newer goal, or shutting down
        return deserialize_message(data, PlanSequence.Result)


    def _adopt(self, plan: Plan, header: dict) -> None:
        """A feasible plan of the design becomes the plan ~/execution follows while no block
        is measured: it is sent on as the design (recorded, so that a replay executes it
        too). Without a design nothing happens (a node asked only to plan stays silent)."""
        if not plan.feasible or plan.scene is None or self._asbuilt.design is None:
            return
        why = ""
        with self._asbuilt_lock:
            if self._asbuilt.measured:
                why = f"{len(self._asbuilt.measured)} blocks are measured already (send a " \
                      "design with a sequence to start again)"
            else:
                try:
                    check_plan_design(plan.scene, self._asbuilt.design)
                except SceneError as exc:
                    why = str(exc)
            if not why:
                self._send_design(dict_to_message(state_to_dict(
                    plan.scene, header["frame_id"], self.get_clock().now().nanoseconds),
                    AssemblyState), plan.timeline.cell if plan.timeline is not None else None,
                    name=self._asbuilt.design.name)
        self.get_logger().info(f"the plan is not executed: {why}" if why else
                               f"executing the plan: {' '.join(plan.order)}")


class RbeNode(RbeChecks, Node):
    """The plain node: checking from the start until shut down."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._setup()
        self._open_bag()
        self._record_settings()
        self._start_foxglove()
        self._start_interfaces()
        path = self.get_parameter("design_file").value
        if path:
            cell, unread, name = None, "", ""
            try:
                state, name = self.design_message(path)
                cell = self.design_cell(path)
            except SceneError as exc:   # answered as an empty design: INVALID_INPUT, why
                unread = f"design_file {path!r} could not be read: {exc} (send a design on " \
                    "~/design)"
                self.get_logger().error(unread)
                state = AssemblyState()
                state.header.frame_id = self.get_parameter("frame_id").value
                state.header.stamp = self.get_clock().now().to_msg()
            self._send_design(state, cell, name=name, unread=unread)


def _free(scene) -> int:
    """The free blocks of an as-built scene (0 for poses refused: a SceneError)."""
    return 0 if isinstance(scene, SceneError) else sum(not b.support for b in scene.blocks)


def _stamp(header: dict) -> str:
    stamp = header["stamp"]
    return f"{stamp['sec']}.{stamp['nanosec']:09d}"


def superseded_report(result: StateCheck) -> Report:
    """The last report of a topic sequence a newer state superseded: the first step not
    checked, no verdict (SOLVER_FAILED), and why."""
    done = len(result.reports)
    step = sequence_step(result.scene, done)
    return Report(Status.SOLVER_FAILED,
                  f"superseded: a newer state arrived after {done} of {result.total} steps; "
                  "the remaining steps were not checked",
                  step_index=step.index, block_placed=step.block)


def _cdr_stamp(data: bytes) -> str:
    """``sec.nanosec`` of the header stamp of a CDR-serialised AssemblyState (for the log)."""
    try:
        little = data[1] == 1                  # encapsulation CDR_LE (0x0001) or CDR_BE
        sec, nanosec = struct.unpack_from("<iI" if little else ">iI", data, 4)
    except (IndexError, struct.error):
        return "?"
    return f"{sec}.{nanosec:09d}"


def _interrupt(signum, _frame):
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _exit_now(signum, _frame):
    os._exit(128 + signum)


def main(args=None) -> None:
    """Run :class:`RbeNode` (see :func:`spin`)."""
    spin(RbeNode, args)


def spin(node_class, args=None) -> None:
    """Run a node of ``node_class`` until SIGINT/SIGTERM (or an external shutdown), then close
    everything.

    rclpy's own signal handling is off: its handler thread triggers the executor's guard
    condition and races with the executor's destruction at shutdown (a segfault in
    rcl_trigger_guard_condition in about one shutdown in ten here). Instead SIGINT and
    SIGTERM raise KeyboardInterrupt in the main thread, which spins in steps of 0.1 s, and
    the node (bag first) is destroyed before the context is shut down.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    node = None
    executor = None
    try:
        node = node_class()
        executor = MultiThreadedExecutor(num_threads=max(4, os.cpu_count() or 1))
        executor.add_node(node)
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ParameterException as exc:  # e.g. -p friction_coefficient:=high
        rclpy.logging.get_logger(NODE_NAME).fatal(f"bad parameter: {exc}")
        raise SystemExit(2) from None
    except ConfigurationError as exc:
        rclpy.logging.get_logger(NODE_NAME).fatal(str(exc))
        raise SystemExit(2) from None
    finally:
        # A second signal during the clean-up exits at once (the bag stays readable).
        signal.signal(signal.SIGINT, _exit_now)
        signal.signal(signal.SIGTERM, _exit_now)
        if node is not None:
            node.stop()
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
