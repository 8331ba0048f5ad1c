"""Replay of recorded runs: re-check the states of a bag and compare with its reports.

A *run* is one rbe_msgs/AssemblyState of a bag with the StabilityReports recorded for it
(matched by header stamp: a report carries the stamp of the state it answers). Replaying a
run re-checks the state exactly as ``rbe_node`` does: a state with a sequence step by step
(:func:`check_sequence`), one without as a whole (:func:`check_scene`), a state that cannot
be checked as an INVALID_INPUT report; reports get the state's header (frame "world" when
empty, the node's default ``frame_id``).

The check options are those stored in the bag (``custom_data`` key ``rbe_ros.check_options``
of metadata.yaml, JSON, written by :func:`record_bag`), else the defaults (the node's
default parameters), unless given.

:func:`compare_runs` compares recorded and replayed reports field by field (message dicts):

* exact: header, step index, block placed, stable, status, number of blocks, the model that
  answered, unstable / held / suggested blocks, the interface pairs (in order), their
  tension and friction flags and polygon / kern vertex counts;
* forces (vertex normal and tangential forces, resultant, N, V, max tension): within
  ``force`` (1e-6) times the free weight W of the step (the weight of its free blocks that
  are not held), the scale the solver works in;
* positions (polygon, kern vertices) and the unit normal: within ``position`` (1e-6 m);
  vertices are matched by position (their order, and so the order of the per-vertex forces,
  is not part of the result);
  centre of pressure: the same plus F d / max(|N|, F) (F the force tolerance, d the polygon
  diameter: it is a ratio of forces, ill-conditioned on an interface that carries little);
  torque: within F d;
* ratios |V|/N: within ``ratio`` (1e-6) plus F (1 + |V|/N) / max(N, F); infinite equals
  infinite;
* margin_g: within ``force`` (1e-6, a share of g); ``margin_direction`` is not
  compared (directions whose margins tie within rounding, as on a symmetric dome, may swap);
  ``insertion_direction`` (unit): within ``position`` (1e-6) per component, ``insertable``
  exact;
* not compared: ``solve_time`` (wall time), ``dropped_states`` (the node's load) and, unless
  ``Tolerances.message`` is set, the message: it names one of the most loaded interfaces,
  and of equally loaded ones (a symmetric arch) rounding picks which; with a tolerance (e.g.
  1e-3) the text with its numbers taken out must be equal and the numbers (printed to 3-4
  significant digits) equal within it, relative.
"""
from __future__ import annotations

import json
import math
import re
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..analysis.option_spec import from_json as options_from_json
from ..analysis.option_spec import to_json as options_to_json
from ..analysis.options import CheckOptions
from ..analysis.pipeline import StateCheck, check_state
from ..analysis.planning import STOPPED
from ..analysis.steps import final_state, sequence_steps
from ..geometry.block import pose_block
from ..rbe.result import NOT_COMPUTED, Report
from ..cell import Cell, cell_from_dict, cell_to_dict
from ..scene import Scene, SceneError
from .bag import BagWriter, read_custom_data, read_raw, typestore
from .cdr import Repeats
from .markers import MARKER_TOPIC, MARKER_TYPE, run_markers
from .messages import (header_stamp_ns, plan_goal_from_dict, plan_result_to_dict,
                       poses_from_dict, report_header, report_to_dict, scene_from_state_dict,
                       state_to_dict)
from .plans import plan_state
from .execution import EXECUTION, PLAN_UPDATE, Execution, Settings, planned_note
from .poses import AsBuilt

OPTIONS_KEY = "rbe_ros.check_options"
#: What the node checked with from a time on (topic ~/settings): the check options and
#: frame_id, recorded at the start and after every parameter change (std_msgs/String, JSON
#: {"options", "frame_id"}), so that a replay re-checks every state as it was checked,
#: run-time changes included.
SETTINGS_TYPE = "std_msgs/msg/String"
STATE_TYPE = "rbe_msgs/msg/AssemblyState"
POSES_TYPE = "rbe_msgs/msg/BlockPoses"
REPORT_TYPE = "rbe_msgs/msg/StabilityReport"
#: A ~/plan goal and its result, as the node records them (topics ~/plan/goal, ~/plan/result).
PLAN_GOAL_TYPE = "rbe_msgs/action/PlanSequence_Goal"
PLAN_RESULT_TYPE = "rbe_msgs/action/PlanSequence_Result"
#: A plan under execution (~/execution) and its repairs (~/plan_update), answers to a design
#: or poses message like its report (the same header stamp).
EXECUTION_TYPE = "rbe_msgs/msg/ExecutionState"
PLAN_UPDATE_TYPE = "rbe_msgs/msg/PlanUpdate"
_ANSWER_TYPES = {REPORT_TYPE: REPORT_TYPE, EXECUTION_TYPE: EXECUTION, PLAN_UPDATE_TYPE: PLAN_UPDATE}
#: Topics of bags written here: the names rbe_node uses (node name rbe_node).
STATE_TOPIC = "/rbe_node/assembly"
REPORT_TOPIC = "/rbe_node/report"
DESIGN_TOPIC = "/rbe_node/design"
POSES_TOPIC = "/rbe_node/poses"
PLAN_GOAL_TOPIC = "/rbe_node/plan/goal"
PLAN_RESULT_TOPIC = "/rbe_node/plan/result"
#: Kinds of run: a state checked as it is, a design (~/design), measured poses (~/poses), a
#: plan goal (~/plan: its "reports" are its one result).
STATE, DESIGN, POSES, PLAN = "state", "design", "poses", "plan"
#: The message types of a run's kind and of its answers.
RUN_TYPES = {STATE: (STATE_TYPE, REPORT_TYPE), DESIGN: (STATE_TYPE, REPORT_TYPE),
             POSES: (POSES_TYPE, REPORT_TYPE), PLAN: (PLAN_GOAL_TYPE, PLAN_RESULT_TYPE)}
#: Log-time spacing of the reports (and markers) of a recorded sequence: one step a second,
#: so that a player's timeline (Foxglove) steps through the sequence one step at a time.
STEP_NS = 1_000_000_000
#: Report fields that are not compared.
IGNORED = frozenset({"solve_time", "dropped_states"})


# --- check options <-> JSON ------------------------------------------------------------------

def settings_dict(options: CheckOptions, frame_id: str, execution: Settings,
                  cell: Cell | None = None, design_name: str = "") -> dict:
    """What the node records on ~/settings: its check options, frame_id and execution
    parameters, the robot cell of the plan it executes (recorded before the design that
    brings the plan: its replay executes it for that cell) and the name of the design it
    sent itself (a design file's scene name, recorded before it: a message has no name)."""
    return {"options": json.loads(options_to_json(options)), "frame_id": frame_id,
            "execution": {"lookahead_steps": execution.lookahead_steps,
                          "min_margin_g": execution.min_margin_g,
                          **({"cell": cell_to_dict(cell)} if cell is not None else {})},
            **({"design_name": design_name} if design_name else {})}


def settings_cell(settings: dict | None) -> Cell | None:
    """The cell of the plan executed in recorded ``settings`` (None: none)."""
    cell = ((settings or {}).get("execution") or {}).get("cell")
    return None if cell is None else cell_from_dict(cell)


def bag_options(path) -> CheckOptions:
    """The check options recorded in the bag at ``path``, else the defaults."""
    text = read_custom_data(path).get(OPTIONS_KEY)
    return options_from_json(text) if text else CheckOptions()


# --- runs ------------------------------------------------------------------------------------

@dataclass
class Run:
    """One recorded state (a message dict) and the reports recorded for it."""

    state: dict
    stamp_ns: int                                   # log time of the state in the bag
    topic: str = STATE_TOPIC
    reports: list[dict] = field(default_factory=list)
    report_stamps: list[int] = field(default_factory=list)
    report_topic: str = REPORT_TOPIC
    kind: str = STATE                               # STATE, DESIGN or POSES
    settings: dict | None = None    # the node's settings when it got the state (~/settings)
    #: a design or poses run: the as-built scene after it (or why there is none)
    asbuilt: Scene | SceneError | None = None
    #: a design or poses run: the as-built scene as the node checked it, with the holds of
    #: the plan it executed then (:meth:`Execution.holding`; None: ``asbuilt``)
    held: Scene | SceneError | None = None
    #: a design or poses run: what the node made of it for the plan it executes, in order:
    #: (EXECUTION, an ExecutionState dict) or (PLAN_UPDATE, a PlanUpdate dict)
    execution: list[tuple[str, dict]] = field(default_factory=list)

    @property
    def header(self) -> dict:
        """The header of the state (of a plan goal: of its assembly)."""
        state = self.state.get("assembly", {}) if self.kind == PLAN else self.state
        return state.get("header", {})

    @property
    def key(self) -> tuple[int, int]:
        return _key(self.header)

    def checked(self) -> tuple[dict, list[dict]]:
        """The state checked and its reports: of a plan, the planned assembly and its steps'
        reports (from its result; nothing without one), else the state and its reports."""
        if self.kind == PLAN:
            result = self.reports[0] if self.reports else {}
            return result.get("plan", {}), result.get("reports", [])
        return self.state, self.reports

    def describe(self) -> str:
        header = self.header
        seq = self.state.get("sequence") or []
        what = f"{len(seq)}-block sequence" if seq else "whole assembly"
        contents = {STATE: f"{len(self.state.get('blocks', []))} blocks, {what}",
                    DESIGN: f"design of {len(self.state.get('blocks', []))} blocks",
                    POSES: f"{len(self.state.get('ids', []))} measured poses",
                    PLAN: f"plan of {len(self.state.get('assembly', {}).get('blocks', []))}"
                          f" blocks, at most {self.state.get('max_held')} held"}[self.kind]
        return (f"{'state' if self.kind == STATE else self.kind} stamp "
                f"{header_stamp_ns(header) / 1e9:.9f} s frame "
                f"{header.get('frame_id', '')!r} ({contents})")


def _key(header: dict) -> tuple[int, int]:
    stamp = header.get("stamp", {})
    return int(stamp.get("sec", 0)), int(stamp.get("nanosec", 0))


def step_stamps(stamp_ns: int, count: int) -> list[int]:
    """Log times of the ``count`` reports of a state logged at ``stamp_ns``."""
    return [stamp_ns + (k + 1) * STEP_NS for k in range(count)]


def _stamp_key(raw: bytes) -> tuple[int, int]:
    """(sec, nanosec) of the header stamp of a CDR AssemblyState, BlockPoses or
    StabilityReport (the header is their first field), read without deserialising."""
    little = raw[1] == 1                    # encapsulation CDR_LE (0x0001) or CDR_BE
    return struct.unpack_from("<iI" if little else ">iI", raw, 4)


class RunReader:
    """The runs of a bag, streamed: every AssemblyState and BlockPoses in log-time order,
    each with the reports whose header stamp is its stamp (a report goes to the latest such
    state before it), the settings then in force and (design, poses) the as-built scene
    after it. Other topics (markers) are not read.

    Two passes, so that memory does not grow with the bag: the first reads only the header
    stamps (from the CDR bytes) to count each run's reports; the second yields a run as soon
    as its reports are in, so only the runs still waiting for a report are held (the node
    answers a state within a check's time). Reports whose state is not in the bag (one
    file of a split bag: the state was in the file before) are counted in
    :attr:`orphan_reports` and skipped (their execution states too, not counted).
    :attr:`total`: the number of runs (after the first pass)."""

    def __init__(self, path):
        self.path = Path(path)
        self.orphan_reports = 0
        self.total: int | None = None

    def _owners(self) -> tuple[list[int], list[int]]:
        """Pass 1: the run of each report in bag order (-1: none) and each run's count."""
        counts: list[int] = []
        owners: list[int] = []
        by_key: dict[tuple[int, int], list[tuple[int, int]]] = {}
        plans: dict[tuple[int, int], list[int]] = {}
        for m in read_raw(self.path, {STATE_TYPE, POSES_TYPE, PLAN_GOAL_TYPE, PLAN_RESULT_TYPE,
                                      *_ANSWER_TYPES}):
            if m.msgtype == PLAN_GOAL_TYPE:     # a goal: its assembly's header comes first
                plans.setdefault(_stamp_key(m.raw), []).append(len(counts))
                counts.append(0)
                continue
            if m.msgtype == PLAN_RESULT_TYPE:
                # the result of the first goal with its planned assembly's stamp still
                # without one (a newer goal preempts an older); results are few: read whole
                key = _key(m.message().data.get("plan", {}).get("header", {}))
                owner = next((i for i in plans.get(key, []) if not counts[i]), -1)
                owners.append(owner)
                if owner >= 0:
                    counts[owner] += 1
                continue
            key = _stamp_key(m.raw)
            if m.msgtype not in _ANSWER_TYPES:
                by_key.setdefault(key, []).append((len(counts), m.stamp_ns))
                counts.append(0)
                continue
            found = by_key.get(key, [])
            before = next((i for i, t in reversed(found) if t <= m.stamp_ns), None)
            owner = before if before is not None else found[-1][0] if found else -1
            owners.append(owner)
            if owner >= 0:
                counts[owner] += 1
            elif m.msgtype == REPORT_TYPE:
                self.orphan_reports += 1
        return owners, counts

    def __iter__(self) -> Iterator[Run]:
        self.orphan_reports = 0
        owners, counts = self._owners()
        self.total = len(counts)
        pending: dict[int, Run] = {}
        created, done = 0, 0        # runs read, runs yielded
        reports = 0                 # reports read
        settings = None
        asbuilt = AsBuilt()
        # per topic: the last message's CDR after the stamp, its dict and as-built scene
        last: dict[str, tuple[bytes, dict, Scene | SceneError | None]] = {}
        repeats = report_repeats()      # a report again but for stamp, time, drops: not read
        for m in read_raw(self.path, {STATE_TYPE, POSES_TYPE, SETTINGS_TYPE, PLAN_GOAL_TYPE,
                                      PLAN_RESULT_TYPE, *_ANSWER_TYPES}):
            if m.msgtype == SETTINGS_TYPE:
                if m.topic.endswith("/settings"):
                    settings = json.loads(m.message().data["data"])
                continue
            if m.msgtype == PLAN_GOAL_TYPE:
                pending[created] = Run(m.message().data, m.stamp_ns, m.topic, kind=PLAN,
                                       settings=settings)
                created += 1
            elif m.msgtype in (EXECUTION_TYPE, PLAN_UPDATE_TYPE):
                owner, reports = owners[reports], reports + 1
                if owner >= 0:
                    pending[owner].execution.append((_ANSWER_TYPES[m.msgtype],
                                                     m.message().data))
            elif m.msgtype in (REPORT_TYPE, PLAN_RESULT_TYPE):
                owner, reports = owners[reports], reports + 1
                if owner < 0:
                    continue
                run = pending[owner]
                report = m.message().data if m.msgtype == PLAN_RESULT_TYPE else \
                    repeats.decode(m.raw)
                if report is None:
                    report = m.message().data
                    repeats.learn(report, m.raw)
                run.reports.append(report)
                run.report_stamps.append(m.stamp_ns)
                run.report_topic = m.topic
            else:
                kind = POSES if m.msgtype == POSES_TYPE else \
                    DESIGN if m.topic.endswith("/design") else STATE
                run = Run(self._state(m, last), m.stamp_ns, m.topic, kind=kind,
                          settings=settings)
                if kind == POSES and last.get(m.topic, (b"",))[0] == m.raw[12:]:
                    run.asbuilt = last[m.topic][2]     # the same poses again: no change
                elif kind != STATE:
                    try:
                        run.asbuilt = merge_message(asbuilt, kind, run.state, settings)
                    except SceneError as exc:
                        run.asbuilt = exc
                if kind == DESIGN:      # the measured poses are forgotten: merge again
                    last.clear()
                else:
                    last[m.topic] = (m.raw[12:], run.state, run.asbuilt)
                pending[created], created = run, created + 1
            while done in pending and \
                    len(pending[done].reports) + len(pending[done].execution) == counts[done]:
                yield pending.pop(done)
                done += 1
        for k in sorted(pending):       # (a bag that changed between the passes)
            yield pending[k]

    @staticmethod
    def _state(m, last) -> dict:
        """The message dict of a state or poses message; one that repeats the last on its
        topic but for the stamp (a cell sends the same poses at 10 Hz) is not read again."""
        if m.topic in last and last[m.topic][0] == m.raw[12:]:
            sec, nanosec = _stamp_key(m.raw)
            state = last[m.topic][1]
            return {**state, "header": {**state["header"],
                                        "stamp": {"sec": sec, "nanosec": nanosec}}}
        return m.message().data


def report_repeats() -> Repeats:
    """Reports that repeat the last but for the stamp, solve_time and dropped_states."""
    return Repeats(typestore(), REPORT_TYPE, ("solve_time", "dropped_states"))


def read_runs(path) -> list[Run]:
    """The runs of a bag, all in memory (:class:`RunReader` streams them)."""
    return list(RunReader(path))


def design_scene(message: dict, settings: dict | None = None) -> Scene:
    """The design of an AssemblyState dict, named as the node named it: the
    ``design_name`` of its recorded ``settings`` (a design file's scene name), else after
    its frame (SceneError)."""
    scene = scene_from_state_dict(message)
    name = (settings or {}).get("design_name")
    return replace(scene, name=name) if name else scene


def merge_message(asbuilt: AsBuilt, kind: str, message: dict,
                  settings: dict | None = None) -> Scene:
    """The as-built scene after a design (``kind`` DESIGN, an AssemblyState dict, named
    by :func:`design_scene` from ``settings``) or measured poses (POSES, a BlockPoses
    dict): the node's and the replay's one step (SceneError: the message's report is
    INVALID_INPUT)."""
    if kind == DESIGN:
        try:
            design, error = design_scene(message, settings), ""
        except SceneError as exc:
            design, error = None, str(exc)
        return asbuilt.set_design(design, error)
    return asbuilt.update(poses_from_dict(message))


def asbuilt_scenes(runs: list[Run]) -> list[Scene | SceneError | None]:
    """For each run, the as-built scene after it (or why there is none); None for states.
    Every design and poses message counts, checked when recorded or not."""
    asbuilt = AsBuilt()
    out: list[Scene | SceneError | None] = []
    for run in runs:
        if run.kind in (STATE, PLAN):
            out.append(None)
            continue
        try:
            out.append(merge_message(asbuilt, run.kind, run.state, run.settings))
        except SceneError as exc:
            out.append(exc)
    return out


def asbuilt_check(scene: Scene | SceneError, options: CheckOptions = CheckOptions(),
                  on_verdict: Callable[[Report], None] | None = None) -> StateCheck:
    """The check ``rbe_node`` makes of an as-built scene (as a whole), or the report of why
    there is none: the node's own dispatch, as for a state. A scene with holds is the state
    a plan has at its step (:meth:`Execution.holding`): its report's message ends with the
    step and the blocks held. ``on_verdict``: given the report before its tolerance
    question is asked (:func:`rbe_ros.analysis.pipeline.check_scene`'s), the note too."""
    def read(_sequence: bool) -> Scene:
        if isinstance(scene, SceneError):
            raise scene
        return scene

    def noted(report: Report) -> Report:
        return replace(report, message=report.message + planned_note(scene, report)) \
            if scene.holds else report

    result = check_state(read, False, options, on_verdict=on_verdict and (
        lambda report: on_verdict(noted(report))))
    if result.error is not None or not scene.holds:
        return result
    return replace(result, reports=[noted(result.reports[0])])


def state_reports(state: dict, options: CheckOptions = CheckOptions()) -> list[Report]:
    """The reports ``rbe_node`` makes for ``state`` (a message dict), in order: the node's
    own dispatch, :func:`rbe_ros.analysis.pipeline.check_state`."""
    def read(sequence: bool) -> Scene:
        return scene_from_state_dict(state if sequence else {**state, "sequence": []})

    return check_state(read, bool(state.get("sequence")), options).reports


def stopped_at(run: Run) -> int | None:
    """How many blocks the recorded plan of a plan run had placed when it was stopped
    (canceled, preempted, its time limit); None if it was not stopped."""
    recorded = run.reports[0] if run.reports else {}
    if not str(recorded.get("message", "")).startswith(STOPPED):
        return None
    return len(recorded.get("order", []))


def replay_plan(run: Run, options: CheckOptions = CheckOptions()) -> list[dict]:
    """The result dict of re-planning the goal of a plan run through the node's dispatch
    (:func:`plan_state`), with the settings the node had then. A recorded plan that was
    stopped (canceled, preempted, its time limit) is re-planned up to as many blocks as it
    had placed: the time it took is not part of the result; else without a time limit."""
    options, frame_id = run_settings(run, options)
    state, limits = plan_goal_from_dict(run.state)
    limits = replace(limits, time_limit=0.0)
    until = stopped_at(run)
    placed = [0]

    def count(progress) -> None:
        placed[0] = progress.placed

    def stop() -> bool:
        return until is not None and placed[0] >= until

    plan = plan_state(lambda: scene_from_state_dict(state), limits, options,
                      progress=count, should_stop=stop)
    return [plan_result_to_dict(plan, report_header(state.get("header"), frame_id))]


def run_settings(run: Run, options: CheckOptions) -> tuple[CheckOptions, str]:
    """The options and frame_id ``run`` was checked with: those the node recorded as its
    settings then (``run.settings``), else ``options`` and the default frame."""
    if run.settings is None:
        return options, "world"
    return (options_from_json(json.dumps(run.settings["options"]), options),
            run.settings["frame_id"])


def replay_run(run: Run, options: CheckOptions = CheckOptions()) -> list[dict]:
    """The report dicts of re-checking ``run.state`` (with the settings it was checked with)."""
    options, frame_id = run_settings(run, options)
    header = report_header(run.state.get("header"), frame_id)
    return [report_to_dict(r, header) for r in state_reports(run.state, options)]


def free_weights(state: dict | Scene | SceneError) -> dict[int, float]:
    """Free weight W (N) by step index (-1: the whole assembly) of a state (or an as-built
    scene): the weight of the free blocks present and not held. Empty if the state cannot
    be read."""
    if isinstance(state, SceneError):
        return {}
    try:
        if isinstance(state, Scene):
            scene, whole, state = state, replace(state, sequence=()), {}
        else:
            scene = scene_from_state_dict(state)
            whole = scene_from_state_dict({**state, "sequence": []})
    except SceneError:
        return {}
    g = float(np.linalg.norm(scene.gravity))
    mass = {b.id: pose_block(b).mass for b in scene.blocks}
    support = {b.id for b in scene.blocks if b.support}

    def weight(present, held) -> float:
        return g * sum(mass[i] for i in present if i not in support and i not in set(held))

    out = {-1: weight(*final_state(whole))}
    if state.get("sequence"):
        for step in sequence_steps(scene):
            out[step.index] = weight(step.present, step.held)
    return out


# --- comparison ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Tolerances:
    """How far a replayed report may be from the recorded one (module docstring)."""

    force: float = 1e-6          # share of the step's free weight
    position: float = 1e-6       # m
    ratio: float = 1e-6          # |V|/N, absolute (plus the force tolerance's share)
    message: float | None = None  # None: the message is not compared; else the relative
                                  # tolerance of the numbers in its text


@dataclass(frozen=True)
class Difference:
    """One field that differs: where (run, step, interface), what, and the two values."""

    run: int
    step: int
    block: str
    where: str
    field: str
    recorded: object
    replayed: object
    tolerance: float | None = None

    def __str__(self) -> str:
        step = "whole assembly" if self.step < 0 else f"step {self.step} ({self.block or '-'})"
        tol = "" if self.tolerance is None else f" (tolerance {self.tolerance:.3g})"
        where = f" {self.where}" if self.where else ""
        return (f"run {self.run} {step}{where}: {self.field}: recorded {_short(self.recorded)}"
                f", replayed {_short(self.replayed)}{tol}")


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 120 else text[:117] + "..."


_NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?|inf|nan")


def _points(points) -> np.ndarray:
    return np.array([[p["x"], p["y"], p["z"]] for p in points], dtype=float).reshape(-1, 3)


def _match(a, b, tol: float) -> list[int] | None:
    """For each point of ``a`` the index of the point of ``b`` within ``tol`` of it (a
    permutation), or None when the two point sets differ."""
    pa, pb = _points(a), _points(b)
    if len(pa) != len(pb):
        return None
    if not len(pa):
        return []
    dist = np.linalg.norm(pa[:, None, :] - pb[None, :, :], axis=2)
    order = [int(j) for j in dist.argmin(axis=1)]
    if len(set(order)) != len(order) or dist[np.arange(len(pa)), order].max() > tol:
        return None
    return order


def _diameter(polygon) -> float:
    pts = np.array([[p["x"], p["y"], p["z"]] for p in polygon], dtype=float).reshape(-1, 3)
    if len(pts) < 2:
        return 0.0
    return float(np.max(np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)))


class _Comparer:
    def __init__(self, run: int, step: int, block: str, weight: float, tol: Tolerances):
        self.run, self.step, self.block = run, step, block
        self.force = tol.force * (weight if weight > 0 else 1.0)
        self.tol = tol
        self.out: list[Difference] = []

    def diff(self, where, name, recorded, replayed, tolerance=None):
        self.out.append(Difference(self.run, self.step, self.block, where, name, recorded,
                                   replayed, tolerance))

    def exact(self, where, name, a, b):
        if a != b:
            self.diff(where, name, a, b)

    def number(self, where, name, a, b, tol):
        a, b = float(a), float(b)
        if math.isinf(a) or math.isinf(b) or math.isnan(a) or math.isnan(b):
            if not (a == b or (math.isnan(a) and math.isnan(b))):
                self.diff(where, name, a, b, tol)
        elif abs(a - b) > tol:
            self.diff(where, name, a, b, tol)

    def vectors(self, where, name, a, b, tol):
        """Lists of numbers, of vector dicts, or single vector dicts."""
        if isinstance(a, dict):
            a, b = [a], [b]
        if len(a) != len(b):
            self.diff(where, f"{name} (count)", len(a), len(b))
            return
        for i, (x, y) in enumerate(zip(a, b)):
            label = f"{name}[{i}]" if len(a) > 1 else name
            if isinstance(x, dict):
                worst = max(abs(float(x[k]) - float(y[k])) for k in x)
                if not worst <= tol:
                    self.diff(where, label, x, y, tol)
            else:
                self.number(where, label, x, y, tol)

    def ratio(self, where, name, a, b, normal):
        a, b = float(a), float(b)
        scale = max(abs(normal), self.force)
        finite = a if math.isfinite(a) else 0.0
        self.number(where, name, a, b, self.tol.ratio + self.force * (1 + abs(finite)) / scale)

    def message(self, a: str, b: str):
        if _NUMBER.sub("#", a) != _NUMBER.sub("#", b):
            self.diff("", "message", a, b)
            return
        for x, y in zip(_NUMBER.findall(a), _NUMBER.findall(b)):
            fx, fy = float(x), float(y)
            if not (fx == fy or abs(fx - fy) <= (self.tol.message or 0.0) * max(abs(fx), abs(fy))):
                self.diff("", "message", a, b, self.tol.message)
                return


_TOP_EXACT = ("step_index", "block_placed", "stable", "status", "num_blocks", "unstable_blocks",
              "held_blocks", "suggested_holds", "model")
_TOP_DONE = set(_TOP_EXACT) | {"header", "message", "max_tension", "worst_friction_ratio",
                               "interfaces", "margin_g", "margin_direction",
                               "insertion_direction", "hold_wrenches"} | IGNORED
_IF_DONE = {"block_a", "block_b", "normal", "polygon", "normal_forces", "tangential_forces",
            "resultant_force", "normal_resultant", "shear_resultant", "centre_of_pressure",
            "torque", "kern", "friction_ratio", "tension", "friction_exceeded"}


def compare_report(recorded: dict, replayed: dict, *, run: int = 0, free_weight: float = 1.0,
                   tolerances: Tolerances = Tolerances()) -> list[Difference]:
    """The differences between two StabilityReport dicts (see the module docstring)."""
    c = _Comparer(run, int(recorded.get("step_index", -1)), str(recorded.get("block_placed", "")),
                  free_weight, tolerances)
    c.exact("", "header", recorded.get("header"), replayed.get("header"))
    for name in _TOP_EXACT:
        c.exact("", name, recorded.get(name), replayed.get(name))
    if tolerances.message is not None:
        c.message(str(recorded.get("message", "")), str(replayed.get("message", "")))
    c.number("", "max_tension", recorded.get("max_tension", 0.0),
             replayed.get("max_tension", 0.0), c.force)
    a_ifs, b_ifs = recorded.get("interfaces", []), replayed.get("interfaces", [])
    pairs_a = [(i["block_a"], i["block_b"]) for i in a_ifs]
    pairs_b = [(i["block_a"], i["block_b"]) for i in b_ifs]
    if pairs_a != pairs_b:
        c.diff("", "interface pairs", [f"{a}|{b}" for a, b in pairs_a],
               [f"{a}|{b}" for a, b in pairs_b])
    ratio_tol = tolerances.ratio
    for k, (x, y) in enumerate(zip(a_ifs, b_ifs)):
        if (x["block_a"], x["block_b"]) != (y["block_a"], y["block_b"]):
            continue
        where = f"interface {x['block_a']}|{x['block_b']}"
        if pairs_a.count((x["block_a"], x["block_b"])) > 1:
            where += f" #{k}"
        for flag in ("tension", "friction_exceeded"):
            c.exact(where, flag, x.get(flag), y.get(flag))
        pos = tolerances.position
        c.vectors(where, "normal", x["normal"], y["normal"], pos)
        # vertices are matched by position: their order is not part of the result
        order = _match(x["polygon"], y["polygon"], pos)
        if order is None:
            c.diff(where, "polygon", x["polygon"], y["polygon"], pos)
        else:
            for name in ("normal_forces", "tangential_forces"):
                c.vectors(where, name, x[name], [y[name][j] for j in order], c.force)
        if _match(x["kern"], y["kern"], pos) is None:
            c.diff(where, "kern", x["kern"], y["kern"], pos)
        for name in ("resultant_force", "shear_resultant"):
            c.vectors(where, name, x[name], y[name], c.force)
        c.number(where, "normal_resultant", x["normal_resultant"], y["normal_resultant"], c.force)
        d = _diameter(x["polygon"])
        n = float(x["normal_resultant"])
        c.vectors(where, "centre_of_pressure", x["centre_of_pressure"], y["centre_of_pressure"],
                  pos + c.force * d / max(abs(n), c.force))
        c.number(where, "torque", x["torque"], y["torque"], c.force * max(d, pos))
        c.ratio(where, "friction_ratio", x["friction_ratio"], y["friction_ratio"], n)
        ratio_tol = max(ratio_tol, tolerances.ratio + c.force * (1 + (
            abs(float(x["friction_ratio"])) if math.isfinite(float(x["friction_ratio"])) else 0.0))
            / max(abs(n), c.force))
        for name in sorted(set(x) - _IF_DONE):
            c.exact(where, name, x.get(name), y.get(name))
    c.number("", "worst_friction_ratio", recorded.get("worst_friction_ratio", 0.0),
             replayed.get("worst_friction_ratio", 0.0), ratio_tol)
    c.number("", "margin_g", recorded.get("margin_g", NOT_COMPUTED),
             replayed.get("margin_g", NOT_COMPUTED), tolerances.force)
    if "insertion_direction" in recorded:
        c.vectors("", "insertion_direction", recorded["insertion_direction"],
                  replayed.get("insertion_direction", dict.fromkeys("xyz", 0.0)),
                  tolerances.position)
    _compare_hold_wrenches(c, recorded.get("hold_wrenches", []),
                           replayed.get("hold_wrenches", []), tolerances)
    for name in sorted(set(recorded) - _TOP_DONE):     # fields added later: exact
        c.exact("", name, recorded.get(name), replayed.get(name))
    return c.out


def _compare_hold_wrenches(c: _Comparer, a: list, b: list, tolerances: Tolerances) -> None:
    """The robots' wrenches: blocks exact, forces within the force tolerance, torques within
    it times the grip's distance from the origin plus one (m), grip points within the
    position tolerance, utilisations within the ratio tolerance."""
    c.exact("", "hold_wrenches blocks", [w["block"] for w in a], [w["block"] for w in b])
    for x, y in zip(a, b):
        where = f"hold of {x['block']}"
        arm = 1.0 + max(abs(float(v)) for v in x["grip_point"].values())
        c.vectors(where, "force", x["force"], y["force"], c.force)
        c.vectors(where, "torque", x["torque"], y["torque"], c.force * arm)
        c.vectors(where, "grip_point", x["grip_point"], y["grip_point"], tolerances.position)
        c.number(where, "utilisation", x["utilisation"], y["utilisation"], tolerances.ratio)


#: Plan result fields compared exactly (the reports are compared as reports).
_PLAN_EXACT = ("feasible", "message", "order", "holds", "failed_step")
#: Fields of a cell timeline's actions compared exactly (not its poses and wrenches: the
#: grips follow from these, and the wrenches are forces, compared in the reports).
_ACTION_EXACT = ("action", "robot", "block", "step", "stable", "status")


def compare_plan(recorded: dict, replayed: dict, *, run: int = 0,
                 tolerances: Tolerances = Tolerances()) -> list[Difference]:
    """The differences between two PlanSequence result dicts: the plan (feasibility,
    message, order, holds, failed step, a cell's robots and its timeline's actions; the
    planned assembly's header, sequence, holds and blocks) exactly, each step's report as
    :func:`compare_report` does (free weight: the planned assembly's at that step)."""
    c = _Comparer(run, -1, "", 1.0, tolerances)
    for name in _PLAN_EXACT:
        c.exact("plan result", name, recorded.get(name), replayed.get(name))
    # a result recorded before cells has neither: none
    c.exact("plan result", "robots", recorded.get("robots", []), replayed.get("robots", []))
    c.exact("plan result", "timeline",
            [[x.get(k) for k in _ACTION_EXACT] for x in recorded.get("timeline", [])],
            [[x.get(k) for k in _ACTION_EXACT] for x in replayed.get("timeline", [])])
    a, b = recorded.get("plan", {}), replayed.get("plan", {})
    for name in ("header", "sequence", "holds"):
        c.exact("planned assembly", name, a.get(name), b.get(name))
    c.exact("planned assembly", "blocks", [x["id"] for x in a.get("blocks", [])],
            [x["id"] for x in b.get("blocks", [])])
    out = c.out
    weights = free_weights(a) if a.get("blocks") else {}
    reports_a, reports_b = recorded.get("reports", []), replayed.get("reports", [])
    if len(reports_a) != len(reports_b):
        out.append(Difference(run, -1, "", "plan result", "reports (count)", len(reports_a),
                              len(reports_b)))
    for rec, rep in zip(reports_a, reports_b):
        out += compare_report(rec, rep, run=run, tolerances=tolerances,
                              free_weight=weights.get(int(rec.get("step_index", -1)), 1.0))
    return out


def compare_run(index: int, run: Run, replayed: list[dict], *,
                tolerances: Tolerances = Tolerances()) -> list[Difference]:
    """Differences between ``run``'s recorded reports and ``replayed`` (the same comparison
    offline and live; ``index``: the run's number in the bag)."""
    out: list[Difference] = []
    if run.kind == PLAN:
        for rec, rep in zip(run.reports, replayed):
            out += compare_plan(rec, rep, run=index, tolerances=tolerances)
        return out
    unequal = [(rec, rep) for rec, rep in zip(run.reports, replayed) if not _equal(rec, rep)]
    if unequal:
        weights = free_weights(run.state if run.kind == STATE else _asbuilt(run))
        for rec, rep in unequal:
            w = weights.get(int(rec.get("step_index", -1)), 1.0)
            out += compare_report(rec, rep, run=index, free_weight=w, tolerances=tolerances)
    for rec in run.reports[len(replayed):]:
        out.append(Difference(index, int(rec.get("step_index", -1)),
                              rec.get("block_placed", ""), "", "report", "recorded",
                              "missing in the replay"))
    for rep in replayed[len(run.reports):]:
        out.append(Difference(index, int(rep.get("step_index", -1)),
                              rep.get("block_placed", ""), "", "report",
                              "missing in the recording", "replayed"))
    return out


def replay_execution(tracker: Execution, run: Run, reports: list[dict],
                     options: CheckOptions = CheckOptions()) -> list[tuple[str, dict]]:
    """What the node's plan execution made of ``run`` (``reports``: its as-built report),
    again, from ``tracker`` (the plan as the runs before left it): a design sets the plan;
    a design or poses run the node answered on ~/execution is advanced as the node did."""
    if run.kind == DESIGN:
        try:
            design = design_scene(run.state, run.settings)
        except SceneError:
            design = None
        tracker.set_design(design, settings_cell(run.settings))
    if run.kind not in (DESIGN, POSES) or not run.execution:
        return []
    run_options, frame_id = run_settings(run, options)
    header = report_header(run.state.get("header"), frame_id)
    # the report of a split bag's file may be in the file before: then the one recorded
    # with the execution state (the report itself is compared where it is)
    as_built = reports[0] if reports else next(
        (m["as_built"] for kind, m in run.execution if kind == EXECUTION), None)
    return tracker.advance(_asbuilt(run), as_built, header, run_options,
                           Settings.of((run.settings or {}).get("execution")))


_EXECUTION_EXACT = ("active", "current_step", "total_steps", "first_failing_step")
_LOOKAHEAD_EXACT = ("step", "block", "stable", "status", "insertable")
_UPDATE_EXACT = ("changed_step", "feasible", "repair", "order", "holds")
#: A repaired timeline's actions: who does what, and whether the state after it stands.
_ACTION_EXACT = ("action", "robot", "block", "step", "stable")


def compare_execution(index: int, run: Run, replayed: list[tuple[str, dict]], *,
                      tolerances: Tolerances = Tolerances()) -> list[Difference]:
    """Differences between the ExecutionStates and PlanUpdates recorded for ``run`` and
    ``replayed``: steps, verdicts, orders, holds and a cell's repaired timeline (its
    actions and their verdicts) exactly, messages as reports' are, margins and hold forces
    within the tolerances."""
    c = _Comparer(index, -1, "", 1.0, tolerances)
    kinds = [k for k, _ in run.execution], [k for k, _ in replayed]
    if kinds[0] != kinds[1]:
        c.diff("execution", "messages", kinds[0], kinds[1])
        return c.out
    for (kind, a), (_, b) in zip(run.execution, replayed):
        if kind == PLAN_UPDATE:
            for name in _UPDATE_EXACT:
                c.exact("plan_update", name, a[name], b[name])
            c.exact("plan_update", "timeline", *([tuple(x[k] for k in _ACTION_EXACT)
                                                  for x in u.get("timeline", [])]
                                                 for u in (a, b)))
            c.message(a["reason"], b["reason"])
            c.message(a["message"], b["message"])
            continue
        for name in _EXECUTION_EXACT:
            c.exact("execution", name, a[name], b[name])
        c.exact("execution", "as_built.status", a["as_built"]["status"],
                b["as_built"]["status"])
        c.message(a["message"], b["message"])
        if len(a["lookahead"]) != len(b["lookahead"]):
            c.diff("execution", "lookahead (count)", len(a["lookahead"]), len(b["lookahead"]))
            continue
        for x, y in zip(a["lookahead"], b["lookahead"]):
            where = f"lookahead step {x['step']}"
            for name in _LOOKAHEAD_EXACT:
                c.exact(where, name, x[name], y[name])
            c.number(where, "margin_g", x["margin_g"], y["margin_g"], tolerances.ratio)
            c.number(where, "max_hold_force", x["max_hold_force"], y["max_hold_force"],
                     tolerances.force * max(1.0, abs(float(x["max_hold_force"]))))
            c.message(x["message"], y["message"])
    return c.out


def _equal(recorded: dict, replayed: dict) -> bool:
    """Whether two report dicts are equal in every compared field (then no tolerance
    matters; the usual case, and the field by field comparison is what costs)."""
    return all(recorded.get(k) == replayed.get(k) for k in set(recorded) | set(replayed)
               if k not in IGNORED)


def _asbuilt(run: Run) -> Scene | SceneError:
    if run.asbuilt is None:
        raise ValueError("a design or poses run without its as-built scene: read the bag "
                         "with RunReader (or fill them in with asbuilt_scenes)")
    return run.asbuilt


def _with_asbuilt(runs: list[Run]) -> list[Run]:
    """``runs`` with the as-built scene of every design and poses run filled in."""
    if any(r.kind in (DESIGN, POSES) and r.asbuilt is None for r in runs):
        for run, scene in zip(runs, asbuilt_scenes(runs)):
            run.asbuilt = scene
    return runs


def compare_runs(runs: list[Run], replayed: list[list[dict]], *,
                 tolerances: Tolerances = Tolerances()) -> list[Difference]:
    """Differences between each run's recorded reports and ``replayed[i]``."""
    out: list[Difference] = []
    for i, (run, new) in enumerate(zip(_with_asbuilt(runs), replayed)):
        out += compare_run(i, run, new, tolerances=tolerances)
    return out


def format_differences(described: dict[int, str], differences: list[Difference],
                       limit: int = 50) -> str:
    """A readable diff: the runs concerned (``described``: a run's number -> its
    description, :meth:`Run.describe`), then one line per differing field."""
    lines = []
    for i in sorted({d.run for d in differences}):
        lines.append(f"run {i}: {described.get(i, '')}")
        shown = [d for d in differences if d.run == i]
        lines += [f"  {d}" for d in shown[:limit]]
        if len(shown) > limit:
            lines.append(f"  ... and {len(shown) - limit} more differences")
    return "\n".join(lines)


# --- writing ---------------------------------------------------------------------------------

class RunWriter:
    """A bag of runs written one at a time: each run's state and its reports (at the
    recorded report times where there are as many, else a step a second after the state:
    :data:`STEP_NS`); with ``markers`` each report's MarkerArray on
    :data:`rbe_ros.io.markers.MARKER_TOPIC` at its time; the options in custom_data."""

    def __init__(self, path, options: CheckOptions, *, markers: bool = True):
        self.options, self.markers = options, markers
        self.bag = BagWriter(path, custom_data={OPTIONS_KEY: options_to_json(options)})
        self.topics: set[str] = set()
        self._last: tuple | None = None     # the last markers drawn: (content, reports, arrays)
        self._reports = report_repeats()

    def __enter__(self) -> "RunWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _topic(self, topic: str, msgtype: str, latched: bool) -> None:
        if topic not in self.topics:
            self.bag.add_topic(topic, msgtype, transient_local=latched)
            self.topics.add(topic)

    def write(self, run: Run, reports: list[dict]) -> None:
        state_type, answer_type = RUN_TYPES[run.kind]
        self._topic(run.topic, state_type, run.kind == DESIGN)
        self._topic(run.report_topic, answer_type, True)
        if self.markers:
            self._topic(MARKER_TOPIC, MARKER_TYPE, True)
        self.bag.write(run.topic, run.state, run.stamp_ns)
        stamps = run.report_stamps if len(run.report_stamps) == len(reports) else \
            step_stamps(run.stamp_ns, len(reports))
        for report, stamp in zip(reports, stamps):
            self.bag.write(run.report_topic, report if run.kind == PLAN else
                           self._reports.encode(report), stamp)
        if self.markers and reports and run.kind != PLAN:
            for array, stamp in zip(self._markers(run, reports), stamps):
                self.bag.write(MARKER_TOPIC, array, stamp)

    def _markers(self, run: Run, reports: list[dict]) -> list[dict]:
        """The MarkerArrays of ``reports``; those of the last run again, with the new
        headers, when the run checked the same state with the same reports (a session's
        repeated poses)."""
        content = {**run.state, "header": None} if run.kind == STATE else _asbuilt(run)
        bare = [{**r, "header": None} for r in reports]
        if self._last is not None and (content is self._last[0] or (
                run.kind == STATE and content == self._last[0])) and bare == self._last[1]:
            return [{"markers": [{**m, "header": r["header"]} for m in array["markers"]]}
                    for array, r in zip(self._last[2], reports)]
        # an as-built run is drawn as the state checked: its scene, as a whole
        drawn = run.state if run.kind == STATE else {} if isinstance(
            run.asbuilt, SceneError) else {**state_to_dict(run.asbuilt), "sequence": []}
        arrays = run_markers(drawn, reports, self.options)
        self._last = (content, bare, arrays)
        return arrays

    def close(self) -> None:
        self.bag.close()


def write_runs(path, runs: list[Run], replayed: list[list[dict]], options: CheckOptions, *,
               markers: bool = True) -> None:
    """A bag with every run's state and its ``replayed`` reports (:class:`RunWriter`)."""
    with RunWriter(path, options, markers=markers) as writer:
        for run, reports in zip(_with_asbuilt(runs) if markers else runs, replayed):
            writer.write(run, reports)


def record_bag(path, scenes: list[tuple[Scene, str, int]], options: CheckOptions = CheckOptions(),
               *, zero_times: bool = False, markers: bool = True) -> list[Run]:
    """Check ``(scene, frame_id, stamp_ns)`` states as the node would and record states,
    reports and (``markers``) their markers in a new bag at ``path`` (a step a second after
    their state). ``zero_times``: solve_time 0 in every report, so that reruns write
    identical files."""
    runs = []
    for scene, frame, stamp in scenes:
        run = Run(state_to_dict(scene, frame, stamp), stamp)
        run.reports = replay_run(run, options)
        if zero_times:
            for r in run.reports:
                r["solve_time"] = 0.0
        run.report_stamps = step_stamps(stamp, len(run.reports))
        runs.append(run)
    write_runs(path, runs, [r.reports for r in runs], options, markers=markers)
    return runs


# --- the whole replay ------------------------------------------------------------------------

#: Differences kept for the diff (all are counted): a replay of hours that differs
#: everywhere must not hold them all.
KEPT_DIFFERENCES = 1000


@dataclass
class ReplayResult:
    """What a replay found: how many runs and reports it re-checked, the differences from
    the recorded reports (the first :data:`KEPT_DIFFERENCES`; :attr:`difference_count`
    counts them all) and, unless streamed (``keep=False``), the runs and their replayed
    reports."""

    runs: list[Run]
    replayed: list[list[dict]]
    differences: list[Difference]
    output: Path | None
    options: CheckOptions
    states: int = 0                 # runs read
    reports: int = 0                # reports replayed
    executed: int = 0               # ExecutionStates and PlanUpdates made again (compared)
    recorded: int = 0               # reports recorded (compared)
    difference_count: int = 0
    orphan_reports: int = 0         # reports whose state is not in the bag (a split file)
    described: dict[int, str] = field(default_factory=dict)  # runs with differences

    @property
    def matches(self) -> bool:
        return not self.difference_count

    def diff(self, limit: int = 50) -> str:
        return format_differences(self.described, self.differences, limit)

    def add(self, index: int, run: Run, replayed: list[dict],
            differences: list[Difference], keep: bool) -> None:
        self.states += 1
        self.reports += len(replayed)
        self.recorded += len(run.reports)
        if differences:
            self.difference_count += len(differences)
            room = KEPT_DIFFERENCES - len(self.differences)
            if room > 0:
                self.differences += differences[:room]
                self.described[index] = run.describe()
        if keep:
            self.runs.append(run)
            self.replayed.append(replayed)


def default_output(path) -> Path:
    """Where a replay of the bag at ``path`` is written unless told: beside it, + "_replay"."""
    path = Path(path)
    return path.with_name(path.name + "_replay")


#: Re-checks runs: ``recheck(runs, options, on_run)`` -> each run with its report dicts, in
#: order, as they are made (a generator: a replay holds one run at a time).
Recheck = Callable[[Iterable[Run], CheckOptions, Callable[[int, Run], None] | None],
                   Iterator[tuple[Run, list[dict]]]]


class _LastCheck:
    """The reports of the last state checked, for the next run if it is the same state
    with the same settings (a cell sends the same poses at 10 Hz between placements; the
    check is deterministic, so its reports are the same but for the header)."""

    def __init__(self) -> None:
        self.what: tuple | None = None
        self.content: object = None
        self.reports: list[dict] = []

    def reports_for(self, run: Run, options: CheckOptions) -> list[dict]:
        run_options, frame_id = run_settings(run, options)
        header = report_header(run.state.get("header"), frame_id)
        # a state by its contents; an as-built scene by identity (AsBuilt returns the same
        # scene for an update that changes nothing)
        asbuilt = run.asbuilt if run.held is None else run.held
        content = {**run.state, "header": None} if run.kind == STATE else asbuilt
        what = (run.kind == STATE, options_to_json(run_options))
        if self.what != what or not (content is self.content or (
                run.kind == STATE and content == self.content)):
            self.what, self.content = what, content
            check = state_reports(run.state, run_options) if run.kind == STATE else \
                asbuilt_check(asbuilt, run_options).reports
            self.reports = [report_to_dict(r, header) for r in check]
        return [{**r, "header": header} for r in self.reports]


def offline_reports(runs: Iterable[Run], options: CheckOptions,
                    on_run: Callable[[int, Run], None] | None = None
                    ) -> Iterator[tuple[Run, list[dict]]]:
    """Each run with the report dicts of re-checking it here, as the node would: a state
    always, a design or poses message only if the node answered it (under overload it
    checks the newest only); the same state again reuses the last reports."""
    last = _LastCheck()
    for i, run in enumerate(runs):
        if run.kind not in (STATE, PLAN) and run.asbuilt is None:
            raise ValueError("offline_reports takes runs with their as-built scenes "
                             "(RunReader)")
        reports = replay_plan(run, options) if run.kind == PLAN else \
            last.reports_for(run, options) if run.kind == STATE or run.reports else []
        if on_run is not None:
            on_run(i, run)
        yield run, reports


def replay_bag(path, output=None, *, options: CheckOptions | None = None, compare: bool = True,
               recheck: Recheck = offline_reports, tolerances: Tolerances = Tolerances(),
               write: bool = True, markers: bool = True,
               on_run: Callable[[int, Run], None] | None = None,
               keep: bool = True) -> ReplayResult:
    """Re-check every state of the bag at ``path`` with ``recheck`` (offline; or through a
    live rbe_node: :func:`rbe_ros.ros.live.live_recheck`), write the states and the new
    reports to ``output`` (default: path + "_replay"; never overwritten; ``write=False``:
    no bag; ``markers``: with the reports' markers), and with ``compare`` list the
    differences from the recorded reports (markers are drawings of the reports: not
    compared). Streamed: a run is read, re-checked, written and compared, then let go
    (``keep``: the result keeps the runs and their replayed reports, memory growing with
    the bag). ``path`` may be a :class:`RunReader` (whose ``total`` a progress display
    reads)."""
    runs = path if isinstance(path, RunReader) else RunReader(path)
    path = runs.path
    if not path.exists():
        raise FileNotFoundError(f"no bag at {str(path)!r}")
    out = Path(output) if output is not None else default_output(path)
    if write and out.exists():
        raise FileExistsError(f"{str(out)!r} exists already, not overwriting it")
    options = options or bag_options(path)
    result = ReplayResult([], [], [], out if write else None, options)
    writer = RunWriter(out, options, markers=markers) if write else None
    execution = Execution()         # the plan the node executed, as the runs leave it

    def holding(runs: Iterable[Run]) -> Iterator[Run]:
        # each run taken once the runs before it are executed: the plan then in force
        for run in runs:
            if run.kind in (DESIGN, POSES) and run.asbuilt is not None:
                run.held = execution.holding(run.asbuilt)
            yield run

    pairs = recheck(holding(runs), options, on_run)
    try:
        for i, (run, reports) in enumerate(pairs):
            if writer is not None:
                writer.write(run, reports)
            executed = replay_execution(execution, run, reports, options)
            result.executed += len(executed)
            found = compare_run(i, run, reports, tolerances=tolerances) + \
                compare_execution(i, run, executed, tolerances=tolerances) if compare else []
            result.add(i, run, reports, found, keep)
    finally:
        getattr(pairs, "close", lambda: None)()
        if writer is not None:
            writer.close()
    result.orphan_reports = runs.orphan_reports
    return result


__all__ = ["DESIGN", "Difference", "KEPT_DIFFERENCES", "OPTIONS_KEY", "PLAN", "POSES",
           "ReplayResult", "Run", "RunReader", "RunWriter", "STATE", "Tolerances",
           "asbuilt_check", "asbuilt_scenes", "bag_options", "compare_plan", "compare_report",
           "compare_execution", "compare_run", "compare_runs", "default_output", "design_scene",
           "free_weights",
           "merge_message",
           "offline_reports", "options_from_json", "options_to_json", "read_runs", "record_bag",
           "replay_bag", "replay_execution", "replay_plan", "replay_run", "report_repeats",
           "run_settings", "SETTINGS_TYPE", "settings_cell", "settings_dict", "state_reports",
           "step_stamps",
           "stopped_at", "write_runs"]
